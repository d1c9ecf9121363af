"""Benchmark: primary-ray acceleration, the projection of the shells onto the image against
the BVH, on every scene at several image sizes.

    python benchmarks/accel.py [SCENE.toml ...] [--sizes 640x360 1280x720 1920x1080]
                               [--repeat 3]

Default scenes: every ``scenes/*.toml``. Each scene runs in a fresh subprocess; at each size
one cold pair of renders is discarded, then ``repeat`` pairs alternate the two methods
(BVH first in even pairs, projection first in odd ones) so both see the same drift of a
shared machine; figures are medians. Columns:

* ``trace bvh`` / ``trace proj``: ``subtrace:time_trace`` (every round of primary rays,
  patch intersection included) with ``accel="bvh"`` / ``"projection"``; ``ratio``: the
  median of the per-pair ratios projection / BVH.
* ``build bvh`` / ``build proj``: ``build_bvh`` / ``project_shells`` called alone on the
  render's shells (medians of ``repeat``); both are also inside ``time_preprocess``.
* ``MB bvh`` / ``MB proj``: bytes of the structure's arrays (BVH nodes and primitive ids;
  tile offsets, tile lists and keys); ``peak`` columns: the build's peak of traced
  allocations (``tracemalloc``, which sees numpy's buffers, scratch included).
* ``walk bvh`` / ``walk proj``: the shell walk alone, no patch intersected: each pixel's ray
  finds the shells it enters before its final hit distance (taken from the render) by
  the trace kernel's own traversal (BVH: accel/bvh.py, near child first; projection:
  its tile's list up to the first key beyond the hit), on the same threads. A lower bound
  on the walk inside the trace (there the hit distance shrinks as patches are hit).
* ``walk2 bvh`` / ``walk2 proj``: the same walk with an infinite bound until it reaches the
  shell of the patch the ray hits, then that hit's distance (as if no other patch were hit):
  the order in which the trace meets the shells; an upper bound on the walk inside the
  trace. ``walk/trace``: ``walk2 bvh`` over ``trace bvh``.
* ``shells bvh`` / ``shells proj``: shell slabs per ray in that walk (BVH: the shells of
  the leaves reached, ``leaves bvh`` of them, each after at least one node slab;
  projection: the listed shells before the stop); ``entered``: shells per
  ray entered before the final hit (the same for both); ``visit``: shells per ray the
  progressive walk enters, i.e. patches the trace would intersect in that order.
* ``tris``: ``subtrace:micro_triangles`` of the render (cells evaluated).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

from _common import REPO, import_subtrace  # benchmarks/ is on sys.path when run as a script

import_subtrace()
from subtrace.accel.bvh import (box_entry, bvh_next_leaf, bvh_start,  # noqa: E402
                                traversal_stack)
from subtrace.accel.projection import TILE  # noqa: E402
from subtrace.runtime.jit import nb  # noqa: E402
from subtrace.geometry.prims import ray_setup  # noqa: E402

DEFAULT_SIZES = ["640x360", "1280x720", "1920x1080"]


@nb.njit(cache=True, nogil=True)
def _walk(task, n_tasks, frame, width, height, t_hit, p_hit, progressive, shell_min,
          shell_max, tiles, bvh, counts):
    """Rows task, task + n_tasks, ...: for each pixel's ray, the shells entered before
    ``t_hit`` through the tiles (``tiles.off`` non-empty) or the BVH, by the traversal of
    the trace kernel (accel/bvh.py); ``counts[r]`` = (shells tested, shells entered, BVH
    leaves reached). ``progressive``: the bound is infinite until the walk reaches the shell
    of the patch hit, ``p_hit`` (-1: none), as if only that patch were hit: the shells
    entered are then the patches the trace would intersect in this walk's order."""
    ox, oy, oz = frame[0, 0], frame[0, 1], frame[0, 2]
    projected = len(tiles.off) > 1
    stack, stack_t = traversal_stack()
    for row in range(task, height, n_tasks):
        for col in range(width):
            r = row * width + col
            dx, dy, dz = ray_setup(frame, row, col)
            ix, iy, iz = 1.0 / dx, 1.0 / dy, 1.0 / dz
            tmax = np.inf if progressive else t_hit[r]
            tests = entered = leaves = 0
            sp = 0
            j = end = np.int64(0)
            if projected:  # the tile's list, nearest box first, up to the first key beyond
                t = (row // TILE) * tiles.per_row + col // TILE
                j, end = tiles.off[t], tiles.off[t + 1]
            else:
                sp = bvh_start(ox, oy, oz, ix, iy, iz, bvh, 0.0, tmax, stack, stack_t)
            while True:
                if j == end:
                    j, end, sp = bvh_next_leaf(ox, oy, oz, ix, iy, iz, bvh, 0.0, tmax,
                                               stack, stack_t, sp)
                    if j == end:
                        break
                    leaves += 1
                if projected:
                    p = np.int64(tiles.items[j])
                    if tiles.key[p] >= tmax:
                        break
                else:
                    p = bvh.prims[j]
                j += 1
                tests += 1
                if box_entry(ox, oy, oz, ix, iy, iz, shell_min, shell_max, p, 0.0,
                             tmax) < np.inf:
                    entered += 1
                    if p == p_hit[r]:
                        tmax = t_hit[r]
            counts[r, 0] = tests
            counts[r, 1] = entered
            counts[r, 2] = leaves


def _traced_peak(fn):
    """(result, peak MB of traced allocations while ``fn()`` ran)."""
    tracemalloc.start()
    try:
        out = fn()
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    return out, peak / 2**20


def worker(scene_path: str, sizes: list[tuple[int, int]], repeat: int) -> list[dict]:
    from subtrace.accel.bvh import build_bvh, no_bvh
    from subtrace.accel.projection import no_tiles, project_shells
    from subtrace.runtime import threads as tasks
    from subtrace.io.scene import apply_overrides, load_scene
    from subtrace.patches.table import build_patch_table
    from subtrace.render import RenderStats, load_objects, render_scene, trace_hits
    from subtrace.camera import camera_frame

    base = load_scene(scene_path)
    cages = load_objects(base)
    table = build_patch_table(cages)
    rows = []
    for width, height in sizes:
        scene = apply_overrides(base, width=width, height=height)
        runs = {"bvh": [], "projection": []}
        ratios = []
        for k in range(repeat + 1):  # pair 0: cold, discarded
            order = ("bvh", "projection") if k % 2 == 0 else ("projection", "bvh")
            pair = {}
            for m in order:
                res = render_scene(scene, cages=cages, accel=m)
                pair[m] = res.stats
            if k:
                for m in order:
                    runs[m].append(pair[m])
                ratios.append(pair["projection"].time_trace / pair["bvh"].time_trace)
        camera = res.camera
        frame = camera_frame(camera)
        # the structures alone: build times, array bytes, peak traced allocations
        args = (table.shell_min, table.shell_max)
        t_bvh, t_proj = [], []
        for _ in range(repeat):
            t0 = time.perf_counter()
            bvh = build_bvh(*args)
            t_bvh.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            tiles = project_shells(*args, frame, width, height)
            t_proj.append(time.perf_counter() - t0)
        _, peak_bvh = _traced_peak(lambda: build_bvh(*args))
        _, peak_proj = _traced_peak(lambda: project_shells(*args, frame, width, height))
        mb_bvh = sum(a.nbytes for a in (bvh.node_min, bvh.node_max, bvh.node_first,
                                        bvh.node_count, bvh.prims)) / 2**20
        mb_proj = sum(a.nbytes for a in (tiles.off, tiles.items, tiles.key)) / 2**20
        # the walk alone, up to each ray's final hit (the same for both methods)
        hits = trace_hits(table, camera, scene.render.tolerance_rad(camera), RenderStats(),
                          accel="bvh")[0]
        t_hit = np.ascontiguousarray(hits.t)
        prim = hits.prim  # -1: no hit; <= -2: the patch -2 - prim
        p_hit = np.where(prim < -1, -prim - 2, -1).astype(np.int64)
        walk = {}
        for m in ("bvh", "projection"):
            tl, b = (no_tiles(), bvh) if m == "bvh" else (tiles, no_bvh())
            counts = np.zeros((width * height, 3), np.int64)
            times = {False: [], True: []}
            for _ in range(repeat + 1):  # the first: compile or cache load
                for progressive in (False, True):
                    t0 = time.perf_counter()
                    tasks.run_tasks(_walk, frame, width, height, t_hit, p_hit, progressive,
                                    table.shell_min, table.shell_max, tl, b, counts)
                    times[progressive].append(time.perf_counter() - t0)
                    if not progressive:
                        mean = counts.mean(axis=0).tolist()
            walk[m] = (statistics.median(times[False][1:]), mean, counts[:, 1].mean(),
                       statistics.median(times[True][1:]))
        assert walk["bvh"][1][1] == walk["projection"][1][1], "walks disagree on shells"

        def med(m, f):
            return statistics.median(getattr(s, f) for s in runs[m])

        rows.append({
            "size": f"{width}x{height}", "patches": table.n_patches,
            "trace_bvh": med("bvh", "time_trace"), "trace_proj": med("projection", "time_trace"),
            "ratio": statistics.median(ratios), "ratios": ratios,
            "total_bvh": med("bvh", "time_total"), "total_proj": med("projection", "time_total"),
            "rounds": runs["bvh"][0].rounds,
            "build_bvh": statistics.median(t_bvh), "build_proj": statistics.median(t_proj),
            "mb_bvh": mb_bvh, "mb_proj": mb_proj, "peak_bvh": peak_bvh, "peak_proj": peak_proj,
            "walk_bvh": walk["bvh"][0], "walk_proj": walk["projection"][0],
            "walk2_bvh": walk["bvh"][3], "walk2_proj": walk["projection"][3],
            "boxes_bvh": walk["bvh"][1][0], "boxes_proj": walk["projection"][1][0],
            "leaves_bvh": walk["bvh"][1][2],
            "entered": walk["bvh"][1][1],
            "visits_bvh": walk["bvh"][2], "visits_proj": walk["projection"][2],
            "tris_bvh": med("bvh", "micro_triangles"),
            "tris_proj": med("projection", "micro_triangles"),
        })
    return rows


def _size(text: str) -> tuple[int, int]:
    w, h = text.lower().split("x")
    return int(w), int(h)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*",
                    default=[str(s) for s in sorted((REPO / "scenes").glob("*.toml"))])
    ap.add_argument("--sizes", nargs="+", default=DEFAULT_SIZES, type=str)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", help="also write the rows to this file")
    ap.add_argument("--worker", nargs=3, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        s, sizes, r = args.worker
        print(json.dumps(worker(s, [_size(z) for z in sizes.split(",")], int(r))))
        return 0
    sizes = [_size(z) for z in args.sizes]
    print(f"{args.repeat} alternated pairs per size (medians), cpus {os.cpu_count()}, "
          f"threads {len(os.sched_getaffinity(0))}")
    cols = ("scene", "size", "patches", "trace bvh", "trace proj", "ratio", "build bvh",
            "build proj", "MB bvh", "MB proj", "peak bvh", "peak proj", "walk bvh",
            "walk proj", "walk2 bvh", "walk2 proj", "walk/trace", "shells bvh", "leaves bvh",
            "shells proj", "entered", "visit bvh",
            "visit proj", "tris bvh", "tris proj")
    print(" ".join(f"{c:>10}" for c in cols))
    all_rows = []
    for scene in args.scenes:
        out = subprocess.run(
            [sys.executable, __file__, "--worker", scene,
             ",".join(f"{w}x{h}" for w, h in sizes), str(args.repeat)],
            check=True, capture_output=True, text=True,
        ).stdout
        for r in json.loads(out.strip().splitlines()[-1]):
            r["scene"] = Path(scene).stem
            all_rows.append(r)
            row = (r["scene"], r["size"], r["patches"], f"{r['trace_bvh']:.4f}",
                   f"{r['trace_proj']:.4f}", f"{r['ratio']:.2f}", f"{r['build_bvh']:.4f}",
                   f"{r['build_proj']:.4f}", f"{r['mb_bvh']:.2f}", f"{r['mb_proj']:.2f}",
                   f"{r['peak_bvh']:.2f}", f"{r['peak_proj']:.2f}", f"{r['walk_bvh']:.4f}",
                   f"{r['walk_proj']:.4f}", f"{r['walk2_bvh']:.4f}", f"{r['walk2_proj']:.4f}",
                   f"{r['walk2_bvh'] / r['trace_bvh']:.2f}",
                   f"{r['boxes_bvh']:.1f}", f"{r['leaves_bvh']:.1f}", f"{r['boxes_proj']:.1f}",
                   f"{r['entered']:.2f}",
                   f"{r['visits_bvh']:.2f}", f"{r['visits_proj']:.2f}",
                   f"{r['tris_bvh']:.0f}", f"{r['tris_proj']:.0f}")
            print(" ".join(f"{c:>10}" for c in row), flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(all_rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
