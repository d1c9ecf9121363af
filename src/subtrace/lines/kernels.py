"""Line / surface intersection kernels: every hit of many lines with a set of Bezier items.

An *item* is a Bezier net over part of some patch's parameters, of one of two kinds:

* a bicubic net (4,4,3) over a square (Catmull-Clark): a regular patch, a regular piece of
  an isolated irregular patch, or (degree-elevated bilinear) an exact-limit-point cell next
  to an extraordinary vertex;
* a quartic triangular net (15,3) over a triangle (Loop, :mod:`subtrace.patches.basis`):
  a regular box-spline patch or piece, or (degree-elevated linear) an exact-limit-point
  cell.

Items sit in a BVH over their boxes. Item ``i`` is quad ``i`` for ``i < len(nets)``, else
triangle ``i - len(nets)``. Per line (nothing is stored between lines):

1. BVH traversal with the line (a parameter interval, possibly infinite both ways) against
   boxes padded by ``touch_tol``, nearer child first.
2. Inside an item, the paper's multi-level 1-to-4 segmentation, lazily: a sub-net (de
   Casteljau halving, on a stack) whose padded box the line misses is dropped; one the line
   enters is split again until it is *flat*: its patch lies within ``tol_flat`` of its
   corner triangles. For a bicubic net

       flatness = max_ij |b_ij - L(i/3, j/3)|  +  |b00 - b30 - b03 + b33| / 4

   ``L`` is the bilinear interpolant of the corners. ``L`` is itself a bicubic Bezier patch
   with control points ``L(i/3, j/3)`` (degree elevation), so the patch minus ``L`` has
   control points ``b_ij - L(i/3, j/3)`` and by the convex-hull property lies within the
   first term of ``L``; the second bounds ``|L - T|`` for the two corner triangles ``T``
   (``L - T = -t (1 - s) twist``). Both terms are second differences: each halving divides
   them by about 4, so the depth is about ``log4(flatness(root) / tol_flat)``. A triangular
   net has the same bound without the twist (:func:`~subtrace.patches.basis.tri_flatness`).
   Children are visited nearest first (entry into their boxes).
3. At a flat leaf: the corner triangles (watertight test) seed Newton on the exact net
   (unknowns s, t, line parameter); a root inside the item (up to ``PARAM_SLACK``) is a
   *crossing*. If Newton fails, the triangle hit itself is kept (within ``tol_flat`` of the
   surface). Without a crossing, Newton (full Hessian) minimises the line's distance to the
   net; a minimum inside the leaf within ``touch_tol`` is a *touch* (a tangent contact). On
   a cell (a flat stand-in within ``tol_flat`` of the surface) a touch must be within
   ``touch_tol - tol_flat``, so the surface is within ``touch_tol`` of the line there.
4. With ``first``, a crossing at ``t`` stops the descent into boxes entered beyond ``t``
   plus the distance within which :func:`merge_candidates` could still merge a later
   candidate into it (``2 touch_tol / |cos|`` along the line).
5. :func:`merge_candidates` turns each line's candidates into hits: see its docstring.

Candidates are rows of ``N_FIELDS`` float64 (``C_*`` columns) in a per-line buffer of
``cap`` rows; ``count`` may exceed ``cap`` (then the caller runs the line again, larger).
"""

from __future__ import annotations

import math

import numpy as np

from subtrace import config
from subtrace.accel.bvh import box_entry, bvh_next_leaf, bvh_start, slab_entry, traversal_stack
from subtrace.patches.basis import (
    N_TRI, TRI_MONO, bez_eval, copy_net as _copy_net, net_box, net_flatness,
    split_net as _split, tri_box, tri_flatness, tri_mono_eval, tri_monomials, tri_split,
)
from subtrace.runtime.jit import leaf_njit, nb
from subtrace.geometry.prims import push_sorted, ray_triangle, shear

# Deepest halving of an item: the renderer's floating-point limit (config.PRECISION_BITS:
# 2^-40 of its side is below what the descent's padded boxes resolve).
MAX_DEPTH = config.PRECISION_BITS
# Work nets on the descent stack: each level keeps at most 3 siblings, plus 10 for splitting.
STACK_NETS = 3 * MAX_DEPTH + 16
# Newton iterations for a crossing / for a touch.
NEWTON_ITERS = 16
# A root found from a leaf counts if it lies within this much (in the leaf's parameter
# units) of the item: roots on a shared side are found from both sides and merged.
PARAM_SLACK = 1e-6
# Newton for touches is damped by this fraction of the normal matrix's trace, so a line
# lying in a flat region (a singular problem) still takes finite steps.
GN_DAMPING = 1e-12
# With ``first``, crossings this close to tangent (|cos| of normal and line) stop the
# descent as if they were at this cosine (the merge distance grows as 1/|cos|).
FIRST_MIN_COS = 1e-3

N_FIELDS = 8
C_T, C_ITEM, C_A, C_B, C_KIND, C_COS, C_DIST, C_SIZE = range(N_FIELDS)
KIND_CROSS = 1.0
KIND_TOUCH = 2.0


@leaf_njit
def _eval(tri, w, q, mono, s, t, out, second):
    """:func:`~subtrace.patches.basis.bez_eval` of quad net ``w[q]``, or the triangle net
    whose monomial coefficients are ``mono`` (``tri``)."""
    if tri:
        tri_mono_eval(mono, s, t, out, second)
    else:
        bez_eval(w, q, s, t, out, second)


@leaf_njit
def _newton_cross(tri, w, q, mono, D, s, t, tau, o0, o1, o2, d0, d1, d2, res_tol):
    """Newton on S(s, t) = o + tau d for the leaf's net; returns (ok, s, t, tau)."""
    for _ in range(NEWTON_ITERS):
        _eval(tri, w, q, mono, s, t, D, False)
        r0 = D[0, 0] - o0 - tau * d0
        r1 = D[0, 1] - o1 - tau * d1
        r2 = D[0, 2] - o2 - tau * d2
        su0, su1, su2 = D[1, 0], D[1, 1], D[1, 2]
        sv0, sv1, sv2 = D[2, 0], D[2, 1], D[2, 2]
        # solve [su sv -d] (ds dt dtau) = -r by Cramer's rule
        c0, c1, c2 = -d0, -d1, -d2
        det = (su0 * (sv1 * c2 - sv2 * c1) - sv0 * (su1 * c2 - su2 * c1)
               + c0 * (su1 * sv2 - su2 * sv1))
        if det == 0.0 or det != det:
            return False, s, t, tau
        b0, b1, b2 = -r0, -r1, -r2
        ds = (b0 * (sv1 * c2 - sv2 * c1) - sv0 * (b1 * c2 - b2 * c1)
              + c0 * (b1 * sv2 - b2 * sv1)) / det
        dt = (su0 * (b1 * c2 - b2 * c1) - b0 * (su1 * c2 - su2 * c1)
              + c0 * (su1 * b2 - su2 * b1)) / det
        dtau = (su0 * (sv1 * b2 - sv2 * b1) - sv0 * (su1 * b2 - su2 * b1)
                + b0 * (su1 * sv2 - su2 * sv1)) / det
        s += ds
        t += dt
        tau += dtau
        if abs(s) > 4.0 or abs(t) > 4.0:  # left the leaf's neighbourhood: not its root
            return False, s, t, tau
    _eval(tri, w, q, mono, s, t, D, False)
    r0 = D[0, 0] - o0 - tau * d0
    r1 = D[0, 1] - o1 - tau * d1
    r2 = D[0, 2] - o2 - tau * d2
    return math.sqrt(r0 * r0 + r1 * r1 + r2 * r2) <= res_tol, s, t, tau


@leaf_njit
def _closest(tri, w, q, mono, D, s, t, o0, o1, o2, e0, e1, e2):
    """Newton minimum of the distance from the leaf's patch to the line through o with unit
    direction e (gradient of |r_perp|^2 / 2 with its full Hessian; damped, and Gauss-Newton
    where the Hessian is not positive), started at (s, t); returns (s, t, distance, tau)."""
    for _ in range(NEWTON_ITERS):
        _eval(tri, w, q, mono, s, t, D, True)
        rx, ry, rz = D[0, 0] - o0, D[0, 1] - o1, D[0, 2] - o2
        p = rx * e0 + ry * e1 + rz * e2
        rx, ry, rz = rx - p * e0, ry - p * e1, rz - p * e2
        pu = D[1, 0] * e0 + D[1, 1] * e1 + D[1, 2] * e2
        ux, uy, uz = D[1, 0] - pu * e0, D[1, 1] - pu * e1, D[1, 2] - pu * e2
        pv = D[2, 0] * e0 + D[2, 1] * e1 + D[2, 2] * e2
        vx, vy, vz = D[2, 0] - pv * e0, D[2, 1] - pv * e1, D[2, 2] - pv * e2
        a = ux * ux + uy * uy + uz * uz
        b = ux * vx + uy * vy + uz * vz
        c = vx * vx + vy * vy + vz * vz
        g0 = -(ux * rx + uy * ry + uz * rz)
        g1 = -(vx * rx + vy * ry + vz * rz)
        lam = GN_DAMPING * (a + c) + 1e-300
        # the full Hessian adds r_perp . second derivatives
        ha = a + rx * D[3, 0] + ry * D[3, 1] + rz * D[3, 2] + lam
        hb = b + rx * D[4, 0] + ry * D[4, 1] + rz * D[4, 2]
        hc = c + rx * D[5, 0] + ry * D[5, 1] + rz * D[5, 2] + lam
        det = ha * hc - hb * hb
        if not (ha > 0.0 and det > 0.0):
            ha, hb, hc = a + lam, b, c + lam  # Gauss-Newton: always a descent direction
            det = ha * hc - hb * hb
        if det <= 0.0 or det != det:
            break
        ds = (hc * g0 - hb * g1) / det
        dt = (ha * g1 - hb * g0) / det
        s = min(max(s + ds, -0.5), 1.5)
        t = min(max(t + dt, -0.5), 1.5)
        if abs(ds) + abs(dt) < 1e-14:
            break
    _eval(tri, w, q, mono, s, t, D, False)
    rx, ry, rz = D[0, 0] - o0, D[0, 1] - o1, D[0, 2] - o2
    p = rx * e0 + ry * e1 + rz * e2
    rx, ry, rz = rx - p * e0, ry - p * e1, rz - p * e2
    return s, t, math.sqrt(rx * rx + ry * ry + rz * rz), p


@leaf_njit
def _push(cand, line, n, cap, t, item, a, b, kind, cs, dist, size):
    if n < cap:
        cand[line, n, C_T] = t
        cand[line, n, C_ITEM] = item
        cand[line, n, C_A] = a
        cand[line, n, C_B] = b
        cand[line, n, C_KIND] = kind
        cand[line, n, C_COS] = cs
        cand[line, n, C_DIST] = dist
        cand[line, n, C_SIZE] = size
    return n + 1


@leaf_njit
def _unit_normal_cos(tri, w, q, mono, D, s, t, e0, e1, e2):
    """Cosine between the unit normal of the leaf's patch at (s, t) and the direction e."""
    _eval(tri, w, q, mono, s, t, D, False)
    nx = D[1, 1] * D[2, 2] - D[1, 2] * D[2, 1]
    ny = D[1, 2] * D[2, 0] - D[1, 0] * D[2, 2]
    nz = D[1, 0] * D[2, 1] - D[1, 1] * D[2, 0]
    ln = math.sqrt(nx * nx + ny * ny + nz * nz)
    if ln == 0.0:
        return 0.0
    return (nx * e0 + ny * e1 + nz * e2) / ln


@leaf_njit
def _inside(tri, a, b, slack):
    """Parameters (a, b) inside the unit square (or triangle), up to ``slack``."""
    if tri:
        return a >= -slack and b >= -slack and a + b <= 1.0 + slack
    return a >= -slack and a <= 1.0 + slack and b >= -slack and b <= 1.0 + slack


@leaf_njit
def _clamp(tri, a, b):
    """Parameters (a, b) moved into the unit square (or triangle)."""
    a = min(max(a, 0.0), 1.0)
    b = min(max(b, 0.0), 1.0)
    if tri and a + b > 1.0:
        h = 0.5 * (a + b - 1.0)
        a, b = max(a - h, 0.0), max(b - h, 0.0)
        a, b = min(a, 1.0 - b), b
    return a, b


@leaf_njit
def _leaf(tri, w, wt, q, mono, D, u0, v0, size, item, line, n, cap, cand, verts, ob0, ob1,
          ob2, d0, d1, d2, e0, e1, e2, dlen, kx, ky, kz, sx, sy, sz, tbase, tlo, thi, exact,
          touch_tol, res_tol, slack, cell_tol):
    """Crossings, else a touch, of the line with flat leaf ``q`` (net ``w[q]``, or ``wt[q]``
    with ``tri``; item parameters ``(u0, v0) + size * (s, t)``) (module doc, step 3);
    appends candidates for line ``line`` from row ``n``; returns the new count."""
    if tri:
        tri_monomials(wt, q, TRI_MONO, mono)
        for k in range(3):
            verts[0, k] = wt[q, 0, k]
            verts[1, k] = wt[q, 4, k]
            verts[2, k] = wt[q, N_TRI - 1, k]
        n_verts, n_tris = 3, 1
    else:
        for k in range(3):
            verts[0, k] = w[q, 0, 0, k]
            verts[1, k] = w[q, 3, 0, k]
            verts[2, k] = w[q, 3, 3, k]
            verts[3, k] = w[q, 0, 3, k]
        n_verts, n_tris = 4, 2
    ob = (ob0, ob1, ob2)
    tmax = thi - tbase
    found = False
    diag = 0.0
    for k in range(3):
        lo = hi = verts[0, k]
        for c in range(1, n_verts):
            lo = min(lo, verts[c, k])
            hi = max(hi, verts[c, k])
        diag += (hi - lo) * (hi - lo)
    diag = math.sqrt(diag)
    for tr in range(n_tris):
        c = 2 if tr == 0 else 3
        b_ = 1 if tr == 0 else 2
        th, ba, bb, bc = ray_triangle(ob[kx], ob[ky], ob[kz], kx, ky, kz, sx, sy, sz, 0, b_, c,
                                      verts, tmax, slack)
        if th == np.inf:
            continue
        # leaf parameters of the triangle hit (corners (0,0) (1,0) (1,1) (0,1), or (0,0)
        # (1,0) (0,1))
        if tri:
            s0, t0 = bb, bc
        elif tr == 0:
            s0, t0 = bb + bc, bc
        else:
            s0, t0 = bb, bb + bc
        ok = False
        s, t, tau = s0, t0, th
        if exact:
            # Newton on the exact net; a root outside this leaf but inside the item is as
            # exact (the net is the item's polynomial there): it is kept, and merged with
            # the same root found from its own leaf
            ok, s, t, tau = _newton_cross(tri, w, q, mono, D, s0, t0, th, ob0, ob1, ob2, d0,
                                          d1, d2, res_tol)
            ok = ok and _inside(tri, u0 + size * s, v0 + size * t, PARAM_SLACK)
        inexact = 0.0
        if not ok:
            s, t, tau = s0, t0, th  # the triangle's hit: within tol_flat of the surface
            inexact = 1.0
        tt = tbase + tau
        if tt < tlo or tt > thi:
            continue
        a, b = _clamp(tri, u0 + size * s, v0 + size * t)
        cs = _unit_normal_cos(tri, w, q, mono, D, (a - u0) / size, (b - v0) / size, e0, e1,
                              e2)
        n = _push(cand, line, n, cap, tt, item, a, b, KIND_CROSS, cs, inexact, diag)
        found = True
    if found:
        return n
    mid = 1.0 / 3.0 if tri else 0.5
    if exact:
        # no triangle hit: Newton from the centre still finds a crossing between the
        # triangles and the surface (a line through a gap of at most tol_flat)
        _eval(tri, w, q, mono, mid, mid, D, False)
        tau0 = ((D[0, 0] - ob0) * d0 + (D[0, 1] - ob1) * d1 + (D[0, 2] - ob2) * d2) / (
            dlen * dlen)
        ok, s, t, tau = _newton_cross(tri, w, q, mono, D, mid, mid, tau0, ob0, ob1, ob2, d0,
                                      d1, d2, res_tol)
        if ok and _inside(tri, u0 + size * s, v0 + size * t, PARAM_SLACK):
            tt = tbase + tau
            if tt >= tlo and tt <= thi:
                a, b = _clamp(tri, u0 + size * s, v0 + size * t)
                cs = _unit_normal_cos(tri, w, q, mono, D, (a - u0) / size, (b - v0) / size,
                                      e0, e1, e2)
                return _push(cand, line, n, cap, tt, item, a, b, KIND_CROSS, cs, 0.0, diag)
    # a touch: the closest approach inside the leaf, within touch_tol (of the surface, so
    # of a cell's stand-in by cell_tol less)
    s, t, dist, p = _closest(tri, w, q, mono, D, mid, mid, ob0, ob1, ob2, e0, e1, e2)
    lim = touch_tol if exact else touch_tol - cell_tol
    if dist <= lim and _inside(tri, s, t, PARAM_SLACK):
        tt = tbase + p / dlen
        if tt >= tlo and tt <= thi:
            s, t = _clamp(tri, s, t)
            cs = _unit_normal_cos(tri, w, q, mono, D, s, t, e0, e1, e2)
            n = _push(cand, line, n, cap, tt, item, u0 + size * s, v0 + size * t,
                      KIND_TOUCH, cs, dist, diag)
    return n


@leaf_njit
def _sub_entry(tri, w, wt, q, o0, o1, o2, i0, i1, i2, pad, tlo, thi):
    """Entry of the line into the box of sub-net ``w[q]`` (or ``wt[q]``), inf on a miss."""
    if tri:
        lo0, lo1, lo2, hi0, hi1, hi2 = tri_box(wt, q)
    else:
        lo0, lo1, lo2, hi0, hi1, hi2 = net_box(w, q)
    return slab_entry(o0, o1, o2, i0, i1, i2, lo0 - pad, lo1 - pad, lo2 - pad, hi0 + pad,
                      hi1 + pad, hi2 + pad, tlo, thi)


@leaf_njit
def _copy_sub(tri, w, wt, dst, src):
    """Sub-net ``src`` to stack slot ``dst`` (quad ``w`` or triangle ``wt``)."""
    if tri:
        for p in range(N_TRI):
            for k in range(3):
                wt[dst, p, k] = wt[src, p, k]
    else:
        _copy_net(w, dst, w, src)


# lines_task is one kernel (about 140 lines) and is not split: the item descent shares some
# twenty scratch arrays and the line's set-up (base point, shear, cut-off) with the BVH walk
# around it, and a call per item taking them all would pass every array's fields on the
# stack (the cost jit.inline_njit exists to avoid). Each step carries a comment instead.
@nb.njit(cache=True, nogil=True, error_model="numpy")
def lines_task(task, n_tasks, org, dirs, t_lo, t_hi, nets, tnets, exact, item_min, item_max,
               bvh, tol_flat, touch_tol, res_tol, first, cap, cand, count, stats):
    """Candidates of lines ``task, task + n_tasks, ...`` (module doc). ``org``, ``dirs`` (L,3);
    ``nets`` (Q,4,4,3) quad items, ``tnets`` (T,15,3) triangle items (item ``Q + i``),
    ``exact`` (Q+T,) bool
    (False: a flat cell, no Newton), ``item_min/max`` (Q+T,3) boxes and ``bvh`` over them
    (:class:`~subtrace.accel.bvh.BVH`), both padded by ``touch_tol`` (``bvh.padded``); ``first``: stop as module doc step 4; ``cand`` (L,
    cap, N_FIELDS) out, ``count`` (L,) out; ``stats`` (L, 2) out: items entered, leaves reached."""
    slack = config.TRI_SLACK
    n_quad = len(nets)
    w = np.empty((STACK_NETS, 4, 4, 3))
    wt = np.empty((STACK_NETS, N_TRI, 3))
    su0 = np.empty(STACK_NETS)
    sv0 = np.empty(STACK_NETS)
    ssz = np.empty(STACK_NETS)
    sent = np.empty(STACK_NETS)
    sdep = np.empty(STACK_NETS, np.int64)
    nodes, nodes_t = traversal_stack()
    verts = np.empty((4, 3))
    mono = np.empty((N_TRI, 3))
    D = np.empty((6, 3))
    kid_t = np.empty(4)
    kid_order = np.empty(4, np.int64)
    for line in range(task, len(org), n_tasks):
        n = 0
        entered = 0
        leaves = 0
        o0, o1, o2 = org[line, 0], org[line, 1], org[line, 2]
        d0, d1, d2 = dirs[line, 0], dirs[line, 1], dirs[line, 2]
        dlen = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        e0, e1, e2 = d0 / dlen, d1 / dlen, d2 / dlen
        i0, i1, i2 = 1.0 / d0, 1.0 / d1, 1.0 / d2
        tlo, thi = t_lo, t_hi
        tcut = thi  # boxes entered beyond tcut are skipped (``first``)
        count[line] = 0
        stats[line, 0] = 0
        stats[line, 1] = 0
        if len(bvh.node_first) == 0:
            continue
        # a base point on the line before every item: the triangle tests measure t from it
        # (one origin per line keeps them watertight on shared edges)
        if tlo > -np.inf:
            tbase = tlo
        else:
            tn = -np.inf
            for k in range(3):
                dk = dirs[line, k]
                if dk != 0.0:
                    a = (bvh.node_min[0, k] - org[line, k]) / dk  # (padded boxes)
                    b = (bvh.node_max[0, k] - org[line, k]) / dk
                    tn = max(tn, min(a, b))
            if tn == -np.inf:
                tn = 0.0
            tbase = tn - 1.0 - abs(tn) * 1e-9
        ob0, ob1, ob2 = o0 + tbase * d0, o1 + tbase * d1, o2 + tbase * d2
        kx, ky, kz, sx, sy, sz = shear(d0, d1, d2)
        # BVH traversal over item boxes, nearer child first
        top = bvh_start(o0, o1, o2, i0, i1, i2, bvh, tlo, thi, nodes, nodes_t)
        at = end = np.int64(0)  # the current leaf's range of bvh.prims
        while True:
            if at == end:
                at, end, top = bvh_next_leaf(o0, o1, o2, i0, i1, i2, bvh, tlo, tcut, nodes,
                                             nodes_t, top)
                if at == end:
                    break
            it = bvh.prims[at]
            at += 1
            te = box_entry(o0, o1, o2, i0, i1, i2, item_min, item_max, it, tlo, tcut)
            if te == np.inf:
                continue
            entered += 1
            # 1-to-4 segmentation of the item, on a stack of nets, nearest child first
            tri = it >= n_quad
            if tri:
                for p in range(N_TRI):
                    for k in range(3):
                        wt[0, p, k] = tnets[it - n_quad, p, k]
            else:
                _copy_net(w, 0, nets, it)
            su0[0], sv0[0], ssz[0], sdep[0], sent[0] = 0.0, 0.0, 1.0, 0, te
            sp = 1
            while sp > 0:
                q = sp - 1
                sp = q
                if sent[q] > tcut:
                    continue
                flat = tri_flatness(wt, q) if tri else net_flatness(w, q)
                if sdep[q] >= MAX_DEPTH or flat <= tol_flat:
                    leaves += 1
                    n0 = n
                    n = _leaf(tri, w, wt, q, mono, D, su0[q], sv0[q], ssz[q], it, line, n,
                              cap, cand, verts, ob0, ob1, ob2, d0, d1, d2, e0, e1, e2,
                              dlen, kx, ky, kz, sx, sy, sz, tbase, tlo, thi, exact[it],
                              touch_tol, res_tol, slack, tol_flat)
                    if first:
                        for i in range(n0, min(n, cap)):
                            if cand[line, i, C_KIND] == KIND_CROSS:
                                cs = max(abs(cand[line, i, C_COS]), FIRST_MIN_COS)
                                tcut = min(tcut, cand[line, i, C_T]
                                           + 2.0 * touch_tol / (cs * dlen))
                    continue
                # the children: quads into q+6 .. q+9 (scratch q+4, q+5), triangles into
                # q+4 .. q+7; those the line enters go back to q, q+1, .. farthest first
                d_kids = q + 4 if tri else q + 6
                if tri:
                    tri_split(wt, q, d_kids)
                else:
                    _split(w, q, w, d_kids)
                h = 0.5 * ssz[q]
                u, v, dep = su0[q], sv0[q], sdep[q] + 1
                m = 0
                for ch in range(4):
                    tk = _sub_entry(tri, w, wt, d_kids + ch, o0, o1, o2, i0, i1, i2,
                                    touch_tol, tlo, tcut)
                    if tk < np.inf:  # kept in descending entry
                        m = push_sorted(kid_t, kid_order, m, tk, ch)
                for j in range(m):
                    ch = kid_order[j]
                    _copy_sub(tri, w, wt, sp, d_kids + ch)
                    if tri:
                        # Loop's child order; child 3 (the middle) turned half a turn
                        su0[sp] = u + h * (ch == 1 or ch == 3)
                        sv0[sp] = v + h * (ch == 2 or ch == 3)
                        ssz[sp] = -h if ch == 3 else h
                    else:
                        su0[sp] = u + h * (ch & 1)
                        sv0[sp] = v + h * (ch >> 1)
                        ssz[sp] = h
                    sdep[sp] = dep
                    sent[sp] = kid_t[j]
                    sp += 1
        count[line] = n
        stats[line, 0] = entered
        stats[line, 1] = leaves


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _preferred(c, i, j, ptex):
    """Whether duplicate crossing ``c[i]`` is kept rather than ``c[j]`` (the nearer one):
    an exact root over a triangle's hit; of two of the same kind, the lower ptex face."""
    if c[i, C_DIST] != c[j, C_DIST]:
        return c[i, C_DIST] < c[j, C_DIST]
    return ptex[int(c[i, C_ITEM])] < ptex[int(c[j, C_ITEM])]


@nb.njit(cache=True, nogil=True, error_model="numpy")
def merge_candidates(cand, count, dlen, precision, keep, tangent, ptex):
    """Turn each line's candidates into hits, in place: sort by t; then

    * crossings (C_DIST 0: Newton's exact root, 1: a triangle's hit, kept only where no
      root is) whose points lie within ``precision`` of each other are one hit (a hit on a
      side or corner shared by leaves or patches is found from each of them): with the same
      orientation (sign of normal . direction) they are duplicates; with opposite ones the
      line enters and leaves within ``precision``: one hit, tangent. Of duplicates the
      exact root is kept, and of two exact roots the one on the lower ptex face
      (``ptex[item]``), then the nearer: the choice depends on the line alone, not on
      which other lines were asked with it (they change which items exist and their order);
    * a touch whose point lies within ``precision`` of the tangent plane of a crossing is
      part of that crossing (the line runs that close to the surface there) and is dropped;
    * touches in a run (each within the two leaves' sizes of the next) are one contact: the
      closest is kept, tangent (a tangent line, or a line lying in a flat region).

    ``keep[line, i]`` says which of the sorted rows are hits; ``tangent[line, i]`` flags."""
    for line in range(len(count)):
        n = min(count[line], cand.shape[1])
        c = cand[line]
        # insertion sort by t (few candidates per line)
        for i in range(1, n):
            j = i
            while j > 0 and c[j - 1, C_T] > c[j, C_T]:
                for f in range(N_FIELDS):
                    tmp = c[j - 1, f]
                    c[j - 1, f] = c[j, f]
                    c[j, f] = tmp
                j -= 1
        L = dlen[line]
        for i in range(n):
            keep[line, i] = True
            tangent[line, i] = False
        # duplicate and grazing crossings
        last = -1
        for i in range(n):
            if c[i, C_KIND] != KIND_CROSS:
                continue
            if last >= 0:
                gap = (c[i, C_T] - c[last, C_T]) * L
                same = (c[i, C_COS] > 0.0) == (c[last, C_COS] > 0.0)
                if gap <= precision or (same and gap * min(abs(c[i, C_COS]),
                                                            abs(c[last, C_COS])) <= precision):
                    # the same crossing (a side's root found twice, or a triangle's hit
                    # beside the root, within precision of the tangent plane); or, with
                    # opposite orientations, the line enters and leaves within precision
                    if not same:
                        tangent[line, last] = True
                    if _preferred(c, i, last, ptex):
                        # keep the exact root (Newton's) rather than a triangle's hit
                        keep[line, last] = False
                        tangent[line, i] = tangent[line, last]
                        last = i
                    else:
                        keep[line, i] = False
                    continue
            last = i
        # touches absorbed by crossings
        for i in range(n):
            if c[i, C_KIND] != KIND_TOUCH:
                continue
            for j in range(n):
                if c[j, C_KIND] == KIND_CROSS and keep[line, j]:
                    if abs(c[i, C_T] - c[j, C_T]) * L * abs(c[j, C_COS]) <= precision:
                        keep[line, i] = False
                        break
        # runs of touches: keep the closest of each
        best = -1
        prev = -1
        for i in range(n):
            if c[i, C_KIND] != KIND_TOUCH or not keep[line, i]:
                continue
            if prev >= 0 and (c[i, C_T] - c[prev, C_T]) * L <= (
                    c[i, C_SIZE] + c[prev, C_SIZE] + precision):
                if c[i, C_DIST] < c[best, C_DIST]:
                    keep[line, best] = False
                    best = i
                else:
                    keep[line, i] = False
            else:
                best = i
            prev = i
            tangent[line, i] = True



@nb.njit(cache=True, nogil=True, error_model="numpy")
def mark_shells(org, dirs, t_lo, t_hi, box_min, box_max, bvh, done, hit):
    """``hit[i] = True`` for every box ``i`` (``box_min/max`` (B,3), under ``bvh``, a
    :class:`~subtrace.accel.bvh.BVH` of them, all padded by the caller) that one of the
    lines meets within [t_lo, t_hi]; boxes with ``done[i]`` are skipped."""
    nodes, nodes_t = traversal_stack()
    for line in range(len(org)):
        o0, o1, o2 = org[line, 0], org[line, 1], org[line, 2]
        i0, i1, i2 = 1.0 / dirs[line, 0], 1.0 / dirs[line, 1], 1.0 / dirs[line, 2]
        top = bvh_start(o0, o1, o2, i0, i1, i2, bvh, t_lo, t_hi, nodes, nodes_t)
        while top > 0:
            at, end, top = bvh_next_leaf(o0, o1, o2, i0, i1, i2, bvh, t_lo, t_hi, nodes,
                                         nodes_t, top)
            for r in range(at, end):
                b = bvh.prims[r]
                if done[b] or hit[b]:
                    continue
                hit[b] = box_entry(o0, o1, o2, i0, i1, i2, box_min, box_max, b, t_lo,
                                   t_hi) < np.inf
