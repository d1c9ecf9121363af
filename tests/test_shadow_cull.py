"""Culling to the view keeps what casts a shadow into it (render.faces_in_view's sweeps): an
object outside the picture whose shadow falls on the visible ground renders the same with
the lazy table as with the full one."""

from __future__ import annotations

import numpy as np
import pytest

from subtrace import config
from subtrace.io.scene import scene_from_dict
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
