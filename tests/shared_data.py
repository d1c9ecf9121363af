"""Where the tests find the shared data (real meshes, OpenSubdiv shapes), and small scene
builders shared by the renderer's tests."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

import subtrace
from subtrace.io.scene import scene_from_dict

SHARED = Path(__file__).resolve().parents[2] / "shared"
MODELS = SHARED / "models"
SHAPES = SHARED / "oracle" / "shapes"

needs_shared = pytest.mark.skipif(not MODELS.is_dir(), reason="../shared/models not present")


def load_shape(name):
    """An OpenSubdiv regression shape's cage (the test is skipped when it is absent)."""
    path = SHAPES / f"{name}.obj"
    if not path.exists():
        pytest.skip(f"{path} not present")
    return subtrace.load_cage(path)


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
