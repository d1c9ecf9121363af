"""The per-ray Bezier descent's bounds (``geometry/bezier.py``): a cell's box cut by its slab
must let through every ray that meets the cell's surface or its two micro-triangles, and a
block's frame must keep every cell whose triangles a ray meets."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from subtrace import config
from subtrace.patches.basis import bez_point, net_box, split_net
from subtrace.geometry.bezier import (
    LOCATE_PAD, _block_cells, _cell_entry, _cell_slab, _interpolation_bound,
)
from subtrace.geometry.prims import ray_triangle, shear


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


def _wavy_net(rng, scale):
    """A wavy random bicubic net (4,4,3), away from the origin, ``scale`` in size."""
    g = np.stack(np.meshgrid(np.arange(4.0), np.arange(4.0), indexing="ij"), -1)
    root = np.concatenate([g, rng.normal(0, 0.7, (4, 4, 1))], -1) + rng.normal(0, 0.2, (4, 4, 3))
    return (root + rng.normal(0, 5, 3)) * scale


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 6), st.sampled_from([1e-3, 1.0, 1e3]))
def test_cell_slab_lets_through_rays_that_meet_the_cell(seed, depth, scale):
    rng = np.random.default_rng(seed)
    root = _wavy_net(rng, scale)
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


def _frame_of_block(root, pd, bi, bj):
    """(corners, bound) of the frame of block (bi, bj) of level pd - 1 of ``root``, as the
    descent makes it: a root block's own net, else the corners of its net as its parent's
    split makes them and the parent's bound over a quarter."""
    if pd == 1:
        net, side = root[None], 1.0
        corners = net[0]
    else:
        net, side = _sub_net(root, pd - 2, bi >> 1, bj >> 1), 0.5
        work = np.empty((8, 4, 4, 3))
        split_net(net, 0, work, 4)
        corners = work[4 + (bi & 1) + 2 * (bj & 1)]
    return ([tuple(corners[a, b]) for a, b in ((0, 0), (3, 0), (0, 3), (3, 3))],
            _interpolation_bound(net, 0, side))


def _cells_of(frame, o, d, shrink=1.0):
    """``_block_cells`` of the ray (o, d) for a block's ``frame`` (its bound times
    ``shrink``: below 1, a mutation the tests must catch)."""
    kx, ky, kz, sx, sy, _ = shear(*d)
    corners, bound = frame
    pad_o = LOCATE_PAD * float(np.abs(o).max())
    return _block_cells(o[kx], o[ky], o[kz], kx, ky, kz, sx, sy, *corners,
                        shrink * bound + pad_o)


def _meets(o, d, tri):
    """Whether the renderer's ray / triangle test (with its slack) meets triangle ``tri``
    (3,3) along the ray (o, d)."""
    kx, ky, kz, sx, sy, sz = shear(*d)
    t, _, _, _ = ray_triangle(o[kx], o[ky], o[kz], kx, ky, kz, sx, sy, sz, 0, 1, 2, tri,
                              np.inf, config.TRI_SLACK)
    return t < np.inf


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 7), st.sampled_from([1e-3, 1.0, 1e3]),
       st.sampled_from([0.0, 1e4]))
def test_block_frame_keeps_every_cell_a_ray_meets(seed, pd, scale, away):
    """Triangles whose corners are points of a cell's surface, as the renderer evaluates
    them (the cell's corners, and any other points of it, as a fan beside a finer
    neighbour has): every ray that meets one, aimed inside or just beside it, from near
    or far, finds the cell in its block's mask; also with the patch ``away`` times its size
    from the origin (the rounding of large coordinates)."""
    _rays_meet_their_cells(seed, pd, scale, away=away)


def _rays_meet_their_cells(seed, pd, scale, shrink=1.0, away=0.0):
    rng = np.random.default_rng(seed)
    root = _wavy_net(rng, scale) + away * scale * rng.standard_normal(3)
    nets = root[None]
    n = 1 << pd
    bi, bj = (int(x) for x in rng.integers(0, n >> 1, 2))
    frame = _frame_of_block(root, pd, bi, bj)
    met = 0
    for q in range(4):
        a, b = q & 1, q >> 1
        i, j = 2 * bi + a, 2 * bj + b

        def point(du, dv):
            return np.array(bez_point(nets, 0, (i + du) / n, (j + dv) / n))

        corners = [point(0, 0), point(1, 0), point(1, 1), point(0, 1)]
        tris = [np.array([corners[0], corners[1], corners[2]]),
                np.array([corners[0], corners[2], corners[3]])]
        for _ in range(3):  # a fan-like triangle: the centre and two points of the sides
            tris.append(np.array([point(0.5, 0.5), point(*rng.random(2) * [1, 0]),
                                  point(1.0, rng.random())]))
        for tri in tris:
            for w in rng.dirichlet(np.ones(3), 8):
                # inside, or just beyond an edge (within a hair of the slack)
                target = w @ tri
                if rng.random() < 0.3:
                    k = int(rng.integers(3))
                    target = tri[k] + (1 + 10.0 ** rng.uniform(-15, -3)) * (target - tri[k])
                dist = scale * 10.0 ** rng.uniform(-1, 3)
                o = target + rng.normal(0, 1, 3) / np.sqrt(3) * dist
                d = target - o
                d /= np.linalg.norm(d)
                if _meets(o, d, tri):
                    met += 1
                    assert _cells_of(frame, o, d, shrink) >> q & 1
    assert met > 0


def test_block_frame_picks_the_one_cell_a_ray_crosses_on_a_flat_block():
    """On a flat block a ray through the middle of a cell keeps that cell alone (the frame
    costs the descent its four cells' triangles only where the ray passes near them)."""
    g = np.stack(np.meshgrid(np.arange(4.0), np.arange(4.0), indexing="ij"), -1)
    root = np.concatenate([g, (0.3 * g[..., :1] + 0.5 * g[..., 1:])], -1)
    frame = _frame_of_block(root, 1, 0, 0)
    for q in range(4):
        u, v = 0.25 + 0.5 * (q & 1), 0.25 + 0.5 * (q >> 1)
        p = np.array(bez_point(root[None], 0, u, v))
        for d in (np.array([0.2, -0.1, -1.0]), np.array([1.0, 0.3, 0.2]), np.array([-0.4, 1, 0])):
            d = d / np.linalg.norm(d)
            assert _cells_of(frame, p - 5 * d, d) == 1 << q
