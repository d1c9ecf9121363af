"""Benchmark: the memory of a field of placed copies of one cage against the cage once.

A field of N Spots (``models/spot_control_mesh.obj``, the default scene's cage), each an
``[[object]]`` of the same file with its own ``translate`` / ``rotate`` / ``scale``, on a
square grid seen from above at a fixed camera (no automatic framing), rendered in a fresh
process per N. Prints, per N: the growth of the resident set over the render
(``sweep.PeakMemory``: VmHWM reset through /proc/self/clear_refs), that growth per copy
beyond the first, the patches in the table, the patches refined, and the render's time.
The interpreter, Numba and the loaded kernels are outside the figures (a 16x12 render of
one Spot warms them first).

    python benchmarks/instances.py [--counts 1 10 100 1000] [--width 640 --height 360]
                                   [--src another/checkout/src]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SPOT = os.path.join(ROOT, "models", "spot_control_mesh.obj")

CHILD = r"""
import json, sys, time
from subtrace.io.scene import apply_overrides, scene_from_dict
from subtrace.render import render_scene
from subtrace.sweep import PeakMemory

spec = json.loads(sys.stdin.read())
warm = scene_from_dict(dict(spec, object=spec["object"][:1]))
render_scene(apply_overrides(warm, width="16", height="12"))  # the kernels loaded
scene = scene_from_dict(spec)
probe = PeakMemory()
probe.start()
t0 = time.perf_counter()
result = render_scene(scene)
seconds = time.perf_counter() - t0
peak = probe.peak()
st = result.stats
print(json.dumps(dict(peak=peak, seconds=seconds, patches=st.patches,
                      refined=st.patches_refined, covered=st.pixels_covered)))
"""


def field(n: int, width: int, height: int) -> dict:
    """The scene (a dict of the TOML format) of ``n`` Spots on a square grid of spacing
    1.6, each turned about its up axis and scaled a little differently, seen from above."""
    side = max(1, math.ceil(math.sqrt(n)))
    span = 1.6 * side
    objects = []
    for k in range(n):
        i, j = divmod(k, side)
        objects.append(dict(mesh=SPOT, translate=[1.6 * (j - (side - 1) / 2), 0.0,
                                                  1.6 * (i - (side - 1) / 2)],
                            rotate=[0.0, (37.0 * k) % 360.0, 0.0],
                            scale=0.9 + 0.2 * ((k * 7) % 11) / 10.0))
    return {"object": objects,
            "camera": {"eye": [0.0, 1.2 * span + 2.0, 0.45 * span + 1.0],
                       "target": [0.0, 0.0, 0.0], "up": [0, 1, 0], "fov": 40.0,
                       "width": width, "height": height},
            "render": {"samples": 1, "tolerance": 1.0, "shadows": True},
            "light": [{"direction": [-0.4, -1.0, -0.5], "intensity": 0.8}]}


def run(n: int, width: int, height: int, src: str) -> dict:
    spec = field(n, width, height)
    env = dict(os.environ, PYTHONPATH=src)
    out = subprocess.run([sys.executable, "-c", CHILD], input=json.dumps(spec), env=env,
                         capture_output=True, text=True, check=False)
    if out.returncode:
        raise SystemExit(f"N={n}: the render failed:\n{out.stderr}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--counts", type=int, nargs="+", default=[1, 10, 100, 1000])
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=360)
    ap.add_argument("--src", default=os.path.join(ROOT, "src"),
                    help="the subtrace sources to measure (default: this tree's)")
    args = ap.parse_args(argv)
    rows = [(n, run(n, args.width, args.height, args.src)) for n in args.counts]
    one = next((r["peak"] for n, r in rows if n == 1), None)
    print(f"| Spots | peak RSS growth MiB | per copy beyond one KiB | patches | refined "
          f"| seconds |")
    print("|---|---|---|---|---|---|")
    for n, r in rows:
        per = "" if one is None or n == 1 else f"{(r['peak'] - one) / (n - 1) / 1024:.1f}"
        print(f"| {n} | {r['peak'] / 2**20:.1f} | {per} | {r['patches']} | {r['refined']} "
              f"| {r['seconds']:.2f} |")


if __name__ == "__main__":
    main()
