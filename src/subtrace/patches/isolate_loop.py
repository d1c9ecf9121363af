"""Feature-adaptive isolation of irregular Loop triangles into per-ray pieces and cells.

A Loop triangle with an extraordinary vertex, a crease, a corner or an irregular boundary is
not one polynomial. :func:`build_loop_isolated` refines its neighbourhood one level at a
time with the subdivision core (every OpenSubdiv rule honoured), keeping Loop's child order
(children 0, 1, 2 at the parent's corners, the middle child 3 turned half a turn), as
:mod:`subtrace.patches.grids` and ``basis.TRI_SPLIT`` do. Children that are regular Loop
patches (``patches.boxspline.loop_regular``, regular boundaries included) become *pieces*:
their quartic triangular Bezier nets, traced per ray by ``geometry/tris.py`` like a regular patch's.
What is still irregular at the patch's grid depth ``D`` becomes *cells*: micro-triangles of
exact limit points. The refinement follows only the irregular remainder (one corner child
per level at an extraordinary vertex), so a patch costs O(D) work, not the 4^D of a grid.

Layout: a piece or cell is a dyadic sub-triangle of the root patch at level ``l``: corner
``A = (i0, j0)`` in units of ``2^-l`` of the patch's (s, t), and its other corners
``A + g (1, 0)`` and ``A + g (0, 1)`` (same units), ``g = +1`` upright, ``-1`` turned. Its
net's (s, t) are the sub-triangle's own: patch point ``(A + g (s, t)) 2^-l``.

Sides: a patch side shared with a coarser neighbour (depth ``de < D``) is *snapped* onto
that neighbour's polyline (design invariant 4), as the regular nets do. The coarse samples
may lie outside the small pieces along the side (near an extraordinary corner the pieces
shrink), so each snapped side's ``2^de + 1`` exact samples are computed once, when the patch
is built (:func:`side_samples`), and every piece and cell interpolates between them.
"""

from __future__ import annotations

import numpy as np

from subtrace.patches.basis import tri_bernstein
from subtrace.patches.boxspline import box_nets, loop_regular
from subtrace.patches.grids import cut_around
from subtrace.patches.isolate import corner_limits
from subtrace.subdiv.refine import refine_level, refine_points


def build_loop_isolated(obj, faces, depth):
    """Pieces and cells of the irregular Loop triangles ``faces`` of ``obj``'s patch level
    (the cage), isolated down to grid depth ``depth`` (a scalar, or one per face).

    Returns ``(subs, cells)``:
    ``subs`` = (root index (s,) into ``faces``, level (s,), corner i0, j0 (s,) in units of
    2^-level, orientation (s,) +1 / -1, nets (s,15,3));
    ``cells`` = (root index (c,), corner i0, j0 (c,) in units of 2^-depth, orientation (c,),
    corner points (c,3,3), corner unit normals (c,3,3), NaN where undefined), corners in the
    order A, A + g (1,0), A + g (0,1)."""
    options = obj.cage.options
    faces = np.asarray(faces, dtype=np.int64)
    depth = np.broadcast_to(np.asarray(depth, dtype=np.int64), faces.shape)
    subs = [[] for _ in range(6)]
    cells = [[] for _ in range(6)]
    cur, pts = obj.level, obj.points
    root = np.arange(len(faces))
    start = faces
    i0 = np.zeros(len(faces), np.int64)
    j0 = np.zeros(len(faces), np.int64)
    g = np.ones(len(faces), np.int64)
    k = 0
    while len(root):
        done = depth[root] <= k
        if done.any():
            # the irregular remainder at its patch's depth: exact limit points
            _add_cells(cells, cur, pts, options, start[done], root[done], i0[done], j0[done],
                       g[done])
            keep = ~done
            root, start, i0, j0, g = root[keep], start[keep], i0[keep], j0[keep], g[keep]
            if not len(root):
                break
        cut, cut_pts, first = cut_around(cur, pts, start, 1)
        ref = refine_level(cut, options)
        pts = refine_points(ref, cut_pts)
        cur = ref.child
        k += 1
        # the four children of each frontier face, in Loop's order (module doc)
        q = np.arange(4)
        kids = (4 * first[:, None] + q).ravel()
        root = np.repeat(root, 4)
        i0 = (2 * i0[:, None] + g[:, None] * ((q == 1) | (q == 3))).ravel()
        j0 = (2 * j0[:, None] + g[:, None] * ((q == 2) | (q == 3))).ravel()
        g = (g[:, None] * np.where(q == 3, -1, 1)).ravel()
        reg = loop_regular(cur, options, kids)
        if reg.any():
            for lst, a in zip(subs, (root[reg], np.full(int(reg.sum()), k), i0[reg], j0[reg],
                                     g[reg], box_nets(cur, pts, kids[reg]))):
                lst.append(a)
        irr = ~reg
        root, start, i0, j0, g = root[irr], kids[irr], i0[irr], j0[irr], g[irr]
    z = np.zeros(0, np.int64)
    out_subs = (tuple(np.concatenate(a) for a in subs) if subs[0]
                else (z, z, z, z, z, np.zeros((0, 15, 3))))
    out_cells = (tuple(np.concatenate(a) for a in cells) if cells[0]
                 else (z, z, z, z, np.zeros((0, 3, 3)), np.zeros((0, 3, 3))))
    return out_subs, out_cells


def _add_cells(cells, level, points, options, faces, root, i0, j0, g):
    """Append the triangles ``faces`` of ``level`` as cells (exact limit points and unit
    normals of their corners) to the lists ``cells``."""
    _, P, nrm = corner_limits(level, points, options, faces, 3)
    for lst, a in zip(cells, (root, i0, j0, g, P, nrm)):
        lst.append(a)


def corner_coords(level, i0, j0, g, depth):
    """(n,3,2) int64 root grid coordinates (units of 2^-depth) of the corners of the
    sub-triangles (level, i0, j0, g) (module doc)."""
    h = np.left_shift(1, depth - level)
    a = np.stack([i0 * h, j0 * h], axis=1)
    step = (g * h)[:, None]
    return np.stack([a, a + step * [1, 0], a + step * [0, 1]], axis=1)


def _side_position(c, N, k):
    """Whether the root grid vertices ``c`` (..., 2) lie on side ``k`` (0: j = 0, 1:
    i + j = N, 2: i = 0, each from its corner k to corner k + 1) and their position along
    it (as ``geometry.tris``)."""
    i, j = c[..., 0], c[..., 1]
    if k == 0:
        return j == 0, i
    if k == 1:
        return i + j == N, j
    return i == 0, N - j


def _side_vertex(t, N, k):
    """(n,2) grid vertex at positions ``t`` along side ``k``."""
    if k == 0:
        return np.stack([t, np.zeros_like(t)], axis=1)
    if k == 1:
        return np.stack([N - t, t], axis=1)
    return np.stack([np.zeros_like(t), N - t], axis=1)


def side_samples(depth, side_depth, subs, cells):
    """Exact samples of the snapped sides of patches isolated to grid depths ``depth`` (m,):
    patch ``r``'s side ``k`` is snapped when ``0 <= side_depth[r, k] < depth[r]``; its
    ``2^de + 1`` samples (positions ``0, 2^(depth-de), ..., 2^depth`` along it) come from the
    piece or cell with an edge on the side there (a piece's net, a cell's corner).

    Returns ``(samples (n,3), offset (m,))``: patch r's samples start at ``offset[r]``
    (-1: none), side after side (snapped ones only). The cells' corners on snapped sides are
    moved onto the polylines in place (``cells[4]``; a corner on two snapped sides by the
    first, as ``geometry.tris.grid_point``)."""
    depth = np.asarray(depth, dtype=np.int64)
    croot, ci, cj, cg, cP = cells[0], cells[1], cells[2], cells[3], cells[4]
    sroot, slev, si, sj, sg, nets = subs
    iroot = np.r_[sroot, croot]
    idep = depth[iroot]
    lev = np.r_[slev, idep[len(sroot):]]
    corners = corner_coords(lev, np.r_[si, ci], np.r_[sj, cj], np.r_[sg, cg], idep)
    ccell = corners[len(sroot):]
    N = np.left_shift(1, idep)[:, None]  # per item, against its corners
    upright = np.r_[sg, cg] > 0
    snapped = (side_depth >= 0) & (side_depth < depth[:, None])
    count = np.where(snapped, np.left_shift(1, np.clip(side_depth, 0, None)) + 1, 0)
    per_patch = count.sum(axis=1)
    offset = np.where(per_patch > 0, np.cumsum(per_patch) - per_patch, -1)
    before = np.cumsum(count, axis=1) - count  # (m,3) first sample of each side
    samples = np.empty((int(per_patch.sum()), 3))
    span = int(np.left_shift(1, depth.max(initial=0))) + 1
    for k in range(3):
        rows = np.nonzero(snapped[:, k])[0]
        if not len(rows):
            continue
        # the items with an edge on side k: upright, corners k and k+1 on it
        on, t = _side_position(corners, N, k)
        edge = np.nonzero(upright & on[:, k] & on[:, (k + 1) % 3])[0]
        key = iroot[edge] * span + t[edge, k]
        order = np.argsort(key, kind="stable")
        edge, key = edge[order], key[order]
        # the queries: every sample of the side of every patch snapped there
        de = side_depth[rows, k]
        n_q = np.left_shift(1, de) + 1
        qrow = np.repeat(rows, n_q)
        qm = np.arange(int(n_q.sum())) - np.repeat(np.cumsum(n_q) - n_q, n_q)
        qt = qm << (depth[qrow] - np.repeat(de, n_q))
        at = edge[np.searchsorted(key, qrow * span + qt, side="right") - 1]
        vert = _side_vertex(qt, np.left_shift(1, depth[qrow]), k)
        pts = np.empty((len(qt), 3))
        piece = at < len(sroot)
        if piece.any():
            a = at[piece]
            h = np.left_shift(1, idep[a] - lev[a]).astype(np.float64)
            st = (vert[piece] - corners[a, 0]) / h[:, None]  # (upright: g = 1)
            pts[piece] = np.einsum("nb,nbc->nc", tri_bernstein(st), nets[a])
        if (~piece).any():
            c = at[~piece] - len(sroot)
            which = np.argmax(np.all(ccell[c] == vert[~piece][:, None], axis=2), axis=1)
            pts[~piece] = cP[c, which]
        samples[offset[qrow] + before[qrow, k] + qm] = pts
    # the cells' corners on snapped sides, onto the polylines (the first side that has one)
    moved = np.zeros(ccell.shape[:2], bool)
    Nc = N[len(sroot):]
    for k in range(3):
        de = side_depth[croot, k]
        on, t = _side_position(ccell, Nc, k)
        move = on & ~moved & ((de >= 0) & (de < depth[croot]))[:, None]
        c, v = np.nonzero(move)
        if not len(c):
            continue
        moved |= move
        r = np.left_shift(1, depth[croot[c]] - de[c])
        m0 = t[c, v] // r
        w = ((t[c, v] - m0 * r) / r)[:, None]
        m1 = np.where(w[:, 0] > 0, m0 + 1, m0)
        base = offset[croot[c]] + before[croot[c], k]
        cP[c, v] = (1.0 - w) * samples[base + m0] + w * samples[base + m1]
    return samples, offset


def sample_ranges(subs, cells, depth, side_depth, offset, samples):
    """(items, 3) lo and hi: per item (the pieces, then the cells), the box of the samples
    whose polyline segments its vertices on snapped sides may be moved onto (+inf / -inf
    where it has none): its box must contain them, since the descent enters the nodes
    touching a snapped side without testing their own boxes (``geometry/tris.py``)."""
    depth = np.asarray(depth, dtype=np.int64)
    sroot, slev, si, sj, sg, _ = subs
    croot, ci, cj, cg = cells[:4]
    iroot = np.r_[sroot, croot]
    idep = depth[iroot]
    corners = corner_coords(np.r_[slev, idep[len(sroot):]], np.r_[si, ci], np.r_[sj, cj],
                            np.r_[sg, cg], idep)
    N = np.left_shift(1, idep)[:, None]
    lo = np.full((len(iroot), 3), np.inf)
    hi = np.full((len(iroot), 3), -np.inf)
    snapped = (side_depth >= 0) & (side_depth < depth[:, None])
    count = np.where(snapped, np.left_shift(1, np.clip(side_depth, 0, None)) + 1, 0)
    before = np.cumsum(count, axis=1) - count
    for k in range(3):
        de = side_depth[iroot, k]
        on, t = _side_position(corners, N, k)
        use = np.nonzero(on.any(axis=1) & (de >= 0) & (de < idep))[0]
        if not len(use):
            continue
        r = np.left_shift(1, idep[use] - de[use])
        tu = np.where(on[use], t[use], -1)
        t_hi = tu.max(axis=1)
        t_lo = np.where(on[use], t[use], t_hi[:, None]).min(axis=1)
        m0, m1 = t_lo // r, -(-t_hi // r)
        base = offset[iroot[use]] + before[iroot[use], k]
        # the samples m0 .. m1 of each: min / max over their (contiguous) runs
        # the samples m0 .. m1 of each (runs padded with their last sample)
        idx = np.minimum((base + m0)[:, None] + np.arange(int((m1 - m0).max()) + 1),
                         (base + m1)[:, None])
        run = samples[idx]
        lo[use] = np.minimum(lo[use], run.min(axis=1))
        hi[use] = np.maximum(hi[use], run.max(axis=1))
    return lo, hi
