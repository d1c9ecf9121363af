"""Per-pixel arrays in one allocation: fewer, larger pages to fault in.

NumPy asks Linux for transparent huge pages (``madvise(MADV_HUGEPAGE)``) on an allocation
of 4 MB or more, so touching it faults once per 2 MB instead of once per 4 kB page. A
render's per-pixel arrays of 4 bytes a pixel (a patch id, a ray's request) are 3.7 MB at
1280x720, just below that, and the trace writes them in scattered rows. On the machine
measured (a virtual machine, 2 cores) those faults cost the trace of osd_catmark_nonquads
about 10 ms, against about 40 ms for its rays' work (BENCHMARKS.md, "Per-pixel arrays in
huge pages"). :func:`one_block` cuts the arrays a render uses together from one allocation
instead, and :func:`let_go` gives back the memory of some of them while a view of the same
allocation stays in use (the hit records but their distances, once shaded).
"""

from __future__ import annotations

import ctypes
import mmap

import numpy as np

_ALIGN = 64  # bytes: each array starts on a cache line of its own


def one_block(*specs) -> list[np.ndarray]:
    """Uninitialised arrays (as ``np.empty``), one per ``(shape, dtype)`` of ``specs``, each
    a view of one allocation, aligned to a cache line."""
    sizes = [int(np.prod(shape, dtype=np.int64)) * np.dtype(dtype).itemsize
             for shape, dtype in specs]
    starts = np.cumsum([0] + [-(-b // _ALIGN) * _ALIGN for b in sizes]).tolist()
    block = np.empty(starts[-1] + _ALIGN, np.uint8)
    skip = -block.ctypes.data % _ALIGN
    return [block[skip + s:skip + s + b].view(dtype).reshape(shape)
            for s, b, (shape, dtype) in zip(starts, sizes, specs)]


# what let_go gives back: whole transparent huge pages (2 MB on x86-64 and arm64 with 4 kB
# pages), so that none is split into small ones (splitting them, when a band of hit records
# was let go at a time, made shading slower: BENCHMARKS.md, "Shading in bands")
_GRANULE = 2 * 1024 * 1024


def _madvise(name="MADV_DONTNEED"):
    """libc's ``madvise`` and the advice ``name``, or None where either is missing."""
    advice = getattr(mmap, name, None)
    try:
        fn = ctypes.CDLL(None, use_errno=True).madvise
    except (OSError, AttributeError, TypeError):
        return None
    if advice is None:
        return None
    fn.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int]
    fn.restype = ctypes.c_int
    return fn, advice


_MADVISE = _madvise()
_NO_HUGE = _madvise("MADV_NOHUGEPAGE")


def let_go(arrays) -> int:
    """Give the memory of the arrays ``arrays`` back to the system while a view of the
    same allocation stays in use (``madvise(MADV_DONTNEED)`` on the whole 2 MB granules
    inside each): their contents are lost (read as zeros), so only for arrays that are
    never read again. Returns the bytes given back (0 where the call does not exist)."""
    if _MADVISE is None:
        return 0
    fn, advice = _MADVISE
    total = 0
    for a in arrays:
        lo = -(-a.ctypes.data // _GRANULE) * _GRANULE
        hi = (a.ctypes.data + a.nbytes) // _GRANULE * _GRANULE
        if hi > lo and fn(lo, hi - lo, advice) == 0:
            total += hi - lo
    return total


def small_pages(a: np.ndarray) -> np.ndarray:
    """``a`` (just allocated, untouched) faulted in small pages: ``madvise(MADV_NOHUGEPAGE)``
    on the whole 4 kB pages inside it. For a large store of which a render touches only the
    start, and a varying amount: NumPy asks for transparent huge pages on every allocation
    of 4 MB and more, and then the first byte written in each 2 MB makes all of it resident.
    The memos' stores (``trace.pools.Memos``: six per thread, each touched up to what one
    chunk of rays split) held 2 MB each at least that way, 24-28 MiB of the tip of the
    sword refined twice, for about 4 MiB of splits a thread (BENCHMARKS.md, "Memory of the
    streamed render"). Returns ``a``."""
    if _NO_HUGE is None or a.nbytes < _GRANULE:
        return a
    fn, advice = _NO_HUGE
    page = mmap.PAGESIZE
    lo = -(-a.ctypes.data // page) * page
    hi = (a.ctypes.data + a.nbytes) // page * page
    if hi > lo:
        fn(lo, hi - lo, advice)
    return a
