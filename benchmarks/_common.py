"""Helpers shared by the benchmark scripts."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def bench_cache(name: str) -> Path:
    """The folder a benchmark keeps what it builds between runs (a base commit's kernels, the
    bpy environment, the Embree driver): ``$XDG_CACHE_HOME/subtrace-benchmarks/<name>``
    (``~/.cache`` where it is unset), apart from subtrace's own kernel cache
    (``~/.cache/subtrace``), which a benchmark never writes."""
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "subtrace-benchmarks" / name


def import_subtrace():
    """The installed subtrace, or the source checkout's when it is not installed."""
    try:
        import subtrace
    except ModuleNotFoundError as exc:
        if exc.name != "subtrace":
            raise
        sys.path.insert(0, str(REPO / "src"))
        import subtrace
    return subtrace


def split_extra(argv):
    """``(own, extra)``: a script's arguments before ``--`` and those after it (passed on to
    ``subtrace render``), or all of them and none."""
    argv = list(argv)
    if "--" not in argv:
        return argv, []
    k = argv.index("--")
    return argv[:k], argv[k + 1:]


def load() -> str:
    """The load average over 1, 5 and 15 minutes."""
    return " ".join(f"{x:.1f}" for x in os.getloadavg())


def timed(argv: list[str], cwd: Path, env: dict, script: str) -> float:
    """Wall seconds of one run of ``argv``; stops ``script`` (its name, for the message) if
    the run fails."""
    t0 = time.perf_counter()
    proc = subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    if proc.returncode != 0:
        tail = (proc.stderr.strip().splitlines() or ["no message"])[-1]
        raise SystemExit(f"{script}: {' '.join(argv)} failed ({proc.returncode}): {tail}")
    return seconds


def render_from_tree(tree: Path, cache: Path, args: list[str], script: str):
    """One ``subtrace render ARGS --quiet`` run from source tree ``tree`` (its ``src`` on
    the path) with kernel cache ``cache``, bytecode cached as an installed package's;
    returns (wall s, the process's ``os.wait4`` resource usage: peak RSS, CPU s of every
    thread). Stops ``script`` (its name, for the message) with the command's error output
    if the render fails."""
    # (SUBTRACE_CACHE_DIR too: where it is set, subtrace takes it before NUMBA_CACHE_DIR, and
    # two trees would share one cache)
    env = dict(os.environ, SUBTRACE_CACHE_DIR=str(cache), NUMBA_CACHE_DIR=str(cache),
               PYTHONPATH=str(tree / "src"))
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # as installed: bytecode cached
    cmd = [sys.executable, "-m", "subtrace.cli", "render", *args, "--quiet"]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    err = proc.stderr.read().decode(errors="replace")
    proc.stderr.close()
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{script}: {tree.name}: {' '.join(cmd)} failed:\n{err}")
    return wall, usage
