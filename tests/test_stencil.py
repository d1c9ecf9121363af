"""Isolation of smooth extraordinary patches by fixed linear maps (patches/stencil.py),
checked against the topological isolation it replaces (patches/isolate.py with
``config.STENCIL_ISOLATION`` off: an independent code path, local refinement of the mesh):
the same depths, shells, pieces and cells to rounding; which faces qualify, against a plain
Python walk of each face's corners; the maps' own properties."""

from __future__ import annotations

import numpy as np
import pytest

from subtrace import config
from subtrace.mesh.cage import load_cage
from subtrace.patches import gridmaps
from subtrace.patches.criterion import wanted_depths
from subtrace.patches.isolate import build_isolated, isolated_depths
from subtrace.patches.stencil import (
    MAX_VALENCE, derive_stencil, stencil, stencil_faces,
)
from subtrace.patches.table import build_patch_table

from shared_data import MODELS, SHAPES, assert_same_isolation

CAGES = ["spot_control_mesh.obj", "blub_control_mesh.obj", "catmark_pole8.obj",
         "catmark_cubes_semisharp.obj", "catmark_nonquads.obj", "catmark_gregory_test4.obj"]


def _irregular(name):
    path = MODELS / name if (MODELS / name).exists() else SHAPES / name
    table = build_patch_table([load_cage(str(path))])
    return table, table.objects[0], np.nonzero(table.is_quad & ~table.regular)[0]


def _isolate(o, faces, cap, eye, tol, stencils):
    # (the grid maps off: what the stencils leave goes through topology on both paths)
    old, old_grid = config.STENCIL_ISOLATION, gridmaps.ENABLED
    config.STENCIL_ISOLATION = stencils
    gridmaps.ENABLED = False
    try:
        boxes = (np.full((len(faces), 3), np.inf), np.full((len(faces), 3), -np.inf))
        record = {}
        depths = isolated_depths(o, faces, cap, eye, tol, record, 0, boxes)
        return depths, boxes, build_isolated(o, faces, depths, eye, tol, record, ring=True)
    finally:
        config.STENCIL_ISOLATION, gridmaps.ENABLED = old, old_grid


@pytest.mark.parametrize("name", CAGES)
def test_maps_isolate_as_the_mesh_does(name):
    table, o, sel = _irregular(name)
    assert stencil_faces(o.level, o.cage.options, table.face[sel])[0].any()
    lo, hi = table.shell_min.min(axis=0), table.shell_max.max(axis=0)
    eye = lo + 3.0 * (hi - lo) + np.array([0.1, 0.2, 0.3])
    tol = np.radians(30.0) / 720
    cap = np.clip(wanted_depths(table, eye, tol)[sel], 0, 9).astype(np.int64)
    faces = table.face[sel]
    d0, b0, out0 = _isolate(o, faces, cap, eye, tol, False)
    d1, b1, out1 = _isolate(o, faces, cap, eye, tol, True)
    assert d1.max() >= 3  # deep enough for the maps to be used
    assert_same_isolation((d0, b0, out0), (d1, b1, out1), float(np.abs(o.points).max()),
                          ring_rtol=1e-12)


def _qualifies(level, f):
    """A plain walk: (ok, corner, valence) of face f (stencil_faces' rule)."""
    fo, fv = level.face_offsets, level.face_verts
    if fo[f + 1] - fo[f] != 4:
        return False, 0, 0
    ev = []
    for k in range(4):
        v = int(fv[fo[f] + k])
        faces = level.vert_faces[level.vert_face_offsets[v]:level.vert_face_offsets[v + 1]]
        edges = level.vert_edges[level.vert_edge_offsets[v]:level.vert_edge_offsets[v + 1]]
        if not level.vert_manifold[v] or len(edges) != len(faces) or level.vert_sharpness[v]:
            return False, 0, 0
        if any(level.edge_sharpness[e] != 0 for e in edges):
            return False, 0, 0
        if any(fo[g + 1] - fo[g] != 4 or level.face_hole[g] for g in faces):
            return False, 0, 0
        if len(faces) != 4:
            ev.append((k, len(faces)))
    if len(ev) != 1 or not 3 <= ev[0][1] <= MAX_VALENCE:
        return False, 0, 0
    return True, ev[0][0], ev[0][1]


@pytest.mark.parametrize("name", CAGES)
def test_the_faces_that_qualify(name):
    table, o, _ = _irregular(name)
    for level in (o.cage.level_topology(0), o.level):
        faces = np.arange(level.n_faces)
        ok, corner, valence = stencil_faces(level, o.cage.options, faces)
        want = [_qualifies(level, f) for f in faces]
        np.testing.assert_array_equal(ok, [w[0] for w in want])
        np.testing.assert_array_equal(corner[ok], [w[1] for w in want if w[0]])
        np.testing.assert_array_equal(valence[ok], [w[2] for w in want if w[0]])


@pytest.mark.parametrize("n", [3, 5, 6, 8])
def test_the_maps_are_affine_and_stored_as_derived(n):
    s = derive_stencil(n)
    K = 2 * n + 8
    assert s.ring.shape == (K, K) and s.grids.shape == (4, 3, 16, K)
    for m in (s.ring, s.grids.reshape(-1, K), s.P):  # points: weights summing to 1
        np.testing.assert_allclose(m.sum(axis=-1), 1.0, atol=1e-14)
    for m in (s.du, s.dv):  # tangents: to 0
        np.testing.assert_allclose(m.sum(axis=-1), 0.0, atol=1e-13)
    assert (s.ring >= -1e-15).all() and (s.P >= -1e-15).all()  # convex combinations
    # the child's ring shrinks: its extraordinary point is the parent's limit, fixed
    np.testing.assert_allclose(s.ring[0] @ np.linalg.matrix_power(s.ring, 40),
                               s.P[0] @ np.linalg.matrix_power(s.ring, 40), atol=1e-12)
    loaded = stencil(n)
    for name in ("ring", "grids", "kids", "P", "du", "dv", "edges", "own", "first"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(s, name))
