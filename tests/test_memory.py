"""The memory budget (issue 8): ``--max-memory`` / ``[render] max_memory``.

Refinement whose estimate (``patches.criterion.memory_estimate``) exceeds the budget is capped
at a coarser depth with one warning line; an image too large for the budget is one clear
error; bad values are one clear error. The estimate against measured peaks:
``benchmarks/memory.py``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from subtrace.cli import main
from subtrace.io.exr import read_exr

ROOT = Path(__file__).resolve().parent.parent
SPOT_LOOP = ROOT / "scenes" / "spot_loop.toml"
CUBE = Path(__file__).resolve().parent / "bad_inputs" / "cube.obj"
SMALL = ["--width", "160", "--height", "120", "--quiet"]


def render(capsys, tmp_path, *argv, name="r.exr"):
    out = tmp_path / name
    code = main(["render", *map(str, argv), "-o", str(out), *SMALL])
    _, err = capsys.readouterr()
    return code, err, out


def levels(path):
    ch, _ = read_exr(str(path))
    covered = ch["A"] > 0
    return ch["level"][covered]


# a budget that Spot's Loop cage at 160x120 fits only coarser: the estimate prices the
# isolation levels of its irregular triangles (its regular ones are nets split per ray,
# their splits kept within the memos) above the minimum (pixels, patches, two memos, and
# the projection's tile lists, which below about 36 MiB fall back to the BVH)
TIGHT = "44M"


def test_tiny_budget_caps_refinement_with_one_warning(capsys, tmp_path):
    code, err, full = render(capsys, tmp_path, SPOT_LOOP, name="full.exr")
    assert code == 0 and err == "", err  # the default budget: no warning
    code, err, capped = render(capsys, tmp_path, SPOT_LOOP, "--max-memory", TIGHT,
                               name="capped.exr")
    assert code == 0, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"subtrace: warning: memory budget {TIGHT[:-1]} MiB: "
                               "refinement capped")
    assert "--max-memory" in lines[0]
    lv_full, lv_capped = levels(full), levels(capped)
    assert lv_capped.max() < lv_full.max()
    # (at least three quarters of a level coarser on average: the tightest budget that
    # still fits the unrefined patches leaves the nearest ones a level or two)
    assert lv_capped.mean() < lv_full.mean() - 0.75
    # the picture is the same surface, only coarser: coverage nearly identical
    assert abs(len(lv_capped) - len(lv_full)) <= 0.02 * len(lv_full)


def test_budget_in_the_scene_file(capsys, tmp_path):
    text = SPOT_LOOP.read_text().replace("[render]", f'[render]\nmax_memory = "{TIGHT}"')
    text = text.replace('"../models/', '"' + (ROOT / "models").as_posix() + "/")
    scene = tmp_path / "s.toml"
    scene.write_text(text)
    code, err, _ = render(capsys, tmp_path, scene)
    assert code == 0 and f"subtrace: warning: memory budget {TIGHT[:-1]} MiB" in err, err
    # the option overrides the file
    code, err, _ = render(capsys, tmp_path, scene, "--max-memory", "2G", name="b.exr")
    assert code == 0 and err == "", err


@pytest.mark.parametrize("value, words", [
    ("0", "at least 1M, got '0'"), ("-5", "at least 1M, got '-5'"),
    ("abc", "expected a size such as 500M or 2G"), ("2X", "expected a size"),
    ("0.5", "at least 1M"), ("nan", "expected a size"),
])
def test_bad_budget_values(capsys, tmp_path, value, words):
    code, err, out = render(capsys, tmp_path, CUBE, f"--max-memory={value}")
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("subtrace: error: --max-memory: "), err
    assert words in lines[0]
    assert not out.exists()


def test_units():
    from subtrace.io.scene import parse_memory

    assert parse_memory("2G") == 2 << 30
    assert parse_memory("500M") == 500 << 20
    assert parse_memory("500MiB") == 500 << 20
    assert parse_memory("2048k") == 2 << 20
    assert parse_memory(512) == 512 << 20  # a bare number is MiB
    assert parse_memory("1.5g") == 3 << 29


def test_image_too_large_for_the_budget(capsys, tmp_path):
    out = tmp_path / "r.exr"
    code = main(["render", str(CUBE), "-o", str(out), "--width", "32768", "--height", "32768",
                 "--quiet"])
    _, err = capsys.readouterr()
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("subtrace: error: a 32768x32768 render"), err
    assert "raise --max-memory" in lines[0]
    assert list(tmp_path.iterdir()) == []


def test_sweep_takes_the_budget(capsys, tmp_path):
    code = main(["sweep", str(SPOT_LOOP), "--tolerances", "2", "--reference-tolerance", "1",
                 "-o", str(tmp_path / "sw"), "--width", "80", "--height", "60", "--quiet",
                 "--max-memory", "25M"])
    _, err = capsys.readouterr()
    assert code == 0, err
    # (at 80x60 the refinement fits; the tile lists do not, and say so)
    assert "subtrace: warning: memory budget 25 MiB" in err


def test_estimate_grows_with_depth_and_cap_fits():
    from subtrace.mesh.cage import load_cage
    from subtrace.io.scene import load_scene
    from subtrace.patches.criterion import depth_cap, memory_estimate
    from subtrace.patches.table import build_patch_table
    from subtrace.trace.budget import isolated_patches

    scene = load_scene(SPOT_LOOP)
    table = build_patch_table([load_cage(o.mesh, scheme=o.scheme) for o in scene.objects])
    iso = isolated_patches(table)  # Spot's irregular Loop triangles
    assert 0 < iso.sum() < table.n_patches
    est = [memory_estimate(table, np.full(table.n_patches, d, np.int32), 1000, iso)
           for d in range(6)]
    assert all(b > a for a, b in zip(est, est[1:]))
    depths = np.full(table.n_patches, 5, np.int32)
    assert depth_cap(table, depths, 1000, est[5], iso) is None
    assert depth_cap(table, depths, 1000, est[5] - 1, iso) == 4
    assert depth_cap(table, depths, 1000, est[2], iso) == 2
    assert depth_cap(table, depths, 1000, est[0] - 1, iso) == -1


def test_tile_lists_over_the_budget_fall_back_to_the_bvh(capsys, tmp_path):
    """With the eye inside Spot many shells reach the eye plane and sit in every tile: a
    budget that fits the refinement but not those lists renders through the BVH, with one
    warning, the same image, and ``subtrace:accel`` saying so."""
    from subtrace import config
    from subtrace.runtime import threads as tasks
    from subtrace.accel.projection import project_shells, tiles_bytes
    from subtrace.io.scene import scene_from_dict
    from subtrace.patches.criterion import choose_depths, memory_estimate
    from subtrace.render import load_objects, table_in_view
    from subtrace.camera import camera_frame

    spot = ROOT / "models" / "spot_control_mesh.obj"
    argv = [spot, "--eye", "0", "0.05", "0.2", "--target", "0.3", "0.15", "1.2", "--fov",
            "120", "--no-shadows"]  # (shadows would keep more patches: a bigger table)
    code, err, free = render(capsys, tmp_path, *argv, name="free.exr")
    assert code == 0 and err == "", err
    # the budget: the refinement's estimate and the memos' minimum, plus half the lists
    scene = scene_from_dict({"object": [{"mesh": str(spot)}],
                             "camera": {"eye": [0, 0.05, 0.2], "target": [0.3, 0.15, 1.2],
                                        "fov": 120, "width": 160, "height": 120}})
    cages = load_objects(scene)
    camera = scene.make_camera()
    table, _ = table_in_view(cages, camera)  # as the render's
    frame = camera_frame(camera)
    shells = table.shell_min.copy(), table.shell_max.copy()
    depths = choose_depths(table, frame[0], scene.render.tolerance_rad(camera),
                           8, {}, shells)
    tiles = project_shells(*shells, frame, 160, 120)
    lists = tiles_bytes(len(tiles.items), len(tiles.off) - 1)
    need = (memory_estimate(table, depths, 160 * 120)
            + config.MEMORY_MEMO_MIN_BYTES * tasks.thread_count())
    assert lists > 1 << 19
    budget = (need + lists // 2) // 1024
    code, err, tight = render(capsys, tmp_path, *argv, "--max-memory", f"{budget}K",
                              name="tight.exr")
    assert code == 0, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "tile lists would not fit" in lines[0], err
    a, _ = read_exr(str(free))
    b, attrs = read_exr(str(tight))
    assert attrs["subtrace:accel"] == "bvh"
    for name in a:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)
