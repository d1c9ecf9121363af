"""Snapped sides of Catmull-Clark patches: a side sampled more coarsely than the patch's grid.

Both sides of an edge sample it alike (design invariant 4, ``criterion.edge_sampling``).
Where a patch beside the edge keeps cells of exact limit points at its depth (they cannot
fan: their sides have no points but their corners), the edge is sampled at the coarsest such
patch's depth, and every patch finer than that *snaps* its side there: the vertices of its
grid on the side are moved onto the coarse polyline, the linear interpolation of the two
coarse samples around each. (Raising the cell-bearing patches to their finest neighbour's
depth instead carried the deepest depth of a crease along the whole crease: on the chess
pieces of ``benchmarks/cycles.py``, 776 of 2,823 irregular patches ended at depth 7, most
needing 3 to 4.) The coarse patch's depth meets the tolerance over its own shell, which
holds the edge, so its polyline does too.

A snapped side's samples are the patch's own limit points at the coarse parameters, taken
when it is built from the item with an edge there (a piece's net, a cell's corner:
:func:`snap_items`) and kept in the pool's sample store: ``2^de + 1`` per side (``de``
its sampling depth), in increasing u (sides 0, 2) or v (sides 1, 3), the slot's ``snap``
(4,) the first row of each side's (-1: not snapped). An item snaps its side ``k`` where
``sides[item, k] < `` its grid depth (only patch sides are sampled more coarsely than an
item's grid: ``isolate.item_sides``); its vertices there come from :func:`snapped_point`,
one function for every item of the patch, so the vertex is the same number in each. The
snapped points lie on the chords between samples, maybe outside the box of the net of the
node that holds them: a node touching a snapped side has its box widened by the samples of
the coarse segments it spans and its slab opened (:func:`widen_node`), an item's box
likewise (:func:`snap_items`), and a cell on such a side is evaluated per ray, as a fan is
(``bezier._fan_samples``). Cells of exact limit points on a snapped side have their corners
moved onto the polyline when built.
"""

from __future__ import annotations

import numpy as np

from subtrace.patches.basis import BOX_PAD, bez_point, pad_box
from subtrace.runtime.jit import leaf_njit, llvm_inline_njit, nb


@llvm_inline_njit
def _along(gi, gj, n, k):
    """(on, t): whether vertex (gi, gj) of an ``n`` x ``n`` grid lies on side ``k`` (0: v = 0,
    1: u = 1, 2: v = 1, 3: u = 0) and its coordinate along the side (u for sides 0 and 2,
    v for 1 and 3), in grid units."""
    if k == 0:
        return gj == 0, gi
    if k == 1:
        return gi == n, gj
    if k == 2:
        return gj == n, gi
    return gi == 0, gj


@llvm_inline_njit
def snaps(sides, srow, depth):
    """Whether item ``srow`` of grid depth ``depth`` snaps any side."""
    return (sides[srow, 0] < depth or sides[srow, 1] < depth or sides[srow, 2] < depth
            or sides[srow, 3] < depth)


@leaf_njit
def snapped_point(gi, gj, depth, sides, srow, snap, samples):
    """``(on, x, y, z)``: whether vertex (gi, gj) of the depth-``depth`` grid of item
    ``srow`` lies on a side it snaps, and then its point on the coarse polyline (the first
    such side's, at a patch corner: every item takes the same)."""
    n = 1 << depth
    for k in range(4):
        de = sides[srow, k]
        if de >= depth or snap[k] < 0:
            continue
        on, t = _along(gi, gj, n, k)
        if not on:
            continue
        sh = depth - de
        m = t >> sh
        b = snap[k] + m
        rest = t - (m << sh)
        if rest == 0:
            return True, samples[b, 0], samples[b, 1], samples[b, 2]
        w = rest / (1 << sh)
        return (True, (1.0 - w) * samples[b, 0] + w * samples[b + 1, 0],
                (1.0 - w) * samples[b, 1] + w * samples[b + 1, 1],
                (1.0 - w) * samples[b, 2] + w * samples[b + 1, 2])
    return False, 0.0, 0.0, 0.0


@llvm_inline_njit
def _stretch(gi, gj, h, n, k):
    """(on, t0): whether the square of cells (gi, gj) .. (gi + h, gj + h) of an ``n`` x
    ``n`` grid has a side on side ``k``, and where it starts along it."""
    if k == 0:
        return gj == 0, gi
    if k == 1:
        return gi + h == n, gj
    if k == 2:
        return gj + h == n, gi
    return gi == 0, gj


@leaf_njit
def touches(gi, gj, h, depth, sides, srow):
    """Whether the square of cells (gi, gj) .. (gi + h, gj + h) of the depth-``depth`` grid
    of item ``srow`` has a side on a side the item snaps."""
    n = 1 << depth
    for k in range(4):
        if sides[srow, k] < depth and _stretch(gi, gj, h, n, k)[0]:
            return True
    return False


@leaf_njit
def widen_node(box, slab, m, gi, gj, h, depth, sides, srow, snap, samples):
    """Widen the box of node ``m`` (the square of cells (gi, gj) .. (gi + h, gj + h) of the
    depth-``depth`` grid of item ``srow``) by the samples of the coarse segments it spans on
    the sides it snaps, and open its slab (normal 0, range unbounded); returns whether it
    touches such a side (nothing changes otherwise)."""
    n = 1 << depth
    lo0, lo1, lo2 = box[m, 0], box[m, 1], box[m, 2]
    hi0, hi1, hi2 = box[m, 3], box[m, 4], box[m, 5]
    touched = False
    for k in range(4):
        de = sides[srow, k]
        if de >= depth or snap[k] < 0:
            continue
        on, t0 = _stretch(gi, gj, h, n, k)
        if not on:
            continue
        touched = True
        sh = depth - de
        for q in range(snap[k] + (t0 >> sh), snap[k] + ((t0 + h + (1 << sh) - 1) >> sh) + 1):
            lo0, lo1, lo2 = min(lo0, samples[q, 0]), min(lo1, samples[q, 1]), min(lo2, samples[q, 2])
            hi0, hi1, hi2 = max(hi0, samples[q, 0]), max(hi1, samples[q, 1]), max(hi2, samples[q, 2])
    if touched:
        lo0, lo1, lo2, hi0, hi1, hi2 = pad_box(lo0, lo1, lo2, hi0, hi1, hi2)
        box[m, 0], box[m, 1], box[m, 2] = lo0, lo1, lo2
        box[m, 3], box[m, 4], box[m, 5] = hi0, hi1, hi2
        slab[m, 0], slab[m, 1], slab[m, 2] = 0.0, 0.0, 0.0
        slab[m, 3], slab[m, 4] = -np.inf, np.inf
    return touched


def side_offsets(depth, side):
    """``(offset (m,4), total)``: where each snapped side's samples start (side ``k`` of
    patch ``p`` is snapped when ``side[p, k] < depth[p]``; -1 where not), side after side,
    patch after patch, ``2^side + 1`` each."""
    depth = np.asarray(depth, dtype=np.int64)
    side = np.asarray(side, dtype=np.int64).reshape(-1, 4)
    count = np.where(side < depth[:, None], np.left_shift(1, np.clip(side, 0, 62)) + 1, 0)
    flat = count.ravel()
    start = (np.cumsum(flat) - flat).reshape(count.shape)
    return np.where(count > 0, start, -1), int(flat.sum())


def snap_items(first, count, is_cell, ref, level, i0, j0, depth_i, side, nets, cells, lo, hi):
    """The samples of the snapped sides of a batch of patches (patch ``p``'s items are rows
    ``first[p] .. first[p] + count[p] - 1``: a cell (``is_cell``) or a piece, row ``ref`` of
    ``cells`` (4 corner rows each, (.,3)) or ``nets``, a dyadic square of ``level`` at
    ``i0, j0`` of grid depth ``depth_i``; the patch samples side k at ``side[p, k]`` and
    its depth is its cells' level, at least its pieces' depths). Moves the cells' corners
    on snapped sides onto the polylines (in ``cells``), sets their boxes (``lo``, ``hi``)
    to their corners' and widens the boxes of the pieces that snap by the samples of the
    segments they span. Returns ``(samples (n,3), offset (m,4))`` (-1: not snapped)."""
    patch_depth = np.zeros(len(first), np.int64)
    if len(level):
        owner = np.repeat(np.arange(len(first)), count)
        np.maximum.at(patch_depth, owner, np.maximum(depth_i, np.where(is_cell, level, 0)))
    offset, total = side_offsets(patch_depth, side)
    samples = np.empty((total, 3))
    if total:
        side = np.ascontiguousarray(side, dtype=np.int64)
        _gather(first, count, is_cell, ref, level, i0, j0, side, offset, nets, cells, samples)
        _move(first, count, is_cell, ref, level, i0, j0, depth_i, side, offset, samples, cells,
              lo, hi)
    return samples, offset


@leaf_njit
def _range(c, level, de):
    """The coarse samples (depth ``de``) on the stretch ``c .. c + 1`` of a level-``level``
    square's side: first and last (``level >= de``: at most its two ends)."""
    if level >= de:
        sh = level - de
        return (c + (1 << sh) - 1) >> sh, (c + 1) >> sh
    return c << (de - level), (c + 1) << (de - level)


@llvm_inline_njit
def _square_side(i0, j0, n, k):
    """(on, c): whether the square (i0, j0) of an ``n`` x ``n`` grid has a side on side
    ``k``, and its place along it."""
    return _stretch(i0, j0, 1, n, k)


# a cell's corner at the start and end of each of its sides, along the side's direction
_SIDE_CORNERS = np.array([[0, 1], [1, 2], [3, 2], [0, 3]], dtype=np.int64)


@nb.njit(cache=True, nogil=True)
def _gather(first, count, is_cell, ref, level, i0, j0, side, offset, nets, cells, out):
    """Fill ``out`` with the samples of every snapped side (see :func:`snap_items`)."""
    for p in range(len(first)):
        for a in range(first[p], first[p] + count[p]):
            lev = level[a]
            n = 1 << lev
            for k in range(4):
                if offset[p, k] < 0:
                    continue
                de = side[p, k]
                on, c = _square_side(i0[a], j0[a], n, k)
                if not on:
                    continue
                m0, m1 = _range(c, lev, de)
                for m in range(m0, m1 + 1):
                    s = m * 2.0 ** lev / 2.0 ** de - c  # (along the square: dyadic, exact)
                    if is_cell[a]:
                        r = 4 * ref[a] + _SIDE_CORNERS[k, 0 if s == 0.0 else 1]
                        x, y, z = cells[r, 0], cells[r, 1], cells[r, 2]
                    elif k == 0:
                        x, y, z = bez_point(nets, ref[a], s, 0.0)
                    elif k == 1:
                        x, y, z = bez_point(nets, ref[a], 1.0, s)
                    elif k == 2:
                        x, y, z = bez_point(nets, ref[a], s, 1.0)
                    else:
                        x, y, z = bez_point(nets, ref[a], 0.0, s)
                    out[offset[p, k] + m, 0] = x
                    out[offset[p, k] + m, 1] = y
                    out[offset[p, k] + m, 2] = z


@nb.njit(cache=True, nogil=True)
def _move(first, count, is_cell, ref, level, i0, j0, depth_i, side, offset, samples, cells,
          lo, hi):
    """Move the cells' corners on snapped sides onto the polylines, with their boxes, and
    widen the boxes of the pieces that snap (see :func:`snap_items`)."""
    sides = np.empty((1, 4), np.int64)
    for p in range(len(first)):
        for k in range(4):
            sides[0, k] = side[p, k]
        for a in range(first[p], first[p] + count[p]):
            lev = level[a]
            n = 1 << lev
            if is_cell[a]:
                moved = False
                for q in range(4):
                    gi = i0[a] + (1 if q == 1 or q == 2 else 0)
                    gj = j0[a] + (1 if q >= 2 else 0)
                    on, x, y, z = snapped_point(gi, gj, lev, sides, 0, offset[p], samples)
                    if on:
                        r = 4 * ref[a] + q
                        cells[r, 0], cells[r, 1], cells[r, 2] = x, y, z
                        moved = True
                if moved:
                    for d in range(3):
                        lo[a, d] = np.inf
                        hi[a, d] = -np.inf
                        for q in range(4):
                            lo[a, d] = min(lo[a, d], cells[4 * ref[a] + q, d])
                            hi[a, d] = max(hi[a, d], cells[4 * ref[a] + q, d])
                continue
            for k in range(4):
                de = side[p, k]
                if offset[p, k] < 0 or de >= depth_i[a]:
                    continue
                on, c = _square_side(i0[a], j0[a], n, k)
                if not on:
                    continue
                if lev >= de:  # (one segment: its two samples)
                    m0 = c >> (lev - de)
                    m1 = m0 + 1
                else:
                    m0, m1 = c << (de - lev), (c + 1) << (de - lev)
                for m in range(m0, m1 + 1):
                    b = offset[p, k] + m
                    pad = BOX_PAD * max(abs(samples[b, 0]), max(abs(samples[b, 1]),
                                                                abs(samples[b, 2])))
                    for d in range(3):
                        lo[a, d] = min(lo[a, d], samples[b, d] - pad)
                        hi[a, d] = max(hi[a, d], samples[b, d] + pad)
