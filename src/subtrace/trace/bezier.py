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
cell, inside its box; boxes are widened by a relative ``BOX_PAD`` for rounding.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .prims import H_B1, H_B2, H_LEAF, H_SLOT, H_T, H_TRI, _tri, push_sorted, slab_bounds

BOX_PAD = 1e-12
MAX_SIDE_SAMPLES = 256  # samples per cell side at most (2^(side depth - depth))


@nb.njit(cache=True)
def _bez_point(net, u, v):
    """Point of the Bezier patch ``net`` (4,4,3) at (u, v): one code path for every caller."""
    su = 1.0 - u
    sv = 1.0 - v
    bu0, bu1, bu2, bu3 = su * su * su, 3.0 * u * su * su, 3.0 * u * u * su, u * u * u
    bv0, bv1, bv2, bv3 = sv * sv * sv, 3.0 * v * sv * sv, 3.0 * v * v * sv, v * v * v
    x = y = z = 0.0
    for a in range(4):
        ba = bu0 if a == 0 else (bu1 if a == 1 else (bu2 if a == 2 else bu3))
        cx = bv0 * net[a, 0, 0] + bv1 * net[a, 1, 0] + bv2 * net[a, 2, 0] + bv3 * net[a, 3, 0]
        cy = bv0 * net[a, 0, 1] + bv1 * net[a, 1, 1] + bv2 * net[a, 2, 1] + bv3 * net[a, 3, 1]
        cz = bv0 * net[a, 0, 2] + bv1 * net[a, 1, 2] + bv2 * net[a, 2, 2] + bv3 * net[a, 3, 2]
        x += ba * cx
        y += ba * cy
        z += ba * cz
    return x, y, z


@nb.njit(cache=True)
def bez_derivatives(net, u, v):
    """dP/du and dP/dv of the Bezier patch ``net`` at (u, v): two 3-tuples."""
    su = 1.0 - u
    sv = 1.0 - v
    bu = (su * su * su, 3.0 * u * su * su, 3.0 * u * u * su, u * u * u)
    bv = (sv * sv * sv, 3.0 * v * sv * sv, 3.0 * v * v * sv, v * v * v)
    du = (-3.0 * su * su, 3.0 * su * (su - 2.0 * u), 3.0 * u * (2.0 * su - u), 3.0 * u * u)
    dv = (-3.0 * sv * sv, 3.0 * sv * (sv - 2.0 * v), 3.0 * v * (2.0 * sv - v), 3.0 * v * v)
    ux = uy = uz = vx = vy = vz = 0.0
    for a in range(4):
        for c in range(4):
            wu = du[a] * bv[c]
            wv = bu[a] * dv[c]
            ux += wu * net[a, c, 0]
            uy += wu * net[a, c, 1]
            uz += wu * net[a, c, 2]
            vx += wv * net[a, c, 0]
            vy += wv * net[a, c, 1]
            vz += wv * net[a, c, 2]
    return (ux, uy, uz), (vx, vy, vz)


@nb.njit(cache=True)
def _split_row(a, b, c, d):
    ab = 0.5 * (a + b)
    bc = 0.5 * (b + c)
    cd = 0.5 * (c + d)
    abc = 0.5 * (ab + bc)
    bcd = 0.5 * (bc + cd)
    m = 0.5 * (abc + bcd)
    return ab, abc, m, bcd, cd


@nb.njit(cache=True)
def _split(w, s, d0):
    """Write the four child nets of net ``w[s]`` into ``w[d0 .. d0+3]`` (child ``cu + 2 cv``
    covers the half cu in u and cv in v), using ``w[d0-2]``, ``w[d0-1]`` as scratch."""
    h0 = d0 - 2
    for c in range(4):  # halve along u (first index)
        for k in range(3):
            p0, p1, p2, p3 = w[s, 0, c, k], w[s, 1, c, k], w[s, 2, c, k], w[s, 3, c, k]
            ab, abc, m, bcd, cd = _split_row(p0, p1, p2, p3)
            w[h0, 0, c, k], w[h0, 1, c, k], w[h0, 2, c, k], w[h0, 3, c, k] = p0, ab, abc, m
            w[h0 + 1, 0, c, k], w[h0 + 1, 1, c, k], w[h0 + 1, 2, c, k], w[h0 + 1, 3, c, k] = m, bcd, cd, p3
    for h in range(2):  # then along v
        src = h0 + h
        lo = d0 + h
        hi = d0 + h + 2
        for a in range(4):
            for k in range(3):
                p0, p1, p2, p3 = w[src, a, 0, k], w[src, a, 1, k], w[src, a, 2, k], w[src, a, 3, k]
                ab, abc, m, bcd, cd = _split_row(p0, p1, p2, p3)
                w[lo, a, 0, k], w[lo, a, 1, k], w[lo, a, 2, k], w[lo, a, 3, k] = p0, ab, abc, m
                w[hi, a, 0, k], w[hi, a, 1, k], w[hi, a, 2, k], w[hi, a, 3, k] = m, bcd, cd, p3


@nb.njit(cache=True)
def _net_entry(ox, oy, oz, ix, iy, iz, net, s, tmax):
    """Entry distance of the ray into the (padded) box of net ``net[s]``; inf on a miss."""
    lo0 = lo1 = lo2 = np.inf
    hi0 = hi1 = hi2 = -np.inf
    for a in range(4):
        for c in range(4):
            x, y, z = net[s, a, c, 0], net[s, a, c, 1], net[s, a, c, 2]
            lo0, hi0 = min(lo0, x), max(hi0, x)
            lo1, hi1 = min(lo1, y), max(hi1, y)
            lo2, hi2 = min(lo2, z), max(hi2, z)
    pad = BOX_PAD * max(max(abs(lo0), abs(hi0)), max(max(abs(lo1), abs(hi1)), max(abs(lo2), abs(hi2))))
    return slab_bounds(ox, oy, oz, ix, iy, iz, lo0 - pad, lo1 - pad, lo2 - pad, hi0 + pad,
                       hi1 + pad, hi2 + pad, tmax)


@nb.njit(cache=True)
def _leaf(ox, oy, oz, kx, ky, kz, sx, sy, sz, net, i, j, depth, oi, oj, root_depth,
          side_depth, slack, hit, code, item, lv, lp):
    """Intersect cell (i, j) of the depth-``depth`` grid of Bezier net ``net``, which covers
    the cells from (oi, oj) of its root patch's depth-``root_depth`` grid; update ``hit``
    (H_SLOT = ``code``, H_TRI = ``item``, (H_B1, H_B2) = root parameter). ``lv`` (K,3) /
    ``lp`` (K,2): scratch for the cell's points and root parameters. Returns the number of
    triangles tested."""
    inv = 1.0 / (1 << depth)
    NR = 1 << root_depth
    rinv = 1.0 / NR
    gi = oi + i
    gj = oj + j
    n = 0
    for corner in range(4):
        di = 1 if corner == 1 or corner == 2 else 0
        dj = 1 if corner >= 2 else 0
        x, y, z = _bez_point(net, (i + di) * inv, (j + dj) * inv)
        lv[n, 0], lv[n, 1], lv[n, 2] = x, y, z
        lp[n, 0], lp[n, 1] = (gi + di) * rinv, (gj + dj) * rinv
        n += 1
        # samples of the side that starts at this corner, when the neighbour is finer
        side = corner
        if side == 0:
            on_side = gj == 0
        elif side == 1:
            on_side = gi == NR - 1
        elif side == 2:
            on_side = gj == NR - 1
        else:
            on_side = gi == 0
        if on_side and side_depth[side] > root_depth:
            r = 1 << (side_depth[side] - root_depth)
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
                x, y, z = _bez_point(net, a * inv, b * inv)
                lv[n, 0], lv[n, 1], lv[n, 2] = x, y, z
                lp[n, 0], lp[n, 1] = ga * rinv, gb * rinv
                n += 1
    if n == 4:
        return tri_pair(ox, oy, oz, kx, ky, kz, sx, sy, sz, lv, lp, slack, hit, code, item,
                        root_depth)
    # a fan around the cell's centre
    x, y, z = _bez_point(net, (i + 0.5) * inv, (j + 0.5) * inv)
    lv[n, 0], lv[n, 1], lv[n, 2] = x, y, z
    lp[n, 0], lp[n, 1] = (gi + 0.5) * rinv, (gj + 0.5) * rinv
    o = (ox, oy, oz)
    px, py, pz = o[kx], o[ky], o[kz]
    for k in range(n):
        b = k
        c = k + 1 if k + 1 < n else 0
        t, ba, bb, bc = _tri(px, py, pz, kx, ky, kz, sx, sy, sz, n, b, c, lv, hit[H_T], slack)
        if t < hit[H_T]:
            _record(hit, t, code, item, root_depth, lp, n, b, c, ba, bb, bc)
    return n


@nb.njit(cache=True)
def _record(hit, t, code, item, depth, lp, a, b, c, ba, bb, bc):
    hit[H_T] = t
    hit[H_SLOT] = code
    hit[H_LEAF] = depth
    hit[H_TRI] = item
    hit[H_B1] = ba * lp[a, 0] + bb * lp[b, 0] + bc * lp[c, 0]
    hit[H_B2] = ba * lp[a, 1] + bb * lp[b, 1] + bc * lp[c, 1]


@nb.njit(cache=True)
def tri_pair(ox, oy, oz, kx, ky, kz, sx, sy, sz, lv, lp, slack, hit, code, item, depth):
    """The two triangles (0,1,2), (0,2,3) of the cell ``lv[:4]`` (parameters ``lp``)."""
    o = (ox, oy, oz)
    px, py, pz = o[kx], o[ky], o[kz]
    for tri in range(2):
        b = 1 + tri
        c = 2 + tri
        t, ba, bb, bc = _tri(px, py, pz, kx, ky, kz, sx, sy, sz, 0, b, c, lv, hit[H_T], slack)
        if t < hit[H_T]:
            _record(hit, t, code, item, depth, lp, 0, b, c, ba, bb, bc)
    return 2


@nb.njit(cache=True, inline="always")
def intersect_bezier(ox, oy, oz, ix, iy, iz, kx, ky, kz, sx, sy, sz, net, depth, oi, oj,
                     root_depth, side_depth, slack, hit, code, item, work, st_i, st_j, st_l,
                     tmp_t, order, lv, lp):
    """Closest hit on the Bezier patch ``net`` refined to grid depth ``depth`` (covering the
    root grid cells from (oi, oj), see :func:`_leaf`) nearer than hit[H_T]; updates ``hit``.
    ``work`` (>= 3*depth+7, 4,4,3) holds the stacked nets (the last six are scratch), ``st_*`` their cell coordinates
    and levels. Returns the number of micro-triangles built."""
    tested = 0
    for a in range(4):
        for c in range(4):
            for k in range(3):
                work[0, a, c, k] = net[a, c, k]
    st_i[0] = 0
    st_j[0] = 0
    st_l[0] = 0
    sp = 1
    base = work.shape[0] - 4  # the last four entries receive children before sorting
    while sp > 0:
        sp -= 1
        lev = st_l[sp]
        ci = st_i[sp]
        cj = st_j[sp]
        if lev == depth:
            tested += _leaf(ox, oy, oz, kx, ky, kz, sx, sy, sz, net, ci, cj, depth, oi, oj,
                            root_depth, side_depth, slack, hit, code, item, lv, lp)
            continue
        _split(work, sp, base)
        # the children the ray enters, pushed far to near
        n = 0
        for q in range(4):
            te = _net_entry(ox, oy, oz, ix, iy, iz, work, base + q, hit[H_T])
            if te < np.inf:
                n = push_sorted(tmp_t, order, n, te, q)
        for e in range(n):
            q = order[e]
            for a in range(4):
                for c in range(4):
                    for k in range(3):
                        work[sp, a, c, k] = work[base + q, a, c, k]
            st_i[sp] = 2 * ci + (q & 1)
            st_j[sp] = 2 * cj + (q >> 1)
            st_l[sp] = lev + 1
            sp += 1
    return tested
