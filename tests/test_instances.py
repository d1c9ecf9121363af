"""Placed copies of one cage (``[[object]]`` tables naming one file with the same reading
options, differing in their placement): the file is read once and the copies share its
face lists, tags and topology (``prepare.load_objects``, ``mesh.cage.placed``), each with
its own mapped points; the render of such a scene is the render of the copies loaded one
by one, bit for bit, mirrored copies included; a missing file among them is one error."""

from __future__ import annotations

import numpy as np
import pytest

from subtrace.errors import SceneError
from subtrace.io.placement import place
from subtrace.io.scene import scene_from_dict
from subtrace.mesh.cage import load_cage, placed, without_unused_vertices
from subtrace.prepare import load_objects
from subtrace.render import render_scene

# an open box with a hole and a crease, so boundaries and tags take part
CAGE = ("v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\n"
        "v -1 1 1\nf 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\n"
        "t crease 2/1/0 0 1 3.0\n")

PLACES = [
    {"translate": [-2.5, 0.0, 0.0]},
    {"translate": [0.0, 0.0, 0.0], "rotate": [30.0, 45.0, 10.0], "scale": 0.8},
    {"translate": [2.5, 0.2, 0.0], "scale": [-1.0, 1.2, 0.9]},  # mirrored: det < 0
    {"matrix": [[1, 0.3, 0, 0], [0, 1, 0, 2.2], [0, 0, 1, 0], [0, 0, 0, 1]]},  # sheared
    {},  # as the file has it, behind the others
]


def _scene(tmp_path, places, **render):
    path = tmp_path / "box.obj"
    path.write_text(CAGE)
    return scene_from_dict({
        "object": [{"mesh": str(path), **p} for p in places],
        "camera": {"eye": [0.5, 2.0, 9.0], "target": [0.0, 0.5, 0.0], "fov": 45.0,
                   "width": 120, "height": 72},
        "render": {"samples": 1, **render},
        "light": [{"direction": [-0.3, -1.0, -0.4], "intensity": 0.8}],
        "ground": {}}, base_dir=tmp_path)


def test_copies_of_one_file_share_its_topology_and_own_their_points(tmp_path):
    scene = _scene(tmp_path, PLACES)
    cages = load_objects(scene)
    assert len(cages) == len(PLACES)
    first = cages[0]
    assert first.has_topology  # built once, for every copy
    for c, o in zip(cages, scene.objects):
        assert c.base is first.base and c.face_verts is first.face_verts
        want = (load_cage(o.mesh).points if o.transform is None
                else place(load_cage(o.mesh).points, o.transform))
        np.testing.assert_array_equal(c.points, want)
    # each copy's caches are its own: a copy's limit points are its own surface's
    np.testing.assert_allclose(cages[1].limit(1)[0],
                               place(cages[4].limit(1)[0], scene.objects[1].transform),
                               atol=1e-12)
    assert cages[4] is not cages[0]


def test_one_object_of_a_file_is_read_as_before(tmp_path):
    """No copies: the cage is the file's as read, its topology not built ahead."""
    c, = load_objects(_scene(tmp_path, PLACES[1:2]))
    assert not c.has_topology


@pytest.mark.parametrize("render", [{"shadows": True}, {"shadows": True, "ao": 4}])
def test_copies_render_as_the_cages_loaded_one_by_one(tmp_path, render):
    """The scene of placed copies (one file read once) against the same cages each read
    and placed on its own (``render_scene(scene, cages)``): every channel equal bit for
    bit, shadows cast from copy to copy and occlusion included; every copy is seen, and
    the mirrored copy's normals face the eye."""
    scene = _scene(tmp_path, PLACES, **render)
    alone = [without_unused_vertices(placed(load_cage(o.mesh), o.transform))
             for o in scene.objects]
    assert all(a.base is not alone[0].base for a in alone[1:])
    got = render_scene(scene).channels
    want = render_scene(scene, cages=alone).channels
    assert set(got) == set(want)
    for name in want:
        np.testing.assert_array_equal(got[name], want[name], err_msg=name)
    ids = got["object_id"]
    assert {int(k) for k in np.unique(ids[ids >= 0])} == set(range(len(PLACES)))
    # the mirrored copy (object 2): unit normals, towards the eye's side of the surface
    on = ids == 2
    n = np.stack([got[f"N.{a}"][on] for a in "XYZ"], axis=1).astype(np.float64)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-6)


def test_a_missing_file_among_copies_is_one_error(tmp_path):
    """One copy of a file that is not there: the scene's one error names that object's
    mesh key and the file (the command line's one line, exit code 2)."""
    scene = _scene(tmp_path, PLACES[:2])
    missing = str(tmp_path / "nowhere.obj")
    with pytest.raises(SceneError) as err:
        scene_from_dict({"object": [{"mesh": scene.objects[0].mesh},
                                    {"mesh": missing, "translate": [1, 0, 0]},
                                    {"mesh": scene.objects[0].mesh, "scale": 2}]},
                        base_dir=tmp_path)
    message = str(err.value)
    assert "nowhere.obj" in message and "object[1].mesh" in message, message
    assert "\n" not in message
