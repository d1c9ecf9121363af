"""Irregular Loop triangles isolated into per-ray pieces and cells (patches/isolate_loop.py,
geometry/tris.py): the pieces and cells are the exact limit surface (the evaluator, checked
against OpenSubdiv) and tile the patch; snapped sides' samples are exact; renders are
watertight from inside creased Loop cages and at an open boundary, build a few
micro-triangles per covered pixel, and never refine a hidden irregular patch."""

from __future__ import annotations

import numpy as np
import pytest
from shared_data import MODELS, SHAPES, small_scene

import subtrace
from subtrace.patches.boxspline import loop_regular
from subtrace.patches.isolate_loop import build_loop_isolated, corner_coords, side_samples
from subtrace.patches.table import build_patch_table
from subtrace.render import render_scene
from subtrace.geometry.tris import tri_point

CREASED = ["loop_cube_creases1", "loop_icos_semisharp", "loop_chaikin1"]


def _irregular(name, n=12):
    cage = subtrace.load_cage(SHAPES / f"{name}.obj")
    table = build_patch_table([cage])
    o = table.objects[0]
    ids = np.nonzero(~loop_regular(o.level, cage.options, table.face))[0][:n]
    assert len(ids)
    return cage, table, o, ids


def _patch_uv(table, ids, st):
    """ptex (face, uv) of patch parameters ``st`` (m,2) on patches ``ids`` (m,)."""
    return table.ptex[ids], table.ptex_uv0[ids] + table.ptex_scale[ids, None] * st


@pytest.mark.parametrize("name", CREASED + ["loop_saddle_edgecorner", "loop_pole8"])
def test_pieces_and_cells_are_the_limit_surface_and_tile_the_patch(name):
    """Every piece's net at random (s, t) and every cell's corners equal the exact evaluator
    at the same patch parameter (1e-12 of the cage's size: two different linear maps of the
    cage points, each exact to rounding); the pieces and cells cover the patch's area once
    (areas 4^-level add up to 1, every corner inside the patch)."""
    cage, table, o, ids = _irregular(name)
    depth = 4
    (sr, sl, si, sj, sg, nets), (cr, ci, cj, cg, cp, _) = build_loop_isolated(
        o, table.face[ids], depth)
    size = np.abs(cage.points).max()
    rng = np.random.default_rng(7)
    st = rng.random((len(sr), 2))
    st[st.sum(axis=1) > 1] = 1 - st[st.sum(axis=1) > 1]
    mine = np.array([tri_point(nets, k, st[k, 0], st[k, 1]) for k in range(len(sr))])
    scale = 0.5 ** sl
    patch_st = (np.stack([si, sj], axis=1) + sg[:, None] * st) * scale[:, None]
    P = cage.evaluate(*_patch_uv(table, ids[sr], patch_st))[0]
    assert np.abs(mine - P).max() <= 1e-12 * size
    corners = corner_coords(np.full(len(cr), depth), ci, cj, cg, depth) / float(1 << depth)
    P = cage.evaluate(*_patch_uv(table, np.repeat(ids[cr], 3), corners.reshape(-1, 2)))[0]
    assert np.abs(cp.reshape(-1, 3) - P).max() <= 1e-12 * size
    # a tiling of each patch
    area = np.bincount(np.r_[sr, cr], np.r_[4.0 ** -sl, np.full(len(cr), 4.0 ** -depth)],
                       minlength=len(ids))
    assert np.allclose(area, 1.0, rtol=0, atol=1e-12)
    allc = np.concatenate([corner_coords(sl, si, sj, sg, depth),
                           corner_coords(np.full(len(cr), depth), ci, cj, cg, depth)])
    assert allc.min() >= 0 and allc.sum(axis=2).max() <= 1 << depth
    # pieces are what stays regular: more of them than cells, cells only at the features
    assert len(cr) < len(sr)


def test_snapped_sides_are_exact_samples_and_cells_lie_on_the_polyline():
    """A side sampled at a coarser depth gets its samples from the exact surface, and the
    cells' corners on it move onto the straight segments between them."""
    cage, table, o, ids = _irregular("loop_icos_semisharp", n=6)
    depth = np.full(len(ids), 4)
    subs, cells = build_loop_isolated(o, table.face[ids], depth)
    side = np.tile([1, -1, 4], (len(ids), 1))  # side 0 at depth 1, 1 unshared, 2 unsnapped
    exact = cells[4].copy()
    samples, offset = side_samples(depth, side, subs, cells)
    assert np.all(offset == 3 * np.arange(len(ids)))
    st = np.array([[0.0, 0.0], [0.5, 0.0], [1.0, 0.0]])
    P = cage.evaluate(*_patch_uv(table, np.repeat(ids, 3), np.tile(st, (len(ids), 1))))[0]
    size = np.abs(cage.points).max()
    assert np.abs(samples - P).max() <= 1e-12 * size
    c = corner_coords(np.full(len(cells[0]), 4), cells[1], cells[2], cells[3], 4)
    on0 = c[..., 1] == 0
    assert on0.any()
    t = c[..., 0][on0] / 16.0
    root = np.broadcast_to(cells[0][:, None], on0.shape)[on0]
    a = samples[3 * root + (t > 0.5)]
    b = samples[3 * root + (t > 0.5) + 1]
    w = (2 * t - (t > 0.5))[:, None]
    assert np.abs(cells[4][on0] - ((1 - w) * a + w * b)).max() <= 1e-12 * size
    assert np.array_equal(cells[4][~on0], exact[~on0])


@pytest.mark.parametrize("tolerance", [4.0, 1.0, 0.25])
@pytest.mark.parametrize("name", CREASED)
def test_watertight_from_inside_creased_loop_cages(name, tolerance, monkeypatch):
    """Invariant 4 inside closed Loop cages whose triangles are nearly all irregular:
    extraordinary vertices, infinitely sharp and semi-sharp creases (Chaikin too)."""
    from shared_data import check_watertight

    check_watertight(SHAPES / f"{name}.obj", None, tolerance, monkeypatch)


def _open_box(path):
    """A triangulated box [-1,1] x [-0.5,0.5] x [0,1], 4 quads a unit, open at z = 0 (a
    boundary), its four vertical edges infinitely sharp creases and one corner a sharp
    corner: irregular boundary, crease and corner patches beside regular ones."""
    n = 4
    ids, lines, faces = {}, [], []

    def vid(p):
        if p not in ids:
            ids[p] = len(ids)
            lines.append("v {} {} {}".format(*(np.array(p) / n - [1.0, 0.5, 0.0])))
        return ids[p] + 1

    X, Y, Z = 2 * n, n, n
    # (origin, axes a and b, counts, outward normal): faces wound consistently (a x b
    # outward), so every edge is manifold
    walls = [((0, 0, 0), (0, 0, 1), (0, 1, 0), Z, Y), ((X, 0, 0), (0, 1, 0), (0, 0, 1), Y, Z),
             ((0, 0, 0), (1, 0, 0), (0, 0, 1), X, Z), ((0, Y, 0), (0, 0, 1), (1, 0, 0), Z, X),
             ((0, 0, Z), (1, 0, 0), (0, 1, 0), X, Y)]
    for o, a, b, na, nb in walls:
        o, a, b = np.array(o), np.array(a), np.array(b)
        for i in range(na):
            for j in range(nb):
                q = [tuple(int(x) for x in o + a * (i + di) + b * (j + dj)) for di, dj in
                     ((0, 0), (1, 0), (1, 1), (0, 1))]
                v = [vid(p) for p in q]
                faces += [f"f {v[0]} {v[1]} {v[2]}", f"f {v[0]} {v[2]} {v[3]}"]
    tags = []
    for x in (0, X):
        for y in (0, Y):
            for z in range(Z):
                tags.append(f"t crease 2/1/0 {ids[(x, y, z)]} {ids[(x, y, z + 1)]} 10.0")
    tags.append(f"t corner 1/1/0 {ids[(X, Y, Z)]} 10.0")
    path.write_text("\n".join(lines + faces + tags) + "\n")


@pytest.mark.parametrize("tolerance", [4.0, 1.0, 0.25])
def test_watertight_at_an_open_boundary(tmp_path, tolerance):
    """Looking from inside an open Loop box at a wall next to its opening (boundary,
    irregular boundary corners, creases): every ray hits."""
    path = tmp_path / "open_box.obj"
    _open_box(path)
    cage = subtrace.load_cage(path)
    assert cage.scheme == "loop"
    for target in ((-1.0, 0.0, 0.45), (1.0, 0.0, 0.45)):
        eye = (0.75 * target[0], 0.0, 0.45)
        scene = small_scene([path], eye, target, fov=96.0, width=48, height=36,
                            tolerance=tolerance)
        res = render_scene(scene, cages=[cage])
        assert np.count_nonzero(res.channels["A"] == 0) == 0


def test_a_hidden_irregular_loop_object_is_not_refined(tmp_path):
    """Invariant 5 for irregular Loop patches: Spot's Loop cage (extraordinary vertices
    throughout) hidden behind a plane gets no piece, no cell; seen alone, its irregular
    patches are isolated (so the test can fail)."""
    from shared_data import write_plane

    plane = tmp_path / "plane.obj"
    write_plane(plane, 2.0, 8.0)
    spot = MODELS / "spot_low_resolution.obj"
    cages = [subtrace.load_cage(plane), subtrace.load_cage(spot)]
    view = ((0.0, 0.3, 5.0), (0.0, 0.3, 0.0))
    res = render_scene(small_scene([plane, spot], *view, fov=40.0), cages=cages)
    assert np.all(res.channels["object_id"] == 0)
    assert np.count_nonzero(res.refined_objects == 1) == 0
    assert res.stats.pieces == 0  # (the plane's patches are regular: built from the start)
    alone = render_scene(small_scene([spot], *view, fov=40.0), cages=cages[1:])
    assert alone.stats.pixels_covered > 100
    # isolated patches become several pieces or cells each: more than the patches built
    assert alone.stats.pieces > len(alone.refined_objects) > 50


@pytest.mark.parametrize("tolerance", [4.0, 1.0, 0.25])
def test_micro_triangles_per_covered_pixel_on_spot_loop(tolerance):
    """At most 4 micro-triangles per covered pixel on Spot's Loop cage, whose irregular
    triangles were whole grids (about 15 per covered pixel at 1 px, 4^depth each)."""
    mesh = MODELS / "spot_low_resolution.obj"
    scene = small_scene([mesh], (2.424, 1.347, -3.694), (0.008, 0.139, 0.172), width=320,
                        height=180, fov=30.0, tolerance=tolerance)
    st = render_scene(scene, cages=[subtrace.load_cage(mesh)]).stats
    assert st.pixels_covered > 5000
    assert st.micro_triangles <= 4 * st.pixels_covered, st.micro_triangles / st.pixels_covered
