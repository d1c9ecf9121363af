"""Tests of the command line (``subtrace.cli.main`` in-process, and the ``cli.py`` launcher).

Expected counts come from sources independent of subtrace's topology code: the models'
README (Spot: 180 faces = 160 quads + 16 pentagons + 4 triangles, closed, genus 0, max
valence 6), the ``v`` lines of the file, and OpenSubdiv's own tables in the oracle ``.npz``
files (edges, sharpness after tag processing, holes, refined levels).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from shared_data import ORACLE

from subtrace.cli import main
from subtrace.data import sample_cage_path

REPO = Path(__file__).resolve().parents[1]


def run_info(capsys, *args):
    """main(['info', *args]) -> (exit code, {key: value}, stdout, stderr)."""
    code = main(["info", *map(str, args)])
    out, err = capsys.readouterr()
    rows = {}
    for line in out.splitlines():
        m = re.match(r"^([^:]+):\s+(.*)$", line)
        assert m, f"unexpected output line {line!r}"
        rows[m.group(1)] = m.group(2)
    return code, rows, out, err


def first_int(text: str) -> int:
    return int(re.match(r"-?\d+", text).group(0))


def assert_one_line_error(err: str, *words: str):
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("subtrace: error: "), err
    assert "Traceback" not in err
    for word in words:
        assert word in lines[0], err


# --------------------------------------------------------------------------------------
# the built-in sample cage
# --------------------------------------------------------------------------------------


def test_sample_cage_ships_with_the_package():
    path = sample_cage_path()
    assert path.is_file()
    text = path.read_text()
    assert sum(1 for line in text.splitlines() if line.startswith("f ")) == 180


def test_info_on_builtin_cage(capsys):
    code, rows, _, err = run_info(capsys)
    assert code == 0, err
    lines = sample_cage_path().read_text().splitlines()
    n_verts = sum(1 for line in lines if line.startswith("v "))
    assert "spot_control_mesh.obj" in rows["file"]
    assert rows["scheme"].startswith("catmark")
    assert "boundary edge-only" in rows["options"]
    assert "crease method uniform" in rows["options"]
    assert first_int(rows["vertices"]) == n_verts
    assert first_int(rows["faces"]) == 180
    # each edge of a closed manifold cage is shared by two faces
    assert first_int(rows["edges"]) == (4 * 160 + 5 * 16 + 3 * 4) // 2
    assert rows["face sizes"] == "triangles 4, quads 160, pentagons 16"
    assert first_int(rows["boundary edges"]) == 0
    assert rows["non-manifold"] == "0 edges, 0 vertices"
    assert first_int(rows["crease edges"]) == 0
    assert first_int(rows["hole faces"]) == 0
    assert rows["valence"].endswith("..6")
    assert first_int(rows["Euler characteristic"]) == 2  # genus 0
    lo, hi = _bounds(rows["cage bounds"])
    pts = np.array(
        [line.split()[1:4] for line in sample_cage_path().read_text().splitlines()
         if line.startswith("v ")],
        dtype=float,
    )
    np.testing.assert_allclose(lo, pts.min(axis=0), rtol=1e-5)
    np.testing.assert_allclose(hi, pts.max(axis=0), rtol=1e-5)
    if "n/a" not in rows["limit bounds"]:
        llo, lhi = _bounds(rows["limit bounds"])
        # limit points lie strictly inside the cage's hull for this smooth closed cage
        assert np.all(llo > lo) and np.all(lhi < hi)


def _bounds(text):
    m = re.match(r"min \(([^)]*)\) max \(([^)]*)\)", text)
    assert m, text
    return (np.array(m.group(1).split(","), dtype=float),
            np.array(m.group(2).split(","), dtype=float))


def test_info_level_counts_on_builtin_cage(capsys):
    code, rows, _, err = run_info(capsys, "--level", "2")
    assert code == 0, err
    # Catmull-Clark: level 1 has V+E+F vertices and sum(face sizes) quads, then each quad
    # splits in four; Keenan Crane's refined Spot (two steps) has 2928 quads
    assert rows["level 2"].startswith("2930 vertices, 2928 faces, 5856 edges")
    assert rows["level 2"].endswith("Euler characteristic 2")


# --------------------------------------------------------------------------------------
# OpenSubdiv oracle shapes
# --------------------------------------------------------------------------------------


def _oracle_counts(name):
    z = np.load(ORACLE / f"{name}.npz")
    sizes, verts = z["face_sizes"], z["face_verts"]
    uses = Counter()
    start = 0
    for n in sizes:
        f = verts[start : start + n]
        for a, b in zip(f, np.roll(f, -1)):
            uses[(min(a, b), max(a, b))] += 1
        start += n
    edges = z["edges"]
    n_use = np.array([uses[(min(a, b), max(a, b))] for a, b in edges])
    interior = (n_use == 2) & (edges[:, 0] != edges[:, 1])
    s = z["edge_sharpness"]
    vs = z["vertex_sharpness"]
    # a vertex pair can only be mapped to its uses when no pair is an edge twice (faces
    # using an edge twice) and no edge is degenerate (faces repeating a vertex)
    pairs = {(min(a, b), max(a, b)) for a, b in edges}
    simple = len(pairs) == len(edges) and not np.any(edges[:, 0] == edges[:, 1])
    return dict(
        V=len(z["control_points"]),
        F=len(sizes),
        E=len(edges),
        boundary=int(np.count_nonzero(n_use == 1)) if simple else None,
        semi=int(np.count_nonzero(interior & (s > 0) & (s < 10))) if simple else None,
        inf=int(np.count_nonzero(interior & (s >= 10))) if simple else None,
        sharp_v=int(np.count_nonzero(vs > 0)),
        holes=int(z["face_is_hole"].sum()),
        V2=len(z["refined2_points"]),
        F2=len(z["refined2_face_sizes"]),
        E2=len(z["refined2_edges"]),
    )


@pytest.mark.parametrize(
    "name",
    [
        "catmark_edgeonly",  # boundaries, corner tags
        "catmark_hole_test2",  # semi-sharp crease, hole tags, edge-and-corner
        "catmark_cubes_semisharp",  # many semi-sharp creases
        "loop_triangle_edgenone",  # Loop, automatic holes of boundary mode "none"
        "catmark_nonman_edges",  # non-manifold edges
    ],
)
def test_info_on_oracle_shape(capsys, name):
    want = _oracle_counts(name)
    path = ORACLE / "shapes" / f"{name}.obj"
    code, rows, _, err = run_info(capsys, path, "--level", "2")
    assert code == 0, err
    assert "Traceback" not in err
    assert rows["scheme"].startswith(name.split("_")[0])
    assert first_int(rows["vertices"]) == want["V"]
    assert first_int(rows["faces"]) == want["F"]
    assert first_int(rows["edges"]) == want["E"]
    if want["boundary"] is not None:
        assert first_int(rows["boundary edges"]) == want["boundary"]
        assert rows["crease edges"].startswith(
            f"{want['semi'] + want['inf']} ({want['semi']} semi-sharp, {want['inf']} infinitely"
        )
    assert first_int(rows["sharp vertices"]) == want["sharp_v"]
    assert first_int(rows["hole faces"]) == want["holes"]
    chi = want["V"] - want["E"] + want["F"]
    assert first_int(rows["Euler characteristic"]) == chi
    assert rows["level 2"] == (
        f"{want['V2']} vertices, {want['F2']} faces, {want['E2']} edges, "
        f"Euler characteristic {want['V2'] - want['E2'] + want['F2']}"
    )


def test_info_scheme_option(capsys):
    # a Catmark reading of an all-triangle Loop shape: the level-1 faces are quads
    path = ORACLE / "shapes" / "loop_tetrahedron.obj"
    code, rows, _, err = run_info(capsys, path, "--scheme", "catmark", "--level", "1")
    assert code == 0, err
    assert rows["scheme"].startswith("catmark")
    # V + E + F vertices, 3 quads per triangle
    assert rows["level 1"].startswith(f"{4 + 6 + 4} vertices, 12 faces")


# --------------------------------------------------------------------------------------
# errors: one line on stderr, exit code 2, no traceback
# --------------------------------------------------------------------------------------


BAD_OBJ = "# a broken cage\nv 0 0 0\nv 1 0 0\nv 0 1 zero\nv 1 1 0\nf 1 2 4 3\n"


def test_malformed_obj_is_one_line_error(capsys, tmp_path):
    path = tmp_path / "broken.obj"
    path.write_text(BAD_OBJ)
    code = main(["info", str(path)])
    out, err = capsys.readouterr()
    assert code == 2
    assert out == ""
    assert_one_line_error(err, "broken.obj:4")


def test_missing_file_is_one_line_error(capsys, tmp_path):
    path = tmp_path / "nothere.obj"
    code = main(["info", str(path)])
    out, err = capsys.readouterr()
    assert code == 2
    assert out == ""
    assert_one_line_error(err, "nothere.obj")


def test_bad_scheme_is_one_line_error(capsys):
    # Spot has quads and pentagons: Loop cannot subdivide it
    code = main(["info", "--scheme", "loop"])
    _, err = capsys.readouterr()
    assert code == 2
    assert_one_line_error(err, "Loop")
    code = main(["info", "--scheme", "butterfly"])
    _, err = capsys.readouterr()
    assert code == 2
    assert_one_line_error(err, "butterfly")


@pytest.mark.parametrize(
    "argv",
    [[], ["info", "--level", "-1"], ["info", "--level", "two"], ["frobnicate"],
     ["info", "a.obj", "b.obj"]],
)
def test_usage_errors_exit_2(capsys, argv):
    # one line naming the problem and where the help is, no usage text (issue 8)
    assert main(argv) == 2
    _, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("subtrace: error: "), err
    assert lines[0].endswith(" --help)")
    assert "usage:" not in err
    assert "Traceback" not in err


def test_help_exits_0(capsys):
    assert main(["--help"]) == 0
    assert "info" in capsys.readouterr().out
    assert main(["info", "--help"]) == 0
    assert "--level" in capsys.readouterr().out


# --------------------------------------------------------------------------------------
# the launcher, as a subprocess from the repository root
# --------------------------------------------------------------------------------------


def _launcher(*args):
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)  # cli.py must find src/ by itself when not installed
    return subprocess.run(
        [sys.executable, "cli.py", *map(str, args)],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_launcher_subprocess_error(tmp_path):
    path = tmp_path / "broken.obj"
    path.write_text(BAD_OBJ)
    proc = _launcher("info", path)
    assert proc.returncode == 2, proc.stderr
    assert proc.stdout == ""
    assert_one_line_error(proc.stderr, "broken.obj:4")


def test_launcher_subprocess_info():
    proc = _launcher("info")
    assert proc.returncode == 0, proc.stderr
    assert re.search(r"^faces:\s+180$", proc.stdout, re.M), proc.stdout
    assert "Traceback" not in proc.stderr


def test_launcher_subprocess_render(tmp_path):
    # the launcher ends the process itself (cli.run): the EXR must be complete, the exit
    # code and the report on stdout (a pipe, so block-buffered) must arrive
    out = tmp_path / "tiny.exr"
    proc = _launcher("render", sample_cage_path(), "-o", out,
                     "--width", "16", "--height", "8")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith(f"{out}: 16x8"), proc.stdout
    from subtrace.io.exr import read_exr

    channels, _ = read_exr(out)
    assert channels["R"].shape == (8, 16)


def test_every_commands_help_reads_as_written():
    """Every command's --help prints its text as written: no '%%' left over from argparse's
    %-formatting of help strings (descriptions are not formatted), no '%(' placeholders."""
    import subprocess
    import sys

    for command in ("render", "info", "compare", "sweep", "intersect", "warmup"):
        out = subprocess.run([sys.executable, "-m", "subtrace.cli", command, "--help"],
                             capture_output=True, text=True, check=True).stdout
        assert "%%" not in out and "%(" not in out, command


def test_render_help_says_what_a_render_does(capsys, tmp_path):
    """``render --help`` names every channel a render writes (read from a real render's
    EXR, not from the code's list) and the anti-aliasing default (the scene reader's
    DEFAULT_SAMPLES), and no longer says "one ray per pixel"."""
    from subtrace.io.exr import read_exr
    from subtrace.io.scene import DEFAULT_SAMPLES

    assert main(["render", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    out = tmp_path / "c.exr"
    assert main(["render", str(sample_cage_path()), "-o", str(out), "--width", "16",
                 "--height", "8", "--quiet"]) == 0
    channels, _ = read_exr(out)
    description = text[:text.index("positional arguments")]
    for name in channels:
        assert re.search(rf"(?<![\w.]){re.escape(name)}(?![\w])", description) or (
            name[:2] in ("N.", "P.") and f"{name[:2]}X/{name[:2]}Y/{name[:2]}Z"
            in description), name
    assert "one ray per pixel" not in text
    assert f"up to --samples rays, {DEFAULT_SAMPLES} by default" in text
