"""Arrays cut from one allocation (``runtime/memory.py``)."""

from __future__ import annotations

import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from subtrace.runtime.memory import let_go, one_block

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


def test_let_go_gives_back_whole_granules_of_the_arrays_named_and_nothing_else():
    """``let_go`` on some arrays of one block: the other arrays keep their values; of the
    arrays named, what it reports given back reads as zeros afterwards (whole 2 MB
    granules, the rest of them kept), and on Linux it gives back most of them."""
    n = 3_000_000  # (24 MB a float64 array: several granules each)
    t, a, b = one_block(((n,), np.float64), ((n,), np.float64), ((n // 2,), np.int32))
    t[:], a[:], b[:] = 1.0, 2.0, 3
    given = let_go([a, b])
    assert np.all(t == 1.0)
    zeroed = np.count_nonzero(a == 0.0) * 8 + np.count_nonzero(b == 0) * 4
    assert zeroed == given
    assert np.all((a == 0.0) | (a == 2.0)) and np.all((b == 0) | (b == 3))
    if sys.platform.startswith("linux"):
        assert given >= a.nbytes + b.nbytes - 4 * 2 * 1024 * 1024


def _mapping(a) -> tuple[dict, set]:
    """The fields (kB) and VmFlags of the /proc/self/smaps entry that holds ``a``'s first
    page-aligned byte."""
    import mmap

    addr = -(-a.ctypes.data // mmap.PAGESIZE) * mmap.PAGESIZE
    fields, flags, inside = {}, set(), False
    with open("/proc/self/smaps") as f:
        for line in f:
            head = line.split()
            if head and "-" in head[0] and not head[0].endswith(":"):
                if inside:
                    break
                lo, hi = (int(x, 16) for x in head[0].split("-"))
                inside = lo <= addr < hi
            elif inside and head[0] == "VmFlags:":
                flags = set(head[1:])
            elif inside and len(head) >= 2 and head[1].isdigit():
                fields[head[0].rstrip(":")] = int(head[1])
    return fields, flags


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc/self/smaps")
def test_small_pages_keep_a_sparsely_written_store_small():
    """An array advised by ``small_pages`` is marked for small pages (VmFlags ``nh``) and,
    written once every 2 MB, holds about a page for each write, not 2 MB; the memos' stores
    are advised so."""
    from subtrace.runtime.memory import small_pages
    from subtrace.trace.pools import Memos

    step = 2 * 1024 * 1024
    a = small_pages(np.empty(32 * step, np.uint8))
    a[::step] = 1
    fields, flags = _mapping(a)
    assert "nh" in flags
    assert fields.get("AnonHugePages", 0) == 0 and fields["Rss"] <= 1024  # kB
    for store in Memos(1).m[0][1:7]:  # (child, box, slab, data, nets, cells)
        assert "nh" in _mapping(store)[1]
