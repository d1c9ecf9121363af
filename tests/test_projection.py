"""Primary-ray acceleration by projection (``accel/projection.py``): conservative binning of
shells into image tiles, and the same images as the BVH traversal."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from subtrace.accel.projection import TILE, project_shells
from subtrace.io.scene import scene_from_dict
from subtrace.render import render_scene
from subtrace.trace.camera import Camera, camera_frame

MODELS = Path(__file__).resolve().parents[2] / "shared" / "models"


def _entries(frame, width, height, lo, hi):
    """(pixels, boxes) bool: whether the ray of each pixel enters each box (t >= 0), by the
    slab test in plain numpy; and the entry distances."""
    rows, cols = np.divmod(np.arange(width * height), width)
    d = frame[3] + cols[:, None] * frame[1] + rows[:, None] * frame[2]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        t0 = (lo[None] - frame[0]) * inv[:, None]
        t1 = (hi[None] - frame[0]) * inv[:, None]
    near = np.maximum(np.nanmax(np.minimum(t0, t1), axis=2), 0.0)
    far = np.nanmin(np.maximum(t0, t1), axis=2)
    return near <= far, near


@settings(max_examples=80, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 40), st.integers(1, 30),
       st.floats(20.0, 150.0))
def test_every_box_a_ray_enters_is_in_its_tile(seed, width, height, fov):
    """Conservative: each box a pixel's ray enters is listed in the pixel's tile, the lists
    run nearest box first, and a box's key is at most any ray's entry distance. Boxes lie
    in front of, around and behind the eye, some containing it."""
    rng = np.random.default_rng(seed)
    eye = rng.normal(0, 1, 3)
    target = eye + rng.normal(0, 1, 3)
    cam = Camera(eye=tuple(eye), target=tuple(target), up=(0.0, 0.0, 1.0), fov_deg=fov, width=width,
                 height=height)
    frame = camera_frame(cam)
    c = eye + rng.normal(0, 2.5, (60, 3))
    c[:5] = eye + rng.normal(0, 0.05, (5, 3))  # around the eye
    half = np.abs(rng.normal(0, 0.4, (60, 3)))
    half[rng.random(60) < 0.2, rng.integers(0, 3)] = 0.0  # flat boxes too
    lo, hi = c - half, c + half
    tiles = project_shells(lo, hi, frame, width, height)
    enters, near = _entries(frame, width, height, lo, hi)
    per_row = -(-width // TILE)
    for px in range(width * height):
        row, col = divmod(px, width)
        t = (row // TILE) * per_row + col // TILE
        listed = tiles.items[tiles.off[t]:tiles.off[t + 1]]
        assert set(np.nonzero(enters[px])[0]) <= set(listed.tolist())
        assert np.all(np.diff(tiles.key[listed]) >= 0)
    hit = enters & np.isfinite(near)
    assert np.all((tiles.key[None].repeat(len(near), 0) <= near * (1 + 1e-12))[hit])


def _scene(mesh, eye, target, fov=50.0, width=72, height=54):
    return scene_from_dict({
        "object": [{"mesh": str(mesh)}],
        "camera": {"eye": list(eye), "target": list(target), "fov": fov, "width": width,
                   "height": height},
        "render": {"tolerance": 1.0},
    })


CAMERAS = [
    ("spot_control_mesh.obj", (1.2, 0.6, 2.2), (0.0, 0.3, 0.0), 50.0),  # outside
    ("spot_control_mesh.obj", (0.0, 0.05, 0.2), (0.3, 0.15, 1.2), 120.0),  # inside
    ("spot_control_mesh.obj", (0.0, 0.3, 0.45), (0.0, 0.3, 3.0), 100.0),  # crossing the eye plane
    ("torus.obj", (0.3, 2.5, 0.4), (0.0, 0.0, 0.0), 60.0),
]


@pytest.mark.skipif(not MODELS.is_dir(), reason="../shared/models not present")
@pytest.mark.parametrize("mesh,eye,target,fov", CAMERAS)
def test_projection_and_bvh_give_the_same_image(mesh, eye, target, fov):
    scene = _scene(MODELS / mesh, eye, target, fov)
    a = render_scene(scene, accel="projection")
    b = render_scene(scene, accel="bvh")
    assert (a.channels["A"] > 0).any()
    for name in a.channels:
        assert np.array_equal(a.channels[name], b.channels[name], equal_nan=True), name
