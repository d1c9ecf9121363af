"""Where the tests find their data (the real meshes of ``models/``, the OpenSubdiv shapes and
reference results of ``tests/oracle/``, both in the repository), and small scene builders
shared by the renderer's tests."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import subtrace
from subtrace.io.scene import scene_from_dict

REPO = Path(__file__).resolve().parents[1]
MODELS = REPO / "models"
ORACLE = REPO / "tests" / "oracle"
SHAPES = ORACLE / "shapes"


def load_shape(name):
    """An OpenSubdiv regression shape's cage."""
    return subtrace.load_cage(SHAPES / f"{name}.obj")


def small_scene(meshes, eye, target, width=64, height=48, fov=60.0, tolerance=1.0,
                colors=None):
    """A scene of ``meshes`` seen from ``eye`` towards ``target``, lit by the headlight
    alone on black, without a ground (the geometry's tests need no more)."""
    objects = [{"mesh": str(m)} for m in meshes]
    for o, c in zip(objects, colors or []):
        o["color"] = c
    return scene_from_dict(
        {
            "object": objects,
            "camera": {"eye": list(eye), "target": list(target), "fov": fov, "width": width,
                       "height": height},
            "render": {"tolerance": tolerance, "background": [0.0, 0.0, 0.0],
                       "headlight_intensity": 1.0},
            "light": [],
            "ground": False,
        }
    )


# The start of a program for :func:`run_fresh`: from then on the list ``compiled`` receives
# the name (``module.qualname``) of every function Numba compiles (not what it loads)
COMPILE_LISTENER = """
from numba.core import event
compiled = []


class _Compiles(event.Listener):
    def on_start(self, ev):
        func = getattr(ev.data.get("dispatcher"), "py_func", None)
        compiled.append(getattr(func, "__module__", "") + "." + getattr(func, "__qualname__", "?"))

    def on_end(self, ev):
        pass


event.register("numba:compile", _Compiles())
"""


def run_fresh(code, *args, cache):
    """Run the Python program ``code`` with ``args`` in a fresh process whose kernel cache is
    the folder ``cache``; its standard output (the test fails with its errors if it fails)."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(SUBTRACE_CACHE_DIR=str(cache), PYTHONDONTWRITEBYTECODE="1")
    proc = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                          env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def error_without_root_powers(code):
    """The standard output of the Python program ``code`` (which prints the error it
    expects) run in a fresh process as this root user without the capabilities that let
    root read and write any file (setpriv, util-linux); the test is skipped where setpriv
    is not installed."""
    setpriv = shutil.which("setpriv")
    if setpriv is None:
        pytest.skip("running as root without setpriv (util-linux): root reads and writes "
                    "any file")
    caps = "-dac_override,-dac_read_search"
    proc = subprocess.run([setpriv, f"--inh-caps={caps}", f"--bounding-set={caps}",
                           sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout
