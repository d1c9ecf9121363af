"""Ray tracing trimmed NURBS patches (subtrace.nurbs.trace, nurbs.scene and the render hook).

Independent checks: the analytic sphere and torus (the sample models are exact rational
quadrics), plain de Boor points and the even-odd rule over densely sampled loops
(tests/naive.py), circles for the circular hole, and renders from inside closed models.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import naive
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from subtrace.camera import Camera, camera_frame
from subtrace.io.obj import read_obj
from subtrace.io.scene import apply_overrides, load_scene
from subtrace.nurbs.freeform import freeform_of
from subtrace.nurbs.model import build_model
from subtrace.nurbs.trace import hit_geometry, patch_bvh, trace_nurbs, trace_rays

ROOT = Path(__file__).resolve().parents[1]
MODELS = ROOT / "models" / "nurbs"


def load(name):
    surfaces = freeform_of(read_obj(MODELS / f"{name}.obj")).surfaces
    model = build_model(surfaces)
    return surfaces, model, patch_bvh(model)


def render_hits(name, eye, target, width=64, height=48, px=1.0, up=(0, 0, 1), fov=40.0):
    """(camera, hits) of one ray per pixel at ``px`` pixels of tolerance."""
    _, model, bvh = load(name)
    cam = Camera(tuple(map(float, eye)), tuple(map(float, target)), up, fov, width, height)
    hits = trace_nurbs(model, bvh, camera_frame(cam), width, height, px * cam.pixel_angle())
    return cam, model, hits


# ------------------------------------------------------------------------------------------
# hits on the exact quadrics
# ------------------------------------------------------------------------------------------

def test_sphere_hits_are_on_the_sphere_and_nearest():
    """Every hit lies on the unit sphere (the rational surface is exact and Newton's root is
    found to rounding: 1e-12 is a few thousand ulps), at the analytic nearest root; every ray
    that clearly meets the sphere hits it and every one that clearly misses it misses."""
    cam, model, hits = render_hits("sphere", (2.2, -2.8, 1.6), (0, 0, 0))
    eye = np.array(cam.eye)
    d = cam.ray_directions().reshape(-1, 3)
    b = d @ eye
    disc = b * b - (eye @ eye - 1.0)
    hit = hits.patch >= 0
    clear = np.abs(disc) > 1e-3  # away from the silhouette
    assert np.array_equal(hit[clear], disc[clear] > 0)
    assert hit.sum() > 500
    P, N, _ = hit_geometry(model, hits.patch[hit], hits.st[hit])
    assert np.abs(np.linalg.norm(P, axis=1) - 1.0).max() < 1e-12
    t_exact = -b[hit] - np.sqrt(disc[hit])
    assert np.abs(hits.t[hit] - t_exact).max() < 1e-9
    # exact normals: the radius direction (up to the parametrisation's orientation)
    cos = np.abs(np.einsum("ij,ij->i", N, P))
    assert np.all(cos > 1 - 1e-12)


def test_sphere_poles_get_the_limit_normal():
    """At the poles a side of the patches shrinks to a point (dP/du = 0): the normal is the
    limit normal (0, 0, +-1), not NaN, for rays through the pole and next to it."""
    _, model, bvh = load("sphere")
    offsets = np.array([[0, 0], [1e-9, 0], [0, 1e-7], [-1e-5, 2e-5], [1e-3, 1e-3]])
    for z in (3.0, -3.0):
        origins = np.column_stack([offsets, np.full(len(offsets), z)])
        dirs = np.tile([0.0, 0.0, -np.sign(z)], (len(offsets), 1))
        hits = trace_rays(model, bvh, origins, dirs, 1e-3)
        assert np.all(hits.patch >= 0)
        P, N, _ = hit_geometry(model, hits.patch, hits.st)
        assert np.all(np.isfinite(N))
        # the normal of the sphere at P is P; the nudge inside the patch costs ~1e-7 rad
        assert np.all(np.abs(np.einsum("ij,ij->i", N, P)) > 1 - 1e-9), N


def torus_distance(P, big=1.0, small=0.35):
    return np.hypot(np.hypot(P[:, 0], P[:, 1]) - big, P[:, 2]) - small


def test_torus_hits_are_on_the_torus_and_first():
    """Every hit on the 16-surface rational torus lies on the analytic torus (to 1e-12) and
    no point of the ray before it is inside the torus (sampled every 1e-3 of the way)."""
    cam, model, hits = render_hits("torus_patches", (2.4, -2.0, 1.5), (0, 0, 0))
    hit = hits.patch >= 0
    assert hit.sum() > 400
    P, _, _ = hit_geometry(model, hits.patch[hit], hits.st[hit])
    assert np.abs(torus_distance(P)).max() < 1e-12
    eye = np.array(cam.eye)
    d = cam.ray_directions().reshape(-1, 3)[hit]
    steps = np.linspace(0.0, 1.0 - 1e-3, 1000)
    for k in range(0, len(P), 7):
        before = eye + (steps * hits.t[hit][k])[:, None] * d[k]
        assert torus_distance(before).min() > -1e-9


def test_channels_are_the_surface_parameters():
    """The hit's (u, v) are its surface's parameters: the rational sphere's point there (by
    plain de Boor) is the hit point."""
    surfaces = load("sphere")[0]
    _, model, hits = render_hits("sphere", (0.4, -3.0, 1.0), (0, 0, 0), 32, 24)
    hit = np.nonzero(hits.patch >= 0)[0]
    P, _, uv = hit_geometry(model, hits.patch[hit], hits.st[hit])
    s = surfaces[0]
    for k in range(0, len(hit), 11):
        ref = naive.nurbs_surface_eval(s.knots_u, s.knots_v, 2, 2, s.control.tolist(),
                                       uv[k, 0], uv[k, 1])[0]
        assert np.allclose(ref, P[k], atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), degree=st.integers(1, 9))
def test_hits_on_random_rational_surfaces(seed, degree):
    """Random rational B-spline surfaces (degree 1 to 9 each way, random knots and weights):
    every ray aimed at a random surface point (plain de Boor) from 1 unit away along the
    normal hits at distance at most 1 (the aimed point, or a nearer fold), on the surface:
    the point at the hit's (u, v) by plain de Boor is the hit point (to 1e-9 of the net's
    size; 150 examples passed when written)."""
    from subtrace.nurbs.surface import make_surface

    rng = np.random.default_rng(seed)
    du, dv = int(rng.integers(1, degree + 1)), degree
    nu, nv = du + 1 + int(rng.integers(0, 3)), dv + 1 + int(rng.integers(0, 3))
    knots = [np.concatenate([np.zeros(d + 1), np.sort(rng.random(n - d - 1)), np.ones(d + 1)])
             for n, d in ((nu, du), (nv, dv))]
    surface = make_surface((du, dv), *knots, rng.normal(size=(nu * nv, 3)),
                           rng.uniform(0.3, 3.0, nu * nv))
    model = build_model([surface])
    uv = rng.uniform(0.05, 0.95, size=(30, 2))
    origins, dirs = aim_at(surface, uv, height=1.0)
    hits = trace_rays(model, patch_bvh(model), origins, dirs, 1e-3)
    scale = np.abs(surface.control[..., :3] / surface.control[..., 3:]).max()
    hit = hits.patch >= 0
    assert np.all(hit)  # each ray meets the surface at normal incidence at least once
    assert np.all(hits.t[hit] <= 1.0 + 1e-9)
    P, _, got = hit_geometry(model, hits.patch[hit], hits.st[hit])
    for k in range(len(P)):
        ref = naive.nurbs_surface_eval(surface.knots_u.tolist(), surface.knots_v.tolist(), du,
                                       dv, surface.control.tolist(), got[k, 0], got[k, 1])[0]
        assert np.allclose(ref, P[k], atol=1e-9 * scale)
        along = origins[hit][k] + hits.t[hit][k] * dirs[hit][k]
        assert np.allclose(along, P[k], atol=1e-8 * max(scale, 1.0))


# ------------------------------------------------------------------------------------------
# trims: holes, the kernel's classification, the next hit behind a trimmed one
# ------------------------------------------------------------------------------------------

def aim_at(surface, uv, height=0.5):
    """Rays from ``height`` above the surface points at ``uv`` (plain de Boor) towards them."""
    origins, dirs = [], []
    for u, v in uv:
        P, Pu, Pv = naive.nurbs_surface_eval(surface.knots_u, surface.knots_v, *surface.degree,
                                             surface.control.tolist(), u, v)
        n = np.cross(Pu, Pv)
        n /= np.linalg.norm(n)
        origins.append(np.array(P) + height * n)
        dirs.append(-n)
    return np.array(origins), np.array(dirs)


def test_rays_through_the_circular_hole_miss_and_next_to_it_hit():
    """The plate's round hole (two rational half circles, centre (0.42, 0.42), radius
    0.16 in parameters): rays aimed at points 1e-4 inside the circle miss, rays aimed
    1e-4 outside it hit the aimed point (distance 0.5, parameters to 1e-9)."""
    surfaces, model, bvh = load("plate_holes")
    angles = np.linspace(0, 2 * np.pi, 48, endpoint=False)
    for radius, kept in ((0.16 - 1e-4, False), (0.16 + 1e-4, True), (0.08, False)):
        uv = np.column_stack([0.42 + radius * np.cos(angles), 0.42 + radius * np.sin(angles)])
        origins, dirs = aim_at(surfaces[0], uv)
        hits = trace_rays(model, bvh, origins, dirs, 1e-3)
        assert np.all((hits.patch >= 0) == kept), radius
        if kept:
            assert np.abs(hits.t - 0.5).max() < 1e-9
            _, _, got = hit_geometry(model, hits.patch, hits.st)
            assert np.abs(got - uv).max() < 1e-9


def test_kernel_trim_agrees_with_the_tree_and_brute_force_parity():
    """Rays aimed at 3000 seeded random parameter points of the plate hit exactly where the
    trim keeps the point, by the Python-called kd-tree (model.inside) and by the even-odd
    rule over the loops sampled densely (points within 2e-3 of a loop, where the sampled
    polygon's chords differ from the curves, left out of the brute-force comparison)."""
    surfaces, model, bvh = load("plate_holes")
    rng = np.random.default_rng(18)
    uv = rng.uniform(0.0, 1.0, size=(3000, 2))
    origins, dirs = aim_at(surfaces[0], uv)
    hits = trace_rays(model, bvh, origins, dirs, 1e-3)
    hit = hits.patch >= 0
    tree = model.inside(np.zeros(len(uv), np.int64), uv)
    loops = surfaces[0].loops
    polys = [naive.loop_polygon(lp.segments, 400) for lp in loops]
    outer = naive.polygon_parity([p for p, lp in zip(polys, loops) if not lp.hole], uv)
    holes = naive.polygon_parity([p for p, lp in zip(polys, loops) if lp.hole], uv)
    brute = outer & ~holes
    near = np.min([np.linalg.norm(uv[:, None] - p[None], axis=-1).min(axis=1) for p in polys],
                  axis=0) < 2e-3
    assert np.array_equal(hit, tree)
    assert np.array_equal(hit[~near], brute[~near])
    assert 0.2 < hit.mean() < 0.9
    assert np.abs(hits.t[hit] - 0.5).max() < 1e-9


def test_a_trimmed_first_hit_goes_on_to_the_next():
    """Through the cylinder's window (u in [0.4, 1.6], v in [0.25, 0.75]: around (0, 1, 1))
    the ray's first root is cut away and it hits the far wall at y = -1; below the window it
    hits the near wall."""
    _, model, bvh = load("cylinder_window")
    origins = np.array([[0.0, 3.0, 1.0], [0.05, 3.0, 0.9], [0.0, 3.0, 0.2], [0.0, 3.0, 1.8]])
    dirs = np.tile([0.0, -1.0, 0.0], (4, 1))
    hits = trace_rays(model, bvh, origins, dirs, 1e-3)
    far = 3.0 + np.sqrt(1 - 0.05**2)
    near = 3.0 - np.sqrt(1 - 0.05**2)
    np.testing.assert_allclose(hits.t, [4.0, far, 2.0, 2.0], atol=1e-9)
    assert near < far


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_kernel_trim_with_random_loops(seed):
    """A flat square (z = 0, u = x, v = y) trimmed by random rational loops (hypothesis
    seeds; possibly self-intersecting): a ray down onto (u, v) hits exactly where the
    kd-tree classifies the point inside, and where the plain parity over the loops' exact
    segment crossings (naive.trim_parity, polynomial roots) says so."""
    from subtrace.nurbs.surface import make_surface
    from subtrace.nurbs.trim import TrimLoop

    def random_loop(rng, segments):
        joints = rng.random((segments, 2))
        segs = []
        for k in range(segments):
            d = int(rng.integers(1, 4))
            pts = np.vstack([joints[k], rng.random((d - 1, 2)), joints[(k + 1) % segments]])
            w = rng.uniform(0.3, 3.0, d + 1)
            segs.append(np.column_stack([pts * w[:, None], w]))
        return TrimLoop(False, tuple(segs), joints)

    rng = np.random.default_rng(seed)
    loops = tuple(random_loop(rng, int(rng.integers(1, 8)))
                  for _ in range(int(rng.integers(1, 3))))
    plane = make_surface((1, 1), [0, 0, 1, 1], [0, 0, 1, 1],
                         [(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0)])
    model = build_model([dataclasses.replace(plane, loops=loops)])
    uv = rng.random((200, 2))
    origins = np.column_stack([uv, np.ones(len(uv))])
    hits = trace_rays(model, patch_bvh(model), origins, np.tile([0.0, 0.0, -1.0], (200, 1)),
                      1e-3)
    hit = hits.patch >= 0
    assert np.array_equal(hit, model.inside(np.zeros(len(uv), np.int64), uv))
    segments = [seg for loop in loops for seg in loop.segments]
    slow = np.array([naive.trim_parity(segments, *p) for p in uv[:40]])
    assert np.array_equal(hit[:40], slow)
    assert np.all(hits.t[hit] == 1.0)


# ------------------------------------------------------------------------------------------
# watertight, deterministic, merged with subdivision surfaces
# ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("px", [4.0, 1.0, 0.25])
@pytest.mark.parametrize("name, eye", [("torus_patches", (1.0, 0.0, 0.05)),
                                       ("blob_bezier", (1.0, 0.0, 0.0))])
def test_watertight_from_inside(name, eye, px):
    """A camera inside a closed model of many patches: every ray hits, at every tolerance
    (patches of different depths and neighbouring surfaces leave no gap)."""
    for target in ((0.0, 1.0, 0.2), (1.0, 1.0, -0.4), (2.0, 0.3, 0.0), (1.0, 0.0, 1.0)):
        up = (1.0, 0.0, 0.0) if target == (1.0, 0.0, 1.0) else (0.0, 0.0, 1.0)
        _, _, hits = render_hits(name, eye, target, 48, 36, px=px, up=up, fov=100.0)
        assert np.all(hits.patch >= 0), (target, np.count_nonzero(hits.patch < 0))


def small_scene(name, **overrides):
    return apply_overrides(load_scene(ROOT / "scenes" / f"{name}.toml"), width=80, height=60,
                           **overrides)


def test_same_image_with_one_and_two_threads():
    """The NURBS pass writes whole rows per thread: the image is bit-identical."""
    from subtrace.render import render_scene

    scene = small_scene("nurbs_plate")
    one = render_scene(scene, threads=1).channels
    two = render_scene(scene, threads=2).channels
    for name in one:
        assert np.array_equal(one[name], two[name], equal_nan=True), name


def test_mixed_scene_merges_by_depth():
    """NURBS beside a Loop cage: each pixel shows the nearer of the two objects rendered
    alone, with its scene object index and its own ids."""
    from subtrace.render import render_scene

    # (one ray a pixel: with anti-aliasing, an edge pixel whose centre ray missed takes
    # the channels of its nearest extra ray that hit, which an object alone may lack)
    scene = small_scene("nurbs_mixed", samples=1)
    both = render_scene(scene).channels
    alone = [render_scene(dataclasses.replace(scene, objects=(o,))).channels
             for o in scene.objects]
    z = np.minimum(alone[0]["Z"], alone[1]["Z"])
    np.testing.assert_array_equal(both["Z"], z)
    first = alone[0]["Z"] < alone[1]["Z"]
    second = np.isfinite(alone[1]["Z"]) & ~first
    assert np.all(both["object_id"][first] == 0) and np.all(both["object_id"][second] == 1)
    np.testing.assert_array_equal(both["patch_id"][first], alone[0]["patch_id"][first])
    assert set(np.unique(both["patch_id"][first])) <= set(range(16))
    assert first.sum() > 200 and second.sum() > 200


def test_render_reports_nurbs_patches_and_levels():
    """A free-form scene's stats count its patches and the level channel holds split depths
    (0 at most for a surface seen whole within the tolerance)."""
    from subtrace.render import render_scene

    result = render_scene(small_scene("nurbs_torus"))
    assert result.stats.patches == 16 + 8
    level = result.channels["level"]
    assert level.max() == result.stats.max_level and level.max() >= 3
    assert set(np.unique(level[result.channels["A"] == 0])) == {-1.0}
    assert "nurbs" in result.schemes
    # (the hits: a pixel's centre ray's, or where that missed its nearest anti-aliasing
    # ray's: every pixel of alpha above 0 has one)
    hit = np.isfinite(result.channels["Z"])
    assert hit.sum() > 1000 and np.all(result.channels["A"][hit] > 0)
    assert np.all(hit[result.channels["A"] > 0])
    n = result.channels["N.X"] ** 2 + result.channels["N.Y"] ** 2 + result.channels["N.Z"] ** 2
    assert np.allclose(n[hit], 1.0, atol=1e-5)
    assert np.all(n[(result.channels["A"] > 0) & ~hit] == 0.0)


# ------------------------------------------------------------------------------------------
# line queries (subtrace.lines.nurbs through intersect_lines and subtrace intersect)
# ------------------------------------------------------------------------------------------

def test_lines_meet_the_sphere_at_both_analytic_roots():
    """2000 seeded random lines, infinite both ways: every line that clearly crosses the
    sphere has exactly its two analytic roots (t to 1e-12 of the line's scale), the others
    none; mode "first" keeps the nearest root at t >= 0."""
    from subtrace.lines.api import intersect_lines

    _, model, _ = load("sphere")
    rng = np.random.default_rng(4)
    o = rng.uniform(-3, 3, (2000, 3))
    d = rng.normal(size=(2000, 3))
    hits = intersect_lines(model, o, d, 1e-6, t_range=(-np.inf, np.inf))
    a, b, c = (d * d).sum(1), 2 * (o * d).sum(1), (o * o).sum(1) - 1
    disc = b * b - 4 * a * c
    clear = np.abs(disc) > 1e-6
    count = np.bincount(hits.line, minlength=len(o))
    assert np.array_equal(count[clear], np.where(disc[clear] > 0, 2, 0))
    r = np.sqrt(np.maximum(disc, 0))
    roots = np.stack([(-b - r) / (2 * a), (-b + r) / (2 * a)], axis=1)
    first_of_line = np.r_[True, hits.line[1:] != hits.line[:-1]]
    want = roots[hits.line, np.where(first_of_line, 0, 1)]
    assert np.abs(hits.t - want).max() < 1e-12 * 10
    assert np.abs(np.linalg.norm(hits.point, axis=1) - 1).max() < 1e-12
    assert hits.ptex.max() == 0 and np.all(np.abs(np.einsum("ij,ij->i", hits.normal,
                                                             hits.point)) > 1 - 1e-9)
    first = intersect_lines(model, o, d, 1e-6, mode="first")
    ahead = np.where(roots[:, 0] >= 0, roots[:, 0], roots[:, 1])
    expect = clear & (disc > 0) & (roots[:, 1] >= 0)
    assert np.array_equal(np.isin(np.arange(len(o)), first.line)[clear], expect[clear])
    assert np.abs(first.t - ahead[first.line]).max() < 1e-11


def test_lines_meet_the_torus_at_its_quartic_roots():
    """Random lines through the torus: the hits are the real roots of the torus's quartic
    along the line (numpy's polynomial roots), for lines not close to a tangency."""
    from subtrace.lines.api import intersect_lines

    _, model, _ = load("torus_patches")
    rng = np.random.default_rng(7)
    o = rng.uniform(-2, 2, (300, 3))
    d = rng.normal(size=(300, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    hits = intersect_lines(model, o, d, 1e-7, t_range=(-np.inf, np.inf))
    R, r = 1.0, 0.35
    checked = 0
    for k in range(len(o)):
        # ((|p|^2 + R^2 - r^2)^2 - 4 R^2 (x^2 + y^2)) along p = o + t d, a quartic in t
        po, pd = o[k], d[k]
        q2 = np.array([1.0, 2 * po @ pd, po @ po + R * R - r * r])
        xy = np.array([pd[0] ** 2 + pd[1] ** 2, 2 * (po[0] * pd[0] + po[1] * pd[1]),
                       po[0] ** 2 + po[1] ** 2])
        quartic = np.polysub(np.polymul(q2, q2), 4 * R * R * np.r_[0, 0, xy])
        roots = np.roots(quartic)
        real = np.sort(roots[np.abs(roots.imag) < 1e-6].real)
        if np.any(np.abs(roots.imag[np.abs(roots.imag) >= 1e-6]) < 1e-2) or (
                len(real) > 1 and np.diff(real).min() < 1e-3):
            continue  # near a tangency: roots about to merge
        got = hits.t[hits.of_line(k)]
        assert len(got) == len(real), (k, got, real)
        assert np.allclose(got, real, atol=1e-8)
        checked += 1
    assert checked > 250 and len(hits) > 100


def test_lines_skip_trimmed_parts():
    """A line through the plate's round hole has no hit; one beside it has one."""
    from subtrace.lines.api import intersect_lines

    surfaces, model, _ = load("plate_holes")
    uv = np.array([[0.42, 0.42], [0.42 + 0.16 - 1e-4, 0.42], [0.42 + 0.16 + 1e-4, 0.42]])
    origins, dirs = aim_at(surfaces[0], uv)
    hits = intersect_lines(model, origins, dirs, 1e-8, t_range=(-np.inf, np.inf))
    assert hits.line.tolist() == [2]
    assert abs(hits.t[0] - 0.5) < 1e-9 and np.abs(hits.uv[0] - uv[2]).max() < 1e-9


def test_intersect_command_on_a_free_form_file(tmp_path, capsys):
    """subtrace intersect takes an OBJ file of free-form surfaces: ptex is the surface
    index; a line through the torus's tube meets it 4 times, merged across patch sides."""
    from subtrace.cli.main import main

    lines = tmp_path / "l.csv"
    lines.write_text("ox,oy,oz,dx,dy,dz\n-3,0,0.1,1,0,0\n-3,5,0,1,0,0\n")
    rc = main(["intersect", str(MODELS / "torus_patches.obj"), "--lines", str(lines),
               "--precision", "1e-6"])
    out = capsys.readouterr().out.strip().splitlines()
    assert rc == 0 and out[0].startswith("line,t,")
    rows = [row.split(",") for row in out[1:]]
    assert [r[0] for r in rows] == ["0"] * 4
    xs = sorted(float(r[2]) for r in rows)
    rho = math.sqrt(0.35**2 - 0.1**2)
    np.testing.assert_allclose(xs, [-1 - rho, -1 + rho, 1 - rho, 1 + rho], atol=1e-9)
    assert {int(r[5]) for r in rows} <= set(range(16))


def test_free_form_file_with_the_automatic_camera():
    """An OBJ file of free-form surfaces alone renders with the automatic camera (framing
    the patches' control boxes): the surface fills a good part of the image."""
    from subtrace.io.scene import scene_for_meshes
    from subtrace.render import render_scene

    scene = apply_overrides(scene_for_meshes([str(MODELS / "cylinder_window.obj")]), width=64,
                            height=48)
    result = render_scene(scene)
    covered = result.channels["A"] > 0
    assert 0.1 < covered.mean() < 0.9
    assert set(np.unique(result.channels["object_id"][covered])) == {0.0}
    assert result.schemes == ("nurbs",) and result.stats.patches == 4


def test_load_model_without_surfaces_is_one_clear_error(tmp_path):
    """load_model on an OBJ file without free-form surfaces names the file."""
    from subtrace.errors import ObjError
    from subtrace.nurbs.model import load_model

    path = tmp_path / "quad.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
    with pytest.raises(ObjError, match="quad.obj: no free-form surfaces"):
        load_model(path)
