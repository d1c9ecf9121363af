"""The lights room (subtrace/lights.py): the sphere light's penumbra against the analytic
share of the ball a point sees past a straight edge (the surfaces' shadow rays and the
ground's), a sphere of radius 0 is the point light bit for bit and one of a tiny radius
nearly so, the soft shadows do not depend on the threads or on cutting the image into a
tile, and bad values are one clear error naming the file, line and key."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from subtrace.errors import SceneError
from subtrace.io.scene import load_scene, scene_from_dict
from subtrace.lights import Light, light_array, ray_keys
from subtrace.render import render_scene
from subtrace.runtime import threads as tasks

# a ball of radius R at height H over the plane y = 0, and an opaque half-plane y = A,
# x < 0 between them: its edge (x = 0, y = A) casts a penumbra on the plane around x = 0
H, R, A = 4.0, 0.8, 1.5


def _visible_share(p, centre, radius):
    """The share of the ball's solid angle that the point p sees past the half-plane
    (:func:`_cone_share` of the cone it subtends)."""
    v = centre - p
    dist = float(np.linalg.norm(v))
    return _cone_share(p, v / dist, math.asin(radius / dist))


def _cone_share(p, w, a):
    """The share of the cone of directions within ``a`` of the unit ``w`` that the point p
    sees past the half-plane: the cone's cap cut by the plane through p and the edge (a
    spherical cap's segment: 2 (acos(sin b / sin a) - cos a acos(tan b / tan a)) of the
    smaller side, b the axis's angle from the cutting plane)."""
    # the plane holds p, the edge's direction (0, 0, 1) and its point (0, A, 0); its normal
    # (A, x, 0) points to the side the half-plane does not cover
    n = np.array([A, p[0], 0.0])
    n /= np.linalg.norm(n)
    b = math.asin(float(w @ n))
    if b >= a:
        return 1.0
    if b <= -a:
        return 0.0
    cap = 2.0 * math.pi * (1.0 - math.cos(a))
    seg = 2.0 * (math.acos(math.sin(abs(b)) / math.sin(a))
                 - math.cos(a) * math.acos(math.tan(abs(b)) / math.tan(a)))
    return 1.0 - seg / cap if b >= 0.0 else seg / cap


def _half_plane(origins, dirs, tmax):
    """Any-hit rays against the half-plane y = A, x < 0: blocked (n,) uint8."""
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (A - origins[:, 1]) / dirs[:, 1]
    x = origins[:, 0] + s * dirs[:, 0]
    return ((s > 0.0) & (s < tmax) & (x < 0.0)).astype(np.uint8)


def _plane_points():
    """Points of the plane y = 0 across the penumbra (x in [-1.2, 1.2]), a few rows in z,
    seen from an eye above: (frame (4,3) with the eye, unit directions, distances)."""
    x, z = np.meshgrid(np.linspace(-1.2, 1.2, 121), np.linspace(-0.3, 0.3, 5))
    points = np.stack([x.ravel(), np.zeros(x.size), z.ravel()], axis=1)
    eye = np.array([0.3, 9.0, 2.0])
    v = points - eye
    t = np.sqrt((v * v).sum(axis=1))
    frame = np.array([eye, [1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]])
    return points, frame, np.ascontiguousarray(v / t[:, None]), t


def _share_errors(got, points, centre):
    want = np.array([_visible_share(p, centre, R) for p in points])
    assert want.min() == 0.0 and want.max() == 1.0  # (umbra, penumbra and light)
    assert np.count_nonzero((want > 0.05) & (want < 0.95)) > 100
    return np.abs(got - want)


@pytest.mark.parametrize("threads", [1, 2])
def test_the_penumbra_on_a_surface_is_the_share_of_the_ball_it_sees(threads):
    """``shade.shadow_visibility`` with a sphere light of 256 rays per point: each point's
    visibility is the analytic share within 0.03, and 0.006 on average (the error of 256
    stratified points on a cap cut by a line; the rays do not depend on the threads)."""
    from subtrace.shade import shadow_visibility

    points, frame, dirs, t = _plane_points()
    centre = np.array([0.0, H, 0.0])
    lights = light_array([Light(position=tuple(centre), radius=R, samples=256)])
    normals = np.tile([0.0, 1.0, 0.0], (len(t), 1))
    tasks.set_threads(threads)
    try:
        visible = shadow_visibility(_half_plane, frame, 1, t, normals,
                                    np.zeros(len(t), np.int32), lights, 0.0, dirs,
                                    ray_keys(np.arange(len(t))))
    finally:
        tasks.set_threads(None)
    err = _share_errors(visible[0].astype(np.float64), points, centre)
    assert err.max() < 0.03 and err.mean() < 0.006, (err.max(), err.mean())


def test_the_penumbra_on_the_ground_is_the_share_of_the_ball_it_sees():
    """The ground's shadow rays (``shade.ground_pixels``, a shadow catcher over a white
    background, no headlight): the share of the background a ground point keeps is its
    share of the ball, as on a surface."""
    from subtrace.shade import CHANNELS, C_R, ground_pixels

    points, frame, dirs, t = _plane_points()
    n = len(t)
    centre = np.array([0.0, H, 0.0])
    lights = light_array([Light(position=tuple(centre), radius=R, samples=256)])
    planes = np.zeros((len(CHANNELS), n), np.float32)
    ground_pixels(frame, 1, np.full(n, -1, np.int32), (0.0, 1.0, 0.0), 0.0, _half_plane,
                  lights, 0.0, None, np.ones((n, 3)), planes, dirs, keys=ray_keys(np.arange(n)))
    err = _share_errors(planes[C_R].astype(np.float64), points, centre)
    assert err.max() < 0.03 and err.mean() < 0.006, (err.max(), err.mean())


def test_a_soft_suns_penumbra_is_the_share_of_its_disc_it_sees():
    """A directional light of angle 20 degrees (256 rays a point) over the half-plane:
    each point's visibility is the share of the cone of 10 degrees around the direction
    to the light that it sees past the edge, as for a sphere light; at angle 0 it is the
    hard directional light, ray for ray."""
    from subtrace.shade import shadow_visibility

    points, frame, dirs, t = _plane_points()
    normals = np.tile([0.0, 1.0, 0.0], (len(t), 1))
    travel = np.array([0.15, -1.0, 0.1])
    travel /= np.linalg.norm(travel)

    def visibility(light):
        return shadow_visibility(_half_plane, frame, 1, t, normals,
                                 np.zeros(len(t), np.int32), light_array([light]), 0.0,
                                 dirs, ray_keys(np.arange(len(t))))[0].astype(np.float64)

    got = visibility(Light(direction=tuple(travel), angle=20.0, samples=256))
    want = np.array([_cone_share(p, -travel, math.radians(10.0)) for p in points])
    assert want.min() == 0.0 and want.max() == 1.0
    assert np.count_nonzero((want > 0.05) & (want < 0.95)) > 100
    err = np.abs(got - want)
    assert err.max() < 0.03 and err.mean() < 0.006, (err.max(), err.mean())
    hard = visibility(Light(direction=tuple(travel)))
    np.testing.assert_array_equal(visibility(Light(direction=tuple(travel), angle=0.0)), hard)
    # (the hard light: the edge's shadow line, all or nothing)
    assert set(np.unique(hard)) == {0.0, 1.0}


def test_one_ray_a_point_is_jittered_over_the_light():
    """A sphere light (or soft sun) of one shadow ray per shading point sends each point's
    ray to its own point of the ball: in the umbra and in full light every point gets the
    analytic 0 or 1, in the penumbra both occur (not one hard edge), and their mean follows
    the analytic share there (the rest is left to the anti-aliasing rays)."""
    from subtrace.shade import shadow_visibility

    points, frame, dirs, t = _plane_points()
    centre = np.array([0.0, H, 0.0])
    normals = np.tile([0.0, 1.0, 0.0], (len(t), 1))
    got = shadow_visibility(_half_plane, frame, 1, t, normals, np.zeros(len(t), np.int32),
                            light_array([Light(position=tuple(centre), radius=R, samples=1)]),
                            0.0, dirs, ray_keys(np.arange(len(t))))[0].astype(np.float64)
    want = np.array([_visible_share(p, centre, R) for p in points])
    sure = (want == 0.0) | (want == 1.0)
    np.testing.assert_array_equal(got[sure], want[sure])
    mid = (want > 0.2) & (want < 0.8)
    assert set(np.unique(got[mid])) == {0.0, 1.0}
    assert abs(got[mid].mean() - want[mid].mean()) < 0.1


CUBE = ("v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\n"
        "v -1 1 1\nf 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n")


def _cube_scene(tmp_path, light, samples=1):
    path = tmp_path / "cube.obj"
    path.write_text(CUBE)
    return scene_from_dict({
        "object": [{"mesh": str(path)}],
        "camera": {"eye": [3.0, 6.0, 7.0], "target": [0.8, -1.0, 0.4], "width": 64,
                   "height": 48},
        "render": {"headlight": False, "samples": samples, "background": [0.5] * 3},
        "light": [light], "ground": {"height": -1.5}}, base_dir=tmp_path)


LAMP = [1.5, 4.0, 1.0]


def test_a_sphere_of_radius_0_is_the_point_light(tmp_path):
    """Radius 0: every channel bit for bit the point light's; a radius of 1e-7 changes only
    pixels on the shadows' outlines, and those by a share of its rays."""
    point = render_scene(_cube_scene(tmp_path, {"position": LAMP})).channels
    zero = render_scene(_cube_scene(tmp_path, {"position": LAMP, "radius": 0.0})).channels
    for c in point:
        assert point[c].tobytes() == zero[c].tobytes(), c
    tiny = render_scene(_cube_scene(tmp_path, {"position": LAMP, "radius": 1e-7})).channels
    for c in point:
        if c not in ("R", "G", "B"):
            assert np.array_equal(point[c], tiny[c], equal_nan=True), c
    differ = np.abs(point["R"] - tiny["R"]) > 1e-6
    assert np.count_nonzero(differ) <= 0.01 * differ.size


SUN = [-0.3, -1.0, -0.2]


@pytest.mark.parametrize("soft, hard_light", [
    ({"position": LAMP, "radius": 0.6, "samples": 4}, {"position": LAMP}),
    ({"direction": SUN, "angle": 12.0, "samples": 4}, {"direction": SUN}),
])
def test_soft_shadows_do_not_depend_on_threads_or_tiles(tmp_path, soft, hard_light):
    """A sphere light, and a soft sun, with adaptive anti-aliasing (its extra rays take
    further points of each pixel's sequence): the same image on 1 and 2 threads, and a
    tile of it rendered alone is its pixels bit for bit; the penumbra holds shares between
    0 and 1."""
    scene = _cube_scene(tmp_path, soft, samples=4)
    one = render_scene(scene, threads=1).channels
    two = render_scene(scene, threads=2).channels
    for c in one:
        assert one[c].tobytes() == two[c].tobytes(), c
    tile = render_scene(scene, threads=2, crop=(16, 8, 48, 40)).channels
    for c in one:
        assert tile[c].tobytes() == np.ascontiguousarray(one[c][8:40, 16:48]).tobytes(), c
    hard = render_scene(_cube_scene(tmp_path, hard_light, samples=4)).channels
    ground = ~np.isfinite(one["Z"])
    soft = ground & (np.abs(one["R"] - hard["R"]) > 1e-3)
    assert np.count_nonzero(soft) > 20  # (a penumbra where the hard shadow had an edge)


@pytest.mark.parametrize("body, key, words", [
    ("position = [0, 3, 0]\nradius = -0.5\n", "light[0].radius", "0 or more"),
    ("radius = 0.5\n", "light[0]", "missing key position"),
    ("position = [0, 3, 0]\nradius = 0.5\nsamples = 0\n", "light[0].samples", "from 1 to"),
    ("position = [0, 3, 0]\nsamples = 4\n", "light[0].samples", "not a key of a point"),
    ("direction = [0, -1, 0]\nradius = 0.5\n", "light[0].direction", "not a key of a sphere"),
    ("direction = [0, -1, 0]\nangle = -1\n", "light[0].angle", "from 0 to 90"),
    ("direction = [0, -1, 0]\nangle = 120\n", "light[0].angle", "from 0 to 90"),
    ("position = [0, 3, 0]\nangle = 2\n", "light[0].angle", "not a key of a point"),
])
def test_bad_sphere_lights_are_one_clear_error(tmp_path, body, key, words):
    (tmp_path / "cube.obj").write_text(CUBE)
    text = '[[object]]\nmesh = "cube.obj"\n\n[[light]]\n' + body
    path = tmp_path / "scene.toml"
    path.write_text(text)
    with pytest.raises(SceneError) as err:
        load_scene(path)
    message = str(err.value)
    assert key in message and words in message, message
    line = text.splitlines().index(body.splitlines()[0] if key == "light[0]" else next(
        x for x in body.splitlines() if x.startswith(key.split(".")[-1]))) + 1
    if key == "light[0]":
        line -= 1  # (the table's own line: [[light]])
    assert f"{path}:{line}" in message, message


def test_a_bad_sphere_light_on_the_command_line_exits_2_with_one_line(tmp_path):
    (tmp_path / "cube.obj").write_text(CUBE)
    path = tmp_path / "scene.toml"
    path.write_text('[[object]]\nmesh = "cube.obj"\n\n[[light]]\nposition = [0, 3, 0]\n'
                    'radius = -1\n')
    run = subprocess.run([sys.executable, "-m", "subtrace.cli", "render", str(path), "-o",
                          str(tmp_path / "out.exr")], capture_output=True, text=True)
    assert run.returncode == 2, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and f"{path}:6" in lines[0] and "radius" in lines[0], run.stderr
    assert not (tmp_path / "out.exr").exists()
