"""Benchmark: a turntable of frames here and on a Dask LocalCluster, and tiles.

    python benchmarks/frames.py [--scene scenes/spot.toml] [--frames 60] [--width 160]
                                [--height 90] [--workers 2] [--tile 64] [--runs 3]

Prints one table (wall times, warm kernel cache; the median of ``--runs`` for the single
renders):

* ``process``: one ``subtrace render`` process for one frame (what a frame costs when
  each is its own command: interpreter, imports, kernel loading, reading the cages);
* ``render_scene``: one frame in a warm process, the cages read again;
* ``turntable``: ``render_frames(turntable=N)`` in one process, per frame (the cages read
  and checked once, the kernels loaded once: the reuse shows against the two above);
* ``dask``: the same frames on a LocalCluster of ``--workers`` processes of one thread,
  per frame, the cluster's start-up separate (and its per-frame overhead: wall time x
  workers / frames against the turntable's per-frame time);
* ``tiles``: one frame as ``--tile`` tiles one after another, and on the cluster (the
  cost of each tile tracing its own table and window).

The command runs this checkout's sources (``src/`` first on sys.path).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default=str(REPO / "scenes" / "spot.toml"))
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--width", type=int, default=160)
    ap.add_argument("--height", type=int, default=90)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--tile", type=int, default=64)
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()

    from subtrace.frames import render_frames
    from subtrace.io.scene import apply_overrides, load_scene
    from subtrace.render import render_scene

    scene = apply_overrides(load_scene(args.scene), width=args.width, height=args.height)
    n = args.frames
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "spin.####.exr")
        render_scene(scene)  # warm: the kernels in this process and the cache on disk
        env = dict(os.environ, PYTHONPATH=str(REPO / "src") + os.pathsep
                   + os.environ.get("PYTHONPATH", ""))
        cmd = [sys.executable, "-m", "subtrace.cli", "render", args.scene, "-o",
               os.path.join(tmp, "one.exr"), "--width", str(args.width), "--height",
               str(args.height), "--quiet"]
        subprocess.run(cmd, env=env, check=True)
        times = []
        for _ in range(args.runs):
            t0 = time.perf_counter()
            subprocess.run(cmd, env=env, check=True)
            times.append(time.perf_counter() - t0)
        rows.append(("process (one frame)", 1, statistics.median(times), None))
        times = []
        for _ in range(args.runs):
            t0 = time.perf_counter()
            render_scene(scene)
            times.append(time.perf_counter() - t0)
        single = statistics.median(times)
        rows.append(("render_scene (one frame)", 1, single, None))

        t0 = time.perf_counter()
        done = render_frames(scene, out, turntable=n)
        wall = time.perf_counter() - t0
        assert len(done) == n
        rows.append((f"turntable, {n} frames, here", n, wall, None))
        local_per_frame = wall / n

        t0 = time.perf_counter()
        done = render_frames(scene, out, turntable=n, tile=args.tile, frames="0")
        rows.append((f"one frame as {args.tile}x{args.tile} tiles, here", 1,
                     time.perf_counter() - t0, None))

        from distributed import Client, LocalCluster

        t0 = time.perf_counter()
        cluster = LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = Client(cluster)
        start = time.perf_counter() - t0
        try:
            # warm the workers (imports, kernels loaded from the cache)
            render_frames(scene, os.path.join(tmp, "warm.#.exr"), turntable=args.workers,
                          dask=client)
            t0 = time.perf_counter()
            done = render_frames(scene, out, turntable=n, dask=client)
            wall = time.perf_counter() - t0
            assert len(done) == n
            rows.append((f"turntable, {n} frames, dask x{args.workers}", n, wall,
                         wall * args.workers / n - local_per_frame))
            t0 = time.perf_counter()
            render_frames(scene, out, turntable=n, tile=args.tile, frames="0", dask=client)
            rows.append((f"one frame as {args.tile}x{args.tile} tiles, dask "
                         f"x{args.workers}", 1, time.perf_counter() - t0, None))
        finally:
            client.close()
            cluster.close()

    print(f"{Path(args.scene).name} at {args.width}x{args.height}; cores here: "
          f"{len(os.sched_getaffinity(0))}; LocalCluster start-up {start:.2f} s")
    print(f"{'what':44s} {'frames':>6s} {'wall s':>8s} {'s/frame':>8s} {'vs one':>7s} "
          f"{'overhead s/frame':>17s}")
    for what, frames, wall, overhead in rows:
        print(f"{what:44s} {frames:6d} {wall:8.3f} {wall / frames:8.3f} "
              f"{wall / frames / single:7.2f} "
              + ("" if overhead is None else f"{overhead:17.3f}"))


if __name__ == "__main__":
    main()
