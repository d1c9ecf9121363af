"""Benchmark: how long the short commands take to start, as whole processes.

    python benchmarks/startup.py [--runs 10]

Prints the median wall time of ``--runs`` runs of each command (after one untimed run that
fills Python's bytecode cache and, for ``render``, Numba's kernel cache):

* ``subtrace --help`` and ``--version`` through ``python -m subtrace.cli`` and through
  ``python -c "from subtrace.cli import run; run()"`` (what a console script does);
* a warm ``subtrace render`` of the default scene at 320x180;
* ``python -c "import subtrace"``, and the bare interpreter (``python -c pass``, and with
  ``-S``: without the site module and the hooks of site-packages' .pth files) for scale.

The commands run this checkout's sources (``src/`` first on PYTHONPATH). The first column
has Python's bytecode cache on, as on a normal machine; the second runs with
PYTHONDONTWRITEBYTECODE=1 (which this sandbox sets), so every subtrace module is compiled
from source in every process. The goal: ``--help`` and ``--version`` under 0.15 s.
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
GOAL_S = 0.15  # --help / --version


def commands(out_dir: str) -> list[tuple[str, list[str], bool]]:
    """(label, argv, also timed without bytecode) of every command measured."""
    py = sys.executable
    script = "from subtrace.cli import run; run()"
    render = [py, "-m", "subtrace.cli", "render", "--width", "320", "--height", "180",
              "--quiet", "-o", os.path.join(out_dir, "startup.exr")]
    return [
        ("python -c pass", [py, "-c", "pass"], True),
        ("python -S -c pass", [py, "-S", "-c", "pass"], True),
        ("python -c 'import subtrace'", [py, "-c", "import subtrace"], True),
        ("python -m subtrace.cli --help", [py, "-m", "subtrace.cli", "--help"], True),
        ("python -m subtrace.cli --version", [py, "-m", "subtrace.cli", "--version"], True),
        ("console script --help", [py, "-c", script, "--help"], True),
        ("console script --version", [py, "-c", script, "--version"], True),
        ("render default scene 320x180 (warm)", render, False),
    ]


def median_time(argv: list[str], env: dict, runs: int) -> float:
    """Median wall time in seconds of ``runs`` runs, after one untimed run."""
    times = []
    for k in range(runs + 1):
        t0 = time.perf_counter()
        proc = subprocess.run(argv, env=env, stdout=subprocess.DEVNULL,
                              stderr=subprocess.PIPE, text=True)
        elapsed = time.perf_counter() - t0
        if proc.returncode != 0:
            raise SystemExit(f"{' '.join(argv)} failed ({proc.returncode}): {proc.stderr}")
        if k:
            times.append(elapsed)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=10, help="timed runs per command (default 10)")
    args = ap.parse_args()
    base = dict(os.environ)
    base["PYTHONPATH"] = str(REPO / "src") + os.pathsep + base.get("PYTHONPATH", "")
    cached = {k: v for k, v in base.items() if k != "PYTHONDONTWRITEBYTECODE"}
    uncached = dict(base, PYTHONDONTWRITEBYTECODE="1")
    rows = []
    with tempfile.TemporaryDirectory(prefix="subtrace-startup-") as tmp:
        for label, argv, both in commands(tmp):
            a = median_time(argv, cached, args.runs)
            b = median_time(argv, uncached, args.runs) if both else None
            rows.append((label, a, b))
    width = max(len(r[0]) for r in rows)
    print(f"median of {args.runs} runs, {sys.executable} (Python {sys.version.split()[0]})")
    print(f"{'command':<{width}}  {'bytecode s':>10}  {'no bytecode s':>13}")
    for label, a, b in rows:
        mark = ""
        if "--help" in label or "--version" in label:
            mark = "  ok" if a < GOAL_S else f"  above {GOAL_S} s"
        second = "-" if b is None else f"{b:.3f}"
        print(f"{label:<{width}}  {a:>10.3f}  {second:>13}{mark}")


if __name__ == "__main__":
    main()
