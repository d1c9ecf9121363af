"""Refinement depth: limited by floating point (config.PRECISION_BITS), not by a constant,
and every cap (precision, memory) recorded in the statistics / EXR header and said in
exactly one warning; the summary's deepest level is the level channel's maximum."""

from __future__ import annotations

import warnings

import numpy as np
from shared_data import MODELS, SHAPES, small_scene

from subtrace import config
from subtrace.errors import SubtraceWarning
from subtrace.io.scene import apply_overrides
from subtrace.render import render_scene, result_attributes

SPOT = MODELS / "spot_control_mesh.obj"
TORUS = MODELS / "torus.obj"
ICOSA = SHAPES / "loop_icosahedron.obj"


def _render(scene):
    """Render ``scene``; returns (result, the subtrace warnings' messages)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = render_scene(scene, threads=1)
    return res, [str(w.message) for w in caught if issubclass(w.category, SubtraceWarning)]


def _spot(tolerance, width=160, height=90):
    return small_scene([SPOT], (2.393, 1.306, -3.637), (0.0, 0.1091, 0.1916), width=width,
                       height=height, fov=30.0, tolerance=tolerance)


def _level_max(res):
    level = res.channels["level"]
    return int(level[res.channels["A"] > 0].max())


def test_finer_tolerance_refines_deeper_without_a_cap():
    """0.01 px asks for finer cells than 0.1 px: it is refined deeper (both were held at
    depth 8 by a constant, silently), and neither is capped nor warned about."""
    coarse, w_coarse = _render(_spot(0.1))
    fine, w_fine = _render(_spot(0.01))
    assert w_coarse == [] and w_fine == []
    for res in (coarse, fine):
        assert res.stats.depth_cap == -1 and res.stats.depth_cap_reason == "none"
        attrs = result_attributes(res, _spot(0.1))
        assert attrs["subtrace:depth_cap"] == -1
        assert attrs["subtrace:max_level"] == res.stats.max_level
        # the statistic and the header agree with the level channel
        assert res.stats.max_level == _level_max(res)
    assert fine.stats.max_depth > max(coarse.stats.max_depth, 8)
    assert _level_max(fine) > _level_max(coarse)


def test_summary_deepest_level_is_the_level_channel_maximum():
    """The line ``subtrace render`` prints names the deepest level of the image (the level
    channel counts the patch level L0 too, which the grid depth does not)."""
    from subtrace.cli.render import _summary

    res, _ = _render(_spot(1.0, 96, 54))
    deepest = _level_max(res)
    assert f"deepest level {deepest};" in _summary("x.exr", None, res, 0.0)
    # Spot's split n-gons sit at level 1: the channel is the grid depth plus L0
    assert res.stats.max_level == deepest


def test_precision_cap_on_an_absurd_tolerance_is_reported_once():
    """At 1e-12 px the tolerance asks for cells below what doubles resolve: refinement stops
    at the precision limit (at most PRECISION_BITS + 2), the render completes, and the cap
    is in the header with its reason and said in exactly one warning."""
    res, said = _render(_spot(1e-12, 96, 54))
    assert len(said) == 1 and "precision" in said[0], said
    st = res.stats
    assert st.depth_cap_reason == "precision"
    assert 20 < st.depth_cap <= config.PRECISION_BITS + 2
    assert st.pixels_covered > 0
    # the image's levels agree with the cap: grid depth (level - L0, L0 <= 1) never above it,
    # and reached
    level = _level_max(res)
    assert st.depth_cap <= level <= st.depth_cap + 1
    attrs = result_attributes(res, _spot(1e-12, 96, 54))
    assert attrs["subtrace:depth_cap"] == st.depth_cap
    assert attrs["subtrace:depth_cap_reason"] == "precision"


def test_irregular_loop_scene_refines_as_deep_as_its_tolerance_asks():
    """Irregular Loop triangles are isolated level by level along their irregular
    remainder, priced per level: at 0.001 px a 256 MiB budget holds the icosahedron (every
    corner of valence 5) to no cap, and it refines deeper than at 0.01 px, which refines
    deeper than at 0.1 px (no constant caps the depth)."""
    levels = []
    for tol in (0.1, 0.01, 0.001):
        scene = small_scene([ICOSA], (1.226, 4.085, 4.902), (0.0, 0.0, 0.0), width=96,
                            height=54, fov=30.0, tolerance=tol)
        res, said = _render(apply_overrides(scene, max_memory="256M"))
        assert said == [], said
        assert res.stats.depth_cap_reason == "none" and res.stats.depth_cap == -1
        levels.append(_level_max(res))
    assert levels[0] < levels[1] < levels[2], levels


def test_loop_scene_over_a_small_budget_is_capped_with_one_warning():
    """A budget too small for the isolation levels a tiny tolerance asks for caps them: one
    warning, reason "memory", and the image's levels are the cap's."""
    scene = small_scene([ICOSA], (1.226, 4.085, 4.902), (0.0, 0.0, 0.0), width=96, height=54,
                        fov=30.0, tolerance=0.001)
    res, said = _render(apply_overrides(scene, max_memory="12M"))
    assert len(said) == 1 and "memory budget 12 MiB" in said[0], said
    # the estimate it names is over the budget (the memos' minimum included)
    estimate = float(said[0].split("an estimated ")[1].split(" MiB")[0])
    assert estimate > 12
    assert res.stats.depth_cap_reason == "memory"
    assert 0 <= res.stats.depth_cap < 8
    # Loop patches are the cage's triangles (L0 = 0): the deepest level is the cap
    assert _level_max(res) == res.stats.depth_cap == res.stats.max_level


def test_regular_loop_patches_are_not_priced_as_grids():
    """Regular Loop triangles are Bezier nets split per ray, their splits kept within the
    threads' memos: the budget that holds the grids above does not cap the torus (every
    corner of valence 6), which refines deeper at the same tolerance."""
    scene = small_scene([TORUS], (1.226, 4.085, 4.902), (0.0, 0.0, 0.0), width=96, height=54,
                        fov=30.0, tolerance=0.001)
    res, said = _render(apply_overrides(scene, max_memory="256M"))
    assert not any("memory budget" in m for m in said), said
    assert "memory" not in res.stats.depth_cap_reason
    assert _level_max(res) >= 8


def test_precision_depths_follow_the_coordinates():
    """A patch's precision limit is PRECISION_BITS plus log2(extent / magnitude), bounded."""
    from types import SimpleNamespace

    from subtrace.patches.criterion import precision_depths

    lo = np.array([[0.0, 0.0, 0.0], [1e6, 0.0, 0.0], [0.0, 0.0, 0.0]])
    hi = np.array([[1.0, 1.0, 1.0], [1e6 + 1.0, 1.0, 1.0], [0.0, 0.0, 0.0]])
    table = SimpleNamespace(shell_min=lo, shell_max=hi)
    d = precision_depths(table, np.zeros(3))
    assert d[0] == config.PRECISION_BITS  # extent sqrt(3), magnitude 1
    assert d[1] == config.PRECISION_BITS - 20  # a unit patch at 1e6 ~ 2^20
    assert d[2] == 0  # no extent
    assert d.max() <= config.PRECISION_BITS + 2


def test_memory_estimate_prices_isolated_loop_patches_per_level():
    """An irregular Loop triangle is isolated one level at a time along its irregular
    remainder (patches/isolate_loop.py), so its estimate grows by the same amount per level
    (not 4^depth, as the retired whole grids did), plus the exact samples of its sides
    (2^depth a side); regular patches cost nothing per level."""
    from types import SimpleNamespace

    from subtrace import config
    from subtrace.patches.criterion import memory_estimate

    table = SimpleNamespace(is_quad=np.array([True, False, False]), regular=np.zeros(3, bool),
                            n_patches=3)
    isolated = np.array([True, True, False])  # an irregular quad, an irregular triangle
    est = [memory_estimate(table, np.full(3, d, np.int32), 100, isolated) for d in range(43)]
    # per level, both; and the triangle's exact side samples, 3 sides of 2^(d-1) + 1
    sides = [3 * (2 ** max(d - 1, 0) + 1) * config.MEMORY_BYTES_PER_SIDE_SAMPLE
             for d in range(43)]
    steps = np.diff(np.array(est) - np.array(sides))
    assert (steps == 2 * config.MEMORY_BYTES_PER_ISOLATED_LEVEL).all()
    assert est[42] > 2**48  # (depth 42 asks for 2^41 samples a side: the budget caps it)
    none = [memory_estimate(table, np.full(3, d, np.int32), 100, np.zeros(3, bool))
            for d in (0, 42)]
    assert none[0] == none[1]


def test_loop_patches_holding_the_eye_are_capped_with_one_warning(tmp_path):
    """From inside an open Loop box, the eye sits on the shells of the patches beside the
    nearest wall (no finite depth asks for their tolerance): they are held at
    config.LOOP_MAX_INSIDE_DEPTH, reason "size", said once; every ray still hits, and the
    patches whose shells the eye is outside are not held."""
    from test_isolate_loop import _open_box

    path = tmp_path / "open_box.obj"
    _open_box(path)
    scene = small_scene([path], (-0.75, 0.0, 0.45), (-1.0, 0.0, 0.45), fov=96.0, width=48,
                        height=36, tolerance=4.0)
    res, said = _render(scene)
    assert len(said) == 1 and f"at {config.LOOP_MAX_INSIDE_DEPTH} where the eye" in said[0]
    assert res.stats.depth_cap == config.LOOP_MAX_INSIDE_DEPTH
    assert res.stats.depth_cap_reason == "size"
    assert np.count_nonzero(res.channels["A"] == 0) == 0
    level = res.channels["level"]
    assert level.max() == config.LOOP_MAX_INSIDE_DEPTH  # the held patches, at the cap
    assert level.min() < 8  # the far walls at their own (finite) depth


def test_isolation_that_doubles_along_a_non_manifold_edge_is_capped_once(tmp_path,
                                                                         monkeypatch):
    """Three quads on one edge (a non-manifold edge, infinitely sharp, no level makes its
    patches regular) seen up close at a tiny tolerance: the isolation's frontier doubles at
    every level. It is stopped before it passes its limit (64 faces per patch and level, at
    least ISOLATION_MIN_FACES, here lowered to 4,096), the depth is capped
    for every patch at the last level within it, and one warning and the header say so
    ("isolation"). Before the limit a fuzzed 32x24 render of such a cage took all memory."""
    import subtrace.patches.criterion as criterion
    import subtrace.patches.isolate as iso

    book = tmp_path / "book.obj"
    book.write_text("v 0 0 0\nv 0 1 0\nv 1 0 0\nv 1 1 0\nv -1 0 0\nv -1 1 0\nv 0 0 1\n"
                    "v 0 1 1\nf 1 3 4 2\nf 1 2 6 5\nf 1 7 8 2\n")
    monkeypatch.setattr(config, "ISOLATION_MIN_FACES", 4096)
    calls = []
    real = iso.isolated_depths

    def counting(obj, faces, cap, *args):
        record = args[2] if len(args) > 2 and args[2] is not None else {}
        args = (*args[:2], record, *args[3:])
        try:
            out = real(obj, faces, cap, *args)
        except iso.IsolationTooLarge:
            calls.append(None)
            raise
        limit = max(4096, 64 * len(faces) * int(np.max(cap)))
        calls.append(([len(lv.start) for lv in record["levels"]], limit))
        return out

    monkeypatch.setattr(criterion, "isolated_depths", counting)
    scene = small_scene([book], (0.2, 0.5, 0.3), (0.0, 0.5, 0.0), width=32, height=24,
                        fov=40.0, tolerance=0.01)
    res, said = _render(scene)
    st = res.stats
    assert len(said) == 1 and "non-manifold edge" in said[0], said
    assert st.depth_cap_reason == "isolation" and 4 <= st.depth_cap < 13, st
    assert calls[0] is None and calls[-1] is not None  # stopped, then chosen within it
    kept, limit = calls[-1]
    assert sum(kept) <= limit and len(kept) == st.depth_cap
    assert np.all(np.diff(kept[2:]) > 0) and kept[-1] > 4 * kept[1]  # (it does double)
    attrs = result_attributes(res, scene)
    assert attrs["subtrace:depth_cap"] == st.depth_cap
    assert attrs["subtrace:depth_cap_reason"] == "isolation"
    assert res.stats.pixels_covered > 100
