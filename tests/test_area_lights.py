"""The area lights of subtrace/lights.py (kind = "quad", kind = "disk"): their unshadowed
irradiance against the closed-form form factors of a differential area to a disk (1e-9
relative) and against a numerical integral over the emitter (a quad, tilted receivers),
one-sided, of the power of a point light of the same intensity; their penumbra over a
plane behind a straight occluder edge against the analytic share of the emitter's area
and the width of similar triangles (the surfaces' shadow rays and the ground's); a
disk-lit render the same on 1 and 2 threads and in a tile, not culled; bad keys one clear
error naming the file, line and key."""

from __future__ import annotations

import math

import numpy as np
import pytest

from subtrace.errors import SceneError
from subtrace.io.scene import load_scene, scene_from_dict
from subtrace.lights import Light, irradiance_at, light_array, ray_keys, shadow_cast
from subtrace.render import render_scene


def _unit(v):
    v = np.asarray(v, np.float64)
    return tuple(v / np.linalg.norm(v))


def _irradiance(light, p, n):
    """The unshadowed irradiance per unit of colour times intensity at the point p of unit
    normal n (``lights.irradiance_at``: direction and factor)."""
    lx, ly, lz, _, f = irradiance_at(light_array([light]), 0, *map(float, p))
    return f * float(np.dot(n, [lx, ly, lz]))


# --------------------------------------------------------------------------------------
# unshadowed irradiance
# --------------------------------------------------------------------------------------


def _disk_parallel(h, r, radius):
    """The form factor from a differential area parallel to a disk of ``radius``, ``h``
    over its plane and ``r`` off its axis, facing it (textbook form)."""
    z = h * h + r * r + radius * radius
    return 0.5 * (1.0 - (h * h + r * r - radius * radius) / math.sqrt(z * z - 4 * r * r *
                                                                        radius * radius))


def _disk_perpendicular(h, r, radius):
    """The form factor from a differential area perpendicular to the disk's plane, ``h``
    over it and ``r`` > 0 off its axis, facing the axis (textbook form)."""
    z = h * h + r * r + radius * radius
    return h / (2.0 * r) * (z / math.sqrt(z * z - 4 * r * r * radius * radius) - 1.0)


DISK_CENTRE = np.array([0.4, 3.0, -0.3])
DISK_NORMAL = np.array(_unit([0.2, -1.0, 0.1]))  # (facing down, a little tilted)
DISK_RADIUS = 0.7


def _disk_frame():
    """Two unit vectors e1, e2 of the disk's plane."""
    e1 = np.cross(DISK_NORMAL, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(DISK_NORMAL, e1)


@pytest.mark.parametrize("h, r", [(0.5, 0.0), (2.0, 0.0), (1.0, 0.3), (0.3, 0.69),
                                  (2.5, 1.7), (0.1, 2.0), (40.0, 3.0)])
def test_a_disks_irradiance_is_its_form_factor(h, r):
    """At points h over the disk's plane and r off its axis (in two directions of the
    plane): a receiver facing the disk gets pi L F_parallel, one facing the axis pi L
    F_perpendicular where the disk lies wholly in front of it (L = 4 intensity / area),
    within 1e-9 relative."""
    intensity = 2.5
    light = Light(kind_key="disk", position=tuple(DISK_CENTRE), normal=tuple(DISK_NORMAL),
                  radius=DISK_RADIUS, intensity=intensity)
    radiance = 4.0 * intensity / (math.pi * DISK_RADIUS ** 2)
    for e in _disk_frame():
        p = DISK_CENTRE + h * DISK_NORMAL + r * e
        got = _irradiance(light, p, -DISK_NORMAL) * intensity
        want = math.pi * radiance * _disk_parallel(h, r, DISK_RADIUS)
        assert abs(got / want - 1.0) < 1e-9, (got, want)
        if r > DISK_RADIUS:  # (the disk wholly in front of it)
            got = _irradiance(light, p, -e) * intensity
            want = math.pi * radiance * _disk_perpendicular(h, r, DISK_RADIUS)
            assert abs(got / want - 1.0) < 1e-9, (got, want)


def _numeric(light, p, n, steps=1200):
    """The irradiance per unit of colour times intensity at p (unit normal n) by the
    midpoint rule over the emitter's area: radiance cos cos / d^2 dA (a quad's
    parameters; a disk's polar coordinates)."""
    c = np.asarray(light.position)
    mid = (np.arange(steps) + 0.5) / steps
    if light.kind_key == "quad":
        u, v = np.asarray(light.u), np.asarray(light.v)
        a, b = np.meshgrid(2.0 * mid - 1.0, 2.0 * mid - 1.0)
        q = c + a.ravel()[:, None] * u + b.ravel()[:, None] * v
        cross = np.cross(u, v)
        area = 4.0 * np.linalg.norm(cross)
        d_area = np.full(len(q), area / steps ** 2)
        normal = cross / np.linalg.norm(cross)
    else:
        e1, e2 = _disk_frame()
        rad, phi = np.meshgrid(mid * light.radius, mid * 2.0 * math.pi)
        rad, phi = rad.ravel(), phi.ravel()
        q = c + (rad * np.cos(phi))[:, None] * e1 + (rad * np.sin(phi))[:, None] * e2
        area = math.pi * light.radius ** 2
        d_area = rad * (light.radius / steps) * (2.0 * math.pi / steps)
        normal = np.asarray(light.normal)
    w = q - p
    d = np.linalg.norm(w, axis=1)
    w /= d[:, None]
    cos_r, cos_l = np.maximum(w @ n, 0.0), np.maximum(-(w @ normal), 0.0)
    return float(np.sum(4.0 / area * cos_r * cos_l / d ** 2 * d_area))


QUAD = Light(kind_key="quad", position=(0.3, 3.0, -0.2), u=(0.6, 0.1, 0.0), v=(0.0, 0.05, 0.4))
DISK = Light(kind_key="disk", position=tuple(DISK_CENTRE), normal=tuple(DISK_NORMAL),
             radius=DISK_RADIUS)
POINTS = [((0.0, 0.0, 0.0), (0.0, 1.0, 0.0)), ((1.5, 0.5, 0.3), (0.0, 1.0, 0.0)),
          ((1.5, 0.5, 0.3), (-0.6, 0.8, 0.0)), ((0.2, 2.5, 0.1), (0.3, 0.9, -0.2)),
          ((-2.0, 1.0, 1.0), (0.5, 0.5, -0.3))]


@pytest.mark.parametrize("light", [QUAD, DISK], ids=["quad", "disk"])
def test_an_area_lights_irradiance_is_the_integral_over_it(light):
    """Receivers tilted every way (the light wholly above their horizon): the irradiance
    is the numerical integral over the emitter within 1e-6 (the midpoint rule's error)."""
    for p, n in POINTS:
        n = np.array(_unit(n))
        got, want = _irradiance(light, p, n), _numeric(light, np.array(p), n)
        assert want > 0.01 and abs(got / want - 1.0) < 1e-6, (p, n, got, want)


@pytest.mark.parametrize("light", [QUAD, DISK], ids=["quad", "disk"])
def test_an_area_light_is_one_sided_with_a_point_lights_power(light):
    """Nothing behind the emitting side (or in its plane); far away on its axis it lights
    as 4 point lights of its intensity do (its power, 4 pi intensity, sent from one side
    of a Lambertian emitter: radiance times area is 4 intensity), within 1e-6."""
    c = np.asarray(light.position)
    axis = np.array(_unit(np.cross(light.u, light.v))) if light.kind_key == "quad" else \
        np.asarray(light.normal)
    for s in (-0.5, -3.0, 0.0):
        assert _irradiance(light, c + s * axis, -axis) == 0.0
        assert _irradiance(light, c + s * axis, axis) == 0.0
    far = 1000.0
    assert abs(_irradiance(light, c + far * axis, -axis) * far * far / 4.0 - 1.0) < 1e-6


def test_an_area_lights_shadow_rays_are_not_bounded_for_the_cull():
    assert shadow_cast(QUAD) is None and shadow_cast(DISK) is None


# --------------------------------------------------------------------------------------
# penumbra: a light at height H over the plane y = 0, the half-plane y = A, x < 0 between
# --------------------------------------------------------------------------------------

H, A = 4.0, 1.5
RADIUS = 0.8  # (the disk's; the quad's half edge along x)


def _half_plane(origins, dirs, tmax):
    """Any-hit rays against the half-plane y = A, x < 0: blocked (n,) uint8."""
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (A - origins[:, 1]) / dirs[:, 1]
    x = origins[:, 0] + s * dirs[:, 0]
    return ((s > 0.0) & (s < tmax) & (x < 0.0)).astype(np.uint8)


def _plane_points():
    """Points of the plane y = 0 across the penumbra (x in [-1.2, 1.2]) in a few rows,
    seen from an eye above: (points, frame (4,3) with the eye, unit directions, t)."""
    x, z = np.meshgrid(np.linspace(-1.2, 1.2, 241), np.linspace(-0.3, 0.3, 3))
    points = np.stack([x.ravel(), np.zeros(x.size), z.ravel()], axis=1)
    eye = np.array([0.3, 9.0, 2.0])
    v = points - eye
    t = np.sqrt((v * v).sum(axis=1))
    frame = np.array([eye, [1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]])
    return points, frame, np.ascontiguousarray(v / t[:, None]), t


def _cut(x):
    """Where the plane through the point (x, 0, z) and the edge meets the light's plane
    y = H: the light's points of x above it are seen past the half-plane."""
    return -x * (H - A) / A


def _disk_share(x):
    """The share of the disk's area (centre (0, H, 0)) with x above :func:`_cut`."""
    c = min(max(_cut(x) / RADIUS, -1.0), 1.0)
    return (math.acos(c) - c * math.sqrt(1.0 - c * c)) / math.pi


def _quad_share(x):
    """The share of the quad's area (x within RADIUS of 0) with x above :func:`_cut`."""
    return min(max((RADIUS - _cut(x)) / (2.0 * RADIUS), 0.0), 1.0)


DOWN_DISK = Light(kind_key="disk", position=(0.0, H, 0.0), normal=(0.0, -1.0, 0.0),
                  radius=RADIUS, samples=256)
DOWN_QUAD = Light(kind_key="quad", position=(0.0, H, 0.0), u=(RADIUS, 0.0, 0.0),
                  v=(0.0, 0.0, 0.5), samples=256)  # (u x v = (0, -0.4, 0): facing down)


def _check_penumbra(got, points, share):
    """``got`` against the analytic share (within 0.03, 0.006 on average), and the
    penumbra's width against similar triangles (the light's width times A / (H - A)): every
    point outside it all dark or all lit, exactly, and every point more than 3 steps of
    the points inside it (the rim's sliver of a disk below one ray in 256) in between."""
    x = points[:, 0]
    want = np.array([share(v) for v in x])
    assert want.min() == 0.0 and want.max() == 1.0
    assert np.count_nonzero((want > 0.05) & (want < 0.95)) > 100
    err = np.abs(got - want)
    assert err.max() < 0.03 and err.mean() < 0.006, (err.max(), err.mean())
    half = RADIUS * A / (H - A)
    step = x[1] - x[0]
    assert np.all(got[x < -half - 1e-9] == 0.0) and np.all(got[x > half + 1e-9] == 1.0)
    inside = np.abs(x) < half - 3.0 * step
    assert np.all((got[inside] > 0.0) & (got[inside] < 1.0))
    # (measured: from the last point all dark to the first all lit)
    measured = x[got == 1.0].min() - x[got == 0.0].max()
    assert 2.0 * half - 8.0 * step <= measured <= 2.0 * half + 2.0 * step, measured


@pytest.mark.parametrize("light, share", [(DOWN_DISK, _disk_share), (DOWN_QUAD, _quad_share)],
                         ids=["disk", "quad"])
def test_an_area_lights_penumbra_on_a_surface(light, share):
    """``shade.shadow_visibility`` with 256 rays per point: the analytic share of the
    emitter's area a point sees past the edge, and the penumbra as wide as similar
    triangles make it (diameter times A / (H - A))."""
    from subtrace.shade import shadow_visibility

    points, frame, dirs, t = _plane_points()
    normals = np.tile([0.0, 1.0, 0.0], (len(t), 1))
    assert light.kind_key == "disk" or np.cross(light.u, light.v)[1] < 0.0  # (facing down)
    visible = shadow_visibility(_half_plane, frame, 1, t, normals, np.zeros(len(t), np.int32),
                                light_array([light]), 0.0, dirs, ray_keys(np.arange(len(t))))
    _check_penumbra(visible[0].astype(np.float64), points, share)


def test_a_disk_lights_penumbra_on_the_ground():
    """The ground's shadow rays (``shade.ground_pixels``, a shadow catcher over a white
    background, no headlight): the share of the background a ground point keeps is its
    share of the disk, as on a surface."""
    from subtrace.shade import CHANNELS, C_R, ground_pixels

    points, frame, dirs, t = _plane_points()
    n = len(t)
    planes = np.zeros((len(CHANNELS), n), np.float32)
    ground_pixels(frame, 1, np.full(n, -1, np.int32), (0.0, 1.0, 0.0), 0.0, _half_plane,
                  light_array([DOWN_DISK]), 0.0, None, np.ones((n, 3)), planes, dirs,
                  keys=ray_keys(np.arange(n)))
    _check_penumbra(planes[C_R].astype(np.float64), points, _disk_share)


# --------------------------------------------------------------------------------------
# renders and scene keys
# --------------------------------------------------------------------------------------

CUBE = ("v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\n"
        "v -1 1 1\nf 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n")
DISK_TABLE = {"kind": "disk", "position": [1.5, 4.0, 1.0], "normal": [-0.3, -1.0, -0.2],
              "radius": 0.8, "samples": 4, "intensity": 3.0}


def _cube_scene(tmp_path, light, samples=4, width=64, height=48):
    path = tmp_path / "cube.obj"
    path.write_text(CUBE)
    return scene_from_dict({
        "object": [{"mesh": str(path)}],
        "camera": {"eye": [3.0, 6.0, 7.0], "target": [0.8, -1.0, 0.4], "width": width,
                   "height": height},
        "render": {"headlight": False, "samples": samples, "background": [0.5] * 3},
        "light": [light], "ground": {"height": -1.5, "color": [0.8, 0.8, 0.8]}},
        base_dir=tmp_path)


def test_a_disk_lit_render_does_not_depend_on_threads_or_tiles(tmp_path):
    """With adaptive anti-aliasing: the same image on 1 and 2 threads, a tile of it alone
    is its pixels bit for bit, the ground holds a penumbra (shares between its lit and
    shadowed values) and the faces turned from the light are black."""
    scene = _cube_scene(tmp_path, DISK_TABLE)
    one = render_scene(scene, threads=1).channels
    two = render_scene(scene, threads=2).channels
    for c in one:
        assert one[c].tobytes() == two[c].tobytes(), c
    tile = render_scene(scene, threads=2, crop=(16, 8, 48, 40)).channels
    for c in one:
        assert tile[c].tobytes() == np.ascontiguousarray(one[c][8:40, 16:48]).tobytes(), c
    ground = ~np.isfinite(one["Z"]) & (one["R"] != np.float32(0.5))
    lit = one["R"][ground].max()
    assert lit > 0.05
    between = ground & (one["R"] > 0.1 * lit) & (one["R"] < 0.6 * lit)
    assert np.count_nonzero(between) > 20


@pytest.mark.parametrize("body, key, words", [
    ('kind = "tube"\nposition = [0, 3, 0]\n', "light[0].kind", "one of 'quad', 'disk'"),
    ('kind = 3\nposition = [0, 3, 0]\n', "light[0].kind", "one of"),
    ('kind = "disk"\nposition = [0, 3, 0]\nnormal = [0, -1, 0]\n', "light[0]",
     "missing key radius"),
    ('kind = "disk"\nposition = [0, 3, 0]\nnormal = [0, 0, 0]\nradius = 1\n',
     "light[0].normal", "zero"),
    ('kind = "disk"\nposition = [0, 3, 0]\nnormal = [0, -1, 0]\nradius = 0\n',
     "light[0].radius", "more than 0"),
    ('kind = "disk"\nposition = [0, 3, 0]\nnormal = [0, -1, 0]\nradius = 1\nu = [1, 0, 0]\n',
     "light[0].u", "not a key of a disk"),
    ('kind = "quad"\nposition = [0, 3, 0]\nu = [1, 0, 0]\nv = [2, 0, 0]\n', "light[0].v",
     "not parallel"),
    ('kind = "quad"\nposition = [0, 3, 0]\nu = [1, 0, 0]\n', "light[0]", "missing key v"),
    ('kind = "quad"\nposition = [0, 3, 0]\nu = [1, 0, 0]\nv = [0, 0, 1]\nsamples = 0\n',
     "light[0].samples", "from 1 to"),
    ('kind = "quad"\nposition = [0, 3, 0]\nu = [1, 0, 0]\nv = [0, 0, 1]\nradius = 1\n',
     "light[0].radius", "not a key of a quad"),
])
def test_bad_area_lights_are_one_clear_error(tmp_path, body, key, words):
    (tmp_path / "cube.obj").write_text(CUBE)
    text = '[[object]]\nmesh = "cube.obj"\n\n[[light]]\n' + body
    path = tmp_path / "scene.toml"
    path.write_text(text)
    with pytest.raises(SceneError) as err:
        load_scene(path)
    message = str(err.value)
    assert key in message and words in message, message
    lines = text.splitlines()
    line = (lines.index("[[light]]") if key == "light[0]" else next(
        i for i, x in enumerate(lines) if x.startswith(key.split(".")[-1] + " "))) + 1
    assert f"{path}:{line}" in message, message


def test_a_good_area_light_table_loads(tmp_path):
    (tmp_path / "cube.obj").write_text(CUBE)
    path = tmp_path / "scene.toml"
    path.write_text('[[object]]\nmesh = "cube.obj"\n\n[[light]]\nkind = "disk"\n'
                    'position = [0, 3, 0]\nnormal = [0, -2, 0]\nradius = 0.5\n\n[[light]]\n'
                    'kind = "quad"\nposition = [0, 3, 0]\nu = [1, 0, 0]\nv = [0, 0, -1]\n'
                    'intensity = 2\n')
    disk, quad = load_scene(path).lights
    assert disk == Light(kind_key="disk", position=(0.0, 3.0, 0.0), normal=(0.0, -1.0, 0.0),
                         radius=0.5)
    assert quad == Light(kind_key="quad", position=(0.0, 3.0, 0.0), u=(1.0, 0.0, 0.0),
                         v=(0.0, 0.0, -1.0), intensity=2.0)
