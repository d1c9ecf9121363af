"""Primary-ray acceleration by projection (``accel/projection.py``): conservative binning of
shells into image tiles, and the same images as the BVH traversal."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shared_data import MODELS

from subtrace.accel.projection import TILE, project_shells
from subtrace.io.scene import scene_from_dict
from subtrace.render import render_scene
from subtrace.trace.pools import candidate_lists
from subtrace.camera import Camera, camera_frame


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


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 40), st.integers(1, 30), st.booleans())
def test_candidate_rows_are_the_listed_tiles_pixels(seed, width, height, some_built):
    """The rounds' candidate lists have a row for each pixel of a tile that lists an unbuilt
    shell, and for no other: distinct rows, all of them used, none for a pixel of a tile
    that lists none, or built ones only (a tile's pixels beyond the image's edge keep their
    rows unused). A window's tiles (a run of whole tile rows) get the rows of its own."""
    rng = np.random.default_rng(seed)
    cam = Camera(eye=(0.0, 0.0, 0.0), target=(0.0, 1.0, 0.0), up=(0.0, 0.0, 1.0), fov_deg=60.0,
                 width=width, height=height)
    frame = camera_frame(cam)
    c = rng.normal(0, 1, (int(rng.integers(0, 6)), 3)) * (1.0, 0.2, 1.0) + (0.0, 4.0, 0.0)
    half = np.abs(rng.normal(0, 0.3, c.shape))
    tiles = project_shells(c - half, c + half, frame, width, height)
    unbuilt = rng.random(len(c)) < 0.5 if some_built else None
    per_row = -(-width // TILE)
    n_ty = -(-height // TILE)
    t0 = int(rng.integers(0, n_ty))  # a window of tile rows (maybe all)
    t1 = int(rng.integers(t0 + 1, n_ty + 1))
    window = tiles._replace(off=tiles.off[t0 * per_row:t1 * per_row + 1])
    for tl, first in ((tiles, 0), (window, t0 * per_row)):
        cands = candidate_lists(width * height, len(c), tl, unbuilt)
        listed = np.array([
            any(unbuilt is None or unbuilt[p]
                for p in tiles.items[tiles.off[k]:tiles.off[k + 1]])
            for k in range(first, first + len(tl.off) - 1)], bool)
        assert len(cands.t) == TILE * TILE * np.count_nonzero(listed) == len(cands.patch)
        assert np.all((cands.tile_row >= 0) == listed)
        rows = []
        for k in np.nonzero(listed)[0]:
            rows += [cands.tile_row[k] + a * TILE + b for a in range(TILE) for b in range(TILE)]
        assert sorted(rows) == list(range(len(cands.t)))
    assert len(candidate_lists(width * height).t) == width * height  # (the BVH's rays)


def _scene(mesh, eye, target, fov=50.0, width=72, height=54, tolerance=1.0):
    return scene_from_dict({
        "object": [{"mesh": str(mesh)}],
        "camera": {"eye": list(eye), "target": list(target), "fov": fov, "width": width,
                   "height": height},
        "render": {"tolerance": tolerance},
    })


CAMERAS = [
    ("spot_control_mesh.obj", (1.2, 0.6, 2.2), (0.0, 0.3, 0.0), 50.0),  # outside
    ("spot_control_mesh.obj", (0.0, 0.05, 0.2), (0.3, 0.15, 1.2), 120.0),  # inside
    ("spot_control_mesh.obj", (0.0, 0.3, 0.45), (0.0, 0.3, 3.0), 100.0),  # crossing the eye plane
    ("torus.obj", (0.3, 2.5, 0.4), (0.0, 0.0, 0.0), 60.0),
]


@pytest.mark.parametrize("mesh,eye,target,fov", CAMERAS)
def test_projection_and_bvh_give_the_same_image(mesh, eye, target, fov):
    scene = _scene(MODELS / mesh, eye, target, fov)
    a = render_scene(scene, accel="projection")
    b = render_scene(scene, accel="bvh")
    assert (a.channels["A"] > 0).any()
    for name in a.channels:
        assert np.array_equal(a.channels[name], b.channels[name], equal_nan=True), name


SCENES = sorted((Path(__file__).resolve().parents[1] / "scenes").glob("*.toml"))


def _same_image(scene):
    """Render with both methods; assert bit-identical channels; the projection's result."""
    a = render_scene(scene, accel="projection")
    b = render_scene(scene, accel="bvh")
    assert (a.accel, b.accel) == ("projection", "bvh")
    for name in a.channels:
        assert np.array_equal(a.channels[name], b.channels[name], equal_nan=True), name
    return a


@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.stem)
def test_every_scene_gives_the_same_image_with_both_methods(path):
    """Each shipped scene at 64x36 (its own camera, framing the object): same image, and
    the object is seen (an empty image would compare equal trivially)."""
    from subtrace.io.scene import apply_overrides, load_scene

    res = _same_image(apply_overrides(load_scene(path), width=64, height=36))
    assert (res.channels["A"] > 0).mean() > 0.02  # (the sword covers 2.4 %)


def _obj_vertices(path):
    with open(path) as f:
        return np.array([[float(x) for x in line.split()[1:4]] for line in f
                         if line.startswith("v ")])


# (mesh, seed): Catmull-Clark and Loop cages; eyes near the surface (inside shells, with
# the eye plane cutting the object) or inside the object, looking anywhere
RANDOM = [(m, s) for m in ("spot_control_mesh.obj", "spot_low_resolution.obj", "torus.obj")
          for s in range(4)]


@pytest.mark.parametrize("mesh,seed", RANDOM)
def test_random_cameras_in_and_around_objects(mesh, seed):
    """Random cameras whose eye sits at a cage vertex pushed a little in or out (seeds
    0-2) or near the centre of the object's box (seed 3), looking anywhere but away from
    the object: both methods give the same image, and on the scene's real shells every box
    a pixel's ray enters is in its tile; some shells straddle the eye plane."""
    from subtrace.accel.projection import project_shells
    from subtrace.patches.table import build_patch_table
    from subtrace.render import load_objects

    rng = np.random.default_rng(1000 + seed)
    verts = _obj_vertices(MODELS / mesh)
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    size = float(np.linalg.norm(hi - lo))
    centre = 0.5 * (lo + hi)
    if seed < 3:
        eye = verts[rng.integers(len(verts))] + rng.normal(0, 0.005 * size, 3)
    else:
        eye = centre + rng.normal(0, 0.02 * size, 3)
    view = rng.normal(0, 1, 3)
    view *= 1.0 if view @ (centre - eye) >= 0 else -1.0  # (not away from the object)
    target = eye + view
    fov = float(rng.uniform(40.0, 130.0))
    # (3 px: an eye at the surface refines the nearest patches to the deepest grids)
    scene = _scene(MODELS / mesh, eye, target, fov, width=40, height=30, tolerance=3.0)
    res = _same_image(scene)
    # conservative on the real shells, eye-plane crossings included
    table = build_patch_table(load_objects(scene))
    frame = camera_frame(res.camera)
    tiles = project_shells(table.shell_min, table.shell_max, frame, 40, 30)
    enters, _ = _entries(frame, 40, 30, table.shell_min, table.shell_max)
    for px in np.nonzero(enters.any(axis=1))[0]:
        row, col = divmod(int(px), 40)
        t = (row // TILE) * tiles.per_row + col // TILE
        listed = tiles.items[tiles.off[t]:tiles.off[t + 1]]
        assert np.isin(np.nonzero(enters[px])[0], listed).all()
    # the cases this test is for: shells straddling the eye plane (seen from this camera)
    normal = np.cross(frame[1], frame[2])
    normal *= np.sign(normal @ frame[3])
    corners = np.stack([np.where(np.array([(k >> a) & 1 for a in range(3)], bool),
                                 table.shell_max, table.shell_min) for k in range(8)], 1)
    side = (corners - frame[0]) @ normal
    assert ((side.min(axis=1) < 0) & (side.max(axis=1) > 0)).any()


def test_two_tasks_project_as_one(monkeypatch):
    """The projection split over two tasks (blocks of boxes each, counts per task) lists
    exactly what one task lists, for a few thousand boxes that land across the image."""
    from subtrace.runtime import threads as tasks
    from subtrace.accel import projection

    rng = np.random.default_rng(7)
    cam = Camera(eye=(0.0, -4.0, 0.5), target=(0.0, 0.0, 0.0), up=(0.0, 0.0, 1.0),
                 fov_deg=60.0, width=97, height=61)
    frame = camera_frame(cam)
    c = rng.normal(0, 1.5, (3000, 3))
    half = np.abs(rng.normal(0, 0.1, (3000, 3)))
    lo, hi = c - half, c + half
    tasks.set_threads(2)
    try:
        monkeypatch.setattr(projection, "_PARALLEL_MIN", 0)
        two = project_shells(lo, hi, frame, cam.width, cam.height)
        monkeypatch.setattr(projection, "_PARALLEL_MIN", 10**9)
        one = project_shells(lo, hi, frame, cam.width, cam.height)
    finally:
        tasks.set_threads(None)
    assert len(one.items) > 5 * len(lo)
    for a, b in zip(two, one):
        np.testing.assert_array_equal(a, b)
