"""Bounding shells of patches contain their limit surface (design invariant 2): Loop grids
and regular nets on real and perturbed cages, isolated irregular patches."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shared_data import MODELS, load_shape

import subtrace
from subtrace.patches.grids import build_grids, leaf_corners
from subtrace.patches.table import build_patch_table

GRID_SHAPES = [
    "catmark_cube_creases1", "catmark_cubes_semisharp", "catmark_chaikin1", "catmark_edgenone",
    "catmark_edgecorner", "catmark_hole_test2", "catmark_nonman_verts", "catmark_nonquads",
    "catmark_pole8", "catmark_val2_interior", "loop_cube_creases1", "loop_saddle_edgecorner",
    "loop_icosahedron", "loop_triangle_edgeonly", "loop_icos_semisharp", "loop_chaikin1",
    "loop_pole8",
]


@pytest.mark.parametrize("name", GRID_SHAPES)
def test_grids_equal_uniform_refinement(name):
    """Grids built by sparse local refinement are bit-identical to the limit points of a
    uniform refinement (same arithmetic in the same order), so two patches that share a
    vertex at the same depth share it exactly."""
    cage = load_shape(name)
    L0 = 1 if cage.scheme == "catmark" else 0
    lev = cage.level_topology(L0)
    faces = np.nonzero(~lev.face_hole)[0]
    faces = faces[:: max(1, len(faces) // 6)]
    quad = cage.scheme == "catmark"
    k = 4 if quad else 3
    for depth in (0, 2):
        P, _ = build_grids(lev, cage.refine(L0).points, cage.options, faces, depth)
        ref, _, _ = cage.limit(L0 + depth)
        fine = cage.level_topology(L0 + depth)
        m = 4**depth
        slot = leaf_corners(depth, quad)
        for a, f in enumerate(faces):
            leaves = f * m + np.arange(m)
            cv = fine.face_verts[fine.face_offsets[leaves][:, None] + np.arange(k)]
            np.testing.assert_array_equal(P[a][slot], ref[cv])


@pytest.mark.parametrize("name", GRID_SHAPES)
def test_shells_contain_limit_grids(name):
    """Invariant 2: the shell of every patch contains the exact limit points of its grid,
    and so does the box the rays find it by (for a Loop triangle, a part of its shell made
    from its children's one-rings, ``patches/table.py``)."""
    cage = load_shape(name)
    table = build_patch_table([cage])
    P = _limit_grids(table, 3)
    _assert_inside(P, table)
    if cage.scheme == "loop":  # (the cut is real: the boxes' sides are shorter)
        ray = (table.ray_max - table.ray_min).sum(axis=1)
        assert np.median(ray / (table.shell_max - table.shell_min).sum(axis=1)) < 0.85


def test_regular_loop_triangles_are_found_by_their_nets_boxes():
    """The renderer also cuts a regular Loop triangle's box for the rays to its quartic
    net's box (``trace.build.cut_to_loop_nets``): on the torus (every triangle regular) the
    boxes' sides are about a third of the shells' and the limit grids stay inside."""
    from subtrace.trace.build import cut_to_loop_nets

    cage = subtrace.load_cage(MODELS / "torus.obj")
    table = build_patch_table([cage])
    lo, hi = table.ray_min.copy(), table.ray_max.copy()
    cut_to_loop_nets(table, lo, hi)
    _assert_inside(_limit_grids(table, 2), table, (lo, hi))
    ray = (hi - lo).sum(axis=1)
    assert np.median(ray / (table.shell_max - table.shell_min).sum(axis=1)) < 0.45


def _limit_grids(table, depth):
    """(points (N,3), patch of each (N,)): the exact limit points of the depth-``depth``
    grid of every patch of a one-object table; a cage quad patch's from its four level-1
    children's grids one level less deep (the same points; grids are built at the patch
    level, where every face is a quad)."""
    o = table.objects[0]
    cage = o.cage
    out, owner = [], []
    for level, points, rows, faces in o.parts():
        patches = np.arange(rows.start, rows.stop)
        if level is cage.base and cage.scheme == "catmark":
            level, points = cage.level_topology(1), cage.refine(1).points
            faces = (cage.base.face_offsets[faces][:, None] + np.arange(4)).ravel()
            patches, depth_here = np.repeat(patches, 4), depth - 1
        else:
            depth_here = depth
        P, _ = build_grids(level, points, cage.options, faces, depth_here)
        out.append(P.reshape(-1, 3))
        owner.append(np.repeat(patches, P.shape[1]))
    return np.concatenate(out), np.concatenate(owner)


def _assert_inside(P, table, boxes=None):
    """The points ``P`` = (points, patch of each) lie in their patches' ``boxes`` (lo, hi),
    or (None) in both their shells and their rays' boxes."""
    pts, owner = P
    for lo, hi in ([boxes] if boxes is not None else
                   ((table.shell_min, table.shell_max), (table.ray_min, table.ray_max))):
        assert np.all(lo <= hi)
        assert np.all(pts >= lo[owner] - 1e-12)
        assert np.all(pts <= hi[owner] + 1e-12)


def _perturbed(name, seed):
    """The oracle shape ``name`` with its points moved at random (any positions are valid)."""
    base = load_shape(name)
    rng = np.random.default_rng(seed)
    pts = base.points + rng.normal(scale=0.3, size=base.points.shape)
    return subtrace.make_cage(
        pts, base.face_sizes, base.face_verts, base.scheme, boundary=base.options.boundary,
        smooth_triangles=base.options.smooth_triangles,
    )


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), name=st.sampled_from(GRID_SHAPES))
def test_shells_contain_limit_of_perturbed_cages(seed, name):
    """Same, for random perturbations of the cage points (any positions are valid)."""
    cage = _perturbed(name, seed)
    table = build_patch_table([cage])
    P = _limit_grids(table, 2)
    _assert_inside(P, table)


def _isolated_shells(cage, tol_rad):
    """The patch table and the shells the depth choice tightens (eye on the +z side, three
    bounding-box diagonals away), with the patches it tightened."""
    from subtrace.patches.criterion import choose_depths

    table = build_patch_table([cage])
    lo, hi = table.shell_min.copy(), table.shell_max.copy()
    centre = 0.5 * (lo.min(axis=0) + hi.max(axis=0))
    eye = centre + np.array([0.0, 0.0, 3.0 * np.linalg.norm(hi.max(axis=0) - lo.min(axis=0))])
    choose_depths(table, eye, tol_rad, 8, {}, (lo, hi))
    changed = np.any(lo != table.shell_min, axis=1) | np.any(hi != table.shell_max, axis=1)
    return table, lo, hi, changed


ISOLATED_SHAPES = [n for n in GRID_SHAPES if n.startswith("catmark")]


@pytest.mark.parametrize("name", ISOLATED_SHAPES)
def test_isolated_shells_contain_limit_grids(name):
    """Invariant 2 for the shells tightened by the depth choice's isolation (the union of
    the Bezier boxes and one-ring boxes of what an irregular patch was refined into): the
    exact limit points of a depth-5 grid of every patch lie inside, and the tightened ones
    are much smaller than the patches' one-ring boxes (else the tightening does nothing)."""
    cage = load_shape(name)
    table, lo, hi, changed = _isolated_shells(cage, 1e-4)
    assert changed.any() == bool((~table.regular).any())
    _assert_inside(_limit_grids(table, 5), table, (lo, hi))
    if changed.any():
        old = np.prod(table.shell_max[changed] - table.shell_min[changed], axis=1)
        new = np.prod(hi[changed] - lo[changed], axis=1)
        assert np.median(new / np.where(old > 0, old, 1.0)) < 0.5


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), name=st.sampled_from(ISOLATED_SHAPES),
       tol_exp=st.floats(-5.0, -1.0))
def test_isolated_shells_contain_limit_of_perturbed_cages(seed, name, tol_exp):
    """Same, for random perturbations of the cage points and tolerances (each tolerance
    stops the isolation at other levels, so other boxes end the union)."""
    cage = _perturbed(name, seed)
    table, lo, hi, _ = _isolated_shells(cage, 10.0**tol_exp)
    _assert_inside(_limit_grids(table, 4), table, (lo, hi))


def test_isolated_shells_contain_spot():
    """On Spot (many extraordinary vertices), at about a pixel of the default scene."""
    cage = subtrace.load_cage(MODELS / "spot_control_mesh.obj")
    table, lo, hi, changed = _isolated_shells(cage, 1e-3)
    assert changed.sum() > 100
    _assert_inside(_limit_grids(table, 4), table, (lo, hi))
