"""Benchmark: what the patches of Numba's internals (src/subtrace/runtime/numba_patches.py) do
to the first run, side by side with them off.

    python benchmarks/patches.py [--rounds 2] [--warm 3] [--keep DIR] [-- RENDER ARGS]

Each round renders the built-in default scene (``subtrace render --png``, or the render
arguments after ``--``) with ``SUBTRACE_NUMBA_PATCHES=1`` and with ``=0``, each as a whole
process on an empty kernel cache of its own (the first render: it compiles the kernels),
then ``--warm`` times again on that cache (their median: the warm start); the order of the
two alternates from round to round. The command is this interpreter's ``subtrace``
(``python -m subtrace.cli``, the checkout as installed). It prints every run with the load
average before it (on a shared machine compile times follow the load), then the medians
and their ratio.
"""

from __future__ import annotations

import argparse
import datetime
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from _common import load, split_extra, timed

from subtrace.runtime.numba_patches import CHECKED_ON

MODES = {"on": "1", "off": "0"}


def run(root: Path, rounds: int, warm: int, render: list[str]) -> list[tuple]:
    """(round, mode, first-render seconds, warm median seconds, load before) of each run."""
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "VIRTUAL_ENV")}
    argv = [sys.executable, "-m", "subtrace.cli", "render", *render]
    rows = []
    for r in range(rounds):
        order = list(MODES) if r % 2 == 0 else list(MODES)[::-1]
        for mode in order:
            cache = root / f"cache-{mode}-{r}"
            shutil.rmtree(cache, ignore_errors=True)
            env.update(SUBTRACE_CACHE_DIR=str(cache), SUBTRACE_NUMBA_PATCHES=MODES[mode])
            before = load()
            first = timed(argv, root, env, "patches.py")
            again = [timed(argv, root, env, "patches.py") for _ in range(warm)]
            rows.append((r + 1, mode, first, statistics.median(again) if again else None,
                         before))
            print(f"round {r + 1}, patches {mode}: first {first:.1f} s", file=sys.stderr)
    return rows


def report(rows, render: list[str]) -> None:
    import numba

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    head = subprocess.run(["git", "-C", str(Path(__file__).resolve().parents[1]), "rev-parse",
                           "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    print(f"benchmarks/patches.py: {datetime.date.today().isoformat()}, commit {head or '?'}, "
          f"Numba {numba.__version__} (patches checked on "
          f"{', '.join(CHECKED_ON.values())}), Python {sys.version.split()[0]}, {cores} cores, "
          f"load after {load()}")
    print(f"command: subtrace render {' '.join(render)}")
    print()
    print("| round | patches | first render (s) | warm render (s) | load before (1, 5, 15 min) |")
    print("|---|---|---|---|---|")
    for r, mode, first, again, before in rows:
        warm = "-" if again is None else f"{again:.2f}"
        print(f"| {r} | {mode} | {first:.1f} | {warm} | {before} |")
    print()
    med = {}
    for mode in MODES:
        firsts = [row[2] for row in rows if row[1] == mode]
        warms = [row[3] for row in rows if row[1] == mode and row[3] is not None]
        med[mode] = (statistics.median(firsts), statistics.median(warms) if warms else None)
        warm = "" if med[mode][1] is None else f", warm {med[mode][1]:.2f} s"
        print(f"patches {mode}: first render {med[mode][0]:.1f} s (median of {len(firsts)})"
              f"{warm}")
    print(f"first render, off / on: {med['off'][0] / med['on'][0]:.2f}x")
    if med["on"][1] and med["off"][1]:
        print(f"warm render, off / on: {med['off'][1] / med['on'][1]:.2f}x")


def main() -> None:
    own, render = split_extra(sys.argv[1:])
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=2, help="rounds of both modes")
    ap.add_argument("--warm", type=int, default=3, help="warm renders after each first one")
    ap.add_argument("--keep", metavar="DIR", help="work in DIR (kept), not a temporary folder")
    args = ap.parse_args(own)
    render = render or ["--png"]
    root = Path(args.keep or tempfile.mkdtemp(prefix="subtrace-patches-"))
    root.mkdir(parents=True, exist_ok=True)
    try:
        rows = run(root, max(1, args.rounds), max(0, args.warm), render)
    finally:
        if not args.keep:
            shutil.rmtree(root, ignore_errors=True)
    report(rows, render)


if __name__ == "__main__":
    main()
