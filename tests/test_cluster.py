"""Frames on a Dask cluster (cluster.py, ``render --turntable N --dask``): the same files as a
local render, and a task's bad input stops the job with the local render's one line."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("distributed", reason="dask[distributed] (subtrace[dask]) is not installed")

from subtrace.cli import main  # noqa: E402
from subtrace.errors import SubtraceError  # noqa: E402
from subtrace.io.exr import read_exr  # noqa: E402
from subtrace.io.scene import scene_for_meshes  # noqa: E402

CUBE = ("v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n"
        "f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 3 4 8 7\nf 2 3 7 6\nf 1 5 8 4\n")


def test_dask_frames_equal_local_frames(tmp_path, capsys):
    cube = tmp_path / "cube.obj"
    cube.write_text(CUBE)
    view = ["--eye", "4", "2", "3", "--target", "0", "0", "0", "--width", "40", "--height",
            "30", "--turntable", "3", "--quiet"]
    assert main(["render", str(cube), "-o", str(tmp_path / "local.#.exr"), *view]) == 0
    assert main(["render", str(cube), "-o", str(tmp_path / "dask.#.exr"), *view,
                 "--dask"]) == 0
    for k in range(3):
        a, _ = read_exr(tmp_path / f"local.{k}.exr")
        b, _ = read_exr(tmp_path / f"dask.{k}.exr")
        for name in a:
            np.testing.assert_array_equal(a[name], b[name], err_msg=f"frame {k} {name}")
    assert not list(tmp_path.glob(".*.tmp"))


def test_a_failing_task_stops_the_job_with_one_line(tmp_path):
    """A frame whose cage the worker cannot read (here: a file changed after the job was
    made) raises the error a local render raises, naming the file and line."""
    from subtrace.cluster import run_frames
    from subtrace.render import render_scene

    bad = tmp_path / "bad.obj"
    bad.write_text(CUBE)
    scene = scene_for_meshes([str(bad)])
    bad.write_text(CUBE + "f 1 2 99\n")
    with pytest.raises(SubtraceError) as local:
        render_scene(scene)
    with pytest.raises(SubtraceError) as remote:
        run_frames(None, [(scene, str(tmp_path / "x.exr"), None, None, 8)], None,
                   lambda *a: None)
    assert str(remote.value) == str(local.value) and "bad.obj:" in str(remote.value)
    assert not (tmp_path / "x.exr").exists()
