"""Per-pixel arrays in one allocation: fewer, larger pages to fault in.

NumPy asks Linux for transparent huge pages (``madvise(MADV_HUGEPAGE)``) on an allocation
of 4 MB or more, so touching it faults once per 2 MB instead of once per 4 kB page. A
render's per-pixel arrays of 4 bytes a pixel (a patch id, a ray's request) are 3.7 MB at
1280x720, just below that, and the trace writes them in scattered rows. On the machine
measured (a virtual machine, 2 cores) those faults cost the trace of osd_catmark_nonquads
about 10 ms, against about 40 ms for its rays' work (BENCHMARKS.md, "Per-pixel arrays in
huge pages"). :func:`one_block` cuts the arrays a render uses together from one allocation
instead.
"""

from __future__ import annotations

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
