"""Benchmark: the memory budget's estimate against the measured peak.

For each scene, tolerance and budget, renders in a fresh process and prints the estimate
the budget is checked against (``patches.criterion.memory_estimate`` of the depths after any
cap, plus the bytes the threads' memos hold at the end, which the budget bounds by what the
estimate leaves) and the render's measured peak: the growth of
the resident set over the render (``sweep.PeakMemory``: VmHWM reset through
/proc/self/clear_refs), and whether the peak stayed within the budget. The interpreter,
Numba and the loaded kernels (about 200-300 MB before the render starts) are outside the
budget.

    python benchmarks/memory.py [--width 640 --height 360]

The memory of many placed copies of one cage against the cage once (a field of 1,000
Spots) is ``benchmarks/instances.py``'s.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

CHILD = r"""
import json, sys, warnings
import numpy as np
from subtrace import config
from subtrace.io.scene import apply_overrides, load_scene
from subtrace.patches import criterion as pt
from subtrace.render import render_scene
from subtrace.sweep import PeakMemory

path, tol, w, h, budget = sys.argv[1:6]
scene = apply_overrides(load_scene(path), tolerance=tol, width=w, height=h,
                        max_memory=None if budget == "default" else budget)
render_scene(apply_overrides(scene, width="16", height="12", max_memory="4G"))  # warm
seen = {}
orig = pt.memory_estimate
def spy(table, depths, n_pixels, grids=None):
    value = orig(table, depths, n_pixels, grids)
    seen["last"] = value
    return value
import subtrace.trace.budget as B
B.memory_estimate = spy
probe = PeakMemory()
probe.start()
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    result = render_scene(scene)
peak = probe.peak()
st = result.stats
budget_bytes = scene.render.max_memory or config.default_max_memory()
print(json.dumps(dict(estimate=seen.get("last", 0) + st.memo_bytes, memo=st.memo_bytes, peak=peak,
                      budget=budget_bytes, cap=st.depth_cap, deepest=st.max_depth,
                      warned=len(caught))))
"""


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", default="640")
    ap.add_argument("--height", default="360")
    args = ap.parse_args(argv)
    runs = [
        ("torus_loop", "2", "default"), ("torus_loop", "1", "default"),
        ("torus_loop", "0.5", "default"), ("torus_loop", "0.5", "512M"),
        ("torus_loop", "0.5", "256M"), ("torus_loop", "0.5", "128M"),
        ("spot_loop", "1", "default"), ("spot_loop", "0.5", "default"),
        ("spot_loop", "0.5", "256M"), ("spot_loop", "0.5", "128M"),
        ("spot", "1", "default"), ("spot", "0.25", "default"), ("spot", "0.25", "128M"),
        ("sword", "1", "default"), ("sword", "1", "320M"), ("sword", "1", "128M"),
    ]
    print(f"{'scene':<11} {'tol px':>6} {'budget MiB':>10} {'cap':>4} {'deepest':>7} "
          f"{'estimate MiB':>12} {'memo MiB':>8} {'peak MiB':>9} {'peak/est':>8} {'within':>6}")
    for scene, tol, budget in runs:
        proc = subprocess.run(
            [sys.executable, "-c", CHILD, os.path.join(ROOT, "scenes", scene + ".toml"), tol,
             args.width, args.height, budget], capture_output=True, text=True)
        if proc.returncode:  # e.g. a budget below what the image itself needs
            last = (proc.stderr.strip().splitlines() or ["?"])[-1]
            print(f"{scene:<11} {tol:>6} {budget:>10} refused: {last}", flush=True)
            continue
        r = json.loads(proc.stdout.strip().splitlines()[-1])
        est = r["estimate"] / 2**20
        peak = r["peak"] / 2**20
        b = r["budget"] / 2**20
        print(f"{scene:<11} {tol:>6} {b:>10.0f} {r['cap']:>4} {r['deepest']:>7} {est:>12.1f} "
              f"{r['memo'] / 2**20:>8.1f} {peak:>9.1f} {peak / est:>8.2f} {'yes' if peak <= b else 'NO':>6}", flush=True)


if __name__ == "__main__":
    main()
