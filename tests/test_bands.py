"""Renders streamed in bands of rows (``render.render_scene(sink=...)``, what ``subtrace
render`` does for an EXR of a whole image): every band is its rows of the render of the whole
image, bit for bit, whatever the band height; the bands arrive in order and cover the image
once; a band's arrays are a band's, not the image's; and the streamed EXR
(``io.exr.ExrBands``) is the file written from the whole image."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from subtrace.cli import main
from subtrace.data import default_scene_path
from subtrace.io.exr import HALF_CHANNELS, read_exr
from subtrace.io.scene import apply_overrides, load_scene
from subtrace.mesh.cage import load_cage
from subtrace.render import apron, render_scene

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "scenes"


def _scene(path, width=96, height=72):
    return apply_overrides(load_scene(path), width=str(width), height=str(height))


def _banded(scene, rows, trace_bands=True):
    """The channels a render in bands of ``rows`` hands to its sink, put together; the
    result; the bytes of the largest buffer a band's arrays were views of."""
    width, height = scene.camera.width, scene.camera.height
    out, seen = {}, []
    largest = [0]

    def sink(y0, y1, channels):
        seen.append((y0, y1))
        for name, band in channels.items():
            assert band.shape == (y1 - y0, width)
            base = band
            while base.base is not None:
                base = base.base
            largest[0] = max(largest[0], base.nbytes)
            out.setdefault(name, np.full((height, width), -7.0, np.float32))[y0:y1] = band

    result = render_scene(scene, threads=2, sink=sink, band_rows=rows, trace_bands=trace_bands)
    assert [y for y, _ in seen] == sorted(y for y, _ in seen)  # top to bottom
    assert seen[0][0] == 0 and seen[-1][1] == height
    assert all(a[1] == b[0] for a, b in zip(seen, seen[1:]))  # each row once
    assert result.channels == {}
    return out, result, largest[0]


@pytest.mark.parametrize("path", [
    SCENES / "spot.toml",  # n-gons, extraordinary vertices, shadows, anti-aliasing
    SCENES / "creases.toml",  # semi-sharp creases, corners
    SCENES / "torus_loop.toml",  # Loop
    SCENES / "spot_ao.toml",  # ambient occlusion, smoothed across band borders
    SCENES / "corners_boundary.toml",  # boundaries
    default_scene_path(),  # a shadow-catching ground, a gradient background
], ids=lambda p: p.stem)
def test_bands_are_the_whole_render(path):
    """Bands of 16 and 32 rows, the rays traced band by band or for the whole image first:
    every channel of every pixel is the whole render's (bands traced apart share the built
    patches, so rays meet them in another order; the apron's rows give anti-aliasing and
    smoothed occlusion their neighbours)."""
    scene = _scene(path)
    whole = render_scene(scene, threads=2)
    assert whole.stats.pixels_covered > 0
    for rows, trace_bands in ((16, True), (32, True), (32, False)):
        bands, result, _ = _banded(scene, rows, trace_bands)
        for name, plane in whole.channels.items():
            np.testing.assert_array_equal(bands[name], plane,
                                          err_msg=f"{path.stem} {rows} {trace_bands}: {name}")
        assert result.stats.pixels_covered == whole.stats.pixels_covered
        assert result.stats.max_level == whole.stats.max_level
        assert result.stats.rays == whole.stats.rays
        if not trace_bands:  # (the same rounds as the whole render's)
            assert result.stats.patches_refined == whole.stats.patches_refined
            assert result.stats.micro_triangles == whole.stats.micro_triangles


def test_a_band_holds_its_rows_alone():
    """A tall image traced and shaded in bands of 16 rows: the arrays handed over are views
    of a buffer of a band's window (its rows, the apron above and below, a row more for
    even bounds: the 16 float32 channels, the normals and patch ids, 92 bytes a pixel), far
    less than the image's channels alone."""
    scene = _scene(SCENES / "spot_ao.toml", width=80, height=240)
    _, result, largest = _banded(scene, 16)
    assert result.stats.pixels_covered > 0
    window = 80 * (16 + 2 * (apron(scene) + 1))
    assert largest <= 100 * window < 64 * 80 * 240


def test_band_rows_are_whole_blocks():
    """A band height that is not a multiple of 16 rows (an EXR's ZIP block) is taken down to
    one (at least 16): every band but the last starts a block."""
    scene = _scene(SCENES / "creases.toml", width=64, height=100)
    seen = []
    render_scene(scene, threads=1, sink=lambda y0, y1, _: seen.append((y0, y1)), band_rows=23,
                 trace_bands=False)
    assert seen == [(0, 16), (16, 32), (32, 48), (48, 64), (64, 80), (80, 96), (96, 100)]


def test_the_command_streams_the_whole_render(tmp_path):
    """``subtrace render`` (an EXR of the whole image, streamed) writes the channels of the
    in-process render of the whole image, and its preview."""
    scene_path = SCENES / "creases.toml"
    out = tmp_path / "c.exr"
    assert main(["render", str(scene_path), "-o", str(out), "--width", "80", "--height",
                 "56", "--png", "--quiet"]) == 0
    channels, head = read_exr(out)
    whole = render_scene(_scene(scene_path, 80, 56), threads=2)
    for name, plane in whole.channels.items():
        stored = plane.astype(np.float16) if name in HALF_CHANNELS else plane  # (the file's)
        np.testing.assert_array_equal(channels[name], stored, err_msg=name)
    assert head["subtrace:pixels_covered"] == whole.stats.pixels_covered
    assert head["subtrace:time_total"] > 0
    assert (tmp_path / "c.png").stat().st_size > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.exr", "c.png"]  # no temporary


def test_progress_over_the_bands():
    """The progress callback counts the image's rays: never back, ending at all of them."""
    scene = _scene(SCENES / "spot.toml", width=96, height=200)
    told = []
    render_scene(scene, threads=2, sink=lambda *a: None, band_rows=32, trace_bands=True,
                 progress=lambda done, total, label: told.append((done, total)))
    done = [d for d, _ in told]
    assert done == sorted(done) and len(told) > 6
    assert told[-1] == (96 * 200, 96 * 200) and {t for _, t in told} == {96 * 200}


def test_which_images_are_traced_in_bands(monkeypatch):
    """By default an image is traced band by band only above config.STREAM_TRACE_PIXELS,
    or when its cages have config.STREAM_TRACE_FACES faces or more; either way the bands
    are the whole render's."""
    from subtrace import config, render

    scene = _scene(SCENES / "creases.toml", width=64, height=48)
    windows = []
    setup = render.trace_setup

    def spy(*args, **kwargs):
        shared = setup(*args, **kwargs)
        windows.append(shared.windows)
        return shared

    monkeypatch.setattr(render, "trace_setup", spy)
    render_scene(scene, threads=1, sink=lambda *a: None)
    monkeypatch.setattr(config, "STREAM_TRACE_PIXELS", 64 * 48 - 1)
    render_scene(scene, threads=1, sink=lambda *a: None)
    monkeypatch.setattr(config, "STREAM_TRACE_PIXELS", 64 * 48)
    faces = load_cage(scene.objects[0].mesh).n_faces
    monkeypatch.setattr(config, "STREAM_TRACE_FACES", faces + 1)
    render_scene(scene, threads=1, sink=lambda *a: None)
    monkeypatch.setattr(config, "STREAM_TRACE_FACES", faces)
    render_scene(scene, threads=1, sink=lambda *a: None)
    assert windows == [False, True, False, True]
