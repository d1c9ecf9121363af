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

from subtrace.runtime.jit import nb

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
    level = np.asarray(level, np.int64)
    top = int(level.max(initial=0))
    if orient is None and top <= _KEY_LEVELS and m <= 1 << (62 - 3 * top):
        # (sub-squares: their keys, order and splits in one kernel, 10 ms less on the
        # chess pieces' largest build of 86,773 items than in NumPy)
        order, split = _square_order(root, level, np.asarray(i0, np.int64),
                                     np.asarray(j0, np.int64), top)
    else:
        order, differs, top = _depth_first(root, level, i0, j0, orient)
        split = _splits(root[order], differs, top)
    root_s = root[order]
    rows, g_level, g_lo, g_hi, g_span, g_root = _layout_kernel(
        split, top, np.ascontiguousarray(np.asarray(lo, np.float64)[order]),
        np.ascontiguousarray(np.asarray(hi, np.float64)[order]), MIN_GROUP)
    take = np.where(rows >= 0, order[np.maximum(rows, 0)], -1) if n else rows
    count = np.bincount(root, minlength=m) + np.bincount(root_s[g_root], minlength=m)
    first = np.cumsum(count) - count
    return take, g_level, g_lo, g_hi, g_span, first, count


@nb.njit(cache=True, nogil=True)
def _layout_kernel(split, top, lo, hi, min_group):
    """:func:`grouped_layout`'s rows of items in depth-first order (``split`` there; boxes
    ``lo``, ``hi`` in that order): ``(rows, g_level, g_lo, g_hi, g_span, g_first)``, row r
    holding sorted item ``rows[r]`` or, where it is -1, the next group (in row order: its
    level, box, span and first sorted item). The level-l subtrees are the runs of items
    without a split at or below l; one is kept as a group with at least ``min_group`` items
    (2 for a whole patch) unless it has the items of the parent level's subtree that was
    kept or had a kept one's items (a chain keeps its coarsest group). A laminar family of
    distinct sets of two or more items: fewer groups than items. A group row goes before
    its first item, coarser groups first. (In NumPy, level by level, this took 42 ms of the
    chess pieces' 6 builds, 92,000 items.)"""
    n = len(split)
    g_s = np.empty(max(n, 1), np.int64)
    g_e = np.empty(max(n, 1), np.int64)
    g_l = np.empty(max(n, 1), np.int64)
    n_g = 0
    held_end = np.full(n + 1, -1, np.int64)  # the end of the subtree from s kept or held
    held_level = np.full(n + 1, -2, np.int64)  # at this level
    for l in range(top + 1):
        s = 0
        while s < n:
            e = s + 1
            while e < n and split[e] > l:
                e += 1
            same = held_level[s] == l - 1 and held_end[s] == e
            keep = e - s >= (2 if l == 0 else min_group) and not same
            if keep:
                g_s[n_g], g_e[n_g], g_l[n_g] = s, e, l
                n_g += 1
            if keep or same:
                held_end[s], held_level[s] = e, l
            s = e
    # groups by first item, coarser first (made level by level: a stable bucket order)
    at_start = np.zeros(n + 1, np.int64)
    for g in range(n_g):
        at_start[g_s[g] + 1] += 1
    before = np.cumsum(at_start)  # groups that start before item s
    slot = before[:-1].copy()
    by_row = np.empty(n_g, np.int64)
    for g in range(n_g):
        by_row[slot[g_s[g]]] = g
        slot[g_s[g]] += 1
    rows = np.empty(n + n_g, np.int64)
    item_row = np.empty(n, np.int64)
    r = 0
    k = 0
    for s in range(n):
        while k < n_g and g_s[by_row[k]] == s:
            rows[r] = -1
            r += 1
            k += 1
        rows[r] = s
        item_row[s] = r
        r += 1
    g_level = np.empty(n_g, np.int64)
    g_span = np.empty(n_g, np.int64)
    g_first = np.empty(n_g, np.int64)
    g_lo = np.empty((n_g, 3))
    g_hi = np.empty((n_g, 3))
    for k in range(n_g):
        g = by_row[k]
        s, e = g_s[g], g_e[g]
        g_level[k], g_first[k] = g_l[g], s
        # (its row: after the items before its first and the groups before it)
        g_span[k] = item_row[e - 1] + 1 - (s + k)
        for c in range(3):
            a, b = lo[s, c], hi[s, c]
            for t in range(s + 1, e):
                a = min(a, lo[t, c])
                b = max(b, hi[t, c])
            g_lo[k, c], g_hi[k, c] = a, b
    return rows, g_level, g_lo, g_hi, g_span, g_first


# the most levels whose child codes (3 bits each with the deeper-item mark) one int64 holds
_KEY_LEVELS = 20


def _splits(root_s, differs, top):
    """(n,) int64: for each item in depth-first order, the first level at which its subtree
    is not the item's before it (0: another patch; top + 1: none; codes 1 .. l differ from
    some l on: that l), from ``differs`` (:func:`_depth_first`)."""
    n = len(root_s)
    split = np.zeros(n, np.int64)
    if n > 1:
        same = root_s[1:] == root_s[:-1]
        tail = np.where(same, top + 1, 0)
        for l in range(top, 0, -1):
            tail[same & differs(l)] = l
        split[1:] = tail
    return split


@nb.njit(cache=True, nogil=True)
def _square_order(root, level, i0, j0, top):
    """:func:`_depth_first`'s order of sub-squares and :func:`_splits` of it: one key per
    item, its patch above its codes (3 bits a level, level 1 highest: the child code, plus
    4 where the item lies deeper), sorted stably."""
    n = len(root)
    key = np.empty(n, np.int64)
    for r in range(n):
        k = root[r]
        for t in range(1, top + 1):
            below = level[r] - t
            code = 0
            if below >= 0:
                code = ((i0[r] >> below) & 1) + 2 * ((j0[r] >> below) & 1)
                if below > 0:
                    code += 4
            k = (k << 3) | code
        key[r] = k
    order = np.argsort(key, kind="mergesort")
    split = np.zeros(n, np.int64)
    for r in range(1, n):
        a, b = key[order[r - 1]], key[order[r]]
        if (a >> (3 * top)) != (b >> (3 * top)):
            continue  # (another patch: 0)
        split[r] = top + 1
        for t in range(1, top + 1):
            shift = 3 * (top - t)
            if (a >> shift) != (b >> shift):
                split[r] = t
                break
    return order, split


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
