"""Benchmark: load a large cage, refine it uniformly, and compute the level's limit positions.

    python benchmarks/refine.py [--model PATH] [--levels 1 2 3 4] [--repeat 3] [--no-limit]

For each level a fresh subprocess (so that the peak memory of one level does not pollute
the next, and caches never help) runs ``repeat + 1`` times: load the OBJ
(``subtrace.load_cage``), ``cage.refine(level)`` and ``cage.limit(level)`` on a fresh cage
each time. The first run is reported separately as *cold* (it includes loading Numba's
on-disk cache, or compiling when the cache is stale); the *warm* columns are the medians of
the remaining ``repeat`` runs. Peak memory is the subprocess's maximum resident set size
(``resource.getrusage``), which includes the interpreter, numpy and Numba (the "base" column
is the same after imports, before any work).

Default model: ``models/sword_quad_dominant.obj`` of the repository
(22,465 faces; "Moonbrand sword, The Oakeshott Institute, remeshed by Oded Stein,
odedstein-meshes", CC BY 4.0).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from _common import REPO, import_subtrace  # benchmarks/ is on sys.path when run as a script
DEFAULT_MODEL = REPO / "models" / "sword_quad_dominant.obj"


def _max_rss_mb() -> float:
    import resource

    kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB on Linux
    return kb / 1024.0


def worker(model: str, level: int, repeat: int, with_limit: bool) -> dict:
    """One level, in this process: cold run, then ``repeat`` warm runs."""
    t = time.perf_counter()
    subtrace = import_subtrace()
    import numpy as np

    import_s = time.perf_counter() - t
    base_rss = _max_rss_mb()
    runs = []
    counts = None
    for _ in range(repeat + 1):
        t0 = time.perf_counter()
        cage = subtrace.load_cage(model)
        t1 = time.perf_counter()
        mesh = cage.refine(level)
        t2 = time.perf_counter()
        if with_limit:
            P, du, dv = cage.limit(level)
            assert P.shape == mesh.points.shape and np.all(np.isfinite(P))
        t3 = time.perf_counter()
        runs.append({"load": t1 - t0, "refine": t2 - t1, "limit": t3 - t2, "total": t3 - t0})
        counts = (len(mesh.points), mesh.n_faces, cage.n_faces)
        del cage, mesh
        if with_limit:
            del P, du, dv
    warm = {k: float(np.median([r[k] for r in runs[1:]])) for k in runs[0]} if repeat else None
    return {
        "level": level,
        "vertices": counts[0],
        "faces": counts[1],
        "cage_faces": counts[2],
        "import_s": import_s,
        "cold": runs[0],
        "warm": warm,
        "warm_runs": runs[1:],
        "base_rss_mb": base_rss,
        "peak_rss_mb": _max_rss_mb(),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", default=str(DEFAULT_MODEL), help="OBJ cage to refine")
    parser.add_argument("--levels", type=int, nargs="+", default=[1, 2, 3, 4])
    parser.add_argument("--repeat", type=int, default=3, help="warm runs per level (median)")
    parser.add_argument("--no-limit", action="store_true", help="time refinement only")
    parser.add_argument("--json", help="also write the results to this file")
    parser.add_argument("--worker", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)

    with_limit = not args.no_limit
    if args.worker is not None:
        print(json.dumps(worker(args.model, args.worker, args.repeat, with_limit)))
        return 0

    if not Path(args.model).is_file():
        print(f"refine.py: error: model not found: {args.model}", file=sys.stderr)
        return 2
    if with_limit:
        subtrace = import_subtrace()  # noqa: F841
        import importlib.util

        if importlib.util.find_spec("subtrace.subdiv.limit") is None:
            print("note: subtrace.subdiv.limit is not available: timing refinement only")
            with_limit = False

    print(f"model: {args.model}")
    print(f"repeat: {args.repeat} warm runs per level after 1 cold run; "
          f"limit positions: {'yes' if with_limit else 'no'}; cpus: {os.cpu_count()}")
    header = (
        f"{'level':>5} {'faces':>10} {'vertices':>10} | {'cold s':>7} | "
        f"{'load':>6} {'refine':>7} {'limit':>6} {'warm s':>7} | {'base MB':>8} {'peak MB':>8}"
    )
    print(header)
    print("-" * len(header))
    results = []
    for level in args.levels:
        cmd = [sys.executable, __file__, "--worker", str(level), "--model", args.model,
               "--repeat", str(args.repeat)] + ([] if with_limit else ["--no-limit"])
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            print(f"{level:>5} failed (exit {proc.returncode}): "
                  f"{proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else ''}")
            continue
        r = json.loads(proc.stdout.strip().splitlines()[-1])
        results.append(r)
        w = r["warm"] or r["cold"]
        print(
            f"{level:>5} {r['faces']:>10,} {r['vertices']:>10,} | {r['cold']['total']:>7.3f} | "
            f"{w['load']:>6.3f} {w['refine']:>7.3f} {w['limit']:>6.3f} {w['total']:>7.3f} | "
            f"{r['base_rss_mb']:>8.0f} {r['peak_rss_mb']:>8.0f}"
        )
    print("columns: cold s = first run (load + refine + limit, with Numba cache loading); "
          "load / refine / limit / warm s = medians of the warm runs; "
          "base MB = max RSS after imports, peak MB = max RSS of the level's process")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
