"""Bad input of ``compare``, ``sweep`` and ``intersect`` (issue 8): one line naming the file,
line, option and problem, no traceback, and no output left behind. ``render`` and ``info``
are covered by tests/test_bad_inputs.py.

Exit codes: 2 for bad input or options; ``compare`` keeps idiff's convention for images
(3: sizes or channels differ, 4: an image that cannot be read; see its --help).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from subtrace.cli import main

CORPUS = Path(__file__).resolve().parent / "bad_inputs"
CUBE = CORPUS / "cube.obj"


def run(capsys, argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def one_line(err: str, *words: str) -> str:
    assert "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("subtrace: error: "), err
    for w in words:
        assert w in lines[0], err
    return lines[0]


# --------------------------------------------------------------------------------------
# compare
# --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def images(tmp_path_factory):
    d = tmp_path_factory.mktemp("images")
    for name, w, h in (("a.exr", 16, 12), ("b.exr", 16, 12), ("small.exr", 8, 6)):
        assert main(["render", str(CUBE), "-o", str(d / name), "--width", str(w),
                     "--height", str(h), "--quiet"]) == 0
    (d / "text.exr").write_text("not an image\n")
    (d / "empty.exr").write_bytes(b"")
    (d / "folder.exr").mkdir()
    return d


@pytest.mark.parametrize("b, code, words", [
    ("missing.exr", 4, "missing.exr"),
    ("text.exr", 4, "text.exr"),
    ("empty.exr", 4, "empty.exr"),
    ("folder.exr", 4, "folder.exr"),
    ("small.exr", 3, "small.exr"),
])
def test_compare_bad_images(capsys, tmp_path, images, b, code, words):
    diff = tmp_path / "d.exr"
    got, out, err = run(capsys, ["compare", images / "a.exr", images / b, "--diff", diff,
                                 "--html", tmp_path / "r.html"])
    assert got == code, err
    one_line(err, words)
    assert list(tmp_path.iterdir()) == []  # no difference image, no page


@pytest.mark.parametrize("flags, words", [
    (["--fail", "colour=abc"], "--fail colour=abc: expected a number >= 0"),
    (["--fail", "-1"], "--fail -1: expected a number >= 0"),
    (["--warn", "nan"], "--warn nan: expected a number >= 0"),
    (["--failpercent", "hue=3"], "unknown channel group 'hue'"),
    (["--hardfail", "="], "--hardfail =: expected a number >= 0"),
    (["--png"], "--png writes the heat map of --diff"),
    (["--diff", "nowhere/d.exr"], "nowhere"),
    (["--html", "nowhere/r.html"], "nowhere/r.html: cannot write the file"),
])
def test_compare_bad_options(capsys, tmp_path, images, flags, words, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, out, err = run(capsys, ["compare", images / "a.exr", images / "b.exr", *flags])
    assert code == 2, err
    one_line(err, words)
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------------------
# sweep
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("flags, words", [
    (["--tolerances", "abc"], "--tolerances"),
    (["--tolerances", "0"], "--tolerances"),
    (["--tolerances", "4", "-1"], "--tolerances"),
    (["--tolerances", "nan"], "--tolerances"),
    (["--tolerances", "inf"], "--tolerances"),
    (["--tolerances", "2", "--reference-tolerance", "4"], "--reference-tolerance"),
    (["--tolerances", "2", "--reference-tolerance", "x"], "--reference-tolerance"),
    (["--tolerances", "2", "--repeat", "0"], "--repeat"),
    (["--tolerances", "2", "--repeat", "two"], "--repeat"),
    (["--tolerances", "2", "--width", "0"], "--width"),
    (["--tolerances", "2", "--max-memory", "0"], "--max-memory"),
    (["--tolerances", "2", "--threads", "0"], "--threads"),
])
def test_sweep_bad_options(capsys, tmp_path, flags, words):
    out = tmp_path / "sw"
    code, _, err = run(capsys, ["sweep", CUBE, "-o", out, "--width", "16", "--height", "12",
                                *flags])
    assert code == 2, err
    one_line(err, words)
    assert not out.exists() or list(out.iterdir()) == []


def test_sweep_html_in_a_missing_folder_is_one_line_before_rendering(capsys, tmp_path):
    out = tmp_path / "sw"
    page = tmp_path / "nowhere" / "r.html"
    code, _, err = run(capsys, ["sweep", CUBE, "-o", out, "--tolerances", "2", "--html", page])
    assert code == 2, err
    one_line(err, str(page), "does not exist")
    assert not out.exists()


@pytest.mark.parametrize("name, words", [
    ("face_index_zero.obj", "face_index_zero.obj:"), ("empty.obj", "empty.obj"),
    ("scene_fov_zero.toml", "camera.fov"), ("missing.obj", "missing.obj"),
])
def test_sweep_bad_inputs(capsys, tmp_path, name, words):
    out = tmp_path / "sw"
    code, _, err = run(capsys, ["sweep", CORPUS / name, "-o", out, "--tolerances", "2",
                                "--width", "16", "--height", "12"])
    assert code == 2, err
    one_line(err, words)
    assert not out.exists() or list(out.iterdir()) == []


def test_sweep_output_is_a_file(capsys, tmp_path):
    (tmp_path / "f").write_text("")
    code, _, err = run(capsys, ["sweep", CUBE, "-o", tmp_path / "f", "--tolerances", "2"])
    assert code == 2
    one_line(err, "is a file")


# --------------------------------------------------------------------------------------
# intersect
# --------------------------------------------------------------------------------------

HEADER = "ox,oy,oz,dx,dy,dz\n"
GOOD = "0,0,5,0,0,-1\n"


@pytest.mark.parametrize("text, words", [
    ("", "lines.csv: empty file"),
    ("a,b,c\n1,2,3\n", "lines.csv:1: missing column(s) ox, oy, oz, dx, dy, dz"),
    (HEADER + GOOD + "0,0,5,0,0\n", "lines.csv:3: expected 6 values (ox,oy,oz,dx,dy,dz), got 5"),
    (HEADER + "0,0,5,0,0,-1,7\n", "lines.csv:2: expected 6 values (ox,oy,oz,dx,dy,dz), got 7"),
    (HEADER + "0,0,five,0,0,-1\n", "lines.csv:2: oz: 'five' is not a number"),
    (HEADER + "0,0,nan,0,0,-1\n", "lines.csv:2: oz: 'nan' is not a finite number"),
    (HEADER + "0,0,5,0,inf,-1\n", "lines.csv:2: dy: 'inf' is not a finite number"),
    (HEADER + GOOD + "0,0,5,0,0,0\n", "lines.csv:3: the direction (0, 0, 0) is zero"),
    (b"ox,oy,oz,dx,dy,dz\n\xff\xfe\x00junk", "lines.csv:2: byte 0xff"),
])
def test_intersect_bad_lines(capsys, tmp_path, text, words):
    lines = tmp_path / "lines.csv"
    (lines.write_bytes if isinstance(text, bytes) else lines.write_text)(text)
    out = tmp_path / "out" / "hits.csv"
    out.parent.mkdir()
    code, stdout, err = run(capsys, ["intersect", CUBE, "--lines", lines, "--precision", "0.01",
                                     "-o", out])
    assert code == 2, err
    one_line(err, words)
    assert list(out.parent.iterdir()) == []


@pytest.mark.parametrize("flags, words", [
    (["--precision", "0"], "--precision 0: expected a finite number > 0"),
    (["--precision", "-1"], "--precision -1: expected a finite number > 0"),
    (["--precision", "abc"], "--precision abc: expected a number"),
    (["--precision", "nan"], "--precision nan: expected a finite number > 0"),
    (["--precision", "inf"], "--precision inf: expected a finite number > 0"),
    (["--precision", "0.01", "--t-min", "x"], "--t-min x: expected a number"),
    (["--precision", "0.01", "--t-min", "2", "--t-max", "1"], "--t-max 1: expected a number "
     "above --t-min 2"),
    (["--precision", "0.01", "--t-min", "nan"], "--t-min nan: expected a number"),
])
def test_intersect_bad_options(capsys, tmp_path, flags, words):
    lines = tmp_path / "lines.csv"
    lines.write_text(HEADER + GOOD)
    code, stdout, err = run(capsys, ["intersect", CUBE, "--lines", lines, *flags])
    assert code == 2, err
    one_line(err, words)
    assert stdout == ""


@pytest.mark.parametrize("cage, words", [
    ("missing.obj", "missing.obj: no such file"),
    ("face_index_zero.obj", "face_index_zero.obj:"),
    ("coord_huge.obj", "coord_huge.obj:7: vertex 6 has a coordinate"),
])
def test_intersect_bad_cage(capsys, tmp_path, cage, words):
    lines = tmp_path / "lines.csv"
    lines.write_text(HEADER + GOOD)
    code, stdout, err = run(capsys, ["intersect", CORPUS / cage, "--lines", lines,
                                     "--precision", "0.01"])
    assert code == 2, err
    one_line(err, words)
    assert stdout == ""


def test_intersect_missing_lines_file_and_output_folder(capsys, tmp_path):
    code, _, err = run(capsys, ["intersect", CUBE, "--lines", tmp_path / "none.csv",
                                "--precision", "0.01"])
    assert code == 2
    one_line(err, "none.csv")
    lines = tmp_path / "lines.csv"
    lines.write_text(HEADER + GOOD)
    code, _, err = run(capsys, ["intersect", CUBE, "--lines", lines, "--precision", "0.01",
                                "-o", tmp_path / "missing" / "hits.csv"])
    assert code == 2
    one_line(err, "missing")


def test_intersect_header_only_is_no_lines(capsys, tmp_path):
    lines = tmp_path / "lines.csv"
    lines.write_text(HEADER)
    code, stdout, err = run(capsys, ["intersect", CUBE, "--lines", lines, "--precision", "0.01"])
    assert code == 0, err
    assert stdout == "line,t,x,y,z,ptex,u,v,nx,ny,nz,tangent\n"
