"""Arrays cut from one allocation (``runtime/memory.py``)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from subtrace.runtime.memory import one_block

DTYPES = [np.float64, np.float32, np.int32, np.int64, np.int8, np.uint8]
SHAPES = st.lists(st.integers(0, 9), min_size=1, max_size=3).map(tuple)


def _owner(a):
    """The array that owns ``a``'s memory."""
    while a.base is not None:
        a = a.base
    return a


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(SHAPES, st.sampled_from(DTYPES)), min_size=1, max_size=6))
def test_arrays_of_one_block_are_disjoint_aligned_and_as_asked(specs):
    arrays = one_block(*specs)
    assert len(arrays) == len(specs)
    base = _owner(arrays[0])
    for a, (shape, dtype) in zip(arrays, specs):
        assert a.shape == shape and a.dtype == np.dtype(dtype) and a.flags.c_contiguous
        assert (a.size == 0 or a.ctypes.data % 64 == 0) and a.flags.writeable
        assert _owner(a) is base  # one allocation
    for k, a in enumerate(arrays):  # writing one leaves the others as they were
        for b in arrays:
            b.view(np.uint8)[...] = 0
        a.view(np.uint8)[...] = 255
        for j, b in enumerate(arrays):
            assert np.all(b.view(np.uint8) == (255 if j == k else 0)) or b.size == 0


def test_a_render_block_is_one_allocation_of_huge_page_size():
    """The hit records of 1280x720 rays and their requests, which the rounds write in
    scattered rows, come from one allocation large enough for NumPy to ask for huge pages
    (4 MB); each of the 4-byte arrays alone is below that."""
    from subtrace.trace.pools import round_arrays

    hits, request = round_arrays(1280 * 720)
    owner = _owner(request)
    assert request.nbytes < 4 << 20 <= owner.nbytes
    assert all(_owner(a) is owner for a in hits)
