"""The per-ray Bezier descent's bounds (``trace/bezier.py``): a cell's box cut by its slab
must let through every ray that meets the cell's surface or its two micro-triangles."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from subtrace.patches.basis import bez_point, net_box, split_net
from subtrace.trace.bezier import _cell_entry, _cell_slab


def _sub_net(root, depth, i, j):
    """The Bezier net of cell (i, j) of the depth-``depth`` grid of ``root`` (4,4,3), by
    repeated halving as the descent does it."""
    work = np.empty((8, 4, 4, 3))
    work[0] = root
    for lev in range(depth):
        shift = depth - 1 - lev
        q = ((i >> shift) & 1) + 2 * ((j >> shift) & 1)
        split_net(work, 0, work, 4)
        work[0] = work[4 + q]
    return work[:1].copy()


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 6), st.sampled_from([1e-3, 1.0, 1e3]))
def test_cell_slab_lets_through_rays_that_meet_the_cell(seed, depth, scale):
    rng = np.random.default_rng(seed)
    # a wavy random bicubic patch, away from the origin
    g = np.stack(np.meshgrid(np.arange(4.0), np.arange(4.0), indexing="ij"), -1)
    root = np.concatenate([g, rng.normal(0, 0.7, (4, 4, 1))], -1) + rng.normal(0, 0.2, (4, 4, 3))
    root = (root + rng.normal(0, 5, 3)) * scale
    nets = root[None]
    n = 1 << depth
    i, j = (int(x) for x in rng.integers(0, n, 2))
    sub = _sub_net(root, depth, i, j)
    box = np.array([net_box(sub, 0)])
    slab = np.empty((1, 5))
    _cell_slab(sub, 0, slab, 0)
    # the cell's exact corners (as the renderer builds them), points of its two triangles
    # and points of its surface
    corners = np.array([bez_point(nets, 0, (i + di) / n, (j + dj) / n)
                        for di, dj in ((0, 0), (1, 0), (1, 1), (0, 1))])
    pts = []
    for tri in ((0, 1, 2), (0, 2, 3)):
        w = rng.dirichlet(np.ones(3), 20)
        pts.append(w @ corners[list(tri)])
    uv = (np.array([i, j]) + rng.random((20, 2))) / n
    pts.append(np.array([bez_point(nets, 0, u, v) for u, v in uv]))
    pts.append(corners)
    for p in np.concatenate(pts):
        o = p + rng.normal(0, 3 * scale, 3)
        d = p - o
        t = float(np.linalg.norm(d))
        d /= t
        with np.errstate(divide="ignore"):
            inv = 1.0 / d
        te = _cell_entry(o[0], o[1], o[2], inv[0], inv[1], inv[2], d[0], d[1], d[2], box, slab, 0,
                         np.inf)
        assert te <= t * (1 + 1e-9)


def test_cell_slab_culls_rays_that_pass_beside_a_flat_cell():
    """The slab is tight for a flat cell: a ray through the cell's box that crosses its plane
    outside the box is culled (where the box alone lets it through)."""
    g = np.stack(np.meshgrid(np.arange(4.0), np.arange(4.0), indexing="ij"), -1)
    # a plane tilted against every axis
    net = np.concatenate([g, (0.3 * g[..., :1] + 0.5 * g[..., 1:])], -1)[None]
    box = np.array([net_box(net, 0)])
    slab = np.empty((1, 5))
    _cell_slab(net, 0, slab, 0)
    # parallel to the plane, above it, through the box
    o = np.array([-1.0, 1.0, 1.9])
    d = np.array([1.0, 0.0, 0.3]) / np.linalg.norm([1.0, 0.0, 0.3])
    inv = 1.0 / np.where(d == 0, 1e-300, d)
    args = (o[0], o[1], o[2], inv[0], inv[1], inv[2])
    from subtrace.accel.bvh import slab_entry

    assert slab_entry(*args, *box[0], 0.0, np.inf) < np.inf
    assert _cell_entry(*args, d[0], d[1], d[2], box, slab, 0, np.inf) == np.inf
