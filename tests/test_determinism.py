"""Determinism (design invariant 6, issue 8): the same scene renders bit-identically, every
channel, with 1 and 2 threads and across runs (Catmull-Clark and Loop scenes)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from subtrace.io.scene import apply_overrides, load_scene
from subtrace.render import render_scene

SCENES = Path(__file__).resolve().parent.parent / "scenes"


def channels(scene, threads):
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (creases.toml's cage warns about an unused tag)
        return render_scene(scene, threads=threads).channels


def assert_identical(a, b):
    assert a.keys() == b.keys()
    for name in a:
        # bit for bit (NaN == NaN: the same bits where a pixel has no hit)
        assert a[name].tobytes() == b[name].tobytes(), name


@pytest.mark.parametrize("name", ["spot", "spot_loop", "creases", "torus_loop"])
def test_same_image_whatever_the_threads_and_the_run(name):
    scene = apply_overrides(load_scene(SCENES / f"{name}.toml"), width="96", height="64")
    one = channels(scene, 1)
    two = channels(scene, 2)
    again = channels(scene, 2)
    assert np.count_nonzero(one["A"]) > 500  # the object is in the picture
    assert_identical(one, two)
    assert_identical(two, again)
