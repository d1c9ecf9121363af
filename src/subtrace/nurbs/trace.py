"""Ray / trimmed NURBS patch intersection by per-ray refinement.

Each rational Bezier patch of a :class:`~subtrace.nurbs.model.NurbsModel` is traced as the
renderer traces its other Bezier pieces, after docs/seeds.md sections 3 and 4:

* a ray walks the BVH over the patches' boxes (:mod:`subtrace.accel.bvh`, the one
  near-first traversal); the box of a net's projected control points ``H / w`` contains
  its patch for positive weights (convex hull), so it is the patch's shell;
* inside a patch the ray descends a quadtree of sub-patches: a net is halved in u and v by
  de Casteljau in homogeneous coordinates (a half of a rational Bezier net is again one),
  and a child is split further while the ray enters its shell (its box cut by the slab of
  its projected control points along the normal of its corners' diagonals: the convex
  hull lies in both) and its angular size is above the tolerance: the longest of its
  projected control polygon's rows and columns (with positive weights each rational de
  Casteljau step cuts corners, so the polygon bounds the lengths of the patch's curves)
  over the distance from the eye to its box. Children are visited nearest first; shells
  beyond the nearest kept hit are dropped;
* at a leaf the hit is found exactly: Newton's method on the rational surface itself (the
  patch's own net at patch parameters, so every leaf computes a point bit for bit alike),
  the ray written as the meet of two planes (Kajiya), starting from where the ray meets the
  two triangles of the leaf's corner points (else the leaf's centre). A root is kept when
  it converged, lies in the patch and within half a leaf of this leaf (the hit of a ray
  near a leaf's side is found from either side: no ray passes between neighbouring leaves
  or patches, whatever their depths), is in front of the eye and nearer than the best so
  far, and the trim test keeps its surface parameters
  (:func:`subtrace.nurbs.trimtree.trim_inside`, XOR the surface's inversion). Where the
  Jacobian is singular (a ray through a sphere's pole) Newton takes the least-squares
  step. A trimmed-away root is dropped and the search goes on, so the ray finds the next
  hit, on this patch or another.

Hit record per ray (:func:`trace_nurbs`): ``t`` (distance, inf: no hit), ``patch``
(-1: none), ``st (n, 2)`` the patch parameters, ``level`` the leaf's depth in the patch's
quadtree. :func:`hit_geometry` turns a hit into position, exact unit normal (where the
patch's parametrisation degenerates, a sphere's pole, the limit of the normal from inside
the patch) and surface parameters (u, v). :func:`trace_rays` traces any rays;
:func:`line_roots_task` finds every root along lines (:mod:`subtrace.lines.nurbs`).

Nothing is stored per ray; each thread keeps the children of the top NURBS_MEMO_LEVELS
levels of the quadtrees of the patches it visits last (:func:`_children`), which every ray
into a patch would otherwise split again (the same arithmetic: images do not change).
Every sub-patch's work is inlined into the descent (``inline_njit``): a call per child
passing the stack's arrays cost more than the box and slab it computes.
"""

from __future__ import annotations

import math

import numpy as np

from subtrace import config
from subtrace.accel.bvh import BVH, build_bvh, bvh_next_leaf, bvh_start, slab_range
from subtrace.nurbs.bezier import patch_eval
from subtrace.nurbs.trimtree import trim_inside
from subtrace.patches.basis import BOX_PAD, pad_box
from subtrace.runtime.jit import inline_njit, leaf_njit, nb
from subtrace.runtime.threads import run_tasks, thread_count
from subtrace.geometry.prims import ray_setup

MAX_LEVEL = config.NURBS_MAX_LEVEL
NEWTON_STEPS = config.NURBS_NEWTON_STEPS
NEWTON_TOL = config.NURBS_NEWTON_TOL
# the descent's stack: each level pops one sub-patch and pushes at most four
DESCENT_STACK = 3 * MAX_LEVEL + 8
TRIM_STACK = config.TRIM_STACK_SIZE
MEMO_SLOTS = config.NURBS_MEMO_PATCHES
MEMO_LEVELS = config.NURBS_MEMO_LEVELS
_NUDGES = (1e-7, 1e-5, 1e-3)
# a sub-patch's slab is widened by this much of its largest |n_k P_k| sum (rounding of n . P)
SLAB_PAD = 1e-12  # steps towards the patch centre for a degenerate normal


def patch_boxes(nets, degrees):
    """(lo (m, 3), hi (m, 3)) padded boxes of the projected control points of every patch."""
    m = len(nets)
    lo = np.empty((m, 3))
    hi = np.empty((m, 3))
    for p in range(m):
        du, dv = degrees[p]
        h = nets[p, : du + 1, : dv + 1].reshape(-1, 4)
        xyz = h[:, :3] / h[:, 3:]
        a, b = xyz.min(axis=0), xyz.max(axis=0)
        pad = BOX_PAD * float(np.abs(np.concatenate([a, b])).max())
        lo[p] = a - pad
        hi[p] = b + pad
    return lo, hi


def patch_bvh(model) -> BVH:
    """The BVH over the patches' shells (boxes of their projected control points)."""
    lo, hi = patch_boxes(model.nets, model.patch_degree)
    return build_bvh(lo, hi)


# ------------------------------------------------------------------------------------------
# sub-patch nets
# ------------------------------------------------------------------------------------------

@inline_njit
def _shell(net, du, dv, proj, g):
    """The shell of the sub-patch ``net`` into ``g`` (11,): the box of its projected control
    points ``H / w`` (lo (3), hi (3), padded by BOX_PAD for rounding), and the slab between
    the planes normal to its corners' diagonals' cross product ``n`` (3) through its extreme
    control points (n . P from lo to hi, padded likewise). The sub-patch lies in the convex
    hull of its projected control points (positive weights), so in both. ``proj`` (>= du+1,
    >= dv+1, >= 3) receives the projected points."""
    lo0 = lo1 = lo2 = np.inf
    hi0 = hi1 = hi2 = -np.inf
    for i in range(du + 1):
        for j in range(dv + 1):
            w = 1.0 / net[i, j, 3]
            x, y, z = net[i, j, 0] * w, net[i, j, 1] * w, net[i, j, 2] * w
            proj[i, j, 0], proj[i, j, 1], proj[i, j, 2] = x, y, z
            lo0, hi0 = min(lo0, x), max(hi0, x)
            lo1, hi1 = min(lo1, y), max(hi1, y)
            lo2, hi2 = min(lo2, z), max(hi2, z)
    g[0], g[1], g[2], g[3], g[4], g[5] = pad_box(lo0, lo1, lo2, hi0, hi1, hi2)
    # the slab: n = (P_dd - P_00) x (P_0d - P_d0), range of n . P over the control points
    ax, ay, az = (proj[du, dv, 0] - proj[0, 0, 0], proj[du, dv, 1] - proj[0, 0, 1],
                  proj[du, dv, 2] - proj[0, 0, 2])
    bx, by, bz = (proj[0, dv, 0] - proj[du, 0, 0], proj[0, dv, 1] - proj[du, 0, 1],
                  proj[0, dv, 2] - proj[du, 0, 2])
    nx, ny, nz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    lo, hi, big = np.inf, -np.inf, 0.0
    for i in range(du + 1):
        for j in range(dv + 1):
            x, y, z = proj[i, j, 0], proj[i, j, 1], proj[i, j, 2]
            h = nx * x + ny * y + nz * z
            lo, hi = min(lo, h), max(hi, h)
            big = max(big, abs(nx * x) + abs(ny * y) + abs(nz * z))
    pad = SLAB_PAD * big
    g[6], g[7], g[8], g[9], g[10] = nx, ny, nz, lo - pad, hi + pad


@inline_njit
def _shell_entry(g, ray, inv, tlo, thi):
    """Entry distance of the ray into the shell ``g`` (:func:`_shell`) within [tlo, thi]
    (inf: a miss)."""
    ox, oy, oz, dx, dy, dz = ray
    tn, tf = slab_range(ox, oy, oz, inv[0], inv[1], inv[2], g[0], g[1], g[2], g[3], g[4], g[5],
                        tlo, thi)
    if tn == np.inf:
        return np.inf
    nx, ny, nz, lo, hi = g[6], g[7], g[8], g[9], g[10]
    h0 = nx * ox + ny * oy + nz * oz
    hd = nx * dx + ny * dy + nz * dz
    if hd != 0.0:
        t1, t2 = (lo - h0) / hd, (hi - h0) / hd
        tn = max(tn, min(t1, t2))
        tf = min(tf, max(t1, t2))
        if not tn <= tf:
            return np.inf
    elif not lo <= h0 <= hi:
        return np.inf
    return tn


@inline_njit
def _children(sub, du, dv, kids, cb, memo, p, q):
    """The four children of the sub-patch ``sub`` into ``kids[:4]`` and their shells into
    ``cb[:4]``: from the thread's memo when node ``q`` (heap numbering: children of q are
    4 q + 1 .. 4 q + 4) of patch ``p`` is one it keeps and has split before, else split
    (and kept when it is one the memo keeps). ``memo``: (nets, shells, split flags, slot
    patch) of :func:`_scratch`; a patch takes slot p % slots."""
    mnets, mshells, mflags, mtag = memo
    keep = q < mflags.shape[1] and mflags.shape[0] > 0
    if keep:
        slot = p % mflags.shape[0]
        if mtag[slot] != p:  # the slot held another patch: forget it
            mtag[slot] = p
            mflags[slot, :] = False
        if mflags[slot, q]:
            for c in range(4):
                _copy(mnets[slot, q, c], kids[c], du, dv)
                for k in range(11):
                    cb[c, k] = mshells[slot, q, c, k]
            return
    _split(sub, du, dv, kids)
    for c in range(4):
        _shell(kids[c], du, dv, kids[5], cb[c])
    if keep:
        for c in range(4):
            _copy(kids[c], mnets[slot, q, c], du, dv)
            for k in range(11):
                mshells[slot, q, c, k] = cb[c, k]
        mflags[slot, q] = True


@inline_njit
def _net_size(net, du, dv):
    """The longest row or column of the projected control polygon of ``net`` (it bounds
    the lengths of the sub-patch's curves: with positive weights each rational de
    Casteljau step cuts corners)."""
    size = 0.0
    for j in range(dv + 1):
        length = 0.0
        for i in range(du):
            a, b = 1.0 / net[i, j, 3], 1.0 / net[i + 1, j, 3]
            dx = net[i + 1, j, 0] * b - net[i, j, 0] * a
            dy = net[i + 1, j, 1] * b - net[i, j, 1] * a
            dz = net[i + 1, j, 2] * b - net[i, j, 2] * a
            length += math.sqrt(dx * dx + dy * dy + dz * dz)
        size = max(size, length)
    for i in range(du + 1):
        length = 0.0
        for j in range(dv):
            a, b = 1.0 / net[i, j, 3], 1.0 / net[i, j + 1, 3]
            dx = net[i, j + 1, 0] * b - net[i, j, 0] * a
            dy = net[i, j + 1, 1] * b - net[i, j, 1] * a
            dz = net[i, j + 1, 2] * b - net[i, j, 2] * a
            length += math.sqrt(dx * dx + dy * dy + dz * dz)
        size = max(size, length)
    return size


@inline_njit
def _copy(src, dst, du, dv):
    """dst[:du+1, :dv+1] = src[:du+1, :dv+1] (element by element: no temporary)."""
    for i in range(du + 1):
        for j in range(dv + 1):
            for c in range(4):
                dst[i, j, c] = src[i, j, c]


@inline_njit
def _split(net, du, dv, out):
    """The four quarters of ``net`` (homogeneous de Casteljau at 1/2 in u, then v) into
    ``out[c]``, child ``c = cu + 2 cv`` covering half cu of u and half cv of v; ``out``
    (6, Du+1, Dv+1, 4), out[4] and out[5] scratch."""
    # along u: out[0] / out[1] get the two halves (out[4] holds the de Casteljau rows)
    row = out[4]
    for j in range(dv + 1):
        for c in range(4):
            for i in range(du + 1):
                row[i, 0, c] = net[i, j, c]
            for r in range(du + 1):
                out[0, r, j, c] = row[0, 0, c]
                out[1, du - r, j, c] = row[du - r, 0, c]
                for i in range(du - r):
                    row[i, 0, c] = 0.5 * (row[i, 0, c] + row[i + 1, 0, c])
    # along v: half h of u into children h (low v) and h + 2 (high v)
    col = out[5]
    for h in range(2):
        for i in range(du + 1):
            for c in range(4):
                for j in range(dv + 1):
                    col[0, j, c] = out[h, i, j, c]
                for r in range(dv + 1):
                    out[h, i, r, c] = col[0, 0, c]
                    out[h + 2, i, dv - r, c] = col[0, dv - r, c]
                    for j in range(dv - r):
                        col[0, j, c] = 0.5 * (col[0, j, c] + col[0, j + 1, c])


# ------------------------------------------------------------------------------------------
# the exact hit at a leaf
# ------------------------------------------------------------------------------------------

@inline_njit
def _point(net, i, j):
    """The projected control point ``net[i, j]``."""
    w = net[i, j, 3]
    return net[i, j, 0] / w, net[i, j, 1] / w, net[i, j, 2] / w


@inline_njit
def _triangle(a, b, c, ox, oy, oz, dx, dy, dz):
    """Barycentrics (b1, b2) of the ray's meet with the plane of triangle (a, b, c), and
    whether it lies in the triangle (Moller-Trumbore)."""
    e1x, e1y, e1z = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    e2x, e2y, e2z = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    px, py, pz = dy * e2z - dz * e2y, dz * e2x - dx * e2z, dx * e2y - dy * e2x
    det = e1x * px + e1y * py + e1z * pz
    if det == 0.0:
        return False, 0.0, 0.0
    qx, qy, qz = ox - a[0], oy - a[1], oz - a[2]
    b1 = (qx * px + qy * py + qz * pz) / det
    rx, ry, rz = qy * e1z - qz * e1y, qz * e1x - qx * e1z, qx * e1y - qy * e1x
    b2 = (dx * rx + dy * ry + dz * rz) / det
    return b1 >= 0.0 and b2 >= 0.0 and b1 + b2 <= 1.0, b1, b2


@inline_njit
def _start_guess(net, du, dv, ox, oy, oz, dx, dy, dz):
    """(s, t) in [0, 1]^2 of the leaf where the ray meets the two triangles of its corner
    points (bilinear parameters of the hit), or (0.5, 0.5) when it meets neither."""
    c00, c10 = _point(net, 0, 0), _point(net, du, 0)
    c11, c01 = _point(net, du, dv), _point(net, 0, dv)
    # triangle (0,0), (1,0), (1,1) in (s, t), then (0,0), (1,1), (0,1)
    inside, b1, b2 = _triangle(c00, c10, c11, ox, oy, oz, dx, dy, dz)
    if inside:
        return b1 + b2, b2
    inside, b1, b2 = _triangle(c00, c11, c01, ox, oy, oz, dx, dy, dz)
    if inside:
        return b1, b1 + b2
    return 0.5, 0.5


@leaf_njit
def _newton(net, du, dv, ox, oy, oz, dx, dy, dz, s, t, work, out):
    """Newton's method for the ray's hit on the patch ``net`` from (s, t): returns
    (converged, s, t, distance along the ray). The ray is the meet of the planes through
    it with normals n1 and n2 = d x n1; the residual is (n1 . (P - o), n2 . (P - o))."""
    if abs(dx) > abs(dy):
        n1x, n1y, n1z = -dz, 0.0, dx
    else:
        n1x, n1y, n1z = 0.0, dz, -dy
    ln = math.sqrt(n1x * n1x + n1y * n1y + n1z * n1z)
    n1x, n1y, n1z = n1x / ln, n1y / ln, n1z / ln
    n2x, n2y, n2z = dy * n1z - dz * n1y, dz * n1x - dx * n1z, dx * n1y - dy * n1x
    step = 1.0
    for _ in range(NEWTON_STEPS):
        patch_eval(net, du, dv, s, t, work, out)
        qx, qy, qz = out[0, 0] - ox, out[0, 1] - oy, out[0, 2] - oz
        f1 = n1x * qx + n1y * qy + n1z * qz
        f2 = n2x * qx + n2y * qy + n2z * qz
        j11 = n1x * out[1, 0] + n1y * out[1, 1] + n1z * out[1, 2]
        j12 = n1x * out[2, 0] + n1y * out[2, 1] + n1z * out[2, 2]
        j21 = n2x * out[1, 0] + n2y * out[1, 1] + n2z * out[1, 2]
        j22 = n2x * out[2, 0] + n2y * out[2, 1] + n2z * out[2, 2]
        det = j11 * j22 - j12 * j21
        a11 = j11 * j11 + j21 * j21
        a12 = j11 * j12 + j21 * j22
        a22 = j12 * j12 + j22 * j22
        if abs(det) > 1e-8 * (a11 + a22):
            ds = (j22 * f1 - j12 * f2) / det
            dt = (j11 * f2 - j21 * f1) / det
        else:
            # J (nearly) singular, as at a pole: the least-squares step (J^T J + mu I) d =
            # J^T F, mu a rounding of J^T J, moves along the direction that changes P
            mu = 1e-14 * (a11 + a22)
            a11 += mu
            a22 += mu
            g1 = j11 * f1 + j21 * f2
            g2 = j12 * f1 + j22 * f2
            det = a11 * a22 - a12 * a12
            if not det > 0.0:
                break
            ds = (a22 * g1 - a12 * g2) / det
            dt = (a11 * g2 - a12 * g1) / det
        s -= ds
        t -= dt
        step = abs(ds) + abs(dt)
        if not (-0.5 < s < 1.5 and -0.5 < t < 1.5):
            return False, s, t, np.inf
        if step <= NEWTON_TOL:
            break
    if not step <= NEWTON_TOL:
        return False, s, t, np.inf
    # snap roots a rounding outside the patch onto its sides; the distance at the root
    s = min(max(s, 0.0), 1.0) if -NEWTON_TOL <= s <= 1.0 + NEWTON_TOL else s
    t = min(max(t, 0.0), 1.0) if -NEWTON_TOL <= t <= 1.0 + NEWTON_TOL else t
    if not (0.0 <= s <= 1.0 and 0.0 <= t <= 1.0):
        return False, s, t, np.inf
    patch_eval(net, du, dv, s, t, work, out)
    qx, qy, qz = out[0, 0] - ox, out[0, 1] - oy, out[0, 2] - oz
    dist = qx * dx + qy * dy + qz * dz
    # the root lies on the ray (to rounding of the point's size)
    miss = abs(n1x * qx + n1y * qy + n1z * qz) + abs(n2x * qx + n2y * qy + n2z * qz)
    size = abs(out[0, 0]) + abs(out[0, 1]) + abs(out[0, 2]) + abs(dist)
    if not miss <= config.NURBS_ON_RAY * size:
        return False, s, t, np.inf
    return True, s, t, dist


@leaf_njit
def _kept(trim, surface_trim, surface_invert, rect, surface, s, t, stack):
    """True when the trim loops of ``surface`` keep the patch point (s, t) (patch rectangle
    ``rect`` (u0, u1, v0, v1)); ``trim``: the trim tree's arrays (:func:`trim_arrays`)."""
    root = surface_trim[surface]
    if root < 0:
        return True
    u = rect[0] + s * (rect[1] - rect[0])
    v = rect[2] + t * (rect[3] - rect[2])
    node_box, node_axis, node_split, node_child, node_count, node_inside, ctrl, degree, p0, \
        p1 = trim
    inside = trim_inside(node_box, node_axis, node_split, node_child, node_count, node_inside,
                         ctrl, degree, p0, p1, root, u, v, stack)
    return inside != surface_invert[surface]


def trim_arrays(model):
    """The trim tree of ``model`` as the tuple the kernels take (node_box, node_axis,
    node_split, node_child, node_count, node_inside, ctrl, degree, p0, p1)."""
    t = model.trim
    return (t.node_box, t.node_axis, t.node_split, t.node_child, t.node_count, t.node_inside,
            t.units.ctrl, t.units.degree, t.units.p0, t.units.p1)


@leaf_njit
def _leaf_root(net0, du, dv, sub, r, ray, work, out):
    """Newton's root for the ray ``ray`` (ox, oy, oz, dx, dy, dz) in the leaf ``sub`` (its
    net) over patch parameters ``r`` (s0, s1, t0, t1): (ok, s, t, distance); ok only for a
    root in the patch within half a leaf of this one."""
    ox, oy, oz, dx, dy, dz = ray
    gs, gt = _start_guess(sub, du, dv, ox, oy, oz, dx, dy, dz)
    ws, wt = r[1] - r[0], r[3] - r[2]
    ok, s, t, dist = _newton(net0, du, dv, ox, oy, oz, dx, dy, dz, r[0] + gs * ws,
                             r[2] + gt * wt, work, out)
    if ok and not (r[0] - 0.5 * ws <= s <= r[1] + 0.5 * ws
                   and r[2] - 0.5 * wt <= t <= r[3] + 0.5 * wt):
        ok = False
    return ok, s, t, dist


@inline_njit
def _push_children(kids, cb, du, dv, r, level, q, ray, inv, tlo, thi, stack, sp):
    """Push the children of a split sub-patch (``kids[:4]``, shells ``cb[:4]``, rectangle
    ``r``, node ``q``) whose shells the ray enters within [tlo, thi] onto the stack,
    farthest first, each with its rectangle and box (``sr`` row: s0, s1, t0, t1, box (6)),
    level, entry distance and node number; returns the stack size."""
    sn, sr, sl, st, sq = stack
    for c in range(4):
        cb[c, 11] = _shell_entry(cb[c], ray, inv, tlo, thi)
    ms, mt = 0.5 * (r[0] + r[1]), 0.5 * (r[2] + r[3])
    done = 0
    for _ in range(4):
        # the farthest child not pushed yet (lowest index first among equals)
        c = -1
        far = -np.inf
        for k in range(4):
            tk = cb[k, 11]
            if not (done >> k) & 1 and tk < np.inf and (c < 0 or tk > far):
                c, far = k, tk
        if c < 0:
            break
        done |= 1 << c
        _copy(kids[c], sn[sp], du, dv)
        sr[sp, 0], sr[sp, 1] = (r[0], ms) if c % 2 == 0 else (ms, r[1])
        sr[sp, 2], sr[sp, 3] = (r[2], mt) if c < 2 else (mt, r[3])
        for k in range(6):
            sr[sp, 4 + k] = cb[c, k]
        sl[sp] = level + 1
        st[sp] = far
        sq[sp] = 4 * q + 1 + c
        sp += 1
    return sp


@inline_njit
def _push_root(net0, du, dv, kids, cb, ray, inv, tlo, thi, stack):
    """Put patch ``net0`` on the stack if the ray enters its shell within [tlo, thi];
    returns the stack size (0 or 1)."""
    sn, sr, sl, st, sq = stack
    _shell(net0, du, dv, kids[5], cb[0])
    te = _shell_entry(cb[0], ray, inv, tlo, thi)
    if te == np.inf:
        return 0
    _copy(net0, sn[0], du, dv)
    sr[0, 0], sr[0, 1], sr[0, 2], sr[0, 3] = 0.0, 1.0, 0.0, 1.0
    for k in range(6):
        sr[0, 4 + k] = cb[0, k]
    sl[0] = 0
    st[0] = te
    sq[0] = 0
    return 1


@leaf_njit
def _descend(net0, du, dv, p, rect, surface, ray, inv, tlo, thi, tol, cone, tables, scratch):
    """The nearest kept hit of the ray on patch ``p`` (net ``net0``) within [tlo, thi] by
    per-ray refinement (module comment): (found, distance, s, t, level, capped), capped:
    leaves held at MAX_LEVEL above the tolerance. ``tables``: (surface_trim,
    surface_invert, trim arrays); ``scratch``: :func:`_scratch`'s buffers. ``cone``: the
    ray's width at its origin (0 from the eye; a secondary ray's ray cone: its pixel's
    footprint at the hit it leaves): a sub-patch is small enough within
    ``cone + tol * distance``."""
    surface_trim, surface_invert, trim = tables
    stack, kids, work, out, tstack, cb, memo = scratch
    sn, sr, sl, st, sq = stack
    ox, oy, oz = ray[0], ray[1], ray[2]
    best, fs, ft, flev, capped = thi, 0.0, 0.0, -1, 0
    sp = _push_root(net0, du, dv, kids, cb, ray, inv, tlo, best, stack)
    while sp > 0:
        sp -= 1
        if st[sp] > best:  # a nearer hit was found since it was pushed
            continue
        sub = sn[sp]
        level = sl[sp]
        # angular size: the control polygon over the distance from the eye to the box
        ex = max(sr[sp, 4] - ox, 0.0, ox - sr[sp, 7])
        ey = max(sr[sp, 5] - oy, 0.0, oy - sr[sp, 8])
        ez = max(sr[sp, 6] - oz, 0.0, oz - sr[sp, 9])
        dist = math.sqrt(ex * ex + ey * ey + ez * ez)
        small = _net_size(sub, du, dv) <= cone + tol * dist
        if small or level >= MAX_LEVEL:
            # a leaf: the exact root, kept when the trim keeps it
            capped += 0 if small else 1
            ok, s, t, d = _leaf_root(net0, du, dv, sub, sr[sp], ray, work, out)
            if (ok and tlo <= d < best
                    and _kept(trim, surface_trim, surface_invert, rect, surface, s, t, tstack)):
                best, fs, ft, flev = d, s, t, level
            continue
        r = (sr[sp, 0], sr[sp, 1], sr[sp, 2], sr[sp, 3])
        _children(sub, du, dv, kids, cb, memo, p, sq[sp])
        sp = _push_children(kids, cb, du, dv, r, level, sq[sp], ray, inv, tlo, best, stack, sp)
    return flev >= 0, best, fs, ft, flev, capped


@nb.njit(cache=True)
def _scratch(max_du, max_dv):
    """Per-thread buffers of :func:`_descend` (each thread its own): the descent stack
    (nets, rectangles with boxes, levels, entry distances, node numbers), the split's
    children, the work and output of :func:`~subtrace.nurbs.bezier.patch_eval`, the trim
    test's stack, the children's shells and entries, and the memo: for MEMO_SLOTS patches
    (fewer where they would take more than NURBS_MEMO_BYTES) the children of their nodes above level NURBS_MEMO_LEVELS (nets, shells, which
    nodes are split, the patch each slot holds). The memo changes the work, never a hit
    (the same arithmetic makes the same children), so images do not depend on it."""
    shape = (max_du + 1, max_dv + 1, 4)
    nodes = (4 ** MEMO_LEVELS - 1) // 3
    per_slot = nodes * 4 * ((max_du + 1) * (max_dv + 1) * 4 + 11) * 8
    memo_slots = max(1, min(MEMO_SLOTS, config.NURBS_MEMO_BYTES // per_slot))
    stack = (np.zeros((DESCENT_STACK,) + shape), np.zeros((DESCENT_STACK, 10)),
             np.zeros(DESCENT_STACK, np.int64), np.zeros(DESCENT_STACK),
             np.zeros(DESCENT_STACK, np.int64))
    memo = (np.zeros((memo_slots, nodes, 4) + shape), np.zeros((memo_slots, nodes, 4, 11)),
            np.zeros((memo_slots, nodes), np.bool_), np.full(memo_slots, -1, np.int64))
    return (stack, np.zeros((6,) + shape), np.zeros((4, config.NURBS_MAX_DEGREE + 1, 4)),
            np.zeros((3, 3)), np.zeros(TRIM_STACK, np.int64), np.zeros((4, 12)), memo)


@leaf_njit
def _trace_ray(ray, tlo, thi, bvh, nets, degrees, rects, owner, tol, cone, tables, scratch,
               stack, stack_t):
    """Nearest kept hit of one ray over all patches: (patch (-1: none), distance, s, t,
    level, capped leaves); ``cone``: the ray's width at its origin (:func:`_descend`)."""
    ox, oy, oz, dx, dy, dz = ray
    inv = (1.0 / dx, 1.0 / dy, 1.0 / dz)
    best, hp, hs, ht, hl, capped = thi, -1, 0.0, 0.0, -1, 0
    sp = bvh_start(ox, oy, oz, inv[0], inv[1], inv[2], bvh, tlo, best, stack, stack_t)
    while sp > 0:
        first, end, sp = bvh_next_leaf(ox, oy, oz, inv[0], inv[1], inv[2], bvh, tlo, best,
                                       stack, stack_t, sp)
        for k in range(first, end):
            p = bvh.prims[k]
            found, d, s, t, level, c = _descend(nets[p], degrees[p, 0], degrees[p, 1], p,
                                                rects[p], owner[p], ray, inv, tlo, best, tol,
                                                cone, tables, scratch)
            capped += c
            if found and d < best:
                best, hp, hs, ht, hl = d, p, s, t, level
    return hp, best, hs, ht, hl, capped


@nb.njit(cache=True, nogil=True)
def _trace_rows(task, n_tasks, frame, width, height, bvh, nets, degrees, rects, owner, tol,
                tables, out_t, out_patch, out_st, out_level, capped):
    """Rows ``task, task + n_tasks, ...`` of the image: each pixel's ray from the eye."""
    buffers = _scratch(nets.shape[1] - 1, nets.shape[2] - 1)
    stack = np.empty(config.STACK_SIZE, np.int64)
    stack_t = np.empty(config.STACK_SIZE)
    n_capped = 0
    ox, oy, oz = frame[0, 0], frame[0, 1], frame[0, 2]
    for row in range(task, height, n_tasks):
        for col in range(width):
            r = row * width + col
            dx, dy, dz = ray_setup(frame, row, col)
            p, d, s, t, level, c = _trace_ray((ox, oy, oz, dx, dy, dz), 0.0, np.inf, bvh, nets,
                                              degrees, rects, owner, tol, 0.0, tables, buffers,
                                              stack, stack_t)
            n_capped += c
            out_t[r] = d
            out_patch[r] = p
            out_st[r, 0] = s
            out_st[r, 1] = t
            out_level[r] = level
    capped[task] = n_capped


class NurbsHits:
    """Per-pixel NURBS hits (n = width * height): ``t`` (n,) f8 distance (inf: none),
    ``patch`` (n,) i8 (-1: none), ``st`` (n, 2) f8 patch parameters, ``level`` (n,) i8,
    ``capped``: leaves held at NURBS_MAX_LEVEL above the tolerance (summed over rays)."""

    def __init__(self, n: int):
        self.t = np.full(n, np.inf)
        self.patch = np.full(n, -1, np.int64)
        self.st = np.zeros((n, 2))
        self.level = np.full(n, -1, np.int64)
        self.capped = 0


def trace_nurbs(model, bvh, frame, width: int, height: int, tol_rad: float) -> NurbsHits:
    """Trace one ray per pixel (camera ``frame``, :func:`subtrace.camera.camera_frame`)
    against the patches of ``model`` (BVH ``bvh``: :func:`patch_bvh`) on every thread; each
    thread writes whole rows, so the hits do not depend on the thread count."""
    hits = NurbsHits(width * height)
    if model.n_patches == 0:
        return hits
    n = thread_count()
    capped = np.zeros(n, np.int64)
    tables = (model.surface_trim, model.surface_trim_invert, trim_arrays(model))
    run_tasks(_trace_rows, np.ascontiguousarray(frame, dtype=np.float64), int(width),
              int(height), bvh, model.nets, model.patch_degree, model.patch_rect,
              model.patch_surface, float(tol_rad), tables, hits.t, hits.patch, hits.st,
              hits.level, capped, n=n)
    hits.capped = int(capped.sum())
    return hits


@leaf_njit
def patch_normal(net, du, dv, s, t, work, out):
    """Unit normal dP/ds x dP/dt of the patch ``net`` at (s, t) (leaves P and the
    derivatives in ``out``); where the parametrisation degenerates (a side shrunk to a
    point, as at a sphere's pole) the normal a short step towards the patch's centre, which
    tends to the surface's limit normal there."""
    patch_eval(net, du, dv, s, t, work, out)
    px, py, pz = out[0, 0], out[0, 1], out[0, 2]
    for k in range(len(_NUDGES) + 1):
        if k > 0:
            h = _NUDGES[k - 1]
            patch_eval(net, du, dv, s + h * (0.5 - s), t + h * (0.5 - t), work, out)
        ax, ay, az = out[1, 0], out[1, 1], out[1, 2]
        bx, by, bz = out[2, 0], out[2, 1], out[2, 2]
        nx, ny, nz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
        ln = math.sqrt(nx * nx + ny * ny + nz * nz)
        scale = ax * ax + ay * ay + az * az + bx * bx + by * by + bz * bz
        if ln > config.NURBS_DEGENERATE * scale:
            out[0, 0], out[0, 1], out[0, 2] = px, py, pz
            return nx / ln, ny / ln, nz / ln
    out[0, 0], out[0, 1], out[0, 2] = px, py, pz
    return 0.0, 0.0, 0.0


@nb.njit(cache=True)
def _geometry(nets, degrees, rects, patch, st, points, normals, uv):
    work = np.empty((4, config.NURBS_MAX_DEGREE + 1, 4))
    out = np.empty((3, 3))
    for k in range(len(patch)):
        p = patch[k]
        s, t = st[k, 0], st[k, 1]
        n = patch_normal(nets[p], degrees[p, 0], degrees[p, 1], s, t, work, out)
        for c in range(3):
            points[k, c] = out[0, c]
            normals[k, c] = n[c]
        uv[k, 0] = rects[p, 0] + s * (rects[p, 1] - rects[p, 0])
        uv[k, 1] = rects[p, 2] + t * (rects[p, 3] - rects[p, 2])


def hit_geometry(model, patch, st):
    """(points (n, 3), unit normals (n, 3), surface parameters uv (n, 2)) of hits on
    ``patch`` (n,) at patch parameters ``st`` (n, 2)."""
    patch = np.ascontiguousarray(patch, dtype=np.int64)
    st = np.ascontiguousarray(st, dtype=np.float64).reshape(-1, 2)
    n = len(patch)
    points, normals, uv = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 2))
    if n:
        _geometry(model.nets, model.patch_degree, model.patch_rect, patch, st, points,
                  normals, uv)
    return points, normals, uv


@nb.njit(cache=True, nogil=True)
def _trace_list(task, n_tasks, origins, directions, tlo, thi, bvh, nets, degrees, rects, owner,
                tol, cone, tables, out_t, out_patch, out_st, out_level):
    """Rays ``task, task + n_tasks, ...`` of the list (origins, unit directions (n, 3))."""
    buffers = _scratch(nets.shape[1] - 1, nets.shape[2] - 1)
    stack = np.empty(config.STACK_SIZE, np.int64)
    stack_t = np.empty(config.STACK_SIZE)
    for r in range(task, len(origins), n_tasks):
        ray = (origins[r, 0], origins[r, 1], origins[r, 2], directions[r, 0],
               directions[r, 1], directions[r, 2])
        p, d, s, t, level, _ = _trace_ray(ray, tlo, thi, bvh, nets, degrees, rects, owner, tol,
                                          cone[r] if len(cone) else 0.0,
                                          tables, buffers, stack, stack_t)
        out_t[r] = d
        out_patch[r] = p
        out_st[r, 0] = s
        out_st[r, 1] = t
        out_level[r] = level


def trace_rays(model, bvh, origins, directions, tol_rad: float, tlo: float = 0.0,
               thi: float = np.inf, cone=None) -> NurbsHits:
    """Nearest kept hits within [tlo, thi] of rays ``origins + t directions`` ((n, 3) each,
    directions of unit length; the angular criterion measured from each ray's origin), on
    every thread. ``cone``: None, or (n,) each ray's width at its origin (a ray cone: a
    shadow ray leaving a hit at distance t from the eye carries its pixel's footprint
    ``t * tol_rad`` there), so a sub-patch at distance s along the ray is small enough
    within ``cone + tol_rad * s``: a secondary ray refines no finer than its pixel needs."""
    origins = np.ascontiguousarray(origins, dtype=np.float64).reshape(-1, 3)
    directions = np.ascontiguousarray(directions, dtype=np.float64).reshape(-1, 3)
    cone = np.zeros(0) if cone is None else np.ascontiguousarray(cone, dtype=np.float64)
    hits = NurbsHits(len(origins))
    if model.n_patches == 0 or not len(origins):
        return hits
    tables = (model.surface_trim, model.surface_trim_invert, trim_arrays(model))
    run_tasks(_trace_list, origins, directions, float(tlo), float(thi), bvh, model.nets,
              model.patch_degree, model.patch_rect, model.patch_surface, float(tol_rad), cone,
              tables, hits.t, hits.patch, hits.st, hits.level, n=thread_count())
    return hits


# ------------------------------------------------------------------------------------------
# every root along a line (subtrace.lines.nurbs)
# ------------------------------------------------------------------------------------------

@leaf_njit
def _net_flatness(net, du, dv):
    """How far the projected control points of ``net`` lie from the bilinear interpolant of
    its corners at their Greville parameters, plus the twist's bound on the corner
    triangles' distance from that interpolant (the line kernels' flatness, on the projected
    points): a leaf for Newton once below the precision."""
    c00, c10 = _point(net, 0, 0), _point(net, du, 0)
    c11, c01 = _point(net, du, dv), _point(net, 0, dv)
    e = 0.0
    for i in range(du + 1):
        s = i / du if du > 0 else 0.0
        for j in range(dv + 1):
            t = j / dv if dv > 0 else 0.0
            p = _point(net, i, j)
            d2 = 0.0
            for k in range(3):
                lin = ((1 - s) * (1 - t) * c00[k] + s * (1 - t) * c10[k] + (1 - s) * t * c01[k]
                       + s * t * c11[k])
                d2 += (p[k] - lin) ** 2
            e = max(e, math.sqrt(d2))
    tw = 0.0
    for k in range(3):
        tw += (c00[k] - c10[k] - c01[k] + c11[k]) ** 2
    return e + 0.25 * math.sqrt(tw)


@leaf_njit
def _inverse(dx, dy, dz):
    """(1/dx, 1/dy, 1/dz) with IEEE division (1/0 = inf: the slab test's axis-parallel case)."""
    return 1.0 / dx, 1.0 / dy, 1.0 / dz


@leaf_njit
def _line_roots(net0, du, dv, rect, surface, ray, inv, tlo, thi, tol_flat, tables, scratch,
                p, out, n):
    """Append every kept root of the line ``ray`` on patch ``p`` within [tlo, thi] to
    ``out[n:]`` (rows t, patch, s, t; rows past ``len(out)`` only counted): sub-patches the
    line enters are split until flat within ``tol_flat`` (or MAX_LEVEL), then Newton's root
    of each leaf is taken as for rays. Returns the new count."""
    surface_trim, surface_invert, trim = tables
    stack, kids, work, out3, tstack, cb, memo = scratch
    sn, sr, sl, _, sq = stack
    sp = _push_root(net0, du, dv, kids, cb, ray, inv, tlo, thi, stack)
    while sp > 0:
        sp -= 1
        sub = sn[sp]
        level = sl[sp]
        if level >= MAX_LEVEL or _net_flatness(sub, du, dv) <= tol_flat:
            ok, s, t, d = _leaf_root(net0, du, dv, sub, sr[sp], ray, work, out3)
            if (ok and tlo <= d <= thi
                    and _kept(trim, surface_trim, surface_invert, rect, surface, s, t, tstack)):
                if n < len(out):
                    out[n, 0], out[n, 1], out[n, 2], out[n, 3] = d, p, s, t
                n += 1
            continue
        r = (sr[sp, 0], sr[sp, 1], sr[sp, 2], sr[sp, 3])
        _children(sub, du, dv, kids, cb, memo, p, sq[sp])
        sp = _push_children(kids, cb, du, dv, r, level, sq[sp], ray, inv, tlo, thi, stack, sp)
    return n


@nb.njit(cache=True, nogil=True)
def line_roots_task(task, n_tasks, origins, directions, tlo, thi, bvh, nets, degrees, rects,
                    owner, tol_flat, tables, out, count):
    """Every kept root of lines ``task, task + n_tasks, ...`` (origins, unit directions
    (n, 3); parameter range [tlo, thi] along the unit direction) into ``out (n, cap, 4)``
    (t, patch, s, t) and ``count (n,)`` (above cap: run the line again with more room). A
    root found from two leaves or patches appears once per leaf (the caller merges)."""
    buffers = _scratch(nets.shape[1] - 1, nets.shape[2] - 1)
    stack = np.empty(config.STACK_SIZE, np.int64)
    stack_t = np.empty(config.STACK_SIZE)
    for r in range(task, len(origins), n_tasks):
        ox, oy, oz = origins[r, 0], origins[r, 1], origins[r, 2]
        dx, dy, dz = directions[r, 0], directions[r, 1], directions[r, 2]
        ray = (ox, oy, oz, dx, dy, dz)
        inv = _inverse(dx, dy, dz)
        n = 0
        sp = bvh_start(ox, oy, oz, inv[0], inv[1], inv[2], bvh, tlo, thi, stack, stack_t)
        while sp > 0:
            first, end, sp = bvh_next_leaf(ox, oy, oz, inv[0], inv[1], inv[2], bvh, tlo, thi,
                                           stack, stack_t, sp)
            for k in range(first, end):
                p = bvh.prims[k]
                n = _line_roots(nets[p], degrees[p, 0], degrees[p, 1], rects[p], owner[p], ray,
                                inv, tlo, thi, tol_flat, tables, buffers, p, out[r], n)
        count[r] = n
