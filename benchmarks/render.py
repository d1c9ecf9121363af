"""Benchmark: render scenes and report the time split, work done and peak memory.

    python benchmarks/render.py [SCENE.toml ...] [--width 1280 --height 720] [--repeat 3]
                                [--tolerance 1] [--samples N] [--no-shadows]
    python benchmarks/render.py --picture-cost [SCENE.toml ...] [--ao 16]

``--samples`` / ``--no-shadows`` set anti-aliasing and shadows (default: the scene's, i.e.
the renderer's defaults). ``--picture-cost`` instead renders each scene warm in one process
with geometry only (``--samples 1 --no-shadows``), with shadows, with anti-aliasing, with
both, and with both plus ambient occlusion (``--ao``, default 16 rays per hit), alternating
the five in ``repeat`` rounds, and prints the median total times and their ratios to
geometry only, with the shadow rays, anti-aliased pixels and AO rays counted, and the
median of the renderer's own AO timer (``time_ao``).

Default scenes: ``scenes/spot.toml`` and ``scenes/sword.toml``. Each scene runs in a fresh
subprocess: one *cold* run (first render in the process: Numba's cache is loaded, or kernels
compile when it is stale) and ``repeat`` *warm* runs whose medians are reported. Times are
the renderer's own (``subtrace:time_*``: load, preprocess, refine, trace, shade) plus the
EXR write (streamed in bands as ``subtrace render`` writes it: the bands' encoding and the
file); ``cmd s`` is the median wall time of ``repeat`` whole ``subtrace render``
commands (interpreter start and imports included), measured separately. Peak memory is the subprocess's max RSS.

The commands run with Python's bytecode cache on, as on a normal machine (``pip install``
compiles it too): PYTHONDONTWRITEBYTECODE, which this sandbox sets, is removed from their
environment (with it, every command compiled subtrace's ~40 modules again, about 0.09 s).
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
from pathlib import Path

from _common import REPO, import_subtrace  # benchmarks/ is on sys.path when run as a script
DEFAULT_SCENES = [REPO / "scenes" / "spot.toml", REPO / "scenes" / "sword.toml"]


def worker(scene_path: str, width: int, height: int, tolerance: float, repeat: int,
           samples=None, shadows=None) -> dict:
    import resource

    import_subtrace()
    from subtrace.io.exr import ExrBands
    from subtrace.io.scene import apply_overrides, load_scene
    from subtrace.render import render_scene, result_attributes

    scene = apply_overrides(load_scene(scene_path), width=width, height=height,
                            tolerance=tolerance, samples=samples, shadows=shadows)
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(repeat + 1):
            # as ``subtrace render`` writes an EXR: streamed in bands, each encoded at once
            exr = ExrBands(os.path.join(tmp, "out.exr"), scene.camera.width,
                           scene.camera.height)
            res = render_scene(scene, sink=exr.write)
            exr.finish(result_attributes(res, scene))
            st = dict(res.stats.__dict__)
            st["time_write"] = exr.seconds
            runs.append(st)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return {"cold": runs[0], "warm": runs[1:], "peak_mb": peak}


PICTURE_MODES = (("geometry", 1, False, 0), ("shadows", 1, True, 0), ("aa", None, False, 0),
                 ("both", None, True, 0), ("ao", None, True, None))
# (name, samples (None: the default), shadows, AO rays (None: --ao))


def picture_worker(scene_path: str, width: int, height: int, repeat: int, ao: int) -> dict:
    """Warm render times of the PICTURE_MODES, alternated over ``repeat`` rounds."""
    import_subtrace()
    import warnings

    from subtrace.io.scene import apply_overrides, load_scene
    from subtrace.render import render_scene

    base = apply_overrides(load_scene(scene_path), width=width, height=height)
    scenes = {name: apply_overrides(base, samples=n, shadows=sh, ao=ao if a is None else a)
              for name, n, sh, a in PICTURE_MODES}
    times = {name: [] for name in scenes}
    ao_times = []
    stats = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, scene in scenes.items():  # warm-up (compilation, caches)
            render_scene(scene)
        for _ in range(repeat):
            for name, scene in scenes.items():
                st = render_scene(scene).stats
                times[name].append(st.time_total)
                stats[name] = {"shadow_rays": st.shadow_rays, "aa_pixels": st.aa_pixels,
                               "aa_rays": st.aa_rays, "samples": scene.render.samples,
                               "ao_rays": st.ao_rays}
                if name == "ao":
                    ao_times.append(st.time_ao)
    return {"times": times, "stats": stats, "time_ao": ao_times}


def picture_cost(args) -> int:
    """The --picture-cost table (see the module doc)."""
    print(f"{args.width}x{args.height}, {args.repeat} alternated warm rounds (medians), "
          f"cpus {os.cpu_count()}")
    cols = ("scene", "geometry s", "shadows", "aa", "both", "+ao", "x shadows", "x aa",
            "x both", "x +ao", "ao s", "shadow rays", "aa px", "aa rays", "ao rays")
    print(" ".join(f"{c:>11}" for c in cols))
    for scene in args.scenes:
        out = subprocess.run(
            [sys.executable, __file__, "--picture-worker", scene, str(args.width),
             str(args.height), str(args.repeat), str(args.ao)],
            check=True, capture_output=True, text=True).stdout
        r = json.loads(out.strip().splitlines()[-1])
        med = {k: statistics.median(v) for k, v in r["times"].items()}
        st = r["stats"]["both"]
        g = med["geometry"]
        row = (Path(scene).stem, f"{g:.3f}", f"{med['shadows']:.3f}", f"{med['aa']:.3f}",
               f"{med['both']:.3f}", f"{med['ao']:.3f}", f"{med['shadows'] / g:.2f}",
               f"{med['aa'] / g:.2f}", f"{med['both'] / g:.2f}", f"{med['ao'] / g:.2f}",
               f"{statistics.median(r['time_ao']):.3f}", str(st["shadow_rays"]),
               str(st["aa_pixels"]), str(st["aa_rays"]), str(r["stats"]["ao"]["ao_rays"]))
        print(" ".join(f"{c:>11}" for c in row), flush=True)
    return 0


def _command_time(scene_path, width, height, tolerance) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, str(REPO / "cli.py"), "render", str(scene_path), "-o",
               os.path.join(tmp, "o.exr"), "--width", str(width), "--height", str(height),
               "--tolerance", str(tolerance), "--quiet"]
        env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, env=env)
        return time.perf_counter() - t0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=[str(s) for s in DEFAULT_SCENES])
    ap.add_argument("--width", type=int, default=1280)
    ap.add_argument("--height", type=int, default=720)
    ap.add_argument("--tolerance", type=float, default=1.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--samples", type=int, help="rays per edge pixel (default: the scene's)")
    ap.add_argument("--no-shadows", dest="shadows", action="store_false", default=None,
                    help="no shadow rays")
    ap.add_argument("--picture-cost", action="store_true",
                    help="the cost of shadows and anti-aliasing (see the module doc)")
    ap.add_argument("--worker", nargs=7, help=argparse.SUPPRESS)
    ap.add_argument("--ao", type=int, default=16,
                    help="--picture-cost: AO rays per hit of its last mode (default 16)")
    ap.add_argument("--picture-worker", nargs=5, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        s, w, h, t, r, n, sh = args.worker
        print(json.dumps(worker(s, int(w), int(h), float(t), int(r),
                                None if n == "-" else int(n), None if sh == "-" else sh == "1")))
        return 0
    if args.picture_worker:
        s, w, h, r, ao = args.picture_worker
        print(json.dumps(picture_worker(s, int(w), int(h), int(r), int(ao))))
        return 0
    if args.picture_cost:
        return picture_cost(args)
    print(f"{args.width}x{args.height}, tolerance {args.tolerance} px, {args.repeat} warm runs "
          f"(medians), cpus {os.cpu_count()}")
    cols = ("scene", "cold s", "load", "prep", "refine", "trace", "shade", "write", "total",
            "cmd s", "Mrays/s", "refined", "patches", "micro-tris", "tris/px", "px", "peak MB")
    print(" ".join(f"{c:>10}" for c in cols))
    for scene in args.scenes:
        out = subprocess.run(
            [sys.executable, __file__, "--worker", scene, str(args.width), str(args.height),
             str(args.tolerance), str(args.repeat),
             "-" if args.samples is None else str(args.samples),
             "-" if args.shadows is None else str(int(args.shadows))],
            check=True, capture_output=True, text=True,
        ).stdout
        r = json.loads(out.strip().splitlines()[-1])
        warm = r["warm"]
        med = {k: statistics.median(run[k] for run in warm) for k in warm[0]}
        cmd = statistics.median(_command_time(scene, args.width, args.height, args.tolerance)
                                for _ in range(args.repeat))
        cold = r["cold"]["time_total"] + r["cold"]["time_write"]
        rays = med["rays"] / med["time_total"] / 1e6
        row = (Path(scene).stem, f"{cold:.2f}", f"{med['time_load']:.3f}",
               f"{med['time_preprocess']:.3f}", f"{med['time_refine']:.3f}",
               f"{med['time_trace']:.3f}", f"{med['time_shade']:.3f}",
               f"{med['time_write']:.3f}", f"{med['time_total']:.3f}", f"{cmd:.2f}",
               f"{rays:.2f}", f"{int(med['patches_refined'])}", f"{int(med['patches'])}",
               f"{int(med['micro_triangles'])}",
               f"{med['micro_triangles'] / max(med['pixels_covered'], 1):.1f}",
               f"{int(med['pixels_covered'])}", f"{r['peak_mb']:.0f}")
        print(" ".join(f"{c:>10}" for c in row), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
