"""Rendering: orchestration only (the maths lives in patches/, accel/, trace/, shade.py).

``render_scene(scene)`` loads the cages, builds the patch table, bins the patch shells into
image tiles (or builds their BVH), chooses each patch's grid depth from the angular
tolerance and makes neighbours sample their shared edges alike, then runs rounds of
``trace.kernels.trace_round``. Regular Catmull-Clark patches are refined per ray inside the
kernel, each thread keeping what its rays split (``trace.pools.Memos``). After each round
the patches that rays asked for are built: irregular Catmull-Clark patches into Bezier
pieces (each with its own depth) and cells (``trace.pools.Pieces``), regular Loop
triangles into quartic Bezier nets split per ray like the quads' (``trace/tris.py``), other
Loop patches into grids with snapped sides and quadtree boxes (``trace.pools.LoopGrids``). The rays that
asked are then traced again. Patches no ray reaches before a closer hit are never refined.
Finally ``shade.py`` turns hits into image channels.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from subtrace import config
from subtrace.accel.bvh import build_bvh, no_bvh
from subtrace.accel.projection import no_tiles, project_shells, tiles_bytes
from subtrace.camera import camera_frame
from subtrace.errors import SceneError
from subtrace.io.limits import check_coordinates, check_valences
from subtrace.mesh.cage import load_cage
from subtrace.patches.criterion import edge_sampling
from subtrace.patches.table import build_patch_table
from subtrace.runtime import threads as tasks
from subtrace.runtime import warmup
from subtrace.picture import paint
from subtrace.shade import CHANNELS, deepest_level, miss_values, patch_shading, shade
from subtrace.subdiv.limit import limit_points
from subtrace.trace.budget import check_memory, choose_within_budget, warn_tiles
from subtrace.trace.build import build_requested
from subtrace.trace.kernels import trace_round
from subtrace.trace.pools import (LoopGrids, Memos, Pieces, candidate_lists, hit_arrays,
                                  leaf_tables)


@dataclass
class RenderStats:
    time_load: float = 0.0
    time_preprocess: float = 0.0
    time_refine: float = 0.0
    time_trace: float = 0.0
    time_shade: float = 0.0
    time_total: float = 0.0
    patches: int = 0
    patches_refined: int = 0
    # built: 2 per cell a thread evaluated first (kept, or a fan counted once) or isolated
    # (threads take bands as they are free, so with several threads the count may differ
    # slightly between runs)
    micro_triangles: int = 0
    grid_points: int = 0
    pieces: int = 0  # regular sub-patches and cells of the isolated irregular patches
    memo_nodes: int = 0  # quadtree nodes of Bezier pieces split and kept by the threads
    memo_full: int = 0  # times a thread's memo ran out during a round (rays split on the spot)
    memo_bytes: int = 0  # bytes of the memos' stores in use at the end
    rounds: int = 0
    max_depth: int = 0  # the deepest grid built (in its patch's units)
    max_level: int = -1  # the deepest level hit: the level channel's maximum (-1: none)
    # the deepest grid depth a cap held a patch to, below what its tolerance asked (-1: no
    # cap), and why: "memory" (the budget), "precision" (what doubles resolve, config:
    # PRECISION_BITS), "size" (Loop grids' quadtree index), comma-separated, or "none"
    depth_cap: int = -1
    depth_cap_reason: str = "none"
    # 1: the projection's tile lists did not fit the memory budget, so rays walked the BVH
    accel_fallback: int = 0
    pixels_covered: int = 0
    rays: int = 0
    shadow_rays: int = 0  # shadow rays traced (towards every light from lit-facing hits)
    time_shadows: float = 0.0  # of time_shade: tracing shadow rays (building included)
    aa_pixels: int = 0  # pixels that got more than their centre ray (--samples)
    aa_rays: int = 0  # the extra rays they got
    time_aa: float = 0.0  # of time_shade: tracing and shading the extra rays
    # built for secondary rays (shadow and anti-aliasing rays: patches no primary ray had
    # reached, micro-triangles they evaluated), not counted in the primary counts above
    secondary_patches_refined: int = 0
    secondary_micro_triangles: int = 0

    def as_attributes(self) -> dict:
        return {f"subtrace:{k}": v for k, v in self.__dict__.items()}


@dataclass
class RenderResult:
    channels: dict  # name -> (H,W) float32
    stats: RenderStats
    camera: object
    tolerance_rad: float
    schemes: tuple
    refined_objects: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    accel: str = "projection"  # how rays found the shells they enter
    # object id of every refined patch (what was built, for tests and reports)


def _shell_walk(chosen, frame, width, height, accel, max_memory, stats):
    """How rays find the shells they enter: (tiles, bvh), one of them empty. Projection
    tiles that would not fit the budget fall back to the BVH, with a warning."""
    if accel == "projection":
        projected = project_shells(chosen.shell_min, chosen.shell_max, frame, width, height,
                                   max_bytes=chosen.left)
        if projected is not None:
            if chosen.left is not None:
                chosen.left -= tiles_bytes(len(projected.items), len(projected.off) - 1)
            return projected, no_bvh()
        warn_tiles(max_memory)  # the lists would not fit the budget: the BVH's do (O(N))
        stats.accel_fallback = 1
    return no_tiles(), build_bvh(chosen.shell_min, chosen.shell_max)


def trace_hits(table, camera, tol_rad, stats, max_depth=None, compiling=None, accel=None,
               progress=None, max_memory=None, keep=None):
    """Run the refinement rounds; returns (hits (:class:`~subtrace.trace.pools.Hits`), the
    Loop grids (:class:`~subtrace.trace.pools.GridArrays`), the Catmull-Clark pieces
    (:class:`~subtrace.trace.pools.Pieces`), every patch refined). ``compiling``: the
    process compiling the trace kernels (``warmup.start``), waited for before the first
    round. ``accel``: how a ray finds the shells it enters, ``"projection"`` (the shells
    binned into image tiles, ``accel/projection.py``) or ``"bvh"`` (``accel/bvh.py``);
    default ``config.PRIMARY_ACCEL``. Either structure is built here (preprocess time).
    ``progress(done, total, label)``: told after each round how many rays are final.
    ``max_memory``: a budget in bytes (None: none); depths whose estimate
    (``patches.criterion.memory_estimate``) exceeds it are capped, with a warning, and the
    threads' memos are kept within what is left. ``max_depth``: an explicit cap on every
    patch's depth (None: only what floating point resolves, ``config.PRECISION_BITS``);
    any cap that holds a patch below its tolerance is warned of and recorded in ``stats``.
    ``keep``: None, or a dict that receives what secondary rays need of the pools
    (``trace.rays.Pools``' fields)."""
    accel = config.PRIMARY_ACCEL if accel is None else accel
    if accel not in ("projection", "bvh"):
        raise ValueError(f"unknown acceleration {accel!r}")
    W, H = camera.width, camera.height
    frame = camera_frame(camera)
    t0 = time.perf_counter()
    chosen = choose_within_budget(table, frame[0], tol_rad, max_depth, max_memory, W * H,
                                  stats)
    stats.time_refine += time.perf_counter() - t0
    t0 = time.perf_counter()
    tiles, bvh = _shell_walk(chosen, frame, W, H, accel, max_memory, stats)
    stats.time_preprocess += time.perf_counter() - t0
    n_threads = tasks.thread_count()
    memo_bytes = (None if chosen.left is None
                  else config.MEMORY_MEMO_MIN_BYTES + chosen.left // n_threads)
    if compiling is not None:
        # a cold cache: while the trace kernels compile elsewhere, compile what the rounds
        # need here (exact limit points of isolated cells), on inputs of the same types
        for o in table.objects[:1]:
            limit_points(o.level, o.points, o.cage.options, which=np.zeros(0, np.int64))
    warmup.wait(compiling)
    return _rounds(table, frame, W, W * H, tol_rad, chosen, tiles, bvh,
                   Memos(n_threads, memo_bytes), stats, progress, keep)


def _rounds(table, frame, width, n_rays, tol_rad, chosen, tiles, bvh, memos, stats, progress,
            keep=None):
    """The rounds of :func:`trace_hits`: trace the rays that asked, build what they asked
    for, until no ray asks."""
    depths = chosen.depths
    edge_depth, reg_side = edge_sampling(table, depths)
    tables = leaf_tables(int(depths[~table.is_quad].max(initial=0)))  # (Loop grids only)
    grids = LoopGrids(table.n_patches)
    iso = Pieces(table.n_patches)
    reg = np.nonzero(table.regular)[0]
    n_irr = int(np.count_nonzero(table.is_quad & ~table.regular))
    iso.reserve("items", len(reg) + 16 * n_irr)
    iso.reserve("nets", len(reg) + 16 * n_irr)
    iso.append_regular(reg, depths[reg], reg_side, table.nets, table.shell_min[reg],
                       table.shell_max[reg])
    hits = hit_arrays(n_rays)
    request = np.empty(n_rays, dtype=np.int64)
    tested = np.empty(n_rays, dtype=np.int64)  # (round 0 writes every ray's entries)
    cands = candidate_lists(n_rays)
    rays = np.arange(n_rays, dtype=np.int64)
    round_no = 0
    while len(rays):
        t0 = time.perf_counter()
        trace_round(rays, frame, width, round_no, bvh, tiles, chosen.shell_min,
                    chosen.shell_max, grids.view(tables), iso.view(),
                    memos.views(len(iso.a["kind"])), cands, config.TRI_SLACK, hits, request,
                    tested)
        stats.time_trace += time.perf_counter() - t0
        req = request[rays]
        asked = req >= 0
        rays = rays[asked]
        if progress is not None:
            progress(n_rays - len(rays), n_rays, f"round {round_no + 1}")
        if not len(rays):
            break
        t0 = time.perf_counter()
        flag = np.zeros(table.n_patches, bool)
        flag[req[asked]] = True
        new = np.nonzero(flag)[0]  # (np.unique, sorted: it hashes every request)
        build_requested(table, new, depths, edge_depth, grids, iso, round_no, stats, frame[0],
                        tol_rad, chosen.record)
        stats.time_refine += time.perf_counter() - t0
        round_no += 1
    stats.rounds = round_no + 1
    memos.finish(stats)
    stats.micro_triangles += int(tested.sum())
    # regular patches count as refined once a ray has descended into them
    direct = iso.a["patch"][(iso.a["round"] < 0) & (iso.a["touched"] > 0)]
    stats.patches_refined += len(direct)
    stats.max_depth = int(max(grids.a["slot_depth"].max(initial=0),
                              iso.a["depth_i"].max(initial=0)))
    built = np.concatenate([grids.a["slot_patch"], iso.a["patch"][iso.a["round"] >= 0], direct])
    if keep is not None:  # for secondary rays (trace/rays.py)
        keep.update(table=table, depths=depths, edge_depth=edge_depth, grids=grids,
                    tables=tables, iso=iso, record=chosen.record, shell_min=chosen.shell_min,
                    shell_max=chosen.shell_max, bvh=bvh, eye=frame[0], tol_rad=tol_rad,
                    stats=stats, round_no=round_no + 1)
    return hits, grids.view(tables), iso, built


def load_objects(scene):
    """Cages of the scene's objects (scheme / boundary overrides applied)."""
    return [load_cage(o.mesh, scheme=o.scheme, boundary=o.boundary_code) for o in scene.objects]


def _check_threads(threads):
    if threads is not None:
        n_max = tasks.max_threads()
        if not 1 <= int(threads) <= n_max:
            raise SceneError(f"expected a thread count from 1 to {n_max}, got {threads}",
                             key="--threads")


def _prepare(scene, cages, stats):
    """Load and check the cages, build the patch table, frame the camera, check the budget:
    (cages, table, camera, tolerance in radians, budget in bytes)."""
    t_start = time.perf_counter()
    if cages is None:
        cages = load_objects(scene)
    for c in cages:
        check_coordinates(c.path, c.points, config.MAX_COORDINATE)
        check_valences(c.path, c.face_sizes, np.diff(c.base.vert_edge_offsets),
                       config.MAX_VALENCE, c.scheme == "catmark")
    stats.time_load = time.perf_counter() - t_start
    t0 = time.perf_counter()
    table = build_patch_table(cages)
    lo = table.shell_min.min(axis=0)
    hi = table.shell_max.max(axis=0)
    points = None
    if scene.camera.is_auto:
        # frame the limit surface: limit points of every object (level 2 on small cages,
        # whose level-1 points are too sparse to reach the silhouette)
        points = np.concatenate([c.limit(2 if c.n_faces < 20000 else 1 if c.n_faces < 200000
                                         else 0)[0] for c in cages])
        lo, hi = points.min(axis=0), points.max(axis=0)
    camera = scene.make_camera(lo, hi, points)
    budget = scene.render.max_memory
    budget = config.default_max_memory() if budget is None else budget
    check_memory(table, camera.width * camera.height, budget, camera.width, camera.height)
    stats.patches = table.n_patches
    stats.rays = camera.width * camera.height
    stats.time_preprocess = time.perf_counter() - t0
    return cages, table, camera, scene.render.tolerance_rad(camera), budget


def render_scene(scene, cages=None, threads=None, progress=None, accel=None) -> RenderResult:
    """Render a :class:`subtrace.io.scene.Scene`; returns the channels and statistics.
    ``accel``: how rays find the shells they enter (see :func:`trace_hits`). ``progress``:
    None, or called as ``progress(done, total, label)`` with the rays whose hits are final
    out of all (e.g. :class:`subtrace.runtime.progress.ProgressBar`); it reaches
    done == total."""
    t_start = time.perf_counter()
    _check_threads(threads)
    accel = config.PRIMARY_ACCEL if accel is None else accel
    if accel not in ("projection", "bvh"):
        raise SceneError(f"expected projection or bvh, got {accel!r}", key="--accel")
    tasks.set_threads(threads)
    stats = RenderStats()
    compiling = warmup.start(tasks.thread_count())  # on a cold cache only
    try:
        cages, table, camera, tol_rad, budget = _prepare(scene, cages, stats)
        if progress is not None:
            progress(0, stats.rays, "tracing")
        keep = {}
        hits, grids, iso, built = trace_hits(table, camera, tol_rad, stats, compiling=compiling,
                                             accel=accel, progress=progress,
                                             max_memory=budget, keep=keep)
    except BaseException:
        warmup.stop(compiling)
        raise
    t0 = time.perf_counter()
    W, H = camera.width, camera.height
    frame = camera_frame(camera)
    # the channels as float32 planes, written in place by the kernel (no conversion pass)
    planes = np.empty((len(CHANNELS), W * H), dtype=np.float32)
    normals = np.empty((W * H, 3))
    pix_patch = np.empty(W * H, np.int64)
    covered = np.zeros(tasks.thread_count(), np.int64)
    patches = patch_shading(table, list(scene.objects))
    shade(frame, W, hits, grids, iso.view(), patches, miss_values(scene.render.background),
          planes, normals, pix_patch, covered)
    paint(scene, cages, camera, keep, hits, normals, pix_patch, patches, planes, stats)
    stats.pixels_covered = int(covered.sum())
    stats.max_level = deepest_level(planes)
    channels = {name: planes[k].reshape(H, W) for k, name in enumerate(CHANNELS)}
    stats.time_shade = time.perf_counter() - t0
    stats.time_total = time.perf_counter() - t_start
    schemes = tuple(c.scheme for c in cages)
    used = "bvh" if stats.accel_fallback else accel
    return RenderResult(channels, stats, camera, tol_rad, schemes, table.object_id[built], used)


# the colour channels are linear Rec.709 / sRGB primaries with a D65 white point
REC709_CHROMATICITIES = (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290)


def result_attributes(result: RenderResult, scene) -> dict:
    """EXR header attributes of a render: camera (``worldToCamera``, ``worldToNDC``),
    ``chromaticities``, what ``Z`` holds, tolerance, schemes, the meshes' file names,
    timings and counts."""
    attrs = dict(result.camera.header_attributes())
    attrs["subtrace:tolerance_rad"] = float(result.tolerance_rad)
    attrs["subtrace:tolerance_px"] = float(result.tolerance_rad / result.camera.pixel_angle())
    attrs["subtrace:scheme"] = ",".join(result.schemes)
    # file names only: a header travels with the image, the user's folders need not
    attrs["subtrace:meshes"] = ";".join(Path(o.mesh).name for o in scene.objects)
    attrs["chromaticities"] = REC709_CHROMATICITIES
    attrs["subtrace:Z"] = "distance from the eye along the pixel's ray (not camera-space z)"
    attrs["subtrace:accel"] = result.accel
    attrs["subtrace:samples"] = int(scene.render.samples or 1)  # rays per edge pixel at most
    attrs["subtrace:shadows"] = int(bool(scene.render.shadows and scene.lights))
    for k, v in result.stats.__dict__.items():
        attrs[f"subtrace:{k}"] = (v if isinstance(v, str) else float(v) if isinstance(v, float)
                                  else int(v))
    return attrs
