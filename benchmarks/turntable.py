"""Benchmark: the time a frame of a turntable takes in one process.

    python benchmarks/turntable.py [SCENE.toml] [--frames 8] [--width 320] [--height 180]

Renders ``--frames`` frames orbiting the scene's target with ``render_frames`` in this
process (the cages read once, the kernels loaded once, what each cage keeps for the next
frame reused), after a 2-frame warm-up, at the scene's own settings but the given size,
and prints the wall time per frame. To compare two trees, run it alternately with each
tree's ``src`` on PYTHONPATH (``benchmarks/frames.py`` measures the whole range of frame
and tile paths, the Dask cluster's included).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import tempfile
import time

from _common import REPO, import_subtrace  # benchmarks/ is on sys.path when run as a script


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene", nargs="?", default=str(REPO / "scenes" / "sword.toml"))
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=180)
    args = ap.parse_args()
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    import_subtrace()
    from subtrace.frames import render_frames
    from subtrace.io.scene import load_scene

    scene = load_scene(args.scene)
    camera = dataclasses.replace(scene.camera, width=args.width, height=args.height)
    scene = dataclasses.replace(scene, camera=camera)
    with tempfile.TemporaryDirectory() as tmp:
        render_frames(scene, os.path.join(tmp, "warm.#.exr"), turntable=2)
        t = time.perf_counter()
        render_frames(scene, os.path.join(tmp, "frame.#.exr"), turntable=args.frames)
        wall = time.perf_counter() - t
    print(f"{os.path.basename(args.scene)}: {args.frames} frames at {args.width}x{args.height}, "
          f"{wall / args.frames:.4f} s a frame")


if __name__ == "__main__":
    main()
