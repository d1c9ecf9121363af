"""subtrace.mesh.topology's jitted relations against the plain oracles of tests/naive.py, on
random face lists that repeat vertices, reuse edges within a face, leave vertices unused and
glue faces non-manifoldly, and on every model and oracle shape."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import naive
from subtrace.errors import SubtraceWarning
from subtrace.mesh.topology import base_edges, build_level

SHARED = Path(__file__).resolve().parents[2] / "shared"
MESHES = sorted((SHARED / "models").glob("*.obj")) + sorted((SHARED / "oracle" / "shapes").glob("*.obj"))


def check_level(n_verts, face_offsets, face_verts):
    """base_edges and build_level equal the oracles, arrays bit for bit with their dtypes."""
    edge_verts, face_edges, forward = base_edges(face_offsets, face_verts, n_verts)
    for got, want in zip((edge_verts, face_edges, forward),
                         naive.base_edges(face_offsets, face_verts, n_verts)):
        assert got.dtype == want.dtype and np.array_equal(got, want)
    level = build_level(n_verts, face_offsets, face_verts, edge_verts, face_edges, forward,
                        np.zeros(len(edge_verts), np.float32), np.zeros(n_verts, np.float32),
                        np.zeros(len(face_offsets) - 1, bool))
    want = naive.relations(n_verts, face_offsets, face_verts, edge_verts, face_edges, forward)
    for name, array in want.items():
        got = getattr(level, name)
        assert got.dtype == array.dtype and np.array_equal(got, array), name
    # given the parent's non-manifold edges (as refinement does), they are kept as given
    flags = np.arange(len(edge_verts)) % 3 == 0
    level = build_level(n_verts, face_offsets, face_verts, edge_verts, face_edges, forward,
                        np.zeros(len(edge_verts), np.float32), np.zeros(n_verts, np.float32),
                        np.zeros(len(face_offsets) - 1, bool), edge_nonmanifold=flags.copy())
    want = naive.relations(n_verts, face_offsets, face_verts, edge_verts, face_edges, forward,
                           edge_nonmanifold=flags.copy())
    for name, array in want.items():
        assert np.array_equal(getattr(level, name), array), name


@st.composite
def face_lists(draw):
    """Faces of 3-6 corners over a few vertices: repeats, reused pairs and fans of any kind."""
    n_verts = draw(st.integers(3, 12))
    sizes = draw(st.lists(st.integers(3, 6), min_size=1, max_size=14))
    verts = [draw(st.integers(0, n_verts - 1)) for _ in range(sum(sizes))]
    offsets = np.zeros(len(sizes) + 1, dtype=np.int64)
    np.cumsum(sizes, out=offsets[1:])
    return n_verts + draw(st.integers(0, 2)), offsets, np.array(verts, dtype=np.int32)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mesh=face_lists())
def test_relations_match_the_oracle_on_random_face_lists(mesh):
    check_level(*mesh)


def test_relations_match_the_oracle_on_a_manifold_grid_with_a_hole():
    # a 5x5 grid of quads (boundary rings, valence 2-4), one face removed
    idx = np.arange(36).reshape(6, 6)
    quads = [[idx[i, j], idx[i, j + 1], idx[i + 1, j + 1], idx[i + 1, j]]
             for i in range(5) for j in range(5) if (i, j) != (2, 2)]
    offsets = np.arange(0, 4 * len(quads) + 1, 4, dtype=np.int64)
    check_level(36, offsets, np.array(quads, dtype=np.int32).ravel())


@pytest.mark.parametrize("path", MESHES, ids=lambda p: p.stem)
def test_relations_match_the_oracle_on_models_and_shapes(path):
    from subtrace.io.obj import read_obj

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SubtraceWarning)
        data = read_obj(path)
    offsets = np.zeros(len(data.face_sizes) + 1, dtype=np.int64)
    np.cumsum(data.face_sizes, out=offsets[1:])
    if len(offsets) > 3000:
        pytest.skip("the ring oracle is plain Python: large meshes take too long")
    check_level(len(data.points), offsets, data.face_verts)
