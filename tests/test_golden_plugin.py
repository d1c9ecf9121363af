"""subtrace's pytest plugin (subtrace.testing.plugin) run on the sample project of
tests/golden_project (pytester, in process): a passing golden, a failing one whose message
holds the group table and which writes its images, ``--update-goldens`` rewriting only what
changed, the project's thresholds from its pyproject.toml, and bad inputs as one line."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from subtrace.compare import GROUPS
from subtrace.io.exr import read_exr, write_exr
from subtrace.testing.plugin import SettingsError, read_settings

PROJECT = Path(__file__).resolve().parent / "golden_project"


@pytest.fixture
def project(pytester):
    """A copy of the sample project as pytester's folder."""
    shutil.copytree(PROJECT, pytester.path, dirs_exist_ok=True)
    return pytester


def sample_render(**kwargs) -> dict:
    """The sample project's render (its check_sphere.render)."""
    sys.path.insert(0, str(PROJECT))
    try:
        import check_sphere
    finally:
        sys.path.remove(str(PROJECT))
    sys.modules.pop("check_sphere", None)
    return check_sphere.render(**kwargs)


def no_traceback(text: str) -> None:
    """The plugin's failures are messages, not tracebacks of subtrace's code."""
    assert "Traceback" not in text and "subtrace/" not in text, text


def test_a_passing_and_a_failing_golden_with_the_group_table(project):
    result = project.runpytest("-rA")
    result.assert_outcomes(passed=1, failed=1)
    out = result.stdout.str()
    assert "sphere_lit differs from goldens/sphere_lit.exr:" in out
    # the group table: a header row and a row per group, then the verdict line
    result.stdout.re_match_lines([r".*group\s+verdict\s+pixels\s+> warn\s+> fail\s+max.*",
                                  r".*colour\s+FAIL\s+1200\s+\d+\s+\d+.*",
                                  r".*depth\s+PASS.*", r".*ids\s+PASS.*",
                                  r".*40x30: FAIL.*"], consecutive=False)
    assert 'python -m pytest "check_sphere.py::test_sphere_lit" --update-goldens' in out
    assert "golden images: 1 pass, 1 fail; report: test_output/golden/report.html" in out
    assert (project.path / "test_output" / "golden" / "report.html").stat().st_size > 0
    no_traceback(out)
    folder = project.path / "test_output" / "golden" / "sphere_lit"
    names = ("rendered.exr", "rendered.png", "reference.exr", "reference.png", "diff.exr",
             "diff.png", "diff_ids.png")
    for name in names:
        assert (folder / name).stat().st_size > 0 and f"test_output/golden/sphere_lit/{name}" in out
    assert not (project.path / "test_output" / "golden" / "sphere").exists()
    # the difference image holds |dR| of the two renders
    diff, _ = read_exr(folder / "diff.exr")
    new, old = sample_render(), read_exr(project.path / "goldens" / "sphere_lit.exr")[0]
    expected = np.abs(new["R"].astype(np.float16).astype(np.float64) - old["R"])
    np.testing.assert_allclose(diff["R"], expected, atol=1e-3)  # half-float |dR|


def test_update_goldens_rewrites_the_changed_golden_only(project):
    goldens = project.path / "goldens"
    before = {p.name: p.read_bytes() for p in goldens.iterdir()}
    result = project.runpytest("--update-goldens")
    result.assert_outcomes(passed=2)
    assert (goldens / "sphere.exr").read_bytes() == before["sphere.exr"]
    assert (goldens / "sphere_lit.exr").read_bytes() != before["sphere_lit.exr"]
    assert "golden images: 1 unchanged, 1 wrote" in result.stdout.str()
    project.runpytest().assert_outcomes(passed=2)
    # the old spelling of the option is the same option
    project.runpytest("--update-golden").assert_outcomes(passed=2)
    assert (goldens / "sphere_lit.exr").read_bytes() != before["sphere_lit.exr"]


def test_a_passing_run_writes_no_page_unless_asked(project, tmp_path):
    """Only the passing golden: nothing is written into the project; --golden-report DIR
    writes the session page (and would write failures) in DIR."""
    result = project.runpytest("check_sphere.py::test_sphere")
    result.assert_outcomes(passed=1)
    assert not (project.path / "test_output").exists()
    assert "report:" not in result.stdout.str()
    out = tmp_path / "ci-report"
    result = project.runpytest("check_sphere.py::test_sphere", "--golden-report", str(out))
    result.assert_outcomes(passed=1)
    assert (out / "report.html").stat().st_size > 0
    assert f"golden images: 1 pass; report: {out / 'report.html'}" in result.stdout.str()


def test_the_projects_thresholds_apply_and_a_call_overrides_them(project):
    """colour fail = 0.03 in the sample's pyproject.toml: a colour change of 0.025 passes
    there (it fails at the default 0.02), and fails where the call sets 0.02 again."""
    image = sample_render()
    for c in "RGB":
        image[c] = image[c] + np.float32(0.025)
    write_exr(project.path / "shifted.exr", image)
    project.makepyfile(check_shift="""
        def test_project(golden):
            golden("shifted.exr", "sphere")

        def test_call(golden):
            golden("shifted.exr", "sphere", colour={"fail": 0.02})
    """)
    result = project.runpytest("check_shift.py")
    result.assert_outcomes(passed=1, failed=1)
    assert "test_call" in "\n".join(line for line in result.outlines if "FAILED" in line)


def test_a_missing_golden_names_the_command_that_creates_it(project):
    (project.path / "goldens" / "sphere.exr").unlink()
    result = project.runpytest("check_sphere.py::test_sphere")
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines(["*golden image goldens/sphere.exr is missing; create it with: "
                                 'python -m pytest "check_sphere.py::test_sphere" '
                                 "--update-goldens*"])
    no_traceback(result.stdout.str())


@pytest.mark.parametrize("table, needle", [
    ("[tool.subtrace.compare.depth]\nfial = 1e-3\n",
     "[tool.subtrace.compare.depth]: unknown threshold 'fial': use warn, fail, warnpercent, "
     "failpercent, hardfail"),
    ("[tool.subtrace.compare.normals]\nfail = -2\n",
     "[tool.subtrace.compare.normals]: normals fail: expected a number >= 0, got -2"),
    ("[tool.subtrace.compare.colours]\nfail = 0.1\n",
     "[tool.subtrace.compare]: unknown key 'colours': use goldens, report, flip, ignore or a "
     "channel group's table (colour, coverage, depth, normals, ids, position)"),
])
def test_a_bad_setting_is_one_line_naming_the_key(project, table, needle):
    pyproject = project.path / "pyproject.toml"
    text = pyproject.read_text()
    assert text.count("[tool.subtrace.compare.colour]") == 1
    pyproject.write_text(text.replace("[tool.subtrace.compare.colour]",
                                      table + "[tool.subtrace.compare.colour]"))
    result = project.runpytest("check_sphere.py")
    result.assert_outcomes(failed=2)
    lines = [line for line in result.outlines if needle in line]
    assert lines and str(pyproject) in lines[0], result.stdout.str()
    no_traceback(result.stdout.str())


def test_bad_images_and_arguments_are_one_line(project):
    small = {c: v[:20] for c, v in sample_render().items()}
    write_exr(project.path / "small.exr", small)
    project.makepyfile(check_small="""
        def test_small(golden):
            golden("small.exr", "sphere")

        def test_missing_file(golden):
            golden("nowhere.exr", "sphere")

        def test_bad_name(golden):
            golden("small.exr", "../sphere")

        def test_bad_group(golden):
            golden("goldens/sphere.exr", "sphere", depht={"fail": 1.0})

        def test_bad_threshold(golden):
            golden("goldens/sphere.exr", "sphere", depth={"fial": 1.0})
    """)
    result = project.runpytest("check_small.py")
    result.assert_outcomes(failed=5)
    out = result.stdout.str()
    assert "sphere: image A is 40x20 but " in out and "goldens/sphere.exr is 40x30" in out
    assert "golden: cannot read the image: nowhere.exr" in out
    assert "golden name '../sphere': expected a file name without a folder" in out
    assert "golden('sphere'): unknown channel group 'depht': use one of colour," in out
    assert "golden('sphere'): unknown threshold 'fial': use warn, fail," in out
    no_traceback(out)


def test_settings_default_without_a_table(tmp_path):
    settings = read_settings(tmp_path)
    assert settings.goldens == tmp_path / "goldens"
    assert settings.report == tmp_path / "test_output" / "golden"
    assert settings.thresholds == {} and settings.flip and settings.ignore == ()
    (tmp_path / "pyproject.toml").write_text('[tool.subtrace.compare]\nignore = ["idz"]\n')
    with pytest.raises(SettingsError, match="ignore must be a list of channel groups"):
        read_settings(tmp_path)
    (tmp_path / "pyproject.toml").write_text("[tool.subtrace.compare\n")
    with pytest.raises(SettingsError, match="cannot read it as TOML"):
        read_settings(tmp_path)
    assert set(GROUPS) >= {"colour", "ids"}


def test_an_unwritable_report_folder_is_named_not_a_traceback(project):
    """--golden-report under a file: the failing golden still fails with its table, saying
    the images were not written; the summary says the page was not written."""
    (project.path / "blocker").write_text("a file, not a folder")
    result = project.runpytest("check_sphere.py", "--golden-report", "blocker/report")
    result.assert_outcomes(passed=1, failed=1)
    out = result.stdout.str()
    assert "sphere_lit differs from goldens/sphere_lit.exr:" in out
    assert "images not written: " in out and "report: not written: " in out
    no_traceback(out)
