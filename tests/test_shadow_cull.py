"""Culling to the view keeps what secondary rays from the view may meet (render.faces_in_view
with accel.cull's reach): an object outside the picture whose shadow falls on the visible
ground, or on an object in view, and what ambient occlusion rays meet, render the same with
the lazy table as with the full one; what shadows nothing in view is left out."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shared_data import MODELS

from subtrace import config
from subtrace.io.scene import scene_from_dict
from subtrace.lights import Light
from subtrace.render import render_scene

CUBE = ("v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n"
        "f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 3 4 8 7\nf 2 3 7 6\nf 1 5 8 4\n")


def _scene(tmp_path, shadows=True):
    """A camera looking down at the ground near the origin; a cube high above and to the
    side, out of the picture; a low sun that throws the cube's shadow into the picture."""
    cube = tmp_path / "cube.obj"
    cube.write_text("".join(
        f"v {float(x) + 6.0} {float(y) + 4.0} {z}\n" if ln.startswith("v ") else ln + "\n"
        for ln in CUBE.splitlines() for x, y, z in [ln.split()[1:4] if ln.startswith("v ")
                                                   else (0, 0, 0)]))
    return scene_from_dict({
        "object": [{"mesh": str(cube)}],
        "camera": {"eye": [0.0, 6.0, 6.0], "target": [0.0, 0.0, 0.0], "fov": 30.0,
                   "width": 64, "height": 48},
        "render": {"shadows": shadows, "samples": 1},
        "light": [{"direction": [-6.0, -4.0, 0.0]}],
        "ground": {"height": 0.0, "color": [0.6, 0.6, 0.6]},
    })


def test_offscreen_caster_keeps_its_shadow(tmp_path, monkeypatch):
    scene = _scene(tmp_path)
    lazy = render_scene(scene)
    assert np.all(lazy.channels["object_id"] < 0)  # the cube is not in the picture
    monkeypatch.setattr(config, "CULL_TO_VIEW", False)
    full = render_scene(scene)
    for name in ("R", "G", "B"):
        np.testing.assert_array_equal(lazy.channels[name], full.channels[name], err_msg=name)
    # and the shadow is there: darker ground pixels than without shadows
    lit = render_scene(_scene(tmp_path, shadows=False))
    assert np.count_nonzero(full.channels["R"] < lit.channels["R"] - 1e-3) > 20


def _cubes(tmp_path, offsets):
    """An OBJ of unit-radius cubes at ``offsets`` (one cage)."""
    lines, faces = [], []
    for k, (ox, oy, oz) in enumerate(offsets):
        for ln in CUBE.splitlines():
            if ln.startswith("v "):
                x, y, z = (float(c) for c in ln.split()[1:4])
                lines.append(f"v {x + ox} {y + oy} {z + oz}")
            else:
                faces.append("f " + " ".join(str(int(i) + 8 * k) for i in ln.split()[1:]))
    path = tmp_path / "cubes.obj"
    path.write_text("\n".join(lines + faces) + "\n")
    return path


def _cube_scene(mesh, eye, target, fov, light, ground=False):
    """``scene(shadows)``: the cubes ``mesh`` seen at 64x48 from ``eye`` under ``light``
    (a [light] table), one sample, over a grey ground at height 0 with ``ground``."""

    def scene(shadows):
        return scene_from_dict({
            "object": [{"mesh": str(mesh)}],
            "camera": {"eye": eye, "target": target, "fov": fov, "width": 64, "height": 48},
            "render": {"shadows": shadows, "samples": 1}, "light": [light],
            **({"ground": {"height": 0.0, "color": [0.6, 0.6, 0.6]}} if ground else {})})

    return scene


def _culled_as_full(scene_of, monkeypatch):
    """``scene_of(shadows)`` rendered with shadows, culled and not: the same image, in which
    shadows darken more than 20 pixels (against ``scene_of(False)``). Returns the culled
    render."""
    lazy = render_scene(scene_of(True))
    with monkeypatch.context() as m:
        m.setattr(config, "CULL_TO_VIEW", False)
        full = render_scene(scene_of(True))
    for name, plane in full.channels.items():
        np.testing.assert_array_equal(lazy.channels[name], plane, err_msg=name)
    lit = render_scene(scene_of(False))
    assert np.count_nonzero(full.channels["R"] < lit.channels["R"] - 1e-3) > 20
    return lazy


@pytest.mark.parametrize("light", [{"direction": [1.0, -1.0, -0.05]},
                                   {"position": [-12.0, 12.0, 0.3]}],
                         ids=["directional", "point"])
def test_offscreen_caster_without_ground_is_kept_and_the_rest_culled(tmp_path, monkeypatch,
                                                                     light):
    """No ground: the points in view are the objects' own. A cube in view, a second out of
    the picture between it and the light (it shadows the first), a third out of the picture
    on the far side (it shadows nothing in view): the second is kept, the third culled (for
    the directional light, its box swept along the light would reach the view), and the
    image is the full table's."""
    mesh = _cubes(tmp_path, [(0, 0, 0), (-6.0, 6.0, 0.0), (6.0, -6.0, 0.0)])
    scene = _cube_scene(mesh, [0.0, 0.5, 7.0], [0.0, 0.0, 0.0], 25.0,
                        {**light, "intensity": 1.0 if "direction" in light else 300.0})

    lazy = _culled_as_full(scene, monkeypatch)
    assert lazy.stats.faces_culled == 6  # the third cube
    assert set(np.unique(lazy.channels["object_id"])) == {-1.0, 0.0}


def test_ambient_occlusion_keeps_what_occludes_the_view(monkeypatch):
    """Ambient occlusion rays from points in view reach config.AO_DISTANCE of the scene's
    diagonal: Spot seen close, with AO, renders as with the full table (the faces beside the
    picture that occlude its points are kept; they were not, and 47 % of the pixels were
    lighter)."""
    mesh = MODELS / "spot_control_mesh.obj"
    scene = scene_from_dict({
        "object": [{"mesh": str(mesh)}],
        "camera": {"eye": [0.3, 0.45, 1.0], "target": [0.0, 0.3, 0.2], "fov": 12.0,
                   "width": 80, "height": 45},
        "render": {"ao": 8, "samples": 1, "shadows": False}})
    lazy = render_scene(scene)
    monkeypatch.setattr(config, "CULL_TO_VIEW", False)
    full = render_scene(scene)
    for name, plane in full.channels.items():
        np.testing.assert_array_equal(lazy.channels[name], plane, err_msg=name)


def _points_in_view(rng, n=40):
    """A random camera and ``n`` random points in its view (depths 0.05 to 6)."""
    from subtrace.camera import Camera

    eye = rng.uniform(-5, 5, 3)
    cam = Camera(eye=tuple(eye), target=tuple(eye + rng.standard_normal(3)),
                 up=(0.0, 1.0, 0.0), fov_deg=float(rng.uniform(5, 60)),
                 width=int(rng.integers(8, 64)), height=int(rng.integers(8, 64)))
    frame = cam.frame()
    cols = rng.uniform(-0.5, cam.width - 0.5, n)
    rows = rng.uniform(-0.5, cam.height - 0.5, n)
    q = frame[0] + rng.uniform(0.05, 6.0, n)[:, None] * (
        frame[3] + cols[:, None] * frame[1] + rows[:, None] * frame[2])
    return cam, q


def _blockers_kept(rng, cam, q, p, light):
    """Small boxes around the points ``p`` of shadow rays from ``q`` towards ``light`` (a
    light with ``position`` and ``direction``), the scene's box holding them and ``q``: the
    cull's reach (None: no cull) and whether its view test keeps every box."""
    from subtrace.accel.cull import secondary_reach, view_test

    r = rng.uniform(1e-4, 0.05, len(p))[:, None]
    lo, hi = p - r, p + r
    bounds = (np.minimum(q, lo).min(axis=0), np.maximum(q, hi).max(axis=0))
    scene = SimpleNamespace(render=SimpleNamespace(ao=0, shadows=True), ground=None,
                            lights=[light])
    reach = secondary_reach(scene, bounds, cam)
    return reach, bounds, reach is not None and view_test(cam, reach)(lo, hi).all()


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_a_box_that_blocks_a_shadow_ray_from_the_view_is_kept(seed):
    """Property: for a random camera and directional light (no ground), a small box around
    a point q - s d, q a point in view inside the scene's box and d the light's travel,
    is kept by the cull's view test, wherever the box lies."""
    rng = np.random.default_rng(seed)
    cam, q = _points_in_view(rng)
    d = rng.standard_normal(3)
    d /= np.linalg.norm(d)
    p = q - rng.uniform(0.01, 4.0, len(q))[:, None] * d
    reach, _, kept = _blockers_kept(rng, cam, q, p, Light(direction=tuple(d)))
    assert reach is not None and reach.light_frames is not None
    assert kept


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_a_box_that_blocks_a_point_lights_shadow_ray_from_the_view_is_kept(seed):
    """Property: for a random camera and a point light L outside the scene's box (no
    ground), a small box around q + t (L - q), q a point in view inside the scene's box and
    0 < t < 1, is kept by the cull's view test; a light inside that box turns the cull
    off."""
    rng = np.random.default_rng(seed)
    cam, q = _points_in_view(rng)
    light = q.mean(axis=0) + rng.standard_normal(3) * rng.uniform(1.0, 30.0)
    p = q + rng.uniform(0.0, 1.0, len(q))[:, None] * (light - q)
    reach, bounds, kept = _blockers_kept(rng, cam, q, p,
                                         Light(position=tuple(light)))
    if reach is None:  # (outside the box, the box's projection from the light bounds it)
        assert np.all((light >= bounds[0]) & (light <= bounds[1]))
    else:
        assert kept


def test_with_a_ground_a_caster_whose_shadow_misses_the_view_is_culled(tmp_path, monkeypatch):
    """The ground in view under a low sun: a cube out of the picture whose shadow falls on
    the visible ground is kept; a second one whose shadow falls beyond the picture, though
    its box swept along the light reaches the view, is culled (the ground's points in view
    lie in the scene box's shadow on the ground, clipped to the view); the image is the
    full table's."""
    mesh = _cubes(tmp_path, [(6.0, 4.0, 0.0), (6.0, 4.0, -10.0)])
    scene = _cube_scene(mesh, [0.0, 6.0, 6.0], [0.0, 0.0, 0.0], 30.0,
                        {"direction": [-6.0, -4.0, 0.0]}, ground=True)

    lazy = _culled_as_full(scene, monkeypatch)
    assert lazy.stats.faces_culled == 6  # the second cube
    assert np.all(lazy.channels["object_id"] < 0)  # (neither is in the picture)


def _ground_blockers(rng, cam, x, q):
    """Of the points ``x`` (n,3) of casters and their shadows ``q`` on the ground, those
    whose shadow ``cam`` sees: small boxes around random points between each and its
    shadow, and the box of them and those casters (the scene's): (lo, hi, bounds), or None
    when no shadow is in view."""
    frame = cam.frame()
    a = np.linalg.solve(np.stack([frame[3], frame[1], frame[2]], axis=1), (q - frame[0]).T).T
    seen = ((a[:, 0] > 0) & (np.abs(a[:, 1] / a[:, 0] - (cam.width - 1) / 2) <= cam.width / 2)
            & (np.abs(a[:, 2] / a[:, 0] - (cam.height - 1) / 2) <= cam.height / 2))
    if not seen.any():
        return None
    x, q = x[seen], q[seen]
    p = x + rng.uniform(0.0, 1.0, len(x))[:, None] * (q - x)
    r = rng.uniform(1e-4, 0.05, len(p))[:, None]
    lo, hi = p - r, p + r
    return lo, hi, (np.minimum(x, lo).min(axis=0), np.maximum(x, hi).max(axis=0))


def _reach_over_ground(cam, bounds, light, ground):
    """The cull's reach for ``light``'s shadows over the ground plane ``ground`` = (up,
    height), the scene's box ``bounds``."""
    from subtrace.accel.cull import secondary_reach

    scene = SimpleNamespace(render=SimpleNamespace(ao=0, shadows=True), ground=object(),
                            lights=[light])
    return secondary_reach(scene, bounds, cam, ground)


def _ground_case(seed):
    """(rng, a random camera, up, the ground's height, 400 random points whose heights the
    caller sets) of a ground property test."""
    rng = np.random.default_rng(seed)
    cam, _ = _points_in_view(rng, 1)
    return (rng, cam, np.array([0.0, 1.0, 0.0]), float(rng.uniform(-3, 3)),
            rng.uniform(-6, 6, (400, 3)))


def _blockers_and_reach(rng, cam, x, q, light, up, height):
    """(lo, hi, bounds, reach): the boxes between ``x`` and their shadows ``q`` whose shadow
    is in view (:func:`_ground_blockers`) and the cull's reach under ``light`` over the
    ground; None when no shadow is in view."""
    boxes = _ground_blockers(rng, cam, x, q)
    if boxes is None:
        return None
    lo, hi, bounds = boxes
    return lo, hi, bounds, _reach_over_ground(cam, bounds, light, (up, height))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_a_box_that_blocks_a_shadow_ray_from_the_ground_in_view_is_kept(seed):
    """Property: a ground plane, a random camera and a light travelling down onto it; for
    points x of the scene's box above the plane whose shadow q = x + s d on the plane is in
    view, a small box around a point between x and q is kept by the cull's view test."""
    from subtrace.accel.cull import view_test

    rng, cam, up, height, x = _ground_case(seed)
    d = rng.standard_normal(3)
    d[1] = -abs(d[1]) - 0.05
    d /= np.linalg.norm(d)
    x[:, 1] = height + rng.uniform(0.01, 4.0, len(x))
    q = x + ((height - x @ up) / (d @ up))[:, None] * d
    case = _blockers_and_reach(rng, cam, x, q, Light(direction=tuple(d)),
                               up, height)
    if case is None:
        return
    lo, hi, _, reach = case
    assert reach is not None and reach.light_frames is not None
    assert view_test(cam, reach)(lo, hi).all()


def test_a_low_suns_long_shadow_on_the_ground_keeps_its_caster(tmp_path, monkeypatch):
    """A low sun carries a cube's shadow along the ground much further than the scene's
    diagonal: the cube, out of the picture, is kept for the ground in view, and the image is
    the full table's (the sweep once stopped at twice the diagonal and lost the shadow)."""
    mesh = _cubes(tmp_path, [(30.0, 1.5, 0.0)])
    scene = _cube_scene(mesh, [10.0, 6.0, 8.0], [10.0, 0.0, 0.0], 40.0,
                        {"direction": [-1.0, -0.1, 0.0]}, ground=True)

    lazy = _culled_as_full(scene, monkeypatch)
    assert np.all(lazy.channels["object_id"] < 0)  # (the cube is not in the picture)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_a_box_that_blocks_a_point_lights_shadow_ray_from_the_ground_is_kept(seed):
    """Property: a ground plane, a random camera and a point light L above it; for points x
    of the scene's box between the plane and L's height whose shadow q (the ray from L
    through x, on the plane) is in view, a small box around a point between x and q is
    kept by the cull's view test; a box reaching L's height turns the cull off."""
    from subtrace.accel.cull import view_test

    rng, cam, up, height, x = _ground_case(seed)
    light = np.array([rng.uniform(-8, 8), height + rng.uniform(0.5, 12.0), rng.uniform(-8, 8)])
    x[:, 1] = height + rng.uniform(0.0, 1.0, len(x)) * (light[1] - height)
    q = light + ((height - light[1]) / (x[:, 1] - light[1]))[:, None] * (x - light)
    case = _blockers_and_reach(rng, cam, x, q, Light(position=tuple(light)),
                               up, height)
    if case is None:
        return
    lo, hi, bounds, reach = case
    if bounds[1][1] >= light[1]:
        assert reach is None
        return
    assert reach is not None and len(reach.point_views) == 1
    assert view_test(cam, reach)(lo, hi).all()


def test_a_point_light_over_a_ground_keeps_the_casters_of_its_shadows_in_view(tmp_path,
                                                                                monkeypatch):
    """A lamp above the ground in view: a cube out of the picture whose shadow the lamp
    throws onto the visible ground is kept; a second one, as far out of the picture but
    behind the lamp, whose shadow falls away from the view, is culled (it was not bounded
    before: a point light above a ground turned the cull off); the image is the full
    table's."""
    mesh = _cubes(tmp_path, [(4.0, 2.0, 0.0), (14.0, 2.0, 0.0)])
    scene = _cube_scene(mesh, [0.0, 6.0, 6.0], [0.0, 0.0, 0.0], 30.0,
                        {"position": [8.0, 6.0, 0.0], "intensity": 80.0}, ground=True)

    lazy = _culled_as_full(scene, monkeypatch)
    assert lazy.stats.faces_culled == 6  # the second cube
    assert np.all(lazy.channels["object_id"] < 0)  # (neither is in the picture)
