"""Ray kernels: slab test, watertight ray / triangle test, BVH and patch-grid traversal.

One ray per pixel from a pinhole camera ``frame`` = [eye, dx, dy, p00] (see
``trace.camera.camera_frame``); ``t`` is the distance from the eye along the unit direction.

Built patches live in pools (see ``render.py``): slot ``s`` holds a grid of depth
``slot_depth[s]`` whose points start at ``slot_vert_off[s]`` in ``verts`` and whose quadtree
node boxes start at ``slot_node_off[s]`` in ``node_lo``/``node_hi``: level ``l`` (4^l nodes)
at ``(4^l - 1) / 3``, node ``i``'s children are ``4i .. 4i+3`` of level ``l+1`` (the multi-level
1-to-4 segmentation of the patch grid), the leaves at level ``depth`` are the micro-faces
whose grid corners are ``lc_data[lc_off[depth, quad] + i]`` (a triangle's 4th is -1).

A round (:func:`trace_round`) traverses the BVH of patch shells for each active ray:
built patches are intersected (only those built since the ray's previous round: older ones
were tested then), and the nearest *unbuilt* patch whose shell the ray enters before its
best hit so far is recorded as the ray's request; the driver builds the requested patches
and runs another round for the rays that asked. This is the refinement criterion: a patch
is refined only when a ray reaches its shell before any closer hit.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

# hit record layout (float64 per ray): t, slot, leaf, triangle, b1, b2
H_T, H_SLOT, H_LEAF, H_TRI, H_B1, H_B2 = range(6)
HIT_FIELDS = 6


@nb.njit(cache=True, inline="always")
def _slab(ox, oy, oz, ix, iy, iz, lo, hi, k, tmax):
    """Entry distance of the ray into box ``k`` of (lo, hi), or inf if it misses before tmax.

    Robust to direction components of zero (IEEE infinities in ``i*``); the far distance is
    widened by 1 + 2 gamma(3) as pbrt does, so a ray grazing a box is not lost to rounding.
    """
    t0 = (lo[k, 0] - ox) * ix
    t1 = (hi[k, 0] - ox) * ix
    tn = min(t0, t1)
    tf = max(t0, t1)
    t0 = (lo[k, 1] - oy) * iy
    t1 = (hi[k, 1] - oy) * iy
    tn = max(tn, min(t0, t1))
    tf = min(tf, max(t0, t1))
    t0 = (lo[k, 2] - oz) * iz
    t1 = (hi[k, 2] - oz) * iz
    tn = max(tn, min(t0, t1))
    tf = min(tf, max(t0, t1))
    tf *= 1.0 + 6.7e-16
    tn = max(tn, 0.0)
    if tn <= tf and tn < tmax:
        return tn
    return np.inf


@nb.njit(cache=True, inline="always")
def _tri(ox, oy, oz, kx, ky, kz, sx, sy, sz, a, b, c, verts, tmax, slack):
    """Watertight ray / triangle test (Woop, Benthin and Wald 2013) on vertices ``a, b, c``
    of ``verts``; ``ox, oy, oz`` is the ray origin's (kx, ky, kz) components. Returns (t, b_a, b_b, b_c) with t = inf on a miss. Edge functions of a
    shared edge are computed identically from both triangles, so no ray slips between them;
    ``slack`` admits edge functions down to -slack times their sum (see config.TRI_SLACK)."""
    ax = verts[a, kx] - ox
    ay = verts[a, ky] - oy
    az = verts[a, kz] - oz
    bx = verts[b, kx] - ox
    by = verts[b, ky] - oy
    bz = verts[b, kz] - oz
    cx = verts[c, kx] - ox
    cy = verts[c, ky] - oy
    cz = verts[c, kz] - oz
    ax, ay = ax - sx * az, ay - sy * az
    bx, by = bx - sx * bz, by - sy * bz
    cx, cy = cx - sx * cz, cy - sy * cz
    u = cx * by - cy * bx
    v = ax * cy - ay * cx
    w = bx * ay - by * ax
    eps = slack * (abs(u) + abs(v) + abs(w))
    if (u < -eps or v < -eps or w < -eps) and (u > eps or v > eps or w > eps):
        return np.inf, 0.0, 0.0, 0.0
    det = u + v + w
    if det == 0.0:
        return np.inf, 0.0, 0.0, 0.0
    tt = (u * az + v * bz + w * cz) * sz
    t = tt / det
    if not (t > 0.0 and t < tmax):
        return np.inf, 0.0, 0.0, 0.0
    return t, u / det, v / det, w / det


@nb.njit(cache=True, inline="always")
def ray_setup(frame, row, col):
    """Unit direction of the ray through the centre of pixel (row, col)."""
    dx = frame[3, 0] + col * frame[1, 0] + row * frame[2, 0]
    dy = frame[3, 1] + col * frame[1, 1] + row * frame[2, 1]
    dz = frame[3, 2] + col * frame[1, 2] + row * frame[2, 2]
    inv = 1.0 / math.sqrt(dx * dx + dy * dy + dz * dz)
    return dx * inv, dy * inv, dz * inv


@nb.njit(cache=True)
def _shear(dx, dy, dz):
    """Woop's permutation and shear constants of a ray direction."""
    ax, ay, az = abs(dx), abs(dy), abs(dz)
    kz = 0
    if ay > ax and ay >= az:
        kz = 1
    elif az > ax and az > ay:
        kz = 2
    kx = (kz + 1) % 3
    ky = (kx + 1) % 3
    d = (dx, dy, dz)
    dkz = d[kz]
    if dkz < 0.0:
        kx, ky = ky, kx
    return kx, ky, kz, d[kx] / dkz, d[ky] / dkz, 1.0 / dkz


@nb.njit(cache=True)
def _intersect_slot(ox, oy, oz, ix, iy, iz, kx, ky, kz, sx, sy, sz, s, slot_depth,
                    slot_vert_off, slot_node_off, slot_quad, verts, node_lo, node_hi, lc_off,
                    lc_data, slack, hit, stack, ent_t, ent_i):
    """Closest hit in the grid of slot ``s`` nearer than hit[H_T]; updates ``hit``.
    ``stack``, ``ent_t`` (4,) and ``ent_i`` (4,) are the caller's scratch buffers."""
    depth = slot_depth[s]
    quad = slot_quad[s]
    lc0 = lc_off[depth, 1 if quad else 0]
    vo = slot_vert_off[s]
    no = slot_node_off[s]
    if _slab(ox, oy, oz, ix, iy, iz, node_lo, node_hi, no, hit[H_T]) == np.inf:
        return
    o = (ox, oy, oz)
    px, py, pz = o[kx], o[ky], o[kz]  # origin in the shear's axis order
    # stack entries: level * 2^40 + index; deeper-first order gives near children first
    sp = 0
    stack[0] = 0
    sp = 1
    while sp > 0:
        sp -= 1
        code = stack[sp]
        level = code >> 40
        idx = code & ((1 << 40) - 1)
        if level == depth:
            # the micro-face: one triangle, or a quad's two triangles (a, b, c), (a, c, d)
            base = lc0 + idx
            a = vo + lc_data[base, 0]
            for tri in range(2 if quad else 1):
                b = vo + lc_data[base, 1 + tri]
                c = vo + lc_data[base, 2 + tri]
                t, ba, bb, bc = _tri(px, py, pz, kx, ky, kz, sx, sy, sz, a, b, c, verts,
                                     hit[H_T], slack)
                if t < hit[H_T]:
                    hit[H_T] = t
                    hit[H_SLOT] = s
                    hit[H_LEAF] = idx
                    hit[H_TRI] = tri
                    hit[H_B1] = bb
                    hit[H_B2] = bc
            continue
        # children: test boxes, push the hit ones far to near
        child_level = level + 1
        lvl_off = no + ((1 << (2 * child_level)) - 1) // 3
        n = 0
        for j in range(4):
            ci = 4 * idx + j
            te = _slab(ox, oy, oz, ix, iy, iz, node_lo, node_hi, lvl_off + ci, hit[H_T])
            if te < np.inf:
                # insertion sort, descending entry distance
                m = n
                while m > 0 and ent_t[m - 1] < te:
                    ent_t[m] = ent_t[m - 1]
                    ent_i[m] = ent_i[m - 1]
                    m -= 1
                ent_t[m] = te
                ent_i[m] = ci
                n += 1
        for j in range(n):
            stack[sp] = (child_level << 40) | ent_i[j]
            sp += 1


RAYS_PER_TASK = 32  # rays per parallel task (scratch buffers are allocated once per task)


@nb.njit(cache=True, parallel=True)
def trace_round(rays, frame, width, round_no, bvh_min, bvh_max, bvh_first, bvh_count, prims,
                shell_min, shell_max, patch_slot, slot_depth, slot_vert_off, slot_node_off,
                slot_quad, slot_round, verts, node_lo, node_hi, lc_off, lc_data, reg_index,
                nets, reg_depth, reg_side, slack, hits, request, tested, touched):
    """One round for the rays ``rays`` (pixel indices): update ``hits`` (n_pixels, 6) and
    set ``request[r]`` to the nearest unbuilt patch the ray reaches first (or -1).

    Regular patches (``reg_index[p] >= 0``: Bezier net ``nets[reg_index[p]]``, grid depth
    ``reg_depth``, side sampling depths ``reg_side``) are intersected directly, in round 0
    (see ``trace/bezier.py``); ``tested[r]`` counts the micro-triangles they built for ray r.
    """
    ox, oy, oz = frame[0, 0], frame[0, 1], frame[0, 2]
    n_rays = len(rays)
    n_tasks = (n_rays + RAYS_PER_TASK - 1) // RAYS_PER_TASK
    max_d = 0
    for k in range(len(reg_depth)):
        max_d = max(max_d, reg_depth[k])
    for task in nb.prange(n_tasks):
        stack = np.empty(128, np.int64)
        gstack = np.empty(64, np.int64)
        ent_t = np.empty(4)
        ent_i = np.empty(4, np.int64)
        work = np.empty((3 * max_d + 8, 4, 4, 3))
        st_i = np.empty(3 * max_d + 8, np.int64)
        st_j = np.empty(3 * max_d + 8, np.int64)
        st_l = np.empty(3 * max_d + 8, np.int64)
        lv = np.empty((4 * 256 + 8, 3))
        lp = np.empty((4 * 256 + 8, 2))
        for q in range(task * RAYS_PER_TASK, min(n_rays, (task + 1) * RAYS_PER_TASK)):
            r = rays[q]
            _trace_ray(r, ox, oy, oz, frame, width, round_no, bvh_min, bvh_max, bvh_first,
                       bvh_count, prims, shell_min, shell_max, patch_slot, slot_depth,
                       slot_vert_off, slot_node_off, slot_quad, slot_round, verts, node_lo,
                       node_hi, lc_off, lc_data, reg_index, nets, reg_depth, reg_side, slack,
                       hits, request, tested, touched, stack, gstack, ent_t, ent_i, work, st_i, st_j,
                       st_l, lv, lp)


@nb.njit(cache=True, error_model="numpy")  # 1/0 -> inf for axis-parallel rays
def _trace_ray(r, ox, oy, oz, frame, width, round_no, bvh_min, bvh_max, bvh_first, bvh_count,
               prims, shell_min, shell_max, patch_slot, slot_depth, slot_vert_off,
               slot_node_off, slot_quad, slot_round, verts, node_lo, node_hi, lc_off, lc_data,
               reg_index, nets, reg_depth, reg_side, slack, hits, request, tested, touched,
               stack,
               gstack, ent_t, ent_i, work, st_i, st_j, st_l, lv, lp):
    row = r // width
    col = r - row * width
    dx, dy, dz = ray_setup(frame, row, col)
    ix, iy, iz = 1.0 / dx, 1.0 / dy, 1.0 / dz
    kx, ky, kz, sx, sy, sz = _shear(dx, dy, dz)
    hit = hits[r]
    req = -1
    req_t = np.inf
    sp = 0
    if _slab(ox, oy, oz, ix, iy, iz, bvh_min, bvh_max, 0, hit[H_T]) < np.inf:
        stack[0] = 0
        sp = 1
    while sp > 0:
        sp -= 1
        node = stack[sp]
        cnt = bvh_count[node]
        if cnt > 0:
            f = bvh_first[node]
            for j in range(f, f + cnt):
                p = prims[j]
                te = _slab(ox, oy, oz, ix, iy, iz, shell_min, shell_max, p, hit[H_T])
                if te == np.inf:
                    continue
                ri = reg_index[p]
                if ri >= 0:
                    if round_no == 0:
                        touched[ri] = 1
                        tested[r] += intersect_bezier(
                            ox, oy, oz, ix, iy, iz, kx, ky, kz, sx, sy, sz, nets, ri,
                            reg_depth[ri], reg_side[ri], slack, hit, -2.0 - p, work, st_i,
                            st_j, st_l, ent_t, ent_i, lv, lp)
                    continue
                s = patch_slot[p]
                if s < 0:
                    if te < req_t:
                        req_t = te
                        req = p
                elif slot_round[s] == round_no - 1:
                    _intersect_slot(ox, oy, oz, ix, iy, iz, kx, ky, kz, sx, sy, sz, s,
                                    slot_depth, slot_vert_off, slot_node_off, slot_quad,
                                    verts, node_lo, node_hi, lc_off, lc_data, slack, hit,
                                    gstack, ent_t, ent_i)
            continue
        left = bvh_first[node]
        right = left + 1
        tl = _slab(ox, oy, oz, ix, iy, iz, bvh_min, bvh_max, left, hit[H_T])
        tr = _slab(ox, oy, oz, ix, iy, iz, bvh_min, bvh_max, right, hit[H_T])
        if tl < np.inf and tr < np.inf:
            if tl <= tr:
                stack[sp] = right
                stack[sp + 1] = left
            else:
                stack[sp] = left
                stack[sp + 1] = right
            sp += 2
        elif tl < np.inf:
            stack[sp] = left
            sp += 1
        elif tr < np.inf:
            stack[sp] = right
            sp += 1
    request[r] = req if req_t < hit[H_T] else -1


from .bezier import intersect_bezier  # noqa: E402  (bezier.py uses _tri from this module)
