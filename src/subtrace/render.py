"""Rendering: orchestration only (the maths lives in patches/, accel/, trace/, shade.py).

``render_scene(scene)`` loads the cages, builds the patch table of the cage faces that can
reach the image (the others' patches are never made: ``faces_in_view``), bins the patch
shells into image tiles (or builds their BVH), chooses each patch's grid depth from the angular
tolerance and makes neighbours sample their shared edges alike, then runs rounds of
``trace.kernels.trace_round``. Regular Catmull-Clark patches are refined per ray inside the
kernel, each thread keeping what its rays split (``trace.pools.Memos``). After each round
the patches that rays asked for are built (``trace.pools.Pieces``): irregular
Catmull-Clark patches into Bezier pieces (each with its own depth) and cells, regular Loop
triangles into quartic Bezier nets split per ray like the quads' (``trace/tris.py``),
irregular Loop triangles into such nets and cells (``patches/isolate_loop.py``). The rays
that asked are then traced again. Patches no ray reaches before a closer hit are never refined.
Finally ``shade.py`` turns hits into image channels. The scene's free-form (trimmed NURBS)
surfaces are traced after that in a pass of their own
(:func:`subtrace.nurbs.scene.nurbs_pass`), which overwrites a pixel's channels where its
hit is nearer.

A render handed to a ``sink`` (``subtrace render`` of an EXR: ``io.exr.ExrBands``) is shaded,
painted and handed over in bands of rows (:func:`render_bands`): its channels are never
held whole. The set-up above is the whole image's, once (:func:`trace_setup`); the rays are
traced for the whole image (:func:`trace_window`), or, for an image of more than
``config.STREAM_TRACE_PIXELS`` or cages of ``config.STREAM_TRACE_FACES`` faces and more,
band by band, so that the hit records are a band's too.
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from subtrace import config
from subtrace.accel.bvh import build_bvh, no_bvh
from subtrace.accel.cull import casting_bounds, secondary_origins, secondary_reach, view_test
from subtrace.accel.projection import TILE, no_tiles, project_shells, tiles_bytes
from subtrace.camera import CameraWindow, whole_image, window_offset
from subtrace.errors import SceneError
from subtrace.io.limits import check_coordinates, check_valences
from subtrace.lights import directional_rows
from subtrace.mesh.cage import load_cage, valence_bound, without_unused_vertices
from subtrace.nurbs.scene import (has_faces, has_surfaces, load_nurbs, nurbs_pass,
                                  picture_hits, with_surfaces)
from subtrace.patches.criterion import edge_sampling
from subtrace.patches.shells import Sight
from subtrace.patches.table import build_patch_table, cage_face_shells, restrict
from subtrace.runtime import threads as tasks
from subtrace.runtime import warmup
from subtrace.runtime.memory import let_go, one_block
from subtrace.picture import ground_plane, ground_shadow_points, lit_in_shading, paint
from subtrace.shade import (C_OBJECT, C_R, CHANNELS, background_rows, deepest_level,
                            miss_values, patch_shading, shade)
from subtrace.subdiv.limit import limit_points
from subtrace.tiles import check_crop
from subtrace.trace.bezier import table_loop_flag
from subtrace.trace.budget import check_memory, choose_within_budget, warn_tiles
from subtrace.trace.build import build_loop_regular, build_requested, cut_to_loop_nets
from subtrace.trace.kernels import trace_round
from subtrace.trace.pools import Hits, Memos, Pieces, candidate_lists, round_arrays
from subtrace.trace.rays import compile_kernel as compile_secondary
from subtrace.trace.tris import TRI


@dataclass
class RenderStats:
    time_load: float = 0.0
    time_preprocess: float = 0.0
    time_refine: float = 0.0
    time_trace: float = 0.0
    time_shade: float = 0.0
    time_total: float = 0.0
    patches: int = 0  # patches built into the table (those in view, of cage faces in view)
    faces_culled: int = 0  # cage faces outside the view, whose patches were never built
    patches_refined: int = 0
    # built: 2 per cell a thread tested first (its corners evaluated and kept, or a fan
    # counted once) or isolated
    # (threads take bands as they are free, so with several threads the count may differ
    # slightly between runs)
    micro_triangles: int = 0
    pieces: int = 0  # regular sub-patches and cells of the isolated irregular patches
    memo_nodes: int = 0  # quadtree nodes of Bezier pieces split and kept by the threads
    memo_full: int = 0  # times a thread's memo ran out during a round (rays split on the spot)
    memo_bytes: int = 0  # the most bytes the memos' stores held at once (summed over threads)
    rounds: int = 0
    max_depth: int = 0  # the deepest grid built (in its patch's units)
    max_level: int = -1  # the deepest level hit: the level channel's maximum (-1: none)
    # the deepest grid depth a cap held a patch to, below what its tolerance asked (-1: no
    # cap), and why: "memory" (the budget), "precision" (what doubles resolve, config:
    # PRECISION_BITS), "size" (Loop patches: LOOP_MAX_ISOLATED_DEPTH, LOOP_MAX_INSIDE_DEPTH),
    # "depth" (an explicit maximum depth), comma-separated, or "none"
    depth_cap: int = -1
    depth_cap_reason: str = "none"
    # 1: the projection's tile lists did not fit the memory budget, so rays walked the BVH
    accel_fallback: int = 0
    pixels_covered: int = 0
    rays: int = 0
    shadow_rays: int = 0  # shadow rays traced (towards every light from lit-facing hits;
    # the ground's only where they may meet an object: shade.ground_pixels)
    time_shadows: float = 0.0  # of time_shade: tracing shadow rays (building included)
    aa_pixels: int = 0  # pixels that got more than their centre ray (--samples)
    aa_rays: int = 0  # the extra rays they got
    time_aa: float = 0.0  # of time_shade: tracing and shading the extra rays
    ao_rays: int = 0  # ambient occlusion rays traced ([render] ao per hit, extra rays too)
    time_ao: float = 0.0  # of time_shade: tracing them (building included)
    # built for secondary rays (shadow and anti-aliasing rays: patches no primary ray had
    # reached, micro-triangles they evaluated), not counted in the primary counts above
    secondary_patches_refined: int = 0
    secondary_micro_triangles: int = 0
    # the deepest grid (in its patch's units, as max_depth) secondary rays reached: where
    # they found their hits or occluders, and what they built (-1: no secondary ray hit)
    secondary_max_depth: int = -1

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
    # crop: (x0, y0, x1, y1), the pixels of ``camera``'s image the channels hold; None: all
    crop: tuple | None = None


def _shell_walk(chosen, frame, width, height, accel, max_memory, stats, image=None):
    """How rays find the shells they enter: (tiles, bvh), one of them empty. Projection
    tiles that would not fit the budget fall back to the BVH, with a warning. ``image``:
    the whole image's (width, height) when ``frame`` is a window's."""
    if accel == "projection":
        projected = project_shells(chosen.shell_min, chosen.shell_max, frame, width, height,
                                   max_bytes=chosen.left, image=image)
        if projected is not None:
            if chosen.left is not None:
                chosen.left -= tiles_bytes(len(projected.items), len(projected.off) - 1)
            return projected, no_bvh()
        warn_tiles(max_memory)  # the lists would not fit the budget: the BVH's do (O(N))
        stats.accel_fallback = 1
    return no_tiles(), build_bvh(chosen.shell_min, chosen.shell_max)


def trace_hits(table, camera, tol_rad, stats, max_depth=None, compiling=None, accel=None,
               progress=None, max_memory=None, keep=None, seen=None):
    """Run the refinement rounds; returns (hits (:class:`~subtrace.trace.pools.Hits`), the
    built patches (:class:`~subtrace.trace.pools.Pieces`), every patch refined). ``compiling``: the
    processes compiling the trace kernels (``warmup.start``), waited for before the first
    round. ``accel``: how a ray finds the shells it enters, ``"projection"`` (the shells
    binned into image tiles, ``accel/projection.py``) or ``"bvh"`` (``accel/bvh.py``);
    default ``config.PRIMARY_ACCEL``. Either structure is built here (preprocess time).
    ``progress(done, total, label)``: told after each round how many rays are final.
    ``max_memory``: a budget in bytes (None: none); depths whose estimate
    (``patches.criterion.memory_estimate``) exceeds it are capped, with a warning, and the
    threads' memos are kept within what is left. ``max_depth``: an explicit cap on every
    patch's depth (None: only what floating point resolves, ``config.PRECISION_BITS``);
    any cap that holds a patch below its tolerance is warned of and recorded in ``stats``.
    The pieces take over the table's net store (``patches.table.net_room``) and append to
    it past the table's nets: a table serves one call at a time.
    ``keep``: None, or a dict that receives what secondary rays need of the pools
    (``trace.rays.Pools``' fields). ``seen``: None (primary rays alone), or where the
    secondary rays start (``accel.cull.secondary_origins``): depths are then chosen for
    the narrowest cone that may reach each patch (``patches.shells.Sight``)."""
    shared = trace_setup(table, camera, tol_rad, stats, max_depth, compiling, accel,
                         max_memory, seen)
    hits = trace_window(shared, camera.frame(), camera.width, camera.height, progress, keep)
    return hits, shared.iso, shared.finish()


class SharedTrace:
    """What the rays of every window of one image share (:func:`trace_setup`): the
    depths, the shells and the structure rays find them by, the threads' memos and the
    built patches. A patch built for one window's rays is there for the next window's.
    ``finish()`` counts what was refined into the stats and returns the patches refined."""

    def __init__(self, table, chosen, tiles, bvh, memos, iso, edge_depth, eye, tol_rad,
                 stats, windows):
        self.table, self.chosen, self.tiles, self.bvh = table, chosen, tiles, bvh
        self.memos, self.iso, self.edge_depth, self.eye = memos, iso, edge_depth, eye
        self.tol_rad, self.stats, self.windows = tol_rad, stats, windows
        self.loop = table_loop_flag(table)  # (None: a kernel without the Loop descents)
        self.rounds = 0  # the most rounds a window took
        self.built_rounds = []  # the pieces' round numbers of the primary rays' builds

    def window_tiles(self, frame, height):
        """The projection's tiles of the window of ``frame`` (full rows of the image, from
        an even row) and ``height`` rows: a view of the image's lists (none with the BVH)."""
        if len(self.tiles.off) <= 1:
            return self.tiles
        col0, row0 = window_offset(frame)
        per_row = int(self.tiles.per_row)
        if col0 or row0 % TILE:
            raise ValueError("a window of the image's tiles has full rows from an even row")
        b0, ty = row0 // TILE, -(-int(height) // TILE)
        return self.tiles._replace(off=self.tiles.off[b0 * per_row:(b0 + ty) * per_row + 1])

    def finish(self):
        """Count the patches refined and pieces made into the stats; returns the ids of
        every patch refined."""
        stats, iso = self.stats, self.iso
        stats.rounds = self.rounds
        self.memos.finish(stats)
        # regular patches count as refined once a ray has descended into them
        first = (iso.a["round"] < 0) & (iso.a["touched"] > 0)
        direct = iso.a["patch"][first]
        stats.patches_refined += len(direct)
        # (regular Loop nets are built before the first round: they count as pieces once a
        # ray descends into them, as they did when rays asked for them)
        stats.pieces += int(np.count_nonzero(first & (iso.a["kind"][iso.a["first"]] == TRI)))
        # (what secondary rays built between windows is counted apart: picture.py)
        primary = np.isin(iso.a["round"], self.built_rounds)
        keep = primary | (iso.a["round"] < 0)
        starts, count = iso.a["first"][keep], iso.a["count"][keep]
        items = np.repeat(starts - np.cumsum(count) + count, count) + np.arange(count.sum())
        stats.max_depth = int(iso.a["depth_i"][items].max(initial=0))
        return np.concatenate([iso.a["patch"][primary], direct])


def trace_setup(table, camera, tol_rad, stats, max_depth=None, compiling=None, accel=None,
                max_memory=None, seen=None, windows=False) -> SharedTrace:
    """What :func:`trace_hits` does before its rounds (see there): the depths, the shells'
    projection (or BVH), the memos, the regular patches' pieces; the kernels waited for.
    ``windows``: the rays will be traced in windows of full rows of ``camera``'s image
    (:meth:`SharedTrace.window_tiles`), not all at once."""
    accel = config.PRIMARY_ACCEL if accel is None else accel
    if accel not in ("projection", "bvh"):
        raise ValueError(f"unknown acceleration {accel!r}")
    W, H = camera.width, camera.height
    frame = camera.frame()
    # (a window, ``camera.CameraWindow``, budgets for its own pixels)
    whole = whole_image(camera)
    t0 = time.perf_counter()
    eye = frame[0] if seen is None else Sight(frame[0], *seen)
    # (the budget is the image's, in windows too: the same depths as a render at once)
    chosen = choose_within_budget(table, eye, tol_rad, max_depth, max_memory, W * H, stats)
    stats.time_refine += time.perf_counter() - t0
    t0 = time.perf_counter()
    cut_to_loop_nets(table, chosen.shell_min, chosen.shell_max)
    tiles, bvh = _shell_walk(chosen, frame, W, H, accel, max_memory, stats,
                             None if whole is camera else (whole.width, whole.height))
    stats.time_preprocess += time.perf_counter() - t0
    n_threads = tasks.thread_count()
    memo_bytes = (None if chosen.left is None
                  else config.MEMORY_MEMO_MIN_BYTES + chosen.left // n_threads)
    if compiling is not None:
        # a cold cache: while the trace kernels compile elsewhere, compile what the rounds
        # need here (exact limit points of isolated cells), on inputs of the same types
        for o in table.objects[:1]:
            limit_points(o.level, o.points, o.cage.options, which=np.zeros(0, np.int64))
        if not compiling.secondary:  # (else a third process compiles them)
            # shadow and extra anti-aliasing rays
            compile_secondary([o.cage.scheme for o in table.objects])
        # the picture's lights, edge flags and background until the trace kernel is ready
        warmup.picture_while_tracing(compiling, tasks.thread_count())
    warmup.wait_traced(compiling)
    depths = chosen.depths
    edge_depth, reg_side = edge_sampling(table, depths)
    iso = Pieces(table.n_patches)
    reg = np.nonzero(table.regular)[0]
    n_irr = int(np.count_nonzero(table.is_quad & ~table.regular))
    iso.reserve("items", len(reg) + 16 * n_irr)
    # the pieces' net store is the table's: its nets, then room for the rest (no copy)
    store = table.nets if table.nets.base is None else table.nets.base
    iso.adopt("nets", len(table.nets), nets=store)
    iso.reserve("nets", len(reg) + 16 * n_irr)
    iso.append_regular(reg, depths[reg], reg_side, None, table.shell_min[reg],
                       table.shell_max[reg])
    build_loop_regular(table, depths, edge_depth, iso)
    return SharedTrace(table, chosen, tiles, bvh, Memos(n_threads, memo_bytes), iso,
                       edge_depth, eye, tol_rad, stats, windows and whole is camera)


def trace_window(shared, frame, width, height, progress=None, keep=None, hits=None):
    """The rounds of the rays of the window ``frame`` (``width`` x ``height`` pixels; the
    whole image's frame, or a window's of full rows: :meth:`SharedTrace.window_tiles`):
    trace the rays that asked, build what they asked for, until no ray asks. Returns the
    hit records (in ``hits``, (Hits, requests) of at least the window's pixels, when
    given). ``keep``: as in :func:`trace_hits`."""
    table, chosen, iso, memos, stats = (shared.table, shared.chosen, shared.iso, shared.memos,
                                        shared.stats)
    depths = chosen.depths
    n_rays = width * height
    tiles = shared.window_tiles(frame, height) if shared.windows else shared.tiles
    # (round 0 writes every ray's request)
    if hits is None:
        hits, request = round_arrays(n_rays)
    else:
        hits, request = Hits(*(f[:n_rays] for f in hits[0])), hits[1][:n_rays]
    # the micro-triangles each thread's rays built (each chunk of rays counts what its own
    # memo built: the sum is the same on any threads)
    tested = np.zeros(len(memos.m), np.int64)
    # (rows for the pixels of the tiles that list a patch, in bands one still unbuilt:
    # pools.Candidates)
    cands = candidate_lists(n_rays, table.n_patches, tiles,
                            iso.patch_iso < 0 if shared.windows else None)
    rays = None  # round 0: every pixel's ray
    round_no = 0
    # (the pieces record the round they were built in: this window's rounds are numbered
    # on from every earlier build, its secondary rays' too)
    base = int(iso.a["round"].max(initial=-1)) + 1
    while rays is None or len(rays):
        t0 = time.perf_counter()
        trace_round(rays, frame, width, round_no, shared.bvh, tiles, chosen.shell_min,
                    chosen.shell_max, iso.view(), memos.views(len(iso.a["kind"])), cands,
                    config.TRI_SLACK, hits, request, tested, shared.loop, base)
        stats.time_trace += time.perf_counter() - t0
        # the rays that asked: traced again
        rays = np.flatnonzero(request >= 0) if rays is None else rays[request[rays] >= 0]
        if progress is not None:
            progress(n_rays - len(rays), n_rays, f"round {round_no + 1}")
        if not len(rays):
            break
        t0 = time.perf_counter()
        new = np.nonzero(cands.wanted)[0]  # (kernels.py: requests and what they overlap)
        cands.wanted[:] = 0
        build_requested(table, new, depths, shared.edge_depth, iso, base + round_no, stats,
                        shared.eye, shared.tol_rad, chosen.record)
        # a built patch's shell shrinks to its items' boxes (all that rays test of it):
        # later rounds, and the secondary rays' BVH, enter it less often
        built = new[iso.patch_iso[new] >= 0]
        if len(built):
            lo, hi = iso.item_boxes(built)
            chosen.shell_min[built] = np.maximum(chosen.shell_min[built], lo)
            chosen.shell_max[built] = np.minimum(chosen.shell_max[built], hi)
        stats.time_refine += time.perf_counter() - t0
        shared.built_rounds.append(base + round_no)
        round_no += 1
    shared.rounds = max(shared.rounds, round_no + 1)
    stats.micro_triangles += int(tested.sum())
    if keep is not None:  # for secondary rays (trace/rays.py)
        keep.update(table=table, depths=depths, edge_depth=shared.edge_depth, iso=iso,
                    record=chosen.record, shell_min=chosen.shell_min,
                    shell_max=chosen.shell_max, bvh=keep.get("bvh", shared.bvh),
                    eye=shared.eye, tol_rad=shared.tol_rad, stats=stats,
                    round_no=base + round_no + 1,
                    memo_bytes=memos.max_bytes)
    return hits


def cage_objects(scene) -> list[int]:
    """Indices of the scene's objects that have a cage: all but OBJ files of free-form
    surfaces only (those render through ``nurbs/scene.py`` alone)."""
    return [k for k, o in enumerate(scene.objects)
            if not has_surfaces(o.mesh) or has_faces(o.mesh)]


def load_objects(scene):
    """Cages of the scene's objects (scheme / boundary overrides applied), in the order of
    :func:`cage_objects`, their coordinates checked and the vertices no face uses left out
    (``mesh.cage.without_unused_vertices``: checked first, so a message's vertex number
    is the file's)."""
    cages = []
    for o in (scene.objects[k] for k in cage_objects(scene)):
        c = load_cage(o.mesh, scheme=o.scheme, boundary=o.boundary_code, prim=o.prim,
                      time=o.time)
        check_coordinates(c.path, c.points, config.MAX_COORDINATE, c.points_box)
        cages.append(without_unused_vertices(c))
    return cages


def scene_bounds(cages, nurbs=None):
    """(lo, hi) that the automatic camera frames: the bounds of the level-1 limit points of
    every object (the limit surface, not the cage), and of the free-form surfaces ``nurbs``
    (their patches' control points)."""
    bounds = [c.bounds() for c in cages]
    if nurbs is not None:
        bounds.append(nurbs.bounds())
    return np.min([b[0] for b in bounds], axis=0), np.max([b[1] for b in bounds], axis=0)


def check_extent(cages, lo, hi) -> None:
    """SceneError naming the cages when their limit surface's box [lo, hi] is a point
    (every vertex at one place): nothing an automatic camera could frame (its eye would
    be the point it looks at)."""
    scale = max(1.0, float(np.abs(lo).max()), float(np.abs(hi).max()))
    if float((hi - lo).max()) > 1e-12 * scale:
        return
    where = ", ".join(f"{v:.6g}" for v in lo)
    if len(cages) == 1:
        raise SceneError(f"the cage has no extent: its vertices all lie at one point "
                         f"({where}); nothing to frame", path=cages[0].path)
    names = ", ".join(str(c.path) for c in cages)
    raise SceneError(f"the cages {names} have no extent: their vertices all lie at one "
                     f"point ({where}); nothing to frame")


def faces_in_view(cages, camera, reach=None):
    """Per cage, a (F,) bool mask of the faces whose limit surface a primary ray may reach:
    the box that holds it (``patches.table.cage_face_shells``) projects into the image
    (``accel.projection.boxes_in_view``, the test the tile lists make). The patches of the
    other faces are never built (design invariant 5). ``reach``: None, or the
    :class:`~subtrace.accel.cull.Reach` of the scene's shadow and ambient occlusion rays
    (:func:`~subtrace.accel.cull.secondary_reach`): the faces those may meet from a point
    in view are kept too."""
    in_view = view_test(camera, reach)
    return [in_view(*cage_face_shells(c)) for c in cages]


def table_in_view(cages, camera, reach=None):
    """The patch table of what a ray of ``camera`` (or a secondary ray, with ``reach``) may
    reach: the patches of the cage faces in view (:func:`faces_in_view`) whose own
    one-ring box is in view too. Returns (table, the per-cage masks of the faces kept)."""
    keep = faces_in_view(cages, camera, reach)
    # (a large cage seen in part: its topology built around the faces kept alone)
    cut = [restrict(c, k) for c, k in zip(cages, keep)]
    return build_patch_table([c for c, _ in cut], [k for _, k in cut],
                             view_test(camera, reach)), keep


def _valences(cage):
    """Each vertex's valence for ``check_valences``: a bound from the face lists where it
    is within ``config.MAX_VALENCE`` (no topology built for it), else the exact ones."""
    bound = valence_bound(cage)
    return bound if bound.max(initial=0) <= config.MAX_VALENCE else np.diff(
        cage.base.vert_edge_offsets)


def _prepare(scene, cages, stats, nurbs=None, crop=None, compiling=None):
    """Load and check the cages, frame the camera (around the free-form surfaces ``nurbs``
    too), build the patch table of the cage faces in view, check the budget against the
    pixels traced (the image's, or the window of its ``crop``: :func:`crop_window`):
    (cages, table (None without cages), camera, the camera or its window, tolerance in
    radians, budget in bytes, where secondary rays start: ``accel.cull.secondary_origins``,
    None without shadows or ambient occlusion). ``compiling``: the processes compiling the
    trace kernels (``warmup.start``), told the cages' schemes once they are loaded."""
    t_start = time.perf_counter()
    if cages is None:
        cages = load_objects(scene)
    warmup.tell(compiling, [c.scheme for c in cages])
    if not cages:
        lo, hi = nurbs.bounds()
        camera = scene.make_camera(lo, hi)
        view = camera if crop is None else crop_window(camera, crop, apron(scene))
        stats.rays = view.width * view.height
        stats.time_load = time.perf_counter() - t_start
        return cages, None, camera, view, scene.render.tolerance_rad(camera), None, None
    for c in cages:
        check_coordinates(c.path, c.points, config.MAX_COORDINATE, c.points_box)
        check_valences(c.path, c.face_sizes, _valences(c),
                       config.MAX_VALENCE, c.scheme == "catmark")
    stats.time_load = time.perf_counter() - t_start
    t0 = time.perf_counter()
    lo = hi = points = None
    if scene.camera.is_auto:
        # frame the limit surface: limit points of every object (level 2 on small cages,
        # whose level-1 points are too sparse to reach the silhouette), and the corners of
        # the box of the free-form surfaces' control points
        extra = []
        if nurbs is not None:
            b = nurbs.bounds()
            extra = [np.array([[b[i & 1][0], b[(i >> 1) & 1][1], b[i >> 2][2]]
                               for i in range(8)])]
        points = np.concatenate([c.limit(2 if c.n_faces < 20000 else 1 if c.n_faces < 200000
                                         else 0)[0] for c in cages] + extra)
        lo, hi = points.min(axis=0), points.max(axis=0)
        if scene.camera.eye is None and nurbs is None:
            check_extent(cages, lo, hi)
        # and the shadows on the ground; the eye outside every cage's box
        points = np.concatenate([points, ground_shadow_points(scene, cages, points, nurbs)])
        lo, hi = points.min(axis=0), points.max(axis=0)
    camera = scene.make_camera(lo, hi, points, [c.points_box for c in cages])
    # (shadow and ambient occlusion rays may meet what the camera does not see; the
    # ground's shadows are bounded by where the ground is)
    secondary = bool(scene.lights and scene.render.shadows) or scene.render.ao > 0
    with contextlib.ExitStack() as stack:  # (the ground's height and the cull share them)
        for c in cages:
            stack.enter_context(c.sharing_star_boxes())
        ground = ground_plane(scene, cages, camera, nurbs) if secondary else None
        reach = secondary_reach(scene, casting_bounds(cages, nurbs), camera,
                                ground if scene.lights and scene.render.shadows else None)
        if config.CULL_TO_VIEW and reach is not None:
            table, keep = table_in_view(cages, camera, reach)
            stats.faces_culled = int(sum(np.count_nonzero(~k) for k in keep))
        else:
            table = build_patch_table(cages)
    budget = scene.render.max_memory
    budget = config.default_max_memory() if budget is None else budget
    view = camera if crop is None else crop_window(camera, crop, apron(scene))
    check_memory(table, view.width * view.height, budget, view.width, view.height)
    stats.patches = table.n_patches
    stats.rays = view.width * view.height
    # where shadow and ambient occlusion rays start: their cones refine what they reach
    # (patches.shells.Sight), from the whole image's camera (a crop's tiles alike)
    # (the shells: they hold the boxes the rays test, patches.table._ray_shells, so a
    # patch in view is no nearer the eye than ``near``, and keeps the eye's depth)
    seen = (secondary_origins(camera, table.shell_min, table.shell_max, ground,
                              None if nurbs is None else nurbs.bounds())
            if secondary else None)
    stats.time_preprocess = time.perf_counter() - t0
    return cages, table, camera, view, scene.render.tolerance_rad(camera), budget, seen


def crop_window(camera, crop, margin=1) -> CameraWindow:
    """The window of ``camera``'s image that :func:`render_scene` traces for ``crop`` =
    (x0, y0, x1, y1) (pixels, x1 and y1 excluded; checked: SceneError naming --crop): the
    crop and ``margin`` pixels around it (anti-aliasing compares each pixel with its right
    and lower neighbours: 1; smoothed ambient occlusion reads its neighbours within
    config.AO_SMOOTH_RADIUS more: :func:`apron`), widened to even bounds (the projection's
    tiles are 2x2 pixels of the image) and held within the image. Every pixel of the crop
    is then traced and shaded exactly as in the whole image."""
    x0, y0, x1, y1 = check_crop(crop, camera.width, camera.height)
    a = TILE
    wx0, wy0 = max(x0 - margin, 0) // a * a, max(y0 - margin, 0) // a * a
    wx1 = min(-(-(x1 + margin) // a) * a, camera.width)
    wy1 = min(-(-(y1 + margin) // a) * a, camera.height)
    return CameraWindow(camera, wx0, wy0, wx1 - wx0, wy1 - wy0)


def apron(scene) -> int:
    """The pixels a tile's window holds around the tile (:func:`crop_window`): none when a
    pixel's value is its own rays' alone (one ray a pixel, no ambient occlusion)."""
    if (scene.render.samples or 1) <= 1 and scene.render.ao <= 0:
        return 0
    return 1 + (config.AO_SMOOTH_RADIUS if scene.render.ao > 0 else 0)


def _threads_and_accel(threads, accel) -> str:
    """Set the render's threads up (``runtime.threads``); the acceleration ``accel``
    checked (SceneError naming --accel), its default filled in."""
    threads = tasks.usable_threads(threads)
    accel = config.PRIMARY_ACCEL if accel is None else accel
    if accel not in ("projection", "bvh"):
        raise SceneError(f"expected projection or bvh, got {accel!r}", key="--accel")
    tasks.set_threads(threads)
    return accel


def render_scene(scene, cages=None, threads=None, progress=None, accel=None,
                 crop=None, sink=None, band_rows=None, trace_bands=None) -> RenderResult:
    """Render a :class:`subtrace.io.scene.Scene`; returns the channels and statistics.
    ``accel``: how rays find the shells they enter (see :func:`trace_hits`). ``progress``:
    None, or called as ``progress(done, total, label)`` with the rays whose hits are final
    out of all (e.g. :class:`subtrace.runtime.progress.ProgressBar`); it reaches
    done == total. ``cages``: the scene's cages already loaded (its free-form surfaces are
    then not rendered); None: loaded here, with the free-form surfaces of its OBJ files.
    ``crop``: (x0, y0, x1, y1), a tile of the image (pixels, x1 and y1 excluded): only the
    rays of its :func:`crop_window` are traced and the channels are the tile's, equal bit
    for bit to those pixels of the whole render (the camera, tolerance, patch table, depths
    and projection lists are the whole image's; the per-pixel arrays are the window's, and
    the memory budget holds them: where the whole image's pixels would make the budget cap
    depths (a warning says so), its tiles, needing less, may be refined further).
    ``sink``: None (the result holds the channels), or ``sink(y0, y1, channels)``, told
    the image's rows [y0, y1) (name -> (y1 - y0, W) float32 views, valid during the call)
    band after band, top to bottom (:func:`render_bands`; ``band_rows``: their height;
    ``trace_bands``: whether the rays are traced band by band too, None: for an image of
    more than ``config.STREAM_TRACE_PIXELS`` or cages of at least
    ``config.STREAM_TRACE_FACES`` faces): the result's channels are then empty. Only
    a whole image of cages is rendered in bands (a crop, or free-form surfaces, go to the
    sink as one band)."""
    t_start = time.perf_counter()
    accel = _threads_and_accel(threads, accel)
    stats = RenderStats()
    compiling = warmup.start(tasks.thread_count())  # on a cold cache only
    try:
        owners = cage_objects(scene) if cages is None else list(range(len(cages)))
        nurbs = load_nurbs(scene) if cages is None else None  # free-form surfaces
        cages, table, camera, view, tol_rad, budget, seen = _prepare(scene, cages, stats,
                                                                     nurbs, crop, compiling)
        if compiling is None and table is not None:  # the kernel for other schemes only
            compiling = warmup.start_for(tasks.thread_count(), [c.scheme for c in cages])
        if crop is not None:
            crop = check_crop(crop, camera.width, camera.height)
        if progress is not None:
            progress(0, stats.rays, "tracing")
        keep = {}
        banded = sink is not None and table is not None and nurbs is None and crop is None
        if trace_bands is None:
            trace_bands = (view.width * view.height > config.STREAM_TRACE_PIXELS
                           or sum(c.n_faces for c in cages) >= config.STREAM_TRACE_FACES)
        if table is None:
            warmup.stop(compiling)  # no cage: the subdivision kernels are not needed
        elif banded:
            shared = trace_setup(table, view, tol_rad, stats, compiling=compiling, accel=accel,
                                 max_memory=budget, seen=seen, windows=trace_bands)
        else:
            hits, iso, built = trace_hits(table, view, tol_rad, stats, compiling=compiling,
                                          accel=accel, progress=progress, max_memory=budget,
                                          keep=keep, seen=seen)
        if banded:
            return render_bands(scene, cages, owners, camera, shared, keep, stats, sink,
                                band_rows, compiling, progress, t_start, accel)
    except BaseException:
        warmup.stop(compiling)
        raise
    try:  # (a helper may still be compiling the picture's kernels)
        t0 = time.perf_counter()
        W, H = view.width, view.height
        frame = view.frame()
        # the channels as float32 planes, written in place by the kernel (no conversion pass)
        planes = np.empty((len(CHANNELS), W * H), dtype=np.float32)
        # (patches number far fewer than 2^31: int32 ids)
        normals, pix_patch = one_block(((W * H, 3), np.float64), ((W * H,), np.int32))
        covered = np.zeros(tasks.thread_count(), np.int64)
        miss = miss_values(scene.render.background)
        patches = lit = None
        if table is None:  # free-form surfaces only: the background, then the NURBS pass
            t = _background(scene, view, camera.height, miss, planes, pix_patch)
            built = np.zeros(0, np.int64)
        else:
            patches = patch_shading(table, [scene.objects[k] for k in owners])
            loop = table_loop_flag(table)
            lit = lit_in_shading(scene, nurbs, loop)
            _shade_hits(frame, W, hits, iso, patches, miss, planes, normals, pix_patch, covered,
                        owners, loop, lit)
            # each pixel's hit distance for the picture (the NURBS pass writes its nearer
            # hits into a copy); the rest of the hit records (one block with the rounds'
            # requests, 40 bytes a ray) is given back before the picture makes its own arrays
            t = hits.t if nurbs is None else hits.t.copy()
            let_go(hits[1:])
            hits = None
        offset = 0
        if nurbs is not None:
            t_trace = stats.time_trace
            t, patches, offset = _nurbs_hits(scene, nurbs, frame, W, H, tol_rad, table, t, normals,
                                             pix_patch, patches, planes, stats)
            t0 += stats.time_trace - t_trace  # (the NURBS pass counts as trace)
            if progress is not None and table is None:
                progress(stats.rays, stats.rays, "NURBS")
    except BaseException:
        warmup.stop(compiling)
        raise
    # the colour: shadows, ambient occlusion, lighting, anti-aliasing (picture.py)
    _picture_kernels(compiling, keep)
    paint(scene, cages, view, keep, t, normals, pix_patch, patches, planes, stats, nurbs,
          offset, lit=lit is not None)
    stats.time_shade = time.perf_counter() - t0
    if crop is not None:  # the tile's pixels of the window
        planes, W, H = _cropped(planes, crop, view)
    # (a pixel whose centre ray missed but an anti-aliasing ray hit is covered too)
    stats.pixels_covered = int(np.count_nonzero(planes[C_OBJECT] >= 0))
    stats.max_level = deepest_level(planes)
    channels = {name: planes[k].reshape(H, W) for k, name in enumerate(CHANNELS)}
    if sink is not None:  # (free-form surfaces or a crop: one band)
        t0 = time.perf_counter()
        sink(0, H, channels)
        t_start += time.perf_counter() - t0
        channels = {}
    stats.time_total = time.perf_counter() - t_start
    schemes = tuple(c.scheme for c in cages) + (("nurbs",) if nurbs is not None else ())
    used = "bvh" if stats.accel_fallback else accel
    refined = np.zeros(0, np.int32) if table is None else table.object_id[built]
    return RenderResult(channels, stats, camera, tol_rad, schemes, refined, used, crop)


def _shade_hits(frame, width, hits, iso, patches, miss, planes, normals, pix_patch, covered,
                owners, loop, lit=None):
    """``shade.shade`` the hits into ``planes`` (and ``normals``, ``pix_patch``,
    ``covered``; their colour too with ``lit``, ``picture.lit_in_shading``); the object ids
    made the scene's (``owners``: the scene index of each cage's object,
    :func:`cage_objects`)."""
    shade(frame, width, hits, iso.view(), patches, miss, planes, normals, pix_patch, covered,
          loop=loop, lit=lit)
    if owners != list(range(len(owners))):  # objects without a cage: scene indices
        hit = planes[C_OBJECT] >= 0
        index = planes[C_OBJECT][hit].astype(np.int64)
        planes[C_OBJECT][hit] = np.array(owners, np.float32)[index]


def _picture_kernels(compiling, keep) -> None:
    """Wait for the picture's kernels a helper compiled while the rays were traced (a cold
    cache: ``warmup.compile_picture``); the secondary rays' BVH build compiles here
    meanwhile."""
    if compiling is not None and compiling.procs and keep:
        warmup.compile_bvh()
    warmup.wait(compiling)


def _background(scene, view, image_height, miss, planes, pix_patch):
    """``planes`` of a render without cages before the NURBS pass: every ray missed (the
    background's rows of the image's gradient); returns their distances (inf)."""
    planes[:] = miss[:, None]
    y0 = getattr(view, "y0", 0)  # (a window's rows of the image's gradient)
    rows = background_rows(scene.render.background, scene.render.background_bottom,
                           image_height)[y0:y0 + view.height]
    for k in range(3):
        planes[C_R + k] = np.repeat(rows[:, k], view.width)
    pix_patch[:] = -1
    return np.full(view.width * view.height, np.inf)


def _cropped(planes, crop, view):
    """The planes of ``crop``'s pixels of its ``view`` (window); their width, height."""
    x0, y0, x1, y1 = crop
    cx, cy = x0 - view.x0, y0 - view.y0
    planes = np.ascontiguousarray(planes.reshape(len(CHANNELS), view.height, view.width)[
        :, cy:cy + y1 - y0, cx:cx + x1 - x0]).reshape(len(CHANNELS), -1)
    return planes, x1 - x0, y1 - y0


def render_bands(scene, cages, owners, camera, shared, keep, stats, sink, band_rows,
                 compiling, progress, t_start, accel) -> RenderResult:
    """The rest of :func:`render_scene` in bands of ``band_rows`` rows (default: about
    ``config.STREAM_BAND_PIXELS`` pixels, ``config.STREAM_TRACE_BAND_PIXELS`` when traced
    band by band), each shaded and painted as the window of
    :func:`crop_window` around it (with the rows its anti-aliasing and smoothed occlusion
    read) and handed to ``sink``: the channels, normals and the picture's arrays are a
    band's, not the image's. The rays are traced for the whole image first, or, when
    ``shared`` was set up for windows (:func:`trace_setup`), band by band too, each window
    through the rounds on reused arrays (its apron's rays traced again): then the hit
    records and candidate lists are a band's as well. Bands share the depths, the
    projection's lists, the memos and what earlier bands built (:class:`SharedTrace`), so a
    patch is built once. Each band's pixels are those of a render of the whole image (the
    tile renders' argument: the same rays, depths and pieces; only the order in which a ray
    meets the patches built differs)."""
    W, H = camera.width, camera.height
    # (whole blocks of an EXR's lines, io.exr.LINES_PER_BLOCK, and so of tiles' rows)
    if band_rows is None:
        band_rows = (config.STREAM_TRACE_BAND_PIXELS if shared.windows
                     else config.STREAM_BAND_PIXELS) // W
    rows = int(band_rows)
    align = config.EXR_LINES_PER_BLOCK
    rows = max(align, rows - rows % align)
    margin = apron(scene)
    table = shared.table
    patches = patch_shading(table, [scene.objects[k] for k in owners])
    miss = miss_values(scene.render.background)
    # one band's arrays, reused: a window holds at most its band, the apron on both
    # sides and a row more on each for the even bounds
    n_max = W * min(H, rows + 2 * (margin + 1))
    buffers = round_arrays(n_max) if shared.windows else None
    planes_store, normals_store, pix_store = one_block(
        ((len(CHANNELS) * n_max,), np.float32), ((3 * n_max,), np.float64), ((n_max,), np.int32))
    covered = np.zeros(tasks.thread_count(), np.int64)
    n_covered = 0
    max_level = -1
    t_sink = t_shade = 0.0
    ground = ground_plane(scene, cages, camera)
    lit = lit_in_shading(scene, None, shared.loop)  # (the colour in the shading's pass)
    whole = built = None
    if not shared.windows:  # the whole image's rays first; their memos then let go
        whole = trace_window(shared, camera.frame(), W, H, progress, keep)
        built = shared.finish()
        shared.memos = None
    for y0 in range(0, H, rows):
        y1 = min(H, y0 + rows)
        window = crop_window(camera, (0, y0, W, y1), margin)
        h = window.height
        n = W * h
        frame = window.frame()
        if whole is not None:
            a = window.y0 * W
            hits = Hits(*(f[a:a + n] for f in whole))
        else:
            band_progress = (None if progress is None else
                             lambda done, total, label, y0=y0: progress(
                                 W * y0 + done * (y1 - y0) // max(h, 1), W * H, label))
            hits = trace_window(shared, frame, W, h, band_progress, keep, buffers)
        t0 = time.perf_counter()
        planes = planes_store[:len(CHANNELS) * n].reshape(len(CHANNELS), n)
        normals, pix_patch = normals_store[:3 * n].reshape(n, 3), pix_store[:n]
        _shade_hits(frame, W, hits, shared.iso, patches, miss, planes, normals, pix_patch,
                    covered, owners, shared.loop, lit)
        if y0 == 0:
            _picture_kernels(compiling, keep)
        paint(scene, cages, window, keep, hits.t, normals, pix_patch, patches, planes, stats,
              ground=ground, lit=lit is not None)
        band = planes.reshape(len(CHANNELS), h, W)[:, y0 - window.y0:y1 - window.y0]
        n_covered += int(np.count_nonzero(band[C_OBJECT] >= 0))
        max_level = max(max_level, deepest_level(band))
        t_shade += time.perf_counter() - t0
        t0 = time.perf_counter()
        sink(y0, y1, {name: band[k] for k, name in enumerate(CHANNELS)})
        t_sink += time.perf_counter() - t0
    stats.time_shade = t_shade
    built = shared.finish() if built is None else built
    stats.pixels_covered = n_covered
    stats.max_level = max_level
    stats.time_total = time.perf_counter() - t_start - t_sink
    schemes = tuple(c.scheme for c in cages)
    used = "bvh" if stats.accel_fallback else accel
    return RenderResult({}, stats, camera, shared.tol_rad, schemes,
                        table.object_id[built], used, None)


def _nurbs_hits(scene, nurbs, frame, W, H, tol_rad, table, t, normals, pix_patch, patches,
                planes, stats):
    """The free-form surfaces' pass (``nurbs.scene.nurbs_pass``: every channel of the
    pixels where they are nearer than ``t``), handed to the picture as hits of their own
    rows of the patch shading (``nurbs.scene.picture_hits``): (t, patches, offset of the
    surfaces' rows)."""
    # (its own Lambert colour is replaced by the picture's lighting)
    lights = directional_rows(scene.lights)
    headlight = np.array([scene.render.headlight_intensity if scene.render.headlight
                          else 0.0])
    nh = nurbs_pass(nurbs, frame, W, H, tol_rad, None if table is None else t, lights,
                    headlight, planes, stats)
    patches, offset = with_surfaces(nurbs, patches)
    picture_hits(nurbs, nh, frame, W, offset, t, normals, pix_patch)
    return t, patches, offset


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
    attrs["subtrace:Z"] = ("distance from the eye along the pixel's ray (not camera-space z): "
                           "its centre ray, or where that missed, its nearest "
                           "anti-aliasing ray that hit")
    attrs["subtrace:P"] = ("world-space hit point of that ray, eye + Z * its unit "
                           "direction; NaN where no ray of the pixel hit (Z = +inf)")
    attrs["subtrace:accel"] = result.accel
    attrs["subtrace:samples"] = int(scene.render.samples or 1)  # rays per edge pixel at most
    attrs["subtrace:shadows"] = int(bool(scene.render.shadows and scene.lights))
    attrs["subtrace:ao"] = int(scene.render.ao)  # ambient occlusion rays per hit (0: none)
    if result.crop is not None:  # (the file's data window, in its display window)
        attrs["subtrace:crop"] = " ".join(map(str, result.crop))
    for k, v in result.stats.__dict__.items():
        attrs[f"subtrace:{k}"] = (v if isinstance(v, str) else float(v) if isinstance(v, float)
                                  else int(v))
    return attrs
