"""pytest plugin: golden-image tests judged as ``subtrace compare`` judges two images.

A test asks for the ``golden`` fixture and calls it with its render::

    def test_spot(golden):
        golden(render_scene(scene), "spot")          # or channels, or an EXR path

which compares the render with ``<goldens>/spot.exr`` by subtrace compare's channel groups
and thresholds (:mod:`subtrace.compare`), fails with the group table when the verdict is
FAIL (a WARN passes with a pytest warning), writes the render, the golden, the difference
EXR and the heat and ids maps to ``<report>/<name>/`` when it fails, and puts every
comparison of the session on one self-contained page, ``<report>/report.html``, when one
failed or warned (always with ``--golden-report DIR``).
``pytest --update-goldens`` (alias ``--update-golden``) writes the goldens from the renders
instead; a golden whose pixels and ``subtrace:`` header values are unchanged is left as it
is, byte for byte.

Settings come from the ``[tool.subtrace.compare]`` table of the project's pyproject.toml
(the one beside pytest's rootdir), every key optional::

    [tool.subtrace.compare]
    goldens = "goldens"            # folder of <name>.exr, relative to pyproject.toml
    report = "test_output/golden"  # failures' images and report.html (--golden-report)
    flip = true                    # compute the colour group's mean FLIP
    ignore = ["position"]          # groups left out
    [tool.subtrace.compare.depth]  # a group's thresholds: warn, fail, warnpercent,
    fail = 1e-4                    # failpercent, hardfail (subtrace compare's defaults else)

and a call may override a group's thresholds: ``golden(img, "spot", depth={"fail": 1e-4})``.
A bad setting fails each golden test with one line naming the file, table and key.

This module imports only the standard library and pytest at load (pytest loads it in every
session of an environment where subtrace is installed); subtrace's comparison, images and
page are imported by the first golden comparison.
"""

from __future__ import annotations

import os
import re
import tomllib
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import pytest

SECTION = ("tool", "subtrace", "compare")
SECTION_NAME = "[tool.subtrace.compare]"
SETTINGS = ("goldens", "report", "flip", "ignore")
DEFAULT_GOLDENS = "goldens"
DEFAULT_REPORT = os.path.join("test_output", "golden")
REPORT_PAGE = "report.html"
NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.\-]*")  # a golden's name: one file name, no path


class GoldenWarning(UserWarning):
    """A golden comparison whose verdict is WARN (it passes)."""


class SettingsError(Exception):
    """A bad ``[tool.subtrace.compare]`` value: the message is the one line to show."""


@dataclass
class Settings:
    """The session's golden settings: folders, thresholds (group -> dict of fields), FLIP,
    the groups left out, and where they were read from (for messages)."""

    goldens: Path
    report: Path
    thresholds: dict = field(default_factory=dict)
    flip: bool = True
    ignore: tuple = ()
    source: str = "defaults"


@dataclass
class Outcome:
    """One golden comparison of the session, for the report page."""

    nodeid: str
    name: str
    golden: Path
    comparison: object = None  # subtrace.compare.Comparison; None: written or not compared
    note: str = ""  # "wrote", "unchanged", or why it was not compared
    files: list = field(default_factory=list)


_SETTINGS = pytest.StashKey[object]()
_OUTCOMES = pytest.StashKey[list]()
_PAGE = pytest.StashKey[str]()  # the session page's path, or why it was not written


def pytest_addoption(parser):
    group = parser.getgroup("subtrace", "golden images (subtrace.testing.plugin)")
    group.addoption("--update-goldens", "--update-golden", action="store_true",
                    dest="update_goldens", default=False,
                    help="write each golden image (<goldens>/<name>.exr) from the test's "
                         "render instead of comparing (unchanged goldens are left as they are)")
    group.addoption("--golden-report", metavar="DIR", dest="golden_report", default=None,
                    help="folder for failed goldens' images and report.html, which is then "
                         "written even when every golden passes (default: "
                         f"{SECTION_NAME} report, else {DEFAULT_REPORT})")


def pytest_configure(config):
    config.stash[_OUTCOMES] = []


def read_settings(root: Path, report_option: str | None = None) -> Settings:
    """The settings of the project at ``root`` (its pyproject.toml's table; defaults without
    one). Raises SettingsError with one line naming the file and the key."""
    from subtrace.compare import GROUPS, resolve_thresholds
    from subtrace.errors import SubtraceError

    path = root / "pyproject.toml"
    table: dict = {}
    if path.is_file():
        try:
            doc = tomllib.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as err:
            raise SettingsError(f"{path}: cannot read it as TOML: {err}") from None
        table = doc
        for key in SECTION:
            table = table.get(key, {}) if isinstance(table, dict) else {}
        if not isinstance(table, dict):
            raise SettingsError(f"{path}: {SECTION_NAME} must be a table")
    where = f"{path} {SECTION_NAME}"

    def text(key, default):
        value = table.get(key, default)
        if not isinstance(value, str) or not value:
            raise SettingsError(f"{where}: {key} must be a folder name (a string), "
                                f"got {value!r}")
        return value

    for key in table:
        if key not in SETTINGS and key not in GROUPS:
            raise SettingsError(f"{where}: unknown key {key!r}: use {', '.join(SETTINGS)} or "
                                f"a channel group's table ({', '.join(GROUPS)})")
    flip = table.get("flip", True)
    if not isinstance(flip, bool):
        raise SettingsError(f"{where}: flip must be true or false, got {flip!r}")
    ignore = table.get("ignore", [])
    if not isinstance(ignore, list) or any(g not in GROUPS for g in ignore):
        raise SettingsError(f"{where}: ignore must be a list of channel groups "
                            f"({', '.join(GROUPS)}), got {ignore!r}")
    thresholds = {}
    for group in GROUPS:
        if group not in table:
            continue
        values = table[group]
        if not isinstance(values, dict):
            raise SettingsError(f"{path} [tool.subtrace.compare.{group}]: must be a table "
                                f"of thresholds, got {values!r}")
        try:
            resolve_thresholds({group: values})
        except SubtraceError as err:
            raise SettingsError(f"{path} [tool.subtrace.compare.{group}]: {err}") from None
        thresholds[group] = dict(values)
    report = Path(report_option) if report_option else root / text("report", DEFAULT_REPORT)
    return Settings(goldens=root / text("goldens", DEFAULT_GOLDENS), report=report,
                    thresholds=thresholds, flip=flip, ignore=tuple(ignore),
                    source=str(path) if path.is_file() else "defaults")


def _settings(config) -> Settings:
    """The session's settings, read once; a bad one fails the test with its line."""
    if _SETTINGS not in config.stash:
        try:
            config.stash[_SETTINGS] = read_settings(config.rootpath,
                                                    config.getoption("golden_report"))
        except SettingsError as err:
            config.stash[_SETTINGS] = err
    settings = config.stash[_SETTINGS]
    if isinstance(settings, SettingsError):
        pytest.fail(str(settings), pytrace=False)
    return settings


class Golden:
    """The ``golden`` fixture's value: call it with an image and a golden name."""

    def __init__(self, request):
        self._request = request

    def __call__(self, image, name: str, *, attributes: dict | None = None,
                 flip: bool | None = None, ignore=None, **thresholds):
        """Compare ``image`` with ``<goldens>/<name>.exr`` (or write it with
        --update-goldens); returns the :class:`subtrace.compare.Comparison` (None when
        writing).

        image: a channel dict (name -> (H,W) array), an object with ``.channels`` (a
          RenderResult), or the path of an EXR.
        attributes: header values written into the golden with --update-goldens.
        flip, ignore: as the settings' (ignore adds to them).
        thresholds: group -> dict of threshold fields, over the project's.
        """
        config = self._request.config
        settings = _settings(config)
        if not isinstance(name, str) or not NAME.fullmatch(name):
            pytest.fail(f"golden name {name!r}: expected a file name without a folder "
                        "(letters, digits, '_', '-', '.')", pytrace=False)
        outcome = Outcome(self._request.node.nodeid, name, settings.goldens / f"{name}.exr")
        command = update_command(self._request.node.nodeid)
        channels = _channels_of(image)
        if config.getoption("update_goldens"):
            outcome.note = write_golden(outcome.golden, channels, attributes or {})
            config.stash[_OUTCOMES].append(outcome)
            return None
        if not outcome.golden.is_file():
            pytest.fail(f"golden image {_rel(outcome.golden, config)} is missing; create it "
                        f"with: {command}", pytrace=False)
        from subtrace.compare import (FAIL, GROUPS, WARN, ImageMismatchError,
                                      UnreadableImageError, compare_images)
        from subtrace.errors import SubtraceError

        merged = {g: dict(v) for g, v in settings.thresholds.items()}
        for group, values in thresholds.items():
            if not isinstance(values, dict):
                pytest.fail(f"golden({name!r}, {group}=...): expected a dict of thresholds "
                            f"such as {{'fail': 0.01}}, got {values!r}", pytrace=False)
            merged.setdefault(group, {}).update(values)
        left_out = set(settings.ignore) | set(ignore or ())
        try:
            comparison = compare_images(
                channels, outcome.golden, merged,
                flip=settings.flip if flip is None else flip,
                groups=[g for g in GROUPS if g not in left_out])
        except (ImageMismatchError, UnreadableImageError) as err:
            pytest.fail(f"{name}: {err}; if the change is intended, regenerate with: "
                        f"{command}", pytrace=False)
        except SubtraceError as err:
            pytest.fail(f"golden({name!r}): {err}", pytrace=False)
        outcome.comparison = comparison
        config.stash[_OUTCOMES].append(outcome)
        if comparison.verdict == FAIL:
            try:
                outcome.files = write_failure(settings.report / name, channels,
                                              outcome.golden, comparison)
            except (SubtraceError, OSError) as err:
                outcome.note = f"images not written: {err}"
            written = ("written: " + ", ".join(_rel(p, config) for p in outcome.files)
                       if outcome.files else outcome.note)
            pytest.fail(f"{name} differs from {_rel(outcome.golden, config)}:\n"
                        f"{comparison.table()}\n{written}\n"
                        f"report: {_rel(settings.report / REPORT_PAGE, config)}\n"
                        f"if the change is intended, regenerate with: {command}",
                        pytrace=False)
        if comparison.verdict == WARN:
            warned = [g.name for g in comparison.groups.values() if g.verdict == WARN]
            warnings.warn(GoldenWarning(f"{name}: WARN in {', '.join(warned)} (passes)"),
                          stacklevel=2)
        return comparison


@pytest.fixture
def golden(request) -> Golden:
    """Compare a render with its golden image: ``golden(image, name, **thresholds)`` (see
    :mod:`subtrace.testing.plugin`)."""
    return Golden(request)


def update_command(nodeid: str) -> str:
    """The command that (re)writes the goldens of the test ``nodeid``."""
    return f'python -m pytest "{nodeid}" --update-goldens'


def _rel(path: Path, config) -> str:
    """``path`` relative to the rootdir where it lies inside it."""
    path = Path(path)
    try:
        return str(path.relative_to(config.rootpath))
    except ValueError:
        return str(path)


def _channels_of(image) -> dict:
    """The channel dict of a golden call's image; a pytest failure for anything else."""
    if isinstance(image, dict):
        return image
    if hasattr(image, "channels") and isinstance(image.channels, dict):
        return image.channels
    if isinstance(image, (str, os.PathLike)):
        from subtrace.errors import SubtraceError
        from subtrace.io.exr import read_exr

        try:
            return read_exr(image)[0]
        except SubtraceError as err:
            pytest.fail(f"golden: cannot read the image: {err}", pytrace=False)
    pytest.fail(f"golden: expected a channel dict, a render result or an EXR path, got "
                f"{type(image).__name__}", pytrace=False)


def same_golden(path: Path, channels: dict, attributes: dict) -> bool:
    """True when the golden at ``path`` holds exactly these pixels (as stored: half or
    float32) and ``subtrace:`` header values."""
    import numpy as np

    from subtrace.io.exr import HALF_CHANNELS, read_exr

    old_channels, old_attrs = read_exr(path)
    if list(old_channels) != list(channels):
        return False
    for c, new in channels.items():
        stored = np.asarray(new, np.float16 if c in HALF_CHANNELS else np.float32)
        if not np.array_equal(old_channels[c], stored.astype(np.float32), equal_nan=True):
            return False
    ours = {k: v for k, v in attributes.items() if k.startswith("subtrace:")}
    return all(old_attrs.get(k) == pytest.approx(v) if isinstance(v, float)
               else old_attrs.get(k) == v for k, v in ours.items())


def write_golden(path: Path, channels: dict, attributes: dict) -> str:
    """Write the golden (its folder created) unless it is unchanged: "wrote" / "unchanged"."""
    from subtrace.errors import SubtraceError
    from subtrace.io.exr import write_exr

    try:
        if path.is_file() and same_golden(path, channels, attributes):
            return "unchanged"
        path.parent.mkdir(parents=True, exist_ok=True)
        write_exr(path, channels, attributes)
    except (SubtraceError, OSError) as err:
        pytest.fail(f"cannot write the golden {path}: {err}", pytrace=False)
    return "wrote"


def write_failure(folder: Path, channels: dict, golden: Path, comparison) -> list[Path]:
    """The render, the golden and their difference in ``folder``: rendered.exr/.png,
    reference.exr/.png (the PNGs where both have colour), diff.exr, diff.png (the heat map)
    and diff_ids.png (the ids map, where ids were compared). Returns the paths."""
    import shutil

    from subtrace.io.exr import write_exr, write_png

    folder.mkdir(parents=True, exist_ok=True)
    paths = [folder / "rendered.exr"]
    write_exr(paths[0], channels)
    if comparison.rgb is not None:
        paths.append(folder / "rendered.png")
        write_png(paths[-1], comparison.rgb[0])
    paths.append(folder / "reference.exr")
    shutil.copyfile(golden, paths[-1])
    if comparison.rgb is not None:
        paths.append(folder / "reference.png")
        write_png(paths[-1], comparison.rgb[1])
    paths.append(folder / "diff.exr")
    paths += [Path(p) for p in comparison.write_diff(paths[-1], png_path=folder / "diff.png")]
    return paths


def pytest_sessionfinish(session):
    """Write the session's page, report.html, of every golden compared or written: when a
    golden failed or warned, or always with --golden-report (a run that passes writes
    nothing into the project)."""
    config = session.config
    outcomes = config.stash.get(_OUTCOMES, [])
    settings = config.stash.get(_SETTINGS, None)
    if not outcomes or not isinstance(settings, Settings):
        return
    flagged = any(o.comparison is not None and o.comparison.verdict != "pass"
                  for o in outcomes)
    if not flagged and config.getoption("golden_report") is None:
        return
    from subtrace.errors import SubtraceError
    from subtrace.htmlreport import compare_page, write_page

    entries = []
    for o in outcomes:
        golden = _rel(o.golden, config)
        entry = {"name": o.name, "comparison": o.comparison, "a": f"the render of {o.nodeid}",
                 "b": golden}
        if o.comparison is None:
            entry["note"] = f"{o.note} {golden} ({o.nodeid}, --update-goldens)"
        elif o.files:
            entry["note"] = "written: " + ", ".join(_rel(p, config) for p in o.files)
        entries.append(entry)
    path = settings.report / REPORT_PAGE
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_page(path, compare_page(entries, "golden images"))
        config.stash[_PAGE] = _rel(path, config)
    except (SubtraceError, OSError) as err:
        config.stash[_PAGE] = f"not written: {err}"


def pytest_terminal_summary(terminalreporter, config):
    outcomes = config.stash.get(_OUTCOMES, [])
    if not outcomes:
        return
    counts: dict = {}
    for o in outcomes:
        key = o.comparison.verdict if o.comparison is not None else o.note
        counts[key] = counts.get(key, 0) + 1
    line = ", ".join(f"{n} {k}" for k, n in counts.items())
    page = config.stash.get(_PAGE, None)
    terminalreporter.write_line(f"golden images: {line}" + (f"; report: {page}" if page else ""))
