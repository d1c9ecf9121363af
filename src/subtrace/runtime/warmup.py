"""Compile the trace and shade kernels in a second process on a cold Numba cache.

The first render with an empty cache spends most of its time compiling: the kernels of
loading and preprocessing, then the trace and shade kernels. The two groups do not depend
on each other, so while the first process compiles (and runs) the loading and
preprocessing, a second process compiles the trace and shade kernels on the other core, by
calling them on empty inputs of exactly the types a render passes, and stores them in the
shared cache; the first process waits for it before tracing and then loads them from the
cache. On a warm cache nothing is started.

    python -m subtrace.runtime.warmup THREADS      # what the second process runs
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path


def _cached(name: str) -> bool:
    """Whether Numba's cache (this package version's folder) holds the kernel ``name``."""
    root = os.environ.get("NUMBA_CACHE_DIR")
    return bool(root) and any(Path(root).rglob(f"*{name}-*.nbi"))


def start(threads: int):
    """Start compiling the trace and shade kernels for ``threads`` threads in a second
    process if the cache lacks them; returns the process (or None)."""
    if _cached("_trace_task") and _cached("_shade_task"):
        return None
    try:
        return subprocess.Popen([sys.executable, "-m", "subtrace.runtime.warmup", str(int(threads))],
                                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
    except OSError:  # no second process: the kernels compile when first called
        return None


def wait(proc) -> None:
    """Wait for a process from :func:`start` (whatever its outcome: a kernel it did not
    store is compiled by the caller when first called)."""
    if proc is not None:
        proc.wait()


def stop(proc) -> None:
    """End a process from :func:`start` (the render it served failed)."""
    if proc is not None:
        proc.kill()
        proc.wait()


def compile_kernels(threads: int) -> None:
    """Compile ``trace.kernels._trace_task`` and ``shade._shade_task`` with the argument
    types of a render on ``threads`` threads: the bundles a render passes
    (``trace/pools.py``), empty, so nothing is traced."""
    import numpy as np

    from subtrace import config
    from subtrace.accel.bvh import no_bvh
    from subtrace.accel.projection import no_tiles
    from subtrace.runtime import threads as tasks
    from subtrace.shade import CHANNELS, PatchShading, miss_values, shade
    from subtrace.trace.kernels import trace_round
    from subtrace.trace.pools import (LeafTables, LoopGrids, Memos, Pieces, candidate_lists,
                                      hit_arrays)

    i64 = np.zeros(0, np.int64)
    frame = np.zeros((4, 3))
    grids = LoopGrids(0).view(LeafTables(0))
    iso = Pieces(0).view()
    tasks.set_threads(threads)
    try:
        trace_round(i64, frame, 1, 0, no_bvh(), no_tiles(), np.zeros((0, 3)), np.zeros((0, 3)),
                    grids, iso, Memos(threads).views(0), candidate_lists(0), config.TRI_SLACK,
                    hit_arrays(0), i64, i64)
        misses = hit_arrays(2)  # two pixels, both missed: the output planes' layout
        misses.t[:] = np.inf
        patches = PatchShading(np.zeros(0, np.int32), np.zeros(0, np.int32), np.zeros((0, 2)),
                               np.zeros(0), np.zeros(0, np.int8), np.zeros((0, 3)),
                               np.zeros((0, 3)), np.zeros(0))
        shade(frame, 1, misses, grids, iso, patches, miss_values((0.0, 0.0, 0.0)),
              np.zeros((len(CHANNELS), 2), np.float32), np.zeros((2, 3)),
              np.zeros(2, np.int64), np.zeros(threads, np.int64))
    finally:
        tasks.set_threads(None)


if __name__ == "__main__":
    compile_kernels(int(sys.argv[1]))
