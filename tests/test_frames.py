"""Turntable frames (frames.py, ``render --turntable N --frames A:B[:STEP]``)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from subtrace.cli import main
from subtrace.errors import SceneError
from subtrace.frames import frame_path, parse_frames, turntable_eye
from subtrace.io.exr import read_exr

CUBE = ("v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n"
        "f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 3 4 8 7\nf 2 3 7 6\nf 1 5 8 4\n")


def test_frame_paths():
    assert frame_path("out/spin.####.exr", 7) == "out/spin.0007.exr"
    assert frame_path("a#b.##.png", 12) == "a#b.12.png"  # the last run of '#'
    assert frame_path("spin.exr", 3) == "spin.0003.exr"
    assert frame_path("spin.#.exr", 123) == "spin.123.exr"  # wider numbers are not cut


def test_frame_ranges():
    assert list(parse_frames(None, 5)) == [0, 1, 2, 3, 4]
    assert list(parse_frames("1:4", 5)) == [1, 2, 3]
    assert list(parse_frames("0::2", 5)) == [0, 2, 4]
    assert list(parse_frames("3", 5)) == [3]
    assert list(parse_frames(":2", 5)) == [0, 1]
    for bad in ("a:b", "1:4:0", "5:9", "4:2", "1:2:3:4", "-1:2"):
        with pytest.raises(SceneError) as err:
            parse_frames(bad, 5)
        assert err.value.key == "--frames"


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 63), st.integers(1, 64),
       st.tuples(*[st.floats(-10, 10)] * 3).filter(lambda v: np.linalg.norm(v) > 0.1))
def test_turntable_keeps_height_and_radius(k, n, offset):
    """The eye turns about the up axis through the target: its height along the axis and its
    distance from it stay; a whole turn returns to the start; frame 0 is the eye itself."""
    target = np.array([0.5, -1.0, 2.0])
    up = np.array([0.0, 1.0, 0.0])
    eye = target + np.asarray(offset)
    e = np.asarray(turntable_eye(eye, target, up, k, n)) - target
    v = eye - target
    assert math.isclose(e[1], v[1], abs_tol=1e-9)
    assert math.isclose(math.hypot(e[0], e[2]), math.hypot(v[0], v[2]), abs_tol=1e-9)
    np.testing.assert_allclose(turntable_eye(eye, target, up, n, n), eye, atol=1e-9)
    np.testing.assert_allclose(turntable_eye(eye, target, up, 0, n), eye, atol=0)


def test_turntable_frames_equal_single_renders(tmp_path, capsys):
    """Each frame written by one --turntable process is, pixel for pixel, the render of the
    same view asked for alone (with --eye at the turned position)."""
    cube = tmp_path / "cube.obj"
    cube.write_text(CUBE)
    view = ["--eye", "4", "2", "3", "--target", "0", "0", "0", "--width", "48", "--height",
            "32", "--quiet"]
    pattern = tmp_path / "spin.##.exr"
    assert main(["render", str(cube), "-o", str(pattern), *view, "--turntable", "6",
                 "--frames", "1:6:2"]) == 0
    assert sorted(p.name for p in tmp_path.glob("spin.*.exr")) == [
        "spin.01.exr", "spin.03.exr", "spin.05.exr"]
    for k in (1, 3, 5):
        eye = turntable_eye((4.0, 2.0, 3.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), k, 6)
        single = tmp_path / f"single{k}.exr"
        assert main(["render", str(cube), "-o", str(single), *view[8:], "--eye",
                     *map(repr, eye), "--target", "0", "0", "0"]) == 0
        a, _ = read_exr(tmp_path / f"spin.{k:02d}.exr")
        b, _ = read_exr(single)
        for name in a:
            np.testing.assert_array_equal(a[name], b[name], err_msg=f"frame {k} {name}")


@pytest.mark.parametrize("flags, words", [
    (["--frames", "0:2"], "--frames"),
    (["--turntable", "0"], "--turntable"),
    (["--turntable", "x"], "--turntable"),
    (["--turntable", "4", "--frames", "4:8"], "--frames"),
])
def test_bad_frame_options(tmp_path, capsys, flags, words):
    cube = tmp_path / "cube.obj"
    cube.write_text(CUBE)
    assert main(["render", str(cube), "-o", str(tmp_path / "x.exr"), *flags]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and words in err
    assert not list(tmp_path.glob("x*.exr"))


def test_resume_leaves_out_complete_frames(tmp_path, capsys):
    """--resume renders only the frames whose output is missing or does not read back (a
    damaged file); the frames already there are left untouched, and it says how many."""
    cube = tmp_path / "cube.obj"
    cube.write_text(CUBE)
    args = ["render", str(cube), "-o", str(tmp_path / "spin.#.exr"), "--width", "24",
            "--height", "16", "--turntable", "4"]
    assert main([*args, "--quiet"]) == 0
    kept = (tmp_path / "spin.1.exr").stat().st_mtime_ns
    (tmp_path / "spin.2.exr").unlink()
    (tmp_path / "spin.3.exr").write_bytes(b"not an image")
    capsys.readouterr()
    assert main([*args, "--resume"]) == 0
    out = capsys.readouterr().out
    assert "--resume: 2 of 4 frames already there, left out" in out
    assert "spin.2.exr" in out and "spin.3.exr" in out and "spin.1.exr" not in out
    assert (tmp_path / "spin.1.exr").stat().st_mtime_ns == kept
    for k in range(4):
        read_exr(tmp_path / f"spin.{k}.exr")
    assert main([*args, "--resume"]) == 0
    assert "--resume: 4 of 4 frames already there" in capsys.readouterr().out


def test_resume_needs_frames(tmp_path, capsys):
    cube = tmp_path / "cube.obj"
    cube.write_text(CUBE)
    assert main(["render", str(cube), "-o", str(tmp_path / "x.exr"), "--resume"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--resume" in err


def test_render_frames_api(tmp_path):
    """subtrace.render_frames: a FrameResult per frame, in frame order, the statistics of
    each; the frames equal the command's."""
    import subtrace

    cube = tmp_path / "cube.obj"
    cube.write_text(CUBE)
    from subtrace.io.scene import apply_overrides, scene_for_meshes

    scene = apply_overrides(scene_for_meshes([str(cube)]), width=24, height=16)
    done = subtrace.render_frames(scene, str(tmp_path / "api.##.exr"), turntable=5,
                                  frames="1:5:2")
    assert [(f.frame, f.path, f.skipped) for f in done] == [
        (1, str(tmp_path / "api.01.exr"), False), (3, str(tmp_path / "api.03.exr"), False)]
    assert all(f.stats["pixels_covered"] > 0 for f in done)
    again = subtrace.render_frames(scene, str(tmp_path / "api.##.exr"), turntable=5,
                                   resume=True)
    assert [(f.frame, f.skipped) for f in again] == [(0, False), (1, True), (2, False),
                                                     (3, True), (4, False)]
