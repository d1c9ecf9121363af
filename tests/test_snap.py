"""Snapped sides (``geometry/snap.py``): an edge beside a patch whose isolation keeps cells of
exact limit points is sampled at the coarsest such patch's depth, its finer neighbours
snapping their sides onto that polyline. Checked: the edge rule (both sides alike, the
cell-bearing patches never raised), the samples against the limit surface
(``Cage.evaluate``, OpenSubdiv-checked in tests/test_oracle.py), the moved cell corners and
the snapped points of pieces against a plain interpolation of the samples, the items' boxes
holding what they test, and renders watertight from inside creased tori where patches snap."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import subtrace
from subtrace import config
from subtrace.geometry.kinds import BEZIER, CELL
from subtrace.patches.criterion import cell_free, choose_depths, edge_sampling
from subtrace.patches.table import build_patch_table
from subtrace.trace import pools
from subtrace.trace.build import build_requested

HARD = Path(__file__).resolve().parents[1] / "models" / "opensubdiv"


def _built(cage, eye, tol_rad):
    """The patch table, depths before and after edge sampling, sides and the pool of every
    patch built (regular ones as the rounds make them, irregular ones by build_requested)."""
    table = build_patch_table([cage])
    record = {}
    depths = choose_depths(table, eye, tol_rad, 12, record=record)
    before = depths.copy()
    edge_depth, side = edge_sampling(table, depths)
    iso = pools.Pieces(table.n_patches)
    store = table.nets if table.nets.base is None else table.nets.base
    iso.adopt("nets", len(table.nets), nets=store)
    reg = np.nonzero(table.regular)[0]
    iso.append_regular(reg, depths[reg], side[reg], None, table.shell_min[reg].copy(),
                       table.shell_max[reg].copy())
    irr = np.nonzero(table.is_quad & ~table.regular)[0]
    stats = SimpleNamespace(pieces=0, micro_triangles=0, patches_refined=0)
    build_requested(table, irr, depths, edge_depth, iso, 0, stats, eye, tol_rad, record, side)
    return table, before, depths, side, iso


@pytest.fixture(scope="module")
def pawn():
    cage = subtrace.load_cage(HARD / "catmark_pawn.obj")
    lo, hi = cage.bounds()
    centre = 0.5 * (lo + hi)
    eye = centre + np.array([1.4, -0.9, 0.5])  # near enough that depths differ a lot
    return cage, _built(cage, eye, 2e-3)


def _side_params(k, t):
    """Patch parameters (n,2) of the points at ``t`` (n,) along side ``k``."""
    z, o = np.zeros_like(t), np.ones_like(t)
    return np.stack({0: (t, z), 1: (o, t), 2: (t, o), 3: (z, t)}[k], axis=1)


def test_every_edge_is_sampled_alike_and_cells_are_not_raised(pawn):
    _, (table, before, depths, side, _) = pawn
    e, shift = table.edges, table.side_shift
    on = e >= 0
    value = np.where(on, side + shift, -1)
    for edge in np.unique(e[on]):
        assert len(set(value[e == edge].tolist())) == 1, edge
    iso = table.is_quad & ~table.regular
    keeps = iso & (before < cell_free(table, iso))
    assert keeps.any()
    np.testing.assert_array_equal(depths[keeps], before[keeps])
    # every side beside a cell-bearing patch is sampled at most at that patch's depth, and a
    # patch that fans keeps within FAN_LEVELS of its sides' sampling
    assert (side[keeps] <= depths[keeps][:, None]).all()
    fans = ~keeps & table.is_quad
    assert (side[fans] - depths[fans][:, None] <= config.FAN_LEVELS).all()
    assert (side < depths[:, None])[fans].any()  # regular and cell-free patches snap too


def test_cell_bearing_patches_deeper_than_the_snap_limit_are_raised(pawn, monkeypatch):
    """Where every cell-bearing patch on an edge is deeper than ``SNAP_MAX_DEPTH`` (a snapped
    side keeps all 2^d + 1 samples of its polyline), the edge is sampled at its finest
    patch's depth as any other: below the pawn's shallowest cells nothing snaps, every edge
    is sampled at the deepest depth on it, and the cell-bearing patches beside a finer one
    are raised to it (their cell-free depth is above it). At the limit's default the table
    is the one the other tests check."""
    cage, (table, before, depths0, side0, _) = pawn
    iso = table.is_quad & ~table.regular
    free = cell_free(table, iso)
    keeps = iso & (before < free)
    limit = int(before[keeps].min()) - 1
    assert limit >= 1
    monkeypatch.setattr(config, "SNAP_MAX_DEPTH", limit)
    depths = before.copy()
    edge_depth, side = edge_sampling(table, depths)
    e, shift = table.edges, table.side_shift
    on = e >= 0
    value = np.where(on, side + shift, -1)
    deepest = np.full(table.n_edges, -1)
    np.maximum.at(deepest, e[on], (depths[:, None] + shift)[on])
    np.testing.assert_array_equal(value[on], deepest[e[on]])
    assert not (on & (side < depths[:, None])).any()
    raised = keeps & (depths > depths0)
    assert raised.any()
    assert (depths[keeps] <= np.maximum(free[keeps], before[keeps])).all()
    monkeypatch.setattr(config, "SNAP_MAX_DEPTH", 12)
    d2 = before.copy()
    _, side2 = edge_sampling(table, d2)
    np.testing.assert_array_equal(d2, depths0)
    np.testing.assert_array_equal(side2, side0)


def test_snapped_samples_are_limit_points(pawn):
    cage, (table, _, depths, side, iso) = pawn
    a = iso.a
    slots = np.nonzero((a["snap"] >= 0).any(axis=1))[0]
    assert len(slots) >= 20
    size = float(np.linalg.norm(np.subtract(*cage.bounds())))
    n_checked = 0
    for s in slots:
        p = int(a["patch"][s])
        for k in range(4):
            b = int(a["snap"][s, k])
            if b < 0:
                continue
            de = int(side[p, k])
            assert de < depths[p]
            t = np.arange((1 << de) + 1) / (1 << de)
            uv = table.ptex_uv0[p] + table.ptex_scale[p] * _side_params(k, t)
            P, _, _ = cage.evaluate(np.full(len(t), table.ptex[p]), uv)
            np.testing.assert_allclose(a["samples"][b:b + len(t)], P, rtol=0, atol=1e-9 * size)
            n_checked += len(t)
    assert n_checked > 200


def _polyline_point(samples, b, de, depth, t):
    """The point at grid coordinate ``t`` (units 2^-depth) of the polyline of samples
    ``b .. b + 2^de``, by plain interpolation."""
    x = t / (1 << depth) * (1 << de)
    m = min(int(np.floor(x)), (1 << de) - 1)
    w = x - m
    return (1 - w) * samples[b + m] + w * samples[b + m + 1]


def _snapped_vertices(a, it, s, depth):
    """The vertices (gi, gj, k) of item ``it``'s depth-``depth`` grid on sides it snaps."""
    lev, i0, j0 = int(a["level"][it]), int(a["i0"][it]), int(a["j0"][it])
    sc = 1 << (depth - lev)
    n = 1 << depth
    out = []
    for k in range(4):
        if a["side"][it, k] >= depth or a["snap"][s, k] < 0:
            continue
        for q in range(sc + 1):
            gi, gj = {0: (i0 * sc + q, j0 * sc), 1: ((i0 + 1) * sc, j0 * sc + q),
                      2: (i0 * sc + q, (j0 + 1) * sc), 3: (i0 * sc, j0 * sc + q)}[k]
            if {0: gj == 0, 1: gi == n, 2: gj == n, 3: gi == 0}[k]:
                out.append((gi, gj, k))
    return out


def test_snapped_points_lie_on_the_polylines_and_in_the_boxes(pawn):
    _, (table, _, depths, side, iso) = pawn
    a = iso.a
    cells = a["cells"]
    moved = tested = 0
    for s in np.nonzero((a["snap"] >= 0).any(axis=1))[0]:
        for it in range(a["first"][s], a["first"][s] + a["count"][s]):
            kind = a["kind"][it]
            if kind not in (BEZIER, CELL):
                continue
            depth = int(a["depth_i"][it])
            for gi, gj, k in _snapped_vertices(a, it, s, depth):
                # the first snapped side through the vertex gives it (as snap.snapped_point)
                first = min(kk for kk in range(4) if a["side"][it, kk] < depth
                            and a["snap"][s, kk] >= 0
                            and {0: gj == 0, 1: gi == 1 << depth, 2: gj == 1 << depth,
                                 3: gi == 0}[kk])
                if first != k:
                    continue
                t = gi if k in (0, 2) else gj
                want = _polyline_point(a["samples"], int(a["snap"][s, k]), int(a["side"][it, k]),
                                       depth, t)
                lo, hi = a["lo"][it], a["hi"][it]
                assert (want >= lo - 1e-12).all() and (want <= hi + 1e-12).all(), it
                tested += 1
                if kind == CELL:
                    q = {(0, 0): 0, (1, 0): 1, (1, 1): 2, (0, 1): 3}[
                        (gi - int(a["i0"][it]), gj - int(a["j0"][it]))]
                    np.testing.assert_allclose(cells[a["ref"][it], q], want, rtol=0, atol=1e-12)
                    moved += 1
    assert moved > 20 and tested > moved


@pytest.mark.parametrize("tolerance, limit", [(4.0, 12), (1.0, 12), (1.0, 5)])
def test_watertight_from_inside_where_patches_snap(tolerance, limit, tmp_path, monkeypatch):
    """From inside the tube of a creased torus (a ring that ends, a ring across it, a ring
    whose sharpness changes), at 160 x 120 pixels four ways, every ray hits the surface,
    and some of the patches it builds snap a side; also where a low ``SNAP_MAX_DEPTH``
    has the deeper cell-bearing patches raised instead."""
    monkeypatch.setattr(config, "SNAP_MAX_DEPTH", limit)
    from test_crease import torus_obj
    from shared_data import small_scene
    from subtrace.render import render_scene

    snapped = _count_snapped(monkeypatch)
    path = torus_obj(tmp_path / "ends.obj", "ends")
    cage = subtrace.load_cage(path)
    eye = np.array([2.0, 0.0, 0.0])
    for d in ([0.3, 0.1, 1.0], [-0.3, -0.1, -1.0], [0.2, 1.0, 0.1], [0.1, -1.0, 0.3]):
        scene = small_scene([path], eye, eye + np.asarray(d), fov=100.0, width=160,
                            height=120, tolerance=tolerance)
        assert np.count_nonzero(render_scene(scene, cages=[cage]).channels["A"] == 0) == 0
    assert sum(snapped) > 0


@pytest.mark.parametrize("tolerance", [4.0, 1.0, 0.25])
@pytest.mark.parametrize("name", ["pawn", "rook", "bishop"])
def test_watertight_from_inside_the_chess_pieces(name, tolerance, monkeypatch):
    """From the middle of OpenSubdiv's pawn, rook and bishop (creases of sharpness 6 and
    7.9, cell-bearing patches beside finer ones that snap onto them), looking up and
    sideways (their open bottoms out of view) at 160 x 120 pixels, every ray hits the
    surface, and patches snap sides on the way."""
    from shared_data import small_scene
    from subtrace.render import render_scene

    snapped = _count_snapped(monkeypatch)
    path = HARD / f"catmark_{name}.obj"
    cage = subtrace.load_cage(path)
    lo, hi = cage.bounds()
    eye = 0.5 * (lo + hi)  # (z is up in these models)
    for d in ([0.0, 0.0, 1.0], [0.6, 0.1, 1.0], [-0.2, -0.6, 1.0], [0.5, -0.5, 0.4]):
        scene = small_scene([path], eye, eye + np.asarray(d), fov=60.0, width=160,
                            height=120, tolerance=tolerance)
        assert np.count_nonzero(render_scene(scene, cages=[cage]).channels["A"] == 0) == 0
    assert sum(snapped) > 0


def _count_snapped(monkeypatch):
    """A list that receives, per batch of patches the pool builds, how many snap a side."""
    snapped = []
    real = pools.Pieces._snapped

    def spy(self, *args):
        out = real(self, *args)
        snapped.append(int((out >= 0).any(axis=1).sum()))
        return out

    monkeypatch.setattr(pools.Pieces, "_snapped", spy)
    return snapped
