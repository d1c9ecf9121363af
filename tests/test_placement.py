"""Placed objects (``[[object]]`` translate / rotate / orient / scale / matrix,
``io/placement.py``): the parts against analytic matrices, the placed cage's limit surface
is the cage's own mapped (subdivision commutes with affine maps), two copies of one cage
render side by side, and bad values are one clear error naming the key."""

from __future__ import annotations

import math

import numpy as np
import pytest

from subtrace.errors import SceneError
from subtrace.io import placement
from subtrace.io.scene import load_scene, scene_from_dict
from subtrace.prepare import load_objects
from subtrace.render import render_scene

CUBE = ("v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\n"
        "v -1 1 1\nf 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n")


def _scene(tmp_path, *objects, **extra):
    path = tmp_path / "cube.obj"
    path.write_text(CUBE)
    return scene_from_dict({"object": [{"mesh": str(path), **o} for o in objects], **extra},
                           base_dir=tmp_path)


def test_the_parts_are_the_rotations_and_scales_they_name():
    r = placement.check_rotate([90.0, 0.0, 0.0])  # about X: y -> z
    np.testing.assert_allclose(r @ [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], atol=1e-15)
    r = placement.check_rotate([0.0, 0.0, 90.0])  # about Z: x -> y
    np.testing.assert_allclose(r @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-15)
    # X first, then Y: (0, 1, 0) -> (0, 0, 1) -> (1, 0, 0)
    np.testing.assert_allclose(placement.check_rotate([90.0, 90.0, 0.0]) @ [0.0, 1.0, 0.0],
                               [1.0, 0.0, 0.0], atol=1e-15)
    h = math.sqrt(0.5)  # 90 degrees about Y as a quaternion, any length
    np.testing.assert_allclose(placement.check_orient([2 * h, 0.0, 2 * h, 0.0]),
                               placement.check_rotate([0.0, 90.0, 0.0]), atol=1e-15)
    m = placement.compose(np.array([1.0, 2.0, 3.0]), placement.check_rotate([0, 0, 90]),
                          placement.check_scale(2.0))
    np.testing.assert_allclose(placement.place(np.array([[1.0, 0.0, 0.0]]), m),
                               [[1.0, 4.0, 3.0]], atol=1e-14)  # scaled, turned, moved


def test_a_placed_cage_is_the_cage_mapped_down_to_its_limit_surface(tmp_path):
    """Uniform refinement and exact limit points of the placed cage equal the mapped ones
    of the cage as read (to rounding), and ``matrix`` is the same placement as its parts."""
    parts = {"translate": [0.5, -2.0, 3.0], "rotate": [20.0, -35.0, 50.0],
             "scale": [1.5, 0.5, 2.0]}
    plain, = load_objects(_scene(tmp_path, {}))
    moved, = load_objects(_scene(tmp_path, parts))
    m = np.array(_scene(tmp_path, parts).objects[0].transform)
    as_matrix, = load_objects(_scene(tmp_path, {"matrix": m.tolist()}))
    for level in (1, 2):
        want = placement.place(plain.refine(level).points, m)
        np.testing.assert_allclose(moved.refine(level).points, want, atol=1e-12)
        np.testing.assert_allclose(moved.limit(level)[0],
                                   placement.place(plain.limit(level)[0], m), atol=1e-12)
    np.testing.assert_array_equal(as_matrix.points, moved.points)


def test_two_placed_copies_render_side_by_side(tmp_path):
    """One cage placed twice, 3 apart along X: the automatic camera frames both, each
    object id covers its own side of the image, and they do not overlap."""
    scene = _scene(tmp_path, {"translate": [-3.0, 0.0, 0.0]},
                   {"translate": [3.0, 0.0, 0.0], "rotate": [0.0, 45.0, 0.0]},
                   camera={"width": 96, "height": 48},
                   render={"samples": 1, "shadows": False})
    ch = render_scene(scene).channels
    ids = ch["object_id"]
    cols = np.arange(ids.shape[1])[None, :].repeat(ids.shape[0], axis=0)
    left, right = cols[ids == 0], cols[ids == 1]
    assert len(left) > 100 and len(right) > 100
    assert left.max() < right.min()


@pytest.mark.parametrize("body, key, words", [
    ("translate = [1, 2]\n", "object[0].translate", "3 numbers"),
    ("scale = 0\n", "object[0].scale", "flattens"),
    ("orient = [0, 0, 0, 0]\n", "object[0].orient", "zero"),
    ("rotate = [0, 90, 0]\norient = [1, 0, 0, 0]\n", "object[0].orient", "not both"),
    ("matrix = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]]\n",
     "object[0].matrix", "last row"),
    ("matrix = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 0, 0], [0, 0, 0, 1]]\n",
     "object[0].matrix", "singular"),
    ("matrix = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]\nscale = 2\n",
     "object[0].scale", "not both"),
])
def test_bad_placements_are_one_clear_error(tmp_path, body, key, words):
    (tmp_path / "cube.obj").write_text(CUBE)
    path = tmp_path / "scene.toml"
    path.write_text('[[object]]\nmesh = "cube.obj"\n' + body)
    with pytest.raises(SceneError) as err:
        load_scene(path)
    message = str(err.value)
    assert str(path) in message and key in message and words in message, message
