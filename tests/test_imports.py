"""What importing subtrace costs: ``import subtrace`` and ``import subtrace.cli`` load
neither Numba nor OpenImageIO (nor numpy, matplotlib) and set no environment variable, and
``subtrace --help`` / ``--version`` parse without them. Each case runs in a fresh
interpreter, since a module once imported stays imported."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import subtrace

# the subtrace this process imported (installed or the sources)
SRC = Path(subtrace.__file__).resolve().parents[1]
HEAVY = ("numba", "OpenImageIO", "numpy", "matplotlib")
CUBE = Path(__file__).resolve().parents[1] / "models" / "chamfer_cube.obj"


def _fresh(code: str) -> dict:
    """Run ``code`` in a fresh interpreter without NUMBA_CACHE_DIR set; it leaves its
    answer in the variable ``answer``, returned decoded from JSON."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["PYTHONPATH"] = str(SRC) + os.pathsep + env.get("PYTHONPATH", "")
    script = code + "\nimport json\nprint(json.dumps(answer))\n"
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          env=env, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.splitlines()[-1])


REPORT = f"""
import os, sys
answer = {{"heavy": [m for m in {HEAVY!r} if m in sys.modules],
          "numba_cache_dir": os.environ.get("NUMBA_CACHE_DIR")}}
"""


@pytest.mark.parametrize("module", ["subtrace", "subtrace.cli"])
def test_import_loads_nothing_heavy_and_sets_no_environment(module):
    answer = _fresh(f"import {module}\n" + REPORT)
    assert answer == {"heavy": [], "numba_cache_dir": None}


@pytest.mark.parametrize("flag", ["--help", "--version"])
def test_help_and_version_parse_without_heavy_modules(flag):
    code = f"""
import contextlib, io
from subtrace.cli import main
with contextlib.redirect_stdout(io.StringIO()) as out:
    code = main([{flag!r}])
""" + REPORT + "answer['code'] = code\nanswer['out'] = out.getvalue()\n"
    answer = _fresh(code)
    assert answer["code"] == 0 and answer["heavy"] == [] and answer["numba_cache_dir"] is None
    assert ("usage: subtrace" in answer["out"]) if flag == "--help" else (
        answer["out"].strip() == f"subtrace {subtrace.__version__}")


def test_public_names_resolve_lazily():
    """Every name of ``subtrace.__all__`` resolves (``sweep`` to the callable package)."""
    code = """
import subtrace
answer = {"missing": [n for n in subtrace.__all__ if getattr(subtrace, n, None) is None],
          "sweep_callable": callable(subtrace.sweep)}
"""
    assert _fresh(code) == {"missing": [], "sweep_callable": True}


def test_sweep_package_loads_numpy_only():
    """``from subtrace.sweep import PeakMemory, format_table`` (benchmarks use them) loads
    neither Numba nor OpenImageIO nor matplotlib: the sweep imports those when it runs."""
    answer = _fresh("from subtrace.sweep import PeakMemory, format_table\n" + REPORT)
    assert answer == {"heavy": ["numpy"], "numba_cache_dir": None}


def test_a_render_to_exr_alone_loads_no_openimageio(tmp_path):
    """``subtrace render`` of an untextured cage to an EXR file writes it through OpenEXR:
    OpenImageIO (about 20 MB of the process and 50 ms to import) loads only where a picture
    is written or an image read; with ``--png`` it does, and the picture is there."""
    code = f"""
import contextlib, io, sys
from subtrace.cli import main
with contextlib.redirect_stderr(io.StringIO()):
    code = main(["render", {str(CUBE)!r}, "--width", "32", "--height", "18", "--quiet",
                 "-o", {str(tmp_path / "a.exr")!r}])
answer = {{"code": code, "oiio": "OpenImageIO" in sys.modules}}
with contextlib.redirect_stderr(io.StringIO()):
    answer["png_code"] = main(["render", {str(CUBE)!r}, "--width", "32", "--height", "18",
                               "--quiet", "--png", "-o", {str(tmp_path / "b.exr")!r}])
answer["png_oiio"] = "OpenImageIO" in sys.modules
"""
    answer = _fresh(code)
    assert answer == {"code": 0, "oiio": False, "png_code": 0, "png_oiio": True}
    assert (tmp_path / "a.exr").stat().st_size > 0 and (tmp_path / "b.png").stat().st_size > 0
