"""``subtrace render --light KIND:KEY=VALUE,...`` (subtrace/lights.py parse_light_flag): each
kind's flag is the light its ``[[light]]`` table makes, the flags' lights replace the
scene's, and a bad value is one clear error line naming the flag and the key, exit 2, no
traceback and no output."""

from __future__ import annotations

import math

import numpy as np
import pytest

from subtrace.cli import main
from subtrace.errors import SceneError
from subtrace.io.exr import read_exr
from subtrace.lights import Light, parse_light_flag

CUBE = ("v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\n"
        "v -1 1 1\nf 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n")


@pytest.mark.parametrize("text, light", [
    ("sun:direction=0,-1,-1", Light(direction=(0.0, -1 / math.sqrt(2), -1 / math.sqrt(2)))),
    ("directional:direction=0,-2,0,angle=5,samples=4",
     Light(direction=(0.0, -1.0, 0.0), angle=5.0, samples=4)),
    ("point:position=1,2,3,intensity=2", Light(position=(1.0, 2.0, 3.0), intensity=2.0)),
    ("sphere:position=1,2,3,radius=0.5,intensity=4",
     Light(position=(1.0, 2.0, 3.0), radius=0.5, intensity=4.0)),
    ("SPHERE: position = 1, 2, 3 , radius=0.5,color=1,0.5,0.25",
     Light(position=(1.0, 2.0, 3.0), radius=0.5, color=(1.0, 0.5, 0.25))),
    ("disk:position=0,3,0,normal=0,-2,0,radius=0.5,samples=16",
     Light(kind_key="disk", position=(0.0, 3.0, 0.0), normal=(0.0, -1.0, 0.0), radius=0.5,
           samples=16)),
    ("quad:position=0,3,0,u=1,0,0,v=0,0,1",
     Light(kind_key="quad", position=(0.0, 3.0, 0.0), u=(1.0, 0.0, 0.0), v=(0.0, 0.0, 1.0))),
])
def test_a_flag_is_the_light_of_its_table(text, light):
    got = parse_light_flag(text)
    assert got.kind == light.kind
    for field in ("direction", "position", "radius", "angle", "samples", "color",
                  "intensity", "kind_key", "u", "v", "normal"):
        a, b = getattr(got, field), getattr(light, field)
        if isinstance(a, tuple):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-15)
        else:
            assert a == b, field


BAD = [
    ("direction=0,-1,0", "KIND one of"),
    ("lamp:position=0,1,0", "KIND one of"),
    ("sun:", "expected KEY=VALUE"),
    ("sun:0,-1,0", "expected KEY=VALUE"),
    ("sun:direction=0,-1", "direction: expected 3 numbers"),
    ("sun:direction=0,0,0", "direction: the direction is zero"),
    ("sun:direction=0,-1,x", "direction: expected a number, got 'x'"),
    ("sun:direction=0,-1,0,angle=120", "angle: a sun's angle"),
    ("sun:position=0,1,0", "missing key direction"),
    ("sun:direction=0,-1,0,direction=0,-1,0", "given twice"),
    ("sun:direction=0,-1,0,colour=1,1,1", "'colour' is not a key"),
    ("point:direction=0,-1,0", "missing key position"),
    ("point:position=0,1,0,radius=1", "a point light has no radius"),
    ("sphere:position=0,1,0", "missing key radius"),
    ("sphere:position=0,1,0,radius=-1", "radius: a sphere light's radius must be 0 or more"),
    ("sphere:position=0,1,0,radius=1,samples=2.5", "samples: expected a whole number"),
    ("sphere:position=0,1,0,radius=1,intensity=nan", "intensity: expected a finite number"),
    ("sphere:position=0,1,0,radius=1,color=2,0,0", "color: color components"),
    ("disk:position=0,3,0,normal=0,-1,0", "missing key radius"),
    ("quad:position=0,3,0,u=1,0,0,v=2,0,0", "not parallel"),
    ("quad:position=0,3,0,u=1,0,0,v=0,0,1,kind=disk", "'kind' is not a key"),
]


@pytest.mark.parametrize("text, words", BAD)
def test_a_bad_flag_is_one_clear_error(text, words):
    with pytest.raises(SceneError) as err:
        parse_light_flag(text)
    message = str(err.value)
    assert message.startswith("--light: ") and words in message, message
    assert "\n" not in message


@pytest.mark.parametrize("text, words", [BAD[0], BAD[6], BAD[14], BAD[19]])
def test_a_bad_flag_on_the_command_line_exits_2_with_one_line(tmp_path, capsys, text,
                                                              words):
    (tmp_path / "cube.obj").write_text(CUBE)
    out = tmp_path / "out.exr"
    code = main(["render", str(tmp_path / "cube.obj"), "-o", str(out), "--width", "16",
                 "--height", "12", "--quiet", "--light", "sun:direction=0,-1,0",
                 "--light", text])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("subtrace: error: --light: "), err
    assert words in lines[0], err
    assert not out.exists()


def test_the_flags_lights_replace_the_scenes(tmp_path, capsys):
    """A cage seen from above, no headlight, its scene's light a sun of 0.3 straight down:
    a flag's sun of 1 the same way lights the top alone (1 / 0.3 of the scene's light,
    about its colour 0.5), a second flag adds its own (0.5 more)."""
    (tmp_path / "cube.obj").write_text(CUBE)
    (tmp_path / "scene.toml").write_text(
        '[[object]]\nmesh = "cube.obj"\ncolor = [0.5, 0.5, 0.5]\n\n[camera]\n'
        'eye = [0.0, 10.0, 0.01]\ntarget = [0.0, 0.0, 0.0]\nwidth = 32\nheight = 32\n\n'
        '[render]\nheadlight = false\nsamples = 1\n\n[[light]]\ndirection = [0, -1, 0]\n'
        'intensity = 0.3\n')
    out = tmp_path / "out.exr"

    def centre(*flags):
        code = main(["render", str(tmp_path / "scene.toml"), "-o", str(out), "--quiet",
                     *flags])
        assert code == 0, capsys.readouterr().err
        channels = read_exr(out)[0]
        return float(channels["R"][16, 16])

    scene_light = centre()
    one = centre("--light", "sun:direction=0,-1,0")
    two = centre("--light", "sun:direction=0,-1,0", "--light", "sun:direction=0,-1,0,"
                 "intensity=0.5")
    # (the same point under lights of one direction: their intensities' ratios, to the
    # EXR's half floats; the point's normal within a few degrees of straight up)
    assert abs(one / scene_light * 0.3 - 1.0) < 2e-3, (one, scene_light)
    assert abs(two / one - 1.5) < 2e-3, (two, one)
    assert abs(one - 0.5) < 0.01, one
