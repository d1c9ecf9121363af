"""Tiles (tiles.py, ``render --crop X0 Y0 X1 Y1`` and ``--tile N``): a tile's pixels are the
whole render's, bit for bit, so tiles put together are the whole image; a window's
projection lists are its image's; a tile's EXR is a data window in the display window."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from subtrace.accel.projection import TILE, project_shells
from subtrace.camera import Camera, CameraWindow
from subtrace.cli import main
from subtrace.io.exr import read_exr, write_exr
from subtrace.tiles import assemble, tile_grid

CUBE = ("v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n"
        "f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 3 4 8 7\nf 2 3 7 6\nf 1 5 8 4\n")

# the built-in scene (lights with shadows, a shadow-catching ground, a gradient behind,
# anti-aliasing): what a pixel's value depends on beyond its own ray is all there
SIZE = ["--width", "64", "--height", "48", "--quiet"]


def _same(a, b, what):
    for name in a:
        np.testing.assert_array_equal(a[name], b[name], err_msg=f"{what}: {name}")


@pytest.fixture(scope="module")
def whole(tmp_path_factory):
    path = tmp_path_factory.mktemp("whole") / "whole.exr"
    assert main(["render", "-o", str(path), *SIZE]) == 0
    return read_exr(path)


def test_tiles_put_together_are_the_whole_render(tmp_path, whole):
    """Four tiles with odd bounds (not on the projection's 2x2 tiles, anti-aliased edges and
    the ground's shadow across their borders): every channel of each is the whole render's
    pixels, bit for bit; each file's data window is its crop in the whole display window;
    each traced fewer rays than the whole image."""
    full, attrs = whole
    assert (full["A"] > 0).any() and (full["A"] == 0).any()  # object and background
    crops = [(0, 0, 23, 17), (23, 0, 64, 17), (0, 17, 31, 48), (31, 17, 64, 48)]
    parts = []
    for crop in crops:
        out = tmp_path / "tile.{}.{}.exr".format(*crop)
        assert main(["render", "-o", str(out), *SIZE, "--crop", *map(str, crop)]) == 0
        tile, head = read_exr(out)
        x0, y0, x1, y1 = crop
        assert head["dataWindow"] == (x0, y0, x1 - 1, y1 - 1)
        assert head["displayWindow"] == (0, 0, 63, 47)
        assert head["subtrace:crop"] == "{} {} {} {}".format(*crop)
        assert head["subtrace:rays"] < attrs["subtrace:rays"]
        assert head["worldToNDC"] == attrs["worldToNDC"]  # the whole image's camera
        _same({k: v[y0:y1, x0:x1] for k, v in full.items()}, tile, f"tile {crop}")
        parts.append((crop, tile))
    _same(full, assemble(64, 48, parts), "put together")


@pytest.mark.parametrize("inputs", [
    ["scenes/nurbs_mixed.toml"],  # the NURBS pass beside subdivision surfaces
    ["scenes/torus_loop.toml"],  # Loop triangles
    ["scenes/creases.toml", "--accel", "bvh"],  # rays walking the BVH
    ["scenes/spot_ao.toml"],  # ambient occlusion: each pixel's pattern is its image pixel's
])
def test_tiles_of_other_scenes(tmp_path, inputs):
    """Two tiles split at an odd column and row: the whole render's pixels, bit for bit."""
    repo = Path(__file__).resolve().parents[1]
    args = [str(repo / inputs[0]), *inputs[1:], "--width", "45", "--height", "33", "--quiet"]
    assert main(["render", *args, "-o", str(tmp_path / "whole.exr")]) == 0
    full, _ = read_exr(tmp_path / "whole.exr")
    assert (full["A"] > 0).any()
    for crop in ((0, 0, 45, 17), (13, 17, 32, 33)):
        assert main(["render", *args, "-o", str(tmp_path / "t.exr"), "--crop",
                     *map(str, crop)]) == 0
        tile, _ = read_exr(tmp_path / "t.exr")
        x0, y0, x1, y1 = crop
        _same({k: v[y0:y1, x0:x1] for k, v in full.items()}, tile, f"{inputs} {crop}")


def test_local_tiles_give_the_whole_render(tmp_path, whole):
    """--tile 16 renders 12 tiles one after another and writes the whole image: the same
    channels as one render."""
    out = tmp_path / "tiled.exr"
    assert main(["render", "-o", str(out), *SIZE, "--tile", "16"]) == 0
    tiled, head = read_exr(out)
    assert "dataWindow" not in head
    _same(whole[0], tiled, "--tile 16")


@pytest.mark.parametrize("crop, words", [
    (["0", "0", "0", "5"], "0 <= X0 < X1 <= 64"),
    (["10", "5", "70", "9"], "0 <= X0 < X1 <= 64"),
    (["0", "0", "8", "49"], "0 <= Y0 < Y1 <= 48"),
    (["-1", "0", "8", "8"], "0 <= X0"),
    (["a", "0", "8", "8"], "four whole numbers"),
    (["1.5", "0", "8", "8"], "four whole numbers"),
])
def test_bad_crop_is_one_line(tmp_path, capsys, crop, words):
    cube = tmp_path / "cube.obj"
    cube.write_text(CUBE)
    assert main(["render", str(cube), "-o", str(tmp_path / "x.exr"), *SIZE,
                 "--crop", *crop]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--crop" in err and words in err, err
    assert not list(tmp_path.glob("*.exr"))


def test_bad_tile_options(tmp_path, capsys):
    cube = tmp_path / "cube.obj"
    cube.write_text(CUBE)
    for flags in (["--tile", "8"], ["--tile", "x"], ["--tile", "16", "--crop", "0", "0", "8", "8"]):
        assert main(["render", str(cube), "-o", str(tmp_path / "x.exr"), *flags]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "--tile" in err, err
    assert not list(tmp_path.glob("*.exr"))


def test_tile_grid_covers_once():
    for w, h, n in ((64, 48, 16), (65, 47, 16), (10, 10, 32), (33, 1, 16)):
        count = np.zeros((h, w), int)
        for x0, y0, x1, y1 in tile_grid(w, h, n):
            assert 0 < x1 - x0 <= n and 0 < y1 - y0 <= n
            count[y0:y1, x0:x1] += 1
        assert (count == 1).all()


def test_exr_data_window_round_trip(tmp_path):
    rng = np.random.default_rng(3)
    ch = {"R": rng.random((5, 7), dtype=np.float32), "Z": rng.random((5, 7), dtype=np.float32)}
    write_exr(tmp_path / "t.exr", ch, window=(40, 33, 100, 80))
    back, head = read_exr(tmp_path / "t.exr")
    assert head["dataWindow"] == (40, 33, 46, 37)
    assert head["displayWindow"] == (0, 0, 99, 79)
    np.testing.assert_array_equal(back["Z"], ch["Z"])


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 50), st.integers(1, 40), st.data())
def test_a_window_lists_its_image_lists(seed, width, height, data):
    """A window's projection (an even offset, in a fifth row of its frame) lists, for each
    of its tiles, exactly the image's list of that tile: the same boxes in the same order."""
    rng = np.random.default_rng(seed)
    eye = rng.normal(0, 1, 3)
    cam = Camera(tuple(eye), tuple(eye + rng.normal(0, 1, 3)), (0.0, 0.0, 1.0), 50.0, width,
                 height)
    c = eye + rng.normal(0, 2.0, (80, 3))
    c[:3] = eye + rng.normal(0, 0.05, (3, 3))  # around the eye: in every tile
    half = np.abs(rng.normal(0, 0.4, (80, 3)))
    lo, hi = c - half, c + half
    full = project_shells(lo, hi, cam.frame(), width, height)
    x0 = TILE * data.draw(st.integers(0, (width - 1) // TILE))
    y0 = TILE * data.draw(st.integers(0, (height - 1) // TILE))
    w = data.draw(st.integers(1, width - x0))
    h = data.draw(st.integers(1, height - y0))
    win = project_shells(lo, hi, CameraWindow(cam, x0, y0, w, h).frame(), w, h,
                         image=(width, height))
    tx = -(-w // TILE)
    for b in range(-(-h // TILE)):
        for a in range(tx):
            k = b * tx + a
            K = (b + y0 // TILE) * full.per_row + a + x0 // TILE
            np.testing.assert_array_equal(win.items[win.off[k]:win.off[k + 1]],
                                          full.items[full.off[K]:full.off[K + 1]])


def test_a_tile_of_a_huge_image_holds_only_its_own_pixels():
    """A 32x24 tile of an 8192x6144 image (50 M pixels: its channels alone would take
    2.2 GB, and the image fails a 256 MiB budget) renders within that budget, traces only
    its window's rays, and allocates about what a tile of a 64x48 image does (tracemalloc
    peaks within 64 MiB of each other: numpy's arrays are traced)."""
    import tracemalloc

    from subtrace.data import default_scene_path
    from subtrace.errors import SceneError
    from subtrace.io.scene import apply_overrides, load_scene
    from subtrace.render import render_scene

    peaks = []
    for w, h in ((64, 48), (8192, 6144)):
        scene = apply_overrides(load_scene(default_scene_path()), width=w, height=h,
                                max_memory="256M")
        render_scene(scene, crop=(w // 2, h // 2, w // 2 + 32, h // 2 + 24))  # (warm)
        tracemalloc.start()
        try:
            result = render_scene(scene, crop=(w // 2, h // 2, w // 2 + 32, h // 2 + 24))
            peaks.append(tracemalloc.get_traced_memory()[1])
        finally:
            tracemalloc.stop()
        assert result.channels["R"].shape == (24, 32)
        assert result.stats.rays <= 36 * 28  # the window: a pixel around, even bounds
    assert peaks[1] - peaks[0] < 64 << 20, [p >> 20 for p in peaks]
    with pytest.raises(SceneError, match="budget"):
        render_scene(scene)  # the whole image does not fit


# how each statistic of a tiled render relates to the whole render's (tiles.merge_stats):
# one value of the whole image, which every tile and the merge have too
WHOLE_IMAGE = ("patches", "faces_culled", "max_depth", "max_level", "depth_cap",
               "depth_cap_reason", "accel_fallback", "secondary_max_depth", "pixels_covered")
# the most any tile had (no relation to the whole render's but that)
MOST = ("rounds", "memo_bytes")
# work counted per tile: summed, at least the whole render's (a patch two tiles reach is
# built by both, the pixels around a tile are traced again); times are sums too
WORK = ("patches_refined", "micro_triangles", "pieces", "memo_nodes", "memo_full", "rays",
        "shadow_rays", "aa_pixels", "aa_rays", "ao_rays", "reflection_rays",
        "secondary_patches_refined",
        "secondary_micro_triangles")


def test_a_tiled_renders_statistics_are_the_whole_renders(tmp_path):
    """Every statistic of a tiled render (``tiles.merge_stats`` of its tiles', as
    ``render --tile`` reports them) against the whole render's and the tiles': the whole
    image's values equal (the deepest secondary grid was the sum over tiles: 35 or 59
    where the whole render said 8), the peaks the largest tile's, the work and the times
    the tiles' sums; every field of RenderStats is one of these."""
    import dataclasses

    from subtrace.io.scene import apply_overrides, scene_for_meshes
    from subtrace.jobs import render_tiled
    from subtrace.render import RenderStats, render_scene
    from subtrace.tiles import merge_stats

    cube = tmp_path / "cube.obj"
    cube.write_text(CUBE)
    scene = apply_overrides(scene_for_meshes([str(cube)]), width=96, height=72, samples=4,
                            ao=4)
    whole = dataclasses.asdict(render_scene(scene).stats)
    tiles = [dataclasses.asdict(render_scene(scene, crop=c).stats)
             for c in tile_grid(96, 72, 32)]
    merged = merge_stats(tiles)
    tiled = dataclasses.asdict(render_tiled(scene, 32).stats)  # (a run of its own)
    times = tuple(f for f in whole if f.startswith("time_"))
    assert sorted(WHOLE_IMAGE + MOST + WORK + times) == sorted(
        f.name for f in dataclasses.fields(RenderStats))
    assert whole["secondary_max_depth"] > 0 and whole["aa_pixels"] > 0
    for f in WHOLE_IMAGE:
        assert merged[f] == whole[f] == tiled[f], f
    for f in MOST:
        assert merged[f] == max(t[f] for t in tiles), f
    for f in WORK:
        assert merged[f] == sum(t[f] for t in tiles) >= whole[f], f
    for f in times:
        assert merged[f] == pytest.approx(sum(t[f] for t in tiles), rel=1e-12), f
