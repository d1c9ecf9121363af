"""Benchmark: a large cage seen whole and seen in part (the lazy patch table).

    python benchmarks/lazy.py [--rounds 3] [--width 1280 --height 720] [--levels 2]
                              [--light none|sun|point] [--ground]

The sword (``models/sword_quad_dominant.obj``, 22,465 faces) refined ``--levels`` times
(twice: 358,048 quads, 366,532 patches) is written once to a temporary OBJ. Each round
renders it in two fresh processes, alternated: *whole*, the sword scene's camera (the whole
sword in view), and *tip*, the same eye looking at the blade's tip through a 2.6 degree
field of view (about a tenth of the cage faces reach the image). Each process first renders
a tiny scene of the original sword (kernels loaded), then measures from that baseline:
loading the OBJ and rendering it as ``subtrace render`` does (in bands, streamed into an
EXR in a temporary folder), the time split (``subtrace:time_*``), the patches built and
the cage faces culled, and the peak of the resident set above the baseline
(``sweep.PeakMemory``: VmHWM reset through /proc/self/clear_refs), of which ``cage MiB`` is
the loaded cage's resident set. The figures are medians over the rounds; the last row
gives tip / whole. ``--ground``: a ground plane (a shadow catcher at the automatic height,
the sword's lowest limit point) under the lights.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

from _common import REPO, import_subtrace  # benchmarks/ is on sys.path when run as a script

SWORD = REPO / "models" / "sword_quad_dominant.obj"
EYE = [1.543, 0.6184, 0.4523]
VIEWS = {"whole": ([0.0009113, 0.001393, -0.01046], 30.0), "tip": ([0.0, 0.0, -0.4], 2.6)}
# --light: none (the headlight), the sword scene's sun, or a point light above the blade;
# with shadows, which the cull keeps what may cast into the view for (accel/cull.py)
LIGHTS = {"none": [], "sun": [{"direction": [-0.4, -1.0, -0.5], "intensity": 0.5}],
          "point": [{"position": [0.6, 1.5, 0.8], "intensity": 2.0}]}


def write_refined(path, levels: int) -> int:
    """Write the sword refined ``levels`` times as an OBJ; returns its face count."""
    import numpy as np

    subtrace = import_subtrace()
    mesh = subtrace.load_cage(SWORD).refine(levels)
    sizes = np.asarray(mesh.face_sizes)
    with open(path, "w") as f:
        np.savetxt(f, mesh.points, fmt="v %.17g %.17g %.17g")
        if np.all(sizes == 4):
            np.savetxt(f, np.asarray(mesh.face_verts).reshape(-1, 4) + 1, fmt="f %d %d %d %d")
        else:
            offsets = np.r_[0, np.cumsum(sizes)]
            for a, b in zip(offsets[:-1], offsets[1:]):
                f.write("f " + " ".join(str(v + 1) for v in mesh.face_verts[a:b]) + "\n")
    return len(sizes)


def worker(obj: str, view: str, width: int, height: int, light: str = "none",
           ground: str = "no") -> dict:
    import_subtrace()
    from subtrace.io.exr import ExrBands
    from subtrace.io.scene import scene_from_dict
    from subtrace.mesh.cage import load_cage
    from subtrace.render import render_scene
    from subtrace.sweep import PeakMemory

    target, fov = VIEWS[view]

    def scene(mesh, w, h):
        return scene_from_dict({"object": [{"mesh": str(mesh)}],
                                "camera": {"eye": EYE, "target": target, "fov": fov,
                                           "width": w, "height": h},
                                "render": {"tolerance": 1.0}, "light": LIGHTS[light],
                                **({"ground": {}} if ground == "yes" else {})})

    def render(sc, cages=None):
        # as ``subtrace render`` does: streamed in bands into its EXR (render_scene's sink)
        with tempfile.TemporaryDirectory() as out:
            exr = ExrBands(os.path.join(out, "render.exr"), sc.camera.width, sc.camera.height)
            res = render_scene(sc, cages=cages, sink=exr.write)
            exr.finish({})
        return res

    render(scene(SWORD, 32, 18))  # kernels loaded (or compiled) before the baseline
    probe = PeakMemory()
    probe.start()
    base_kb = _rss_kb()
    t0 = time.perf_counter()
    cage = load_cage(obj)
    t_load = time.perf_counter() - t0
    cage_mib = (_rss_kb() - base_kb) / 1024.0
    res = render(scene(obj, width, height), [cage])
    wall = time.perf_counter() - t0
    st = res.stats
    return dict(load=t_load, prep=st.time_preprocess, refine=st.time_refine,
                trace=st.time_trace, wall=wall, patches=st.patches, culled=st.faces_culled,
                faces=cage.n_faces, px=st.pixels_covered, refined=st.patches_refined,
                peak_mib=(probe.peak() or 0) / 2**20, cage_mib=cage_mib)


def _rss_kb() -> int:
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmRSS:"))



def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--width", type=int, default=1280)
    ap.add_argument("--height", type=int, default=720)
    ap.add_argument("--levels", type=int, default=2)
    ap.add_argument("--light", choices=sorted(LIGHTS), default="none",
                    help="the lights, with shadows (default: none, the headlight alone)")
    ap.add_argument("--ground", action="store_true", help="a ground plane under the lights")
    ap.add_argument("--worker", nargs=6, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        obj, view, w, h, light, ground = args.worker
        print(json.dumps(worker(obj, view, int(w), int(h), light, ground)))
        return 0
    runs = {v: [] for v in VIEWS}
    with tempfile.TemporaryDirectory() as tmp:
        obj = os.path.join(tmp, "sword_refined.obj")
        n = write_refined(obj, args.levels)
        print(f"sword refined {args.levels}x: {n} faces; {args.width}x{args.height}, 1 px, "
              f"lights: {args.light}{', ground' if args.ground else ''}; {args.rounds} "
              "alternated rounds (medians), "
              f"cpus {os.cpu_count()}")
        for _ in range(args.rounds):
            for view in VIEWS:
                out = subprocess.run([sys.executable, __file__, "--worker", obj, view,
                                      str(args.width), str(args.height), args.light,
                                      "yes" if args.ground else "no"],
                                     check=True, capture_output=True, text=True).stdout
                runs[view].append(json.loads(out.strip().splitlines()[-1]))
    cols = ("view", "load s", "prep s", "refine s", "prep+ref s", "trace s", "wall s",
            "patches", "faces culled", "refined", "px", "cage MiB", "peak MiB")
    print(" ".join(f"{c:>12}" for c in cols))
    med = {}
    for view, rs in runs.items():
        m = {k: statistics.median(r[k] for r in rs) for k in rs[0]}
        m["prep_refine"] = statistics.median(r["prep"] + r["refine"] for r in rs)
        med[view] = m
        print(" ".join(f"{c:>12}" for c in (
            view, f"{m['load']:.3f}", f"{m['prep']:.3f}", f"{m['refine']:.3f}",
            f"{m['prep_refine']:.3f}", f"{m['trace']:.3f}", f"{m['wall']:.2f}",
            f"{int(m['patches'])}", f"{int(m['culled'])}", f"{int(m['refined'])}",
            f"{int(m['px'])}", f"{m['cage_mib']:.0f}", f"{m['peak_mib']:.0f}")))
    tip, whole = med["tip"], med["whole"]
    print(f"tip / whole: faces kept {1 - tip['culled'] / tip['faces']:.3f}, "
          f"patches {tip['patches'] / whole['patches']:.3f}, "
          f"preprocess + refine {tip['prep_refine'] / whole['prep_refine']:.3f}, "
          f"peak memory {tip['peak_mib'] / whole['peak_mib']:.3f} (less the loaded cage: "
          f"{(tip['peak_mib'] - tip['cage_mib']) / (whole['peak_mib'] - whole['cage_mib']):.3f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
