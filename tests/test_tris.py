"""Loop patches traced per ray through quartic Bezier nets (geometry/tris.py): the net's
points and normals are the exact limit surface's, the per-ray descent meets the
micro-triangles of the exact whole grids, builds a few per covered pixel, and the image does
not depend on the thread count."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shared_data import MODELS, small_scene

import subtrace
from subtrace.patches.boxspline import box_nets, loop_regular
from subtrace.patches.table import build_patch_table
from subtrace.render import render_scene
from subtrace.geometry.tris import _level_deviation, tri_deviation, tri_normal, tri_point

TORUS_VIEW = ((1.226, 4.085, 4.902), (0.0, 0.0, 0.0))  # scenes/torus_loop.toml's camera
SPOT_VIEW = ((2.0, 0.8, 2.4), (0.0, 0.1, 0.2))


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


@pytest.mark.parametrize("tolerance", [4.0, 1.0, 0.25])
@pytest.mark.parametrize("mesh,view", [("torus.obj", TORUS_VIEW),
                                       ("spot_low_resolution.obj", SPOT_VIEW)],
                         ids=["torus", "spot"])
def test_hits_are_the_exact_grids_micro_triangles(mesh, view, tolerance):
    """Every hit lies on a micro-triangle of the exact limit-point grid of its patch at its
    depth (``patches.grids.build_grids``: the subdivision core's own refinement, the whole
    grid), found by a brute-force ray test (``naive.ray_triangle_hits``): the per-ray nets
    and the isolated patches' pieces and cells meet the same micro-triangles. The distances
    agree to float32 rounding where no side is snapped (the grid is not snapped: near a
    coarser neighbour the two may differ by less than the pixel's footprint)."""
    from naive import ray_triangle_hits

    from subtrace.camera import camera_frame
    from subtrace.patches.grids import build_grids, leaf_corners

    cage = subtrace.load_cage(MODELS / mesh)
    scene = small_scene([MODELS / mesh], *view, width=80, height=60, fov=30.0,
                        tolerance=tolerance)
    res = render_scene(scene, cages=[cage])
    ch = res.channels
    hit = np.nonzero(ch["A"].ravel() > 0)[0]
    assert len(hit) > 400
    table = build_patch_table([cage])
    o = table.objects[0]
    patch_of = np.empty(table.ptex.max() + 1, np.int64)
    patch_of[table.ptex] = np.arange(table.n_patches)
    patch = patch_of[ch["patch_id"].ravel()[hit].astype(np.int64)]
    depth = ch["level"].ravel()[hit].astype(np.int64)
    frame = camera_frame(res.camera)
    row, col = np.divmod(hit, res.camera.width)
    d = frame[3] + col[:, None] * frame[1] + row[:, None] * frame[2]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    z = ch["Z"].ravel()[hit].astype(np.float64)
    ref = np.full(len(hit), np.inf)
    for p, n in set(zip(patch.tolist(), depth.tolist())):
        P = build_grids(o.level, o.points, cage.options, table.face[[p]], n)[0][0]
        tri = P[leaf_corners(n, False)]
        for k in np.nonzero((patch == p) & (depth == n))[0]:
            t, _ = ray_triangle_hits(frame[0], d[k], tri[:, 0], tri[:, 1], tri[:, 2], 1e-9)
            t = t[t > 0]
            ref[k] = t[0] if len(t) else np.inf
    rel = np.abs(ref - z) / z
    assert np.mean(rel <= 1e-6) > 0.9, np.mean(rel <= 1e-6)
    found = np.isfinite(ref)
    assert np.mean(found) > 0.98
    assert np.all(rel[found] <= 2 * res.tolerance_rad), rel[found].max()


@pytest.mark.parametrize("tolerance", [4.0, 1.0, 0.25])
def test_micro_triangles_per_covered_pixel_stay_bounded(tolerance):
    """RenderStats: at most 4 micro-triangles per covered pixel at every tolerance on the
    regular Loop torus (the grids need 4^depth per patch a ray reaches)."""
    st = _torus(tolerance, width=320, height=180).stats
    assert st.micro_triangles <= 4 * st.pixels_covered, st.micro_triangles / st.pixels_covered


def test_threads_do_not_change_the_image():
    """Bit-identical channels with 1 and 2 threads (and on Spot's Loop cage, whose irregular
    triangles are isolated into pieces and cells beside the regular nets)."""
    from subtrace.runtime import threads as tasks

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


def test_a_hidden_loop_object_is_not_refined(tmp_path):
    """Invariant 5 for the per-ray nets: a Loop torus hidden behind a plane gets no net and
    no piece; seen alone, it is refined (so the test can fail)."""
    from shared_data import write_plane

    plane = tmp_path / "plane.obj"
    write_plane(plane, 3.0, 8.0)
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


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), level=st.integers(0, 5))
def test_a_nodes_box_holds_its_part_of_the_patch(seed, level):
    """A memo node's box is its corners' box grown by the net's deviation bound, a quarter
    per level (tris.tri_deviation, _level_deviation): every point of the patch over the node
    lies in it. Random quartic nets (wild ones: control points anywhere in a unit cube),
    a random dyadic sub-triangle at ``level`` (upright or turned), points at random
    barycentric coordinates in it, evaluated from the whole net."""
    rng = np.random.default_rng(seed)
    net = np.zeros((1, 16, 3))
    net[0, :15] = rng.random((15, 3)) * rng.choice([1e-3, 1.0, 1e3])
    dev = tri_deviation(net, 0)
    # a node of the level, by random 1-to-4 splits (Loop's child order, as tris._child)
    g, i, j = 1, 0, 0
    for lev in range(level):
        hh = g << (level - lev - 1)
        q = rng.integers(0, 4)
        i, j = i + (hh if q in (1, 3) else 0), j + (hh if q in (2, 3) else 0)
        g = -g if q == 3 else g
    corners = np.array([(i, j), (i + g, j), (i, j + g)], float) / (1 << level)
    e = _level_deviation(dev, level, 0)
    pc = np.array([tri_point(net, 0, s, t) for s, t in corners])
    lo, hi = pc.min(axis=0) - e, pc.max(axis=0) + e
    w = rng.dirichlet(np.ones(3), 200)
    for s, t in w @ corners:
        p = np.array(tri_point(net, 0, s, t))
        slack = 1e-12 * np.abs(net).max()
        assert np.all(p >= lo - slack) and np.all(p <= hi + slack), (p, lo, hi)
