"""The HTML reports (subtrace.htmlreport) opened in headless Chromium (tests/browser.py):
``subtrace compare --html`` shows the verdicts the command line prints, every image loads
from the page itself, the heat maps carry their colour keys; two renders that differ only
in their ids give an empty heat map and an ids map of exactly the changed pixels; the golden
plugin's session page shows each test's verdict."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from browser import assert_offline, read_page

from subtrace.cli import main
from subtrace.htmlreport import png_bytes
from subtrace.io.exr import read_exr, srgb8, write_exr

ROOT = Path(__file__).resolve().parents[1]
GOLDEN = ROOT / "golden_images" / "creases.exr"
PROJECT = Path(__file__).resolve().parent / "golden_project"


def perturbed(tmp_path, name, **changes) -> Path:
    """The creases golden with some channels changed (name -> function of the channels)."""
    channels, _ = read_exr(GOLDEN)
    for channel, change in changes.items():
        channels[channel] = change(channels).astype(np.float32)
    path = tmp_path / f"{name}.exr"
    write_exr(path, channels)
    return path


def covered(channels) -> np.ndarray:
    return np.isfinite(channels["Z"])


def test_png_bytes_round_trip(tmp_path):
    """The page's own PNG encoder gives the codes write_png's sRGB conversion gives."""
    rgb = np.random.default_rng(3).random((7, 5, 3))
    path = tmp_path / "x.png"
    path.write_bytes(png_bytes(rgb))
    back, _ = read_exr(path)  # OpenImageIO reads it; values as 8-bit codes / 255
    codes = np.rint(np.stack([back[c] for c in "RGB"], axis=-1) * 255).astype(np.uint8)
    np.testing.assert_array_equal(codes, srgb8(rgb))


def test_compare_page_shows_the_command_lines_verdicts(tmp_path, capsys):
    """Depth 0.2 % off and a block of patch ids changed: the page's verdicts are the JSON's,
    all images load from data: URIs, each heat map has its key with units."""
    new = perturbed(tmp_path, "new", Z=lambda c: c["Z"] * np.float32(1.002),
                    patch_id=lambda c: c["patch_id"] + (np.arange(160)[None, :] > 120))
    page = tmp_path / "report.html"
    code = main(["compare", str(new), str(GOLDEN), "--html", str(page), "--json"])
    report = json.loads(capsys.readouterr().out)
    assert code == 2 and report["html"] == str(page)
    assert_offline(page)
    seen = read_page(page, tmp_path)
    [section] = seen["sections"]
    assert section["verdict"] == report["verdict"] == "fail"
    assert section["groups"] == {g: v["verdict"] for g, v in report["groups"].items()}
    assert section["groups"]["depth"] == "fail" and section["groups"]["ids"] == "fail"
    assert seen["images"] and all(i["loaded"] and i["inline"] for i in seen["images"])
    assert all((i["width"], i["height"]) == (160, 120) for i in seen["images"])
    heat = [f for f in seen["figures"] if "heat map" in f["alts"]]
    assert len(heat) == 1 and "heat-key" in heat[0]["key"]
    assert "fail" in heat[0]["key_text"] and "error / the group's fail threshold" in \
        heat[0]["key_text"]
    [depth] = [f for f in seen["figures"] if "depth heat map" in f["alts"]]
    assert "|ΔZ| / Z (relative)" in depth["key_text"] and "0.001 fail" in depth["key_text"]
    [ids] = [f for f in seen["figures"] if "ids map" in f["alts"]]
    count = report["groups"]["ids"]["count"]
    assert f"changed ({count} px)" in ids["key_text"]
    # the slider's pair: the new render and the reference
    assert any(f["alts"] == ["reference", "new"] for f in seen["figures"])


def test_renders_differing_only_in_ids(tmp_path, capsys):
    """Only patch ids changed (tests/test_compare.py checks the maps' pixels): the page
    shows the ids map with its count and no group heat map, every image loaded."""
    channels, _ = read_exr(GOLDEN)
    changed = covered(channels) & (np.arange(160)[None, :] >= 80)
    new = perturbed(tmp_path, "ids", patch_id=lambda c: c["patch_id"] + 7 * changed)
    page = tmp_path / "ids.html"
    assert main(["compare", str(new), str(GOLDEN), "--html", str(page)]) == 2
    capsys.readouterr()
    seen = read_page(page, tmp_path)
    assert seen["sections"][0]["groups"] == {"colour": "pass", "coverage": "pass",
                                             "depth": "pass", "normals": "pass", "ids": "fail"}
    [ids] = [f for f in seen["figures"] if "ids map" in f["alts"]]
    assert f"changed ({changed.sum()} px)" in ids["key_text"]
    assert not any(a.endswith(" heat map") for f in seen["figures"] for a in f["alts"])
    assert all(i["loaded"] for i in seen["images"])


def test_the_plugins_session_page(pytester, tmp_path):
    """The sample project's run writes test_output/golden/report.html: one section per
    golden with the test's verdict, every image loaded."""
    shutil.copytree(PROJECT, pytester.path, dirs_exist_ok=True)
    result = pytester.runpytest()
    result.assert_outcomes(passed=1, failed=1)
    page = pytester.path / "test_output" / "golden" / "report.html"
    assert "report: test_output/golden/report.html" in result.stdout.str()
    assert_offline(page)
    seen = read_page(page, tmp_path)
    assert {s["name"]: s["verdict"] for s in seen["sections"]} == {"sphere": "pass",
                                                                   "sphere_lit": "fail"}
    lit = next(s for s in seen["sections"] if s["name"] == "sphere_lit")
    assert lit["groups"]["colour"] == "fail" and lit["groups"]["depth"] == "pass"
    assert all(i["loaded"] and (i["width"], i["height"]) == (40, 30) for i in seen["images"])
    assert any("heat-key" in (f["key"] or "") for f in seen["figures"])


@pytest.mark.parametrize("option", ["--html", "--diff"])
def test_unwritable_report_is_one_error_line(tmp_path, capsys, option):
    code = main(["compare", str(GOLDEN), str(GOLDEN), option, str(tmp_path / "no" / "r.x")])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "does not exist" in err
