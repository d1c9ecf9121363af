"""Tests of subtrace.accel.bvh: the flat tree is a valid BVH over the given boxes."""

from __future__ import annotations

import numpy as np
import pytest

from subtrace.accel.bvh import build_bvh


def check_tree(bvh, bmin, bmax, leaf_size):
    """Every primitive in exactly one leaf, each node box the union of what it holds, leaves
    small unless their centroids coincide."""
    n = len(bmin)
    assert sorted(bvh.prims.tolist()) == list(range(n))
    seen = np.zeros(n, np.int64)
    stack = [0]
    while stack:
        node = stack.pop()
        first, count = bvh.node_first[node], bvh.node_count[node]
        if count > 0:
            held = bvh.prims[first:first + count]
            seen[held] += 1
            lo, hi = bmin[held].min(axis=0), bmax[held].max(axis=0)
            if count > leaf_size:  # only when binning cannot split: one centroid for all
                cent = 0.5 * (bmin[held] + bmax[held])
                assert np.all(cent == cent[0])
        else:
            kids = [first, first + 1]
            assert all(node < k < bvh.n_nodes for k in kids)
            lo = np.minimum(*(bvh.node_min[k] for k in kids))
            hi = np.maximum(*(bvh.node_max[k] for k in kids))
            stack += kids
        # exact: a node box is the min / max of the boxes below it
        np.testing.assert_array_equal(bvh.node_min[node], lo)
        np.testing.assert_array_equal(bvh.node_max[node], hi)
    assert np.all(seen == 1)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("n", [1, 2, 3, 7, 100, 2000])
@pytest.mark.parametrize("leaf_size", [1, 2, 5])
def test_random_boxes(seed, n, leaf_size):
    rng = np.random.default_rng(seed)
    bmin = rng.normal(size=(n, 3)) * rng.uniform(0.01, 10.0, 3)
    bmax = bmin + rng.uniform(0.0, 0.5, (n, 3))
    bvh = build_bvh(bmin, bmax, leaf_size)
    check_tree(bvh, bmin, bmax, leaf_size)
    again = build_bvh(bmin, bmax, leaf_size)  # deterministic
    for name in ("node_min", "node_max", "node_first", "node_count", "prims"):
        np.testing.assert_array_equal(getattr(bvh, name), getattr(again, name))


def test_coincident_and_repeated_boxes():
    rng = np.random.default_rng(5)
    same = np.zeros((9, 3))
    bvh = build_bvh(same, same + 1.0, 2)
    check_tree(bvh, same, same + 1.0, 2)
    assert bvh.n_nodes == 1 and bvh.node_count[0] == 9
    reps = np.repeat(rng.random((10, 3)), 7, axis=0)
    bvh = build_bvh(reps, reps + 0.1, 2)
    check_tree(bvh, reps, reps + 0.1, 2)


def test_empty():
    bvh = build_bvh(np.zeros((0, 3)), np.zeros((0, 3)))
    assert bvh.n_nodes == 1 and bvh.node_count[0] == 0 and len(bvh.prims) == 0
    assert np.all(bvh.node_min[0] == np.inf) and np.all(bvh.node_max[0] == -np.inf)


def _leaves_reached(bvh, o, d, pad, tlo, thi):
    """Every primitive of the leaves the shared traversal returns (node boxes grown by
    ``pad``), in order."""
    from subtrace.accel.bvh import bvh_next_leaf, bvh_start, padded, traversal_stack

    bvh = padded(bvh, pad)
    with np.errstate(divide="ignore"):
        inv = 1.0 / d
    stack, stack_t = traversal_stack()
    sp = bvh_start(*o, *inv, bvh, tlo, thi, stack, stack_t)
    out = []
    while sp > 0:
        a, b, sp = bvh_next_leaf(*o, *inv, bvh, tlo, thi, stack, stack_t, sp)
        out.extend(bvh.prims[a:b].tolist())
    return out


def _brute_entry(lo, hi, o, d, pad, tlo, thi):
    """The slab test in plain Python: where o + t d enters [lo - pad, hi + pad] within
    [tlo, thi], or inf (exact comparisons; the kernel's exit pad only adds grazing hits)."""
    tn, tf = tlo, thi
    for k in range(3):
        if d[k] == 0.0:
            if not (lo[k] - pad <= o[k] <= hi[k] + pad):
                return np.inf
            continue
        a = (lo[k] - pad - o[k]) / d[k]
        b = (hi[k] + pad - o[k]) / d[k]
        tn, tf = max(tn, min(a, b)), min(tf, max(a, b))
    return tn if tn <= tf else np.inf


@pytest.mark.parametrize("seed", range(4))
def test_traversal_finds_every_box_the_line_enters(seed):
    """The one near-first traversal (accel.bvh) reaches, among its leaves, every box a
    line (possibly unbounded both ways, padded boxes) enters within its interval, each
    primitive once; the slab test agrees with a plain-Python one away from grazing."""
    from subtrace.accel.bvh import box_entry

    rng = np.random.default_rng(seed)
    lo = rng.uniform(-1, 1, (300, 3))
    hi = lo + rng.uniform(0, 0.3, (300, 3))
    bvh = build_bvh(lo, hi)
    for _ in range(60):
        o = rng.uniform(-2, 2, 3)
        d = rng.normal(size=3)
        if rng.uniform() < 0.3:
            d[rng.integers(3)] = 0.0  # an axis-parallel component
        pad = float(rng.choice([0.0, 0.01]))
        tlo, thi = (0.0, np.inf) if rng.uniform() < 0.5 else (-np.inf, float(rng.uniform(0, 3)))
        with np.errstate(divide="ignore"):
            inv = 1.0 / d
        seen = _leaves_reached(bvh, o, d, pad, tlo, thi)
        assert len(seen) == len(set(seen))
        for i in range(len(lo)):
            want = _brute_entry(lo[i], hi[i], o, d, pad, tlo, thi)
            got = box_entry(*o, *inv, lo - pad, hi + pad, i, tlo, thi)
            if want < np.inf:
                assert i in seen
                assert got <= want + 1e-12 * (1 + abs(want))
            elif got < np.inf:  # only a grazing box may be entered in addition
                assert i in seen
