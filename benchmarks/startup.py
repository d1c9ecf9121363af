"""Benchmark: how long the short commands take to start, as whole processes, and the first
render on an empty kernel cache.

    python benchmarks/startup.py [--runs 10] [--cold 3]

First (``--cold N`` times, 0 to skip) the **cold first render**: the default scene at its
full size (1280x720, ``subtrace render --quiet``) on an empty kernel cache
(``SUBTRACE_CACHE_DIR`` a fresh folder), run from a fresh copy of ``src/`` (new files, new
modification times: an install); then the **reinstall**: the same command from a second
copy in another folder with other modification times (``pip install .`` again, or another
virtual environment) and the same cache, which must compile nothing: its time, and the
cache files it added (0). The load average is printed beside each cold run: on a shared
machine compile times follow it.

Then the median wall time of ``--runs`` runs of each command (after one untimed run that
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
import shutil
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


def _copy_sources(dest: Path) -> Path:
    """``src/subtrace`` copied to ``dest/subtrace`` (new files: new modification times,
    no bytecode); returns ``dest``, the PYTHONPATH entry."""
    shutil.copytree(REPO / "src" / "subtrace", dest / "subtrace",
                    ignore=shutil.ignore_patterns("__pycache__"))
    return dest


def _cache_files(tmp: Path) -> int:
    """Numba cache files under ``tmp`` (the cache and XDG_CACHE_HOME folders)."""
    return sum(1 for _ in tmp.rglob("*.nb[ic]"))


def cold_and_reinstall(runs: int, env: dict) -> list[tuple[float, float, int, str]]:
    """``runs`` times: (cold first render s, reinstall render s, cache files the reinstall
    added, load averages before / after the cold render)."""
    rows = []
    for _ in range(runs):
        with tempfile.TemporaryDirectory(prefix="subtrace-cold-") as tmp:
            tmp = Path(tmp)
            cache = tmp / "cache"
            run_env = {k: v for k, v in env.items()
                       if k not in ("NUMBA_CACHE_DIR", "PYTHONPATH")}
            run_env["SUBTRACE_CACHE_DIR"] = str(cache)
            run_env["XDG_CACHE_HOME"] = str(tmp / "xdg")  # (a tree older than the variable)
            argv = [sys.executable, "-m", "subtrace.cli", "render", "--quiet",
                    "-o", str(tmp / "cold.exr")]
            times = []
            load0 = os.getloadavg()[0]
            for copy in ("install-a", "install-b"):
                run_env["PYTHONPATH"] = str(_copy_sources(tmp / copy))
                before = _cache_files(tmp)
                t0 = time.perf_counter()
                proc = subprocess.run(argv, env=run_env, stdout=subprocess.DEVNULL,
                                      stderr=subprocess.PIPE, text=True)
                times.append(time.perf_counter() - t0)
                if proc.returncode != 0:
                    raise SystemExit(f"{' '.join(argv)} failed: {proc.stderr}")
                if copy == "install-a":
                    load1 = os.getloadavg()[0]
                added = _cache_files(tmp) - before
            rows.append((times[0], times[1], added, f"{load0:.1f} / {load1:.1f}"))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=10, help="timed runs per command (default 10)")
    ap.add_argument("--cold", type=int, default=3,
                    help="cold first renders, each followed by a reinstall (default 3; 0: none)")
    args = ap.parse_args()
    base = dict(os.environ)
    if args.cold > 0:
        cold = cold_and_reinstall(args.cold, base)
        print("cold first render (default scene, 1280x720, empty cache) and reinstall:")
        print(f"{'cold s':>8}  {'reinstall s':>11}  {'files added':>11}  load before / after")
        for c, r, added, load in cold:
            print(f"{c:>8.1f}  {r:>11.2f}  {added:>11d}  {load}")
        print(f"median cold {statistics.median(r[0] for r in cold):.1f} s, reinstall "
              f"{statistics.median(r[1] for r in cold):.2f} s\n", flush=True)
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
