"""The environment light of subtrace/lights.py (kind = "environment", a lat-long ``file`` or
a constant ``color``): its irradiance against the analytic pi L of a constant environment
and pi (L1 (1 + cos) / 2 + L2 (1 - cos) / 2) of one colour per hemisphere (the kernel's,
and a white convex object's shaded value in a render), its shadow rays drawn by the
image's luminance, their cosine-weighted visibility past a half-plane against the analytic
share converging with samples, and a missing or unreadable file one clear error (exit 2)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from subtrace.cli import main
from subtrace.errors import SceneError
from subtrace.io.exr import write_exr
from subtrace.io.scene import load_scene, scene_from_dict
from subtrace.lights import (Light, environment_irradiance, light_array, ray_keys,
                             shadow_cast, shadow_target)
from subtrace.render import render_scene

TOP, BOTTOM = np.array([0.75, 0.625, 0.375]), np.array([0.125, 0.25, 0.3125])  # (halfs)


def _two_colour(path, width=64, height=32):
    """A lat-long image of TOP over its upper half (+Y) and BOTTOM below."""
    rgb = np.empty((height, width, 3), np.float32)
    rgb[: height // 2], rgb[height // 2:] = TOP, BOTTOM
    write_exr(path, {"R": rgb[..., 0], "G": rgb[..., 1], "B": rgb[..., 2]})
    return str(path)


def _want_two_colour(ny):
    return math.pi * (TOP * (1.0 + ny) / 2.0 + BOTTOM * (1.0 - ny) / 2.0)


def _normals(n=40):
    rng = np.random.default_rng(3)
    v = rng.normal(size=(n, 3))
    return np.concatenate([v / np.linalg.norm(v, axis=1)[:, None],
                           [[0, 1, 0], [0, -1, 0], [1, 0, 0], [0, 0, -1]]])


def test_a_constant_environments_irradiance_is_pi_l():
    assert shadow_cast(Light(kind_key="environment")) is None  # (its rays: not bounded)
    rows = light_array([Light(kind_key="environment")])
    for n in _normals():
        got = environment_irradiance(rows, 0, *map(float, n))
        np.testing.assert_allclose(got, math.pi, rtol=1e-12)


def test_a_two_colour_environments_irradiance_follows_the_normal(tmp_path):
    """E(n) = pi (L1 (1 + cos) / 2 + L2 (1 - cos) / 2), cos the normal's with +Y, within
    1e-9 relative (the image's exact integrals to the harmonics of order 2, which hold a
    hemisphere step's irradiance exactly)."""
    light = Light(kind_key="environment", file=_two_colour(tmp_path / "sky.exr"))
    rows = light_array([light])
    for n in _normals():
        got = environment_irradiance(rows, 0, *map(float, n))
        np.testing.assert_allclose(got, _want_two_colour(n[1]), rtol=1e-9)


def test_the_shadow_rays_follow_the_images_luminance(tmp_path):
    """Rays of many pixels: the share going up is the upper half's share of the luminance
    (within 0.01); an image dark but for one pixel sends every ray into that pixel."""
    light = Light(kind_key="environment", file=_two_colour(tmp_path / "sky.exr"))
    rows = light_array([light])
    keys = ray_keys(np.arange(400))
    d = np.array([shadow_target(rows, 0, s, int(key), 0.0, 0.0, 0.0)[:3]
                  for key in keys for s in range(8)])
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, rtol=1e-12)
    lum = np.array([0.2126, 0.7152, 0.0722])
    want = TOP @ lum / (TOP @ lum + BOTTOM @ lum)
    assert abs((d[:, 1] > 0).mean() - want) < 0.01
    spot = np.zeros((32, 64, 3), np.float32)
    spot[5, 40] = 10.0  # (theta in [5, 6] pi / 32, phi in [40, 41] 2 pi / 64 - pi)
    path = tmp_path / "spot.exr"
    write_exr(path, {"R": spot[..., 0], "G": spot[..., 1], "B": spot[..., 2]})
    rows = light_array([Light(kind_key="environment", file=str(path))])
    d = np.array([shadow_target(rows, 0, s, int(key), 0.0, 0.0, 0.0)[:3]
                  for key in keys[:50] for s in range(4)])
    theta = np.arccos(np.clip(d[:, 1], -1, 1))
    phi = np.arctan2(d[:, 0], -d[:, 2])
    assert np.all((theta >= 5 * math.pi / 32 - 1e-12) & (theta <= 6 * math.pi / 32 + 1e-12))
    assert np.all((phi >= 40 * math.pi / 32 - math.pi - 1e-12)
                  & (phi <= 41 * math.pi / 32 - math.pi + 1e-12))


A = 1.0  # (the half-plane y = A, x < 0 over the plane y = 0)


def _half_plane(origins, dirs, tmax):
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (A - origins[:, 1]) / dirs[:, 1]
    x = origins[:, 0] + s * dirs[:, 0]
    return ((s > 0.0) & (s < tmax) & (x < 0.0)).astype(np.uint8)


def test_the_visibility_past_a_half_plane_converges_to_the_cosine_share():
    """A constant environment over points of the plane y = 0 (normal +Y) under the
    half-plane: the cosine-weighted share of the sky a point at x sees is
    (1 + x / sqrt(x^2 + A^2)) / 2; the mean error falls with the rays per point (16, 64,
    256) and is below 0.01 at 256."""
    from subtrace.shade import shadow_visibility

    x = np.linspace(-3.0, 3.0, 301)
    points = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
    eye = np.array([0.3, 9.0, 2.0])
    v = points - eye
    t = np.linalg.norm(v, axis=1)
    dirs = np.ascontiguousarray(v / t[:, None])
    frame = np.array([eye, [1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]])
    normals = np.tile([0.0, 1.0, 0.0], (len(t), 1))
    want = (1.0 + x / np.sqrt(x * x + A * A)) / 2.0
    errors = []
    for samples in (16, 64, 256):
        rows = light_array([Light(kind_key="environment", samples=samples)])
        got = shadow_visibility(_half_plane, frame, 1, t, normals, np.zeros(len(t), np.int32),
                                rows, 0.0, dirs, ray_keys(np.arange(len(t))))[0]
        errors.append(float(np.abs(got - want).mean()))
    assert errors[0] > errors[1] > errors[2] and errors[2] < 0.01, errors


CUBE = ("v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\n"
        "v -1 1 1\nf 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n")


def _blob(tmp_path, light):
    """A white convex blob (the cube's Catmull-Clark limit) under ``light`` alone."""
    (tmp_path / "cube.obj").write_text(CUBE)
    return scene_from_dict({
        "object": [{"mesh": "cube.obj", "color": [1.0, 1.0, 1.0]}],
        "camera": {"eye": [3.0, 2.5, 4.0], "target": [0.0, 0.0, 0.0], "width": 48,
                   "height": 40},
        "render": {"headlight": False, "samples": 1}, "ground": False,
        "light": [light]}, base_dir=tmp_path)


@pytest.mark.parametrize("samples", [1, 4, 16])
def test_a_white_convex_object_under_a_constant_environment_is_pi_l(tmp_path, samples):
    """Every covered pixel's colour is pi times the radiance (the object's own occlusion
    irrelevant: no ray above a convex surface's horizon meets it), at any rays per point
    (the unshadowed term is exact, the rays only see that nothing blocks them): within
    1e-6 relative, but a few pixels by the micro-surface's facets (grazing rays)."""
    light = {"kind": "environment", "color": [0.5, 0.25, 1.0], "intensity": 0.3,
             "samples": samples}
    ch = render_scene(_blob(tmp_path, light)).channels
    covered = ch["A"] == 1.0
    assert np.count_nonzero(covered) > 300
    for c, l in zip("RGB", (0.5, 0.25, 1.0)):
        rel = np.abs(ch[c][covered] / (math.pi * 0.3 * l) - 1.0)
        assert np.median(rel) < 1e-6 and np.mean(rel > 1e-3) < 0.02, (c, rel.max())


def test_a_white_convex_object_under_two_hemispheres(tmp_path):
    """The two-colour environment: each covered pixel's colour against E(n) of its normal
    (the N channels), within 1e-4 relative but for a few grazing pixels."""
    light = {"kind": "environment", "file": _two_colour(tmp_path / "sky.exr"),
             "samples": 8}
    ch = render_scene(_blob(tmp_path, light)).channels
    covered = ch["A"] == 1.0
    want = _want_two_colour(ch["N.Y"][covered].astype(np.float64)[:, None])
    got = np.stack([ch[c][covered] for c in "RGB"], axis=1)
    rel = np.abs(got / want - 1.0)
    assert np.median(rel) < 1e-4 and np.mean(rel.max(axis=1) > 1e-3) < 0.02, rel.max()


@pytest.mark.parametrize("content, words", [(None, "no such file"),
                                            (b"not an image", "cannot read the image")])
def test_a_missing_or_unreadable_file_is_one_clear_error(tmp_path, capsys, content, words):
    (tmp_path / "cube.obj").write_text(CUBE)
    sky = tmp_path / "sky.hdr"
    if content is not None:
        sky.write_bytes(content)
    scene = tmp_path / "scene.toml"
    scene.write_text('[[object]]\nmesh = "cube.obj"\n\n[[light]]\nkind = "environment"\n'
                     'file = "sky.hdr"\n')
    with pytest.raises(SceneError) as err:
        load_scene(scene)
    message = str(err.value)
    assert f"{scene}:6" in message and str(sky) in message and words in message, message
    out = tmp_path / "out.exr"
    code = main(["render", str(scene), "-o", str(out), "--quiet"])
    lines = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and str(sky) in lines[0] and words in lines[0], lines
    assert not out.exists()
