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
