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
    from subtrace.cluster import run_jobs
    from subtrace.render import render_scene

    bad = tmp_path / "bad.obj"
    bad.write_text(CUBE)
    scene = scene_for_meshes([str(bad)])
    bad.write_text(CUBE + "f 1 2 99\n")
    with pytest.raises(SubtraceError) as local:
        render_scene(scene)
    with pytest.raises(SubtraceError) as remote:
        run_jobs(None, [(0, scene, str(tmp_path / "x.exr"), None)], None, None, None, 8,
                 None)
    assert str(remote.value) == str(local.value) and "bad.obj:" in str(remote.value)
    assert not (tmp_path / "x.exr").exists()


@pytest.fixture(scope="module")
def two_workers():
    """A LocalCluster of two worker processes (one thread each) and its client."""
    from distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                           dashboard_address=None)
    client = Client(cluster)
    yield client
    client.close()
    cluster.close()


def _scene(tmp_path):
    from subtrace.io.scene import apply_overrides

    cube = tmp_path / "cube.obj"
    cube.write_text(CUBE)
    return apply_overrides(scene_for_meshes([str(cube)]), width=40, height=30,
                           eye=(4.0, 2.0, 3.0), target=(0.0, 0.0, 0.0))


def test_tiles_on_two_workers_equal_the_local_render(tmp_path, two_workers):
    """Frames cut into tiles of 16 x 16 (6 tasks a frame, on two worker processes) and put
    together by a task each: every channel of every frame is the local render's, bit for
    bit, and no tile file is left."""
    from subtrace.frames import render_frames

    scene = _scene(tmp_path)
    local = render_frames(scene, str(tmp_path / "local.#.exr"), turntable=3)
    remote = render_frames(scene, str(tmp_path / "dask.#.exr"), turntable=3, tile=16,
                           dask=two_workers)
    assert [f.frame for f in remote] == [0, 1, 2]
    for f, g in zip(local, remote):
        a, _ = read_exr(f.path)
        b, head = read_exr(g.path)
        assert head["subtrace:tiles"] == 6
        for name in a:
            np.testing.assert_array_equal(a[name], b[name], err_msg=f"{g.path} {name}")
    assert not list(tmp_path.glob(".*.tile.npz")) and not list(tmp_path.glob(".*.tmp"))


def test_a_worker_killed_mid_job_is_survived(tmp_path, two_workers):
    """A worker process that dies as it starts a tile (a worker plugin kills it once, the
    first time a tile task starts executing, leaving a marker file) has the task run again
    elsewhere: the job completes and the frame is the local render's."""
    import os

    from distributed.diagnostics.plugin import WorkerPlugin

    from subtrace.frames import render_frames

    marker = str(tmp_path / "killed")

    class KillOnce(WorkerPlugin):
        name = "subtrace-kill-once"

        def transition(self, key, start, finish, **kwargs):
            if (finish == "executing" and str(key).startswith("subtrace-tile")
                    and not os.path.exists(marker)):
                open(marker, "w").close()
                os._exit(1)

    scene = _scene(tmp_path)
    local = render_frames(scene, str(tmp_path / "local.exr"))
    two_workers.register_plugin(KillOnce())
    try:
        remote = render_frames(scene, str(tmp_path / "dask.exr"), tile=16, dask=two_workers)
    finally:
        two_workers.unregister_worker_plugin("subtrace-kill-once")
    assert os.path.exists(marker)  # a worker did die
    a, _ = read_exr(local[0].path)
    b, _ = read_exr(remote[0].path)
    for name in a:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)


def test_command_on_a_scheduler_address_with_tiles_and_resume(tmp_path, two_workers, capsys):
    """``render --turntable 2 --tile 16 --dask ADDRESS``: the frames are the local ones;
    run again with --resume, every frame is left out and said so."""
    cube = tmp_path / "cube.obj"
    cube.write_text(CUBE)
    view = [str(cube), "--eye", "4", "2", "3", "--target", "0", "0", "0", "--width", "40",
            "--height", "30", "--turntable", "2"]
    address = two_workers.scheduler.address
    assert main(["render", *view, "-o", str(tmp_path / "local.#.exr"), "--quiet"]) == 0
    assert main(["render", *view, "-o", str(tmp_path / "dask.#.exr"), "--tile", "16",
                 "--dask", address, "--quiet"]) == 0
    for k in range(2):
        a, _ = read_exr(tmp_path / f"local.{k}.exr")
        b, _ = read_exr(tmp_path / f"dask.{k}.exr")
        for name in a:
            np.testing.assert_array_equal(a[name], b[name], err_msg=f"frame {k} {name}")
    capsys.readouterr()
    assert main(["render", *view, "-o", str(tmp_path / "dask.#.exr"), "--tile", "16",
                 "--dask", address, "--resume"]) == 0
    assert "--resume: 2 of 2 frames already there" in capsys.readouterr().out


def test_render_frames_gives_futures(tmp_path, two_workers):
    """With a Client and wait=False, render_frames returns a future per frame, each giving
    (output, preview, statistics) once its file is written."""
    from subtrace.frames import render_frames

    futures = render_frames(_scene(tmp_path), str(tmp_path / "f.#.exr"), turntable=2,
                            dask=two_workers, wait=False)
    assert len(futures) == 2
    done = [f.result() for f in futures]
    assert [d[0] for d in done] == [str(tmp_path / "f.0.exr"), str(tmp_path / "f.1.exr")]
    assert all(d[2]["pixels_covered"] > 0 for d in done)
    for out, _, _ in done:
        read_exr(out)


def test_a_failing_tile_stops_the_job_and_leaves_no_tile(tmp_path, two_workers):
    """A tiled frame whose cage is bad by the time the workers read it: the local render's
    one line, no frame, no tile file."""
    from subtrace.cluster import run_jobs

    bad = tmp_path / "bad.obj"
    bad.write_text(CUBE)
    scene = scene_for_meshes([str(bad)])
    bad.write_text(CUBE + "f 1 2 99\n")
    with pytest.raises(SubtraceError, match="bad.obj:"):
        run_jobs(two_workers, [(0, scene, str(tmp_path / "x.exr"), None)], None, 16, None,
                 8, None)
    assert not list(tmp_path.glob("x.exr")) and not list(tmp_path.glob(".*.tile.npz"))
