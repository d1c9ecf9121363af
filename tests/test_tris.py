"""Regular Loop patches traced per ray through their quartic Bezier nets (trace/tris.py):
the net's points and normals are the exact limit surface's, the per-ray descent finds the
same micro-triangles as the whole grids it replaces, builds a few per covered pixel, and the
image does not depend on the thread count."""

from __future__ import annotations

import numpy as np
import pytest
from shared_data import MODELS, needs_shared, small_scene

import subtrace
from subtrace import config
from subtrace.lines.items import box_nets, loop_regular
from subtrace.patches.table import build_patch_table
from subtrace.render import render_scene
from subtrace.trace.tris import tri_normal, tri_point

TORUS_VIEW = ((1.226, 4.085, 4.902), (0.0, 0.0, 0.0))  # scenes/torus_loop.toml's camera
SPOT_VIEW = ((2.0, 0.8, 2.4), (0.0, 0.1, 0.2))


@needs_shared
@pytest.mark.parametrize("mesh", ["torus.obj", "spot_low_resolution.obj"])
def test_net_points_and_normals_are_the_limit_surface(mesh):
    """tri_point / tri_normal on a regular triangle's net equal the exact evaluator
    (OpenSubdiv-checked) at random parameters, to rounding (1e-12 of the model's size: the
    net is a 15x12 linear map of the cage points, the evaluator another)."""
    cage = subtrace.load_cage(MODELS / mesh)
    table = build_patch_table([cage])
    o = table.objects[0]
    faces = table.face[:len(o.patch_faces)]
    reg = np.nonzero(loop_regular(o.level, cage.options, faces))[0][:40]
    assert len(reg) > 10
    nets = box_nets(o.level, o.points, faces[reg])
    rng = np.random.default_rng(3)
    st = rng.random((len(reg), 2))
    st[st.sum(axis=1) > 1] = 1 - st[st.sum(axis=1) > 1]  # inside the triangle
    mine = np.array([tri_point(nets, k, st[k, 0], st[k, 1]) for k in range(len(reg))])
    nrm = np.array([tri_normal(nets, k, st[k, 0], st[k, 1]) for k in range(len(reg))])
    uv = table.ptex_uv0[reg] + table.ptex_scale[reg, None] * st
    P, du, dv = cage.evaluate(table.ptex[reg], uv)
    size = np.abs(cage.points).max()
    assert np.abs(mine - P).max() <= 1e-12 * size
    n = np.cross(du, dv)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    assert np.all(np.sum(n * nrm, axis=1) > 1 - 1e-9)


def _torus(tolerance, width=160, height=90, threads=None):
    mesh = MODELS / "torus.obj"
    scene = small_scene([mesh], *TORUS_VIEW, width=width, height=height, fov=30.0,
                        tolerance=tolerance)
    return render_scene(scene, cages=[subtrace.load_cage(mesh)], threads=threads)


@needs_shared
@pytest.mark.parametrize("tolerance", [4.0, 1.0, 0.25])
def test_per_ray_nets_hit_the_grids_micro_triangles(tolerance, monkeypatch):
    """The per-ray descent meets the same micro-triangles as the whole grids of exact limit
    points (same depths, same corners up to rounding): the same pixels are covered, at
    the same distances (stored as float32: the corners' rounding, 1e-16 relative, is far
    below it), with the same ptex (u, v) and level; and it builds a few micro-triangles
    per covered pixel where the grids build hundreds at 0.25 px."""
    monkeypatch.setattr(config, "LOOP_PER_RAY", False)
    old = _torus(tolerance)
    monkeypatch.setattr(config, "LOOP_PER_RAY", True)
    new = _torus(tolerance)
    a, b = old.channels, new.channels
    assert np.array_equal(a["A"], b["A"])
    hit = a["A"] > 0
    assert np.count_nonzero(hit) > 1500
    for name in ("Z", "u", "v", "level"):
        assert np.allclose(a[name][hit], b[name][hit], rtol=1e-6, atol=1e-6), name
    per_px = new.stats.micro_triangles / new.stats.pixels_covered
    assert per_px <= 4.0, per_px
    # the shading normal is the net's exact one: close to the grid's interpolated normal
    na = np.stack([a["N.X"], a["N.Y"], a["N.Z"]], axis=-1)[hit]
    nb = np.stack([b["N.X"], b["N.Y"], b["N.Z"]], axis=-1)[hit]
    assert np.median(np.sum(na * nb, axis=1)) > np.cos(np.radians(1.0))


@needs_shared
@pytest.mark.parametrize("tolerance", [4.0, 1.0, 0.25])
def test_micro_triangles_per_covered_pixel_stay_bounded(tolerance, monkeypatch):
    """RenderStats: at most 4 micro-triangles per covered pixel at every tolerance on the
    regular Loop torus (the grids need 4^depth per patch a ray reaches)."""
    monkeypatch.setattr(config, "LOOP_PER_RAY", True)
    st = _torus(tolerance, width=320, height=180).stats
    assert st.micro_triangles <= 4 * st.pixels_covered, st.micro_triangles / st.pixels_covered


@needs_shared
def test_threads_do_not_change_the_image(monkeypatch):
    """Bit-identical channels with 1 and 2 threads (and on the mixed spot cage, whose
    irregular triangles stay grids beside the per-ray nets)."""
    from subtrace.runtime import threads as tasks

    monkeypatch.setattr(config, "LOOP_PER_RAY", True)
    n2 = min(2, tasks.max_threads())
    one, two = _torus(1.0, threads=1), _torus(1.0, threads=n2)
    for name in one.channels:
        assert np.array_equal(one.channels[name], two.channels[name], equal_nan=True), name
    mesh = MODELS / "spot_low_resolution.obj"
    cage = subtrace.load_cage(mesh)
    scene = small_scene([mesh], *SPOT_VIEW, width=120, height=90, fov=40.0, tolerance=0.5)
    one = render_scene(scene, cages=[cage], threads=1)
    two = render_scene(scene, cages=[cage], threads=n2)
    for name in one.channels:
        assert np.array_equal(one.channels[name], two.channels[name], equal_nan=True), name


@needs_shared
def test_a_hidden_loop_object_is_not_refined(tmp_path, monkeypatch):
    """Invariant 5 for the per-ray nets: a Loop torus hidden behind a plane gets no net and
    no grid; seen alone, it is refined (so the test can fail)."""
    from test_render import _write_plane

    monkeypatch.setattr(config, "LOOP_PER_RAY", True)
    plane = tmp_path / "plane.obj"
    _write_plane(plane, 3.0, 8.0)
    torus = MODELS / "torus.obj"
    cages = [subtrace.load_cage(plane), subtrace.load_cage(torus)]
    scene = small_scene([plane, torus], (0.0, 0.0, 6.0), (0.0, 0.0, 0.0), fov=40.0)
    res = render_scene(scene, cages=cages)
    assert np.all(res.channels["object_id"] == 0)
    assert np.count_nonzero(res.refined_objects == 1) == 0
    res = render_scene(small_scene([torus], (0.0, 0.0, 6.0), (0.0, 0.0, 0.0), fov=40.0),
                       cages=cages[1:])
    assert res.stats.pixels_covered > 100
    assert np.count_nonzero(res.refined_objects == 0) > 100
