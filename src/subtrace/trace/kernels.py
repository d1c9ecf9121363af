"""Ray kernels: the rounds of primary rays through the patch shells, and patch-grid traversal.

One ray per pixel from a pinhole camera ``frame`` = [eye, dx, dy, p00] (see
``trace.camera.camera_frame``); ``t`` is the distance from the eye along the unit direction.

Built patches live in pools (see ``render.py``): slot ``s`` holds a grid of depth
``slot_depth[s]`` whose points start at ``slot_vert_off[s]`` in ``verts`` and whose quadtree
node boxes start at ``slot_node_off[s]`` in ``node_lo``/``node_hi``: level ``l`` (4^l nodes)
at ``(4^l - 1) / 3``, node ``i``'s children are ``4i .. 4i+3`` of level ``l+1`` (the multi-level
1-to-4 segmentation of the patch grid), the leaves at level ``depth`` are the micro-faces
whose grid corners are ``lc_data[lc_off[depth, quad] + i]`` (a triangle's 4th is -1).

A round (:func:`trace_round`) takes each active ray through the patch shells it enters,
from its image tile's list (``accel/projection.py``, nearest box first) or the BVH of the
shells: built patches are intersected (only those built since the ray's previous round:
older ones were tested then), and the nearest *unbuilt* patch whose shell the ray enters
before its best hit so far is recorded as the ray's request; the driver builds the requested
patches and runs another round for the rays that asked, each going through just the unbuilt
shells it remembers. This is the refinement criterion: a patch is refined only when a ray
reaches its shell before any closer hit.
"""

from __future__ import annotations


from subtrace.runtime.jit import nb
import numpy as np

from subtrace.accel.projection import TILE
from subtrace.trace.bezier import MAX_SIDE_SAMPLES, intersect_patch
from subtrace.trace.prims import (  # noqa: F401  (H_* are re-exported for the driver)
    H_B1, H_B2, H_LEAF, H_SLOT, H_T, H_TRI, HIT_FIELDS, _shear, _slab, _tri, leaf_njit,
    push_sorted, ray_setup,
)


@leaf_njit
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
                n = push_sorted(ent_t, ent_i, n, te, ci)
        for j in range(n):
            stack[sp] = (child_level << 40) | ent_i[j]
            sp += 1


BAND_ROWS = 8  # image rows per band of rays
BAND_CHUNK = 2  # bands a thread takes at a time (the next free ones, as it finishes)
CANDIDATES = 8  # unbuilt shells a ray remembers between rounds (more: it traverses again)


def trace_round(rays, frame, width, round_no, bvh_min, bvh_max, bvh_first, bvh_count, prims,
                tiles, shell_min, shell_max, patch_slot, slot_depth, slot_vert_off, slot_node_off,
                slot_quad, slot_round, verts, node_lo, node_hi, lc_off, lc_data, iso, mems,
                cands, slack, hits, request, tested):
    """One round for the rays ``rays`` (sorted pixel indices): update ``hits`` (6, n_pixels)
    and set ``request[r]`` to the nearest unbuilt patch the ray reaches first (or -1).
    Round 0 starts every ray afresh: it writes ``hits``, ``tested``, ``request`` and the
    candidate counts of each ray without reading them (they need no initial values).

    Catmull-Clark patches are intersected per ray through their pieces (``render._Pieces``),
    held in the tuple ``iso`` = (slot of each patch (P,) or -1 while unbuilt; per slot:
    first item, item count, round built (-1: from the start); per item: grid depth and side
    sampling depths (I,4) in the patch's units, kind (0: Bezier piece, 1: cell), row in the
    nets / cells, level, origin i0, j0 in units of 2^-level, box lo, hi (I,3), the box of the
    item and the patch's items after it, rest_lo, rest_hi (I,3); the Bezier
    nets (.,4,4,3), the cells' corners (4 rows per cell, (.,3)); and a per-slot flag set
    when a ray tests it).
    Loop patches are grids in the pools. ``tested[r]`` counts the micro-triangles built for
    ray r. The rays are cut into bands of ``BAND_ROWS`` image rows; each of n threads
    (n = len(mems)) takes the next ``BAND_CHUNK`` bands whenever it is free
    (``tasks.run_chunks``), with its own memo of split Bezier nets ``mems[t]`` (see
    ``bezier.intersect_patch``): neighbouring rays of a band share their splits. What a
    memo holds changes the work, never a hit, so the image does not depend on the threads.
    ``cands`` (:func:`candidate_lists`) carries each ray's unbuilt shells to the next round.
    """
    from subtrace.runtime.threads import run_chunks

    max_d = int(iso[4].max(initial=0))
    band_rows = BAND_ROWS * int(width)
    n_bands = -(-(int(rays[-1]) + 1) // band_rows) if len(rays) else 0
    bands = np.searchsorted(rays, np.arange(n_bands + 1) * band_rows).astype(np.int64)
    scratch = tuple(_scratch(max_d) for _ in mems)
    args = (float(frame[0, 0]), float(frame[0, 1]), float(frame[0, 2]), frame, int(width),
            int(round_no), bvh_min, bvh_max, bvh_first, bvh_count, prims, tiles, shell_min,
            shell_max, patch_slot, slot_depth, slot_vert_off, slot_node_off, slot_quad,
            slot_round, verts, node_lo, node_hi, lc_off, lc_data, iso, mems, scratch, cands,
            float(slack), hits, request, tested)

    def work(t, a, b):
        _trace_task(t, rays, bands[a:b + 1], *args)

    # (at least one call: the warm-up compiles the kernel by tracing no rays)
    run_chunks(work, max(n_bands, 1), BAND_CHUNK, n=len(mems))


def candidate_lists(n_rays):
    """Per ray, the unbuilt shells it entered before its best hit (patch ids, entry
    distances, count or -1 when there were more than ``CANDIDATES``): a ray traced again
    after they are built tests just those instead of traversing the BVH again."""
    return (np.empty((n_rays, CANDIDATES), np.int32), np.empty((n_rays, CANDIDATES)),
            np.empty(n_rays, np.int8))  # (set by round 0 for every ray)


def _scratch(max_d):
    """A thread's scratch buffers for grids up to depth ``max_d``: BVH and grid stacks,
    Bezier nets being split, the quadtree stack and its entry distances, child order,
    a cell's points and parameters (fans included), the ray's hit record."""
    n = 6 * max_d + 8
    return (np.empty(128, np.int64), np.empty(64, np.int64), np.empty((3 * max_d + 10, 4, 4, 3)),
            np.empty((n, 5), np.int64), np.empty(n), np.empty(4), np.empty(4, np.int64),
            np.empty((4 * MAX_SIDE_SAMPLES + 8, 3)), np.empty((4 * MAX_SIDE_SAMPLES + 8, 2)),
            np.empty(HIT_FIELDS))


@nb.njit(cache=True, nogil=True, _nrt=False, error_model="numpy")  # see prims.leaf_njit
def _trace_task(task, rays, bands, ox, oy, oz, frame, width, round_no, bvh_min,
                bvh_max, bvh_first, bvh_count, prims, tiles, shell_min, shell_max, patch_slot,
                slot_depth, slot_vert_off, slot_node_off, slot_quad, slot_round, verts,
                node_lo, node_hi, lc_off, lc_data, iso, mems, scratches, cands, slack, hits,
                request, tested):
    """The bands of rays ``bands`` (band k: rays[bands[k]:bands[k+1]]) on thread ``task``,
    with its memo and scratch buffers."""
    mem = mems[task]
    stack, gstack, work, st, st_t, ent_t, ent_i, lv, lp, hit = scratches[task]
    scratch = (work, st, st_t, ent_t, ent_i, lv, lp)
    patch_iso, slot_first, slot_count, iso_round, item_depth, item_side = iso[:6]
    kind, ref, level, i0, j0, it_lo, it_hi, rest_lo, rest_hi, nets, cells, iso_touched = iso[6:]
    cand_p, cand_t, cand_n = cands
    tile_off, tile_items, tile_key, tiles_per_row = tiles
    projected = len(tile_off) > 1

    def visit(p, r, ray):
        """Intersect patch ``p`` if it was built in the previous round; False if unbuilt."""
        s = patch_iso[p]
        if s >= 0:
            if iso_round[s] == round_no - 1:
                iso_touched[s] = 1
                tested[r] += intersect_patch(ray, p, s, slot_first, slot_count, item_depth,
                                             item_side, kind, ref, level, i0, j0, it_lo, it_hi,
                                             rest_lo, rest_hi, nets, cells, mem, slack, hit,
                                             scratch)
            return True
        s = patch_slot[p]
        if s < 0:
            return False
        if slot_round[s] == round_no - 1:
            ox, oy, oz, ix, iy, iz, kx, ky, kz, sx, sy, sz, dx, dy, dz = ray
            _intersect_slot(ox, oy, oz, ix, iy, iz, kx, ky, kz, sx, sy, sz, s, slot_depth,
                            slot_vert_off, slot_node_off, slot_quad, verts, node_lo, node_hi,
                            lc_off, lc_data, slack, hit, gstack, ent_t, ent_i)
        return True

    for band in range(len(bands) - 1):
        for q in range(bands[band], bands[band + 1]):
            r = rays[q]
            row = r // width
            col = r - row * width
            dx, dy, dz = ray_setup(frame, row, col)
            ix, iy, iz = 1.0 / dx, 1.0 / dy, 1.0 / dz
            kx, ky, kz, sx, sy, sz = _shear(dx, dy, dz)
            if round_no == 0:  # a fresh ray: ``hits`` and ``tested`` are not initialised
                for k in range(HIT_FIELDS):
                    hit[k] = 0.0
                hit[H_T] = np.inf
                hit[H_SLOT] = -1.0
                tested[r] = 0
            else:
                for k in range(HIT_FIELDS):
                    hit[k] = hits[k, r]
            ray = (ox, oy, oz, ix, iy, iz, kx, ky, kz, sx, sy, sz, dx, dy, dz)
            # the shells the ray may enter, one at a time, from one of three sources: the
            # unbuilt shells it remembers from its last round (nearest first: no traversal),
            # its tile's list (the projection, nearest box first), or the BVH's leaves
            # (nearest child first); one place below handles a shell, so the patch
            # intersection is inlined once
            src = 2
            sp = 0
            j = j_end = np.int64(0)
            if round_no > 0 and cand_n[r] >= 0:
                src = 0
                j_end = np.int64(cand_n[r])
                for k in range(j_end):  # nearest first
                    m = k
                    while m > 0 and cand_t[r, m - 1] > cand_t[r, m]:
                        cand_t[r, m - 1], cand_t[r, m] = cand_t[r, m], cand_t[r, m - 1]
                        cand_p[r, m - 1], cand_p[r, m] = cand_p[r, m], cand_p[r, m - 1]
                        m -= 1
            elif projected:
                src = 1
                tile = (row // TILE) * tiles_per_row + col // TILE
                j, j_end = tile_off[tile], tile_off[tile + 1]
            elif _slab(ox, oy, oz, ix, iy, iz, bvh_min, bvh_max, 0, hit[H_T]) < np.inf:
                stack[0] = 0
                sp = 1
            req = -1
            req_t = np.inf
            n_c = 0
            while True:
                if j == j_end:  # the next BVH leaf
                    while sp > 0 and j == j_end:
                        sp -= 1
                        node = stack[sp]
                        cnt = bvh_count[node]
                        if cnt > 0:
                            j, j_end = bvh_first[node], bvh_first[node] + cnt
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
                    if j == j_end:
                        break
                if src == 0:
                    p = np.int64(cand_p[r, j])
                    te = cand_t[r, j]
                    if te >= hit[H_T]:  # it and every later one lie beyond the hit
                        break
                else:
                    if src == 1:
                        p = np.int64(tile_items[j])
                        if tile_key[p] >= hit[H_T]:  # it and every later one: beyond the hit
                            break
                    else:
                        p = prims[j]
                    te = _slab(ox, oy, oz, ix, iy, iz, shell_min, shell_max, p, hit[H_T])
                j += 1
                if te < np.inf and not visit(p, r, ray):
                    # unbuilt: a candidate (rewritten in place when remembered: n_c < j), the
                    # nearest one the request
                    if n_c < CANDIDATES:
                        cand_p[r, n_c] = p
                        cand_t[r, n_c] = te
                        n_c += 1
                    else:
                        n_c = CANDIDATES + 1
                    if te < req_t:
                        req_t = te
                        req = p
            request[r] = req if req_t < hit[H_T] else -1
            cand_n[r] = n_c if n_c <= CANDIDATES else -1
            # (a miss writes only its t and slot: fields by rows, so what the shading reads
            # of the misses is contiguous)
            hits[H_T, r] = hit[H_T]
            hits[H_SLOT, r] = hit[H_SLOT]
            if hit[H_T] < np.inf:
                for k in range(HIT_FIELDS):
                    hits[k, r] = hit[k]
