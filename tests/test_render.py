"""The renderer (render.render_scene): progress up to every ray, images independent of
the memos and threads, unused vertices, the automatic camera."""

from __future__ import annotations

import numpy as np
import pytest
from shared_data import MODELS, small_scene

import subtrace
from subtrace.render import render_scene


def test_render_reports_progress_up_to_every_ray():
    """``render_scene(progress=...)`` is told the rays whose hits are final, never fewer than
    before, ending at all of them; a ProgressBar draws that on one line."""
    import io

    from subtrace.runtime.progress import ProgressBar

    calls = []
    scene = small_scene([MODELS / "spot_control_mesh.obj"], (1.2, 0.6, 2.2), (0.0, 0.3, 0.0),
                   width=48, height=36)
    render_scene(scene, progress=lambda d, t, label: calls.append((d, t, label)))
    done = [d for d, _, _ in calls]
    assert len(calls) >= 3 and all(t == 48 * 36 for _, t, _ in calls)
    assert done[0] == 0 and done[-1] == 48 * 36 and np.all(np.diff(done) >= 0)
    out = io.StringIO()
    bar = ProgressBar(out)
    for d, t, label in calls:
        bar(d, t, label)
    text = out.getvalue()
    assert text.count("\n") == 1 and text.endswith("\n") and "round" in text


@pytest.mark.parametrize("mesh", ["spot_control_mesh.obj", "spot_low_resolution.obj"])
def test_memo_and_threads_do_not_change_the_image(mesh, monkeypatch):
    """Rays share their Bezier splits (quads, and Loop triangles' nets) through a per-thread
    memo; a memo that runs out makes the rays split on the spot instead. Neither the memo's
    size nor the thread count may change a single bit of the image (the same cells, boxes
    and order either way)."""
    from subtrace.runtime import threads as tasks
    from subtrace.trace import pools

    mesh = MODELS / mesh
    scene = small_scene([mesh], (1.2, 0.6, 2.2), (0.0, 0.3, 0.0), width=96, height=72,
                   tolerance=0.5)
    cage = subtrace.load_cage(mesh)
    base = render_scene(scene, cages=[cage], threads=1)
    assert base.stats.pixels_covered > 1000
    two = render_scene(scene, cages=[cage], threads=min(2, tasks.max_threads()))
    monkeypatch.setattr(pools.Memos, "START", {"child": 64, "nets": 8, "cells": 16})
    small = render_scene(scene, cages=[cage], threads=1)
    assert small.stats.rounds > base.stats.rounds or small.stats.memo_full > 0
    for name, ch in base.channels.items():
        assert np.array_equal(ch, two.channels[name], equal_nan=True), name
        assert np.array_equal(ch, small.channels[name], equal_nan=True), name


CUBE = """v -0.5 -0.5 0.5
v 0.5 -0.5 0.5
v -0.5 0.5 0.5
v 0.5 0.5 0.5
v -0.5 0.5 -0.5
v 0.5 0.5 -0.5
v -0.5 -0.5 -0.5
v 0.5 -0.5 -0.5
f 1 2 4 3
f 3 4 6 5
f 5 6 8 7
f 7 8 2 1
f 2 8 6 4
f 7 1 3 5
"""


def _unused_cube(tmp_path, before, after):
    """The cube with a vertex ``before`` its eight and one ``after``, which no face uses."""
    lines = CUBE.splitlines()
    renumber = lambda s: " ".join(str(int(i) + 1) for i in s.split())
    text = "\n".join([f"v {before}"] + lines[:8] + [f"f {renumber(f[2:])}" for f in lines[8:]]
                     + [f"v {after}"]) + "\n"
    path = tmp_path / "cube_unused.obj"
    path.write_text(text)
    return path


@pytest.mark.parametrize("before,after", [("9 9 9", "7 7 7"), ("0 -40 0", "0.1 0.2 0.3")])
def test_unused_vertices_leave_the_picture_as_it_is(tmp_path, before, after):
    """Vertices that no face uses (common in OBJ files) are no part of the limit surface:
    the default picture of a cube with two of them (the automatic camera, which they used
    to push away until the cube was a few pixels wide, the lights and the ground, which
    they could move far below it) is the cube's alone, channel for channel."""
    from subtrace.io.scene import apply_overrides, scene_for_meshes

    plain = tmp_path / "cube.obj"
    plain.write_text(CUBE)
    images = []
    for path in (plain, _unused_cube(tmp_path, before, after)):
        scene = apply_overrides(scene_for_meshes([str(path)]), width=96, height=64)
        images.append(render_scene(scene).channels)
    assert set(images[0]) == set(images[1])
    assert np.count_nonzero(images[0]["A"]) > 0.1 * images[0]["A"].size
    for name in images[0]:
        assert np.array_equal(images[0][name], images[1][name], equal_nan=True), name


def test_the_automatic_camera_stays_out_of_the_shells_and_frames_the_shadow(tmp_path):
    """A four-face Loop tetrahedron, whose limit surface is far smaller than its cage,
    with the default picture: the eye lies outside the cage's box (it was inside the
    patches' shells: depth 14, 828k micro-triangles and a warning about the eye inside
    them), nothing warns, and the ground's shadow lies whole in the image (no pixel on the
    border darker than the background there)."""
    import warnings

    from subtrace.io.scene import apply_overrides, scene_for_meshes

    path = tmp_path / "tetrahedron.obj"
    path.write_text("v 1 1 1\nv -1 -1 1\nv -1 1 -1\nv 1 -1 -1\n"
                    "f 1 2 3\nf 1 4 2\nf 1 3 4\nf 2 4 3\n")
    scene = apply_overrides(scene_for_meshes([str(path)]), width=160, height=90)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        result = render_scene(scene)
    eye = np.asarray(result.camera.eye)
    assert np.any(np.abs(eye) > 1.0)  # (the cage's box is [-1, 1]^3)
    ch = result.channels
    top, bottom = (np.asarray(c) for c in (scene.render.background,
                                           scene.render.background_bottom))
    w = (np.arange(90) + 0.5) / 90
    back = (1 - w) * top[0] + w * bottom[0]  # the gradient's red, row by row
    shadow = (ch["A"] == 0) & (ch["R"] < 0.8 * back[:, None])
    assert shadow.sum() > 100  # (the key light's shadow, beside the object)
    assert not (shadow[0].any() or shadow[-1].any() or shadow[:, 0].any()
                or shadow[:, -1].any())
