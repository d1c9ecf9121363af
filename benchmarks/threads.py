"""Scaling: the same renders on 1 and on more threads, side by side, stage by stage.

    python benchmarks/threads.py [--rounds 5] [--threads 1 2] [default | SCENE | MESH ...]
                                 [-- options]

Each round renders every input (a scene file, or a mesh rendered as ``subtrace render
MESH`` renders it; ``default`` or no input: the built-in default picture) once per thread
count, the
counts in turn forwards in even rounds and backwards in odd ones (the machine's speed
drifts within minutes: alternating spreads it over all of them), each a fresh ``subtrace
render`` process of this checkout with the input's own picture (options after ``--`` are
appended). The table gives, per input and thread count, the medians of the renderer's own
timings (``subtrace:time_*`` in the EXR header: load, preprocess, refine, trace, shade and
its shadow and anti-aliasing parts, total) and the process's wall time, and each stage's
speed-up over the first count. A stage whose speed-up stays near 1 runs on one thread.

``--serial``: instead, render each input in this process on one thread (``--rounds``
times after one untimed render, medians) and split each stage's time into what its
kernels run on the thread pool (``runtime.threads.run_tasks`` / ``run_chunks``: what more
threads divide) and the rest (Python, NumPy, kernels that run on one thread: what more
threads leave as it is), with Amdahl's bound for 2 to 16 threads. The secondary rays'
builds of patches (run between their rounds, in the shading stage) are shown apart. The
stages are told apart by the functions on the stack when a pool runs.
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

from _common import REPO, split_extra  # benchmarks/ is on sys.path when run as a script

STAGES = ("load", "preprocess", "refine", "trace", "shade", "shadows", "aa", "total")


def render(source: str | None, threads: int, out: Path, extra: list[str]) -> dict:
    """One ``subtrace render`` of ``source`` (None: the default picture) on ``threads``
    threads: the header's stage times and the process's wall time."""
    import OpenImageIO as oiio

    cmd = [sys.executable, "-m", "subtrace.cli", "render", *([source] if source else []),
           "-o", str(out), "--quiet", "--threads", str(threads), *extra]
    env = dict(os.environ, PYTHONPATH=str(REPO / "src"))
    t0 = time.perf_counter()
    done = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"threads: render {source or '(default)'} failed:\n{done.stderr}")
    spec = oiio.ImageInput.open(str(out)).spec()
    row = {k: float(spec.getattribute(f"subtrace:time_{k}") or 0.0) for k in STAGES}
    row["process"] = wall
    return row


# a pool's work belongs to the stage of the first of these functions on the stack (the
# secondary rays' builds, in the picture, to the shading)
_STAGE_OF = (("paint", "shade"), ("_shade_hits", "shade"), ("build_requested", "refine"),
             ("trace_window", "trace"), ("trace_hits", "trace"), ("trace_setup", "preprocess"),
             ("_prepare", "preprocess"))


def serial_split(source: str | None, rounds: int, extra: list[str]) -> None:
    """Print :func:`main`'s ``--serial`` table for one input."""
    import collections
    import inspect

    from _common import import_subtrace

    import_subtrace()
    from dataclasses import replace

    from subtrace.cli.parser import build_parser
    from subtrace.cli.render import scene_from_inputs
    from subtrace.io.scene import DEFAULT_SAMPLES
    from subtrace.render import render_scene
    from subtrace.runtime import threads
    from subtrace.trace import rays

    # the scene as ``subtrace render`` makes it of the input and options
    args = build_parser().parse_args(["render", *([source] if source else []), *extra])
    scene = scene_from_inputs(list(args.inputs), args, tolerance=args.tolerance,
                              tolerance_deg=args.tolerance_deg, shadows=args.shadows,
                              samples=args.samples, ao=getattr(args, "ao", None))
    if scene.render.samples is None:
        scene = replace(scene, render=replace(scene.render, samples=DEFAULT_SAMPLES))
    pooled = collections.Counter()
    built = [0.0]

    def pool(f):
        def run(*a, **k):
            t0 = time.perf_counter()
            try:
                return f(*a, **k)
            finally:
                names = [fr.function for fr in inspect.stack()[1:40]]
                stage = next((st for fn, st in _STAGE_OF if fn in names), "other")
                pooled[stage] += time.perf_counter() - t0
        return run

    def timed_build(*a, **k):
        t0 = time.perf_counter()
        try:
            return build(*a, **k)
        finally:
            built[0] += time.perf_counter() - t0

    pools = {name: getattr(threads, name) for name in ("run_tasks", "run_chunks")}
    wrapped = {name: pool(f) for name, f in pools.items()}
    for module in list(sys.modules.values()):  # (and every module that imported them)
        if getattr(module, "__name__", "").startswith("subtrace"):
            for name, f in pools.items():
                if getattr(module, name, None) is f:
                    setattr(module, name, wrapped[name])
    build = rays.build_requested
    rays.build_requested = timed_build
    rows = []
    for r in range(rounds + 1):
        pooled.clear()
        built[0] = 0.0
        t0 = time.perf_counter()
        st = render_scene(scene, threads=1, sink=lambda *a: None).stats
        wall = time.perf_counter() - t0
        rows.append((wall, {k: getattr(st, f"time_{k}") for k in STAGES[:5]}, dict(pooled),
                     built[0]))
    rows = rows[1:]
    med = statistics.median
    name = Path(source).name if source else "(default picture)"
    print(f"\n{name}, one thread, medians of {rounds}: render {med(r[0] for r in rows):.3f} s\n")
    print("| stage | s | on the pool | the rest | the rest's share |\n|---|---:|---:|---:|---:|")
    rest_all = pool_all = 0.0
    for k in STAGES[:5]:
        tot = med(r[1][k] for r in rows)
        on = min(tot, med(r[2].get(k, 0.0) for r in rows))
        rest_all += tot - on
        pool_all += on
        share = (tot - on) / max(tot, 1e-12)
        print(f"| {k} | {tot:.3f} | {on:.3f} | {tot - on:.3f} | {share:.0%} |")
    print(f"\nthe secondary rays' builds (serial, in shade): {med(r[3] for r in rows):.3f} s; "
          + ", ".join(f"{n} threads {rest_all + pool_all / n:.3f} s "
                      f"({(rest_all + pool_all) / (rest_all + pool_all / n):.2f}x)"
                      for n in (2, 4, 8, 16)) + " at best (Amdahl)")


def main(argv=None) -> int:
    argv, extra = split_extra(sys.argv[1:] if argv is None else argv)
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("inputs", nargs="*",
                    help="scene files or meshes (none, or 'default': the default picture)")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--serial", action="store_true",
                    help="split one thread's stages into pooled work and the rest")
    args = ap.parse_args(argv)
    inputs = [None if s in ("", "default") else str(Path(s).resolve())
              for s in args.inputs] or [None]
    if args.serial:
        for source in inputs:
            serial_split(source, args.rounds, extra)
        return 0
    rows: dict = {}
    with tempfile.TemporaryDirectory(prefix="subtrace-threads-") as work:
        out = Path(work) / "out.exr"
        for source in inputs:  # warm-up: each thread count's kernels compiled and cached
            for n in args.threads:
                render(source, n, out, extra)
        for r in range(args.rounds):
            order = args.threads if r % 2 == 0 else args.threads[::-1]
            for source in inputs:
                for n in order:
                    rows.setdefault((source, n), []).append(render(source, n, out, extra))
            print(f"round {r + 1}/{args.rounds}", file=sys.stderr, flush=True)
    metrics = (*STAGES, "process")
    print(f"medians of {args.rounds} alternated rounds, {os.cpu_count()} CPUs; seconds "
          f"(speed-up over {args.threads[0]} thread{'s' if args.threads[0] > 1 else ''})\n")
    print("| input | threads | " + " | ".join(metrics) + " |")
    print("|---|---:|" + "---:|" * len(metrics))
    for source in inputs:
        base = {m: statistics.median(x[m] for x in rows[(source, args.threads[0])])
                for m in metrics}
        for n in args.threads:
            cells = []
            for m in metrics:
                v = statistics.median(x[m] for x in rows[(source, n)])
                cells.append(f"{v:.3f}" + (f" ({base[m] / v:.2f})" if n != args.threads[0]
                                           and v > 0 else ""))
            name = Path(source).name if source else "(default picture)"
            print(f"| {name} | {n} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
