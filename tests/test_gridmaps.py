"""Isolation of patches under any crease pattern at valence-4 corners by their control grids
alone (patches/gridmaps.py), checked against the topological isolation it replaces
(patches/isolate.py with ``gridmaps.ENABLED`` off: local refinement of the mesh, an
independent code path) and against OpenSubdiv's limit surface (the oracle's exact samples):
the same depths, shells, pieces and cells to rounding, at the root (crease ends and
junctions) and below it (beside extraordinary vertices), on fractional and integer
sharpness; which faces qualify, against a plain walk of each face's corners; chunks and
threads change nothing."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest
from shared_data import SHAPES, assert_same_isolation, lathe_cage
from test_crease import HARD, oracle_distances, same_in_chunks_and_threads, torus_obj

import subtrace
from subtrace.patches import gridmaps, isolate
from subtrace.patches.criterion import wanted_depths
from subtrace.patches.grids import unit_normals
from subtrace.patches.isolate import build_isolated, isolated_depths
from subtrace.patches.table import build_patch_table
from subtrace.subdiv.topology import INF_SHARP


@pytest.fixture(scope="module")
def cages(tmp_path_factory):
    folder = tmp_path_factory.mktemp("gridmaps")
    out = {name: torus_obj(folder / f"{name}.obj", name) for name in ("ends", "rings")}
    out["lathe"] = lathe_cage(folder / "lathe.obj")
    return out


def _cage(name, cages):
    return subtrace.load_cage(cages[name] if name in cages else HARD / name)


def _isolate(o, faces, cap, eye, tol, maps, monkeypatch):
    """Depths, boxes and pieces of ``faces`` with the grid maps on or off; the levels the
    maps started at."""
    starts = []
    real = gridmaps.grid_pieces

    def counted(*args, **kw):
        starts.append(args[10] if len(args) > 10 else kw.get("k0", 0))
        return real(*args, **kw)

    monkeypatch.setattr(gridmaps, "ENABLED", maps)
    monkeypatch.setattr(isolate, "grid_pieces", counted)
    boxes = (np.full((len(faces), 3), np.inf), np.full((len(faces), 3), -np.inf))
    record = {}
    depths = isolated_depths(o, faces, cap, eye, tol, record, 0, boxes)
    out = build_isolated(o, faces, depths, eye, tol, record, ring=True)
    monkeypatch.setattr(gridmaps, "ENABLED", True)
    return depths, boxes, out, starts


def _compare(o, faces, cap, eye, tol, monkeypatch):
    """Both paths on ``faces``: the same depths, boxes, pieces and cells to rounding (a
    vertex blending two rules takes the mean of its edges' sharpness in float32, summed in
    another order than the topology's: float32 rounding of that weight, 1e-7 of the
    scale); returns the levels the maps started at and the counts."""
    d0, b0, out0, none = _isolate(o, faces, cap, eye, tol, False, monkeypatch)
    d1, b1, out1, starts = _isolate(o, faces, cap, eye, tol, True, monkeypatch)
    assert not none
    pieces, cells = assert_same_isolation((d0, b0, out0), (d1, b1, out1),
                                          float(np.abs(o.points).max()), atol=1e-7,
                                          normal_atol=1e-6)
    return starts, pieces, cells


CAGES = ["catmark_pawn.obj", "catmark_helmet.obj", "catmark_car.obj", "catmark_rook.obj",
         "ends", "lathe"]


@pytest.mark.parametrize("far", [1.5, 8.0], ids=["near", "far"])
@pytest.mark.parametrize("name", CAGES)
def test_maps_isolate_as_the_mesh_does(name, far, cages, monkeypatch):
    """From near (deep: every crease runs out) and far (shallow: cells left at crease ends
    and junctions) the grid maps give what topology gives, at the root and below it."""
    cage = _cage(name, cages)
    table = build_patch_table([cage])
    o = table.objects[0]
    sel = np.nonzero(table.is_quad & ~table.regular)[0]
    lo, hi = table.shell_min.min(axis=0), table.shell_max.max(axis=0)
    eye = lo + far * (hi - lo) + np.array([0.1, 0.2, 0.3])
    tol = np.radians(30.0) / 720
    cap = np.clip(wanted_depths(table, eye, tol)[sel], 0, 9).astype(np.int64)
    starts, pieces, cells = _compare(o, table.face[sel], cap, eye, tol, monkeypatch)
    assert pieces > 0 and (cells > 0 or far < 2)
    # the maps serve the crease ends and junctions at the root, and on the hard-surface
    # cages the frontier beside extraordinary vertices below it
    assert (0 in starts) == (name != "catmark_pawn.obj" and name != "catmark_helmet.obj")
    if name in ("catmark_rook.obj", "lathe"):
        assert max(starts) > 0


@pytest.mark.parametrize("depth", [0, 1, 3])
def test_at_the_cages_level(depth, cages, monkeypatch):
    """The cage's own quads of the torus whose rings end and cross (as if they were the
    patch level): the quads at the ends and junctions are the grid maps'."""
    cage = _cage("ends", cages)
    o = SimpleNamespace(cage=cage, level=cage.base, points=cage.points)
    faces = np.arange(cage.base.n_faces)
    irregular = ~subtrace.patches.bspline.regular_mask(cage.base, cage.options, faces)
    faces = faces[irregular]
    assert gridmaps.grid_faces(cage.base, cage.options, faces)[0].any()
    lo, hi = cage.points.min(axis=0), cage.points.max(axis=0)
    _, pieces, cells = _compare(o, faces, np.full(len(faces), depth), lo + 1.5 * (hi - lo),
                                np.radians(30.0) / 720, monkeypatch)
    assert (pieces > 0) == (depth > 0)
    assert cells > 0


def _walk(level, f):
    """(ok, es, vs) of face f by a plain walk (grid_faces' rule), es in gridrefine's
    layout (the corners' edges: +u, +v, -u, -v of each grid position)."""
    fo, fv = level.face_offsets, level.face_verts
    corners = fv[fo[f]:fo[f + 1]]
    es, vs = np.zeros(24, np.float32), np.zeros(4, np.float32)
    if len(corners) != 4:
        return False, es, vs
    semi = False
    for v in corners:
        faces = level.vert_faces[level.vert_face_offsets[v]:level.vert_face_offsets[v + 1]]
        edges = level.vert_edges[level.vert_edge_offsets[v]:level.vert_edge_offsets[v + 1]]
        if (not level.vert_manifold[v] or len(faces) != 4 or len(edges) != 4
                or level.vert_sharpness[v] >= INF_SHARP):
            return False, es, vs
        if any(fo[g + 1] - fo[g] != 4 or level.face_hole[g] for g in faces):
            return False, es, vs
        s = level.edge_sharpness[edges]
        if (s >= INF_SHARP).any():
            return False, es, vs
        semi |= bool((s > 0).any() or level.vert_sharpness[v] > 0)
    if not semi:
        return False, es, vs
    grid = subtrace.patches.bspline.control_grids(level, np.array([f]))[0]
    edge_of = {tuple(sorted(map(int, e))): k for k, e in enumerate(level.edge_verts)}
    for q, (i, j) in enumerate(gridmaps.CORNERS):
        vs[q] = level.vert_sharpness[grid[i, j]]
        for row, (a, b) in zip(gridmaps.CORNER_EDGES[q], ((i + 1, j), (i, j + 1), (i - 1, j),
                                                          (i, j - 1))):
            es[row] = level.edge_sharpness[edge_of[tuple(sorted((int(grid[i, j]),
                                                                 int(grid[a, b]))))]]
    return True, es, vs


@pytest.mark.parametrize("name", ["catmark_car.obj", "catmark_helmet.obj", "ends", "lathe"])
def test_the_faces_that_qualify(name, cages):
    cage = _cage(name, cages)
    level = cage.base
    faces = np.arange(level.n_faces)
    ok, es, vs = gridmaps.grid_faces(level, cage.options, faces)
    assert ok.any()
    for f in faces:
        want_ok, want_es, want_vs = _walk(level, int(f))
        assert ok[f] == want_ok, f
        if want_ok:
            np.testing.assert_array_equal(es[f], want_es)
            np.testing.assert_array_equal(vs[f], want_vs)


def test_chaikin_cages_go_through_topology():
    cage = subtrace.load_cage(HARD / "catmark_chaikin1.obj")
    faces = np.arange(cage.base.n_faces)
    assert not gridmaps.grid_faces(cage.base, cage.options, faces)[0].any()


@pytest.mark.parametrize("name", ["catmark_tent_creases0", "catmark_chaikin0",
                                  "catmark_dart_edgeonly"])
def test_the_pieces_are_opensubdivs_limit_surface(name, monkeypatch):
    """The pieces with the grid maps, evaluated at the oracle's exact samples on the
    patches they cover, give OpenSubdiv's limit points."""
    z = np.load(SHAPES.parent / f"{name}.npz")
    meta = json.loads(str(z["meta"]))
    cage = subtrace.load_cage(SHAPES / f"{name}.obj", scheme=meta["scheme"])
    table = build_patch_table([cage])
    o = table.objects[0]
    sel = np.nonzero(~table.regular)[0]
    starts = []
    real = gridmaps.grid_pieces
    monkeypatch.setattr(isolate, "grid_pieces",
                        lambda *a, **k: starts.append(a[10]) or real(*a, **k))
    (root, level, i0, j0, nets, *_), _ = build_isolated(o, table.face[sel], 9)
    assert starts  # the grid maps took part
    checked, worst = oracle_distances(table, sel, root, level, i0, j0, nets, z)
    assert checked > 30
    assert worst <= 1e-7 * meta["bbox_diag"]


@pytest.mark.parametrize("name", ["catmark_car.obj", "lathe"])
def test_the_kernels_chunks_and_threads_change_nothing(name, cages, monkeypatch):
    """Depths, boxes, pieces and cells are the same bit for bit in one call on one thread
    and in chunks of three squares on two."""
    same_in_chunks_and_threads(_cage(name, cages), gridmaps, _isolate, monkeypatch)


@pytest.mark.parametrize("name", ["catmark_car.obj", "catmark_helmet.obj", "catmark_rook.obj",
                                  "ends", "lathe"])
def test_hard_vertices_limits_by_their_rings(name, cages, monkeypatch):
    """The limits of the semi-sharp vertices with quads around by their rings
    (subdiv/limit.py's grid path) against one-ring cuts refined through topology: the same
    points to rounding, the same unit normals, on the cage and one level down."""
    from subtrace.subdiv import limit

    cage = _cage(name, cages)
    for level in (0, 1):
        lev, pts = cage.level_topology(level), cage.refine(level).points
        cls = limit.classify(lev, cage.options)
        hard = np.nonzero(cls == limit.HARD_SHARP)[0]
        assert len(hard)
        taken = limit._grid_limits(lev, np.ascontiguousarray(pts, np.float64), hard,
                                   *(np.zeros((len(hard), 3)) for _ in range(3)),
                                   np.arange(len(hard)))
        assert taken.mean() > 0.5
        got = limit.limit_points(lev, pts, cage.options, which=hard)
        monkeypatch.setattr(limit, "GRID_LIMITS", False)
        ref = limit.limit_points(lev, pts, cage.options, which=hard)
        monkeypatch.setattr(limit, "GRID_LIMITS", True)
        scale = float(np.abs(pts).max())
        np.testing.assert_allclose(got[0], ref[0], rtol=0, atol=1e-7 * scale)
        for a, b in ((got[1], ref[1]), (got[2], ref[2])):  # along the same edges
            cos = (a * b).sum(axis=1) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1)
            assert cos.min() > 1 - 1e-9
        np.testing.assert_allclose(unit_normals(*got[1:]), unit_normals(*ref[1:]), rtol=0,
                                   atol=1e-6)
