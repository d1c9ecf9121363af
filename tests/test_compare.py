"""subtrace.compare and ``subtrace compare``: metrics of constructed images with known
answers, idiff's verdict rule at its boundaries, exit codes, JSON, diff images and errors."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import subtrace
from subtrace.cli import main
from subtrace.compare import (DEFAULT_THRESHOLDS, FAIL, GROUPS, PASS, WARN, ImageMismatchError,
                              Thresholds, UnreadableImageError, compare_images)
from subtrace.io.exr import read_exr, write_exr

H, W = 12, 16


def image(covered=None, rgb=0.25, z=2.0, normal=(0.0, 0.0, 1.0), patch=3):
    """A render-like channel dict: the surface over ``covered`` (default: the left half)."""
    if covered is None:
        covered = np.zeros((H, W), dtype=bool)
        covered[:, : W // 2] = True
    on = covered.astype(np.float32)
    ch = {c: np.full((H, W), rgb, dtype=np.float32) for c in "RGB"}
    ch["A"] = on
    ch["Z"] = np.where(covered, np.float32(z), np.float32(np.inf))
    for k, c in enumerate(("N.X", "N.Y", "N.Z")):
        ch[c] = np.where(covered, np.float32(normal[k]), np.float32(0))
    ch["level"] = np.where(covered, 2.0, -1.0).astype(np.float32)
    ch["patch_id"] = np.where(covered, float(patch), -1.0).astype(np.float32)
    ch["object_id"] = np.where(covered, 0.0, -1.0).astype(np.float32)
    return ch


def run_cli(capsys, *argv):
    code = main(["compare", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


# --------------------------------------------------------------------------------------
# metrics with known values
# --------------------------------------------------------------------------------------


def test_identical_images_pass_with_zero_errors():
    a = image()
    result = compare_images(a, {k: v.copy() for k, v in a.items()})
    assert result.verdict == PASS and result.exit_code == 0
    colour = result.groups["colour"].metrics
    assert colour["rmse"] == 0 and colour["psnr"] == math.inf and colour["max_abs"] == 0
    assert colour["mean_flip"] == 0
    for name, g in result.groups.items():
        assert g.max_error == 0 and g.n_warn == 0, name


def test_rmse_psnr_max_of_a_constant_offset():
    """R off by 0.1 everywhere, G and B equal: MSE over the three channels is 0.01 / 3."""
    a, b = image(), image()
    b["R"] = a["R"] + np.float32(0.1)
    m = compare_images(a, b).groups["colour"].metrics
    mse = (np.float32(0.35) - np.float32(0.25)) ** 2 / 3  # the float32 values compared
    assert m["rmse"] == pytest.approx(math.sqrt(mse), rel=1e-6)
    assert m["psnr"] == pytest.approx(10 * math.log10(1 / mse), rel=1e-6)
    assert m["max_abs"] == pytest.approx(0.1, rel=1e-6)
    assert m["mean_flip"] > 0


def test_coverage_counts_pixels_with_the_surface_in_one_image_only():
    a = image()
    covered = a["A"] > 0
    covered[0, W // 2] = True  # gained
    covered[1:4, 0] = False  # lost
    result = compare_images(a, image(covered), {"coverage": {"failpercent": 2.5}})
    assert result.groups["coverage"].metrics["count"] == 4
    # judged over all 192 pixels: 2.5 % allows 4.8 flips (a warning), not 4.8 of the 93
    # pixels covered in both
    assert result.groups["coverage"].pixels == H * W
    assert result.groups["coverage"].verdict == WARN
    # the other groups look only at pixels covered in both
    assert result.groups["depth"].pixels == int((a["A"] > 0).sum()) - 3


def test_depth_relative_error():
    """Z 2.0 against 2.02: |dZ| / min(Z) = 0.01, at every covered pixel."""
    result = compare_images(image(z=2.0), image(z=2.02))
    g = result.groups["depth"]
    assert g.metrics["max_rel"] == pytest.approx(0.01, rel=1e-5)
    assert g.metrics["mean_rel"] == pytest.approx(0.01, rel=1e-5)
    assert g.n_fail == g.pixels  # 0.01 > the 1e-3 default


@pytest.mark.parametrize("degrees", [0.01, 1.0, 30.0, 90.0, 179.0])
def test_normal_angle_of_a_rotated_normal(degrees):
    t = math.radians(degrees)
    n = (0.0, math.sin(t), math.cos(t))
    m = compare_images(image(), image(normal=n)).groups["normals"].metrics
    assert m["max_deg"] == pytest.approx(degrees, rel=1e-4, abs=1e-5)
    assert m["mean_deg"] == pytest.approx(degrees, rel=1e-4, abs=1e-5)


def test_ids_count_pixels_that_differ_where_both_are_covered():
    a, b = image(), image()
    b["patch_id"][0, :5] = 7  # covered in both: 5 pixels
    b["level"][5, 0] = 3  # covered: 1 pixel
    b["object_id"][0, W - 3:] = 4  # background in both: not counted
    assert compare_images(a, b).groups["ids"].metrics["count"] == 6


def test_ids_are_judged_by_count_and_never_heat():
    """Ids changed over 3 covered pixels and one background pixel: the ids group counts the
    3; the heat map stays 0 there (ids are labels: no size to divide by a threshold), the
    ids map marks exactly those 3 and tells covered pixels from the background."""
    from subtrace.compare import IDS_COLOURS, ids_map

    a, b = image(), image()
    b["patch_id"][2, :3] = 9
    b["object_id"][2, W - 1] = 5  # background in both
    result = compare_images(a, b, {"ids": {"failpercent": 50.0}})
    assert result.groups["ids"].metrics["count"] == 3 and result.verdict == WARN
    assert not result.heat().any() and not result.diff_channels()["heat"].any()
    changed = result.ids_changed()
    assert changed.sum() == 3 and changed[2, :3].all()
    pixels = ids_map(changed, result.covered)
    np.testing.assert_array_equal(pixels[2, 0], IDS_COLOURS["changed"])
    np.testing.assert_array_equal(pixels[0, 0], IDS_COLOURS["same"])  # covered, same ids
    np.testing.assert_array_equal(pixels[0, W - 1], IDS_COLOURS["not judged"])
    # without the ids group: no ids map
    assert compare_images(a, b, groups=["colour", "depth"]).ids_changed() is None


def test_two_renders_differing_only_in_ids(tmp_path, capsys):
    """subtrace compare on a golden render and a copy whose patch ids changed over the right
    half of the surface: every other group passes, the heat channel and heat map PNG are
    all black, the ids map PNG is magenta at exactly the changed pixels."""
    from pathlib import Path

    from subtrace.compare import IDS_COLOURS
    from subtrace.io.exr import srgb8

    golden = Path(__file__).resolve().parents[1] / "golden_images" / "creases.exr"
    channels, _ = read_exr(golden)
    changed = np.isfinite(channels["Z"]) & (np.arange(channels["Z"].shape[1])[None, :] >= 80)
    channels["patch_id"] = channels["patch_id"] + np.float32(7) * changed
    new, diff = tmp_path / "ids.exr", tmp_path / "d.exr"
    write_exr(new, channels)
    code, out, _ = run_cli(capsys, new, golden, "--diff", diff, "--png")
    assert code == 2 and "ids map: " + str(tmp_path / "d_ids.png") in out
    result = compare_images(new, golden)
    assert {g: r.verdict for g, r in result.groups.items()} == {
        "colour": PASS, "coverage": PASS, "depth": PASS, "normals": PASS, "ids": FAIL}
    assert result.groups["ids"].metrics["count"] == changed.sum() > 1000
    d, _ = read_exr(diff)
    assert not d["heat"].any()
    np.testing.assert_array_equal(d["ids"] > 0, changed)
    rows = changed.shape[0]  # (the maps' rows; their colour keys follow)
    heat_png, _ = read_exr(tmp_path / "d.png")
    assert not any(heat_png[c][:rows].any() for c in "RGB")
    ids_png, _ = read_exr(tmp_path / "d_ids.png")
    magenta = srgb8(np.array([[IDS_COLOURS["changed"]]]))[0, 0] / 255.0
    shown = np.all([np.isclose(ids_png[c][:rows], magenta[k], atol=1e-3) for k, c in
                    enumerate("RGB")], axis=0)
    np.testing.assert_array_equal(shown, changed)


def test_the_maps_pngs_carry_their_colour_keys(tmp_path):
    """The heat and ids maps' PNGs are their image's rows and then their colour keys: the
    heat ramp's colours from black through red and yellow (at the fail threshold, half way
    along) to white, with white labels; a swatch of each of the ids map's colours."""
    from subtrace.compare import IDS_COLOURS, KEY_ROWS, heat_key, heat_map, ids_key

    a, b = image(), image()
    b["Z"] = b["Z"] + np.float32(0.5)
    b["patch_id"] = b["patch_id"] + np.float32(1)
    pngs = compare_images(a, b).write_diff(tmp_path / "d.exr", png_path=tmp_path / "d.png")
    assert len(pngs) == 2
    for path in pngs:
        png, _ = read_exr(path)
        assert png["R"].shape == (H + KEY_ROWS, W)
    width = 201  # (the ramp: columns 4 .. 196, 0 to 2 in equal steps)
    key = heat_key(width)
    assert key.shape == (KEY_ROWS, width, 3)
    for value, column in ((0.0, 4), (0.5, 52), (1.0, 100), (2.0, 196)):
        np.testing.assert_allclose(key[9, column], heat_map(np.array([[value]]))[0, 0],
                                   atol=1e-6)
    assert (key[18:] > 0.9).all(axis=-1).sum() > 20  # the labels' white
    key = ids_key(width)
    for colour in IDS_COLOURS.values():
        assert np.isclose(key[7:17], colour, atol=1e-6).all(axis=-1).sum() >= 64


def test_nan_counts_as_a_failure():
    a, b = image(), image()
    b["G"][3, 3] = np.nan
    g = compare_images(a, b, {"colour": {"failpercent": 0.0}}).groups["colour"]
    assert g.max_error == math.inf and g.verdict == FAIL
    assert g.metrics["psnr"] == -math.inf


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_metrics_are_symmetric(seed):
    """Swapping the images changes no metric other than FLIP (which has a reference)."""
    rng = np.random.default_rng(seed)
    covered = rng.random((H, W)) < 0.6
    a = image(covered, rgb=0.3)
    b = image(covered ^ (rng.random((H, W)) < 0.1), rgb=0.3)
    for c in ("R", "G", "B", "Z", "N.X", "N.Y", "N.Z"):
        b[c] = b[c] * (1 + 0.05 * rng.random((H, W))).astype(np.float32)
    ab, ba = compare_images(a, b, flip=False), compare_images(b, a, flip=False)
    assert ab.verdict == ba.verdict
    for name in ab.groups:
        assert ab.groups[name].metrics == pytest.approx(ba.groups[name].metrics), name


# --------------------------------------------------------------------------------------
# the verdict: idiff's rule per group
# --------------------------------------------------------------------------------------


def _with_bad_pixels(n: int, value: float) -> tuple[dict, dict]:
    a, b = image(), image()
    b["R"].ravel()[:n] += np.float32(value)
    return a, b


@pytest.mark.parametrize("n_bad, verdict", [(0, PASS), (1, WARN), (4, WARN), (5, FAIL)])
def test_failpercent_boundary(n_bad, verdict):
    """192 pixels, failpercent 2.5 %: up to 4.8 pixels above fail are allowed (as a warning,
    since warnpercent is 0); 5 fail. Errors of 0.25 exceed both thresholds."""
    limits = {"colour": Thresholds(warn=0.01, fail=0.1, warnpercent=0.0, failpercent=2.5)}
    a, b = _with_bad_pixels(n_bad, 0.25)
    assert compare_images(a, b, limits).groups["colour"].verdict == verdict


def test_warn_and_hardfail():
    a, b = _with_bad_pixels(1, 0.05)
    base = {"warn": 0.01, "fail": 0.1, "warnpercent": 0.0, "failpercent": 0.0}
    assert compare_images(a, b, {"colour": base}).verdict == WARN
    assert compare_images(a, b, {"colour": {**base, "warnpercent": 1.0}}).verdict == PASS
    assert compare_images(a, b, {"colour": {**base, "hardfail": 0.04}}).verdict == FAIL
    assert compare_images(a, b, {"colour": {**base, "hardfail": 0.06}}).verdict == WARN


def test_worst_group_decides_and_defaults_are_kept():
    a, b = image(), image(z=2.5)  # depth fails, colour passes
    result = compare_images(a, b, {"colour": {"fail": 0.5}})
    assert result.groups["colour"].verdict == PASS
    assert result.groups["depth"].verdict == FAIL and result.verdict == FAIL
    assert result.exit_code == 2
    assert result.groups["colour"].thresholds.warn == DEFAULT_THRESHOLDS["colour"].warn


def test_bad_thresholds_are_errors():
    with pytest.raises(subtrace.SubtraceError, match="unknown channel group 'color'"):
        compare_images(image(), image(), {"color": {"fail": 1}})
    with pytest.raises(subtrace.SubtraceError, match="unknown threshold 'fial'"):
        compare_images(image(), image(), {"colour": {"fial": 1}})
    with pytest.raises(subtrace.SubtraceError, match="expected a number >= 0"):
        compare_images(image(), image(), {"depth": {"fail": -1}})


# --------------------------------------------------------------------------------------
# mismatches and unreadable files
# --------------------------------------------------------------------------------------


def test_size_and_channel_mismatch():
    small = {k: v[:-1] for k, v in image().items()}
    with pytest.raises(ImageMismatchError, match="is 16x12 but image B is 16x11"):
        compare_images(image(), small)
    no_normals = {k: v for k, v in image().items() if not k.startswith("N.")}
    with pytest.raises(ImageMismatchError, match="image A has the normals channels"):
        compare_images(image(), no_normals)
    with pytest.raises(ImageMismatchError, match="no channel group in common"):
        compare_images({"u": np.zeros((2, 2))}, {"u": np.zeros((2, 2))})


def test_only_shared_groups_are_compared():
    colour_only = {c: np.full((H, W), 0.5, np.float32) for c in "RGB"}
    result = compare_images(colour_only, {k: v.copy() for k, v in colour_only.items()})
    assert list(result.groups) == ["colour"] and result.verdict == PASS


def test_position_is_an_optional_group():
    """P.X, P.Y, P.Z compare as the position group when both images have them (relative to
    the depth, as depth is), and an image without them still compares with one that has
    them (the group is left out)."""
    a, b = image(), image()
    for k, c in enumerate(("P.X", "P.Y", "P.Z")):
        a[c] = np.where(a["A"] > 0, np.float32(k + 1.0), np.float32(np.nan))
        b[c] = a[c].copy()
    b["P.X"] = b["P.X"] + np.float32(0.01)  # 0.01 / Z (2) = 5e-3: above the fail threshold
    result = compare_images(a, b)
    g = result.groups["position"]
    assert g.verdict == FAIL and g.pixels == int((a["A"] > 0).sum())
    assert g.metrics["max"] == pytest.approx(0.005, rel=1e-4)
    assert "position_rel" in result.diff_channels()
    plain = image()
    for x, y in ((a, plain), (plain, a)):
        r = compare_images(x, y)
        assert "position" not in r.groups and r.verdict == PASS


def test_unreadable_file(tmp_path):
    with pytest.raises(UnreadableImageError, match="missing.exr: no such file"):
        compare_images(tmp_path / "missing.exr", image())


# --------------------------------------------------------------------------------------
# subtrace compare
# --------------------------------------------------------------------------------------


@pytest.fixture
def files(tmp_path):
    """Paths of EXRs: same, same2 (equal), depth (depth off by 1 %), small (other size),
    colour (R,G,B only)."""
    paths = {k: tmp_path / f"{k}.exr" for k in ("same", "same2", "depth", "small", "colour")}
    write_exr(paths["same"], image())
    write_exr(paths["same2"], image())
    write_exr(paths["depth"], image(z=2.02))
    write_exr(paths["small"], {k: v[:, :-2] for k, v in image().items()})
    write_exr(paths["colour"], {c: image()[c] for c in "RGB"})
    return paths


def test_cli_pass_table(files, capsys):
    code, out, err = run_cli(capsys, files["same"], files["same2"])
    assert code == 0 and err == ""
    assert "depth" in out and out.strip().endswith("16x12: PASS")


def test_cli_fail_and_warn_exit_codes(files, capsys):
    assert run_cli(capsys, files["same"], files["depth"])[0] == 2
    # 1 % relative error: below a fail threshold of 0.02, above the warn threshold
    assert run_cli(capsys, files["same"], files["depth"], "--fail", "depth=0.02")[0] == 1
    # every pixel fails, but failpercent 100 allows it: then a warning
    assert run_cli(capsys, files["same"], files["depth"], "--failpercent", "depth=100")[0] == 1
    code = run_cli(capsys, files["same"], files["depth"], "--fail", "depth=0.02",
                   "--warnpercent", "depth=100")[0]
    assert code == 0
    code = run_cli(capsys, files["same"], files["depth"], "--fail", "depth=0.02",
                   "--hardfail", "depth=0.005")[0]
    assert code == 2


def test_cli_bare_threshold_is_colour(files, capsys, tmp_path):
    write_exr(tmp_path / "bright.exr", image(rgb=0.35))
    assert run_cli(capsys, files["same"], tmp_path / "bright.exr")[0] == 2
    code = run_cli(capsys, files["same"], tmp_path / "bright.exr", "--fail", "0.2",
                   "--warn", "0.2")[0]
    assert code == 0


def test_cli_json(files, capsys):
    code, out, _ = run_cli(capsys, files["same"], files["depth"], "--json")
    report = json.loads(out)
    assert code == 2 and report["verdict"] == "fail" and report["exit_code"] == 2
    depth = report["groups"]["depth"]
    assert depth["verdict"] == "fail" and depth["max_rel"] == pytest.approx(0.01, rel=1e-5)
    assert depth["pixels"] == H * W // 2
    assert report["groups"]["colour"]["psnr"] == "inf"  # JSON has no infinity
    assert report["a"] == str(files["same"])


def test_cli_mismatch_exit_3(files, capsys):
    code, out, err = run_cli(capsys, files["same"], files["small"])
    assert code == 3 and out == ""
    assert err.startswith("subtrace: error: ") and "16x12" in err and "14x12" in err
    code, _, err = run_cli(capsys, files["same"], files["colour"])
    assert code == 3 and "coverage channels" in err and str(files["colour"]) in err


def test_cli_unreadable_exit_4(files, capsys, tmp_path):
    missing = tmp_path / "nope.exr"
    code, out, err = run_cli(capsys, files["same"], missing)
    assert code == 4 and out == ""
    assert err == f"subtrace: error: {missing}: no such file\n"
    garbage = tmp_path / "garbage.exr"
    garbage.write_text("not an image\n")
    code, _, err = run_cli(capsys, garbage, files["same"])
    assert code == 4 and str(garbage) in err and "cannot read" in err
    assert err.count("\n") == 1
    code, _, err = run_cli(capsys, tmp_path, files["same"])
    assert code == 4 and "is a directory" in err


def test_cli_bad_options_exit_2(files, capsys, tmp_path):
    code, _, err = run_cli(capsys, files["same"], files["same2"], "--fail", "depht=1")
    assert code == 2 and "unknown channel group 'depht'" in err
    code, _, err = run_cli(capsys, files["same"], files["same2"], "--warn", "depth=x")
    assert code == 2 and "expected a number" in err
    code, _, err = run_cli(capsys, files["same"], files["same2"], "--png")
    assert code == 2 and "--diff" in err
    code, _, err = run_cli(capsys, files["same"], files["same2"], "--diff",
                           tmp_path / "no" / "d.exr")
    assert code == 2 and "does not exist" in err
    assert not (tmp_path / "no").exists()


def test_cli_diff_images(files, capsys, tmp_path):
    diff = tmp_path / "diff.exr"
    code, out, _ = run_cli(capsys, files["same"], files["depth"], "--diff", diff, "--png")
    assert code == 2 and str(diff) in out
    channels, attrs = read_exr(diff)
    assert attrs["subtrace:compare_verdict"] == "fail"
    covered = image()["A"] > 0
    np.testing.assert_allclose(channels["depth_rel"][covered], 0.01, rtol=1e-5)
    assert np.all(channels["depth_rel"][~covered] == 0)
    # heat: error / fail threshold (0.01 / 1e-3 = 10 where depth differs)
    np.testing.assert_allclose(channels["heat"][covered], 10, rtol=1e-4)
    assert (tmp_path / "diff.png").stat().st_size > 0
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("diff")) == [
        "diff.exr", "diff.png", "diff_ids.png"]
    assert f"heat map: {tmp_path / 'diff.png'}, ids map: {tmp_path / 'diff_ids.png'}" in out


def test_package_exports_compare_images():
    assert subtrace.compare_images is compare_images
    assert "compare_images" in subtrace.__all__


def test_other_renderers_channels_by_alias(tmp_path):
    """An image whose normals are Normal.X/Y/Z and depth 'depth' compares with subtrace's
    once --channels names them; without the aliases its groups do not match."""
    ours = image()
    theirs = {("Normal" + k[1:] if k.startswith("N.") else "depth" if k == "Z" else k): v
              for k, v in image().items()}
    with pytest.raises(ImageMismatchError):
        compare_images(ours, theirs)
    res = compare_images(ours, theirs, aliases={"N": "Normal", "Z": "depth"})
    assert res.verdict == PASS and {"normals", "depth"} <= set(res.groups)
    write_exr(tmp_path / "a.exr", ours)
    write_exr(tmp_path / "b.exr", theirs)
    code, out, _ = run_cli_paths(tmp_path, "--channels", "N=Normal", "Z=depth")
    assert code == 0 and "normals" in out


def test_only_and_ignore_choose_the_groups(tmp_path, capsys):
    """--ignore ids leaves a patch-id difference out of the verdict; --only depth compares
    depth alone, so an image without normals still compares; unknown groups are refused."""
    a, b = image(patch=3), image(patch=4)
    assert compare_images(a, b).verdict == FAIL
    res = compare_images(a, b, groups=[g for g in GROUPS if g != "ids"])
    assert res.verdict == PASS and "ids" not in res.groups
    no_normals = {k: v for k, v in image().items() if not k.startswith("N.")}
    assert set(compare_images(a, no_normals, groups=["depth"]).groups) == {"depth"}
    write_exr(tmp_path / "a.exr", a)
    write_exr(tmp_path / "b.exr", b)
    assert run_cli(capsys, tmp_path / "a.exr", tmp_path / "b.exr")[0] == 2
    assert run_cli(capsys, tmp_path / "a.exr", tmp_path / "b.exr", "--ignore", "ids")[0] == 0
    code, _, err = run_cli(capsys, tmp_path / "a.exr", tmp_path / "b.exr", "--only", "hair")
    assert code == 2 and "--only hair" in err and err.count("\n") == 1
    code, _, err = run_cli(capsys, tmp_path / "a.exr", tmp_path / "b.exr", "--channels", "N")
    assert code == 2 and "OURS=THEIRS" in err


def run_cli_paths(tmp_path, *extra):
    """``subtrace compare a.exr b.exr`` in ``tmp_path`` with ``extra`` options, as
    (code, stdout, stderr), run in a fresh process."""
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, "-m", "subtrace.cli", "compare",
                           str(tmp_path / "a.exr"), str(tmp_path / "b.exr"), *extra],
                          capture_output=True, text=True)
    return proc.returncode, proc.stdout, proc.stderr
