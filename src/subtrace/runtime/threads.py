"""Run a Numba kernel on a few Python threads: the kernel is compiled with ``nogil=True``
and called once per thread as ``kernel(task, n_tasks, *args)``, taking the task's share of
the work (interleaved blocks, so both halves of an image cost about the same).

Numba's own ``parallel=True`` loops were the alternative; their bodies are typed and
compiled several times over (a parfor and its gufunc), which tripled the first-render
compile of the trace kernel, and gain nothing here over one call per thread.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor

_state = {"threads": None, "pool": None}


def max_threads() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        return os.cpu_count() or 1


def usable_threads(n, key: str = "--threads") -> int | None:
    """``n`` threads as asked, or every core this process may use where ``n`` is more (a
    scene or script written on a larger machine), with one warning per process; None stays
    None (every core). A count below 1 is an error naming ``key``."""
    from subtrace.errors import SceneError, SubtraceWarning

    if n is None:
        return None
    n = int(n)
    if n < 1:
        raise SceneError(f"expected a thread count of at least 1, got {n}", key=key)
    n_max = max_threads()
    if n > n_max:
        if n not in _warned:
            _warned.add(n)
            import warnings

            warnings.warn(SubtraceWarning(
                f"{key} {n}: this machine has {n_max} core{'s' if n_max != 1 else ''} for "
                f"this process; using {n_max}"), stacklevel=2)
        return n_max
    return n


_warned: set[int] = set()


def set_threads(n: int | None) -> None:
    """Use ``n`` threads for the kernels (None: every core)."""
    _state["threads"] = None if n is None else int(n)


def thread_count() -> int:
    return _state["threads"] or max_threads()


def run_tasks(kernel, *args, n: int | None = None) -> None:
    """``kernel(task, n, *args)`` for task = 0 .. n-1 on n threads (default
    :func:`thread_count`); re-raises the first error."""
    n = thread_count() if n is None else n
    if n == 1:
        kernel(0, 1, *args)
        return
    _on_threads(n, lambda t: kernel(t, n, *args))


def run_chunks(work, n_items: int, chunk: int, n: int | None = None) -> None:
    """``work(t, a, b)`` for the chunks [a, b) of ``range(n_items)``, ``chunk`` items each,
    on n threads (default :func:`thread_count`); ``t`` is the thread's index, for buffers of
    its own. Re-raises the first error.

    Each thread owns a contiguous segment (an n-th of the items) and takes its chunks front
    to back; a thread whose segment is done takes the next chunk from the back of the
    segment with the most left. So a thread with cheaper chunks takes more of them, and
    each thread's items stay mostly contiguous: neighbouring image rows, whose rays reuse
    what the thread's memo split for the rows before (with chunks handed out in turn, both
    threads split most patches). The chunks are the same on any number of threads,
    [k chunk, (k+1) chunk): the segments start at multiples of ``chunk`` and a thread takes
    whole ones from either end, so what a chunk's rays share (a memo each) does not depend
    on the threads."""
    n = thread_count() if n is None else n
    lock = threading.Lock()
    n_chunks = -(-n_items // chunk)
    front = [n_chunks * t // n * chunk for t in range(n)]
    back = front[1:] + [n_items]

    def worker(t):
        while True:
            with lock:
                if front[t] < back[t]:
                    a = front[t]
                    b = front[t] = min(a + chunk, back[t])
                else:
                    v = max(range(n), key=lambda k: back[k] - front[k])
                    if back[v] <= front[v]:
                        return
                    b = back[v]
                    a = back[v] = max(front[v], (b - 1) // chunk * chunk)
            work(t, a, b)

    if n == 1:
        worker(0)
    else:
        _on_threads(n, worker)


def _on_threads(n, fn) -> None:
    """``fn(t)`` for t = 0 .. n-1, ``fn(0)`` on the calling thread."""
    pool = _state["pool"]
    if pool is None or pool._max_workers < n:
        pool = _state["pool"] = ThreadPoolExecutor(max_workers=n, thread_name_prefix="subtrace")
    futures = [pool.submit(fn, t) for t in range(1, n)]
    fn(0)  # the calling thread takes the first share
    for f in futures:
        f.result()
