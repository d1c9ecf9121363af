"""``subtrace render`` on the command line: outputs, options, progress, bad options."""

from __future__ import annotations

import numpy as np
import pytest
from shared_data import MODELS, needs_shared


@needs_shared
def test_render_cli_writes_exr(tmp_path):
    from subtrace.cli import main
    from subtrace.io.exr import read_exr

    out = tmp_path / "spot.exr"
    rc = main(["render", str(MODELS / "spot_control_mesh.obj"), "-o", str(out), "--width",
               "64", "--height", "48", "--png", "--quiet"])
    assert rc == 0
    ch, attrs = read_exr(out)
    for name in ["R", "G", "B", "A", "Z", "N.X", "N.Y", "N.Z", "level", "patch_id",
                 "object_id"]:
        assert name in ch
    assert (tmp_path / "spot.png").exists()
    miss = ch["A"] == 0
    assert np.all(np.isinf(ch["Z"][miss])) and np.all(np.isfinite(ch["Z"][~miss]))
    assert np.all(ch["object_id"][~miss] == 0)
    for key in ["subtrace:time_total", "subtrace:time_refine", "subtrace:time_trace",
                "subtrace:time_load", "subtrace:scheme", "subtrace:camera",
                "subtrace:patches_refined", "subtrace:micro_triangles"]:
        assert key in attrs, key
    assert attrs["subtrace:scheme"] == "catmark"


def test_render_cli_accel_chooses_the_traversal(tmp_path, capsys):
    """``--accel bvh`` renders the same image as the default projection and says so in the
    header; an unknown method is a usage error (exit 2, nothing written)."""
    from subtrace.cli import main
    from subtrace.io.exr import read_exr

    args = ["render", str(MODELS / "spot_control_mesh.obj"), "--width", "40", "--height", "30",
            "--quiet"]
    assert main(args + ["-o", str(tmp_path / "p.exr")]) == 0
    assert main(args + ["-o", str(tmp_path / "b.exr"), "--accel", "bvh"]) == 0
    (p, pa), (b, ba) = read_exr(tmp_path / "p.exr"), read_exr(tmp_path / "b.exr")
    assert (pa["subtrace:accel"], ba["subtrace:accel"]) == ("projection", "bvh")
    assert all(np.array_equal(p[k], b[k], equal_nan=True) for k in p)
    assert main(args + ["-o", str(tmp_path / "x.exr"), "--accel", "kd"]) == 2
    assert "invalid choice" in capsys.readouterr().err
    assert not (tmp_path / "x.exr").exists()


def test_render_cli_shows_no_progress_bar_off_a_terminal(tmp_path, capsys):
    from subtrace.cli import main

    assert main(["render", "-o", str(tmp_path / "x.exr"), "--width", "16", "--height",
                 "12"]) == 0
    err = capsys.readouterr().err
    assert "\r[" not in err and "#" not in err


def test_render_cli_bad_output_folder(tmp_path, capsys):
    from subtrace.cli import main

    out = tmp_path / "missing" / "x.exr"
    rc = main(["render", "-o", str(out), "--width", "16", "--height", "8", "--quiet"])
    assert rc == 2
    assert "Traceback" not in capsys.readouterr().err
    assert not out.exists()


def test_render_cli_default_scene_writes_to_working_directory(tmp_path, monkeypatch):
    from subtrace.cli import main
    from subtrace.io.exr import read_exr

    monkeypatch.chdir(tmp_path)
    assert main(["render", "--width", "24", "--height", "16", "--quiet"]) == 0
    ch, attrs = read_exr(tmp_path / "render.exr")
    assert ch["A"].shape == (16, 24) and np.count_nonzero(ch["A"]) > 0
    assert "spot_control_mesh.obj" in attrs["subtrace:meshes"]


@pytest.mark.parametrize("threads", ["0", "9999"])
def test_render_cli_bad_thread_count(tmp_path, capsys, threads):
    from subtrace.cli import main

    out = tmp_path / "x.exr"
    rc = main(["render", "-o", str(out), "--width", "8", "--height", "8", "--threads", threads])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.count("\n") == 1 and "--threads" in err and "Traceback" not in err
    assert not out.exists() and list(tmp_path.iterdir()) == []
