"""Benchmark: what a new user waits for on a fresh machine, the README's commands as they are.

    python benchmarks/first_run.py [--warm 3] [--keep DIR]

Makes a fresh virtual environment in a temporary folder, installs this checkout into it
(``pip install .``, from a copy of the files git tracks or would track, so the checkout is
left as it was), and times, each as a whole process on a kernel cache of its own
(``SUBTRACE_CACHE_DIR`` a new empty folder, never ``~/.cache/subtrace``):

* the first render of the built-in default scene (``subtrace render --png``), which
  compiles the kernels;
* the same render again, warm (the median of ``--warm`` runs on the cache the first filled);
* a first Loop render (``subtrace render scenes/spot_loop.toml --png``) on an empty cache;
* ``subtrace warmup`` on an empty cache.

The commands run in a scratch folder, with stdout and stderr on pipes (so the first-run
notice, which only a terminal hears, is not printed). It prints one table with the date,
the commit (``+ changes`` when the working tree differs from it), the machine's cores and
its load average (``os.getloadavg``) before each command: on a shared machine compile times
follow the load. The last line quotes the compile notice's estimate
(``subtrace.runtime.jit.COLD_COMPILE``), which should say what the first render measures.
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
import time
from pathlib import Path

from _common import load, timed  # benchmarks/ is on sys.path when run as a script

REPO = Path(__file__).resolve().parents[1]


def git(*args: str) -> str:
    """A git command's output in the checkout ('' where git fails)."""
    try:
        return subprocess.run(["git", "-C", str(REPO), *args], capture_output=True,
                              text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return ""


def commit() -> str:
    """The checkout's commit, with ``+ changes`` where tracked files differ from it."""
    head = git("rev-parse", "--short", "HEAD") or "unknown"
    return f"{head} + changes" if git("status", "--porcelain", "--untracked-files=no") else head


def copy_checkout(dest: Path) -> Path:
    """The checkout's files (tracked, and untracked ones git does not ignore) copied to
    ``dest``: what a clone of this working tree holds."""
    listed = git("ls-files", "-z", "--cached", "--others", "--exclude-standard")
    names = [n for n in listed.split("\0") if n] if listed else None
    if names is None:
        raise SystemExit("first_run.py: git cannot list the checkout's files")
    for name in names:
        src = REPO / name
        if src.is_file():
            target = dest / name
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, target)
    return dest


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--warm", type=int, default=3, help="warm renders (their median)")
    ap.add_argument("--keep", metavar="DIR",
                    help="work in DIR (kept) instead of a temporary folder")
    args = ap.parse_args()
    root = Path(args.keep or tempfile.mkdtemp(prefix="subtrace-first-run-"))
    root.mkdir(parents=True, exist_ok=True)
    head = (datetime.date.today().isoformat(), commit())  # (what was copied)
    try:
        rows, notice = run(root, args.warm)
    finally:
        if not args.keep:
            shutil.rmtree(root, ignore_errors=True)
    report(head, rows, notice)


def run(root: Path, warm: int) -> tuple[list[tuple[str, str, float, str]], str]:
    """(step, command, seconds, load before) of each step, and the notice's estimate."""
    src = copy_checkout(root / "checkout")
    venv = root / "venv"
    rows = []
    before = load()
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    pip = [str(venv / "bin" / "python"), "-m", "pip", "install", "-q", str(src)]
    subprocess.run(pip, check=True, stdout=subprocess.DEVNULL)
    rows.append(("install", "python -m venv && pip install .", time.perf_counter() - t0,
                 before))
    subtrace = str(venv / "bin" / "subtrace")
    work = root / "work"
    work.mkdir()
    env = {k: v for k, v in os.environ.items()
           if k not in ("NUMBA_CACHE_DIR", "PYTHONPATH", "VIRTUAL_ENV")}
    env["PATH"] = f"{venv / 'bin'}{os.pathsep}{env.get('PATH', '')}"

    def step(argv, cache):
        """(seconds, load before) of ``subtrace ARGV`` on the kernel cache ``cache``."""
        env["SUBTRACE_CACHE_DIR"] = str(root / cache)
        before = load()
        return timed([subtrace, *argv], work, env, "first_run.py"), before

    rows.append(("first render", "subtrace render --png", *step(["render", "--png"],
                                                                "cache-default")))
    warm_runs = [step(["render", "--png"], "cache-default") for _ in range(max(1, warm))]
    rows.append((f"warm render (median of {len(warm_runs)})", "subtrace render --png",
                 statistics.median(s for s, _ in warm_runs), warm_runs[0][1]))
    loop = ["render", str(src / "scenes" / "spot_loop.toml"), "--png", "-o", "spot_loop.exr"]
    rows.append(("first Loop render", "subtrace render scenes/spot_loop.toml --png",
                 *step(loop, "cache-loop")))
    rows.append(("warmup", "subtrace warmup", *step(["warmup"], "cache-warmup")))
    notice = subprocess.run([str(venv / "bin" / "python"), "-c",
                             "from subtrace.runtime.jit import COLD_COMPILE; print(COLD_COMPILE)"],
                            env=env, capture_output=True, text=True).stdout.strip()
    return rows, notice


def report(head: tuple[str, str], rows, notice: str) -> None:
    """The table, headed by the date and commit (``head``), the interpreter and cores."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    print(f"benchmarks/first_run.py: {head[0]}, commit {head[1]}, Python "
          f"{sys.version.split()[0]}, {cores} cores, load after {load()}")
    print()
    print("| step | command | seconds | load before (1, 5, 15 min) |")
    print("|---|---|---|---|")
    for name, command, seconds, before in rows:
        print(f"| {name} | `{command}` | {seconds:.1f} | {before} |")
    print()
    print(f"The compile notice says: {notice or '(not found)'}.")


if __name__ == "__main__":
    main()
