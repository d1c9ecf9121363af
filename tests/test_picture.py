"""The picture (subtrace/picture.py): adaptive anti-aliasing keeps every pixel's centre ray
for the auxiliary channels and changes only edge pixels, whose alpha approaches their true
coverage (checked against a render at four times the resolution, box-filtered); the
sample pattern; the background gradient; the default scene's first impression."""

from __future__ import annotations

import numpy as np
import pytest

from subtrace.io.scene import apply_overrides, scene_from_dict
from subtrace.picture import edge_pixels, sample_offsets
from subtrace.render import render_scene
from subtrace.shade import CHANNELS

CUBE = ("v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\n"
        "v -1 1 1\nf 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n")
AUX = ("Z", "N.X", "N.Y", "N.Z", "level", "patch_id", "object_id", "u", "v")


@pytest.fixture
def scene(tmp_path):
    path = tmp_path / "cube.obj"
    path.write_text(CUBE)
    return scene_from_dict({
        "object": [{"mesh": str(path)}],
        "camera": {"eye": [3.0, 2.5, 4.0], "target": [0.0, 0.0, 0.0], "width": 64,
                   "height": 48},
        "render": {"background": [[0.3, 0.3, 0.4], [0.1, 0.1, 0.1]]},
        "light": [{"direction": [0.3, -1.0, -0.5]}],
    }, base_dir=tmp_path)


def test_sample_offsets_are_spread_over_the_pixel():
    for n in (2, 4, 8, 16):
        off = sample_offsets(n)
        assert off.shape == (n - 1, 2)
        assert np.all(np.abs(off) < 0.5) and len(np.unique(off, axis=0)) == n - 1
    # with the centre, 16 rays leave no quarter-pixel cell far from a ray
    pts = np.vstack([[0.0, 0.0], sample_offsets(16)])
    g = (np.arange(4) + 0.5) / 4 - 0.5
    cells = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    gap = np.sqrt(((cells[:, None] - pts[None]) ** 2).sum(-1)).min(axis=1)
    assert gap.max() < 0.25


def test_antialiasing_changes_only_edge_pixels(scene):
    """--samples 1 is one ray per pixel; with more, only pixels edge_pixels marks change
    (colour and alpha; the auxiliary channels where the centre ray missed:
    :func:`test_a_covered_pixel_has_the_channels_of_a_ray_that_hit`), some get intermediate
    alpha, and every auxiliary channel of a pixel whose centre ray hit is bit for bit the
    centre ray's."""
    one = render_scene(apply_overrides(scene, samples=1)).channels
    many = render_scene(apply_overrides(scene, samples=8)).channels
    centre = np.isfinite(one["Z"])
    for c in AUX:
        assert one[c][centre].tobytes() == many[c][centre].tobytes(), c
    assert set(np.unique(one["A"])) == {0.0, 1.0}
    partial = (many["A"] > 0) & (many["A"] < 1)
    assert partial.sum() > 20
    planes = np.stack([one[c].ravel() for c in CHANNELS])
    edges = edge_pixels(planes, 64, 48)
    changed = np.zeros(one["A"].shape, bool)
    for c in "RGBA":
        changed |= one[c] != many[c]
    assert changed.any() and not np.any(changed & ~edges)


def test_antialiased_alpha_is_the_coverage(scene):
    """Alpha with 16 rays per edge pixel against the coverage of a 4x4 supersampled
    render (one ray per sub-pixel), box-filtered: equal totals within 1 %, and per edge
    pixel within 0.25 on average (16 samples of an edge resolve coverage to about 1/16;
    the two patterns differ)."""
    aa = render_scene(apply_overrides(scene, samples=16)).channels["A"].astype(np.float64)
    fine = render_scene(apply_overrides(scene, samples=1, width=256, height=192))
    cov = fine.channels["A"].astype(np.float64).reshape(48, 4, 64, 4).mean(axis=(1, 3))
    assert abs(aa.sum() - cov.sum()) < 0.01 * cov.sum()
    edge = (cov > 0) & (cov < 1)
    assert edge.sum() > 30
    assert np.abs(aa[edge] - cov[edge]).mean() < 0.1
    assert np.abs(aa - cov).max() < 0.5


def test_gradient_background(scene):
    ch = render_scene(apply_overrides(scene, samples=1)).channels
    miss = ch["A"] == 0
    top, bottom = ch["R"][0][miss[0]], ch["R"][-1][miss[-1]]
    assert np.allclose(top, 0.3 + (0.1 - 0.3) * 0.5 / 48, atol=1e-6)
    assert np.allclose(bottom, 0.3 + (0.1 - 0.3) * 47.5 / 48, atol=1e-6)


def test_default_scene_is_a_first_impression():
    """The built-in scene shows Spot whole (no covered pixel on the border), centred (the
    covered pixels' bounding box centre within 10 % of the image centre), filling a good
    part of the height, from the front (its head, at -z, nearer than its tail), over a
    gradient with a ground shadow."""
    from subtrace.data import default_scene_path
    from subtrace.io.scene import load_scene

    scene = apply_overrides(load_scene(default_scene_path()), width=160, height=90)
    result = render_scene(scene)
    ch = result.channels
    cov = ch["A"] > 0
    assert not (cov[0].any() or cov[-1].any() or cov[:, 0].any() or cov[:, -1].any())
    rows, cols = np.nonzero(cov)
    assert abs(0.5 * (rows.min() + rows.max()) - 44.5) < 9
    assert abs(0.5 * (cols.min() + cols.max()) - 79.5) < 16
    assert rows.max() - rows.min() > 0.6 * 90
    eye = np.asarray(result.camera.eye)
    assert eye[2] < 0  # Spot faces -z: the camera is in front of it
    miss = ~cov
    assert ch["R"][0][miss[0]].mean() > ch["R"][-1][miss[-1]].mean()  # the gradient
    # in the ground shadow the background is darker than beside it on the same row
    r = rows.max()
    row_miss = ch["R"][r][miss[r]]
    assert row_miss.min() < 0.6 * row_miss.max()


def _pixel_directions(camera):
    """(H, W, 3) unit directions through the pixel centres, built from the camera's
    eye, target, up and field of view alone (not the renderer's frame)."""
    eye, target, up = (np.asarray(v, np.float64) for v in (camera.eye, camera.target,
                                                           camera.up))
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    s = 2.0 * np.tan(np.radians(camera.fov_deg) / 2.0) / camera.height
    x = (np.arange(camera.width) + 0.5 - 0.5 * camera.width) * s
    y = (np.arange(camera.height) + 0.5 - 0.5 * camera.height) * s
    d = forward + x[None, :, None] * right - y[:, None, None] * true_up
    return d / np.linalg.norm(d, axis=-1)[..., None]


@pytest.mark.parametrize("which", ["cube", "nurbs_mixed"])
def test_position_channels_are_eye_plus_z_along_the_ray(scene, tmp_path, which):
    """P.X, P.Y, P.Z (written to the EXR and read back) equal eye + Z d for every hit pixel,
    d from the camera's geometry; NaN where Z is +inf; the header says what P and Z hold.
    nurbs_mixed: the free-form surfaces' pass writes P too."""
    from pathlib import Path

    from subtrace.io.exr import read_exr, write_exr
    from subtrace.io.scene import load_scene
    from subtrace.render import result_attributes

    if which == "nurbs_mixed":
        root = Path(__file__).resolve().parents[1]
        scene = apply_overrides(load_scene(root / "scenes" / "nurbs_mixed.toml"), width=96,
                                height=54, samples=1)
    result = render_scene(scene)
    path = tmp_path / "p.exr"
    write_exr(path, result.channels, result_attributes(result, scene))
    ch, attrs = read_exr(path)
    assert "along the pixel's ray" in attrs["subtrace:Z"] and "eye + Z" in attrs["subtrace:P"]
    z = ch["Z"].astype(np.float64)
    hit = np.isfinite(z)
    assert hit.sum() > 200 and (~hit).sum() > 200
    p = np.stack([ch[c] for c in ("P.X", "P.Y", "P.Z")], axis=-1).astype(np.float64)
    assert np.all(np.isnan(p[~hit]))
    expected = np.asarray(scene.make_camera().eye) + z[..., None] * _pixel_directions(
        result.camera)
    # float32 storage of P and Z (2^-24 relative each) and the two ways of building d
    err = np.linalg.norm(p[hit] - expected[hit], axis=-1)
    scale = np.abs(expected[hit]).max(axis=-1) + z[hit]
    assert np.all(err <= 1e-6 * scale), err.max()
    if which == "nurbs_mixed":  # both passes' pixels were checked
        assert np.unique(ch["object_id"][hit]).tolist() == [0.0, 1.0]


@pytest.mark.parametrize("bands", [False, True])
def test_hits_coloured_in_the_shading_pass_as_the_lights_pass_colours_them(tmp_path,
                                                                           monkeypatch, bands):
    """A render without shadows or ambient occlusion colours its hits in the shading pass
    (``picture.lit_in_shading``): every channel is the same, bit for bit, as when the
    lights' own pass colours them, for a shiny material under the headlight, a directional
    and a point light, the whole image at once and in bands; with shadows the lights' pass
    colours them."""
    import subtrace.picture as picture
    import subtrace.render as render

    path = tmp_path / "cube.obj"
    path.write_text(CUBE)
    scene = scene_from_dict({
        "object": [{"mesh": str(path), "specular": [0.3, 0.25, 0.2], "shininess": 30.0}],
        "camera": {"eye": [3.0, 2.5, 4.0], "target": [0.0, 0.0, 0.0], "width": 64,
                   "height": 48},
        "render": {"shadows": False},
        "light": [{"direction": [0.3, -1.0, -0.5]},
                  {"position": [2.0, 3.0, 2.5], "color": [1.0, 0.8, 0.6]}],
    }, base_dir=tmp_path)
    assert picture.lit_in_shading(scene) is not None
    assert picture.lit_in_shading(apply_overrides(scene, shadows=True)) is None
    assert picture.lit_in_shading(scene, loop=True) is None

    def channels(sc):
        if not bands:
            return render_scene(sc).channels
        out = {}

        def sink(y0, y1, band):
            for name, plane in band.items():
                out.setdefault(name, []).append(np.array(plane))

        render_scene(sc, sink=sink, band_rows=16)
        return {name: np.concatenate(parts) for name, parts in out.items()}

    calls = []
    light = picture.light
    monkeypatch.setattr(picture, "light", lambda *a, **k: calls.append(1) or light(*a, **k))
    fused = channels(scene)
    assert calls == []  # (no lights' pass)
    monkeypatch.setattr(render, "lit_in_shading", lambda *a, **k: None)
    apart = channels(scene)
    assert calls  # (the lights' pass coloured them)
    assert (fused["R"] > 0).any() and set(fused) == set(CHANNELS)
    for name in CHANNELS:
        np.testing.assert_array_equal(fused[name], apart[name], err_msg=name)


@pytest.mark.parametrize("which", ["cube", "nurbs_mixed"])
def test_a_covered_pixel_has_the_channels_of_a_ray_that_hit(scene, which):
    """With anti-aliasing, a pixel of alpha above 0 has a finite depth and ids, as a
    compositor expects (they were the missed centre ray's: Z = +inf at alpha up to 0.75,
    2-20 pixels a view): where the centre ray missed, the auxiliary channels are those of
    a ray through the pixel's own square that hit the surface, its point P at distance Z
    from the eye (checked from the camera's geometry alone); elsewhere they are the
    centre ray's, and a pixel no ray hit says so."""
    from pathlib import Path

    from subtrace.io.scene import load_scene

    if which == "nurbs_mixed":
        root = Path(__file__).resolve().parents[1]
        scene = apply_overrides(load_scene(root / "scenes" / "nurbs_mixed.toml"), width=160,
                                height=90)
    one = render_scene(apply_overrides(scene, samples=1)).channels
    result = render_scene(apply_overrides(scene, samples=8))
    many = result.channels
    covered = many["A"] > 0
    assert np.all(np.isfinite(many["Z"][covered])) and np.all(np.isinf(many["Z"][~covered]))
    for c in ("patch_id", "object_id"):
        assert np.all(many[c][covered] >= 0) and np.all(many[c][~covered] == -1)
    taken = covered & np.isinf(one["Z"])
    assert taken.sum() >= 3
    p = np.stack([many[c][taken] for c in ("P.X", "P.Y", "P.Z")], axis=-1).astype(np.float64)
    cam = result.camera
    eye, target, up = (np.asarray(v, np.float64) for v in (cam.eye, cam.target, cam.up))
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    d = p - eye
    dist = np.linalg.norm(d, axis=1)
    z = many["Z"][taken].astype(np.float64)
    assert np.all(np.abs(dist - z) <= 1e-5 * (dist + np.abs(eye).max()))
    s = 2.0 * np.tan(np.radians(cam.fov_deg) / 2.0) / cam.height
    depth = d @ forward
    col = (d @ right) / depth / s + 0.5 * cam.width - 0.5
    row = -(d @ true_up) / depth / s + 0.5 * cam.height - 0.5
    rows, cols = np.nonzero(taken)
    # (float32 P: far below a pixel's half)
    assert np.abs(col - cols).max() < 0.5 + 1e-3 and np.abs(row - rows).max() < 0.5 + 1e-3
