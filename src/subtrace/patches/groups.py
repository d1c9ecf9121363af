"""Skip groups over the items of an isolated patch: its split tree, as flat rows a ray walks.

An isolated patch (either scheme) is a set of *items*: dyadic sub-squares (Catmull-Clark) or
sub-triangles (Loop) of the patch at various levels, regular pieces near the middle and ever
smaller ones towards its features. They are the leaves of the patch's 1-to-4 split tree.
A ray that enters the patch should not test every item's box: near three extraordinary
corners (or along a crease) the items of each level lie at every corner, so no box of "this
level and the finer ones" excludes anything.

:func:`grouped_layout` lays the items out depth first in that tree and puts before each
subtree that holds two items or more a *group* row (item kind :data:`GROUP`): the box of
its items and the number of rows it spans. A ray walks the rows in order; on a group whose
box it misses it jumps past the group (``it + ref``), else it goes on to the group's first
row. This is a stackless BVH (the skip-pointer layout of flat trees, as in pbrt's
``LinearBVHNode`` walked without a stack), built from the split tree instead of by
partitioning, so it costs one sort per batch of patches. A chain of subtrees over the same
items keeps one group (the coarsest).

Child codes: a sub-square (level l, corner (i, j) in units of 2^-l) is child
``(i & 1) + 2 (j & 1)`` of the square (l - 1, i >> 1, j >> 1). A sub-triangle with corner
A = (i, j) and orientation g (corners A, A + g (1, 0), A + g (0, 1), as
``patches/isolate_loop.py``) lies in the level l - 1 triangle that holds its centroid
``(i + g/3, j + g/3) / 2``: with ``a, b`` the integer parts, upright at (a, b) when the
fractional parts sum below 1, else turned at (a + 1, b + 1). Its code is 3 when its
orientation differs from its parent's (the middle child), else ``g (i - 2 pi) + 2 g (j -
2 pj)`` (0, 1, 2: the corner children in Loop's order). The order among a node's children
puts its items first (they are the coarsest pieces left there, the likeliest first hits:
a hit found early bounds the boxes tested after it), then its subtrees.
"""

from __future__ import annotations

import numpy as np

# the fewest items a subtree below the patch's own needs for a group row: a ray entering a
# group tests its box besides its items', so a small group saves nothing
MIN_GROUP = 4


def child_codes(level, i0, j0, orient=None):
    """(n, L+1) int8: ``codes[k, l]`` is the child code (module doc) of item k's ancestor at
    level l (1 <= l <= level[k]; 0 elsewhere), L = level.max(). ``orient`` (n,) +1 / -1 for
    sub-triangles, None for sub-squares."""
    level = np.asarray(level, np.int64)
    n = len(level)
    top = int(level.max(initial=0))
    codes = np.zeros((n, top + 1), np.int8)
    i, j, lev = np.array(i0, np.int64), np.array(j0, np.int64), level.copy()
    g = None if orient is None else np.array(orient, np.int64)
    rows = np.arange(n)
    for _ in range(top):
        m = lev > 0
        if not m.any():
            break
        r, ci, cj = rows[m], i[m], j[m]
        if g is None:
            code = (ci & 1) + 2 * (cj & 1)
            pi, pj = ci >> 1, cj >> 1
        else:
            cg = g[m]
            x3, y3 = 3 * ci + cg, 3 * cj + cg  # 3 x the centroid, in level-l units
            a, b = x3 // 6, y3 // 6  # the parent level's cell
            up = (x3 - 6 * a) + (y3 - 6 * b) < 6
            pg = np.where(up, 1, -1)
            pi, pj = np.where(up, a, a + 1), np.where(up, b, b + 1)
            code = np.where(cg != pg, 3, pg * (ci - 2 * pi) + 2 * pg * (cj - 2 * pj))
            g[m] = pg
        codes[r, lev[m]] = code
        i[m], j[m], lev[m] = pi, pj, lev[m] - 1
    return codes


def grouped_layout(root, level, i0, j0, orient, lo, hi):
    """The rows of the items of a batch of patches with their groups (module doc).

    ``root`` (n,) the patch (0 .. m-1) of each item; ``level``, ``i0``, ``j0`` (n,) its
    place in the patch; ``orient`` (n,) for sub-triangles, None for sub-squares; ``lo``,
    ``hi`` (n,3) its box. Returns ``(take, g_level, g_lo, g_hi, g_span, first, count)``:
    row r holds item ``take[r]``, or a group where ``take[r] < 0`` (its level, box and row
    span, the rows of the group's own subtree including itself, in the order of those rows);
    patch p's rows are ``first[p] .. first[p] + count[p] - 1``. A patch of one item gets no
    group."""
    root = np.asarray(root, np.int64)
    n = len(root)
    m = int(root.max(initial=-1)) + 1
    order, differs, top = _depth_first(root, level, i0, j0, orient)
    root_s = root[order]
    # subtree k of level l: the items whose patch and codes 1..l agree; a new subtree
    # starts where its key changes
    new = np.ones((top + 1, n), bool)  # new[l, r]: sorted item r starts a level-l subtree
    if n:
        new[0, 1:] = root_s[1:] != root_s[:-1]
        for l in range(1, top + 1):
            new[l, 1:] = new[l - 1, 1:] | differs(l)
    starts, ends, levels = [], [], []
    # (a subtree with the same items as a coarser kept group adds nothing: then it has the
    # items of its parent, which was kept or had them too; held[s]: the end of the
    # parent level's subtree from sorted row s that was kept or had a kept group's items,
    # else -1)
    held = np.full(n + 1, -1, np.int64)
    for l in range(top + 1):
        s = np.nonzero(new[l])[0]
        e = np.r_[s[1:], n]
        same = held[s] == e
        keep = (e - s >= (2 if l == 0 else MIN_GROUP)) & ~same
        starts.append(s[keep])
        ends.append(e[keep])
        levels.append(np.full(int(keep.sum()), l))
        held = np.full(n + 1, -1, np.int64)
        held[s[keep | same]] = e[keep | same]
    g_s = np.concatenate(starts) if starts else np.zeros(0, np.int64)
    g_e = np.concatenate(ends) if ends else np.zeros(0, np.int64)
    g_l = np.concatenate(levels) if levels else np.zeros(0, np.int64)
    # rows: a group goes before its first item, coarser groups first
    n_g = len(g_s)
    key_pos = np.r_[np.arange(n), g_s]
    key_lev = np.r_[np.full(n, top + 1), g_l]
    rows = np.lexsort((key_lev, key_pos))  # row r: sorted item rows[r] (< n) or group
    where = np.empty(n + n_g, np.int64)
    where[rows] = np.arange(n + n_g)
    # a group spans from its row to the row after its last item
    g_span = where[g_e - 1] + 1 - where[n:]
    take = np.where(rows < n, order[np.minimum(rows, n - 1)], -1) if n else rows
    g_rows = rows[rows >= n] - n  # the groups in row order
    g_lo, g_hi = _group_boxes(np.asarray(lo)[order], np.asarray(hi)[order], g_s, g_e)
    count = np.bincount(root, minlength=m) + np.bincount(root_s[g_s], minlength=m)
    first = np.cumsum(count) - count
    return (take, g_l[g_rows], g_lo[g_rows], g_hi[g_rows], g_span[g_rows], first, count)


# the most levels whose child codes (3 bits each with the deeper-item mark) one int64 holds
_KEY_LEVELS = 20


def _depth_first(root, level, i0, j0, orient):
    """``(order, differs, top)``: the items in depth-first order (by patch, then from the
    top of the tree down by child code, a node's own items, the larger pieces that a ray
    hits first, before its subtrees: code + 4 where the item lies deeper); ``differs(l)``
    (n - 1,) bool: whether each item in that order and the one before differ in their codes
    of levels 1 .. l; ``top`` the deepest level. Sub-squares of at most ``_KEY_LEVELS``
    levels sort by one key, their codes read from the bits of ``i0``, ``j0`` (the code at
    level t of a square of level l is bit l - t of each), level 1 highest: the order of
    the codes' columns (:func:`child_codes`) sorted one by one, in two sorts instead of one
    per level (the chess pieces' 312,676 items, 9 levels)."""
    level = np.asarray(level, np.int64)
    top = int(level.max(initial=0))
    if orient is None and top <= _KEY_LEVELS:
        i, j = np.asarray(i0, np.int64), np.asarray(j0, np.int64)
        key = np.zeros(len(level), np.int64)
        for t in range(1, top + 1):
            below = level - t  # (the item's bit at level t; < 0: the item is above t)
            at = np.maximum(below, 0)
            code = ((i >> at) & 1) + 2 * ((j >> at) & 1) + 4 * (below > 0)
            key = (key << 3) | np.where(below >= 0, code, 0)
        order = np.lexsort((key, root))
        key = key[order]
        return order, lambda l: (key[1:] >> 3 * (top - l)) != (key[:-1] >> 3 * (top - l)), top
    codes = child_codes(level, i0, j0, orient)
    top = codes.shape[1] - 1
    codes = codes + 4 * (level[:, None] > np.arange(top + 1)).astype(np.int8)
    order = np.lexsort(tuple(codes[:, l] for l in range(top, 0, -1)) + (root,))
    codes = codes[order]
    return order, lambda l: codes[1:, l] != codes[:-1, l], top


def _group_boxes(lo, hi, s, e):
    """The boxes of the sorted items' ranges [s, e) (s < e)."""
    if not len(s):
        return np.zeros((0, 3)), np.zeros((0, 3))
    lo = np.concatenate([lo, lo[-1:]])  # (reduceat's last range needs a row past it)
    hi = np.concatenate([hi, hi[-1:]])
    idx = np.ravel(np.column_stack([s, e]))
    return np.minimum.reduceat(lo, idx)[::2], np.maximum.reduceat(hi, idx)[::2]
