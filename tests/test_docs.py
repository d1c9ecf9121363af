"""The user's guide says what the code does: the scene-format page lists exactly the TOML keys
the parser accepts, table by table, and each key's example is a value the parser takes; the
README and the guide link only to files and headings that exist, none outside the
repository, and none names the developers' folder beside it.

The page's layout (docs/guide/scene-format.md): a ``## `` heading per table (``Top level``,
``[[object]]``, ``[camera]`` ...), then a Markdown table whose first column is ``key`` and
whose columns are key, type, default, example and meaning."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest

from subtrace.data import sample_cage_path
from subtrace.io.scene import SCENE_KEYS, scene_from_dict

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "guide" / "scene-format.md"
COLUMNS = ("key", "type", "default", "example", "meaning")
HEADING = re.compile(r"^## (.+)$")
SECTION = re.compile(r"`\[\[?([a-z_]+)\]\]?`")


def documented_tables(text: str) -> dict[str, list[list[str]]]:
    """Section ("" for the top level, else the table's name) -> the rows of its key table,
    each a list of cells with the backticks of the key stripped; a heading without a key
    table is left out."""
    tables: dict[str, list[list[str]]] = {}
    section, rows, in_table = None, None, False
    for line in text.splitlines():
        m = HEADING.match(line)
        if m:
            title = m.group(1).strip()
            s = SECTION.fullmatch(title)
            section = "" if title == "Top level" else s.group(1) if s else None
            in_table = False
            continue
        if not line.startswith("|"):
            in_table = False
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells[0] == "key" and section is not None:
            assert tuple(cells) == COLUMNS, f"{section!r}: columns {cells}"
            assert section not in tables, f"two key tables for {section!r}"
            rows = tables[section] = []
            in_table = True
        elif in_table and not set(cells[0]) <= set("-: "):
            rows.append([cells[0].strip("`"), *cells[1:]])
    return tables


@pytest.fixture(scope="module")
def tables():
    return documented_tables(PAGE.read_text(encoding="utf-8"))


def test_every_table_of_the_parser_has_a_key_table(tables):
    assert set(tables) == set(SCENE_KEYS)


@pytest.mark.parametrize("section", sorted(SCENE_KEYS))
def test_the_page_lists_exactly_the_keys_the_parser_accepts(tables, section):
    keys = [row[0] for row in tables.get(section, [])]
    assert len(keys) == len(set(keys)), f"a key listed twice: {keys}"
    missing = set(SCENE_KEYS[section]) - set(keys)
    extra = set(keys) - set(SCENE_KEYS[section])
    assert not missing, f"[{section}]: accepted but not documented: {sorted(missing)}"
    assert not extra, f"[{section}]: documented but not accepted: {sorted(extra)}"


def test_every_row_has_a_type_default_example_and_meaning(tables):
    for section, rows in tables.items():
        for row in rows:
            assert len(row) == len(COLUMNS) and all(row), f"[{section}] {row}"


def _example(row) -> object:
    """The value of a row's example (a TOML line `key = value` in backticks, or a table
    header such as `[camera]`), checked to define exactly that key."""
    m = re.fullmatch(r"`([^`]+)`", row[3])
    assert m, f"{row[0]}: the example is not one `...` snippet: {row[3]}"
    data = tomllib.loads(m.group(1))
    assert list(data) == [row[0]], f"{row[0]}: the example defines {list(data)}"
    return data[row[0]]


# what a key's example needs beside it in its table to be accepted
COMPANIONS = {("camera", "target"): {"eye": [3.0, 2.0, 5.0]},
              ("light", "color"): {"direction": [0, -1, 0]},
              ("light", "intensity"): {"direction": [0, -1, 0]},
              ("light", "radius"): {"position": [0, 3, 0]},
              ("light", "angle"): {"direction": [0, -1, 0]},
              ("light", "samples"): {"position": [0, 3, 0], "radius": 0.3},
              ("light", "kind"): {"position": [0, 3, 0], "normal": [0, -1, 0], "radius": 1},
              ("light", "normal"): {"kind": "disk", "position": [0, 3, 0], "radius": 1},
              ("light", "u"): {"kind": "quad", "position": [0, 3, 0], "v": [0, 0, -1]},
              ("light", "v"): {"kind": "quad", "position": [0, 3, 0], "u": [1, 0, 0]},
              ("light", "file"): {"kind": "environment"}}


def test_every_example_is_a_value_the_parser_takes(tables):
    """Each example, put alone (with what it needs) into a scene of the sample cage, is
    accepted."""
    mesh = str(sample_cage_path())
    for section, rows in tables.items():
        for row in rows:
            key, value = row[0], _example(row)
            scene = {"object": [{"mesh": mesh}]}
            if section == "":
                if key in SCENE_KEYS:  # a table: its header parses as that table
                    continue
                scene[key] = value
            elif section == "object":
                scene["object"][0][key] = value
            else:
                table = {**COMPANIONS.get((section, key), {}), key: value}
                scene[section] = [table] if section == "light" else table
            scene_from_dict(scene, base_dir=ROOT)  # raises SceneError if not accepted


def test_the_complete_example_is_a_scene():
    text = PAGE.read_text(encoding="utf-8")
    block = re.search(r"## A complete example.*?```toml\n(.*?)```", text, re.S)
    assert block, "no complete example"
    scene = scene_from_dict(tomllib.loads(block.group(1)), base_dir=ROOT / "scenes")
    assert scene.objects and scene.lights and scene.ground is not None


def test_the_checker_finds_a_missing_and_an_unknown_key():
    page = PAGE.read_text(encoding="utf-8")
    broken = page.replace("| `shininess` |", "| `shinyness` |")
    rows = documented_tables(broken)["object"]
    keys = {row[0] for row in rows}
    assert "shininess" not in keys and "shinyness" in keys


LINK = re.compile(r"\]\(([^)#\s]*)(?:#([^)\s]*))?\)")


def anchors(page: Path) -> set[str]:
    """The anchors of a page's headings, as GitHub makes them: lower case, punctuation but
    hyphens and underscores dropped, spaces as hyphens."""
    out = set()
    for line in page.read_text(encoding="utf-8").splitlines():
        m = re.match(r"#{1,6} (.+)", line)
        if m:
            out.add(re.sub(r"[^\w\- ]", "", m.group(1).strip().lower()).replace(" ", "-"))
    return out


def _doc_files():
    return [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def test_links_lead_to_files_of_the_repository():
    """Every relative link of the README and docs/ names a file or folder that exists (and a
    heading of it, where it names one), and none leaves the repository (a clone has nothing
    beside it)."""
    bad = []
    for page in _doc_files():
        for target, anchor in LINK.findall(page.read_text(encoding="utf-8")):
            if re.match(r"[a-z]+:", target):
                continue  # a web address
            path = (page.parent / target).resolve() if target else page.resolve()
            where = f"{page.relative_to(ROOT)}: {target}#{anchor}"
            if ROOT.resolve() not in path.parents and path != ROOT.resolve():
                bad.append(f"{where} leaves the repository")
            elif not path.exists():
                bad.append(f"{where} does not exist")
            elif anchor and path.suffix == ".md" and anchor not in anchors(path):
                bad.append(f"{where}: no such heading")
    assert not bad, "\n".join(bad)


FIRST_RUN_STEPS = ("install", "first render", "warm render", "first Loop render", "warmup")


def _first_run_figures(text: str, section: str) -> list[float]:
    """The ``seconds`` column of the first table after the heading ``section``."""
    column, figures = None, []
    for line in text[text.index(section):].splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if not line.startswith("|"):
            if figures:
                break
        elif column is None and "seconds" in cells:
            column = cells.index("seconds")
        elif column is not None and not set(cells[0]) <= set("-: "):
            figures.append(float(cells[column]))
    return figures


def test_the_readme_quotes_the_first_run_benchmark():
    """The README's first-run figures are BENCHMARKS.md's benchmarks/first_run.py table, and
    the compile notice's estimate is that run's first render."""
    from subtrace.runtime import jit

    bench = _first_run_figures((ROOT / "BENCHMARKS.md").read_text(encoding="utf-8"),
                               "## First run (`benchmarks/first_run.py`)")
    readme = _first_run_figures((ROOT / "README.md").read_text(encoding="utf-8"),
                                "## Two commands")
    assert len(bench) == len(FIRST_RUN_STEPS), bench
    assert readme == bench
    assert jit.COLD_COMPILE_S == round(bench[1])
    assert str(jit.COLD_COMPILE_S) in jit.COLD_COMPILE


BESIDE = ".." + "/shared"  # the developers' folder beside a checkout (spelt so, not named)


def test_no_page_names_the_folder_beside_the_repository():
    bad = [str(p.relative_to(ROOT)) for p in _doc_files()
           if BESIDE in p.read_text(encoding="utf-8")]
    assert not bad, bad
