"""The trace's rounds: the set-up every window of one image shares (depths within the
budget, the shells' projection or BVH, the threads' memos, the regular patches' pieces:
:func:`trace_setup`), then rounds of ``trace.kernels.trace_round`` over a window's rays
(:func:`trace_window`): trace the rays that asked, build what they asked for
(``trace.build.build_requested``), shrink the built patches' shells to their items' boxes,
until no ray asks. :func:`trace_hits` is both for a whole image. ``render.py`` orchestrates
them; the maths is in ``patches/``, ``accel/`` and the kernels of ``trace/``.
"""

from __future__ import annotations

import time

import numpy as np

from subtrace import config
from subtrace.accel.bvh import build_bvh, no_bvh
from subtrace.accel.projection import TILE, no_tiles, project_shells, tiles_bytes
from subtrace.camera import whole_image, window_offset
from subtrace.patches.criterion import edge_sampling
from subtrace.patches.shells import Sight
from subtrace.runtime import threads as tasks
from subtrace.subdiv.limit import limit_points
from subtrace.geometry.bezier import table_loop_flag
from subtrace.trace.budget import choose_within_budget, warn_tiles
from subtrace.trace.build import build_loop_regular, build_requested, cut_to_loop_nets
from subtrace.trace.kernels import trace_round
from subtrace.trace.pools import Hits, Memos, Pieces, candidate_lists, round_arrays
from subtrace.trace.rays import compile_kernel as compile_secondary
from subtrace.geometry.kinds import TRI


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
    processes compiling the trace kernels (``startup.warmup.start``: its ``Helpers``), waited
    for before the first round. ``accel``: how a ray finds the shells it enters, ``"projection"`` (the shells
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

    def __init__(self, table, chosen, tiles, bvh, memos, iso, edge_depth, patch_side, eye,
                 tol_rad, stats, windows):
        self.table, self.chosen, self.tiles, self.bvh = table, chosen, tiles, bvh
        self.memos, self.iso, self.edge_depth, self.eye = memos, iso, edge_depth, eye
        self.patch_side = patch_side  # (P,4) how finely each patch samples its sides
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
        compiling.picture_while_tracing(tasks.thread_count())
        compiling.wait_traced()
    depths = chosen.depths
    edge_depth, patch_side = edge_sampling(table, depths)
    iso = Pieces(table.n_patches)
    reg = np.nonzero(table.regular)[0]
    n_irr = int(np.count_nonzero(table.is_quad & ~table.regular))
    iso.reserve("items", len(reg) + 16 * n_irr)
    # the pieces' net store is the table's: its nets, then room for the rest (no copy)
    store = table.nets if table.nets.base is None else table.nets.base
    iso.adopt("nets", len(table.nets), nets=store)
    iso.reserve("nets", len(reg) + 16 * n_irr)
    iso.append_regular(reg, depths[reg], patch_side[reg], None, table.shell_min[reg],
                       table.shell_max[reg])
    build_loop_regular(table, depths, edge_depth, iso)
    return SharedTrace(table, chosen, tiles, bvh, Memos(n_threads, memo_bytes), iso,
                       edge_depth, patch_side, eye, tol_rad, stats, windows and whole is camera)


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
                        shared.eye, shared.tol_rad, chosen.record, shared.patch_side)
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
        keep.update(table=table, depths=depths, edge_depth=shared.edge_depth,
                    patch_side=shared.patch_side, iso=iso,
                    record=chosen.record, shell_min=chosen.shell_min,
                    shell_max=chosen.shell_max, bvh=keep.get("bvh", shared.bvh),
                    eye=shared.eye, tol_rad=shared.tol_rad, stats=stats,
                    round_no=base + round_no + 1,
                    memo_bytes=memos.max_bytes)
    return hits

