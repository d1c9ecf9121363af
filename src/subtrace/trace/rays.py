"""Secondary rays: rays of any origin and direction (shadow rays, extra samples) traced
through the BVH of the patch shells with the primary trace's pools.

The primary trace (``trace.rounds.trace_hits``) leaves its pools behind: the Catmull-Clark pieces
and the Loop nets, pieces and cells (:class:`~subtrace.trace.pools.Pieces`) and each patch's
grid depth. A secondary ray is intersected with exactly the same micro-surface as the
primary rays (the same per-item function, ``bezier.intersect_patch``, at the same depths), so a
shadow ray leaving a hit cannot meet a differently tessellated copy of its own surface.
Patches no primary ray reached (the underside of a model that casts the ground shadow, say)
are built when a secondary ray first enters their shell before any closer hit, in rounds as
for primary rays, at the depth the angular criterion chose for them.

Ray cones: a shadow or ambient occlusion ray leaving a hit at distance t carries the
pixel's cone (spread: the tolerance angle; width t * tol_rad at its origin), whose width
at a point q a distance s along it is tol_rad (t + s). With secondary rays, each patch's
depth is chosen for the narrowest cone that can reach it (``patches.shells.Sight``): every
point a secondary ray leaves lies in a box (the shells in view, the ground plane) at least
``near`` from the eye, so at a box a gap g from that one, t + s >= near + g, and also
t + s >= |q - eye| (triangle inequality). The larger of the two is the distance the
tolerance is taken at: a patch in view gets the eye's depth, as for its pixels; a caster
out of view, nearer the eye than what is in view, is refined no finer than the cones of
the rays that may reach it ask (``secondary_max_depth`` in the render's statistics reports
the deepest grid those rays reached; tests/test_shadows.py, tests/test_cones.py). The
depth is shared by every ray, not cut per ray: a patch's sides must sample the edges its
neighbours built alike (design invariant 4), and a narrower cone reaching it later must
find the surface as fine as it needs.

``any_hit`` rays (shadow rays) stop at the first occluder found before ``tmax``: built
patches are intersected first, and unbuilt ones are built only when no built one occludes.

Array layout: ``origins``, ``dirs`` (R,3) float64 (unit directions), ``tmax`` (R,) float64
(distance to the light, or inf). Results: ``blocked`` (R,) uint8 and the closest hit of each
ray as a :class:`~subtrace.trace.pools.Hits` (t = tmax, prim = -1 where nothing is nearer).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from subtrace import config
from subtrace.accel.bvh import BVH, box_entry, bvh_next_leaf, bvh_start
from subtrace.accel.parallel import ParallelGrid, grid_cell, no_grid, parallel_grid
from subtrace.runtime import threads as tasks
from subtrace.runtime.jit import nb
from subtrace.geometry.bezier import intersect_patch, table_loop_flag
from subtrace.trace.build import build_requested
from subtrace.trace.kernels import scratch_buffers
from subtrace.trace.pools import CANDIDATES, Hits, Memo, Memos, PieceArrays, hit_arrays
from subtrace.geometry.prims import (H_B1, H_B2, H_LEAF, H_SLOT, H_T, H_TRI, HIT_FIELDS, memo_restart,
                                  shear)

RAY_CHUNK = 4096  # rays a thread takes at a time


@dataclass
class Pools:
    """What a finished primary trace leaves for secondary rays: the patch table, each
    patch's grid depth and edge sampling, the pools built so far (``iso``: Pieces), the
    isolation records, the shells and
    their BVH, the eye (a point, or the ``patches.shells.Sight`` the depths were chosen
    from), the tolerance (radians), the render's statistics, the next
    round number and each thread's memo budget (bytes; None: none), the primary trace's.
    :func:`trace_rays` builds into the pools what its rays ask for."""

    table: object
    depths: np.ndarray
    edge_depth: np.ndarray
    iso: object
    record: dict
    shell_min: np.ndarray
    shell_max: np.ndarray
    bvh: BVH
    eye: object
    tol_rad: float
    stats: object
    round_no: int
    memo_bytes: int | None = None
    patch_side: np.ndarray | None = None  # (P,4) the sides' sampling (criterion.edge_sampling)
    # the threads' memos of these rays (None: fresh ones each call). Each chunk of rays
    # starts its memo afresh, so what a memo held for earlier rays is never read: sharing
    # them over the calls of a render (its bands' shadow, occlusion and extra rays) only
    # spares faulting their pages in again
    memos: object = None
    # the grids of the shells seen along the directions of parallel rays (trace_rays),
    # by direction: made once for all the calls that share the shells (None: none yet).
    # A shell only shrinks once made (trace.rounds.trace_window, to its built items' boxes), so
    # a grid made before lists a box in every cell its box now reaches, and more
    grids: dict | None = None


def trace_rays(pools: Pools, origins, dirs, tmax, any_hit: bool):
    """Trace rays ``origins + t dirs``, ``0 < t < tmax``: (blocked (R,) uint8, hits
    (:class:`~subtrace.trace.pools.Hits`)). ``any_hit``: stop at the first occluder (then
    ``hits`` holds that occluder, not necessarily the nearest, and its distance may be
    one no farther than it: ``bezier.intersect_patch``'s ``stop``). Patches a ray reaches
    unbuilt are built into ``pools`` (counted in its statistics). The result does not
    depend on the thread count: a ray's hits depend only on the pools, never on the
    threads' memos.

    Any-hit rays that come in runs of one direction (a directional light's, many in a row:
    :func:`_runs`) find the shells they enter from a grid of the shells seen along it
    (``accel/parallel.py``, kept in ``pools.grids``) instead of the BVH: the same shells,
    so the same answers."""
    n = len(tmax)
    origins = np.ascontiguousarray(origins, np.float64).reshape(n, 3)
    dirs = np.ascontiguousarray(dirs, np.float64).reshape(n, 3)
    tmax = np.ascontiguousarray(tmax, np.float64)
    blocked = np.zeros(n, np.uint8)
    hits = hit_arrays(n)
    if n and not len(pools.shell_min):  # no patch (every face a hole): every ray misses
        # (with no rays the kernel still runs: compile_kernel compiles it so)
        hits.t[:] = tmax
        hits.prim[:] = -1
        hits.leaf[:] = 0
        hits.item[:] = 0
        hits.a[:] = 0.0
        hits.b[:] = 0.0
        return blocked, hits
    first_round = pools.round_no
    for a, b, grid in _runs(pools, dirs, any_hit):
        part = slice(a, b)
        _trace_part(pools, origins[part], dirs[part], tmax[part], any_hit, grid,
                    blocked[part], Hits(*(f[part] for f in hits)))
    _deepest(pools, hits, tmax, first_round)
    return blocked, hits


def _runs(pools, dirs, any_hit):
    """[(a, b, grid)]: the rays [a, b) traced together, with the grid of their one
    direction (:func:`~subtrace.accel.parallel.parallel_grid`) or ``no_grid()`` (the
    BVH): runs of one direction of an any-hit trace long enough to repay the grid (at
    least ``config.PARALLEL_MIN_RAYS`` rays, ``config.PARALLEL_RAYS_PER_SHELL`` per
    shell), and the rays between them."""
    n = len(dirs)
    least = max(config.PARALLEL_MIN_RAYS,
                config.PARALLEL_RAYS_PER_SHELL * len(pools.shell_min))
    if not any_hit or n < least:
        return [(0, n, no_grid())]
    bounds = np.concatenate([[0], _direction_changes(dirs), [n]])
    # (the long runs alone are visited: a soft light's rays change direction at every ray,
    # and a Python pass over the runs was 0.27 s of the default picture's 0.85)
    runs, at = [], 0
    for i in np.nonzero(np.diff(bounds) >= least)[0]:
        a, b = int(bounds[i]), int(bounds[i + 1])
        if a > at:  # (the short runs before it, together)
            runs.append((at, a, no_grid()))
        runs.append((a, b, _grid(pools, dirs[a])))
        at = b
    if at < n:
        runs.append((at, n, no_grid()))
    return runs


@nb.njit(cache=True)
def _direction_changes(dirs):
    """The rays (n,) int64 whose direction is not their predecessor's (a pass over the
    rays; numpy's comparison of the rows and their reduction took three)."""
    out = np.empty(len(dirs), np.int64)
    k = 0
    for r in range(1, len(dirs)):
        if (dirs[r, 0] != dirs[r - 1, 0] or dirs[r, 1] != dirs[r - 1, 1]
                or dirs[r, 2] != dirs[r - 1, 2]):
            out[k] = r
            k += 1
    return out[:k]


def _grid(pools, d):
    """The grid of ``pools``' shells along direction ``d``, made once per direction."""
    if pools.grids is None:
        pools.grids = {}
    key = d.tobytes()
    if key not in pools.grids:
        pools.grids[key] = parallel_grid(pools.shell_min, pools.shell_max, d)
    return pools.grids[key]


def _trace_part(pools, origins, dirs, tmax, any_hit, grid, blocked, hits):
    """:func:`trace_rays` of these rays (views of its arrays), through the rounds: each
    round traces the rays that asked for patches in the last, once those are built."""
    n = len(tmax)
    req = np.empty((n, CANDIDATES), np.int64)
    req_n = np.zeros(n, np.int64)
    n_threads = tasks.thread_count()
    # memos of the secondary rays' own: reusing the primary trace's (warmer: faster)
    # changed a Loop render by an ulp between the projection and the BVH
    # (tests/test_projection.py, random cameras) (within the primary memos' budget: they
    # are gone by now)
    memos = Memos(n_threads, pools.memo_bytes) if pools.memos is None else pools.memos
    built = np.zeros(n_threads, np.int64)
    req_ts = np.empty((n_threads, CANDIDATES))  # each thread's entry distances of req
    rays = np.arange(n, dtype=np.int64)
    loop = table_loop_flag(pools.table)
    first = True
    while len(rays) or first:  # (no rays still run the kernel once: compile_kernel)
        first = False
        iso = pools.iso
        max_d = int(iso.a["depth_i"].max(initial=0))
        scratch = tuple(scratch_buffers(max_d) for _ in range(n_threads))
        mems = tuple(tuple(m) for m in memos.views(len(iso.a["kind"])))
        args = (rays, origins, dirs, tmax, bool(any_hit), tuple(pools.bvh), tuple(grid),
                pools.shell_min, pools.shell_max, tuple(iso.view()),
                mems, scratch, float(config.TRI_SLACK), tuple(hits), blocked, req, req_n,
                req_ts, built, loop)

        def work(t, a, b):
            _rays_task(t, a, b, *args)

        run_chunks(work, len(rays))
        asked = req_n[rays] > 0
        rays = rays[asked]
        if not len(rays):
            break
        flag = np.zeros(pools.table.n_patches, bool)
        for k in range(CANDIDATES):
            ids = req[rays, k][req_n[rays] > k]
            flag[ids] = True
        build_requested(pools.table, np.nonzero(flag)[0], pools.depths, pools.edge_depth,
                        pools.iso, pools.round_no, pools.stats, pools.eye, pools.tol_rad,
                        pools.record, pools.patch_side)
        pools.round_no += 1
    # (each chunk of rays has a memo of its own: its count is the same on any thread)
    pools.stats.micro_triangles += int(built.sum())


def _deepest(pools, hits, tmax, first_round) -> None:
    """Raise ``pools.stats.max_depth`` (if it has one) to the deepest grid these rays
    reached: the depth of the grid each hit (or occluder) was found on, and of every item
    built for them (rounds from ``first_round``)."""
    if not hasattr(pools.stats, "max_depth"):
        return
    hit = hits.t < tmax
    deepest = int(hits.leaf[hit].max(initial=-1))
    a = pools.iso.a
    new = np.nonzero(a["round"] >= first_round)[0]  # slots built for these rays
    count = a["count"][new]
    start = np.repeat(a["first"][new] - np.cumsum(count) + count, count)
    items = start + np.arange(int(count.sum()))
    deepest = max(deepest, int(a["depth_i"][items].max(initial=-1)))
    pools.stats.max_depth = max(pools.stats.max_depth, deepest)


def compile_kernel(schemes=("catmark",)) -> None:
    """Compile the secondary-ray kernel for the current thread
    count (``runtime.threads``) and cages of these ``schemes`` (``bezier.loop_flag``) by
    tracing no rays through empty pools of the types a render passes (a cold cache:
    ``trace.rounds.trace_hits`` does it while the trace kernels compile in another process)."""
    from types import SimpleNamespace

    from subtrace.accel.bvh import no_bvh
    from subtrace.trace.pools import Pieces

    none = np.zeros((0, 3))
    cages = tuple(SimpleNamespace(cage=SimpleNamespace(scheme=s)) for s in schemes)
    pools = Pools(table=SimpleNamespace(objects=cages), depths=None, edge_depth=None,
                  iso=Pieces(0), record={},
                  shell_min=none, shell_max=none, bvh=no_bvh(), eye=np.zeros(3), tol_rad=1.0,
                  stats=SimpleNamespace(micro_triangles=0), round_no=0)
    trace_rays(pools, none, none, np.zeros(0), True)
    _direction_changes(none)  # (and the parallel rays' grid: its lists' kernel)
    parallel_grid(np.zeros((1, 3)), np.ones((1, 3)), np.array([0.0, 0.0, 1.0]))


def run_chunks(work, n_rays):
    """``work(t, a, b)`` over chunks of RAY_CHUNK rays on every thread."""
    n_chunks = max(1, -(-n_rays // RAY_CHUNK))
    tasks.run_chunks(lambda t, a, b: work(t, a * RAY_CHUNK, min(n_rays, b * RAY_CHUNK)),
                     n_chunks, 1)


@nb.njit(cache=True, nogil=True, _nrt=False, error_model="numpy")  # see jit.leaf_njit
def _rays_task(task, a, b, rays, origins, dirs, tmax, any_hit, bvh_t, grid_t, shell_min,
               shell_max, iso_t, mems_t, scratches, slack, hits_t, blocked, req, req_n, req_ts,
               built, loop):
    """Rays ``rays[a:b]`` on thread ``task`` (see :func:`trace_rays`): each walks the BVH
    of the shells from scratch (or its cell's list of the grid ``grid_t``, where it has
    cells: rays of its one direction), intersects the built patches whose shells it enters
    before its best hit and lists (in ``req``, count ``req_n``) the unbuilt ones, nearest
    kept when there are more than CANDIDATES; an ``any_hit`` ray stops at its first
    occluder."""
    bvh, grid = BVH(*bvh_t), ParallelGrid(*grid_t)
    iso, hits = PieceArrays(*iso_t), Hits(*hits_t)
    mem = Memo(*mems_t[task])
    memo_restart(mem.root, mem.cnt)  # one chunk of rays: a memo of its own (geometry/prims.py)
    stack, stack_t, work, st, st_t, ent_t, ent_i, lv, lp, hit = scratches[task]
    scratch = (work, st, st_t, ent_t, ent_i, lv, lp)
    req_t = req_ts[task]
    n_built = 0  # (counted here: threads adding to ``built`` share a cache line)
    for q in range(a, b):
        r = rays[q]
        ox, oy, oz = origins[r, 0], origins[r, 1], origins[r, 2]
        dx, dy, dz = dirs[r, 0], dirs[r, 1], dirs[r, 2]
        ix, iy, iz = 1.0 / dx, 1.0 / dy, 1.0 / dz
        kx, ky, kz, sx, sy, sz = shear(dx, dy, dz)
        ray = (ox, oy, oz, ix, iy, iz, kx, ky, kz, sx, sy, sz, dx, dy, dz)
        for k in range(HIT_FIELDS):
            hit[k] = 0.0
        hit[H_T] = tmax[r]
        hit[H_SLOT] = -1.0
        n_req = 0
        done = False
        stop = tmax[r] if any_hit else -np.inf  # (an any-hit ray's pieces stop at an occluder)
        # the shells the ray enters before its best hit: its grid cell's (nearest along
        # the direction first), or the BVH's leaves' (nearest child first) in turn
        j = j_end = sp = 0
        prims = bvh.prims
        if len(grid.start):
            c = grid_cell(grid, ox, oy, oz)
            if c >= 0:
                j, j_end, prims = grid.start[c], grid.start[c + 1], grid.items
        else:
            sp = bvh_start(ox, oy, oz, ix, iy, iz, bvh, 0.0, hit[H_T], stack, stack_t)
        while not done:
            if j == j_end:
                if sp == 0:
                    break
                j, j_end, sp = bvh_next_leaf(ox, oy, oz, ix, iy, iz, bvh, 0.0, hit[H_T],
                                             stack, stack_t, sp)
                if j == j_end:
                    break
            p = prims[j]
            j += 1
            te = box_entry(ox, oy, oz, ix, iy, iz, shell_min, shell_max, p, 0.0, hit[H_T])
            if te == np.inf:
                continue
            s = iso.patch_iso[p]
            if s >= 0:
                n_built += intersect_patch(ray, p, s, iso, mem, slack, hit, scratch, loop, stop)
            else:
                # unbuilt: keep the CANDIDATES nearest
                m = n_req if n_req < CANDIDATES else CANDIDATES - 1
                if n_req < CANDIDATES or te < req_t[m]:
                    while m > 0 and req_t[m - 1] > te:
                        req_t[m] = req_t[m - 1]
                        req[r, m] = req[r, m - 1]
                        m -= 1
                    req_t[m] = te
                    req[r, m] = p
                    n_req = min(n_req + 1, CANDIDATES)
            if any_hit and hit[H_T] < tmax[r]:
                done = True
        # the hit and the unbuilt shells still nearer than it
        blocked[r] = 1 if hit[H_T] < tmax[r] else 0
        n_keep = 0
        if not done:
            for m in range(n_req):
                if req_t[m] < hit[H_T]:
                    req[r, n_keep] = req[r, m]
                    n_keep += 1
        req_n[r] = n_keep
        hits.t[r] = hit[H_T]
        hits.prim[r] = np.int32(hit[H_SLOT])
        hits.leaf[r] = np.int32(hit[H_LEAF])
        hits.item[r] = np.int32(hit[H_TRI])
        hits.a[r] = hit[H_B1]
        hits.b[r] = hit[H_B2]
    built[task] += n_built
