"""``subtrace warmup [--jobs N]``: compile every kernel into the kernel cache
(:func:`subtrace.runtime.warmup.compile_all`) and say where the cache is, with a line of
progress (:func:`progress_line`) after each of its commands and every few seconds between.

Run it once after installing (or in a cluster's image, or on one worker of a shared cache
folder) so that the first real command loads its kernels instead of compiling them.
"""

from __future__ import annotations

import os

from subtrace.cli.common import set_up_numba
from subtrace.errors import SubtraceError


def execute(args) -> int:
    """Compile what the cache lacks; print the cache folder and what it holds."""
    jobs = _jobs(args.jobs)
    set_up_numba(args)
    from subtrace.runtime import jit, warmup

    before = _files(jit.KERNEL_DIR)
    if not args.quiet:
        print(f"kernel cache: {jit.KERNEL_DIR}", flush=True)
    report = None if args.quiet else _reporter(jit.KERNEL_DIR)
    seconds = warmup.compile_all(jobs, report)
    after = _files(jit.KERNEL_DIR)
    if not args.quiet:
        kernels = sum(1 for name in after if name.endswith(".nbi"))
        new = len(after - before)
        what = (f"compiled in {seconds:.1f} s" if new
                else f"every kernel was cached already ({seconds:.1f} s)")
        print(f"{kernels} kernels, {_megabytes(jit.KERNEL_DIR):.1f} MB: {what}")
    return 0


def progress_line(done: int, total: int, kernels: int, seconds: float) -> str:
    """One line of ``subtrace warmup``'s progress: commands done of all, the kernels the
    cache holds so far, the seconds since it started."""
    return f"warmup: {done}/{total} commands done, {kernels} kernels in the cache, {seconds:.0f} s"


def _reporter(folder):
    """``progress(done, total, seconds)`` for compile_all: a :func:`progress_line`, with the
    kernels counted in ``folder``, printed at once."""

    def report(done, total, seconds):
        kernels = sum(1 for name in _files(folder) if name.endswith(".nbi"))
        print(progress_line(done, total, kernels, seconds), flush=True)

    return report


def _jobs(text) -> int:
    """``--jobs``: commands compiled at once (default: the usable cores)."""
    if text is None:
        return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
                   else os.cpu_count() or 1)
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise SubtraceError(f"--jobs: expected an integer >= 1, got {text!r}")
    return value


def _files(folder) -> set[str]:
    """The cache files under ``folder`` (relative paths)."""
    return {str(p.relative_to(folder)) for p in folder.rglob("*.nb[ic]")}


def _megabytes(folder) -> float:
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file()) / 2**20
