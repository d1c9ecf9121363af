"""Arrays cut from one allocation (``runtime/memory.py``)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from subtrace.runtime.memory import one_block

DTYPES = [np.float64, np.float32, np.int32, np.int64, np.int8, np.uint8]
SHAPES = st.lists(st.integers(0, 9), min_size=1, max_size=3).map(tuple)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(SHAPES, st.sampled_from(DTYPES)), min_size=1, max_size=6))
def test_arrays_of_one_block_are_disjoint_aligned_and_as_asked(specs):
    arrays = one_block(*specs)
    assert len(arrays) == len(specs)
    base = arrays[0].base
    while base.base is not None:
        base = base.base
    for a, (shape, dtype) in zip(arrays, specs):
        assert a.shape == shape and a.dtype == np.dtype(dtype) and a.flags.c_contiguous
        assert (a.size == 0 or a.ctypes.data % 64 == 0) and a.flags.writeable
        owner = a
        while owner.base is not None:
            owner = owner.base
        assert owner is base  # one allocation
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
    from subtrace.trace.pools import hit_arrays

    hits, request = hit_arrays(1280 * 720, request=True)
    owner = request
    while owner.base is not None:
        owner = owner.base
    assert request.nbytes < 4 << 20 <= owner.nbytes
    for a in hits:
        o = a
        while o.base is not None:
            o = o.base
        assert o is owner
