"""subtrace.subdiv.topology's jitted relations against the plain oracles of tests/naive.py, on
random face lists that repeat vertices, reuse edges within a face, leave vertices unused and
glue faces non-manifoldly, and on every model and oracle shape."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from shared_data import MODELS, SHAPES

import naive
from subtrace.errors import SubtraceWarning
from subtrace.subdiv.topology import base_edges, build_level

# the ring oracle is plain Python: larger meshes (the sword, the Loop torus) take too long
MAX_FACES = 3000


def _faces(path):
    return sum(line.startswith(b"f ") for line in path.read_bytes().splitlines())


MESHES = [p for p in sorted(MODELS.glob("*.obj")) + sorted(SHAPES.glob("*.obj"))
          if _faces(p) < MAX_FACES]


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
    check_level(len(data.points), offsets, data.face_verts)


def _tags_with_the_kernel(level, boundary, edge_sharp, vert_sharp):
    """What tag_base_level makes of ``level`` tagged with these sharpnesses (per edge, per
    vertex), the tagging kernel always run."""
    from subtrace.subdiv.topology import _tag_kernel

    edge_sharp, vert_sharp = edge_sharp.copy(), vert_sharp.copy()
    face_hole = np.zeros(level.n_faces, bool)
    vert_nonman = ~level.vert_manifold & (np.diff(level.vert_face_offsets) > 0)
    vert_nonman |= np.diff(level.vert_face_offsets) == 0
    _tag_kernel(level.vert_face_offsets, level.vert_faces, level.vert_edge_offsets,
                level.vert_edges, np.diff(level.edge_face_offsets).astype(np.int64),
                level.edge_nonmanifold, vert_nonman, edge_sharp, vert_sharp, face_hole, boundary)
    return edge_sharp, vert_sharp, face_hole, level.vert_manifold & ~vert_nonman


def _untagged_level(n_verts, face_offsets, face_verts):
    edge_verts, face_edges, forward = base_edges(face_offsets, face_verts, n_verts)
    return build_level(n_verts, face_offsets, face_verts, edge_verts, face_edges, forward,
                       np.zeros(len(edge_verts), np.float32), np.zeros(n_verts, np.float32),
                       np.zeros(len(face_offsets) - 1, bool))


def _check_tags(level, seed=0):
    """tag_base_level equals the kernel's tagging in every boundary mode, with crease and
    corner tags on random edges and vertices (boundary ones included)."""
    from subtrace.subdiv.topology import Options, tag_base_level

    rng = np.random.default_rng(seed)
    # (tags name an edge by its two vertices: only edges whose pair is their own)
    pairs = np.sort(level.edge_verts, axis=1)
    _, first, count = np.unique(pairs, axis=0, return_index=True, return_counts=True)
    own = np.zeros(level.n_edges, bool)
    own[first[count == 1]] = True
    creased = np.nonzero((rng.random(level.n_edges) < 0.3) & own)[0]
    cornered = np.nonzero(rng.random(level.n_verts) < 0.3)[0]
    crease_s = rng.choice([0.5, 2.0, 10.0], len(creased)).astype(np.float32)
    corner_s = rng.choice([1.0, 10.0], len(cornered)).astype(np.float32)
    edge_sharp = np.zeros(level.n_edges, np.float32)
    edge_sharp[creased] = crease_s
    vert_sharp = np.zeros(level.n_verts, np.float32)
    vert_sharp[cornered] = corner_s
    for boundary in (0, 1, 2):
        got = tag_base_level(level, Options(boundary=boundary), level.edge_verts[creased],
                             crease_s, cornered, corner_s, np.zeros(0, np.int64))
        want = _tags_with_the_kernel(level, boundary, edge_sharp, vert_sharp)
        for name, array in zip(("edge_sharpness", "vert_sharpness", "face_hole",
                                "vert_manifold"), want):
            assert np.array_equal(getattr(got, name), array), (boundary, name)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mesh=face_lists(), seed=st.integers(0, 2**32 - 1))
def test_tags_without_the_kernel_are_the_kernels(mesh, seed):
    """tag_base_level leaves its kernel out on manifold cages outside boundary mode "none"
    (it sharpens their boundary edges and, in edge-and-corner mode, their one-face corners
    itself): on random face lists, manifold or not, open or closed, with random crease and
    corner tags, in every boundary mode, it gives what the kernel gives."""
    _check_tags(_untagged_level(*mesh), seed)


def test_tags_of_closed_and_open_cages():
    """The same on a closed cube and on the cube with a face removed (its boundary edges
    made infinitely sharp, its corners too in edge-and-corner mode), and the shortcut is
    taken there: the kernel does not run."""
    from unittest import mock

    from subtrace.subdiv import topology

    cube = np.array([[0, 1, 2, 3], [4, 7, 6, 5], [0, 4, 5, 1], [1, 5, 6, 2], [2, 6, 7, 3],
                     [3, 7, 4, 0]], np.int32)
    strip = np.array([[0, 1, 4, 3], [1, 2, 5, 4]], np.int32)  # a corner of one face: 0
    for n_verts, faces in ((8, cube), (8, cube[1:]), (6, strip)):
        offsets = np.arange(0, 4 * len(faces) + 1, 4, dtype=np.int64)
        level = _untagged_level(n_verts, offsets, faces.ravel())
        _check_tags(level)
        with mock.patch.object(topology, "_tag_kernel", side_effect=AssertionError):
            for boundary in (1, 2):
                tagged = topology.tag_base_level(
                    level, topology.Options(boundary=boundary), np.zeros((0, 2), np.int64),
                    np.zeros(0, np.float32), np.zeros(0, np.int64), np.zeros(0, np.float32),
                    np.zeros(0, np.int64))
        assert (tagged.edge_sharpness > 0).any() == (len(faces) < 6)
    # in edge-and-corner mode the strip's one-face corners are sharpened
    tagged = topology.tag_base_level(level, topology.Options(boundary=1),
                                     np.zeros((0, 2), np.int64), np.zeros(0, np.float32),
                                     np.zeros(0, np.int64), np.zeros(0, np.float32),
                                     np.zeros(0, np.int64))
    assert np.count_nonzero(tagged.vert_sharpness) == 4


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mesh=face_lists(), data=st.data())
def test_child_sharpness_without_semi_sharp_edges_is_the_kernels(mesh, data):
    """Refinement leaves its sharpness kernel out when no edge is semi-sharp (every edge 0
    or infinitely sharp): the halves are then what the kernel gives, under either crease
    rule; with a semi-sharp edge the kernel runs."""
    import dataclasses

    from subtrace.subdiv.topology import INF_SHARP
    from subtrace.subdiv.refine import _child_edge_sharpness, _child_edge_sharpness_kernel

    level = _untagged_level(*mesh)
    values = [0.0, float(INF_SHARP), 12.0] + ([1.5] if data.draw(st.booleans()) else [])
    sharp = np.array(data.draw(st.lists(st.sampled_from(values), min_size=level.n_edges,
                                        max_size=level.n_edges)), np.float32)
    level = dataclasses.replace(level, edge_sharpness=sharp)
    for chaikin in (False, True):
        want = np.empty((level.n_edges, 2), np.float32)
        _child_edge_sharpness_kernel(level.edge_verts, sharp, level.vert_edge_offsets,
                                     level.vert_edges, chaikin, want)
        got = _child_edge_sharpness(level, chaikin)
        assert got.dtype == np.float32 and np.array_equal(got, want), chaikin
