"""Where the tests find the shared data (real meshes, OpenSubdiv shapes), and small scene
builders shared by the renderer's tests."""

from __future__ import annotations

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
    """A scene of ``meshes`` seen from ``eye`` towards ``target``."""
    objects = [{"mesh": str(m)} for m in meshes]
    for o, c in zip(objects, colors or []):
        o["color"] = c
    return scene_from_dict(
        {
            "object": objects,
            "camera": {"eye": list(eye), "target": list(target), "fov": fov, "width": width,
                       "height": height},
            "render": {"tolerance": tolerance},
        }
    )
