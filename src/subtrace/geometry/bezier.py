"""Ray / regular-patch intersection by per-ray refinement of the Bezier net (nothing stored).

A regular patch is one bicubic Bezier patch (``patches/bspline.py``), with a grid depth ``d``
from the angular criterion. A ray that enters its shell descends the patch's quadtree: each
node is the net of a dyadic sub-square (de Casteljau halving in u and v), tested by the box of
its net, which contains the sub-patch (convex hull of the Bernstein basis); only the children
whose boxes the ray enters are split further, nearest first, until depth ``d``. That is the
refinement criterion per ray: a sub-patch is refined while its angular size is above the
tolerance (its depth is below ``d``) and the ray hits its shell.

A leaf is the grid cell ``(i, j)`` of the depth-``d`` grid. Its corners are limit points
evaluated from the patch's net at the dyadic parameters ``(i/N, j/N)`` by one function
(:func:`_bez_point`), so every cell of the patch computes a shared corner bit-identically.
A cell on a side whose neighbour samples the shared edge more finely (``side_depth`` > d)
also evaluates those samples and is cut into a fan around its centre, so both patches have
the same points on the edge (no T-junction). The cell's points lie on the surface of the
cell, inside its box; boxes are widened by a relative ``BOX_PAD`` for rounding. A side
sampled more coarsely (beside cells of exact limit points, which cannot fan) is snapped: its
vertices are moved onto the coarse polyline, and the nodes touching it widened
(``geometry/snap.py``).

The module holds the Catmull-Clark kinds of ``geometry.kinds``: Bezier pieces (a regular
patch, or a piece of an isolated one) and cells of exact limit points (two triangles of
their corners; their shading normal, :func:`cell_normal`), and :func:`intersect_patch`,
the walk over one patch's items (group rows skipped whole), which hands the Loop kinds to
``geometry/tris.py``.
"""

from __future__ import annotations

import numpy as np

from subtrace import config
from subtrace.accel.bvh import box_entry, four_entries, slab_entry
from subtrace.runtime.jit import inline_njit, leaf_njit, llvm_inline_njit
from subtrace.patches.basis import (
    bez_across as _bez_across, bez_point as _bez_point, bez_rows as _bez_rows,
    copy_net as _copy_net, net_box as _net_box, quadrant as _quadrant, split_net as _split,
)
from subtrace.geometry.prims import (
    H_B1, H_B2, H_LEAF, H_SLOT, H_T, H_TRI, M_CELLS, M_FULL, M_NETS, M_NODES, NOT_YET,
    new_node, push_sorted, ray_triangle, unit_or_cross,
)
from subtrace.geometry.kinds import CELL, GROUP, LOOP_CELL, TRI
from subtrace.geometry.snap import snapped_point, snaps, touches as _touches_snapped, widen_node
from subtrace.geometry.tris import intersect_tri, intersect_tri_cell, slab_cut_entry

# samples per cell side at most (2^(side depth - depth)): neighbours are kept within
# config.FAN_LEVELS of each other (patches/criterion.py: edge_sampling, trace/pools.py)
MAX_SIDE_SAMPLES = 1 << config.FAN_LEVELS


@leaf_njit
def _corner_params(lp, gi, gj, inv):
    """Root parameters of the four corners of grid cell (gi, gj) of spacing ``inv`` into
    ``lp[:4]`` (corner order (0,0), (1,0), (1,1), (0,1))."""
    for k in range(4):
        lp[k, 0] = (gi + (1 if k == 1 or k == 2 else 0)) * inv
        lp[k, 1] = (gj + (1 if k >= 2 else 0)) * inv


@leaf_njit
def _net_entry(ox, oy, oz, ix, iy, iz, net, s, tmax):
    """Entry distance of the ray into the (padded) box of net ``net[s]``; inf on a miss."""
    lo0, lo1, lo2, hi0, hi1, hi2 = _net_box(net, s)
    return slab_entry(ox, oy, oz, ix, iy, iz, lo0, lo1, lo2, hi0, hi1, hi2, 0.0, tmax)


SLAB_PAD = 1e-11  # a cell's slab is widened by this much of its net's largest coordinate


@leaf_njit
def _cell_slab(net, s, slab, m):
    """The slab of a cell's Bezier net ``net[s]`` into ``slab[m]``: the normal ``n`` of its
    corners' diagonals and the range of ``n . P`` over its 16 points, widened for rounding.
    The cell's surface, its corners and fan samples (evaluated from its patch's net: equal to
    the net's points to rounding) lie in the convex hull of the net, so between the planes."""
    ax = net[s, 3, 3, 0] - net[s, 0, 0, 0]
    ay = net[s, 3, 3, 1] - net[s, 0, 0, 1]
    az = net[s, 3, 3, 2] - net[s, 0, 0, 2]
    bx = net[s, 0, 3, 0] - net[s, 3, 0, 0]
    by = net[s, 0, 3, 1] - net[s, 3, 0, 1]
    bz = net[s, 0, 3, 2] - net[s, 3, 0, 2]
    nx, ny, nz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    lo = np.inf
    hi = -np.inf
    big = 0.0
    for a in range(4):
        for c in range(4):
            x, y, z = net[s, a, c, 0], net[s, a, c, 1], net[s, a, c, 2]
            d = nx * x + ny * y + nz * z
            lo = min(lo, d)
            hi = max(hi, d)
            big = max(big, max(abs(x), max(abs(y), abs(z))))
    pad = SLAB_PAD * (abs(nx) + abs(ny) + abs(nz)) * big
    slab[m, 0], slab[m, 1], slab[m, 2] = nx, ny, nz
    slab[m, 3], slab[m, 4] = lo - pad, hi + pad


# What places a ray among a block's cells (:func:`_block_cells`) is the block's *frame*: its
# four corners (exact points of the surface) and a bound ``delta`` on how far, in any
# coordinate, its surface leaves their bilinear interpolant (:func:`_interpolation_bound`).
# The frames of a node's four blocks are made when the node is split: the 3 x 3 corners of
# its children (its grid at 0, 1/2, 1) and one bound, kept in the cell store, three units
# (corner (a, b) in row a + 3 b, delta in row 9); the node's data then points to them. A
# root that is a block has its net's corners and the bound in its slab row.
FRAME_UNITS = 3
# a block's data: the first unit of its corner rows in the cell store, shifted left by
# BLOCK_FLAGS, over flags: bits 0 .. 2 set once row b of its 3 x 3 corners is stored, bits
# 3 .. 6 once cell q has been tested (its triangles counted), or NOT_YET
BLOCK_FLAGS = 7
LOCATE_PAD = 1e-11  # widens delta by this much of the coordinates' magnitude (rounding)


@leaf_njit
def _interpolation_bound(net, s, side):
    """A bound, in every coordinate, on the distance between the patch of net ``net[s]``
    and the bilinear interpolant of its corners over any square of side ``side`` (1: the
    whole patch) of its parameters, widened by ``LOCATE_PAD`` of the net's largest
    coordinate.

    Bilinear interpolation is linear interpolation in u, then in v, so over an a x b
    rectangle it errs by at most ``(a^2 max|S_uu| + b^2 max|S_vv|) / 8``; a bicubic Bezier
    patch's ``S_uu`` is 6 times a convex combination of its net's second differences in u
    (``S_vv`` likewise). The corners a cell's triangles use are evaluated from the piece's
    own net (:func:`_store_row`), equal to the surface's to rounding, which the widening
    covers."""
    dev = 0.0
    big = 0.0
    for k in range(3):
        muu = 0.0
        mvv = 0.0
        for i in range(4):
            for j in range(4):
                big = max(big, abs(net[s, i, j, k]))
                if i < 2:
                    muu = max(muu, abs(net[s, i + 2, j, k] - 2.0 * net[s, i + 1, j, k]
                                       + net[s, i, j, k]))
                if j < 2:
                    mvv = max(mvv, abs(net[s, i, j + 2, k] - 2.0 * net[s, i, j + 1, k]
                                       + net[s, i, j, k]))
        dev = max(dev, 6.0 * (muu + mvv) * side * side / 8.0)
    return dev + LOCATE_PAD * big


@leaf_njit
def _store_frame(net, s, children, c0, m_cells, cnt):
    """The frames of the four blocks of net ``net[s]`` (split into ``children[c0 .. c0 +
    3]``) into three new units of the cell store: the 3 x 3 corners of the children, then
    the bound of :func:`_interpolation_bound` over a quarter. Returns its first row."""
    r = 4 * cnt[M_CELLS]
    cnt[M_CELLS] += FRAME_UNITS
    for b in range(3):
        for a in range(3):
            q = (1 if a == 2 else 0) + (2 if b == 2 else 0)  # a child with that corner
            i = 0 if a == 0 else 3
            j = 0 if b == 0 else 3
            m_cells[r + a + 3 * b, 0] = children[c0 + q, i, j, 0]
            m_cells[r + a + 3 * b, 1] = children[c0 + q, i, j, 1]
            m_cells[r + a + 3 * b, 2] = children[c0 + q, i, j, 2]
    m_cells[r + 9, 0] = _interpolation_bound(net, s, 0.5)
    return r


@llvm_inline_njit
def _block_cells(px, py, pz, kx, ky, kz, sx, sy, c00, c10, c01, c11, dlt):
    """Which of the four cells of a block the ray may hit: a mask, bit ``a + 2 b`` for cell
    (a, b) (half a in u, b in v). The block's frame: its corners ``c00, c10, c01, c11``
    (3-tuples at (u, v) = (0, 0), (1, 0), (0, 1), (1, 1)) and bound ``dlt`` (widened for
    the ray's origin ``px, py, pz``, its (kx, ky, kz) coordinates).

    In the ray's sheared frame (that of ``prims.ray_triangle``: the ray is the origin of the
    (X, Y) plane) a cell's triangles have their corners within ``dlt`` (per coordinate:
    ``dlt (1 + |s|)`` after the shear) of the interpolant ``L`` at points of the cell, so
    within that of the hull of ``L``'s projections at the cell's corners, which are
    averages of the block's. A ray that a direction separates from that widened hull
    cannot hit them."""
    pad_x = dlt * (1.0 + abs(sx))
    pad_y = dlt * (1.0 + abs(sy))
    z = c00[kz] - pz
    a0, e0 = c00[kx] - px - sx * z, c00[ky] - py - sy * z
    z = c10[kz] - pz
    a2, e2 = c10[kx] - px - sx * z, c10[ky] - py - sy * z
    z = c01[kz] - pz
    c0, g0 = c01[kx] - px - sx * z, c01[ky] - py - sy * z
    z = c11[kz] - pz
    c2, g2 = c11[kx] - px - sx * z, c11[ky] - py - sy * z
    # the interpolant at the block's 3 x 3 grid, projected: rows a (v = 0), b, c (v = 1)
    a1, e1 = 0.5 * (a0 + a2), 0.5 * (e0 + e2)
    c1, g1 = 0.5 * (c0 + c2), 0.5 * (g0 + g2)
    b0, f0 = 0.5 * (a0 + c0), 0.5 * (e0 + g0)
    b2, f2 = 0.5 * (a2 + c2), 0.5 * (e2 + g2)
    b1, f1 = 0.5 * (b0 + b2), 0.5 * (f0 + f2)
    # a cell's points lie in the hull of its projected corners, widened: the ray misses
    # them if some direction n separates 0 from it (max of n . corners + |n_x| pad_x +
    # |n_y| pad_y below 0). The directions: across the frame's u and v sides (a cell of a
    # parallelogram frame is then tested exactly), and the axes
    ux, uy = 0.5 * (a2 - a0 + c2 - c0), 0.5 * (e2 - e0 + g2 - g0)
    vx, vy = 0.5 * (c0 - a0 + c2 - a2), 0.5 * (g0 - e0 + g2 - e2)
    nx, ny = -uy, ux  # across u: sorts by v
    mx, my = -vy, vx  # across v: sorts by u
    pad_n = abs(nx) * pad_x + abs(ny) * pad_y
    pad_m = abs(mx) * pad_x + abs(my) * pad_y
    # the grid's 3 x 3 values, row by row (v), in each of the four directions
    X = (a0, a1, a2, b0, b1, b2, c0, c1, c2)
    Y = (e0, e1, e2, f0, f1, f2, g0, g1, g2)
    N = (nx * a0 + ny * e0, nx * a1 + ny * e1, nx * a2 + ny * e2,
         nx * b0 + ny * f0, nx * b1 + ny * f1, nx * b2 + ny * f2,
         nx * c0 + ny * g0, nx * c1 + ny * g1, nx * c2 + ny * g2)
    M = (mx * a0 + my * e0, mx * a1 + my * e1, mx * a2 + my * e2,
         mx * b0 + my * f0, mx * b1 + my * f1, mx * b2 + my * f2,
         mx * c0 + my * g0, mx * c1 + my * g1, mx * c2 + my * g2)
    mask = 0
    for q in range(4):
        g = (q & 1) + 3 * (q >> 1)  # the cell's corners: g, g + 1, g + 3, g + 4
        if (_spans(N[g], N[g + 1], N[g + 3], N[g + 4], pad_n)
                and _spans(M[g], M[g + 1], M[g + 3], M[g + 4], pad_m)
                and _spans(X[g], X[g + 1], X[g + 3], X[g + 4], pad_x)
                and _spans(Y[g], Y[g + 1], Y[g + 3], Y[g + 4], pad_y)):
            mask |= 1 << q
    return mask


@llvm_inline_njit
def _spans(a, b, c, d, pad):
    """Whether [min, max] of the four values, widened by ``pad``, holds 0."""
    return min(min(a, b), min(c, d)) <= pad and max(max(a, b), max(c, d)) >= -pad


# An any-hit ray (a shadow or occlusion ray) needs only to know that it meets the surface
# before its end, not where: a node of a piece's quadtree whose frame (corners and bound, as
# for _block_cells) certainly holds a triangle the ray meets ends its descent there, before
# the node's cells are made (:func:`_covers`). On the default picture (Spot, key and fill
# lights, ground shadows) nine tenths of the blocked shadow rays were decided so within two
# levels of the piece they met, instead of at its cells four to eight levels down.
COVER_MARGIN = 1e-9  # relative: the rounding of the t range and of the edge tests, with room


@llvm_inline_njit
def _covers(px, py, pz, kx, ky, kz, sx, sy, sz, c00, c10, c01, c11, dlt, lo_z, hi_z, thi):
    """Whether the ray certainly meets the micro-triangles of a node before ``thi``: the
    node's frame (its corners ``c00, c10, c01, c11`` and bound ``dlt``, widened for the
    origin, as :func:`_block_cells` takes them) and the range [lo_z, hi_z] of its box in the
    ray's kz coordinate. Returns the nearest distance along the ray of the node's box (a
    distance no farther than the triangle it meets), or inf when that is not certain.

    Why: the node's triangles form a disc whose boundary (samples of its four sides, a
    piecewise linear curve) lies within ``dlt`` per coordinate of the frame's edges at the
    same parameters, so within the pads of :func:`_block_cells` after the ray's shear. When
    the ray's point (the origin of the sheared plane) lies strictly on the same side of all
    four projected edges, farther from each than the pads reach, the straight homotopy
    from the boundary to the frame never passes over it: the boundary winds once around
    it, so the triangles' signed covers of it add up to one and some triangle covers it;
    the watertight triangle test (``prims.ray_triangle``: shared edges' functions computed
    alike) then finds that hit. Every point of the node lies in its box, so the hit's
    distance lies in the box's range along the ray, which must lie within (0, ``thi``)."""
    # the box's distances along the ray: all ahead of the origin and before thi
    ta = (lo_z - pz) * sz
    tb = (hi_z - pz) * sz
    t0, t1 = min(ta, tb), max(ta, tb)
    if not (t0 > COVER_MARGIN * t1 and t1 * (1.0 + COVER_MARGIN) < thi):
        return np.inf
    pad_x = dlt * (1.0 + abs(sx))
    pad_y = dlt * (1.0 + abs(sy))
    pad2 = pad_x * pad_x + pad_y * pad_y
    z = c00[kz] - pz
    x0, y0 = c00[kx] - px - sx * z, c00[ky] - py - sy * z
    z = c10[kz] - pz
    x1, y1 = c10[kx] - px - sx * z, c10[ky] - py - sy * z
    z = c11[kz] - pz
    x2, y2 = c11[kx] - px - sx * z, c11[ky] - py - sy * z
    z = c01[kz] - pz
    x3, y3 = c01[kx] - px - sx * z, c01[ky] - py - sy * z
    # the four edges (0,0) -> (1,0) -> (1,1) -> (0,1) -> (0,0), each seen on one side
    e0 = _edge_side(x0, y0, x1, y1, pad2)
    if e0 == 0:
        return np.inf
    if (_edge_side(x1, y1, x2, y2, pad2) == e0 and _edge_side(x2, y2, x3, y3, pad2) == e0
            and _edge_side(x3, y3, x0, y0, pad2) == e0):
        return t0
    return np.inf


@llvm_inline_njit
def _edge_side(ax, ay, bx, by, pad2):
    """The side (1 or -1) of the sheared plane's origin from the edge a -> b when it lies
    farther than ``sqrt(pad2)`` from the edge's line (its cross product's rounding
    taken off), else 0."""
    e = ax * by - ay * bx
    m = abs(e) - COVER_MARGIN * (abs(ax * by) + abs(ay * bx))
    if not m > 0.0:
        return 0
    dx, dy = bx - ax, by - ay
    if m * m > (dx * dx + dy * dy) * pad2 * (1.0 + COVER_MARGIN):
        return 1 if e > 0.0 else -1
    return 0


@llvm_inline_njit
def _net_corners(net, s):
    """The corners of net ``net[s]`` at (u, v) = (0, 0), (1, 0), (0, 1), (1, 1): points of
    its patch."""
    return ((net[s, 0, 0, 0], net[s, 0, 0, 1], net[s, 0, 0, 2]),
            (net[s, 3, 0, 0], net[s, 3, 0, 1], net[s, 3, 0, 2]),
            (net[s, 0, 3, 0], net[s, 0, 3, 1], net[s, 0, 3, 2]),
            (net[s, 3, 3, 0], net[s, 3, 3, 1], net[s, 3, 3, 2]))


@llvm_inline_njit
def _frame_corners(m_cells, f, step):
    """The corners, as :func:`_net_corners`, of a frame in a node's 3 x 3 corners of the
    cell store (``_store_frame``) from row ``f``: a block's (``step`` 1: rows f, f + 1,
    f + 3, f + 4) or the node's own (``f`` its first row, ``step`` 2)."""
    a, b, c = f + step, f + 3 * step, f + 4 * step
    return ((m_cells[f, 0], m_cells[f, 1], m_cells[f, 2]),
            (m_cells[a, 0], m_cells[a, 1], m_cells[a, 2]),
            (m_cells[b, 0], m_cells[b, 1], m_cells[b, 2]),
            (m_cells[c, 0], m_cells[c, 1], m_cells[c, 2]))


@llvm_inline_njit
def _occluded(hit, t, code, item, depth, u, v):
    """Record an occluder certainly met (:func:`_covers`): at distance ``t`` no farther
    than the triangle, on ``item`` of grid depth ``depth``, at the centre ``(u, v)`` of the
    node in its patch's parameters."""
    hit[H_T] = t
    hit[H_SLOT] = code
    hit[H_LEAF] = depth
    hit[H_TRI] = item
    hit[H_B1] = u
    hit[H_B2] = v


@llvm_inline_njit
def _cell_entry(ox, oy, oz, ix, iy, iz, dx, dy, dz, box, slab, c, tmax):
    """Entry distance of the ray into the box of cell node ``c`` cut by its slab; inf when
    the ray misses either before ``tmax`` (``tris.slab_cut_entry``, as Loop nodes are cut)."""
    return slab_cut_entry(ox, oy, oz, ix, iy, iz, dx, dy, dz, box[c, 0], box[c, 1], box[c, 2],
                          box[c, 3], box[c, 4], box[c, 5], slab[c, 0], slab[c, 1], slab[c, 2],
                          slab[c, 3], slab[c, 4], tmax)


@leaf_njit
def _fan_samples(i, j, depth, root_depth, sides, srow):
    """Whether cell (i, j) of a piece's depth-``depth`` grid (``root_depth`` in the patch's
    units) lies on a side of the piece sampled otherwise than its grid (``sides[srow]``):
    more finely (the piece beside it is finer: the cell is cut into a fan) or more coarsely
    (a snapped side, ``geometry/snap.py``: its corners there are moved onto the polyline)."""
    N = 1 << depth
    return ((j == 0 and sides[srow, 0] != root_depth)
            or (i == N - 1 and sides[srow, 1] != root_depth)
            or (j == N - 1 and sides[srow, 2] != root_depth)
            or (i == 0 and sides[srow, 3] != root_depth))


@leaf_njit
def _snapped_cells(ci, cj, pd, root_depth, sides, srow):
    """The mask (bit ``a + 2 b``) of the cells (2 ci + a, 2 cj + b) of a block of a piece's
    depth-``pd`` grid that lie on a side it snaps (``sides[srow, k] < root_depth``): their
    triangles may leave the block's frame, so every ray that enters the block tests them."""
    N = 1 << pd
    mask = 0
    for q in range(4):
        i = 2 * ci + (q & 1)
        j = 2 * cj + (q >> 1)
        if ((j == 0 and sides[srow, 0] < root_depth)
                or (i == N - 1 and sides[srow, 1] < root_depth)
                or (j == N - 1 and sides[srow, 2] < root_depth)
                or (i == 0 and sides[srow, 3] < root_depth)):
            mask |= 1 << q
    return mask


@leaf_njit
def _leaf(ox, oy, oz, kx, ky, kz, sx, sy, sz, nets, nk, i, j, depth, oi, oj, root_depth,
          sides, srow, slack, hit, code, item, lv, lp, snap, samples):
    """Intersect cell (i, j) of the depth-``depth`` grid of Bezier net ``nets[nk]``, which
    covers the cells from (oi, oj) of its root patch's depth-``root_depth`` grid; update
    ``hit`` (H_SLOT = ``code``, H_TRI = ``item``, (H_B1, H_B2) = root parameter). ``lv``
    (K,3) / ``lp`` (K,2): scratch for the cell's points and root parameters. Its corners on
    a side the piece snaps are the polyline's (``snap``, ``samples``: ``geometry/snap.py``).
    Returns the number of triangles tested."""
    N = 1 << depth
    inv = 1.0 / N
    rinv = 1.0 / (1 << root_depth)
    gi = oi + i
    gj = oj + j
    snapping = snaps(sides, srow, root_depth)
    n = 0
    for corner in range(4):
        di = 1 if corner == 1 or corner == 2 else 0
        dj = 1 if corner >= 2 else 0
        on = False
        if snapping:
            on, x, y, z = snapped_point(gi + di, gj + dj, root_depth, sides, srow, snap,
                                        samples)
        if not on:
            x, y, z = _bez_point(nets, nk, (i + di) * inv, (j + dj) * inv)
        lv[n, 0], lv[n, 1], lv[n, 2] = x, y, z
        lp[n, 0], lp[n, 1] = (gi + di) * rinv, (gj + dj) * rinv
        n += 1
        # samples of the side that starts at this corner, when the piece beside is finer
        side = corner
        if side == 0:
            on_side = j == 0
        elif side == 1:
            on_side = i == N - 1
        elif side == 2:
            on_side = j == N - 1
        else:
            on_side = i == 0
        if on_side and sides[srow, side] > root_depth:
            r = 1 << (sides[srow, side] - root_depth)
            for k in range(1, r):
                f = k / r
                if side == 0:
                    a, b = i + f, j
                    ga, gb = gi + f, gj
                elif side == 1:
                    a, b = i + 1, j + f
                    ga, gb = gi + 1, gj + f
                elif side == 2:
                    a, b = i + 1 - f, j + 1
                    ga, gb = gi + 1 - f, gj + 1
                else:
                    a, b = i, j + 1 - f
                    ga, gb = gi, gj + 1 - f
                x, y, z = _bez_point(nets, nk, a * inv, b * inv)
                lv[n, 0], lv[n, 1], lv[n, 2] = x, y, z
                lp[n, 0], lp[n, 1] = ga * rinv, gb * rinv
                n += 1
    if n == 4:
        return tri_pair(ox, oy, oz, kx, ky, kz, sx, sy, sz, lv, 0, 1, 2, 3, lp, slack, hit, code,
                        item, root_depth)
    # a fan around the cell's centre
    x, y, z = _bez_point(nets, nk, (i + 0.5) * inv, (j + 0.5) * inv)
    lv[n, 0], lv[n, 1], lv[n, 2] = x, y, z
    lp[n, 0], lp[n, 1] = (gi + 0.5) * rinv, (gj + 0.5) * rinv
    o = (ox, oy, oz)
    px, py, pz = o[kx], o[ky], o[kz]
    for k in range(n):
        b = k
        c = k + 1 if k + 1 < n else 0
        t, ba, bb, bc = ray_triangle(px, py, pz, kx, ky, kz, sx, sy, sz, n, b, c, lv, hit[H_T],
                                     slack)
        if t < hit[H_T]:
            _record(hit, t, code, item, root_depth, lp, n, b, c, ba, bb, bc)
    return n


@leaf_njit
def _record(hit, t, code, item, depth, lp, a, b, c, ba, bb, bc):
    hit[H_T] = t
    hit[H_SLOT] = code
    hit[H_LEAF] = depth
    hit[H_TRI] = item
    hit[H_B1] = ba * lp[a, 0] + bb * lp[b, 0] + bc * lp[c, 0]
    hit[H_B2] = ba * lp[a, 1] + bb * lp[b, 1] + bc * lp[c, 1]


@llvm_inline_njit
def tri_pair(ox, oy, oz, kx, ky, kz, sx, sy, sz, lv, v0, v1, v2, v3, lp, slack, hit, code, item,
             depth):
    """The two triangles (0,1,2), (0,2,3) of the cell whose corners are the rows v0, v1,
    v2, v3 of ``lv`` (root parameters ``lp[:4]``)."""
    o = (ox, oy, oz)
    px, py, pz = o[kx], o[ky], o[kz]
    for tri in range(2):
        b = 1 + tri
        c = 2 + tri
        t, ba, bb, bc = ray_triangle(px, py, pz, kx, ky, kz, sx, sy, sz, v0, v2 if tri else v1,
                                     v3 if tri else v2, lv, hit[H_T], slack)
        if t < hit[H_T]:
            _record(hit, t, code, item, depth, lp, 0, b, c, ba, bb, bc)
    return 2


@leaf_njit
def _descend(ox, oy, oz, ix, iy, iz, kx, ky, kz, sx, sy, sz, src, s, lev0, ci0, cj0, nets, nk,
             depth, oi, oj, root_depth, sides, srow, slack, hit, code, item, work, st, st_t,
             st0, tmp_t, order, lv, lp, snap, samples):
    """Closest hit on the sub-patch ``src[s]`` (cell (ci0, cj0) of level ``lev0`` of the
    Bezier patch ``nets[nk]``) refined down to level ``depth``, splitting per ray and storing
    nothing. ``work`` (>= 3*depth+7, 4,4,3) holds the stacked nets (the last six are
    scratch), rows ``st0 ..`` of ``st`` their cell coordinates and levels (columns 2, 3, 4)
    and of ``st_t`` their entry distances. A child on a side the piece snaps is entered
    untested (its snapped points may leave its net's box). Returns the number of triangles
    tested."""
    snapping = snaps(sides, srow, root_depth)
    tested = 0
    _copy_net(work, 0, src, s)
    st[st0, 2] = ci0
    st[st0, 3] = cj0
    st[st0, 4] = lev0
    st_t[st0] = 0.0
    sp = 1
    base = work.shape[0] - 4  # the last four entries receive children before sorting
    while sp > 0:
        sp -= 1
        if st_t[st0 + sp] >= hit[H_T]:  # a nearer hit was found since it was pushed
            continue
        ci, cj, lev = st[st0 + sp, 2], st[st0 + sp, 3], st[st0 + sp, 4]
        if lev == depth:
            tested += _leaf(ox, oy, oz, kx, ky, kz, sx, sy, sz, nets, nk, ci, cj, depth, oi, oj,
                            root_depth, sides, srow, slack, hit, code, item, lv, lp, snap,
                            samples)
            continue
        _split(work, sp, work, base)
        # the children the ray enters, pushed far to near
        n = 0
        h = 1 << (depth - lev - 1)
        for q in range(4):
            if snapping and _touches_snapped(oi + (2 * ci + (q & 1)) * h,
                                             oj + (2 * cj + (q >> 1)) * h, h, root_depth,
                                             sides, srow):
                te = st_t[st0 + sp]
            else:
                te = _net_entry(ox, oy, oz, ix, iy, iz, work, base + q, hit[H_T])
            if te < np.inf:
                n = push_sorted(tmp_t, order, n, te, q)
        for e in range(n):
            q = order[e]
            _copy_net(work, sp, work, base + q)
            st[st0 + sp, 2] = 2 * ci + (q & 1)
            st[st0 + sp, 3] = 2 * cj + (q >> 1)
            st[st0 + sp, 4] = lev + 1
            st_t[st0 + sp] = tmp_t[e]
            sp += 1
    return tested


# --------------------------------------------------------------------------------------
# the per-thread memo of split nets
# --------------------------------------------------------------------------------------
#
# Rays of neighbouring pixels descend the same nodes of a patch's quadtree. A thread keeps
# what its rays split: ``mem`` = (root node of each item (I,) or -1, first of the four
# children of each node (N,) or -1, each node's padded box (N,6), a block's slab (N,6): a
# normal and the range of the normal coordinate of its net (see :func:`_cell_slab`; for
# any-hit rays every node's; column 5 a node's own bound, :func:`_covers`), each
# node's row (N,) in the net store (an inner node whose children are split in turn), in
# the cell store (a node whose children are blocks: their frames; a block: its corners and
# flags, ``BLOCK_FLAGS``), or -1 (not yet), the net store (.,4,4,3), the cell store ((.,3),
# in units of 4 rows), counts (4,): nodes, nets and cell units used, and a flag set when a
# store ran out (the descent then goes on without storing; the driver grows the stores for
# the next round)).
#
# The quadtree stops one level above the cells: a node of level pd - 1 is a *block* of 2 x
# 2 cells, never split. A ray that enters a block's box and slab is placed among its cells
# by the block's frame (:func:`_block_cells`: the hull of its corners, widened by how far
# the surface leaves their bilinear interpolant): it tests the triangles of the cells it
# may hit, not the block's eight, and a cell's corners are evaluated (from the piece's own
# net, as :func:`_leaf` does: a row of three at a time, stored) when a ray first tests it.
# That is what a micro-triangle costs and what is counted: two per cell a thread tested
# (Spot at 1280x720 and 1 px: 2.8 a covered pixel, against 10.8 when every ray that
# entered a block evaluated and tested all eight, at the same trace time). A cell whose
# side is sampled more finely (a fan) is evaluated per ray. Splitting a block into four
# cells with boxes and slabs cost more than testing the four cells' triangles (the trace
# of Spot, 0.100 -> 0.082 s). Everything is made lazily: a node's box when its parent is
# split, its net (or its blocks' frames) when it is split itself, a row of a block's
# corners when a ray first tests a cell of it; so what is stored is what the thread's
# rays needed.

COUNTED = -3  # an item root: a one-cell piece (evaluated per ray) whose triangles counted


@leaf_njit
def _store_net(m_nets, cnt, src, s):
    r = cnt[M_NETS]
    cnt[M_NETS] = r + 1
    _copy_net(m_nets, r, src, s)
    return r


@leaf_njit
def _store_row(m_cells, r, nets, nk, bi, bj, b, depth):
    """Store row ``b`` (0 .. 2, in v) of the 3 x 3 corners of the four cells (2 bi + a,
    2 bj + b), a, b in {0, 1}, of the depth-``depth`` grid of ``nets[nk]`` (evaluated from
    the patch's own net, as :func:`_leaf` does: a corner is the same number in every cell
    that has it): corner (a, b) at row ``r + a + 3 b`` of the cell store (a block takes
    three units of four rows)."""
    inv = 1.0 / (1 << depth)
    rows = _bez_rows(nets, nk, (2 * bj + b) * inv)  # (shared by the three points)
    for a in range(3):
        x, y, z = _bez_across(rows, (2 * bi + a) * inv)
        m_cells[r + a + 3 * b, 0] = x
        m_cells[r + a + 3 * b, 1] = y
        m_cells[r + a + 3 * b, 2] = z


@leaf_njit
def _expand(node, parent, ci, cj, lev, pd, child, box, slab, data, m_nets, m_cells, cnt, work,
            bound, fr, sides, srow, snap, samples):
    """Split ``node`` (cell (ci, cj) of level ``lev`` < pd - 1 of a piece of depth ``pd``):
    get its net (stored, or the quadrant of its parent's) and create its four children with
    their boxes (and slabs, for blocks: level pd - 1); its net is kept if its children will
    be split in turn, else its blocks' frames (:func:`_store_frame`). ``bound``: keep the
    node's own :func:`_interpolation_bound` in its slab row (an inner node has no slab;
    any-hit rays test its frame, :func:`_covers`). ``fr`` = (oi, oj, root_depth, snapping):
    the piece's place in its patch's grid and whether it snaps a side; a child touching
    one gets the box and slab of :func:`~subtrace.geometry.snap.widen_node`. Returns the first
    child, or -1 when a store is full."""
    if (cnt[M_NODES] + 4 > len(child) or cnt[M_NETS] + 1 > len(m_nets)
            or cnt[M_CELLS] + FRAME_UNITS > len(m_cells) // 4):
        cnt[M_FULL] = 1
        return -1
    base = work.shape[0] - 4
    src, s = m_nets, data[node]
    if s < 0:
        _quadrant(m_nets, data[parent], ci & 1, cj & 1, work, 0)
        if lev + 2 < pd:
            data[node] = s = _store_net(m_nets, cnt, work, 0)
        else:  # its children are blocks: their corners come from the piece's own net
            src, s = work, 0
    if bound:
        slab[node, 5] = _interpolation_bound(src, s, 1.0)
    _split(src, s, work, base)
    if lev + 2 == pd:  # (its net is not needed again: its data holds the frames)
        data[node] = _store_frame(src, s, work, base, m_cells, cnt)
    first = cnt[M_NODES]
    oi, oj, root_depth, snapping = fr
    h = 1 << (pd - lev - 1)
    for q in range(4):
        lo0, lo1, lo2, hi0, hi1, hi2 = _net_box(work, base + q)
        m = new_node(child, box, data, cnt, lo0, lo1, lo2, hi0, hi1, hi2, NOT_YET)
        if lev + 2 == pd or bound:  # a block (or an any-hit ray's node): its slab too
            _cell_slab(work, base + q, slab, m)
        if snapping:
            widen_node(box, slab, m, oi + (2 * ci + (q & 1)) * h, oj + (2 * cj + (q >> 1)) * h,
                       h, root_depth, sides, srow, snap, samples)
    child[node] = first
    return first


@leaf_njit
def cell_normal(pts, nrm, a, b):
    """Bilinear blend of a cell's exact corner normals at (a, b) in [0,1]^2 (corner order
    (0,0), (1,0), (1,1), (0,1)); the cell's own normal where a corner's is undefined."""
    w0, w1, w2, w3 = (1 - a) * (1 - b), a * (1 - b), a * b, (1 - a) * b
    nx = w0 * nrm[0, 0] + w1 * nrm[1, 0] + w2 * nrm[2, 0] + w3 * nrm[3, 0]
    ny = w0 * nrm[0, 1] + w1 * nrm[1, 1] + w2 * nrm[2, 1] + w3 * nrm[3, 1]
    nz = w0 * nrm[0, 2] + w1 * nrm[1, 2] + w2 * nrm[2, 2] + w3 * nrm[3, 2]
    return unit_or_cross(nx, ny, nz, pts, 0, 2, 1, 3)  # (the diagonals' cross product)


def loop_flag(schemes) -> bool | None:
    """The ``loop`` argument of :func:`intersect_patch` for a render of cages of these
    ``schemes`` ("catmark" or "loop"): None when none is Loop, else True."""
    return None if all(s == "catmark" for s in schemes) else True


def table_loop_flag(table) -> bool | None:
    """:func:`loop_flag` of the cages of a patch table (``patches.table.PatchTable``)."""
    return loop_flag(o.cage.scheme for o in table.objects)


# intersect_patch (about 120 lines) is not split: it is inlined into the trace kernel once
# (see kernels._trace_task), and its quadtree descent keeps the ray, the stack and the memo
# in locals that helpers would have to take and return at every node.
@inline_njit
def intersect_patch(ray, p, s, iso, mem, slack, hit, scratch, loop, stop):
    """Closest hit on the pieces of Catmull-Clark patch ``p`` (slot ``s`` of ``iso``, a
    :class:`~subtrace.trace.pools.PieceArrays`) nearer than hit[H_T]; updates ``hit``. Returns the
    number of micro-triangles built: those of the cells this ray was the first of its
    thread to test (stored in the memo ``mem``, or fans and one-cell pieces, evaluated on
    the spot by every ray but counted once), and any it split on the spot when the memo was
    full. ``ray`` = (ox, oy, oz, ix, iy, iz, kx, ky, kz,
    sx, sy, sz, dx, dy, dz): origin, inverse direction, shear constants and direction.

    A Bezier piece (item ``it``; a regular patch is one) is refined to its own grid depth
    (``item_depth``, in the patch's units): the ray descends its quadtree, nearest child
    first, into the nodes whose boxes it enters before its best hit; a node is split (its
    children's boxes stored) once per thread, and a cell's corners are evaluated once, when
    a ray may hit the cell (see the memo above). ``work`` (>= 3*depth+10, 4,4,3), the stack ``st`` (>= 6*depth+8, 5) with entry distances ``st_t``,
    ``tmp_t`` / ``order`` (4,) and ``lv`` (K,3) / ``lp`` (K,2) (a cell's points and
    parameters) are the thread's ``scratch``. (Calls with more than 30 arguments are
    compiled by Python as calls with ``*args``, which Numba cannot inline: hence the
    bundles.)

    ``loop``: None when no patch of the render is a Loop triangle (:func:`loop_flag`): the
    kernel that inlines this is then compiled without the Loop items' descents (Numba
    prunes a branch on an argument that is None before typing it), about half of its
    compile; True otherwise.

    ``stop``: -inf for the closest hit; an any-hit ray's end (its tmax): it returns at the
    first hit nearer than that, and at the first node of a piece that certainly holds one
    (:func:`_covers`; ``hit`` then holds the node's nearest distance, not the triangle's).
    The memo's nodes then keep their own bound (slab column 0) for that test.
    """
    ox, oy, oz, ix, iy, iz, kx, ky, kz, sx, sy, sz, dx, dy, dz = ray
    work, st, st_t, tmp_t, order, lv, lp = scratch
    root_m, child, box, slab, data, m_nets, m_cells, cnt = mem
    item_depth, item_side, kind, ref, level = iso.depth_i, iso.side, iso.kind, iso.ref, iso.level
    i0, j0, lo, hi = iso.i0, iso.j0, iso.lo, iso.hi
    nets, cells = iso.nets, iso.cells
    first, count = iso.first[s], iso.count[s]
    snap, samples = iso.snap[s], iso.samples  # (the slot's snapped sides: geometry/snap.py)
    code = -2.0 - p
    tested = 0
    # (for _block_cells: the origin's coordinates in the ray's frame, and its rounding)
    o = (ox, oy, oz)
    px, py, pz = o[kx], o[ky], o[kz]
    pad_o = LOCATE_PAD * max(abs(ox), max(abs(oy), abs(oz)))
    nxt, end = first, first + count
    while nxt < end:  # the rows depth first; a group missed is skipped whole
        if hit[H_T] < stop:  # an any-hit ray's occluder
            return tested
        it = nxt
        nxt = it + 1
        if box_entry(ox, oy, oz, ix, iy, iz, lo, hi, it, 0.0, hit[H_T]) == np.inf:
            if kind[it] == GROUP:
                nxt = it + ref[it]
            continue
        if kind[it] == GROUP:  # entered: its rows follow
            continue
        depth = item_depth[it]  # its grid, in the patch's units
        inv = 1.0 / (1 << depth)
        if kind[it] == TRI:  # a Loop patch or piece: its triangular net (geometry/tris.py)
            if loop is not None:
                sh = depth - level[it]
                fr = (np.int64(iso.orient[it]), i0[it] << sh, j0[it] << sh, sh)
                tested += intersect_tri(ray, it, iso.tri_nets, ref[it], depth, fr, item_side,
                                        iso.samples, slack, hit, code, mem, scratch)
            continue
        if kind[it] == LOOP_CELL:  # an isolated Loop patch's cell (counted when built)
            if loop is not None:
                intersect_tri_cell(ray, cells, ref[it], i0[it], j0[it],
                                   np.int64(iso.orient[it]), depth, slack, hit, code, it)
            continue
        if kind[it] == CELL:  # an irregular cell: its exact corners
            c = ref[it]
            _corner_params(lp, i0[it], j0[it], inv)
            tri_pair(ox, oy, oz, kx, ky, kz, sx, sy, sz, cells, 4 * c, 4 * c + 1, 4 * c + 2,
                     4 * c + 3, lp, slack, hit, code, it, depth)  # (counted when built)
            continue
        nk = ref[it]
        pd = depth - level[it]  # the piece's own grid depth
        oi = i0[it] << pd
        oj = j0[it] << pd
        snapping = snaps(item_side, it, depth)
        node = root_m[it]
        if node < 0:
            if pd == 0:  # a one-cell piece: its cell (counted once per thread)
                n_t = _leaf(ox, oy, oz, kx, ky, kz, sx, sy, sz, nets, nk, 0, 0, 0, oi, oj, depth,
                            item_side, it, slack, hit, code, it, lv, lp, snap, samples)
                if node == NOT_YET:
                    tested += n_t
                    root_m[it] = COUNTED
                continue
            if cnt[M_NODES] + 1 > len(child) or cnt[M_NETS] + 1 > len(m_nets):
                cnt[M_FULL] = 1
                zero = np.int64(0)  # (literal arguments would compile another _descend)
                tested += _descend(ox, oy, oz, ix, iy, iz, kx, ky, kz, sx, sy, sz, nets, nk,
                                   zero, zero, zero, nets, nk, pd, oi, oj, depth, item_side, it,
                                   slack, hit, code, it, work, st, st_t, zero, tmp_t, order, lv,
                                   lp, snap, samples)
                continue
            lo0, lo1, lo2, hi0, hi1, hi2 = _net_box(nets, nk)
            # (a root that is a block keeps no net: its corners come from nets[nk])
            node = new_node(child, box, data, cnt, lo0, lo1, lo2, hi0, hi1, hi2,
                             _store_net(m_nets, cnt, nets, nk) if pd > 1 else NOT_YET)
            if pd == 1 or stop > -np.inf:  # (a block's frame: its net's corners and this
                slab[node, 5] = _interpolation_bound(nets, nk, 1.0)  # bound)
            if stop > -np.inf:  # (an any-hit ray's nodes are cut by their slabs)
                _cell_slab(nets, nk, slab, node)
            if snapping:
                widen_node(box, slab, node, oi, oj, 1 << pd, depth, item_side, it, snap, samples)
            root_m[it] = node
        if stop > -np.inf and _cell_entry(ox, oy, oz, ix, iy, iz, dx, dy, dz, box, slab, node,
                                          hit[H_T]) == np.inf:
            continue
        # stack rows: node, parent, i, j, level; st_t: entry distance when pushed
        st[0, 0], st[0, 1], st[0, 2], st[0, 3], st[0, 4] = node, -1, 0, 0, 0
        st_t[0] = 0.0
        sp = 1
        while sp > 0:
            sp -= 1
            if st_t[sp] >= hit[H_T]:  # a nearer hit was found since it was pushed
                continue
            node, parent, ci, cj, lev = st[sp, 0], st[sp, 1], st[sp, 2], st[sp, 3], st[sp, 4]
            if lev == pd - 1:  # a block of 2 x 2 cells: the triangles of those near the ray
                # its frame: a root's own (its net's corners, its slab row), or from its
                # parent's split (kept in the cell store)
                if lev == 0:
                    dlt = slab[node, 5]
                    c00 = (nets[nk, 0, 0, 0], nets[nk, 0, 0, 1], nets[nk, 0, 0, 2])
                    c10 = (nets[nk, 3, 0, 0], nets[nk, 3, 0, 1], nets[nk, 3, 0, 2])
                    c01 = (nets[nk, 0, 3, 0], nets[nk, 0, 3, 1], nets[nk, 0, 3, 2])
                    c11 = (nets[nk, 3, 3, 0], nets[nk, 3, 3, 1], nets[nk, 3, 3, 2])
                else:
                    f = data[parent] + (ci & 1) + 3 * (cj & 1)
                    dlt = m_cells[data[parent] + 9, 0]
                    c00 = (m_cells[f, 0], m_cells[f, 1], m_cells[f, 2])
                    c10 = (m_cells[f + 1, 0], m_cells[f + 1, 1], m_cells[f + 1, 2])
                    c01 = (m_cells[f + 3, 0], m_cells[f + 3, 1], m_cells[f + 3, 2])
                    c11 = (m_cells[f + 4, 0], m_cells[f + 4, 1], m_cells[f + 4, 2])
                # (not a block on a snapped side: its triangles there are not its surface's,
                # and a shadow ray leaving them may cross the surface without meeting them)
                if stop > -np.inf and not (snapping and _touches_snapped(
                        oi + 2 * ci, oj + 2 * cj, 2, depth, item_side, it)):
                    te = _covers(px, py, pz, kx, ky, kz, sx, sy, sz, c00, c10, c01, c11,
                                 dlt + pad_o, box[node, kz], box[node, 3 + kz], hit[H_T])
                    if te < np.inf:
                        _occluded(hit, te, code, it, depth, (oi + 2 * ci + 1.0) * inv,
                                  (oj + 2 * cj + 1.0) * inv)
                        return tested
                near = _block_cells(px, py, pz, kx, ky, kz, sx, sy, c00, c10, c01, c11,
                                    dlt + pad_o)
                if snapping:
                    near |= _snapped_cells(ci, cj, pd, depth, item_side, it)
                if near == 0:
                    continue
                d = data[node]
                if d == NOT_YET:  # its corner rows, filled as its cells are first tested
                    if cnt[M_CELLS] + 3 <= len(m_cells) // 4:
                        d = cnt[M_CELLS] << BLOCK_FLAGS
                        cnt[M_CELLS] += 3
                    else:
                        cnt[M_FULL] = 1
                r = 4 * (d >> BLOCK_FLAGS)
                for q in range(4):
                    if not (near >> q) & 1:
                        continue
                    a, b = q & 1, q >> 1
                    gi, gj = 2 * ci + a, 2 * cj + b
                    if d < 0 or _fan_samples(gi, gj, pd, depth, item_side, it):
                        # evaluated on the spot (a fan's triangles count once per thread)
                        n_t = _leaf(ox, oy, oz, kx, ky, kz, sx, sy, sz, nets, nk, gi, gj, pd,
                                    oi, oj, depth, item_side, it, slack, hit, code, it, lv, lp,
                                    snap, samples)
                    else:
                        for row in range(b, b + 2):
                            if not (d >> row) & 1:
                                _store_row(m_cells, r, nets, nk, ci, cj, row, pd)
                                d |= 1 << row
                        _corner_params(lp, oi + gi, oj + gj, inv)
                        v = r + a + 3 * b
                        n_t = tri_pair(ox, oy, oz, kx, ky, kz, sx, sy, sz, m_cells, v, v + 1,
                                       v + 4, v + 3, lp, slack, hit, code, it, depth)
                    if d < 0:  # (not stored: counted by every ray)
                        tested += n_t
                    elif not (d >> (3 + q)) & 1:
                        tested += n_t
                        d |= 1 << (3 + q)
                    if hit[H_T] < stop:  # an any-hit ray's occluder
                        break
                if d >= 0:
                    data[node] = d
                if hit[H_T] < stop:
                    return tested
                continue
            c = child[node]
            if c < 0:
                c = _expand(node, parent, ci, cj, lev, pd, child, box, slab, data, m_nets,
                            m_cells, cnt, work, stop > -np.inf, (oi, oj, depth, snapping),
                            item_side, it, snap, samples)
                if c < 0:  # a store is full: split per ray below this node
                    tested += _descend_node(ox, oy, oz, ix, iy, iz, kx, ky, kz, sx, sy, sz, node,
                                            parent, lev, ci, cj, nets, nk, pd, oi, oj, depth,
                                            item_side, it, slack, hit, code, it, mem, work, st,
                                            st_t, sp + 1, tmp_t, order, lv, lp, snap, samples)
                    if hit[H_T] < stop:
                        return tested
                    continue
            hs = 1 << (pd - lev)  # (the node's side, in its grid's cells)
            if stop > -np.inf and not (snapping and _touches_snapped(
                    oi + ci * hs, oj + cj * hs, hs, depth, item_side, it)):
                # the node's own frame: its net's corners, or its 3 x 3's
                if lev == 0:
                    c00, c10, c01, c11 = _net_corners(nets, nk)
                elif lev + 2 < pd:
                    c00, c10, c01, c11 = _net_corners(m_nets, data[node])
                else:
                    c00, c10, c01, c11 = _frame_corners(m_cells, data[node], 2)
                te = _covers(px, py, pz, kx, ky, kz, sx, sy, sz, c00, c10, c01, c11,
                             slab[node, 5] + pad_o, box[node, kz], box[node, 3 + kz], hit[H_T])
                if te < np.inf:
                    half = 1 << (pd - lev - 1)  # (the node's centre, in its grid's cells)
                    _occluded(hit, te, code, it, depth, (oi + (2 * ci + 1) * half) * inv,
                              (oj + (2 * cj + 1) * half) * inv)
                    return tested
            # the children the ray enters, pushed far to near (blocks, and any-hit rays'
            # nodes: box and slab)
            n = 0
            if lev + 2 == pd or stop > -np.inf:
                for q in range(4):
                    te = _cell_entry(ox, oy, oz, ix, iy, iz, dx, dy, dz, box, slab, c + q,
                                     hit[H_T])
                    if te < np.inf:
                        n = push_sorted(tmp_t, order, n, te, q)
            else:
                e = four_entries(ox, oy, oz, ix, iy, iz, box, c, hit[H_T])
                for q in range(4):
                    if e[q] < np.inf:
                        n = push_sorted(tmp_t, order, n, e[q], q)
            for e in range(n):
                q = order[e]
                st[sp, 0], st[sp, 1], st[sp, 4] = c + q, node, lev + 1
                st[sp, 2], st[sp, 3] = 2 * ci + (q & 1), 2 * cj + (q >> 1)
                st_t[sp] = tmp_t[e]
                sp += 1
    return tested


@leaf_njit
def _descend_node(ox, oy, oz, ix, iy, iz, kx, ky, kz, sx, sy, sz, node, parent, lev, ci, cj,
                  nets, nk, pd, oi, oj, depth, sides, srow, slack, hit, code, it, mem, work, st,
                  st_t, st0, tmp_t, order, lv, lp, snap, samples):
    """:func:`_descend` below memo node ``node`` (whose net may not be stored: then the
    quadrant of its parent's)."""
    root_m, child, box, slab, data, m_nets, m_cells, cnt = mem
    if data[node] >= 0:
        return _descend(ox, oy, oz, ix, iy, iz, kx, ky, kz, sx, sy, sz, m_nets, data[node], lev,
                        ci, cj, nets, nk, pd, oi, oj, depth, sides, srow, slack, hit, code, it,
                        work, st, st_t, st0, tmp_t, order, lv, lp, snap, samples)
    _quadrant(m_nets, data[parent], ci & 1, cj & 1, work, 1)  # (row 0 is _descend's)
    return _descend(ox, oy, oz, ix, iy, iz, kx, ky, kz, sx, sy, sz, work, np.int64(1), lev, ci,
                    cj, nets, nk, pd, oi, oj, depth, sides, srow, slack, hit, code, it, work, st,
                    st_t, st0, tmp_t, order, lv, lp, snap, samples)
