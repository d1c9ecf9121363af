"""Ray / Loop-patch intersection by per-ray refinement of quartic triangular Bezier nets.

A regular Loop triangle (three smooth valence-6 corners, or a regular boundary: see
``lines.items.loop_regular``) is one quartic triangular Bezier net of 15 points
(``patches/basis.py``: box spline -> net, ``BOX_TO_TRI``), stored in the pieces' net store
as the first 15 of a (4,4,3) net's 16 points (item kind ``TRI``). Its grid depth ``d``
comes from the angular criterion. A ray that enters the net's box descends the patch's
1-to-4 split in Loop's child order (corner children 0, 1, 2, then the middle child turned
half a turn: ``basis.TRI_SPLIT``), entering the children whose net boxes it hits, nearest
first, until level ``d``. Each thread keeps what its rays split in its memo (the quads' memo,
``trace/bezier.py``: node boxes, the nets of the nodes split, three corner rows per cell),
so a node is split and a cell evaluated once per thread (:func:`intersect_tri`); a full store
makes the ray split on the spot (:func:`descend_tri`), which changes no hit. The last split
evaluates no nets: a node of level ``d - 1`` becomes its four cells at once, from its six
grid points (:func:`_expand_cells`), each cell boxed by its own micro-triangle (three
quarters of all splits are these; splitting their nets was half the trace time of a Loop
cage with creases). A cell counts as a micro-triangle when a ray of the memo first tests it.

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

from subtrace.accel.bvh import slab_entry
from subtrace.patches.basis import (
    DEGREE, N_TRI, NORMAL_STEP, NORMAL_TRIES, copy_net, pad_box,
    tri_box, tri_child, tri_split, unit_normal,
)
from subtrace.runtime.jit import inline_njit, leaf_njit
from subtrace.trace.prims import (
    H_B1, H_B2, H_LEAF, H_SLOT, H_T, H_TRI, M_CELLS, M_FULL, M_NETS, M_NODES, NOT_YET,
    new_node, push_sorted, ray_triangle,
)

TRI = 2  # item kind of a Loop net (a regular patch, or a piece) in ``trace.pools.Pieces``
LOOP_CELL = 3  # item kind of a cell of exact limit points of an isolated Loop patch
COUNTED = -3  # memo root of a one-cell patch whose triangle was counted (as bezier's)


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


@leaf_njit
def _tri_entry(ox, oy, oz, ix, iy, iz, w, q, tmax):
    """Entry distance of the ray into the padded box of net ``w[q]``; inf on a miss."""
    lo0, lo1, lo2, hi0, hi1, hi2 = tri_box(w, q)
    lo0, lo1, lo2, hi0, hi1, hi2 = pad_box(lo0, lo1, lo2, hi0, hi1, hi2)
    return slab_entry(ox, oy, oz, ix, iy, iz, lo0, lo1, lo2, hi0, hi1, hi2, 0.0, tmax)


@leaf_njit
def _tri_points(net, q, gi, gj, g, depth, fr, sides, srow, samples, out, r0):
    """The corners (gi, gj), (gi + g, gj), (gi, gj + g) of a micro-triangle of the patch's
    depth-``depth`` grid (:func:`grid_point`) into ``out[r0:r0+3]``."""
    for c in range(3):
        a = gi + (g if c == 1 else 0)
        b = gj + (g if c == 2 else 0)
        out[r0 + c, 0], out[r0 + c, 1], out[r0 + c, 2] = grid_point(net, q, a, b, depth, fr,
                                                                    sides, srow, samples)


@leaf_njit
def _tri_hit(ox, oy, oz, kx, ky, kz, sx, sy, sz, pts, r0, gi, gj, g, depth, slack, hit, code,
             item):
    """Intersect the micro-triangle ``pts[r0:r0+3]`` (corners as :func:`_tri_points`);
    update ``hit`` (H_SLOT = ``code``, H_LEAF = depth, H_TRI = ``item``, (H_B1, H_B2) = patch
    parameter)."""
    inv = 1.0 / (1 << depth)
    o = (ox, oy, oz)
    t, ba, bb, bc = ray_triangle(o[kx], o[ky], o[kz], kx, ky, kz, sx, sy, sz, r0, r0 + 1,
                                 r0 + 2, pts, hit[H_T], slack)
    if t < hit[H_T]:
        hit[H_T] = t
        hit[H_SLOT] = code
        hit[H_LEAF] = depth
        hit[H_TRI] = item
        hit[H_B1] = (gi + g * bb) * inv
        hit[H_B2] = (gj + g * bc) * inv


@leaf_njit
def _push_children(ox, oy, oz, ix, iy, iz, w, base, g, i, j, lev, t_parent, depth, sides, srow,
                   samples, tmax, tmp_t, order):
    """The children (nets ``w[base:base+4]``) of node (g, i, j, lev) that the ray enters
    before ``tmax``, sorted far to near into ``order`` / ``tmp_t``; returns their count. A
    child that may hold snapped points (:func:`_snapped_node`) is tested by its box widened
    by its side's samples where the item has them (:func:`_snapped_entry`), else entered
    untested, at its parent's entry distance ``t_parent``."""
    n = 0
    hh = g * (1 << (depth - lev - 1))  # half the node's side, signed
    for q in range(4):
        ci = i + (hh if q == 1 or q == 3 else 0)
        cj = j + (hh if q == 2 or q == 3 else 0)
        ch = -hh if q == 3 else hh
        if _snapped_node(ci, cj, ch, lev + 1, depth, sides, srow):
            if sides[srow, 3] >= 0:
                lo0, lo1, lo2, hi0, hi1, hi2 = tri_box(w, base + q)
                te = _snapped_entry(ox, oy, oz, ix, iy, iz, lo0, lo1, lo2, hi0, hi1, hi2, ci,
                                    cj, ch, lev + 1, depth, sides, srow, samples, tmax)
            else:
                te = t_parent
        else:
            te = _tri_entry(ox, oy, oz, ix, iy, iz, w, base + q, tmax)
        if te < np.inf:
            n = push_sorted(tmp_t, order, n, te, q)
    return n


@leaf_njit
def _child(g, i, j, lev, depth, q):
    """Orientation and origin of child ``q`` of node (g, i, j, lev) (Loop's child order)."""
    hh = g * (1 << (depth - lev - 1))
    return (-g if q == 3 else g, i + (hh if q == 1 or q == 3 else 0),
            j + (hh if q == 2 or q == 3 else 0))


@leaf_njit
def descend_tri(ray, src, s, g0, i0, j0, lev0, nets, nk, depth, fr, sides, srow, samples,
                slack, hit, code, item, work, st, st_t, st0, tmp_t, order, lv):
    """Closest hit on the node (g0, i0, j0, lev0) of the Loop item (a regular patch, or a
    piece of an isolated one: frame ``fr``, :func:`grid_point`) whose quartic net is
    ``nets[nk]`` ((.,4,4,3) stores: the first 15 points), its own net ``src[s]``,
    refined per ray down to the grid depth ``depth``, storing nothing; updates ``hit``.
    ``sides[srow]``: the sampling depth of each patch side's edge (-1: none) and the first
    of its side samples in ``samples`` (-1: none). ``work`` (>=
    3*depth+5 nets), rows ``st0 ..`` of the stack ``st`` (>= 3*depth+1 of them) with entry
    distances ``st_t``, ``tmp_t`` / ``order`` (4,) and ``lv`` (>= 3, 3) are scratch.
    Returns the number of micro-triangles tested."""
    ox, oy, oz, ix, iy, iz, kx, ky, kz, sx, sy, sz, dx, dy, dz = ray
    root = nets.reshape((nets.shape[0], 16, 3))
    w = work.reshape((work.shape[0], 16, 3))
    sw = src.reshape((src.shape[0], 16, 3))
    base = w.shape[0] - 4  # the last four rows receive children before sorting
    for p in range(N_TRI):
        for c in range(3):
            w[0, p, c] = sw[s, p, c]
    # stack rows: orientation g (+1 upright, -1 turned), -, i, j, level (nets in w[row])
    st[st0, 0], st[st0, 2], st[st0, 3], st[st0, 4] = g0, i0, j0, lev0
    st_t[st0] = 0.0
    sp = 1
    tested = 0
    while sp > 0:
        sp -= 1
        if st_t[st0 + sp] >= hit[H_T]:  # a nearer hit was found since it was pushed
            continue
        g, i, j, lev = st[st0 + sp, 0], st[st0 + sp, 2], st[st0 + sp, 3], st[st0 + sp, 4]
        if lev == depth:
            _tri_points(root, nk, i, j, g, depth, fr, sides, srow, samples, lv, 0)
            _tri_hit(ox, oy, oz, kx, ky, kz, sx, sy, sz, lv, 0, i, j, g, depth, slack, hit, code,
                     item)
            tested += 1
            continue
        tri_split(w, sp, base)
        n = _push_children(ox, oy, oz, ix, iy, iz, w, base, g, i, j, lev, st_t[st0 + sp], depth,
                           sides, srow, samples, hit[H_T], tmp_t, order)
        for e in range(n):
            q = order[e]
            for p in range(N_TRI):
                for c in range(3):
                    w[sp, p, c] = w[base + q, p, c]
            cg, ci, cj = _child(g, i, j, lev, depth, q)
            st[st0 + sp, 0], st[st0 + sp, 2], st[st0 + sp, 3] = cg, ci, cj
            st[st0 + sp, 4] = lev + 1
            st_t[st0 + sp] = tmp_t[e]
            sp += 1
    return tested


@leaf_njit
def _expand_tri(node, parent, lev, depth, mem, work):
    """Split memo node ``node`` (level ``lev`` < depth - 1, child of ``parent``): its four
    children with their boxes. Its net is the stored one, or is split off its parent's and
    stored (a node's net is stored when the node is split: its children's are split off it
    when they are split in turn, or when a full store makes a ray split below them on the
    spot); the children's nets are not stored: a child is split only if a ray enters it,
    and most are not (a cell's parent is split into cells without nets). Returns the first
    child, or -1 when a store is full."""
    root_m, child, box, slab, data, m_nets, m_cells, cnt = mem
    if cnt[M_NODES] + 4 > len(child) or cnt[M_NETS] + 1 > len(m_nets):
        cnt[M_FULL] = 1
        return -1
    w = work.reshape((work.shape[0], 16, 3))
    mw = m_nets.reshape((m_nets.shape[0], 16, 3))
    base = w.shape[0] - 4
    if data[node] < 0:
        row = cnt[M_NETS]
        cnt[M_NETS] = row + 1
        _split_off_parent(node, parent, mem, mw, row)
        data[node] = row
    first = cnt[M_NODES]
    for q in range(4):
        tri_child(mw, data[node], q, w, base + q)
        lo0, lo1, lo2, hi0, hi1, hi2 = tri_box(w, base + q)
        lo0, lo1, lo2, hi0, hi1, hi2 = pad_box(lo0, lo1, lo2, hi0, hi1, hi2)
        new_node(child, box, data, cnt, lo0, lo1, lo2, hi0, hi1, hi2, -1)
    child[node] = first
    return first


@leaf_njit
def _split_off_parent(node, parent, mem, out, o):
    """Memo node ``node``'s net, split off the stored net of its ``parent`` (which was
    split), into ``out[o]`` ((., 16, 3): the 16th point repeats the 15th, as in the
    stores)."""
    root_m, child, box, slab, data, m_nets, m_cells, cnt = mem
    mw = m_nets.reshape((m_nets.shape[0], 16, 3))
    tri_child(mw, data[parent], node - child[parent], out, o)
    for c in range(3):
        out[o, N_TRI, c] = out[o, N_TRI - 1, c]


@leaf_njit
def _node_net(node, parent, mem, work):
    """Memo node ``node``'s net as (store, row): its stored net, or split off its parent's
    into ``work[0]``."""
    root_m, child, box, slab, data, m_nets, m_cells, cnt = mem
    if data[node] >= 0:
        return m_nets, data[node]
    _split_off_parent(node, parent, mem, work.reshape((work.shape[0], 16, 3)), 0)
    return work, np.int64(0)


@leaf_njit
def _expand_cells(node, g, i, j, depth, root, nk, fr, sides, srow, samples, mem, lv):
    """Split memo node ``node`` (g, i, j) of level ``depth - 1`` into its four cells: the
    six grid points of its corners and side midpoints (:func:`grid_point`, the points every
    cell of the patch shares bit for bit) into the cells' rows of the memo, each cell's box
    the box of its three corners (the micro-triangle the rays test, snapped sides
    included), its fourth row's first entry 0 until a ray tests it. No net is split: the
    nets of cells are never needed. Returns the first child, or -1 when a store is full.
    ``lv`` (>= 6, 3) is scratch."""
    root_m, child, box, slab, data, m_nets, m_cells, cnt = mem
    if cnt[M_NODES] + 4 > len(child) or cnt[M_CELLS] + 4 > len(m_cells) // 4:
        cnt[M_FULL] = 1
        return -1
    # lv rows: 0 A, 1 A + 2g (1,0), 2 A + 2g (0,1), 3 A + g (1,0), 4 A + g (0,1), 5 A + g (1,1)
    for k in range(6):
        a = i + g * (2 if k == 1 else (1 if k == 3 or k == 5 else 0))
        b = j + g * (2 if k == 2 else (1 if k == 4 or k == 5 else 0))
        lv[k, 0], lv[k, 1], lv[k, 2] = grid_point(root, nk, a, b, depth, fr, sides, srow,
                                                  samples)
    first = cnt[M_NODES]
    for q in range(4):  # Loop's child order (_child); corners A, A + g (1,0), A + g (0,1)
        r = cnt[M_CELLS]
        cnt[M_CELLS] = r + 1
        for c in range(3):
            k = _CELL_CORNER[q][c]
            m_cells[4 * r + c, 0] = lv[k, 0]
            m_cells[4 * r + c, 1] = lv[k, 1]
            m_cells[4 * r + c, 2] = lv[k, 2]
        m_cells[4 * r + 3, 0] = 0.0  # (tested yet)
        lo0 = min(m_cells[4 * r, 0], m_cells[4 * r + 1, 0], m_cells[4 * r + 2, 0])
        lo1 = min(m_cells[4 * r, 1], m_cells[4 * r + 1, 1], m_cells[4 * r + 2, 1])
        lo2 = min(m_cells[4 * r, 2], m_cells[4 * r + 1, 2], m_cells[4 * r + 2, 2])
        hi0 = max(m_cells[4 * r, 0], m_cells[4 * r + 1, 0], m_cells[4 * r + 2, 0])
        hi1 = max(m_cells[4 * r, 1], m_cells[4 * r + 1, 1], m_cells[4 * r + 2, 1])
        hi2 = max(m_cells[4 * r, 2], m_cells[4 * r + 1, 2], m_cells[4 * r + 2, 2])
        lo0, lo1, lo2, hi0, hi1, hi2 = pad_box(lo0, lo1, lo2, hi0, hi1, hi2)
        new_node(child, box, data, cnt, lo0, lo1, lo2, hi0, hi1, hi2, r)
    child[node] = first
    return first


# the six points of _expand_cells (rows of lv) at each child's corners A, A + g' (1, 0),
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
    """Closest hit on the Loop item ``it`` (its quartic net ``nets[nk]``, grid depth
    ``depth``, frame ``fr`` = (g, oi, oj, sh), :func:`grid_point`: a regular patch is
    (1, 0, 0, depth); side sampling ``sides[it]`` and side samples ``samples``) nearer than
    hit[H_T]; updates ``hit``.
    The ray descends the patch's 1-to-4 splits nearest first into the nodes whose boxes it
    enters; a node is split (its children's boxes and nets stored) once per thread, a cell's
    corners evaluated once, in the thread's memo ``mem`` (``trace/bezier.py``; a cell keeps 3
    of its 4 corner rows); when a store is full the ray goes on splitting per ray
    (:func:`descend_tri`). Returns the micro-triangles built: cells this ray was the first of
    its thread to evaluate, and those it evaluated per ray."""
    ox, oy, oz, ix, iy, iz, kx, ky, kz, sx, sy, sz, dx, dy, dz = ray
    work, st, st_t, tmp_t, order, lv, lp = scratch
    root_m, child, box, slab, data, m_nets, m_cells, cnt = mem
    root = nets.reshape((nets.shape[0], 16, 3))
    node = root_m[it]
    if node < 0:
        if cnt[M_NODES] + 1 > len(child) or cnt[M_NETS] + 1 > len(m_nets) or fr[3] == 0:
            if fr[3] > 0:
                cnt[M_FULL] = 1
            zero = np.int64(0)
            n_t = descend_tri(ray, nets, nk, fr[0], fr[1], fr[2], depth - fr[3], nets, nk,
                              depth, fr, sides, it, samples, slack, hit, code, it, work, st,
                              st_t, zero, tmp_t, order, lv)
            if fr[3] > 0 or node == NOT_YET:  # a one-cell item counts once per thread
                if fr[3] == 0:
                    root_m[it] = COUNTED
                return n_t
            return 0
        row = cnt[M_NETS]
        cnt[M_NETS] = row + 1
        copy_net(m_nets, row, nets, nk)
        node = cnt[M_NODES]
        cnt[M_NODES] = node + 1
        child[node] = -1
        data[node] = row
        root_m[it] = node
    # stack rows: node, orientation, i, j, level, parent; st_t: entry distance when pushed
    st[0, 0], st[0, 1], st[0, 2], st[0, 3], st[0, 4] = node, fr[0], fr[1], fr[2], depth - fr[3]
    st[0, 5] = -1
    st_t[0] = 0.0
    sp = 1
    tested = 0
    while sp > 0:
        sp -= 1
        if st_t[sp] >= hit[H_T]:  # a nearer hit was found since it was pushed
            continue
        node, g, i, j, lev = st[sp, 0], st[sp, 1], st[sp, 2], st[sp, 3], st[sp, 4]
        parent = st[sp, 5]
        if lev == depth:  # a cell (its corners evaluated when its parent was split)
            r = data[node]
            if m_cells[4 * r + 3, 0] == 0.0:  # the first ray of the memo to test it
                m_cells[4 * r + 3, 0] = 1.0
                tested += 1
            _tri_hit(ox, oy, oz, kx, ky, kz, sx, sy, sz, m_cells, 4 * r, i, j, g, depth,
                     slack, hit, code, it)
            continue
        c = child[node]
        if c < 0:
            if lev + 1 == depth:
                c = _expand_cells(node, g, i, j, depth, root, nk, fr, sides, it, samples, mem,
                                  lv)
            else:
                c = _expand_tri(node, parent, lev, depth, mem, work)
            if c < 0:  # a store is full: split per ray below this node
                src, row = _node_net(node, parent, mem, work)
                tested += descend_tri(ray, src, row, g, i, j, lev, nets, nk, depth, fr, sides,
                                      it, samples, slack, hit, code, it, work, st, st_t,
                                      sp + 1, tmp_t, order, lv)
                continue
        # the children the ray enters, pushed far to near (a cell's box is its triangle's)
        n = 0
        hh = g * (1 << (depth - lev - 1))  # half the node's side, signed
        for q in range(4):
            cg, ci, cj = _child(g, i, j, lev, depth, q)
            if lev + 1 < depth and _snapped_node(ci, cj, cg * abs(hh), lev + 1, depth, sides,
                                                 it):
                if sides[it, 3] >= 0:  # (see _push_children)
                    te = _snapped_entry(ox, oy, oz, ix, iy, iz, box[c + q, 0], box[c + q, 1],
                                        box[c + q, 2], box[c + q, 3], box[c + q, 4],
                                        box[c + q, 5], ci, cj, cg * abs(hh), lev + 1, depth,
                                        sides, it, samples, hit[H_T])
                else:
                    te = st_t[sp]
            else:
                te = slab_entry(ox, oy, oz, ix, iy, iz, box[c + q, 0], box[c + q, 1],
                                box[c + q, 2], box[c + q, 3], box[c + q, 4], box[c + q, 5],
                                0.0, hit[H_T])
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
    _tri_hit(ox, oy, oz, kx, ky, kz, sx, sy, sz, cells, 4 * c, gi, gj, g, depth, slack, hit,
             code, item)


def tri_nets_as_pieces(nets15: np.ndarray) -> np.ndarray:
    """(m,4,4,3) store rows holding the (m,15,3) triangular nets (the 16th point repeats
    the 15th, so a box over all 16 is the net's)."""
    out = np.empty((len(nets15), 16, 3))
    out[:, :N_TRI] = nets15
    out[:, N_TRI] = nets15[:, N_TRI - 1]
    return out.reshape(-1, 4, 4, 3)

