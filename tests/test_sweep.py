"""Tests of angular-tolerance sweeps (``subtrace.sweep`` and ``subtrace sweep``).

One small CLI sweep of Spot (64x48, tolerances 4, 1, 0.25 px, reference 0.0625 px) is shared
by the tests of its records and files; a Loop octahedron built here checks the growth of the
micro-triangle count. Expected values come from geometry (errors of a finer tolerance are
smaller; a Loop grid of depth d has 4^d cells) and from the documented columns.
"""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import numpy as np
import pytest

import subtrace
from subtrace.cli import main

REPO = Path(__file__).resolve().parents[1]
SPOT = REPO / "scenes" / "spot.toml"

# The documented columns of sweep.csv and of every record of sweep.json (README), in order.
DOCUMENTED_COLUMNS = (
    "scene", "tolerance_px", "tolerance_deg", "width", "height", "repeats",
    "time_total_s", "time_refine_s", "time_trace_s", "peak_memory_mb",
    "patches", "patches_refined", "micro_triangles", "max_depth", "pixels_covered",
    "depth_err_mean", "depth_err_max", "depth_err_px_mean", "depth_err_px_max",
    "normal_err_mean_deg", "normal_err_max_deg", "coverage_mismatches",
    "colour_rmse", "flip_mean", "reference_tolerance_px", "exr", "levels_png",
)
PLOT_FILES = ("time_vs_tolerance.png", "micro_triangles_vs_tolerance.png",
              "error_vs_tolerance.png")
SPOT_TOLS = (4.0, 1.0, 0.25)

OCTAHEDRON = """\
v 1 0 0
v -1 0 0
v 0 1 0
v 0 -1 0
v 0 0 1
v 0 0 -1
f 1 3 5
f 3 2 5
f 2 4 5
f 4 1 5
f 3 1 6
f 2 3 6
f 4 2 6
f 1 4 6
"""


@pytest.fixture(scope="module")
def spot_sweep(tmp_path_factory):
    """(output folder, stdout, records of sweep.json) of one CLI sweep of Spot, its HTML
    page in the output folder (report.html)."""
    out = tmp_path_factory.mktemp("sweep") / "out"
    import contextlib
    import io

    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        code = main(["sweep", str(SPOT), "--width", "64", "--height", "48", "--tolerances",
                     *map(str, SPOT_TOLS), "--reference-tolerance", "0.0625", "-o", str(out),
                     "--html", str(out / "report.html")])
    assert code == 0
    records = json.loads((out / "sweep.json").read_text())["records"]
    return out, stdout.getvalue(), records


def test_error_falls_as_the_tolerance_tightens(spot_sweep):
    _, _, recs = spot_sweep
    assert [r["tolerance_px"] for r in recs] == list(SPOT_TOLS)
    for coarse, fine in zip(recs, recs[1:]):
        # a cell's chord error grows as its size squared, so a 4x finer tolerance should cut
        # depth and normal errors about 16x; at 64x48 the coarse step is measured ~5x (the
        # coarse depths are small whole numbers), so 3x is asked for
        assert fine["depth_err_px_mean"] * 3 < coarse["depth_err_px_mean"]
        assert fine["depth_err_mean"] * 3 < coarse["depth_err_mean"]
        assert fine["normal_err_mean_deg"] * 3 < coarse["normal_err_mean_deg"]
        assert fine["colour_rmse"] < coarse["colour_rmse"]
        assert fine["flip_mean"] < coarse["flip_mean"]
        assert fine["coverage_mismatches"] <= coarse["coverage_mismatches"]
        assert fine["max_depth"] > coarse["max_depth"]
    # world and pixel-footprint depth errors describe the same pixels: their ratio is the
    # footprint Z * pixel angle, about 3.4 units * 0.0109 rad for Spot's camera at 48 rows
    for r in recs:
        footprint = r["depth_err_mean"] / r["depth_err_px_mean"]
        assert 0.02 < footprint < 0.06
        assert r["depth_err_max"] >= r["depth_err_mean"] > 0


def test_catmark_micro_triangles_are_bounded_by_the_pixels_covered(spot_sweep):
    """Catmull-Clark patches are split per ray: the count stays a few triangles per covered
    pixel instead of growing as 1/tolerance^2 (which would be 256x from 4 to 0.25 px, and
    16x from 1 to 0.25 px, where the cells are already below a pixel)."""
    _, _, recs = spot_sweep
    for r in recs:
        # each ray builds the triangles of the cells it may hit in the blocks it enters
        # (geometry/bezier.py), plus fan triangles beside finer neighbours: measured 3.8,
        # 10.1 and 4.9 per pixel at 4, 1 and 0.25 px on this 64x48 image (its patches
        # are a pixel or two, their frames coarse; 2-3 per pixel at 1280x720)
        assert r["micro_triangles"] <= 16 * r["pixels_covered"]
    assert [r["tolerance_px"] for r in recs] == [4.0, 1.0, 0.25]
    assert recs[-1]["micro_triangles"] < 1.3 * recs[1]["micro_triangles"]
    assert recs[-1]["micro_triangles"] < 8 * recs[0]["micro_triangles"]


def test_loop_micro_triangles_stay_bounded_by_the_pixels(tmp_path):
    """Halving the tolerance adds one level to every Loop patch, and the depth error falls,
    but the micro-triangles stay a few per covered pixel: the octahedron's 8 patches (every
    corner extraordinary: all isolated, patches/isolate_loop.py) are split per ray, not
    built as whole grids of 4^depth cells (which grew 4x per halving)."""
    obj = tmp_path / "octahedron.obj"
    obj.write_text(OCTAHEDRON)
    from subtrace.io.scene import apply_overrides, scene_for_meshes

    scene = apply_overrides(scene_for_meshes([obj]), width=64, height=48)
    calls = []
    recs = subtrace.sweep([scene], [2, 8, 4, 4], reference_tolerance=1, repeat=2,
                          progress=lambda *a: calls.append(a))
    assert [r.tolerance_px for r in recs] == [8, 4, 2]  # coarse to fine, duplicates once
    assert all(r.repeats == 2 and r.exr is None for r in recs)
    for coarse, fine in zip(recs, recs[1:]):
        assert fine.max_depth == coarse.max_depth + 1
        assert fine.depth_err_px_mean < coarse.depth_err_px_mean
        # (measured: 1555 and 1551 at 4 and 2 px, 3.6 per covered pixel)
        assert fine.micro_triangles < 1.5 * coarse.micro_triangles
    for r in recs:
        assert r.micro_triangles <= 4 * r.pixels_covered
    # progress: before the first render, then after the reference and 3 x 2 renders
    assert [c[0] for c in calls] == list(range(8)) and {c[1] for c in calls} == {7}


def test_csv_json_and_plots_have_the_documented_content(spot_sweep):
    import OpenImageIO as oiio

    from subtrace.io.exr import read_exr
    from subtrace.sweep import LEVEL_COLOURS, PLOTS

    out, stdout, recs = spot_sweep
    with open(out / "sweep.csv", newline="") as f:
        rows = list(csv.reader(f))
    assert tuple(rows[0]) == DOCUMENTED_COLUMNS
    assert len(rows) == 1 + len(SPOT_TOLS)
    doc = json.loads((out / "sweep.json").read_text())
    assert tuple(doc["columns"]) == DOCUMENTED_COLUMNS
    assert all(tuple(r) == DOCUMENTED_COLUMNS for r in doc["records"])
    for row, rec in zip(rows[1:], recs):  # the CSV and the JSON hold the same values
        assert row[0] == rec["scene"] == "spot"
        assert float(row[1]) == rec["tolerance_px"]
        assert int(row[DOCUMENTED_COLUMNS.index("micro_triangles")]) == rec["micro_triangles"]
        assert rec["width"] == 64 and rec["height"] == 48 and rec["repeats"] == 1
        assert rec["reference_tolerance_px"] == 0.0625
        assert rec["peak_memory_mb"] > 0
        assert rec["time_total_s"] >= rec["time_refine_s"] + rec["time_trace_s"] > 0
    # every documented column is described in the guide's sweep section
    guide = (REPO / "docs" / "guide" / "compare-sweep-intersect.md").read_text()
    section = guide[guide.index("## Tolerance sweeps"):guide.index("## Line / surface")]
    for column in DOCUMENTED_COLUMNS:
        assert f"`{column}`" in section, column
    # plots: PNG files OpenImageIO reads, of a plausible size
    assert set(PLOTS) == set(PLOT_FILES)
    for name in PLOT_FILES:
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n"
        spec = oiio.ImageInput.open(str(out / name)).spec()
        assert spec.width >= 400 and spec.height >= 300
    # per tolerance: an EXR with its tolerance in the header, and a heat map whose colours
    # are the levels of the EXR's level channel
    srgb = np.array([[int(h[k:k + 2], 16) for k in (1, 3, 5)] for h in LEVEL_COLOURS])
    mean_levels = []  # finer tolerances refine deeper
    for rec in recs:
        channels, attrs = read_exr(out / rec["exr"])
        assert attrs["subtrace:tolerance_px"] == pytest.approx(rec["tolerance_px"])
        level = channels["level"].astype(int)
        heat = oiio.ImageInput.open(str(out / rec["levels_png"]))
        pixels = heat.read_image(format="uint8")
        heat.close()
        assert pixels.shape == (48, 64, 3)
        assert (pixels[level < 0] == 0).all()
        hit = level >= 0
        assert np.abs(pixels[hit].astype(int) - srgb[np.minimum(level[hit], 8)]).max() <= 1
        mean_levels.append(level[hit].mean())
    assert mean_levels == sorted(mean_levels) and mean_levels[0] < mean_levels[-1]
    assert (out / "spot" / "reference.exr").is_file()
    # the terminal table: a header and one row per tolerance
    lines = stdout.strip().splitlines()
    assert lines[0].split()[:2] == ["scene", "tol"]
    assert [ln.split()[1] for ln in lines[1:4]] == ["4", "1", "0.25"]


def test_html_page_in_a_browser(spot_sweep, tmp_path):
    """report.html, opened in headless Chromium (tests/browser.py): the table has a row per
    tolerance, the plots and every render and level heat map load from the page itself
    (at the sweep's size), and each tolerance's figure carries the level key."""
    from browser import assert_offline, read_page

    from subtrace.sweep import LEVEL_COLOURS, PLOTS

    out, stdout, recs = spot_sweep
    page = out / "report.html"
    assert f"report: {page}" in stdout
    assert_offline(page)
    text = page.read_text(encoding="utf-8")
    assert text.count('<tr data-scene="spot">') == len(SPOT_TOLS)
    seen = read_page(page, tmp_path)
    assert seen["images"] and all(i["loaded"] and i["inline"] for i in seen["images"])
    plots = [i for i in seen["images"] if i["alt"] in PLOTS]
    assert sorted(i["alt"] for i in plots) == sorted(PLOTS)
    levels = [i for i in seen["images"] if i["alt"].startswith("levels at ")]
    assert [i["alt"] for i in levels] == [f"levels at {t:g} px" for t in SPOT_TOLS]
    assert all((i["width"], i["height"]) == (64, 48) for i in levels)
    figures = [f for f in seen["figures"] if any(a.startswith("levels at") for a in f["alts"])]
    assert len(figures) == len(SPOT_TOLS)
    for f in figures:
        assert "swatch-key" in f["key"] and "refinement level" in f["key_text"]
        assert f"{len(LEVEL_COLOURS) - 1}+" in f["key_text"] and "no surface" in f["key_text"]


def test_peak_memory_is_the_growth_over_the_render_alone():
    """PeakMemory sees a 64 MiB array touched between start and peak, and does not see it
    again in the next measurement (the high-water mark is reset)."""
    from subtrace.sweep import PeakMemory

    probe = PeakMemory()
    probe.start()
    big = np.ones(8 * 2**20)  # 64 MiB, written so that it is resident
    del big
    peak = probe.peak()
    if peak is None:
        pytest.skip("/proc/self/clear_refs is not writable here")
    assert 60 * 2**20 <= peak <= 80 * 2**20
    probe.start()
    assert probe.peak() < 8 * 2**20


@pytest.mark.parametrize("args, needle", [
    (["nosuch.toml", "--tolerances", "1"], "nosuch.toml: no such scene file"),
    (["nosuch.obj", "--tolerances", "1"], "nosuch.obj: no such mesh file"),
    (["--tolerances", "1", "0"], "--tolerances: expected tolerances in pixels > 0, got '0'"),
    (["--tolerances", "x"], "--tolerances: expected tolerances in pixels > 0, got 'x'"),
    (["--tolerances", "1", "--reference-tolerance", "1"],
     "--reference-tolerance: 1 px is not finer than the finest swept tolerance 1 px"),
    (["--tolerances", "1", "--repeat", "0"], "--repeat: expected a whole number"),
    (["--tolerances", "1", "--width", "-3"], "--width"),
])
def test_bad_input_is_one_error_line_and_writes_nothing(tmp_path, capsys, args, needle):
    out = tmp_path / "out"
    code = main(["sweep", *[str(tmp_path / a) if a.startswith("nosuch") else a for a in args],
                 "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith("subtrace: error: ") and err.count("\n") == 1, err
    assert needle in err
    assert not out.exists()


@pytest.mark.parametrize("where", ["file", "below_file"])
def test_unwritable_output_folder_is_an_error_naming_it(tmp_path, capsys, where):
    blocker = tmp_path / "taken"
    blocker.write_text("not a folder")
    out = blocker if where == "file" else blocker / "sub"
    code = main(["sweep", str(SPOT), "--width", "8", "--height", "6", "--tolerances", "1",
                 "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert re.match(rf"subtrace: error: output folder {re.escape(str(out))}: ", err), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["taken"]
    assert blocker.read_text() == "not a folder"
