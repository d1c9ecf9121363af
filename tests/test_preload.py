"""The render command's kernels read ahead (subtrace.startup.preload): what a render asks
for is remembered per kind of render, read from the cache on a thread of its own by the next
render of that kind, handed over when the render asks, never compiled, and forgotten when no
longer asked for; the images are the same bit for bit."""

from __future__ import annotations

import json
import os
import pickle
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from shared_data import COMPILE_LISTENER, MODELS
from subtrace.io.scene import Light, load_scene
from subtrace.startup import preload

pytest.importorskip("OpenImageIO")
import OpenImageIO as oiio  # noqa: E402

# a render command in a fresh process (its own: the loader trimmed, kernels read ahead),
# reporting what the read-ahead did
_PROBE = COMPILE_LISTENER + r"""
import json, sys
from subtrace.startup import preload

seen = {}
loading = preload.loading


def watched(key):
    seen["key"] = key
    return watching(loading(key))


class watching:
    def __init__(self, block):
        self.block = block

    def __enter__(self):
        self.loader = self.block.__enter__()
        return self.loader

    def __exit__(self, *exc):
        self.loader._thread.join()  # (what it read, before the manifest is stored)
        seen["left"] = len(preload._READ_AHEAD)
        seen["read"] = self.loader.read
        seen["items"] = len(self.loader.items or [])
        return self.block.__exit__(*exc)


preload.loading = watched
from subtrace.cli.main import main

code = main(["render", *sys.argv[1:], "--width", "64", "--height", "48", "--quiet"],
            own_process=True)
seen.update(code=code, compiled=compiled, path=str(preload._manifest_path(seen["key"])),
            loaded=[q for _, q, _ in preload.LOADED])
print(json.dumps(seen))
"""


def _command(*args):
    proc = subprocess.run([sys.executable, "-c", _PROBE, *map(str, args)],
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["code"] == 0
    return out


def _pixels(path):
    inp = oiio.ImageInput.open(str(path))
    try:
        return inp.read_image(format="float")
    finally:
        inp.close()


def test_render_key_follows_what_changes_the_kernels(tmp_path):
    """The key of a kind of render changes with the cages and the passes, not with the
    camera, the colours or the tolerance."""
    from dataclasses import replace

    scene = load_scene(Path(__file__).resolve().parents[1] / "scenes" / "spot.toml")
    key = preload.render_key(scene, "projection")
    same = [
        replace(scene, render=replace(scene.render, tolerance_px=0.25,
                                      background=(1.0, 0.0, 0.0))),
        replace(scene, camera=replace(scene.camera, fov_deg=12.0, width=99)),
        replace(scene, objects=tuple(replace(o, color=(0.1, 0.2, 0.3))
                                     for o in scene.objects)),
    ]
    assert all(preload.render_key(s, "projection") == key for s in same)
    other = [
        replace(scene, objects=tuple(replace(o, mesh=str(tmp_path / "other.obj"))
                                     for o in scene.objects)),
        replace(scene, objects=tuple(replace(o, scheme="loop") for o in scene.objects)),
        replace(scene, render=replace(scene.render, ao=0 if scene.render.ao else 4)),
        replace(scene, render=replace(scene.render,
                                      samples=1 if (scene.render.samples or 1) > 1 else 4)),
        replace(scene, render=replace(scene.render, shadows=not scene.render.shadows),
                lights=scene.lights or (Light(direction=(0.0, -1.0, 0.0)),)),
    ]
    keys = {preload.render_key(s, "projection") for s in other}
    assert key not in keys and len(keys) == len(other)
    assert preload.render_key(scene, "bvh") != key


def test_kernels_are_read_ahead_taken_and_forgotten(tmp_path):
    """A first render of a cage remembers the kernels it asked for, in order; the next
    render of the same kind in a fresh process reads every one ahead, takes every one, asks
    for the same and renders the same image bit for bit as without reading ahead. A
    manifest entry the render does not ask for (a kernel of a Loop render, read ahead all
    the same) is left unused and dropped, one absent from the cache (an unknown
    signature) is never compiled, and an unreadable manifest is ignored and written again."""
    cage = tmp_path / "spot.obj"
    shutil.copy(MODELS / "spot_control_mesh.obj", cage)
    loop_cage = tmp_path / "torus.obj"
    shutil.copy(MODELS / "torus.obj", loop_cage)
    manifest = Path(_command(cage, "-o", tmp_path / "warm.exr")["path"])
    manifest.unlink()  # (that render may have compiled some kernels: none read from a cache)
    first = _command(cage, "-o", tmp_path / "first.exr")
    assert Path(first["path"]) == manifest
    assert first["items"] == 0 and first["read"] == 0  # (nothing remembered yet)
    assert "_trace_task" in first["loaded"] and "_shade_task" in first["loaded"]
    items = pickle.loads(manifest.read_bytes())
    assert [q for _, q, _ in items] == first["loaded"]

    again = _command(cage, "-o", tmp_path / "again.exr")
    assert again["path"] == first["path"]
    assert again["items"] == again["read"] == len(items)  # every kernel read ahead ...
    assert again["left"] == 0  # ... and taken
    assert again["loaded"] == first["loaded"] and again["compiled"] == []
    assert pickle.loads(manifest.read_bytes()) == items
    plain = subprocess.run(
        [sys.executable, "-m", "subtrace.cli", "render", str(cage), "--width", "64",
         "--height", "48", "--quiet", "-o", str(tmp_path / "plain.exr")],
        env={**os.environ, "SUBTRACE_NO_PRELOAD": "1"}, capture_output=True, text=True,
        timeout=900)
    assert plain.returncode == 0, plain.stderr
    for name in ("first", "again"):
        np.testing.assert_array_equal(_pixels(tmp_path / f"{name}.exr"),
                                      _pixels(tmp_path / "plain.exr"))

    # a Loop render's own kernel, and an entry of a signature no cache holds
    loop = _command(loop_cage, "--scheme", "loop", "-o", tmp_path / "loop.exr")
    loop_items = pickle.loads(Path(loop["path"]).read_bytes())
    extra = next(i for i in loop_items if i[1] not in first["loaded"])
    module, qualname, sig = items[0]
    unknown = (module, qualname, sig + sig[:1])
    manifest.write_bytes(pickle.dumps(items + [extra, unknown]))
    stale = _command(cage, "-o", tmp_path / "stale.exr")
    assert stale["items"] == len(items) + 2 and stale["read"] == len(items) + 1
    assert stale["left"] == 1 and stale["compiled"] == []  # (the Loop kernel, untaken)
    assert pickle.loads(manifest.read_bytes()) == items
    np.testing.assert_array_equal(_pixels(tmp_path / "stale.exr"),
                                  _pixels(tmp_path / "plain.exr"))

    manifest.write_bytes(b"not a manifest")
    junk = _command(cage, "-o", tmp_path / "junk.exr")
    assert junk["items"] == 0 and junk["loaded"] == first["loaded"]
    assert pickle.loads(manifest.read_bytes()) == items
