"""Bounding volume hierarchy over boxes, as flat arrays (pbrt's LinearBVHNode layout).

``build_bvh(bmin, bmax)`` returns a :class:`BVH`:

* ``node_min``/``node_max`` (K,3) float64 node boxes;
* ``node_first`` (K,) int64: for an inner node the index of its first child (the second is
  the next node), for a leaf the first entry of ``prims``;
* ``node_count`` (K,) int64: 0 for inner nodes, the number of primitives for leaves;
* ``prims`` (N,) int64: primitive ids in leaf order.

Built top-down by binned surface-area heuristic over centroids (16 bins), leaves of at most
``config.BVH_LEAF_SIZE`` primitives; deterministic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from .. import config

_BINS = 16


@dataclass(frozen=True, eq=False)
class BVH:
    node_min: np.ndarray
    node_max: np.ndarray
    node_first: np.ndarray
    node_count: np.ndarray
    prims: np.ndarray

    @property
    def n_nodes(self) -> int:
        return len(self.node_first)


def build_bvh(bmin: np.ndarray, bmax: np.ndarray, leaf_size: int | None = None) -> BVH:
    bmin = np.ascontiguousarray(bmin, dtype=np.float64).reshape(-1, 3)
    bmax = np.ascontiguousarray(bmax, dtype=np.float64).reshape(-1, 3)
    n = len(bmin)
    leaf = config.BVH_LEAF_SIZE if leaf_size is None else int(leaf_size)
    cap = max(1, 2 * n)
    node_min = np.empty((cap, 3))
    node_max = np.empty((cap, 3))
    first = np.zeros(cap, np.int64)
    count = np.zeros(cap, np.int64)
    prims = np.arange(n, dtype=np.int64)
    k = _build(bmin, bmax, prims, leaf, node_min, node_max, first, count)
    return BVH(node_min[:k].copy(), node_max[:k].copy(), first[:k].copy(), count[:k].copy(),
               prims)


@nb.njit(cache=True)
def _area(lo, hi):
    d0, d1, d2 = hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]
    if d0 < 0:
        return 0.0
    return d0 * d1 + d1 * d2 + d2 * d0


@nb.njit(cache=True)
def _build(bmin, bmax, prims, leaf_size, node_min, node_max, first, count):
    n = len(prims)
    if n == 0:
        node_min[0, :] = np.inf
        node_max[0, :] = -np.inf
        first[0] = 0
        count[0] = 0
        return 1
    cent = 0.5 * (bmin + bmax)
    # explicit stack of (node index, start, end); children are written depth-first
    st_node = np.empty(128, np.int64)
    st_lo = np.empty(128, np.int64)
    st_hi = np.empty(128, np.int64)
    sp = 0
    st_node[0], st_lo[0], st_hi[0] = 0, 0, n
    sp = 1
    n_nodes = 1
    bin_lo = np.empty((_BINS, 3))
    bin_hi = np.empty((_BINS, 3))
    bin_n = np.empty(_BINS, np.int64)
    right_area = np.empty(_BINS)
    right_n = np.empty(_BINS, np.int64)
    lo = np.empty(3)
    hi = np.empty(3)
    while sp > 0:
        sp -= 1
        node, s, e = st_node[sp], st_lo[sp], st_hi[sp]
        # node box and centroid bounds
        nlo = np.full(3, np.inf)
        nhi = np.full(3, -np.inf)
        clo = np.full(3, np.inf)
        chi = np.full(3, -np.inf)
        for i in range(s, e):
            p = prims[i]
            for a in range(3):
                nlo[a] = min(nlo[a], bmin[p, a])
                nhi[a] = max(nhi[a], bmax[p, a])
                clo[a] = min(clo[a], cent[p, a])
                chi[a] = max(chi[a], cent[p, a])
        node_min[node] = nlo
        node_max[node] = nhi
        cnt = e - s
        ax = 0
        ext = chi[0] - clo[0]
        for a in range(1, 3):
            if chi[a] - clo[a] > ext:
                ax = a
                ext = chi[a] - clo[a]
        if cnt <= leaf_size or ext <= 0.0:
            first[node] = s
            count[node] = cnt
            continue
        # binned SAH along the widest centroid axis
        bin_n[:] = 0
        bin_lo[:] = np.inf
        bin_hi[:] = -np.inf
        scale = _BINS / ext
        for i in range(s, e):
            p = prims[i]
            b = min(_BINS - 1, int((cent[p, ax] - clo[ax]) * scale))
            bin_n[b] += 1
            for a in range(3):
                bin_lo[b, a] = min(bin_lo[b, a], bmin[p, a])
                bin_hi[b, a] = max(bin_hi[b, a], bmax[p, a])
        lo[:] = np.inf
        hi[:] = -np.inf
        acc = 0
        for b in range(_BINS - 1, 0, -1):
            for a in range(3):
                lo[a] = min(lo[a], bin_lo[b, a])
                hi[a] = max(hi[a], bin_hi[b, a])
            acc += bin_n[b]
            right_area[b] = _area(lo, hi)
            right_n[b] = acc
        lo[:] = np.inf
        hi[:] = -np.inf
        acc = 0
        best = np.inf
        split = -1
        for b in range(0, _BINS - 1):
            for a in range(3):
                lo[a] = min(lo[a], bin_lo[b, a])
                hi[a] = max(hi[a], bin_hi[b, a])
            acc += bin_n[b]
            if acc == 0 or right_n[b + 1] == 0:
                continue
            cost = acc * _area(lo, hi) + right_n[b + 1] * right_area[b + 1]
            if cost < best:
                best = cost
                split = b
        # partition (stable within each side keeps the build deterministic)
        mid = s
        if split >= 0:
            tmp = np.empty(cnt, np.int64)
            k = 0
            for i in range(s, e):
                p = prims[i]
                if min(_BINS - 1, int((cent[p, ax] - clo[ax]) * scale)) <= split:
                    tmp[k] = p
                    k += 1
            mid = s + k
            for i in range(s, e):
                p = prims[i]
                if min(_BINS - 1, int((cent[p, ax] - clo[ax]) * scale)) > split:
                    tmp[k] = p
                    k += 1
            prims[s:e] = tmp
        if mid == s or mid == e:
            mid = s + cnt // 2  # degenerate binning: split the range in two
        left = n_nodes
        right = n_nodes + 1
        n_nodes += 2
        first[node] = left
        count[node] = 0
        st_node[sp], st_lo[sp], st_hi[sp] = right, mid, e
        sp += 1
        st_node[sp], st_lo[sp], st_hi[sp] = left, s, mid
        sp += 1
    return n_nodes
