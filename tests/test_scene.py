"""Tests of subtrace.io.scene: the TOML schema, error messages (file, line, key, problem),
automatic cameras and command-line overrides."""

from __future__ import annotations

import math
import os
from pathlib import Path

import pytest
from shared_data import error_without_root_powers

from subtrace.errors import SceneError
from subtrace.io.obj import BOUNDARY_EDGE_AND_CORNER, BOUNDARY_NONE
from subtrace.io.scene import (
    CameraSettings,
    Ground,
    Light,
    RenderSettings,
    Scene,
    SceneObject,
    apply_overrides,
    load_scene,
    scene_for_meshes,
    scene_from_dict,
)
from subtrace.camera import Camera

TRI = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"

# Every feature of the schema; line numbers below refer to this text.
FULL = """\
# a scene with every feature
output = "renders/out.exr"
preview = "renders/out.png"

[camera]
eye = [0.0, 1.0, 5.0]
target = [0.0, 0.5, 0.0]
up = [0.0, 1.0, 0.0]
fov = 40
width = 320
height = 200

[render]
tolerance = 0.5
background = [0.1, 0.2, 0.3]
headlight = false
headlight_intensity = 0.7

[[light]]
direction = [0, -2, 0]
color = [1.0, 0.9, 0.8]
intensity = 2.5

[[light]]
direction = [1, 0, 0]

[[object]]
mesh = "meshes/tri.obj"
scheme = "catmull-clark"
boundary = "edge-and-corner"
color = [0.8, 0.5, 0.25]

[[object]]
mesh = "tri2.obj"
scheme = "loop"
boundary = "none"
"""


@pytest.fixture
def folder(tmp_path) -> Path:
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "tri.obj").write_text(TRI)
    (tmp_path / "tri2.obj").write_text(TRI)
    return tmp_path


def write(folder: Path, text: str, name: str = "scene.toml") -> Path:
    path = folder / name
    path.write_bytes(text.encode("utf-8"))
    return path


def error_of(path: Path) -> SceneError:
    with pytest.raises(SceneError) as info:
        load_scene(path)
    return info.value


# --------------------------------------------------------------------------------------
# a valid scene
# --------------------------------------------------------------------------------------


def test_full_scene(folder, monkeypatch):
    path = write(folder, FULL)
    monkeypatch.chdir("/")  # relative paths follow the scene file, not the working dir
    scene = load_scene(path)
    assert isinstance(scene, Scene)
    assert scene.path == str(path)
    assert scene.output == str(folder / "renders" / "out.exr")
    assert scene.preview == str(folder / "renders" / "out.png")
    assert scene.camera == CameraSettings(
        eye=(0.0, 1.0, 5.0),
        target=(0.0, 0.5, 0.0),
        up=(0.0, 1.0, 0.0),
        fov_deg=40.0,
        width=320,
        height=200,
    )
    assert not scene.camera.is_auto
    assert scene.render == RenderSettings(
        tolerance_px=0.5,
        tolerance_deg=None,
        background=(0.1, 0.2, 0.3),
        background_bottom=None,  # (one colour given: a flat background)
        headlight=False,
        headlight_intensity=0.7,
    )
    assert scene.lights == (
        Light(direction=(0.0, -1.0, 0.0), color=(1.0, 0.9, 0.8), intensity=2.5),
        Light(direction=(1.0, 0.0, 0.0), color=(1.0, 1.0, 1.0), intensity=1.0),
    )
    assert scene.objects == (
        SceneObject(
            mesh=str(folder / "meshes" / "tri.obj"),
            scheme="catmark",
            boundary="edge-and-corner",
            color=(0.8, 0.5, 0.25),
        ),
        SceneObject(mesh=str(folder / "tri2.obj"), scheme="loop", boundary="none", color=None),
    )
    assert scene.objects[0].boundary_code == BOUNDARY_EDGE_AND_CORNER
    assert scene.objects[1].boundary_code == BOUNDARY_NONE
    cam = scene.make_camera()
    assert isinstance(cam, Camera) and (cam.width, cam.height, cam.fov_deg) == (320, 200, 40.0)
    assert scene.render.tolerance_rad(cam) == pytest.approx(0.5 * cam.pixel_angle(), rel=1e-15)
    with pytest.raises(AttributeError):
        scene.output = "x"  # frozen


def test_minimal_scene_defaults(folder):
    """A bare scene gets the picture defaults (io/scene.py: the command line's too): the
    automatic camera at 1280x720 and 30 degrees, a gradient, a key and a fill light with
    shadows, a weak headlight and a shadow-catching ground at the lowest point."""
    scene = load_scene(write(folder, '[[object]]\nmesh = "tri2.obj"\n'))
    obj = scene.objects[0]
    assert (obj.scheme, obj.boundary, obj.color, obj.boundary_code) == (None, None, None, None)
    assert scene.camera == CameraSettings()
    assert scene.camera.is_auto and scene.camera.eye is None and scene.camera.target is None
    assert (scene.camera.width, scene.camera.height, scene.camera.fov_deg) == (1280, 720, 30.0)
    assert scene.camera.up == (0.0, 1.0, 0.0)
    assert scene.render == RenderSettings()
    assert scene.render.tolerance_px == 1.0 and scene.render.tolerance_deg is None
    assert scene.render.headlight is True and scene.render.headlight_intensity == 0.2
    assert scene.render.background != scene.render.background_bottom  # a gradient
    assert scene.render.shadows and scene.render.background_bottom is not None
    assert len(scene.lights) == 2 and all(lamp.direction[1] < 0 for lamp in scene.lights)
    assert [lamp.intensity for lamp in scene.lights] == [0.75, 0.25]
    assert scene.ground == Ground(height=None, color=None)
    assert scene.output is None and scene.preview is None


def test_auto_camera_frames_bounds(folder):
    text = '[camera]\nwidth = 200\nheight = 100\nfov = 25\n\n[[object]]\nmesh = "tri2.obj"\n'
    scene = load_scene(write(folder, text))
    assert scene.camera.is_auto
    with pytest.raises(ValueError, match="bounds"):
        scene.make_camera()
    cam = scene.make_camera((0, 0, 0), (1, 1, 0))
    assert (cam.width, cam.height, cam.fov_deg) == (200, 100, 25.0)
    assert cam.target == (0.5, 0.5, 0.0)
    z_up = load_scene(write(folder, text.replace("fov = 25", "up = [0, 0, 1]")))
    assert z_up.make_camera((0, 0, 0), (1, 1, 0)).up == (0.0, 0.0, 1.0)


def test_tolerance_in_degrees(folder):
    text = '[render]\ntolerance_deg = 0.05\n[[object]]\nmesh = "tri2.obj"\n'
    scene = load_scene(write(folder, text))
    assert scene.render.tolerance_px is None and scene.render.tolerance_deg == 0.05
    cam = Camera((0, 0, 5), (0, 0, 0), (0, 1, 0), 30, 64, 64)
    assert scene.render.tolerance_rad(cam) == math.radians(0.05)


def test_single_tables_and_dotted_keys(folder):
    text = '[object]\nmesh = "tri2.obj"\n\n[light]\ndirection = [0, 0, -3]\n'
    scene = load_scene(write(folder, text))
    assert len(scene.objects) == 1 and scene.lights[0].direction == (0.0, 0.0, -1.0)


def test_utf8_bom_and_crlf(folder):
    text = '\ufeff[[object]]\r\nmesh = "tri2.obj"\r\n'
    path = folder / "bom.toml"
    path.write_bytes(text.encode("utf-8"))
    assert load_scene(path).objects[0].mesh == str(folder / "tri2.obj")


def test_scene_from_dict_and_base_dir(folder, monkeypatch):
    d = {"object": [{"mesh": "tri2.obj"}], "output": "a.exr"}
    scene = scene_from_dict(d, base_dir=folder)
    assert scene.path is None and scene.output == str(folder / "a.exr")
    monkeypatch.chdir(folder)
    assert scene_from_dict(d).objects[0].mesh == str(folder / "tri2.obj")
    with pytest.raises(SceneError) as info:
        scene_from_dict({"object": [{"mesh": "tri2.obj", "sheme": "loop"}]})
    # no file: the message starts with the key path
    assert str(info.value).startswith("object[0].sheme: unknown key 'sheme'")


def test_scene_for_meshes(folder, monkeypatch):
    monkeypatch.chdir(folder)
    scene = scene_for_meshes(["tri2.obj", folder / "meshes" / "tri.obj"], scheme="loop")
    assert [o.mesh for o in scene.objects] == [
        str(folder / "tri2.obj"),
        str(folder / "meshes" / "tri.obj"),
    ]
    assert all(o.scheme == "loop" for o in scene.objects) and scene.camera.is_auto
    with pytest.raises(SceneError, match="--scheme: unknown value 'bezier'"):
        scene_for_meshes(["tri2.obj"], scheme="bezier")
    with pytest.raises(SceneError, match="^nope.obj: no such mesh file$"):
        scene_for_meshes(["nope.obj"])


# --------------------------------------------------------------------------------------
# errors: one per bad input; each names the file, the line, the key and the problem
# --------------------------------------------------------------------------------------

BAD = [
    # (name, replace this, with this, line, key, words in the message)
    ("fov 180", "fov = 40", "fov = 180", 9, "camera.fov", "between 0 and 180"),
    ("fov 0", "fov = 40", "fov = 0", 9, "camera.fov", "between 0 and 180"),
    ("fov negative", "fov = 40", "fov = -5.0", 9, "camera.fov", "between 0 and 180"),
    ("fov nan", "fov = 40", "fov = nan", 9, "camera.fov", "between 0 and 180"),
    ("fov string", "fov = 40", 'fov = "wide"', 9, "camera.fov", "expected a number"),
    ("fov typo", "fov = 40", "fvo = 40", 9, "camera.fvo", "did you mean 'fov'"),
    ("eye = target", "eye = [0.0, 1.0, 5.0]", "eye = [0.0, 0.5, 0.0]", 7, "camera.target",
     "coincide"),
    ("up parallel", "up = [0.0, 1.0, 0.0]", "up = [0.0, -0.1, -1.0]", 8, "camera.up",
     "parallel"),
    ("up zero", "up = [0.0, 1.0, 0.0]", "up = [0, 0, 0]", 8, "camera.up", "zero"),
    ("eye short", "eye = [0.0, 1.0, 5.0]", "eye = [0.0, 1.0]", 6, "camera.eye", "3 numbers"),
    ("eye inf", "eye = [0.0, 1.0, 5.0]", "eye = [0.0, 1.0, inf]", 6, "camera.eye", "finite"),
    ("eye string", "eye = [0.0, 1.0, 5.0]", 'eye = "front"', 6, "camera.eye", "3 numbers"),
    ("eye missing", "eye = [0.0, 1.0, 5.0]\n", "", 6, "camera.target",
     "target is given but eye is not"),
    ("width 0", "width = 320", "width = 0", 10, "camera.width", "between 1 and 32768"),
    ("width negative", "width = 320", "width = -320", 10, "camera.width", "between 1 and 32768"),
    ("width huge", "width = 320", "width = 32769", 10, "camera.width", "between 1 and 32768"),
    ("height float", "height = 200", "height = 200.5", 11, "camera.height", "whole number"),
    ("height string", "height = 200", 'height = "200"', 11, "camera.height", "whole number"),
    ("tolerance 0", "tolerance = 0.5", "tolerance = 0", 14, "render.tolerance",
     "greater than 0"),
    ("tolerance negative", "tolerance = 0.5", "tolerance = -1", 14, "render.tolerance",
     "greater than 0"),
    ("tolerance both", "tolerance = 0.5", "tolerance = 0.5\ntolerance_deg = 0.1", 15,
     "render.tolerance_deg", "not both"),
    ("tolerance_deg 0", "tolerance = 0.5", "tolerance_deg = 0.0", 14, "render.tolerance_deg",
     "greater than 0"),
    ("background range", "background = [0.1, 0.2, 0.3]", "background = [0.1, 2, 0.3]", 15,
     "render.background", "between 0 and 1"),
    ("headlight string", "headlight = false", 'headlight = "no"', 16, "render.headlight",
     "true or false"),
    ("headlight intensity", "headlight_intensity = 0.7", "headlight_intensity = -0.7", 17,
     "render.headlight_intensity", "0 or more"),
    ("render typo", "headlight = false", "headlite = false", 16, "render.headlite",
     "did you mean 'headlight'"),
    ("light direction zero", "direction = [0, -2, 0]", "direction = [0, 0, 0]", 20,
     "light[0].direction", "non-zero"),
    ("light missing direction", "direction = [1, 0, 0]\n", "", 24, "light[1]",
     "missing key direction"),
    ("light intensity", "intensity = 2.5", "intensity = -1", 22, "light[0].intensity",
     "0 or more"),
    ("light color", "color = [1.0, 0.9, 0.8]", "color = [1.0, 0.9]", 21, "light[0].color",
     "3 numbers"),
    ("mesh missing file", 'mesh = "tri2.obj"', 'mesh = "cow.obj"', 34, "object[1].mesh",
     "'cow.obj' does not exist"),
    ("mesh is a folder", 'mesh = "tri2.obj"', 'mesh = "meshes"', 34, "object[1].mesh",
     "is a directory"),
    ("mesh not a string", 'mesh = "tri2.obj"', "mesh = 3", 34, "object[1].mesh",
     "expected a file name"),
    ("mesh key missing", 'mesh = "tri2.obj"\n', "", 33, "object[1]", "missing key mesh"),
    ("scheme unknown", 'scheme = "loop"', 'scheme = "bspline"', 35, "object[1].scheme",
     "unknown value 'bspline'"),
    ("boundary unknown", 'boundary = "none"', 'boundary = "sharp"', 36, "object[1].boundary",
     "'edge-only'"),
    ("object color", "color = [0.8, 0.5, 0.25]", "color = [0.8, -0.5, 0.25]", 31,
     "object[0].color", "between 0 and 1"),
    ("object typo", 'scheme = "loop"', 'schema = "loop"', 35, "object[1].schema",
     "did you mean 'scheme'"),
    ("top-level typo", 'output = "renders/out.exr"', 'outptu = "renders/out.exr"', 2,
     "outptu", "allowed keys: object, camera, render, light, ground, output, preview"),
    ("table typo", "[camera]", "[camra]", 5, "camra", "did you mean 'camera'"),
    ("output not a string", 'output = "renders/out.exr"', "output = true", 2, "output",
     "expected a file name"),
    ("preview not a png", 'preview = "renders/out.png"', 'preview = "renders/out.jpg"', 3,
     "preview", "ending in .png"),
]


@pytest.mark.parametrize(
    "old, new, line, key, words", [b[1:] for b in BAD], ids=[b[0] for b in BAD]
)
def test_bad_input(folder, old, new, line, key, words):
    assert FULL.count(old) >= 1
    text = FULL.replace(old, new, 1)
    path = write(folder, text)
    err = error_of(path)
    assert err.path == str(path)
    assert err.line == line, str(err)
    assert err.key == key, str(err)
    message = str(err)
    assert message.startswith(f"{path}:{line}: {key}: "), message
    assert words in message, message


def test_table_of_the_wrong_type(folder):
    err = error_of(write(folder, 'camera = 3\n[[object]]\nmesh = "tri2.obj"\n'))
    assert (err.line, err.key) == (1, "camera") and "expected a table [camera]" in str(err)
    err = error_of(write(folder, 'object = ["tri2.obj"]\n'))
    assert (err.line, err.key) == (1, "object") and "expected [[object]] tables" in str(err)


def test_no_objects(folder):
    err = error_of(write(folder, "[camera]\nfov = 30\n"))
    assert err.key == "object" and "no objects" in str(err) and "[[object]]" in str(err)
    assert str(err).startswith(f"{folder / 'scene.toml'}: object: ")


def test_empty_object_list(folder):
    err = error_of(write(folder, "object = []\n"))
    assert err.line == 1 and "no objects" in str(err)


@pytest.mark.parametrize(
    "text, line, words",
    [
        ("[[object]]\nmesh = tri2.obj\n", 2, "Invalid value"),
        ('[[object]]\nmesh = "tri2.obj"\nmesh = "tri.obj"\n', 3, "Cannot overwrite"),
        ("[camera]\nfov = 40 40\n", 2, "Expected newline"),
        ('[[object]]\nmesh = "tri2.obj', 2, "Unterminated string"),
        ("[camera]\neye = [1, 2,\n", 2, "at the end of the file"),
    ],
)
def test_toml_syntax_error(folder, text, line, words):
    path = write(folder, text)
    err = error_of(path)
    assert err.line == line, str(err)
    assert str(err).startswith(f"{path}:{line}: TOML syntax error: ")
    assert words in str(err)


def test_not_utf8(folder):
    path = folder / "latin1.toml"
    path.write_bytes('# scene\n[[object]]\nmesh = "caf\u00e9.obj"\n'.encode("latin-1"))
    err = error_of(path)
    assert err.line == 3
    assert str(err).startswith(f"{path}:3: ") and "not valid UTF-8" in str(err)


def test_unreadable_paths(folder):
    err = error_of(folder / "missing.toml")
    assert str(err) == f"{folder / 'missing.toml'}: no such scene file"
    err = error_of(folder)
    assert "is a directory" in str(err) and str(folder) in str(err)


def test_permission_denied(folder):
    path = write(folder, FULL)
    path.chmod(0)
    try:
        if hasattr(os, "geteuid") and os.geteuid() == 0:  # root reads anything: not so
            message = error_without_root_powers(f"""
from subtrace.errors import SceneError
from subtrace.io.scene import load_scene
try:
    load_scene({str(path)!r})
except SceneError as exc:
    print(exc)
""")
        else:
            message = str(error_of(path))
        assert "permission denied" in message and str(path) in message
    finally:
        path.chmod(0o644)


def test_line_lookup_survives_multiline_values(folder):
    text = (
        '[[object]]\nmesh = "tri2.obj"\n\n'
        "[camera]\n"
        "eye = [\n  0.0,\n  1.0,  # fov = 10 in a comment\n  5.0,\n]\n"
        'target = [0, 0, 0]\nnote = """\nwidth = 3\n"""\n'
        "width = 0\n"
    )
    err = error_of(write(folder, text))
    # `note` is unknown: reported first, at its own line
    assert err.key == "camera.note" and err.line == 11
    # the scanner skipped the insides of the array, the comment and the string
    from subtrace.io.scene import _KeyLines

    lines = _KeyLines(text).lines
    assert lines[("camera", "width")] == 14
    assert ("camera", "fov") not in lines
    assert lines[("camera", "eye")] == 5 and lines[("camera", "target")] == 10
    assert lines[("object", 0, "mesh")] == 2 and lines[("camera",)] == 4
    err = error_of(write(folder, text.replace('note = """\nwidth = 3\n"""\n', "")))
    assert err.key == "camera.width" and err.line == 11


def test_line_lookup_for_dotted_and_inline_keys(folder):
    text = 'camera.width = 0\n[[object]]\nmesh = "tri2.obj"\n'
    err = error_of(write(folder, text))
    assert (err.key, err.line) == ("camera.width", 1)
    text = '\ncamera = { eye = [0, 0, 1], target = [0, 0, 0], fov = 200 }\n'
    text += '[object]\nmesh = "tri2.obj"\n'
    err = error_of(write(folder, text))
    # keys inside an inline table: the line of the table's key
    assert (err.key, err.line) == ("camera.fov", 2)
    text = '[[object]]\nmesh = "tri2.obj"\n[[object]]\n\n[[object]]\nmesh = "nope.obj"\n'
    err = error_of(write(folder, text))
    assert (err.key, err.line) == ("object[1]", 3)


def test_scene_error_plain_message_still_works():
    err = SceneError("something is wrong")
    assert str(err) == "something is wrong"
    assert err.path is None and err.line is None and err.key is None


# --------------------------------------------------------------------------------------
# command-line overrides
# --------------------------------------------------------------------------------------


def test_overrides(folder, monkeypatch):
    scene = load_scene(write(folder, FULL))
    monkeypatch.chdir(folder / "meshes")
    new = apply_overrides(
        scene,
        width=64,
        height="48",
        fov="55.5",
        eye="1, 2, 3",
        target=[0, 0, 0],
        up="0 0 1",
        tolerance="2",
        scheme="loop",
        output="x.exr",
        preview="y.png",
    )
    assert new is not scene and scene.camera.width == 320  # the original is unchanged
    assert new.camera == CameraSettings(
        eye=(1.0, 2.0, 3.0), target=(0.0, 0.0, 0.0), up=(0.0, 0.0, 1.0), fov_deg=55.5,
        width=64, height=48,
    )
    assert new.render.tolerance_px == 2.0 and new.render.tolerance_deg is None
    assert [o.scheme for o in new.objects] == ["loop", "loop"]
    assert new.output == str(folder / "meshes" / "x.exr")  # relative to the working dir
    assert new.preview == str(folder / "meshes" / "y.png")
    assert new.lights == scene.lights and new.path == scene.path
    deg = apply_overrides(scene, tolerance_deg=0.25)
    assert deg.render.tolerance_deg == 0.25 and deg.render.tolerance_px is None
    assert apply_overrides(scene) == scene


OVERRIDE_ERRORS = [
    ({"fov": 180}, "--fov", "between 0 and 180"),
    ({"fov": "wide"}, "--fov", "expected a number"),
    ({"width": 0}, "--width", "between 1 and 32768"),
    ({"height": "40000"}, "--height", "between 1 and 32768"),
    ({"height": "4.5"}, "--height", "whole number"),
    ({"eye": "1,2"}, "--eye", "3 numbers"),
    ({"eye": "a,b,c"}, "--eye", "3 numbers"),
    ({"eye": "0, 0.5, 0"}, "--eye", "coincide"),
    ({"target": "0, 1, 5"}, "--target", "coincide"),
    ({"eye": "1e300, 0, 0"}, "--eye", "beyond 1e+100"),
    ({"up": "0, -0.5, -5"}, "--up", "parallel"),
    ({"tolerance": 0}, "--tolerance", "greater than 0"),
    ({"tolerance_deg": "-1"}, "--tolerance-deg", "greater than 0"),
    ({"tolerance": 1, "tolerance_deg": 1}, "--tolerance-deg", "not both"),
    ({"scheme": "bezier"}, "--scheme", "unknown value 'bezier'"),
    ({"output": ""}, "--output", "empty"),
]


@pytest.mark.parametrize("flags, option, words", OVERRIDE_ERRORS)
def test_override_errors(folder, flags, option, words):
    scene = load_scene(write(folder, FULL))
    with pytest.raises(SceneError) as info:
        apply_overrides(scene, **flags)
    assert info.value.key == option
    assert str(info.value).startswith(f"{option}: "), str(info.value)
    assert words in str(info.value)


def test_override_eye_alone_looks_at_the_centre(folder):
    """--eye without --target aims at the bounds' centre; --target alone needs an eye."""
    scene = load_scene(write(folder, '[[object]]\nmesh = "tri2.obj"\n'))
    alone = apply_overrides(scene, eye="0,0,5")
    assert alone.camera.is_auto
    cam = alone.make_camera((-1.0, 0.0, -2.0), (3.0, 2.0, 0.0))
    assert cam.eye == (0, 0, 5) and cam.target == (1.0, 1.0, -1.0)
    with pytest.raises(SceneError, match="^eye: .*coincide"):
        apply_overrides(scene, eye="1,1,-1").make_camera((0.0, 0, -2), (2.0, 2, 0))
    with pytest.raises(SceneError, match="^--target: .*give --eye as well"):
        apply_overrides(scene, target="0,0,0")
    new = apply_overrides(scene, eye="0,0,5", target="0,0,0", width=10)
    assert not new.camera.is_auto
    assert new.make_camera() == Camera((0, 0, 5), (0, 0, 0), (0, 1, 0), 30, 10, 720)


def test_override_unknown_flag_is_a_type_error(folder):
    scene = load_scene(write(folder, FULL))
    with pytest.raises(TypeError):
        apply_overrides(scene, fvo=30)


# --------------------------------------------------------------------------------------
# lighting, materials, ground and background
# --------------------------------------------------------------------------------------


def test_lights_materials_ground_and_gradient(folder):
    scene = load_scene(write(folder, """
[[object]]
mesh = "tri2.obj"
color = [0.5, 0.4, 0.3]
specular = [0.2, 0.2, 0.2]
shininess = 50

[render]
background = [[0.4, 0.5, 0.6], [0.1, 0.1, 0.1]]
shadows = false
transparent = true

[[light]]
direction = [0, -2, 0]

[[light]]
position = [1, 4, 2]
intensity = 3

[ground]
height = -1.5
"""))
    o = scene.objects[0]
    assert (o.color, o.specular, o.shininess) == ((0.5, 0.4, 0.3), (0.2, 0.2, 0.2), 50.0)
    r = scene.render
    assert (r.background, r.background_bottom) == ((0.4, 0.5, 0.6), (0.1, 0.1, 0.1))
    assert not r.shadows and r.transparent
    assert scene.lights[0].direction == (0.0, -1.0, 0.0) and scene.lights[0].position is None
    assert scene.lights[1].position == (1.0, 4.0, 2.0) and scene.lights[1].direction is None
    assert scene.ground.height == -1.5 and scene.ground.color is None


@pytest.mark.parametrize("text,key,words", [
    ('[[light]]\ndirection = [0, -1, 0]\nposition = [0, 1, 0]\n', "light[0].position", "not both"),
    ('[[light]]\nintensity = 2\n', "light[0]", "needs direction"),
    ('[render]\nbackground = [[0, 0, 0], [2, 0, 0]]\n', "render.background", "between 0 and 1"),
    ('[render]\nshadows = "yes"\n', "render.shadows", "true or false"),
    ('[ground]\nheight = "low"\n', "ground.height", "number"),
    ('[ground]\nlevel = 0\n', "ground.level", "allowed keys: height, color"),
])
def test_bad_lighting_keys(folder, text, key, words):
    path = write(folder, '[[object]]\nmesh = "tri2.obj"\n' + text)
    err = error_of(path)
    assert err.key == key and err.line is not None, str(err)
    assert words in str(err), str(err)


def test_override_colours(folder):
    scene = load_scene(write(folder, '[[object]]\nmesh = "tri2.obj"\n'))
    new = apply_overrides(scene, color="#ffffff", background="0.1,0.2,0.3 0,0,0",
                          shadows=False, transparent=True)
    assert new.objects[0].color == pytest.approx((1.0, 1.0, 1.0))
    assert new.render.background == (0.1, 0.2, 0.3)
    assert new.render.background_bottom == (0.0, 0.0, 0.0)
    assert not new.render.shadows and new.render.transparent
    # sRGB hex codes are decoded to linear
    assert apply_overrides(scene, background="#808080").render.background == pytest.approx(
        (0.2158605,) * 3)
    for option, value in (("color", "1,2,3"), ("color", "#12345"), ("background", "0.1,0.2"),
                          ("color", "0,0,0,1,1,1")):
        with pytest.raises(SceneError, match=f"^--{option}: expected a colour"):
            apply_overrides(scene, **{option: value})


def test_scene_for_meshes_lights_a_picture(folder, monkeypatch):
    """OBJ inputs get 1280x720, key and fill lights, a gradient and a ground shadow."""
    monkeypatch.chdir(folder)
    scene = scene_for_meshes(["tri2.obj"])
    assert (scene.camera.width, scene.camera.height) == (1280, 720)
    assert len(scene.lights) == 2 and scene.render.shadows
    assert scene.render.background_bottom is not None and scene.ground is not None


def test_one_set_of_picture_defaults(folder, monkeypatch):
    """A bare TOML scene, the same cage on the command line and a scene built in code get
    the same camera, render settings, lights and ground; what a scene sets it keeps:
    ``light = []`` no lights, ``ground = false`` no ground, its background and headlight
    (it rendered at 640x480 on black with a headlight alone, the command line at 1280x720
    with the gradient, key and fill lights, shadows and the ground)."""
    monkeypatch.chdir(folder)
    bare = load_scene(write(folder, '[[object]]\nmesh = "tri2.obj"\n'))
    cli = scene_for_meshes(["tri2.obj"])
    code = Scene(objects=bare.objects)
    for scene in (cli, code):
        assert (scene.camera, scene.render, scene.lights, scene.ground) == (
            bare.camera, bare.render, bare.lights, bare.ground)
    assert (bare.camera.width, bare.camera.height) == (1280, 720) and len(bare.lights) == 2
    plain = load_scene(write(folder, 'light = []\nground = false\n[render]\n'
                                     'background = [0, 0, 0]\nheadlight_intensity = 1.0\n'
                                     '[camera]\nwidth = 640\nheight = 480\n'
                                     '[[object]]\nmesh = "tri2.obj"\n', "plain.toml"))
    assert plain.lights == () and plain.ground is None
    assert plain.render.background == (0.0, 0.0, 0.0) and plain.render.background_bottom is None
    assert plain.render.headlight_intensity == 1.0
    assert (plain.camera.width, plain.camera.height) == (640, 480)
    own = load_scene(write(folder, '[[light]]\ndirection = [0, -1, 0]\n[ground]\n'
                                   'height = -2\n[[object]]\nmesh = "tri2.obj"\n', "own.toml"))
    assert own.lights == (Light(direction=(0.0, -1.0, 0.0)),)
    assert own.ground == Ground(height=-2.0)
    assert load_scene(write(folder, 'ground = true\n[[object]]\nmesh = "tri2.obj"\n',
                            "g.toml")).ground == Ground()
    with pytest.raises(SceneError, match="ground"):
        load_scene(write(folder, 'ground = 3\n[[object]]\nmesh = "tri2.obj"\n', "bad.toml"))
