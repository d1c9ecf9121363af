"""Ray kernels: the rounds of primary rays through the patch shells.

One ray per pixel from a pinhole camera ``frame`` = [eye, dx, dy, p00] (see
``trace.camera.camera_frame``); ``t`` is the distance from the eye along the unit direction.

Built patches live in the pieces' pool (``trace/pools.py``), Catmull-Clark and Loop alike:
a slot per patch, its items intersected per ray (``geometry/bezier.py``, ``geometry/tris.py``).

A round (:func:`trace_round`) takes each active ray through the patch shells it enters,
from its image tile's list (``accel/projection.py``, nearest box first) or the BVH of the
shells: built patches are intersected (only those built since the ray's previous round:
older ones were tested then), and the nearest *unbuilt* patch whose shell the ray enters
before its best hit so far is recorded as the ray's request. The driver builds the requested
patches, and with them the unbuilt patches whose shells an asking ray entered before its
request's exit (or its hit, if nearer): their shells overlap the request's along the ray, so
the surface that shell hides may lie beyond their entries and the ray would ask for them
next. Taking them a round early saves rounds (each a pass of every asking ray) where shells
overlap, as those of a coarse cage's patches do; a shell that begins past the request's exit
(an object hidden behind another) waits for a round that shows it is reached. Then another
round runs for the rays that asked, each going through just the unbuilt shells it
remembers. This is the refinement criterion: a patch is refined only when a ray reaches its
shell before any closer hit.
"""

from __future__ import annotations


import numpy as np

from subtrace.accel.bvh import (
    BVH, box_entry, bvh_next_leaf, bvh_start, slab_range, traversal_stack,
)
from subtrace.accel.projection import TILE, Tiles
from subtrace.runtime.jit import inline_njit, nb
from subtrace.runtime.memory import one_block
from subtrace.runtime.threads import run_chunks
from subtrace.geometry.bezier import MAX_SIDE_SAMPLES, intersect_patch
from subtrace.trace.pools import CANDIDATES, Candidates, Hits, Memo, PieceArrays
from subtrace.geometry.prims import (
    H_B1, H_B2, H_LEAF, H_SLOT, H_T, H_TRI, HIT_FIELDS, memo_restart, ray_setup, shear,
)


BAND_ROWS = 8  # image rows per band of rays
# bands a thread takes at a time (the next free ones, as it finishes). Each take is a chunk
# with a memo of its own, and a memo holds the splits of its chunk's rays: at one band a
# chunk, the memos' pages held at once are halved (Spot 8.4 -> 4.7 MiB, gen_vase_loop 21 ->
# 11) for the same trace time within 2 % (two bands a chunk before: BENCHMARKS.md, "Memory
# of the streamed render"); four-row bands lost 2-8 % of the trace time
BAND_CHUNK = 1


def trace_round(rays, frame, width, round_no, bvh, tiles, shell_min, shell_max, iso, mems,
                cands, slack, hits, request, tested, loop, base=0):
    """One round for the rays ``rays`` (sorted pixel indices; None: every pixel's): update
    ``hits`` (a :class:`~subtrace.trace.pools.Hits` over all pixels) and set ``request[r]``
    to the nearest unbuilt patch the ray reaches first (or -1). Round 0 starts every ray
    afresh: it writes ``hits``, ``request`` and the candidates of each ray without reading
    them (they need no initial values).

    The ray finds the shells ``[shell_min, shell_max]`` (P,3) it enters in its tile of
    ``tiles`` (:class:`~subtrace.accel.projection.Tiles`, nearest box first) or, when the
    tiles are empty, by walking ``bvh`` (:class:`~subtrace.accel.bvh.BVH`). Patches are
    intersected per ray through their items, ``iso``
    (:class:`~subtrace.trace.pools.PieceArrays`). ``tested[t]`` (one per thread, added to)
    counts the micro-triangles the rays of thread t built. The rays are cut into bands of
    ``BAND_ROWS`` image rows; each of n threads (n = len(mems)) takes the next
    ``BAND_CHUNK`` bands whenever it is free
    (``runtime.threads.run_chunks``), with its own memo of split Bezier nets ``mems[t]`` (a
    :class:`~subtrace.trace.pools.Memo`, see ``bezier.intersect_patch``): neighbouring rays
    of a band share their splits. What a memo holds changes the work, never a hit, so the
    image does not depend on the threads. ``cands``
    (:class:`~subtrace.trace.pools.Candidates`) carries each ray's unbuilt shells to the
    next round. ``loop``: ``bezier.loop_flag`` of the patches (None: no Loop patch, and a
    kernel compiled without the Loop descents). ``base``: the rounds' number in the
    pieces' records (``round``) of this call's round 0: a patch built in round
    ``base + k`` is tested in round ``k + 1`` (in round 0, every patch built before); the
    windows of one image (``trace.rounds.trace_window``) count their rounds on from the last.
    """
    max_d = int(iso.depth_i.max(initial=0))
    band_rows = BAND_ROWS * int(width)
    if rays is None:  # every pixel's ray (round 0): bands of pixels, no list of them
        n_rays = len(hits.t)
        n_bands = -(-n_rays // band_rows)
        bands = np.minimum(np.arange(n_bands + 1, dtype=np.int64) * band_rows, n_rays)
        rays = _ALL_RAYS
    else:
        n_bands = -(-(int(rays[-1]) + 1) // band_rows) if len(rays) else 0
        bands = np.searchsorted(rays, np.arange(n_bands + 1) * band_rows).astype(np.int64)
    scratch = tuple(scratch_buffers(max_d) for _ in mems)
    # the bundles cross into the kernel as plain tuples and are named again inside: Numba's
    # dispatcher types plain tuples of arrays in C but named tuples in Python (28 against
    # 9 us a call, measured; a render of the sword makes about 320 calls)
    args = (float(frame[0, 0]), float(frame[0, 1]), float(frame[0, 2]), frame, int(width),
            int(round_no), int(base), tuple(bvh), tuple(tiles), shell_min, shell_max,
            tuple(iso), tuple(tuple(m) for m in mems), scratch, tuple(cands), float(slack),
            tuple(hits), request, tested, loop)

    def work(t, a, b):
        _trace_task(t, rays, bands[a:b + 1], *args)

    # (at least one call: the warm-up compiles the kernel by tracing no rays)
    run_chunks(work, max(n_bands, 1), BAND_CHUNK, n=len(mems))


# ``rays`` of a round that traces every pixel's ray: the bands index the pixels themselves
_ALL_RAYS = np.zeros(0, np.int64)


def scratch_buffers(max_d):
    """A thread's scratch buffers for items up to depth ``max_d``: BVH stack and its entry
    distances, Bezier nets being split, the quadtree stack and its entry
    distances, child order, a cell's points and parameters (fans included), the ray's hit
    record."""
    n = 6 * max_d + 8
    stack, stack_t = traversal_stack.py_func()  # (numpy's: no kernel to load for it)
    # (in one allocation, each array on cache lines of its own: small arrays allocated one
    # after another may share a line, and a thread's stores would then take it from the
    # thread whose arrays lie beside its own)
    return tuple(one_block(((len(stack),), stack.dtype), ((len(stack_t),), stack_t.dtype),
                     ((3 * max_d + 10, 4, 4, 3), np.float64), ((n, 6), np.int64),
                     ((n,), np.float64), ((4,), np.float64), ((4,), np.int64),
                     ((4 * MAX_SIDE_SAMPLES + 8, 3), np.float64),
                     ((4 * MAX_SIDE_SAMPLES + 8, 2), np.float64), ((HIT_FIELDS,), np.float64)))


@inline_njit
def _load_hit(hit, hits, r, fresh):
    """The ray's working record ``hit`` from ``hits`` (``fresh``: round 0, a new ray)."""
    if fresh:
        for k in range(HIT_FIELDS):
            hit[k] = 0.0
        hit[H_T] = np.inf
        hit[H_SLOT] = -1.0
        return
    hit[H_T] = hits.t[r]
    hit[H_SLOT] = hits.prim[r]
    hit[H_LEAF] = hits.leaf[r]
    hit[H_TRI] = hits.item[r]
    hit[H_B1] = hits.a[r]
    hit[H_B2] = hits.b[r]


@inline_njit
def _store_hit(hit, hits, r):
    """Store the ray's record (a miss writes only its t and prim: what the shading reads of
    the misses stays contiguous)."""
    hits.t[r] = hit[H_T]
    hits.prim[r] = np.int32(hit[H_SLOT])
    if hit[H_T] < np.inf:
        hits.leaf[r] = np.int32(hit[H_LEAF])
        hits.item[r] = np.int32(hit[H_TRI])
        hits.a[r] = hit[H_B1]
        hits.b[r] = hit[H_B2]


@inline_njit
def _sort_candidates(cands, r):
    """Sort ray r's remembered candidates nearest first; returns their count."""
    n = np.int64(cands.count[r])
    for k in range(n):
        m = k
        while m > 0 and cands.t[r, m - 1] > cands.t[r, m]:
            cands.t[r, m - 1], cands.t[r, m] = cands.t[r, m], cands.t[r, m - 1]
            cands.patch[r, m - 1], cands.patch[r, m] = cands.patch[r, m], cands.patch[r, m - 1]
            m -= 1
    return n


@inline_njit
def _visit(p, ray, round_no, base, iso, mem, slack, hit, scratch, loop):
    """Intersect patch ``p`` for the ray if it was built in the previous round (in round
    0: at all; :func:`trace_round`'s ``base``): the micro-triangles that built (0 for an
    older patch), or -1 if it is unbuilt. (A function,
    not a closure of the kernel: a closure over the bundles named inside the kernel lost
    its writes, with Numba 0.68.)"""
    s = iso.patch_iso[p]
    if s < 0:
        return -1
    if round_no > 0 and iso.round[s] != base + round_no - 1:
        return 0
    if iso.touched[s] == 0:  # (a store, even of the same value, takes the cache line from
        iso.touched[s] = 1   # the other threads reading it)
    return intersect_patch(ray, p, s, iso, mem, slack, hit, scratch, loop, -np.inf)


@inline_njit
def _want(wanted, p):
    """Flag patch ``p`` to be built after the round: stored only where not set yet, as
    ``touched`` in :func:`_visit` (rays ask for the same few patches over and over)."""
    if wanted[p] == 0:
        wanted[p] = 1


@inline_njit
def _background_run(tiles, r, col, width, tile, all_rays, request, hits):
    """Record ray ``r`` (pixel column ``col``), whose tile ``tile`` lists no shell, as a
    miss, as :func:`_trace_task` records one (without the ray's set-up; its tile has no
    candidate rows); with ``all_rays`` (every pixel's ray, in pixel order) the rest of the
    row's pixels up to the next tile that lists a shell too (most of an image is
    background). Returns how many rays it recorded."""
    end = col + 1
    if all_rays:
        end = col - col % TILE + TILE
        while end < width and tiles.off[tile + 1] == tiles.off[tile + 2]:
            end += TILE
            tile += 1
        end = min(end, width)
    for x in range(r, r + end - col):
        request[x] = -1
        hits.t[x] = np.inf
        hits.prim[x] = -1
    return end - col


@nb.njit(cache=True, nogil=True, _nrt=False, error_model="numpy")  # see jit.leaf_njit
def _trace_task(task, rays, bands, ox, oy, oz, frame, width, round_no, base, bvh_t, tiles_t,
                shell_min, shell_max, iso_t, mems_t, scratches, cands_t, slack, hits_t,
                request, tested, loop):
    """The bands of rays ``bands`` (band k: rays[bands[k]:bands[k+1]]) on thread ``task``,
    with its memo and scratch buffers; the ``*_t`` are :func:`trace_round`'s bundles as
    plain tuples, named again here."""
    bvh, tiles = BVH(*bvh_t), Tiles(*tiles_t)
    iso, cands, hits = PieceArrays(*iso_t), Candidates(*cands_t), Hits(*hits_t)
    mem = Memo(*mems_t[task])
    memo_restart(mem.root, mem.cnt)  # one chunk of bands: a memo of its own (prims)
    stack, stack_t, work, st, st_t, ent_t, ent_i, lv, lp, hit = scratches[task]
    scratch = (work, st, st_t, ent_t, ent_i, lv, lp)
    projected = len(tiles.off) > 1
    # the micro-triangles this thread's rays built, added to ``tested[task]`` at the end
    # (added to per patch there, the threads' counts shared a cache line)
    n_tested = 0
    for band in range(len(bands) - 1):
        q, q_end = bands[band], bands[band + 1]
        while q < q_end:
            r = q if len(rays) == 0 else rays[q]
            q += 1
            row = r // width
            col = r - row * width
            tile = (row // TILE) * tiles.per_row + col // TILE if projected else 0
            if projected and round_no == 0 and tiles.off[tile] == tiles.off[tile + 1]:
                # no shell projects onto its tile: a miss (and with every pixel's ray, the
                # rest of the row's up to the next tile that lists a shell)
                q += _background_run(tiles, r, col, width, tile, len(rays) == 0, request,
                                     hits) - 1
                continue
            # the ray's row of the candidate lists (pools.Candidates; -1: none, its tile
            # lists built patches only)
            cr = r
            if len(cands.tile_row):
                cr = cands.tile_row[tile]
                if cr >= 0:
                    cr += (row % TILE) * TILE + col % TILE
            dx, dy, dz = ray_setup(frame, row, col)
            ix, iy, iz = 1.0 / dx, 1.0 / dy, 1.0 / dz
            kx, ky, kz, sx, sy, sz = shear(dx, dy, dz)
            _load_hit(hit, hits, r, round_no == 0)  # (round 0: ``hits`` not initialised)
            ray = (ox, oy, oz, ix, iy, iz, kx, ky, kz, sx, sy, sz, dx, dy, dz)
            # the shells the ray may enter, one at a time, from one of three sources: the
            # unbuilt shells it remembers from its last round (nearest first: no traversal),
            # its tile's list (the projection, nearest box first), or the BVH's leaves
            # (nearest child first); one place below handles a shell, so the patch
            # intersection is inlined once
            src = 2
            sp = 0
            j = j_end = np.int64(0)
            if round_no > 0 and cr >= 0 and cands.count[cr] >= 0:
                src = 0
                j_end = _sort_candidates(cands, cr)
            elif projected:
                src = 1
                j, j_end = tiles.off[tile], tiles.off[tile + 1]
            else:
                sp = bvh_start(ox, oy, oz, ix, iy, iz, bvh, 0.0, hit[H_T], stack, stack_t)
            req = -1
            req_t = req_x = np.inf
            n_c = 0
            while True:
                if j == j_end:  # the next BVH leaf
                    j, j_end, sp = bvh_next_leaf(ox, oy, oz, ix, iy, iz, bvh, 0.0,
                                                 hit[H_T], stack, stack_t, sp)
                    if j == j_end:
                        break
                if src == 0:
                    p = np.int64(cands.patch[cr, j])
                    te = cands.t[cr, j]
                    if te >= hit[H_T]:  # it and every later one lie beyond the hit
                        break
                else:
                    if src == 1:
                        p = np.int64(tiles.items[j])
                        if tiles.key[p] >= hit[H_T]:  # it and every later one: beyond the hit
                            break
                    else:
                        p = bvh.prims[j]
                    te = box_entry(ox, oy, oz, ix, iy, iz, shell_min, shell_max, p, 0.0,
                                   hit[H_T])
                j += 1
                if te == np.inf:
                    continue
                built = _visit(p, ray, round_no, base, iso, mem, slack, hit, scratch, loop)
                if built >= 0:
                    n_tested += built
                else:
                    # unbuilt: a candidate (rewritten in place when remembered: n_c < j), the
                    # nearest one the request
                    if cr < 0:  # (no row: traverses its tile again when traced again)
                        n_c = CANDIDATES + 1
                    elif n_c < CANDIDATES:
                        cands.patch[cr, n_c] = p
                        cands.t[cr, n_c] = te
                        n_c += 1
                    else:
                        n_c = CANDIDATES + 1
                    if te < req_t:
                        req_t = te
                        req = p
                        req_x = slab_range(ox, oy, oz, ix, iy, iz, shell_min[p, 0],
                                           shell_min[p, 1], shell_min[p, 2], shell_max[p, 0],
                                           shell_max[p, 1], shell_max[p, 2], 0.0, np.inf)[1]
            request[r] = -1
            if req_t < hit[H_T]:
                # the request, and the unbuilt shells the ray entered before the request's
                # exit (its surface may lie beyond their entries): built together (the
                # flags are only ever set, so threads may race on them)
                request[r] = req
                _want(cands.wanted, req)
                reach = min(req_x, hit[H_T])
                for k in range(min(n_c, CANDIDATES) if cr >= 0 else 0):
                    if cands.t[cr, k] < reach:
                        _want(cands.wanted, cands.patch[cr, k])
            if cr >= 0:
                cands.count[cr] = n_c if n_c <= CANDIDATES else -1
            _store_hit(hit, hits, r)
    tested[task] += n_tested
