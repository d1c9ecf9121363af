"""Ray / Loop-patch intersection by per-ray refinement of quartic triangular Bezier nets.

A regular Loop triangle (three smooth valence-6 corners, or a regular boundary: see
``patches.boxspline.loop_regular``) is one quartic triangular Bezier net of 15 points
(``patches/basis.py``: box spline -> net, ``BOX_TO_TRI``), stored in the pieces' net store
as the first 15 of a (4,4,3) net's 16 points (item kind ``TRI``). Its grid depth ``d``
comes from the angular criterion. A ray that enters the net's box descends the patch's
1-to-4 split in Loop's child order (corner children 0, 1, 2, then the middle child turned
half a turn: ``basis.TRI_SPLIT``), entering the children whose boxes it hits, nearest first,
until level ``d``. No net is split on the way: a node is known by its three corners, exact
limit points evaluated from the item's own net, and its box is theirs grown by a bound on
how far the patch strays from the plane of its corners (below). Splitting a node evaluates
its three side midpoints; a node of level ``d - 1`` evaluates its six grid points and tests
its four cells in place, each boxed by its own micro-triangle. Each thread keeps what its
rays split in its memo (the quads' memo, ``geometry/bezier.py``: node boxes and children; a
split node's six points in the cell store, a block of 8 rows, the last two a cells'
parent's flags of cells tested), so a node is split once per thread
(:func:`intersect_tri`); a full store makes the ray split on the spot (:func:`descend_tri`,
the same boxes from the same points), which changes no hit. A cell counts as a
micro-triangle when a ray of the memo first tests it.

The box bound. Let ``P`` be the patch over a node and ``L`` the linear interpolant of its
corners. ``P - L`` is a quartic Bezier triangle whose control points ``e`` are the net's
minus ``L`` at the points ``(i, j, k) / 4``: zero at the corners, with the net's second
differences (``L`` has none). On a side, ``e`` vanishes at both ends and its second
differences are at most ``D`` (per coordinate, the net's largest pure second difference in
the three directions of its grid), so ``|e| <= 2 D`` there (``3/2 D`` at the quarter
points); an inner point is the second of a row of four whose ends are quarter points of two
sides, so ``|e| <= 3/2 D + D``. By the convex hull property ``|P - L| <= 5/2 D`` per
coordinate (``DEVIATION``; measured on random nets, the patch comes within about half of
it), and ``L`` lies in its corners' box. A child's parameter steps are half its parent's
along the same three directions, so its pure second differences are a quarter of convex
combinations of its parent's: ``D`` falls fourfold per level (:func:`_level_deviation`). A
child's box is also clipped to its parent's. The boxes are looser than the nets' own
(about 6 % more nodes entered on a Loop vase), but a split costs three point evaluations
where the four child nets cost five net splits, and the memo holds no nets. A node is also
cut by its *slab*: the planes parallel to its corners' at ``n . corners -/+ |n| . e``
(:func:`_node_slab`; the item's root by its net's points, :func:`_net_slab`), which a
ray passing by a tilted, nearly flat node leaves before it enters the box; on the vase the
slabs cut the nodes entered by 42 % and the cells tested by 24 %.

A node at level ``l`` is the sub-triangle with corners ``A, A + g (h, 0), A + g (0, h)`` of
the depth-``d`` grid (``h = 2^(d-l)``, ``g = +1`` upright, ``-1`` turned), grid vertex
``(i, j)`` at patch parameter ``(i/N, j/N)``, ``N = 2^d`` (as ``patches/grids.py``). A leaf
is the micro-triangle of its three grid vertices, each evaluated exactly from the item's
own net by one function (:func:`grid_point`), so every cell of the item computes a shared
corner bit-identically.

An irregular Loop triangle is isolated when a ray first asks for it
(``patches/isolate_loop.py``): its regular descendants are *pieces*, each one such net over
a dyadic sub-triangle of the patch (level ``l``, corner ``A``, orientation ``g``: the item's
*frame*), descended exactly as above from that node down to the patch's grid depth (every
item of a patch has the same depth, so the patch's inner edges are sampled alike from both
sides); what stays irregular at that depth is *cells* (kind ``LOOP_CELL``), micro-triangles
of exact limit points (:func:`intersect_tri_cell`).

Watertight against neighbours of other depths: a grid vertex on a patch side whose edge is
sampled more coarsely (``side`` depth < d, the shallowest patch on the edge) is snapped
onto the coarse polyline (linear interpolation of the two coarse samples around it), so the
finer side's boundary lies on the coarser side's triangles' edges. A regular patch
evaluates the coarse samples from its own net; a piece's side may be shorter than a coarse
segment, so an isolated patch keeps its snapped sides' exact samples (``samples``) and
its pieces and cells take them from there.
"""

from __future__ import annotations

import numpy as np

from subtrace.accel.bvh import slab_entry, slab_range
from subtrace.patches.basis import (
    DEGREE, N_TRI, NORMAL_STEP, NORMAL_TRIES, pad_box, tri_box, unit_normal,
)
from subtrace.runtime.jit import inline_njit, leaf_njit, llvm_inline_njit
from subtrace.geometry.prims import (
    H_B1, H_B2, H_LEAF, H_SLOT, H_T, H_TRI, M_CELLS, M_FULL, M_NODES, NOT_YET,
    new_node, push_sorted, ray_triangle, unit_or_cross,
)

COUNTED = -3  # memo root of a one-cell patch whose triangle was counted (as bezier's)
DEVIATION = 2.5  # a node's box: its corners' grown by this times its net's second differences
SLAB_PAD = 1e-11  # a node's slab is widened by this much of its corners' largest coordinate


@leaf_njit
def tri_point(net, q, s, t):
    """Point of the quartic triangular net ``net[q]`` (15 points, flat order of
    ``basis.tri_index``) at (s, t), by its Bernstein sum."""
    w = 1.0 - s - t
    pw = (1.0, w, w * w, w * w * w, w * w * w * w)
    ps = (1.0, s, s * s, s * s * s, s * s * s * s)
    pt = (1.0, t, t * t, t * t * t, t * t * t * t)
    fact = (1.0, 1.0, 2.0, 6.0, 24.0)
    x = y = z = 0.0
    p = 0
    for k in range(DEGREE + 1):
        for j in range(DEGREE + 1 - k):
            i = DEGREE - j - k
            b = 24.0 / (fact[i] * fact[j] * fact[k]) * pw[i] * ps[j] * pt[k]
            x += b * net[q, p, 0]
            y += b * net[q, p, 1]
            z += b * net[q, p, 2]
            p += 1
    return x, y, z


@leaf_njit
def _tri_index(j, k):
    return k * (DEGREE + 1) - k * (k - 1) // 2 + j


@leaf_njit
def tri_derivatives(net, q, s, t):
    """First derivatives (Ps, Pt) of the net ``net[q]`` at (s, t): degree-3 Bernstein sums
    of the net's forward differences."""
    w = 1.0 - s - t
    pw = (1.0, w, w * w, w * w * w)
    ps = (1.0, s, s * s, s * s * s)
    pt = (1.0, t, t * t, t * t * t)
    fact = (1.0, 1.0, 2.0, 6.0)
    sx = sy = sz = tx = ty = tz = 0.0
    for k in range(DEGREE):
        for j in range(DEGREE - k):
            i = DEGREE - 1 - j - k
            b = 4.0 * 6.0 / (fact[i] * fact[j] * fact[k]) * pw[i] * ps[j] * pt[k]
            p0 = _tri_index(j, k)
            p1 = _tri_index(j + 1, k)
            p2 = _tri_index(j, k + 1)
            sx += b * (net[q, p1, 0] - net[q, p0, 0])
            sy += b * (net[q, p1, 1] - net[q, p0, 1])
            sz += b * (net[q, p1, 2] - net[q, p0, 2])
            tx += b * (net[q, p2, 0] - net[q, p0, 0])
            ty += b * (net[q, p2, 1] - net[q, p0, 1])
            tz += b * (net[q, p2, 2] - net[q, p0, 2])
    return (sx, sy, sz), (tx, ty, tz)


@leaf_njit
def tri_normal(net, q, s, t):
    """Unit normal (Ps x Pt) of net ``net[q]`` at (s, t); where the derivatives' cross
    product vanishes, retaken a little way towards the triangle's centre (as
    ``basis.bez_normal``)."""
    third = 1.0 / 3.0
    nx = ny = nz = 0.0
    for _ in range(NORMAL_TRIES):
        ds, dt = tri_derivatives(net, q, s, t)
        nx, ny, nz, ok = unit_normal(ds, dt)
        if ok:
            break
        s += (third - s) * NORMAL_STEP
        t += (third - t) * NORMAL_STEP
    return nx, ny, nz


@leaf_njit
def tri_cell_normal(pts, nrm, b, c):
    """Blend of a Loop cell's exact corner normals at barycentrics (1 - b - c, b, c); the
    cell's own normal where a corner's is undefined."""
    a = 1.0 - b - c
    nx = a * nrm[0, 0] + b * nrm[1, 0] + c * nrm[2, 0]
    ny = a * nrm[0, 1] + b * nrm[1, 1] + c * nrm[2, 1]
    nz = a * nrm[0, 2] + b * nrm[1, 2] + c * nrm[2, 2]
    return unit_or_cross(nx, ny, nz, pts, 0, 1, 0, 2)


@leaf_njit
def _side_param(gi, gj, N, k):
    """Whether grid vertex (gi, gj) lies on side ``k`` (0: j = 0 from corner 0 to 1, 1:
    i + j = N from corner 1 to 2, 2: i = 0 from corner 2 to 0), and its position along it."""
    if k == 0:
        return gj == 0, gi
    if k == 1:
        return gi + gj == N, gj
    return gi == 0, N - gj


@leaf_njit
def _side_vertex(t, N, k):
    """Grid vertex at position ``t`` along side ``k``."""
    if k == 0:
        return t, 0
    if k == 1:
        return N - t, t
    return 0, N - t


@leaf_njit
def _side_base(sides, srow, depth, k):
    """First row in the side samples of side ``k``'s: row ``sides[srow, 3]`` and on, side
    after side, ``2^de + 1`` for each snapped side (``0 <= de < depth``)."""
    base = sides[srow, 3]
    for m in range(k):
        de = sides[srow, m]
        if 0 <= de < depth:
            base += (1 << de) + 1
    return base


@leaf_njit
def grid_point(net, q, gi, gj, depth, fr, sides, srow, samples):
    """Grid vertex (gi, gj) of the depth-``depth`` grid of the Loop patch of the item whose
    net is ``net[q]`` (its frame ``fr`` = (g, oi, oj, sh): the item's corner A = (oi, oj) in
    grid units, its orientation g and its own grid depth sh: the net's (s, t) are
    ``g (gi - oi, gj - oj) 2^-sh``): its exact limit point, or, on a patch side sampled more
    coarsely (``0 <= sides[srow, k] < depth``), the point of the coarse polyline there, from
    the side's exact samples ``samples`` when the item has them (``sides[srow, 3] >= 0``:
    a piece of an isolated patch, ``patches/isolate_loop.py``), else from its own net."""
    N = 1 << depth
    for k in range(3):
        on, t = _side_param(gi, gj, N, k)
        de = sides[srow, k]
        if on and 0 <= de < depth:
            r = 1 << (depth - de)
            t0 = (t // r) * r
            if sides[srow, 3] >= 0:
                b = _side_base(sides, srow, depth, k) + t // r
                if t0 == t:
                    return samples[b, 0], samples[b, 1], samples[b, 2]
                w = (t - t0) / r
                return ((1.0 - w) * samples[b, 0] + w * samples[b + 1, 0],
                        (1.0 - w) * samples[b, 1] + w * samples[b + 1, 1],
                        (1.0 - w) * samples[b, 2] + w * samples[b + 1, 2])
            if t0 == t:
                break  # a coarse sample itself
            t1 = min(t0 + r, N)
            w = (t - t0) / r
            a0, b0 = _side_vertex(t0, N, k)
            a1, b1 = _side_vertex(t1, N, k)
            x0, y0, z0 = _frame_point(net, q, a0, b0, fr)
            x1, y1, z1 = _frame_point(net, q, a1, b1, fr)
            return ((1.0 - w) * x0 + w * x1, (1.0 - w) * y0 + w * y1,
                    (1.0 - w) * z0 + w * z1)
    return _frame_point(net, q, gi, gj, fr)


@leaf_njit
def _frame_point(net, q, gi, gj, fr):
    """Point of net ``net[q]`` at grid vertex (gi, gj) in its item's frame ``fr``."""
    g, oi, oj, sh = fr
    inv = 1.0 / (1 << sh)
    return tri_point(net, q, g * (gi - oi) * inv, g * (gj - oj) * inv)


@leaf_njit
def tri_deviation(net, q):
    """A bound, per coordinate, on how far the patch of the quartic net ``net[q]`` lies from
    the plane of its corners: 5/2 of its largest pure second difference (module doc)."""
    e0 = e1 = e2 = 0.0
    for k in range(DEGREE - 1):
        for j in range(DEGREE - 1 - k):
            a, b, c = _tri_index(j, k), _tri_index(j + 1, k), _tri_index(j + 2, k)
            d, f = _tri_index(j, k + 1), _tri_index(j, k + 2)
            m = _tri_index(j + 1, k + 1)
            for x in range(3):
                s = max(abs(net[q, a, x] - 2.0 * net[q, b, x] + net[q, c, x]),
                        abs(net[q, a, x] - 2.0 * net[q, d, x] + net[q, f, x]),
                        abs(net[q, c, x] - 2.0 * net[q, m, x] + net[q, f, x]))
                if x == 0:
                    e0 = max(e0, s)
                elif x == 1:
                    e1 = max(e1, s)
                else:
                    e2 = max(e2, s)
    return DEVIATION * e0, DEVIATION * e1, DEVIATION * e2


@llvm_inline_njit
def _tri_hit(ox, oy, oz, kx, ky, kz, sx, sy, sz, pts, ra, rb, rc, gi, gj, g, depth, slack, hit,
             code, item):
    """Intersect the micro-triangle of rows ``ra, rb, rc`` of ``pts``: the grid vertices
    (gi, gj), (gi + g, gj), (gi, gj + g) of the item's depth-``depth`` grid; update ``hit``
    (H_SLOT = ``code``, H_LEAF = depth, H_TRI = ``item``, (H_B1, H_B2) = patch
    parameter)."""
    inv = 1.0 / (1 << depth)
    o = (ox, oy, oz)
    t, ba, bb, bc = ray_triangle(o[kx], o[ky], o[kz], kx, ky, kz, sx, sy, sz, ra, rb, rc, pts,
                                 hit[H_T], slack)
    if t < hit[H_T]:
        hit[H_T] = t
        hit[H_SLOT] = code
        hit[H_LEAF] = depth
        hit[H_TRI] = item
        hit[H_B1] = (gi + g * bb) * inv
        hit[H_B2] = (gj + g * bc) * inv


@leaf_njit
def _corner_points(net, q, g, i, j, lev, depth, fr, sides, srow, samples, pts, r):
    """The corners of node (g, i, j, lev) into ``pts[r:r+3]``: its exact limit points, or
    grid points (:func:`grid_point`, snapped sides moved) for a cell (``lev == depth``)."""
    h = g * (1 << (depth - lev))
    for c in range(3):
        a = i + (h if c == 1 else 0)
        b = j + (h if c == 2 else 0)
        if lev == depth:
            x, y, z = grid_point(net, q, a, b, depth, fr, sides, srow, samples)
        else:
            x, y, z = _frame_point(net, q, a, b, fr)
        pts[r + c, 0], pts[r + c, 1], pts[r + c, 2] = x, y, z


@leaf_njit
def _node_points(net, q, g, i, j, lev, depth, fr, sides, srow, samples, pts, r):
    """The six points of node (g, i, j, lev) < depth, rows ``pts[r:r+6]``: corners A,
    A + g h (1, 0), A + g h (0, 1), then side midpoints A + g h/2 (1, 0), A + g h/2 (0, 1),
    A + g h/2 (1, 1) (h its side in grid steps); the corners of its four children by
    ``_CELL_CORNER``. Above the cells' parents the corners must be in place (the parent's
    points) and the midpoints are exact limit points; a cells' parent takes all six from
    :func:`grid_point` (the points its cells share bit for bit with every other cell)."""
    hh = g * (1 << (depth - lev - 1))
    cells = lev + 1 == depth
    for k in range(0 if cells else 3, 6):
        a = i + (2 * hh if k == 1 else (hh if k == 3 or k == 5 else 0))
        b = j + (2 * hh if k == 2 else (hh if k == 4 or k == 5 else 0))
        if cells:
            x, y, z = grid_point(net, q, a, b, depth, fr, sides, srow, samples)
        else:
            x, y, z = _frame_point(net, q, a, b, fr)
        pts[r + k, 0], pts[r + k, 1], pts[r + k, 2] = x, y, z


@llvm_inline_njit
def _child_box(pts, r, q, e0, e1, e2, plo0, plo1, plo2, phi0, phi1, phi2):
    """Box of child ``q`` of a node whose six points are ``pts[r:r+6]``: its corners' box
    grown by the deviation bound ``e`` of its level (zero for a cell: the micro-triangle
    itself), padded, within its parent's box ``plo, phi``."""
    a, b, c = r + _CELL_CORNER[q][0], r + _CELL_CORNER[q][1], r + _CELL_CORNER[q][2]
    lo0, lo1, lo2, hi0, hi1, hi2 = pad_box(
        min(pts[a, 0], pts[b, 0], pts[c, 0]) - e0, min(pts[a, 1], pts[b, 1], pts[c, 1]) - e1,
        min(pts[a, 2], pts[b, 2], pts[c, 2]) - e2, max(pts[a, 0], pts[b, 0], pts[c, 0]) + e0,
        max(pts[a, 1], pts[b, 1], pts[c, 1]) + e1, max(pts[a, 2], pts[b, 2], pts[c, 2]) + e2)
    return (max(lo0, plo0), max(lo1, plo1), max(lo2, plo2), min(hi0, phi0), min(hi1, phi1),
            min(hi2, phi2))


@llvm_inline_njit
def _node_slab(pts, a, b, c, e0, e1, e2):
    """The slab of a node whose corners are rows ``a, b, c`` of ``pts`` and whose deviation
    bound is ``e``: the normal ``n`` of its corners' plane and the range of ``n . P`` over
    the node, ``n`` . its corners (equal but for rounding) widened by ``|n| . e``, and by
    ``SLAB_PAD`` of its corners' largest coordinate for rounding."""
    ux, uy, uz = pts[b, 0] - pts[a, 0], pts[b, 1] - pts[a, 1], pts[b, 2] - pts[a, 2]
    vx, vy, vz = pts[c, 0] - pts[a, 0], pts[c, 1] - pts[a, 1], pts[c, 2] - pts[a, 2]
    nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    lo = np.inf
    hi = -np.inf
    big = 0.0
    for k in (a, b, c):
        d = nx * pts[k, 0] + ny * pts[k, 1] + nz * pts[k, 2]
        lo = min(lo, d)
        hi = max(hi, d)
        big = max(big, abs(pts[k, 0]), abs(pts[k, 1]), abs(pts[k, 2]))
    an = abs(nx) + abs(ny) + abs(nz)
    w = abs(nx) * e0 + abs(ny) * e1 + abs(nz) * e2 + SLAB_PAD * an * big
    return nx, ny, nz, lo - w, hi + w


@leaf_njit
def _net_slab(net, q):
    """The slab of the quartic net ``net[q]``: the normal of its corners' plane and the
    range of ``n . P`` over its 15 points (the patch lies in their convex hull), widened by
    ``SLAB_PAD`` for rounding."""
    a, b, c = 0, DEGREE, N_TRI - 1  # its corners (s, t) = (0, 0), (1, 0), (0, 1)
    ux, uy, uz = (net[q, b, 0] - net[q, a, 0], net[q, b, 1] - net[q, a, 1],
                  net[q, b, 2] - net[q, a, 2])
    vx, vy, vz = (net[q, c, 0] - net[q, a, 0], net[q, c, 1] - net[q, a, 1],
                  net[q, c, 2] - net[q, a, 2])
    nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    lo = np.inf
    hi = -np.inf
    big = 0.0
    for k in range(N_TRI):
        d = nx * net[q, k, 0] + ny * net[q, k, 1] + nz * net[q, k, 2]
        lo = min(lo, d)
        hi = max(hi, d)
        big = max(big, abs(net[q, k, 0]), abs(net[q, k, 1]), abs(net[q, k, 2]))
    w = SLAB_PAD * (abs(nx) + abs(ny) + abs(nz)) * big
    return nx, ny, nz, lo - w, hi + w


@llvm_inline_njit
def slab_cut_entry(ox, oy, oz, ix, iy, iz, dx, dy, dz, lo0, lo1, lo2, hi0, hi1, hi2, nx, ny, nz,
                slo, shi, tmax):
    """Entry distance of the ray into the box ``lo, hi`` cut by the slab ``slo <= n . x <=
    shi``; inf when it misses either before ``tmax``. (The ray's stretch between the planes
    is widened by a relative 1e-9 for rounding.) Catmull-Clark cells are cut alike
    (``bezier._cell_entry``)."""
    tn, tf = slab_range(ox, oy, oz, ix, iy, iz, lo0, lo1, lo2, hi0, hi1, hi2, 0.0, tmax)
    if tn == np.inf:
        return np.inf
    dn = nx * dx + ny * dy + nz * dz
    no = nx * ox + ny * oy + nz * oz
    if dn == 0.0:
        return tn if slo <= no <= shi else np.inf
    inv = 1.0 / dn  # (one division: the stretch is widened below far beyond its rounding)
    ta = (slo - no) * inv
    tb = (shi - no) * inv
    if ta > tb:
        ta, tb = tb, ta
    ta -= 1e-9 * abs(ta)
    tb += 1e-9 * abs(tb)
    tn = max(tn, ta)
    if tn <= min(tf, tb):
        return tn
    return np.inf


@leaf_njit
def _level_deviation(dev, lev, lev0):
    """The deviation bound of the nodes of level ``lev`` of an item of level ``lev0`` whose
    own bound is ``dev``: a quarter per level (exact: powers of two)."""
    s = 1.0 / (1 << (2 * (lev - lev0)))
    return dev[0] * s, dev[1] * s, dev[2] * s


@llvm_inline_njit
def _snapped_node(i, j, h, lev, depth, sides, srow):
    """Whether the level-``lev`` node with corners (i, j), (i + h, j), (i, j + h) may hold
    snapped grid vertices: it touches a side sampled at a depth ``de`` < ``lev``. Its
    snapped points lie on the chords of its ancestor at level ``de`` (whose side on the edge
    is one coarse segment, its ends that ancestor's corners), so in that ancestor's box,
    which the ray entered, but maybe not in the node's own: the ray enters it untested."""
    N = 1 << depth
    for k in range(3):
        de = sides[srow, k]
        if 0 <= de < lev:
            for c in range(3):
                a = i + (h if c == 1 else 0)
                b = j + (h if c == 2 else 0)
                if _side_param(a, b, N, k)[0]:
                    return True
    return False


@leaf_njit
def _snapped_entry(ox, oy, oz, ix, iy, iz, lo0, lo1, lo2, hi0, hi1, hi2, i, j, h, lev, depth,
                   sides, srow, samples, tmax):
    """Entry distance of the ray into the box ``lo, hi`` of node (i, j, h, lev) of an item
    with side samples (``sides[srow, 3] >= 0``) widened by the samples of the coarse
    segments its vertices on snapped sides (``0 <= de < lev``) may be moved onto: its
    snapped points lie on those segments, so in that box. (Without samples the node is
    entered untested: :func:`_snapped_node`.)"""
    N = 1 << depth
    for k in range(3):
        de = sides[srow, k]
        if not 0 <= de < lev:
            continue
        r = 1 << (depth - de)
        t_lo = N + 1
        t_hi = -1
        for c in range(3):
            on, t = _side_param(i + (h if c == 1 else 0), j + (h if c == 2 else 0), N, k)
            if on:
                t_lo = min(t_lo, t)
                t_hi = max(t_hi, t)
        if t_hi < 0:
            continue
        b = _side_base(sides, srow, depth, k)
        for m in range(t_lo // r, -(-t_hi // r) + 1):
            x, y, z = samples[b + m, 0], samples[b + m, 1], samples[b + m, 2]
            lo0, lo1, lo2 = min(lo0, x), min(lo1, y), min(lo2, z)
            hi0, hi1, hi2 = max(hi0, x), max(hi1, y), max(hi2, z)
    lo0, lo1, lo2, hi0, hi1, hi2 = pad_box(lo0, lo1, lo2, hi0, hi1, hi2)
    return slab_entry(ox, oy, oz, ix, iy, iz, lo0, lo1, lo2, hi0, hi1, hi2, 0.0, tmax)


@llvm_inline_njit
def _child_entry(ray, lo0, lo1, lo2, hi0, hi1, hi2, nx, ny, nz, slo, shi, cg, ci, cj, h, lev,
                 depth, sides, srow, samples, t_parent, tmax):
    """Entry distance of the ray into child (cg, ci, cj) of level ``lev`` < ``depth`` (side
    ``h``) whose box is ``lo, hi`` and slab ``n, slo, shi`` (:func:`_node_slab`): a child
    that may hold snapped points (:func:`_snapped_node`: they may lie off its slab too) is
    tested by its box widened by its side's samples where the item has them
    (:func:`_snapped_entry`), else entered untested at its parent's entry ``t_parent``."""
    ox, oy, oz, ix, iy, iz, kx, ky, kz, sx, sy, sz, dx, dy, dz = ray
    if _snapped_node(ci, cj, cg * h, lev, depth, sides, srow):
        if sides[srow, 3] >= 0:
            return _snapped_entry(ox, oy, oz, ix, iy, iz, lo0, lo1, lo2, hi0, hi1, hi2, ci, cj,
                                  cg * h, lev, depth, sides, srow, samples, tmax)
        return t_parent
    return slab_cut_entry(ox, oy, oz, ix, iy, iz, dx, dy, dz, lo0, lo1, lo2, hi0, hi1, hi2, nx,
                       ny, nz, slo, shi, tmax)


@llvm_inline_njit
def _child(g, i, j, lev, depth, q):
    """Orientation and origin of child ``q`` of node (g, i, j, lev) (Loop's child order)."""
    hh = g * (1 << (depth - lev - 1))
    return (-g if q == 3 else g, i + (hh if q == 1 or q == 3 else 0),
            j + (hh if q == 2 or q == 3 else 0))


@leaf_njit
def descend_tri(ray, g0, i0, j0, lev0, t0, lev_item, nets, nk, depth, fr, sides, srow,
                samples, slack, hit, code, item, work, st, st_t, st0, tmp_t, order):
    """Closest hit on the node (g0, i0, j0, lev0), entered at ``t0``, of the Loop item (a
    regular patch, or a piece of an isolated one: frame ``fr``, :func:`grid_point`; level
    ``lev_item``) whose quartic net is ``nets[nk]``, refined per ray down to the grid depth
    ``depth``, storing nothing; updates ``hit``. The node's corners and box are the first
    five rows of ``work`` read as rows of points (a cell's corners are its grid points), as
    the memo would hold them: the ray meets the same boxes, slabs and triangles either way.
    ``sides[srow]``: the sampling depth of each patch side's edge (-1: none) and the first
    of its side samples in ``samples`` (-1: none). ``work`` ((., 4, 4, 3): 5 rows of points
    a stacked node, 22 more), rows ``st0 ..`` of the stack ``st`` (>= 3*depth+1 of them)
    with entry distances ``st_t``, ``tmp_t`` / ``order`` (4,) are scratch. Returns the
    number of micro-triangles tested."""
    ox, oy, oz, ix, iy, iz, kx, ky, kz, sx, sy, sz, dx, dy, dz = ray
    pts = work.reshape((-1, 3))
    tb = pts.shape[0] - 22  # each child's box (2 rows) and slab (2), then the six points
    top = tb + 16
    dev = tri_deviation(nets, nk)
    # stack rows: orientation g, -, i, j, level; rows 5 k .. 5 k + 4 of pts: the corners
    # and the box (lo, hi) of the node in stack row k
    st[st0, 0], st[st0, 2], st[st0, 3], st[st0, 4] = g0, i0, j0, lev0
    st_t[st0] = t0
    sp = 1
    tested = 0
    while sp > 0:
        sp -= 1
        if st_t[st0 + sp] >= hit[H_T]:  # a nearer hit was found since it was pushed
            continue
        g, i, j, lev = st[st0 + sp, 0], st[st0 + sp, 2], st[st0 + sp, 3], st[st0 + sp, 4]
        r = 5 * sp
        if lev == depth:
            _tri_hit(ox, oy, oz, kx, ky, kz, sx, sy, sz, pts, r, r + 1, r + 2, i, j, g, depth,
                     slack, hit, code, item)
            tested += 1
            continue
        for k in range(3):
            for c in range(3):
                pts[top + k, c] = pts[r + k, c]
        cells = lev + 1 == depth
        plo0, plo1, plo2 = pts[r + 3, 0], pts[r + 3, 1], pts[r + 3, 2]
        phi0, phi1, phi2 = pts[r + 4, 0], pts[r + 4, 1], pts[r + 4, 2]
        _node_points(nets, nk, g, i, j, lev, depth, fr, sides, srow, samples, pts, top)
        e0, e1, e2 = (0.0, 0.0, 0.0) if cells else _level_deviation(dev, lev + 1, lev_item)
        h = 1 << (depth - lev - 1)
        n = 0
        for q in range(4):
            b = tb + 4 * q
            if cells:
                lo0, lo1, lo2, hi0, hi1, hi2 = _cell_box(pts, top, q)
                te = slab_entry(ox, oy, oz, ix, iy, iz, lo0, lo1, lo2, hi0, hi1, hi2, 0.0,
                                hit[H_T])
            else:
                lo0, lo1, lo2, hi0, hi1, hi2 = _child_box(pts, top, q, e0, e1, e2, plo0, plo1,
                                                          plo2, phi0, phi1, phi2)
                nx, ny, nz, slo, shi = _node_slab(pts, top + _CELL_CORNER[q][0],
                                                  top + _CELL_CORNER[q][1],
                                                  top + _CELL_CORNER[q][2], e0, e1, e2)
                cg, ci, cj = _child(g, i, j, lev, depth, q)
                te = _child_entry(ray, lo0, lo1, lo2, hi0, hi1, hi2, nx, ny, nz, slo, shi, cg,
                                  ci, cj, h, lev + 1, depth, sides, srow, samples,
                                  st_t[st0 + sp], hit[H_T])
            pts[b, 0], pts[b, 1], pts[b, 2] = lo0, lo1, lo2
            pts[b + 1, 0], pts[b + 1, 1], pts[b + 1, 2] = hi0, hi1, hi2
            if te < np.inf:
                n = push_sorted(tmp_t, order, n, te, q)
        for e in range(n):
            q = order[e]
            cg, ci, cj = _child(g, i, j, lev, depth, q)
            r = 5 * sp
            for c in range(3):
                k = top + _CELL_CORNER[q][c]
                pts[r + c, 0], pts[r + c, 1], pts[r + c, 2] = pts[k, 0], pts[k, 1], pts[k, 2]
            for k in range(2):
                b = tb + 4 * q + k
                pts[r + 3 + k, 0], pts[r + 3 + k, 1], pts[r + 3 + k, 2] = (pts[b, 0], pts[b, 1],
                                                                           pts[b, 2])
            st[st0 + sp, 0], st[st0 + sp, 2], st[st0 + sp, 3] = cg, ci, cj
            st[st0 + sp, 4] = lev + 1
            st_t[st0 + sp] = tmp_t[e]
            sp += 1
    return tested


@leaf_njit
def _block(m_cells, cnt):
    """A block of 8 rows of the memo's cell store ``m_cells`` (two cells' room), as its
    first row; -1 when the store is full."""
    if cnt[M_CELLS] + 2 > len(m_cells) // 4:
        cnt[M_FULL] = 1
        return -1
    u = cnt[M_CELLS]
    cnt[M_CELLS] = u + 2
    return 4 * u


@leaf_njit
def _parent_corners(node, parent, child, data, m_cells, pts, r):
    """The corners of memo node ``node`` into ``pts[r:r+3]``: three of the six points of its
    ``parent`` (which was split; the memo's ``child``, ``data`` and cells ``m_cells``)."""
    q = node - child[parent]
    for c in range(3):
        k = data[parent] + _CELL_CORNER[q][c]
        pts[r + c, 0], pts[r + c, 1], pts[r + c, 2] = m_cells[k, 0], m_cells[k, 1], m_cells[k, 2]


@leaf_njit
def _expand_node(node, parent, g, i, j, lev, lev_item, depth, net, nk, fr, sides, srow,
                 samples, child, box, slab, data, m_cells, cnt):
    """Split memo node ``node`` (g, i, j, lev < depth - 1; a child of ``parent``, -1 for the
    item's root) into its four children: its six points (:func:`_node_points`; the corners
    its parent's) into a block of the cell store (:func:`_block`; its data) with its
    children's deviation bound in row 6 (a quarter of its parent's; the item's root
    computes it from the net), its children's boxes and slabs (:func:`_child_box`,
    :func:`_node_slab`). No net is split (``child`` .. ``cnt``: the memo's arrays it
    writes). Returns the first child, or -1 when a store is full."""
    if cnt[M_NODES] + 4 > len(child):
        cnt[M_FULL] = 1
        return -1
    r = _block(m_cells, cnt)
    if r < 0:
        return -1
    if parent < 0:
        _corner_points(net, nk, g, i, j, lev, depth, fr, sides, srow, samples, m_cells, r)
    else:
        _parent_corners(node, parent, child, data, m_cells, m_cells, r)
    _node_points(net, nk, g, i, j, lev, depth, fr, sides, srow, samples, m_cells, r)
    if parent < 0:
        e0, e1, e2 = _level_deviation(tri_deviation(net, nk), lev + 1, lev_item)
    else:
        k = data[parent] + 6
        e0, e1, e2 = 0.25 * m_cells[k, 0], 0.25 * m_cells[k, 1], 0.25 * m_cells[k, 2]
    m_cells[r + 6, 0], m_cells[r + 6, 1], m_cells[r + 6, 2] = e0, e1, e2
    first = cnt[M_NODES]
    for q in range(4):
        lo0, lo1, lo2, hi0, hi1, hi2 = _child_box(m_cells, r, q, e0, e1, e2, box[node, 0],
                                                  box[node, 1], box[node, 2], box[node, 3],
                                                  box[node, 4], box[node, 5])
        m = new_node(child, box, data, cnt, lo0, lo1, lo2, hi0, hi1, hi2, NOT_YET)
        (slab[m, 0], slab[m, 1], slab[m, 2], slab[m, 3],
         slab[m, 4]) = _node_slab(m_cells, r + _CELL_CORNER[q][0], r + _CELL_CORNER[q][1],
                                  r + _CELL_CORNER[q][2], e0, e1, e2)
    data[node] = r
    child[node] = first
    return first


@llvm_inline_njit
def _cell_box(pts, r, q):
    """Box of cell ``q`` of a cells' parent whose six grid points are ``pts[r:r+6]``: its
    micro-triangle's, padded (not within its parent's: its snapped corners may lie outside
    it, :func:`_snapped_node`)."""
    return _child_box(pts, r, q, 0.0, 0.0, 0.0, -np.inf, -np.inf, -np.inf, np.inf, np.inf,
                      np.inf)


# the six points of _node_points (rows) at each child's corners A, A + g' (1, 0),
# A + g' (0, 1) (the middle child is turned: g' = -g)
_CELL_CORNER = ((0, 3, 4), (3, 1, 5), (4, 5, 2), (5, 4, 3))


# intersect_tri (about 80 lines) is not split: it is inlined into the trace kernel (through
# bezier.intersect_patch) and its descent keeps the ray, the stack and the memo in locals.
# Its stack loop has the shape of intersect_patch's quadtree descent; they stay two loops
# because the nodes differ (a triangle's children and their orientation, cells of three
# corners snapped to coarser sides, no fans), and a shared loop would need the node kind
# tested at every step of the per-ray path.
@inline_njit
def intersect_tri(ray, it, nets, nk, depth, fr, sides, samples, slack, hit, code, mem,
                  scratch):
    """Closest hit on the Loop item ``it`` (its quartic net ``nets[nk]``, ``nets`` the
    pieces' nets read as (., 16, 3) triangular nets: ``PieceArrays.tri_nets``; grid depth
    ``depth``, frame ``fr`` = (g, oi, oj, sh), :func:`grid_point`: a regular patch is
    (1, 0, 0, depth); side sampling ``sides[it]`` and side samples ``samples``) nearer than
    hit[H_T]; updates ``hit``.
    The ray descends the patch's 1-to-4 splits nearest first into the nodes whose boxes it
    enters; a node is split (its six points, its children's boxes and slabs stored) once per
    thread, in the thread's memo ``mem`` (``geometry/bezier.py``); when a store is full the ray
    goes on splitting per ray (:func:`descend_tri`). Returns the micro-triangles built:
    cells this ray was the first of its thread to test, and those it tested per ray."""
    ox, oy, oz, ix, iy, iz, kx, ky, kz, sx, sy, sz, dx, dy, dz = ray
    work, st, st_t, tmp_t, order, lv, lp = scratch
    root_m, child, box, slab, data, m_nets, m_cells, cnt = mem
    root = nets  # (., 16, 3)
    lev_item = depth - fr[3]
    node = root_m[it]
    if node < 0:
        pts = work.reshape((-1, 3))
        if fr[3] == 0:  # a one-cell item: its triangle, counted once per thread
            _corner_points(root, nk, fr[0], fr[1], fr[2], depth, depth, fr, sides, it, samples,
                           pts, 0)
            tested = descend_tri(ray, fr[0], fr[1], fr[2], depth, 0.0, depth, root, nk, depth,
                                 fr, sides, it, samples, slack, hit, code, it, work, st, st_t,
                                 np.int64(0), tmp_t, order)
            if node == NOT_YET:
                root_m[it] = COUNTED
                return tested
            return 0
        lo0, lo1, lo2, hi0, hi1, hi2 = tri_box(root, nk)
        lo0, lo1, lo2, hi0, hi1, hi2 = pad_box(lo0, lo1, lo2, hi0, hi1, hi2)
        nx, ny, nz, slo, shi = _net_slab(root, nk)
        if cnt[M_NODES] + 1 > len(child):  # a full store: the item split per ray
            cnt[M_FULL] = 1
            t0 = slab_cut_entry(ox, oy, oz, ix, iy, iz, dx, dy, dz, lo0, lo1, lo2, hi0, hi1, hi2,
                             nx, ny, nz, slo, shi, hit[H_T])
            if t0 == np.inf:
                return 0
            _corner_points(root, nk, fr[0], fr[1], fr[2], lev_item, depth, fr, sides, it,
                           samples, pts, 0)
            pts[3, 0], pts[3, 1], pts[3, 2], pts[4, 0], pts[4, 1], pts[4, 2] = (
                lo0, lo1, lo2, hi0, hi1, hi2)
            return descend_tri(ray, fr[0], fr[1], fr[2], lev_item, t0, lev_item, root, nk,
                               depth, fr, sides, it, samples, slack, hit, code, it, work, st,
                               st_t, np.int64(0), tmp_t, order)
        node = new_node(child, box, data, cnt, lo0, lo1, lo2, hi0, hi1, hi2, NOT_YET)
        slab[node, 0], slab[node, 1], slab[node, 2], slab[node, 3], slab[node, 4] = (
            nx, ny, nz, slo, shi)
        root_m[it] = node
    t0 = slab_cut_entry(ox, oy, oz, ix, iy, iz, dx, dy, dz, box[node, 0], box[node, 1],
                     box[node, 2], box[node, 3], box[node, 4], box[node, 5], slab[node, 0],
                     slab[node, 1], slab[node, 2], slab[node, 3], slab[node, 4], hit[H_T])
    if t0 == np.inf:  # the ray misses the patch's slab
        return 0
    # stack rows: node, orientation, i, j, level, parent; st_t: entry distance when pushed
    st[0, 0], st[0, 1], st[0, 2], st[0, 3], st[0, 4] = node, fr[0], fr[1], fr[2], lev_item
    st[0, 5] = -1
    st_t[0] = t0
    sp = 1
    tested = 0
    while sp > 0:
        sp -= 1
        if st_t[sp] >= hit[H_T]:  # a nearer hit was found since it was pushed
            continue
        node, g, i, j, lev = st[sp, 0], st[sp, 1], st[sp, 2], st[sp, 3], st[sp, 4]
        parent = st[sp, 5]
        cells = lev + 1 == depth
        c = data[node] if cells else child[node]
        if c < 0:  # not yet split (a cells' parent: its points not yet evaluated)
            if cells:
                c = _block(m_cells, cnt)
                if c >= 0:
                    _node_points(root, nk, g, i, j, lev, depth, fr, sides, it, samples, m_cells,
                                 c)
                    m_cells[c + 6, 0] = m_cells[c + 6, 1] = m_cells[c + 6, 2] = 0.0
                    m_cells[c + 7, 0] = 0.0
                    data[node] = c
            else:
                c = _expand_node(node, parent, g, i, j, lev, lev_item, depth, root, nk, fr,
                                 sides, it, samples, child, box, slab, data, m_cells, cnt)
            if c < 0:  # a store is full: split per ray below this node
                pts = work.reshape((-1, 3))
                if parent < 0:
                    _corner_points(root, nk, g, i, j, lev, depth, fr, sides, it, samples, pts, 0)
                else:
                    _parent_corners(node, parent, child, data, m_cells, pts, 0)
                for k in range(3):
                    pts[3, k] = box[node, k]
                    pts[4, k] = box[node, 3 + k]
                tested += descend_tri(ray, g, i, j, lev, st_t[sp], lev_item, root, nk, depth, fr,
                                      sides, it, samples, slack, hit, code, it, work, st, st_t,
                                      sp + 1, tmp_t, order)
                continue
        if cells:  # its four cells (rows c .. c + 5: their corners; c + 6, c + 7: tested
            n = 0  # yet), the ones the ray enters nearest first
            for q in range(4):
                lo0, lo1, lo2, hi0, hi1, hi2 = _cell_box(m_cells, c, q)
                te = slab_entry(ox, oy, oz, ix, iy, iz, lo0, lo1, lo2, hi0, hi1, hi2, 0.0,
                                hit[H_T])
                if te < np.inf:
                    n = push_sorted(tmp_t, order, n, te, q)
            for e in range(n - 1, -1, -1):
                if tmp_t[e] >= hit[H_T]:  # (a nearer hit was found)
                    break
                q = order[e]
                f, k = (c + 7, 0) if q == 3 else (c + 6, q)
                if m_cells[f, k] == 0.0:  # the first ray of the memo to test it
                    m_cells[f, k] = 1.0
                    tested += 1
                cg, ci, cj = _child(g, i, j, lev, depth, q)
                _tri_hit(ox, oy, oz, kx, ky, kz, sx, sy, sz, m_cells, c + _CELL_CORNER[q][0],
                         c + _CELL_CORNER[q][1], c + _CELL_CORNER[q][2], ci, cj, cg, depth,
                         slack, hit, code, it)
            continue
        # the children the ray enters, pushed far to near (a cell's box is its triangle's)
        n = 0
        h = 1 << (depth - lev - 1)
        for q in range(4):
            cg, ci, cj = _child(g, i, j, lev, depth, q)
            te = _child_entry(ray, box[c + q, 0], box[c + q, 1], box[c + q, 2], box[c + q, 3],
                              box[c + q, 4], box[c + q, 5], slab[c + q, 0], slab[c + q, 1],
                              slab[c + q, 2], slab[c + q, 3], slab[c + q, 4], cg, ci, cj, h,
                              lev + 1, depth, sides, it, samples, st_t[sp], hit[H_T])
            if te < np.inf:
                n = push_sorted(tmp_t, order, n, te, q)
        for e in range(n):
            q = order[e]
            cg, ci, cj = _child(g, i, j, lev, depth, q)
            st[sp, 0], st[sp, 1], st[sp, 2], st[sp, 3], st[sp, 4] = c + q, cg, ci, cj, lev + 1
            st[sp, 5] = node
            st_t[sp] = tmp_t[e]
            sp += 1
    return tested


@leaf_njit
def intersect_tri_cell(ray, cells, c, gi, gj, g, depth, slack, hit, code, item):
    """Intersect the Loop cell ``cells[4c : 4c+3]`` (corners (gi, gj), (gi + g, gj),
    (gi, gj + g) of its patch's depth-``depth`` grid: exact limit points, moved onto a
    coarser neighbour's polyline on a snapped side when the patch was built); update
    ``hit`` as :func:`_tri_hit`."""
    ox, oy, oz, ix, iy, iz, kx, ky, kz, sx, sy, sz, dx, dy, dz = ray
    _tri_hit(ox, oy, oz, kx, ky, kz, sx, sy, sz, cells, 4 * c, 4 * c + 1, 4 * c + 2, gi, gj, g,
             depth, slack, hit, code, item)


def tri_nets_as_pieces(nets15: np.ndarray) -> np.ndarray:
    """(m,4,4,3) store rows holding the (m,15,3) triangular nets (the 16th point repeats
    the 15th, so a box over all 16 is the net's)."""
    out = np.empty((len(nets15), 16, 3))
    out[:, :N_TRI] = nets15
    out[:, N_TRI] = nets15[:, N_TRI - 1]
    return out.reshape(-1, 4, 4, 3)

