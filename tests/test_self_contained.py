"""The repository is self-contained: a clone passes its own tests with nothing beside it.

* No source, test, benchmark, scene, tool or model file names a folder outside the
  repository: not ``../shared`` (or any ``..``-path to a ``shared`` folder), nor a path
  built to a sibling ``shared`` folder (``REPO.parent / "shared"``,
  ``os.path.join(root, "..", "shared")``), nor one built from ``__file__`` that climbs
  above the repository (``Path(__file__).parents[2]`` in ``tests/``).
* The data the tests read is here with its licence: the OpenSubdiv reference data in
  ``tests/oracle/`` (one shape per result file), every model of ``models/`` listed in its
  README.

Python files are read with :mod:`ast` (a string ``"shared"`` elsewhere, e.g. a symbol's
name, is fine); every text file is also searched for the ``..``-path itself.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SCANNED = ("src", "tests", "benchmarks", "scenes", "tools", "models", ".ci")
TOP_FILES = ("cli.py", "pyproject.toml")
SIBLING = "shared"  # the folder a checkout of the developers' material has beside it
DOTDOT = re.compile(r"\.\.[/\\]+" + SIBLING + r"\b")
PATH_CALLS = {"join", "joinpath", "Path", "PurePath", "PosixPath", "WindowsPath"}


def _text_files():
    """(path relative to REPO, text) of every text file scanned (binary data is skipped)."""
    paths = [REPO / name for name in TOP_FILES]
    for top in SCANNED:
        paths += sorted(p for p in (REPO / top).rglob("*") if p.is_file())
    for path in paths:
        if _built(path) or path.suffix in (".npz", ".exr", ".png"):
            continue
        try:
            yield path.relative_to(REPO), path.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue


def _built(path: Path) -> bool:
    """Whether ``path`` is a build or install artefact (git ignores them), not a source."""
    return path.suffix == ".pyc" or any(
        part in ("__pycache__", "build", "dist") or part.endswith(".egg-info")
        for part in path.relative_to(REPO).parts)


def _is_sibling(node) -> bool:
    """Whether ``node`` is a string naming the sibling folder as a path component."""
    if not (isinstance(node, ast.Constant) and isinstance(node.value, str)):
        return False
    value = node.value.replace("\\", "/").strip("/")
    return value == SIBLING or value.startswith(SIBLING + "/")


def _call_name(node) -> str:
    func = node.func
    return func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")


def _climbs(node, depth: int) -> bool:
    """``<...__file__...>.parents[k]`` with k above the repository root, for a file
    ``depth`` folders below it (its ``parents[depth]`` is the root)."""
    return (isinstance(node, ast.Subscript) and isinstance(node.value, ast.Attribute)
            and node.value.attr == "parents" and isinstance(node.slice, ast.Constant)
            and isinstance(node.slice.value, int) and node.slice.value > depth
            and any(isinstance(n, ast.Name) and n.id == "__file__"
                    for n in ast.walk(node.value)))


def python_violations(rel: Path, text: str) -> list[str]:
    """``path:line: what`` for each path out of the repository built in a Python file."""
    found = []
    for node in ast.walk(ast.parse(text, str(rel))):
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Div) and (
                _is_sibling(node.left) or _is_sibling(node.right)):
            found.append(f"{rel}:{node.lineno}: a path to a sibling {SIBLING!r} folder")
        elif (isinstance(node, ast.Call) and _call_name(node) in PATH_CALLS
              and any(_is_sibling(a) for a in node.args)):
            found.append(f"{rel}:{node.lineno}: a path to a sibling {SIBLING!r} folder")
        elif _climbs(node, len(rel.parts) - 1):
            found.append(f"{rel}:{node.lineno}: a path above the repository "
                         f"(parents[{node.slice.value}] of a file {len(rel.parts) - 1} "
                         "folders down)")
    return found


def violations(files) -> list[str]:
    found = []
    for rel, text in files:
        found += [f"{rel}:{text.count(chr(10), 0, m.start()) + 1}: names {m.group(0)!r}"
                  for m in DOTDOT.finditer(text)]
        if rel.suffix == ".py":
            found += python_violations(rel, text)
    return found


def test_nothing_reads_outside_the_repository():
    """No scanned file names or builds a path to a folder beside the repository."""
    me = Path(__file__).resolve().relative_to(REPO)
    found = violations((rel, text) for rel, text in _text_files() if rel != me)
    assert not found, "\n".join(found)


@pytest.mark.parametrize("code", [
    'SHARED = Path(__file__).resolve().parents[2] / "shared"',
    'MODELS = REPO.parent / "shared" / "models"',
    'ORACLE = os.path.join(ROOT, "..", "shared", "oracle")',
    'SHAPES = Path(__file__).parents[1] / "../shared/oracle/shapes"',
    'DATA = Path(__file__).resolve().parents[3]',
    '# reads ../shared/models when present',
])
def test_the_check_finds_each_way_out(code):
    """Each form of a path beside the repository is found, in a file of ``tests/``."""
    assert violations([(Path("tests/test_x.py"), code + "\n")])


def test_the_check_leaves_the_word_alone():
    """``shared`` as a word, a symbol's name or a folder inside the repository is fine."""
    code = ('"""shared edges are sampled alike"""\n'
            'names = {"table", "shared"}\n'
            'ROOT = Path(__file__).resolve().parents[1]\n'
            'cache = ROOT / "models" / "shared_cage.obj"\n'
            'key = shared["x"]\n')
    assert violations([(Path("tests/test_x.py"), code)]) == []


def test_the_oracle_data_is_here_with_its_licence():
    """tests/oracle: OpenSubdiv's results and shapes, one OBJ per result file, with
    OpenSubdiv's LICENSE and NOTICE and the README that documents the arrays."""
    oracle = REPO / "tests" / "oracle"
    results = {p.stem for p in oracle.glob("*.npz")}
    shapes = {p.stem for p in (oracle / "shapes").glob("*.obj")}
    assert len(results) == 68 and results == shapes
    for name in ("LICENSE.txt", "NOTICE.txt", "README.md"):
        assert (oracle / name).is_file(), name
    readme = (oracle / "README.md").read_text(encoding="utf-8")
    assert all(f"`{name}`" in readme for name in results)


def test_every_model_is_listed_with_its_licence():
    """Each OBJ of models/ has a row in models/README.md; the licence files named there
    are here."""
    models = REPO / "models"
    readme = (models / "README.md").read_text(encoding="utf-8")
    for path in sorted(models.rglob("*.obj")):
        assert f"`{path.relative_to(models).as_posix()}`" in readme, path
    named = set(re.findall(r"`((?:\w+/)?(?:LICENSE|NOTICE)[\w.-]*\.txt)`", readme))
    assert named >= {"LICENSE.pmp-library.txt", "opensubdiv/LICENSE.txt"}
    for name in named:
        assert (models / name).is_file(), name
