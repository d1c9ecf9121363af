"""Skip groups over an isolated patch's items (patches/groups.py) against a plain reading of
their definition: the items of each patch depth first in its split tree (a node's own items
before its subtrees, children by code), and a group before every subtree of at least
``MIN_GROUP`` items (two for a whole patch) unless a coarser group holds the same items.
Seeded random layouts of sub-squares (the one-key order) and of sub-triangles (the child
codes' columns)."""

from __future__ import annotations

import numpy as np
import pytest

from subtrace.patches.groups import MIN_GROUP, child_codes, grouped_layout


def _naive(root, level, i0, j0, orient, lo, hi):
    """``grouped_layout``'s rows from its definition: ``[(item or None, group level,
    span)]`` per row, by walking each patch's tree from the root."""
    codes = child_codes(level, i0, j0, orient)
    rows = []
    for p in range(int(root.max()) + 1):
        mine = [k for k in range(len(root)) if root[k] == p]
        # an item's path: the codes of its ancestors at levels 1 .. its level
        path = {k: tuple(int(codes[k, t]) for t in range(1, int(level[k]) + 1)) for k in mine}
        kept = set()

        def walk(prefix, items):
            l = len(prefix)
            group = len(items) >= (2 if l == 0 else MIN_GROUP) and frozenset(items) not in kept
            here = len(rows)
            if group:
                kept.add(frozenset(items))
                rows.append([None, l, 0])
            # the node's own items (a child at this level) by code, then its subtrees
            own = sorted((path[k][l], k) for k in items if len(path[k]) == l + 1)
            if l == 0:
                own = [(0, k) for k in items if not path[k]] + own
            rows.extend([k, -1, 0] for _, k in own)
            for c in range(4):
                sub = [k for k in items if len(path[k]) > l + 1 and path[k][l] == c]
                if sub:
                    walk(prefix + (c,), sub)
            if group:
                rows[here][2] = len(rows) - here

        walk((), mine)
    return rows


def _layout(rng, triangles):
    """Random items of a few patches: distinct places, levels 1 .. 7, or a patch of one item
    at level 0 (the whole patch: the only item whose codes are all its ancestors'), shuffled."""
    rows = []
    for p in range(int(rng.integers(1, 6))):
        if rng.random() < 0.2:
            rows.append((p, 0, 0, 0, 1))
            continue
        seen = set()
        for _ in range(int(rng.integers(1, 70))):
            lv = int(rng.integers(1, 8))
            i, j = int(rng.integers(0, 1 << lv)), int(rng.integers(0, 1 << lv))
            g = 1
            if triangles:  # (upright at (i, j) with i + j < 2^lv, or turned)
                g = 1 if i + j < (1 << lv) else -1
                if g < 0:
                    i, j = i + 1, j + 1
            if (lv, i, j, g) not in seen:
                seen.add((lv, i, j, g))
                rows.append((p, lv, i, j, g))
    rows = np.array(rows, np.int64)[rng.permutation(len(rows))]
    return rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3], (rows[:, 4] if triangles else None)


@pytest.mark.parametrize("triangles", [False, True], ids=["squares", "triangles"])
@pytest.mark.parametrize("seed", range(12))
def test_groups_as_defined(seed, triangles):
    """Every row where the definition puts it: items in depth-first order, each group's
    level and span, boxes the union of the items' a group spans, each patch's first row
    and count."""
    rng = np.random.default_rng(seed)
    root, level, i0, j0, orient = _layout(rng, triangles)
    lo = rng.normal(size=(len(root), 3))
    hi = lo + rng.random((len(root), 3))
    take, g_level, g_lo, g_hi, g_span, first, count = grouped_layout(
        root, level, i0, j0, orient, lo, hi)
    want = _naive(root, level, i0, j0, orient, lo, hi)
    assert len(take) == len(want)
    g = 0
    for r, (item, lv, span) in enumerate(want):
        if item is not None:
            assert take[r] == item
            continue
        assert take[r] < 0 and g_level[g] == lv and g_span[g] == span
        items = take[r:r + span]
        items = items[items >= 0]
        np.testing.assert_array_equal(g_lo[g], lo[items].min(axis=0))
        np.testing.assert_array_equal(g_hi[g], hi[items].max(axis=0))
        g += 1
    assert g == len(g_level)
    sizes = [sum(1 for k in range(len(root)) if root[k] == p) for p in range(len(first))]
    np.testing.assert_array_equal(first, np.cumsum(count) - count)
    assert count.sum() == len(take) and all(c >= s for c, s in zip(count, sizes))
