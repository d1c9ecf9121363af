"""subdiv/gridrefine.py: one level of a 4x4 grid's refinement under any sharpness pattern
against subtrace's own topological refinement (subdiv/refine.py) of the 3x3 quads the grid
spans: the inner 5x5 points of the child lattice to rounding (float32's where a vertex
blends two rules by the mean of its edges' sharpness, float64's elsewhere), and the
sharpness of the children's edges and corners exactly."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from subtrace.subdiv.gridrefine import CHILD_AT, CORNERS, refine_grids
from subtrace.subdiv.refine import refine_level, refine_points
from subtrace.subdiv.topology import INF_SHARP, Options, cage_level


def _grid_cage(sharp, corner_sharp, rng):
    """A 3x3-quad cage over a jittered grid (point (i, j) = vertex 4 i + j), its 24 edges'
    sharpness ``sharp`` in gridrefine's order and its inner corners' ``corner_sharp``."""
    pts = np.array([[i, j, 0.0] for i in range(4) for j in range(4)])
    pts += rng.normal(scale=0.2, size=pts.shape)
    faces = [[4 * i + j, 4 * (i + 1) + j, 4 * (i + 1) + j + 1, 4 * i + j + 1]
             for i in range(3) for j in range(3)]
    edges = [(4 * i + j, 4 * (i + 1) + j) for i in range(3) for j in range(4)]
    edges += [(4 * i + j, 4 * i + j + 1) for i in range(4) for j in range(3)]
    corners = [4 * i + j for i, j in CORNERS]
    offsets = np.arange(0, 37, 4, dtype=np.int64)
    tags = (np.array(edges, np.int64), np.asarray(sharp, np.float32),
            np.array(corners, np.int64), np.asarray(corner_sharp, np.float32),
            np.zeros(0, np.int64))
    level = cage_level(16, offsets, np.array(faces, np.int32).ravel(), Options(), tags)
    return level, pts


def _lattice_ids(level):
    """The child vertex of each inner lattice point (a, b), 1 <= a, b <= 5, of a grid cage
    refined once (vertex points first, then face points, then edge points)."""
    n_v, n_f = level.n_verts, level.n_faces
    ev = level.edge_verts.astype(np.int64)
    edge_of = {(min(a, b), max(a, b)): e for e, (a, b) in enumerate(ev)}
    ids = np.full((7, 7), -1, np.int64)
    for a in range(1, 6):
        for b in range(1, 6):
            i, j = a // 2, b // 2
            if a % 2 == 0 and b % 2 == 0:
                ids[a, b] = 4 * i + j
            elif a % 2 == 1 and b % 2 == 1:
                ids[a, b] = n_v + 3 * i + j
            elif a % 2 == 1:
                ids[a, b] = n_v + n_f + edge_of[(4 * i + j, 4 * (i + 1) + j)]
            else:
                ids[a, b] = n_v + n_f + edge_of[(4 * i + j, 4 * i + j + 1)]
    return ids


SHARPNESS = st.sampled_from([0.0, 0.0, 0.0, 0.3, 0.7, 1.0, 1.5, 2.0, 6.0, 6.9, 7.2, 8.0])


@settings(max_examples=60, deadline=None)
@given(sharp=st.lists(SHARPNESS, min_size=24, max_size=24),
       corner=st.lists(st.sampled_from([0.0, 0.0, 0.0, 0.5, 2.5]), min_size=4, max_size=4),
       seed=st.integers(0, 2**31 - 1))
def test_a_grid_refines_as_the_topology_does(sharp, corner, seed):
    rng = np.random.default_rng(seed)
    level, pts = _grid_cage(sharp, corner, rng)
    ref = refine_level(level, Options())
    child_pts = refine_points(ref, pts)
    ids = _lattice_ids(level)
    es = level.edge_sharpness  # (after the cage's own sharpening: its boundary edges)
    ev = level.edge_verts.astype(np.int64)
    edge_of = {(min(a, b), max(a, b)): e for e, (a, b) in enumerate(ev)}
    grid_es = np.array([es[edge_of[(4 * i + j, 4 * (i + 1) + j)]] for i in range(3)
                        for j in range(4)]
                       + [es[edge_of[(4 * i + j, 4 * i + j + 1)]] for i in range(4)
                          for j in range(3)], np.float32)
    vs = np.array([level.vert_sharpness[4 * i + j] for i, j in CORNERS], np.float32)
    out_P = np.empty((1, 4, 16, 3))
    out_es = np.empty((1, 4, 24), np.float32)
    out_vs = np.empty((1, 4, 4), np.float32)
    refine_grids(pts[None], grid_es[None], vs[None], out_P, out_es, out_vs)
    child = ref.child
    cev = child.edge_verts.astype(np.int64)
    child_edge = {(min(a, b), max(a, b)): e for e, (a, b) in enumerate(cev)}
    scale = np.abs(pts).max()
    # the vertex points (even rows and columns of the lattice) to float32's rounding: the
    # fractional weight between a vertex's two rules is a float32 mean of its edges'
    # sharpness (as OpenSubdiv's is), summed in the order each visits the edges; the
    # other points to float64's
    a, b = np.meshgrid(np.arange(4), np.arange(4), indexing="ij")
    for q in range(4):
        a0, b0 = CHILD_AT[q]
        want = child_pts[ids[a0:a0 + 4, b0:b0 + 4].ravel()]
        vertex = (((a0 + a) % 2 == 0) & ((b0 + b) % 2 == 0)).ravel()
        err = np.abs(out_P[0, q] - want).max(axis=1)
        assert err[~vertex].max() <= 1e-14 * scale
        assert err[vertex].max() <= 1e-6 * scale
        win = ids[a0:a0 + 4, b0:b0 + 4]
        want_es = [child.edge_sharpness[child_edge[(min(win[i, j], win[i + 1, j]),
                                                    max(win[i, j], win[i + 1, j]))]]
                   for i in range(3) for j in range(4)]
        want_es += [child.edge_sharpness[child_edge[(min(win[i, j], win[i, j + 1]),
                                                     max(win[i, j], win[i, j + 1]))]]
                    for i in range(4) for j in range(3)]
        assert out_es[0, q].tolist() == np.asarray(want_es, np.float32).tolist()
        want_vs = [child.vert_sharpness[win[i, j]] for i, j in CORNERS]
        assert out_vs[0, q].tolist() == np.asarray(want_vs, np.float32).tolist()


def test_an_infinitely_sharp_line_stays_a_polyline():
    """A grid line of infinitely sharp edges through the patch: its children's points on
    it are the crease curve's (midpoints and the (1, 6, 1) / 8 rule), exactly."""
    sharp = np.zeros(24, np.float32)
    sharp[[12 + 3 * 1 + j for j in range(3)]] = INF_SHARP  # V(1, j): the line i = 1
    level, pts = _grid_cage(sharp, np.zeros(4), np.random.default_rng(3))
    out_P = np.empty((1, 4, 16, 3))
    refine_grids(pts[None], sharp[None], np.zeros((1, 4), np.float32), out_P,
                 np.empty((1, 4, 24), np.float32), np.empty((1, 4, 4), np.float32))
    # child 0's grid point (1, 1) is the vertex point of grid point (1, 1), on the line
    want = 0.75 * pts[5] + 0.125 * (pts[4] + pts[6])
    assert np.abs(out_P[0, 0, 5] - want).max() < 1e-15 * np.abs(pts).max()
    # and its (1, 2) the line's midpoint of grid points (1, 1) and (1, 2)
    assert np.abs(out_P[0, 0, 6] - 0.5 * (pts[5] + pts[6])).max() < 1e-15 * np.abs(pts).max()


@pytest.mark.parametrize("s", [0.0, 0.5])
def test_smooth_grids_refine_uniformly(s):
    """Without sharpness (or a fractional one that blends), the children's sharpness is 0."""
    sharp = np.full(24, s, np.float32)
    level, pts = _grid_cage(sharp, np.zeros(4), np.random.default_rng(5))
    out_es = np.empty((1, 4, 24), np.float32)
    refine_grids(pts[None], sharp[None], np.zeros((1, 4), np.float32),
                 np.empty((1, 4, 16, 3)), out_es, np.empty((1, 4, 4), np.float32))
    assert (out_es == 0).all()
