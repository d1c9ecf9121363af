"""Bounding volume hierarchy over boxes, as flat arrays (pbrt's LinearBVHNode layout), and the
one slab test and near-first traversal that every kernel walks boxes with.

``build_bvh(bmin, bmax)`` returns a :class:`BVH`:

* ``node_min``/``node_max`` (K,3) float64 node boxes;
* ``node_first`` (K,) int64: for an inner node the index of its first child (the second is
  the next node), for a leaf the first entry of ``prims``;
* ``node_count`` (K,) int64: 0 for inner nodes, the number of primitives for leaves;
* ``prims`` (N,) int64: primitive ids in leaf order.

Built top-down by binned surface-area heuristic over centroids (16 bins), leaves of at most
``config.BVH_LEAF_SIZE`` primitives; deterministic.

Traversal (:func:`bvh_start`, :func:`bvh_next_leaf`): a ray or line ``o + t d`` (given by
its origin and ``1/d``) walks the nodes whose boxes (grown by :func:`padded` where a margin
is wanted) it enters within
``[tlo, thi]``, nearer child first, on a caller's stack of ``config.STACK_SIZE`` (node,
entry distance) pairs; each call returns the next leaf's range of ``prims``. ``thi`` may
shrink between calls (a closest-hit search): nodes entered beyond it are dropped as they
are popped. The renderer's primary rays, the line queries and their shell marking all walk
this way (inlined into each kernel).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from subtrace import config
from subtrace.runtime.jit import callee_njit, leaf_njit, llvm_inline_njit, nb

_BINS = 16
STACK_SIZE = config.STACK_SIZE  # (a global the jitted build reads as a constant)
# a slab's exit distance is pushed out by this much of itself: the rounding of its three
# operations (a few ulps), so a box is never missed by a ray that grazes it
SLAB_ROUNDING = 1e-15


class BVH(NamedTuple):
    node_min: np.ndarray
    node_max: np.ndarray
    node_first: np.ndarray
    node_count: np.ndarray
    prims: np.ndarray

    @property
    def n_nodes(self) -> int:
        return len(self.node_first)


def no_bvh() -> BVH:
    """An empty BVH (the kernels' arguments when rays use the projection instead)."""
    z = np.zeros(0, np.int64)
    return BVH(np.zeros((0, 3)), np.zeros((0, 3)), z, z, z)


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
def traversal_stack():
    """A traversal stack: node ids and their entry distances (from Python or a kernel)."""
    return np.empty(STACK_SIZE, np.int64), np.empty(STACK_SIZE)


@llvm_inline_njit
def slab_range(ox, oy, oz, ix, iy, iz, lo0, lo1, lo2, hi0, hi1, hi2, tlo, thi):
    """Entry and exit distances of the line ``o + t d`` (``i`` = 1/d) in the box [lo, hi]
    clipped to [tlo, thi], or (inf, inf) if it misses it there. IEEE infinities handle zero
    direction components; where one meets a slab plane (0 * inf: NaN) the box counts as
    entered at ``tlo``. The exit is pushed out by ``SLAB_ROUNDING`` of itself."""
    t0 = (lo0 - ox) * ix
    t1 = (hi0 - ox) * ix
    tn = min(t0, t1)
    tf = max(t0, t1)
    t0 = (lo1 - oy) * iy
    t1 = (hi1 - oy) * iy
    tn = max(tn, min(t0, t1))
    tf = min(tf, max(t0, t1))
    t0 = (lo2 - oz) * iz
    t1 = (hi2 - oz) * iz
    tn = max(tn, min(t0, t1))
    tf = min(tf, max(t0, t1))
    if tn != tn or tf != tf:
        return tlo, thi
    tf = tf + SLAB_ROUNDING * abs(tf) + 1e-300
    tn = max(tn, tlo)
    if tn <= min(tf, thi):
        return tn, tf
    return np.inf, np.inf


@llvm_inline_njit
def slab_entry(ox, oy, oz, ix, iy, iz, lo0, lo1, lo2, hi0, hi1, hi2, tlo, thi):
    """Entry distance of :func:`slab_range` (inf: a miss)."""
    return slab_range(ox, oy, oz, ix, iy, iz, lo0, lo1, lo2, hi0, hi1, hi2, tlo, thi)[0]


@llvm_inline_njit
def _lane_entry(ox, oy, oz, ix, iy, iz, box, r, thi):
    """:func:`slab_entry` of box row ``r`` of ``box`` (N,6) (lo, hi) from 0 to ``thi``,
    without branches: the same operations, a miss or a NaN chosen at the end."""
    t0 = (box[r, 0] - ox) * ix
    t1 = (box[r, 3] - ox) * ix
    tn = min(t0, t1)
    tf = max(t0, t1)
    t0 = (box[r, 1] - oy) * iy
    t1 = (box[r, 4] - oy) * iy
    tn = max(tn, min(t0, t1))
    tf = min(tf, max(t0, t1))
    t0 = (box[r, 2] - oz) * iz
    t1 = (box[r, 5] - oz) * iz
    tn = max(tn, min(t0, t1))
    tf = min(tf, max(t0, t1))
    nan = (tn != tn) | (tf != tf)
    tf = tf + SLAB_ROUNDING * abs(tf) + 1e-300
    tn = max(tn, 0.0)
    te = tn if tn <= min(tf, thi) else np.inf
    return 0.0 if nan else te


@llvm_inline_njit
def four_entries(ox, oy, oz, ix, iy, iz, box, c, thi):
    """:func:`slab_entry` (from 0 to ``thi``) of the four boxes ``c .. c + 3`` of ``box``
    (N,6), the children of a quadtree node: one straight run of the same operations on
    four lanes, which the compiler does side by side."""
    return (_lane_entry(ox, oy, oz, ix, iy, iz, box, c, thi),
            _lane_entry(ox, oy, oz, ix, iy, iz, box, c + 1, thi),
            _lane_entry(ox, oy, oz, ix, iy, iz, box, c + 2, thi),
            _lane_entry(ox, oy, oz, ix, iy, iz, box, c + 3, thi))


@leaf_njit
def box_entry(ox, oy, oz, ix, iy, iz, lo, hi, k, tlo, thi):
    """Entry distance into box ``k`` of (lo, hi) (N,3) (inf: a miss). Boxes that need a
    margin are grown beforehand (:func:`padded`): padding each box per test cost the
    renderer about 4 % of its trace time (Spot, measured)."""
    return slab_range(ox, oy, oz, ix, iy, iz, lo[k, 0], lo[k, 1], lo[k, 2], hi[k, 0], hi[k, 1],
                      hi[k, 2], tlo, thi)[0]


def padded(bvh: BVH, pad: float) -> BVH:
    """``bvh`` with every node box grown by ``pad`` on each side (the line queries' touch
    margin), the same arithmetic as padding each box as it is tested."""
    return bvh._replace(node_min=bvh.node_min - pad, node_max=bvh.node_max + pad)


@llvm_inline_njit
def bvh_start(ox, oy, oz, ix, iy, iz, bvh, tlo, thi, stack, stack_t):
    """Start a traversal: the root on the stack if the line enters it; returns the stack
    size."""
    if len(bvh.node_count) == 0:
        return 0
    te = box_entry(ox, oy, oz, ix, iy, iz, bvh.node_min, bvh.node_max, 0, tlo, thi)
    if te == np.inf:
        return 0
    stack[0] = 0
    stack_t[0] = te
    return 1


@llvm_inline_njit
def bvh_next_leaf(ox, oy, oz, ix, iy, iz, bvh, tlo, thi, stack, stack_t, sp):
    """Pop nodes (nearer child first) until a leaf the line enters within [tlo, thi];
    returns (first, end, sp): its range of ``bvh.prims`` and the new stack size, or
    (0, 0, 0) when no node is left."""
    while sp > 0:
        sp -= 1
        if stack_t[sp] > thi:  # a nearer hit was found since it was pushed
            continue
        node = stack[sp]
        first = bvh.node_first[node]
        cnt = bvh.node_count[node]
        if cnt > 0:
            return first, first + cnt, sp
        ta = box_entry(ox, oy, oz, ix, iy, iz, bvh.node_min, bvh.node_max, first, tlo, thi)
        tb = box_entry(ox, oy, oz, ix, iy, iz, bvh.node_min, bvh.node_max, first + 1, tlo, thi)
        near, far, t_near, t_far = first, first + 1, ta, tb
        if tb < ta:
            near, far, t_near, t_far = first + 1, first, tb, ta
        if t_far < np.inf:
            stack[sp] = far
            stack_t[sp] = t_far
            sp += 1
        if t_near < np.inf:
            stack[sp] = near
            stack_t[sp] = t_near
            sp += 1
    return np.int64(0), np.int64(0), np.int64(0)


@leaf_njit
def _area(lo, hi):
    d0, d1, d2 = hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]
    if d0 < 0:
        return 0.0
    return d0 * d1 + d1 * d2 + d2 * d0


@callee_njit
def _bin(c, lo, scale):
    """The SAH bin of a centroid coordinate ``c`` (``lo``: the node's least)."""
    return min(_BINS - 1, int((c - lo) * scale))


@callee_njit
def _sah_split(bmin, bmax, prims, cent, s, e, ax, clo, scale, bins):
    """The last bin of the left side of the cheapest binned-SAH split of ``prims[s:e]``
    along axis ``ax`` (-1: none); ``bins``: scratch (bin boxes and counts, the areas and
    counts right of each bin, a box)."""
    bin_lo, bin_hi, bin_n, right_area, right_n, lo, hi = bins
    for b in range(_BINS):
        bin_n[b] = 0
        for a in range(3):
            bin_lo[b, a] = np.inf
            bin_hi[b, a] = -np.inf
    for i in range(s, e):
        p = prims[i]
        b = _bin(cent[p, ax], clo, scale)
        bin_n[b] += 1
        for a in range(3):
            bin_lo[b, a] = min(bin_lo[b, a], bmin[p, a])
            bin_hi[b, a] = max(bin_hi[b, a], bmax[p, a])
    for a in range(3):
        lo[a] = np.inf
        hi[a] = -np.inf
    acc = 0
    for b in range(_BINS - 1, 0, -1):
        for a in range(3):
            lo[a] = min(lo[a], bin_lo[b, a])
            hi[a] = max(hi[a], bin_hi[b, a])
        acc += bin_n[b]
        right_area[b] = _area(lo, hi)
        right_n[b] = acc
    for a in range(3):
        lo[a] = np.inf
        hi[a] = -np.inf
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
    return split


@callee_njit
def _partition(prims, cent, s, e, ax, clo, scale, split, tmp):
    """Put ``prims[s:e]`` in bins up to ``split`` before the others, each side in its
    order (stable: the build is deterministic); returns where the right side starts."""
    k = 0
    for i in range(s, e):
        p = prims[i]
        if _bin(cent[p, ax], clo, scale) <= split:
            tmp[k] = p
            k += 1
    mid = s + k
    for i in range(s, e):
        p = prims[i]
        if _bin(cent[p, ax], clo, scale) > split:
            tmp[k] = p
            k += 1
    for i in range(e - s):
        prims[s + i] = tmp[i]
    return mid


@nb.njit(cache=True)
def _build(bmin, bmax, prims, leaf_size, node_min, node_max, first, count):
    # Written with scalar loops only: whole-array expressions, np.full and array-to-slice
    # assignment each pull a generic Numba implementation into the first compile (the slice
    # assignment alone, through its error message, about 1.5 s).
    n = len(prims)
    if n == 0:
        for a in range(3):
            node_min[0, a] = np.inf
            node_max[0, a] = -np.inf
        first[0] = 0
        count[0] = 0
        return 1
    cent = np.empty((n, 3))
    for p in range(n):
        for a in range(3):
            cent[p, a] = 0.5 * (bmin[p, a] + bmax[p, a])
    # explicit stack of (node index, start, end); children are written depth-first
    st_node = np.empty(STACK_SIZE, np.int64)
    st_lo = np.empty(STACK_SIZE, np.int64)
    st_hi = np.empty(STACK_SIZE, np.int64)
    st_node[0], st_lo[0], st_hi[0] = 0, 0, n
    sp = 1
    n_nodes = 1
    bins = (np.empty((_BINS, 3)), np.empty((_BINS, 3)), np.empty(_BINS, np.int64),
            np.empty(_BINS), np.empty(_BINS, np.int64), np.empty(3), np.empty(3))
    clo = np.empty(3)
    chi = np.empty(3)
    tmp = np.empty(n, np.int64)
    while sp > 0:
        sp -= 1
        node, s, e = st_node[sp], st_lo[sp], st_hi[sp]
        # node box (straight into the node arrays) and centroid bounds
        for a in range(3):
            node_min[node, a] = np.inf
            node_max[node, a] = -np.inf
            clo[a] = np.inf
            chi[a] = -np.inf
        for i in range(s, e):
            p = prims[i]
            for a in range(3):
                node_min[node, a] = min(node_min[node, a], bmin[p, a])
                node_max[node, a] = max(node_max[node, a], bmax[p, a])
                clo[a] = min(clo[a], cent[p, a])
                chi[a] = max(chi[a], cent[p, a])
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
        # binned SAH along the widest centroid axis, then a stable partition
        scale = _BINS / ext
        split = _sah_split(bmin, bmax, prims, cent, s, e, ax, clo[ax], scale, bins)
        mid = s
        if split >= 0:
            mid = _partition(prims, cent, s, e, ax, clo[ax], scale, split, tmp)
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
