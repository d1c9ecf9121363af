"""Ambient occlusion (shade.ambient_occlusion through picture.paint): a point in a concave
corner is darker than one on an open convex face; a convex surface never occludes itself;
0 rays is no ambient occlusion, bit for bit; the cosine-weighted directions; the image does
not depend on the thread count; the ground darkens beside an object standing on it and
nowhere else; the smoothing (shade.smooth_occlusion) keeps constants, removes most of the
grain and mixes neither objects nor surfaces apart in depth."""

from __future__ import annotations

import numpy as np
import pytest

from subtrace.io.scene import apply_overrides, scene_from_dict
from subtrace.render import render_scene
from subtrace import config
from subtrace.camera import Camera
from subtrace.shade import ao_directions, pixel_rays, smooth_occlusion

CUBE = ("v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\n"
        "v -1 1 1\nf 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n")
# every edge infinitely sharp: the limit surface is the cube itself (flat faces, a
# concave corner where the block meets the slab)
SHARP = "".join(f"t crease 2/1/0 {a} {b} 10\n" for a, b in (
    (0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6),
    (3, 7)))


def _box(path, lo, hi, sharp=True):
    """A cube cage scaled into the box lo..hi."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    lines = []
    for line in CUBE.splitlines():
        if line.startswith("v "):
            p = (np.array([float(x) for x in line.split()[1:]]) + 1) / 2 * (hi - lo) + lo
            line = "v " + " ".join(f"{x:.6f}" for x in p)
        lines.append(line)
    path.write_text("\n".join(lines) + "\n" + (SHARP if sharp else ""))
    return str(path)


def _scene(tmp_path, objects, ao, eye=(3.0, 4.0, 5.0), target=(0.0, 0.0, 0.0), size=(96, 72)):
    return scene_from_dict({
        "object": [{"mesh": m} for m in objects],
        "camera": {"eye": list(eye), "target": list(target), "width": size[0],
                   "height": size[1]},
        "render": {"headlight": True, "headlight_intensity": 1.0, "shadows": False,
                   "samples": 1, "ao": ao, "background": [0.0, 0.0, 0.0]},
        "light": [], "ground": False,  # (the headlight alone)
    }, base_dir=tmp_path)


@pytest.fixture
def block_on_slab(tmp_path):
    """A 1x1x1 block standing on a 6x0.5x6 slab."""
    slab = _box(tmp_path / "slab.obj", (-3, -0.5, -3), (3, 0, 3))
    block = _box(tmp_path / "block.obj", (-0.5, 0, -0.5), (0.5, 1, 0.5))
    return [slab, block]


def _pixel_of(result, point):
    """(row, col) of the pixel whose centre ray passes nearest ``point``."""
    d = result.camera.ray_directions()
    v = np.asarray(point) - np.asarray(result.camera.eye)
    v /= np.linalg.norm(v)
    return np.unravel_index(np.argmax(d @ v), d.shape[:2])


def test_concave_corner_is_darker_than_an_open_face(tmp_path, block_on_slab):
    """With shadows off and only the headlight, a pixel's colour with ambient occlusion
    over its colour without is the share of its AO rays that escape: 1 on the block's
    open top (nothing above it), well below 1 on the slab in the corner beside the block
    (a quarter of the hemisphere is the block's wall), and 1 far out on the slab."""
    off = render_scene(_scene(tmp_path, block_on_slab, 0))
    on = render_scene(_scene(tmp_path, block_on_slab, 64))
    with np.errstate(invalid="ignore", divide="ignore"):
        share = on.channels["R"].astype(np.float64) / off.channels["R"]
    top = share[_pixel_of(off, (0.0, 1.0, 0.0))]
    corner = share[_pixel_of(off, (0.55, 0.0, 0.55))]  # the slab beside the block's corner
    far = share[_pixel_of(off, (2.5, 0.0, 2.5))]
    assert top == 1.0 and far == 1.0
    # (the corner between two walls: cos-weighted, about half the rays hit a wall)
    assert corner < 0.8
    assert on.stats.ao_rays == 64 * on.stats.pixels_covered


def test_a_convex_surface_does_not_occlude_itself(tmp_path):
    """A smooth convex closed surface (the cube's limit surface): every AO ray escapes, so
    the colour with ambient occlusion is bit for bit the colour without (the rays leave the
    surface by its error bound, as shadow rays do)."""
    cube = _box(tmp_path / "cube.obj", (-1, -1, -1), (1, 1, 1), sharp=False)
    off = render_scene(_scene(tmp_path, [cube], 0)).channels
    on = render_scene(_scene(tmp_path, [cube], 16)).channels
    assert (on["A"] > 0).sum() > 500
    for c in "RGB":
        assert np.array_equal(on[c], off[c]), c


def test_zero_rays_is_no_ambient_occlusion(tmp_path, block_on_slab):
    """``ao = 0`` renders exactly what a scene without the key renders."""
    scene = _scene(tmp_path, block_on_slab, 0)
    plain = scene_from_dict({
        "object": [{"mesh": m} for m in block_on_slab],
        "camera": {"eye": [3.0, 4.0, 5.0], "target": [0.0, 0.0, 0.0], "width": 96,
                   "height": 72},
        "render": {"headlight": True, "headlight_intensity": 1.0, "shadows": False,
                   "samples": 1, "background": [0.0, 0.0, 0.0]},
        "light": [], "ground": False,
    }, base_dir=tmp_path)
    a, b = render_scene(scene), render_scene(plain)
    assert a.stats.ao_rays == 0
    for c in a.channels:
        assert a.channels[c].tobytes() == b.channels[c].tobytes(), c


def test_ambient_occlusion_does_not_depend_on_the_threads(tmp_path, block_on_slab):
    scene = apply_overrides(_scene(tmp_path, block_on_slab, 8), samples=4)
    one = render_scene(scene, threads=1).channels
    two = render_scene(scene, threads=2).channels
    for c in one:
        assert one[c].tobytes() == two[c].tobytes(), c


def test_directions_are_cosine_weighted():
    """The directions lie in the normal's hemisphere, unit, with the cosine-weighted
    moments: E[cos] = 2/3 and E[cos^2] = 1/2 (over many ids), and a row's set depends only
    on its id."""
    rng = np.random.default_rng(7)
    n = rng.normal(size=(2000, 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    ids = np.arange(2000, dtype=np.int64)
    d = ao_directions(n, ids, 16)
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0)
    cos = (d.reshape(2000, 16, 3) * n[:, None]).sum(-1)
    assert cos.min() >= 0.0
    assert cos.mean() == pytest.approx(2 / 3, abs=0.01)
    assert (cos ** 2).mean() == pytest.approx(0.5, abs=0.01)
    again = ao_directions(n[::-1], ids[::-1], 16).reshape(2000, 16, 3)[::-1]
    assert np.array_equal(again.reshape(-1, 3), d)


def _ground_scene(tmp_path, block, ao, color):
    data = {
        "object": [{"mesh": block}],
        "camera": {"eye": [3.0, 4.0, 5.0], "target": [0.0, 0.0, 0.0], "width": 96,
                   "height": 72},
        "render": {"headlight": True, "headlight_intensity": 1.0, "shadows": False,
                   "samples": 1, "ao": ao, "background": [0.5, 0.6, 0.7]},
        "ground": {} if color is None else {"color": color},
        "light": [],  # (the headlight alone)
    }
    return scene_from_dict(data, base_dir=tmp_path)


@pytest.mark.parametrize("smooth", [0, 3])  # each pixel's own rays; smoothed
@pytest.mark.parametrize("color", [[0.6, 0.6, 0.6], None])  # opaque, a shadow catcher
def test_ground_darkens_beside_an_object_and_nowhere_else(tmp_path, color, smooth,
                                                          monkeypatch):
    """A block standing on the ground (at its lowest point): with ambient occlusion the
    ground beside the block's corner keeps about 3/4 of its colour (a quarter of its
    cosine-weighted hemisphere is the block's: under 80 % from its own rays; under 85 %
    smoothed over 3 pixels, every other ground pixel traced, at this coarse 96x72, where 3
    pixels reach well into the lighter ground around), while the ground far from the
    block (beyond the rays' reach) keeps its colour bit for bit, and so does every pixel of
    the block's open top."""
    monkeypatch.setattr(config, "AO_SMOOTH_RADIUS", smooth)
    block = _box(tmp_path / "block.obj", (-0.5, 0, -0.5), (0.5, 1, 0.5))
    off = render_scene(_ground_scene(tmp_path, block, 0, color))
    on = render_scene(_ground_scene(tmp_path, block, 32, color))
    with np.errstate(invalid="ignore", divide="ignore"):
        share = on.channels["R"].astype(np.float64) / off.channels["R"]
    corner = share[_pixel_of(off, (0.55, 0.0, 0.55))]
    assert off.channels["A"][_pixel_of(off, (0.55, 0.0, 0.55))] == 0  # the ground's
    assert 0.6 < corner < (0.85 if smooth else 0.8)
    far = _pixel_of(off, (-2.5, 0.0, 3.0))  # 3 from the block: past 0.2 of its diagonal
    assert on.channels["R"][far] == off.channels["R"][far]
    assert share[_pixel_of(off, (0.0, 1.0, 0.0))] == 1.0


def _plane_grid(width=48, height=36):
    """A camera looking straight down at the plane z = 0 from z = 10: each pixel's frame,
    distance to the plane and the plane's normal."""
    camera = Camera((0.0, 0.0, 10.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 40.0, width, height)
    frame = camera.frame()
    d = pixel_rays(frame, width, np.arange(width * height))
    t = 10.0 / -d[:, 2]
    normals = np.repeat(np.array([[0.0, 0.0, 1.0]]), len(t), axis=0)
    return camera, frame, t, normals


def test_smoothing_keeps_a_constant_and_removes_most_of_the_grain():
    camera, frame, t, normals = _plane_grid()
    group = np.zeros(len(t), np.int64)
    rad = camera.pixel_angle()
    flat = np.full(len(t), 0.625, np.float32)
    assert np.array_equal(smooth_occlusion(frame, 48, t, normals, group, flat, rad, 3), flat)
    rng = np.random.default_rng(3)
    noisy = (0.8 + 0.1 * rng.standard_normal(len(t))).astype(np.float32)
    smooth = smooth_occlusion(frame, 48, t, normals, group, noisy, rad, 3)
    inner = np.zeros((36, 48), bool)
    inner[3:-3, 3:-3] = True
    inner = inner.ravel()
    assert smooth[inner].std() < noisy[inner].std() / 3
    assert abs(smooth[inner].mean() - noisy[inner].mean()) < 0.01
    assert np.array_equal(smooth_occlusion(frame, 48, t, normals, group, noisy, rad, 0),
                          noisy)


def test_smoothing_mixes_no_objects_no_depths_and_leaves_other_pixels():
    """Left half object 0 (value 1), right half object 1 (value 0): unchanged. One object
    whose right half lies twice as far (a step in depth): unchanged too. Pixels of group -1
    keep their values."""
    camera, frame, t, normals = _plane_grid()
    rad = camera.pixel_angle()
    col = np.arange(len(t)) % 48
    values = np.where(col < 24, 1.0, 0.0).astype(np.float32)
    two = np.where(col < 24, 0, 1).astype(np.int64)
    assert np.array_equal(smooth_occlusion(frame, 48, t, normals, two, values, rad, 3), values)
    step = np.where(col < 24, t, 2.0 * t)
    one = np.zeros(len(t), np.int64)
    assert np.array_equal(smooth_occlusion(frame, 48, step, normals, one, values, rad, 3),
                          values)
    none = np.full(len(t), -1, np.int64)
    noisy = np.random.default_rng(5).random(len(t)).astype(np.float32)
    assert np.array_equal(smooth_occlusion(frame, 48, t, normals, none, noisy, rad, 3), noisy)
