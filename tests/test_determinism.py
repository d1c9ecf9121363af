"""Determinism (design invariant 6, issue 8): the same scene renders bit-identically, every
channel, with 1 and 2 threads and across runs (Catmull-Clark and Loop scenes, ambient
occlusion, NURBS beside a Loop cage)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from subtrace.io.scene import apply_overrides, load_scene
from subtrace.render import render_scene

SCENES = Path(__file__).resolve().parent.parent / "scenes"


def render(scene, threads):
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (creases.toml's cage warns about an unused tag)
        return render_scene(scene, threads=threads)


def channels(scene, threads):
    return render(scene, threads).channels


def assert_identical(a, b):
    assert a.keys() == b.keys()
    for name in a:
        # bit for bit (NaN == NaN: the same bits where a pixel has no hit)
        assert a[name].tobytes() == b[name].tobytes(), name


@pytest.mark.parametrize("name", ["spot", "spot_loop", "creases", "torus_loop", "spot_ao",
                                  "nurbs_mixed"])
def test_same_image_whatever_the_threads_and_the_run(name):
    scene = apply_overrides(load_scene(SCENES / f"{name}.toml"), width="96", height="64")
    one = channels(scene, 1)
    two = channels(scene, 2)
    again = channels(scene, 2)
    assert np.count_nonzero(one["A"]) > 500  # the object is in the picture
    assert_identical(one, two)
    assert_identical(two, again)


def test_hard_surface_cage_the_same_whatever_the_threads(tmp_path):
    """A hard-surface cage (``shared_data.lathe_cage``: creases of sharpness 6 to 8 beside
    the poles' extraordinary vertices, a crease junction and crease ends) lit by a sun with
    shadows, 4 samples a pixel: every channel the same with 1 and 2 threads."""
    from shared_data import lathe_cage

    from subtrace.io.scene import scene_from_dict

    mesh = lathe_cage(tmp_path / "lathe.obj")
    scene = scene_from_dict({
        "object": [{"mesh": str(mesh)}],
        "camera": {"eye": [2.6, 2.4, 3.2], "target": [0.0, 0.9, 0.0], "fov": 40.0,
                   "width": 160, "height": 120},
        "render": {"tolerance": 0.5, "samples": 4, "shadows": True},
        "light": [{"direction": [-0.4, -1.0, -0.3], "intensity": 2.0}],
    })
    one = channels(scene, 1)
    two = channels(scene, 2)
    assert np.count_nonzero(one["A"]) > 3000  # (of 19,200 pixels)
    assert_identical(one, two)


@pytest.mark.parametrize("name", ["spot", "creases", "torus_loop"])
def test_counts_whatever_the_threads_and_the_run(name):
    """Micro-triangles and the other counts of the header are the same with 1 and 2 threads
    and across runs: each chunk of rays has a memo of its own, so a chunk counts the same
    cells on any thread (geometry/prims.memo_restart). Full resolution, so that rays of one
    patch land in several chunks and the threads share patches (the memos must not run
    out: the count would then include cells evaluated per ray)."""
    scene = load_scene(SCENES / f"{name}.toml")
    runs = [render(scene, t).stats for t in (1, 2, 2)]
    assert all(st.memo_full == 0 for st in runs)
    keys = ("micro_triangles", "patches_refined", "pieces", "pixels_covered", "max_level")
    first = {k: getattr(runs[0], k) for k in keys}
    assert first["micro_triangles"] > 0
    for st in runs[1:]:
        assert {k: getattr(st, k) for k in keys} == first


@settings(max_examples=60, deadline=None)
@given(n_items=st.integers(1, 120), chunk=st.integers(1, 6), threads=st.integers(1, 4),
       delays=st.lists(st.sampled_from([0.0, 0.0, 0.0005]), min_size=1, max_size=8))
def test_chunks_are_the_same_on_any_number_of_threads(n_items, chunk, threads, delays):
    """run_chunks hands out the chunks [k chunk, (k+1) chunk) whatever the threads and
    whoever steals from whom (uneven work, made by sleeping): what a chunk of rays shares
    (its memo) and counts is then the same on any thread."""
    import threading
    import time

    from subtrace.runtime.threads import run_chunks

    seen, lock = [], threading.Lock()

    def work(t, a, b):
        time.sleep(delays[a % len(delays)])
        with lock:
            seen.append((a, b))

    run_chunks(work, n_items, chunk, n=threads)
    expected = [(a, min(a + chunk, n_items)) for a in range(0, n_items, chunk)]
    assert sorted(seen) == expected
