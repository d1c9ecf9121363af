"""Line / surface intersection on Loop cages (subtrace.lines.api with subtrace.lines.items): the
quartic Bezier items against the exact evaluator, the Table 1 situations on regular and
extraordinary patches, random lines against a brute-force reference (a closed model with
extraordinary vertices, all-extraordinary icosahedron, a cage with a boundary), the oracle's
samples, ``mode="first"`` against ``"all"``, and the per-cage cache."""

from __future__ import annotations

import numpy as np
import pytest
from shared_data import MODELS, ORACLE
from test_lines import check_random_lines

import subtrace
from subtrace.lines.api import intersect_lines
from subtrace.lines.items import isolate_loop
from subtrace.patches.basis import CHILD_ORIGIN, CHILD_SCALE, TRI_SPLIT
from subtrace.patches.basis import tri_bernstein as bernstein
from subtrace.patches.boxspline import box_nets, loop_regular
from subtrace.patches.table import build_patch_table
from subtrace.shapes import torus_cage
from subtrace.subdiv.topology import INF_SHARP

PREC = 1e-3


@pytest.fixture(scope="module")
def spot():
    return subtrace.load_cage(MODELS / "spot_low_resolution.obj")


@pytest.fixture(scope="module")
def icosahedron():
    # every vertex of valence 5: no regular patch at all
    t = (1 + 5 ** 0.5) / 2
    v = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                  [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]],
                 float) / 2
    f = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
         [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
         [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    return subtrace.make_cage(v, [3] * 20, np.ravel(f), scheme="loop")


@pytest.fixture(scope="module")
def disc():
    """An open disc: a valence-5 centre, a ring of regular vertices, a boundary ring of 10,
    on a saddle (so nothing is flat)."""
    a1 = 2 * np.pi * np.arange(5) / 5
    a2 = 2 * np.pi * np.arange(10) / 10
    xy = np.concatenate([[[0.0, 0.0]], np.c_[np.cos(a1), np.sin(a1)],
                         2 * np.c_[np.cos(a2), np.sin(a2)]])
    z = 0.15 * (xy[:, 0] ** 2 - xy[:, 1] ** 2) + 0.1 * xy[:, 0]
    z[0] = 0.4
    r1 = lambda i: 1 + i % 5  # noqa: E731
    r2 = lambda j: 6 + j % 10  # noqa: E731
    f = []
    for i in range(5):
        f += [[0, r1(i), r1(i + 1)], [r1(i), r2(2 * i), r2(2 * i + 1)],
              [r1(i), r2(2 * i + 1), r1(i + 1)], [r1(i + 1), r2(2 * i + 1), r2(2 * i + 2)]]
    return subtrace.make_cage(np.c_[xy, z], [3] * len(f), np.ravel(f), scheme="loop")


def _random_st(rng, n):
    st = rng.uniform(0, 1, (n, 2))
    flip = st.sum(axis=1) > 1
    st[flip] = 1 - st[flip]
    return st


def _surface(cage, ptex, uv):
    P, du, dv = cage.evaluate(np.array([ptex]), np.array([uv], float))
    n = np.cross(du[0], dv[0])
    return P[0], du[0], dv[0], n / np.linalg.norm(n)


# ---------------------------------------------------------------------------------------
# the items: quartic Bezier nets of regular patches and isolated pieces
# ---------------------------------------------------------------------------------------


def test_regular_patch_nets_are_the_box_splines(spot):
    faces = np.arange(spot.n_faces)
    reg = faces[loop_regular(spot.base, spot.options, faces)]
    assert 0 < len(reg) < spot.n_faces  # Spot has both kinds
    rng = np.random.default_rng(1)
    st = _random_st(rng, len(reg))
    nets = box_nets(spot.base, spot.points, reg)
    P = np.einsum("mp,mpx->mx", bernstein(st), nets)
    # the evaluator's box-spline basis, in another basis: equal to rounding
    np.testing.assert_allclose(P, spot.evaluate(reg, st)[0], atol=1e-13)
    # each child net of the midpoint split is the parent's polynomial on its triangle
    kids = np.einsum("cpr,rx->cpx", TRI_SPLIT, nets[0])
    for c in range(4):
        par = CHILD_ORIGIN[c] + CHILD_SCALE[c] * st[:50]
        np.testing.assert_allclose(bernstein(st[:50]) @ kids[c], bernstein(par) @ nets[0],
                                   atol=1e-14)


def test_isolated_pieces_and_cells(icosahedron):
    tb = build_patch_table([icosahedron])
    allowed = 0.01
    root, uv0, scale, nets, exact = isolate_loop(tb.objects[0], tb.face[:3], allowed, 40)
    assert exact.sum() > 3 * (~exact).sum() > 0
    rng = np.random.default_rng(2)
    st = _random_st(rng, len(root))
    uv = uv0 + scale[:, None] * st
    assert (uv >= -1e-12).all() and (uv.sum(axis=1) <= 1 + 1e-12).all()
    ref = icosahedron.evaluate(tb.ptex[root], uv)[0]
    err = np.linalg.norm(np.einsum("mp,mpx->mx", bernstein(st), nets) - ref, axis=1)
    # regular pieces are the surface; cells (flat) lie within their proven bound
    assert err[exact].max() < 1e-13
    assert err[~exact].max() <= allowed
    # the pieces tile each patch: their areas (|scale|^2 / 2) add up to the triangle's
    area = np.bincount(root, weights=scale**2 / 2, minlength=3)
    np.testing.assert_allclose(area, 0.5, rtol=1e-12)


@pytest.mark.parametrize("which", ["disc", "creased"])
def test_boundary_and_crease_patches_are_box_splines(which, disc, icosahedron):
    """Triangles along a boundary or an infinitely sharp crease whose crease vertices are
    regular (3 faces on the triangle's side) are box splines with phantom points: their
    nets equal the exact evaluator (level-1 faces, ptex parameters of their base face)."""
    if which == "disc":
        cage = disc
    else:  # the icosahedron with the five edges around vertex 0 infinitely sharp
        ring = [11, 5, 1, 7, 10]
        cage = subtrace.make_cage(icosahedron.points, icosahedron.face_sizes,
                                  icosahedron.face_verts, scheme="loop",
                                  crease_edges=[(a, b) for a, b in zip(ring, np.roll(ring, 1))],
                                  crease_sharpness=[10.0] * 5)
    lev = cage.level_topology(1)
    faces = np.arange(lev.n_faces)
    reg = faces[loop_regular(lev, cage.options, faces)]
    sharp_v = np.zeros(lev.n_verts, bool)
    sharp_v[lev.edge_verts[lev.edge_sharpness >= INF_SHARP].ravel()] = True
    on = sharp_v[lev.face_verts.reshape(-1, 3)[reg]].any(axis=1)
    assert on.sum() >= 10  # phantom-point patches exist
    rng = np.random.default_rng(4)
    st = _random_st(rng, len(reg))
    uv = CHILD_ORIGIN[reg % 4] + CHILD_SCALE[reg % 4, None] * st
    P = np.einsum("mp,mpx->mx", bernstein(st), box_nets(lev, cage.refine(1).points, reg))
    np.testing.assert_allclose(P, cage.evaluate(reg // 4, uv)[0], atol=1e-12)


def test_boundary_items_do_not_follow_precision(disc):
    """Along a boundary the pieces are regular boundary patches after a level or two: items
    grow with log(1 / precision), not with the boundary's length / precision."""
    rng = np.random.default_rng(8)
    org = rng.uniform(-2, 2, (40, 3))
    dirs = rng.normal(size=(40, 3))
    n = [intersect_lines(disc, org, dirs, p, t_range=(-np.inf, np.inf)).stats["items"]
         for p in (1e-2, 1e-6)]
    assert n[1] < 3 * n[0] < 3000


# ---------------------------------------------------------------------------------------
# the paper's Table 1 situations, on a regular and on an extraordinary patch
# ---------------------------------------------------------------------------------------


def test_table1_situations_on_a_regular_patch(spot):
    faces = np.arange(spot.n_faces)
    f = int(faces[loop_regular(spot.base, spot.options, faces)][10])
    P, du, _, n = _surface(spot, f, (0.3, 0.3))
    h = intersect_lines(spot, [P + 0.01 * n], [-n], PREC, t_range=(0, 0.02))
    assert len(h) == 1 and not h.tangent[0]
    assert np.linalg.norm(h.point[0] - P) < 1e-9  # Newton on the exact net
    assert h.ptex[0] == f and np.allclose(h.uv[0], (0.3, 0.3), atol=1e-8)
    assert np.dot(h.normal[0], n) > 1 - 1e-8
    e = du / np.linalg.norm(du)
    # a tangent line: one tangent hit within precision of the surface
    h = intersect_lines(spot, [P - 0.005 * e], [e], PREC, t_range=(0, 0.01))
    assert len(h) == 1 and h.tangent[0]
    assert np.linalg.norm(spot.evaluate(h.ptex, h.uv)[0][0] - h.point[0]) <= PREC
    # moved off by twice the precision it misses, on whichever side is convex; by half the
    # precision it still touches on the convex side
    off = [len(intersect_lines(spot, [P + s * PREC * n - 0.005 * e], [e], PREC,
                               t_range=(0, 0.01))) for s in (2, -2, 0.5, -0.5)]
    assert off[:2].count(0) >= 1 and max(off[2:]) == 1


def test_extraordinary_vertex_hit_once(icosahedron):
    # a line along the normal through an extraordinary vertex's limit point: five patches
    # meet there, one hit
    P = icosahedron.limit(0)[0][0]
    n = P / np.linalg.norm(P)
    h = intersect_lines(icosahedron, [P + 0.1 * n], [-n], PREC, t_range=(0, 0.2))
    assert len(h) == 1 and not h.tangent[0]
    assert np.linalg.norm(h.point[0] - P) <= PREC
    assert np.linalg.norm(icosahedron.evaluate(h.ptex, h.uv)[0][0] - h.point[0]) <= PREC
    assert np.dot(h.normal[0], n) > 0.99
    # the whole line: in and out
    h = intersect_lines(icosahedron, [P + 0.1 * n], [-n], PREC, t_range=(-np.inf, np.inf))
    assert len(h) == 2 and not h.tangent.any()
    np.testing.assert_allclose(h.point[1], -P, atol=PREC)


def test_shared_edge_hit_once(icosahedron):
    # the limit point of an edge's midpoint (ptex (0.5, 0)) lies on two patches
    for ptex, uv in ((0, (0.5, 0.0)), (3, (0.25, 0.75)), (7, (0.0, 0.5))):
        P, _, _, n = _surface(icosahedron, ptex, uv)
        h = intersect_lines(icosahedron, [P + 0.1 * n], [-n], PREC, t_range=(0, 0.2))
        assert len(h) == 1, (ptex, uv, h.t)
        assert np.linalg.norm(h.point[0] - P) <= PREC


def test_flat_region_line_lying_in_it():
    # a planar triangular lattice (valence 6 inside, a boundary around): a flat surface
    n = 7
    pts = np.array([[x + 0.5 * y, y * np.sqrt(3) / 2, 0.0] for y in range(n) for x in range(n)])
    v = lambda x, y: y * n + x  # noqa: E731
    f = [t for y in range(n - 1) for x in range(n - 1)
         for t in ([v(x, y), v(x + 1, y), v(x, y + 1)],
                   [v(x + 1, y), v(x + 1, y + 1), v(x, y + 1)])]
    cage = subtrace.make_cage(pts, [3] * len(f), np.ravel(f), scheme="loop")
    # a line lying in the plane, inside: one tangent hit on it
    h = intersect_lines(cage, [[3.0, 2.6, 0.0]], [[1.0, 0.1, 0.0]], PREC, t_range=(0, 2.0))
    assert len(h) == 1 and h.tangent[0]
    assert abs(h.point[0, 2]) < 1e-12
    # crossing the plane: one transverse hit, exact
    h = intersect_lines(cage, [[4.1, 2.7, 1.0]], [[0.1, 0.0, -1.0]], PREC)
    assert len(h) == 1 and not h.tangent[0]
    np.testing.assert_allclose(h.point[0], [4.2, 2.7, 0.0], atol=1e-12)
    assert abs(h.normal[0, 2]) == pytest.approx(1.0)


# ---------------------------------------------------------------------------------------
# random lines against the brute-force reference
# ---------------------------------------------------------------------------------------

# Reference: the level-L limit mesh (chord error about h^2 k / 8: below 1e-4 for each case
# and level below), so t agrees within PREC + 1e-3 for lines crossing at more than 0.1 rad.
REF_TOL = PREC + 1e-3
CASES = {"spot": 3, "icosahedron": 5, "disc": 6}


@pytest.mark.parametrize("which", list(CASES))
def test_random_lines_against_brute_force(which, request):
    cage = request.getfixturevalue(which)
    org, dirs, h = check_random_lines(cage, CASES[which], 30, seed=11, ref_tol=REF_TOL)
    assert len(h) >= len(org) // 2
    # every hit: its (ptex, uv) evaluates within precision of its point, most exactly
    P = cage.evaluate(h.ptex, h.uv)[0]
    err = np.linalg.norm(P - h.point, axis=1)
    assert err.max() <= PREC
    assert np.median(err[~h.tangent]) < 1e-9
    assert np.all(np.isfinite(h.normal)) and np.allclose(np.linalg.norm(h.normal, axis=1), 1)


def test_oracle_samples(icosahedron):
    """OpenSubdiv's limit points (random, corner, centre and near-extraordinary samples of
    loop_icosahedron) hit by lines along their normals."""
    z = np.load(ORACLE / "loop_icosahedron.npz")
    cage = subtrace.load_cage(ORACLE / "shapes" / "loop_icosahedron.obj")
    P = z["sample_P"]
    n = np.cross(z["sample_dPdu"], z["sample_dPdv"])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    h = intersect_lines(cage, P + 0.05 * n, -n, PREC, t_range=(0, 0.1), mode="first")
    assert np.array_equal(h.line, np.arange(len(P)))  # each one hit
    err = np.linalg.norm(h.point - P, axis=1)
    assert err.max() <= PREC
    assert np.median(err) < 1e-12  # most on exact pieces: OpenSubdiv's value to rounding


# ---------------------------------------------------------------------------------------
# first hit, memory, cache
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("which", ["icosahedron", "torus"])
def test_first_is_the_nearest_of_all(which, icosahedron):
    cage = icosahedron if which == "icosahedron" else torus_cage()
    rng = np.random.default_rng(5)
    org = rng.uniform(-1.5, 1.5, (300, 3))
    dirs = rng.normal(size=(300, 3))
    # and lines that enter and leave within the precision (one tangent hit, from two
    # crossings: "first" must not stop before the second)
    ptex = rng.integers(0, len(cage.face_sizes), 40)
    P, du, dv = cage.evaluate(ptex, np.full((40, 2), 0.25))
    n = np.cross(du, dv)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    e = du / np.linalg.norm(du, axis=1, keepdims=True)
    org = np.concatenate([org, P - 1e-8 * n - 0.1 * e])
    dirs = np.concatenate([dirs, e])
    a = intersect_lines(cage, org, dirs, PREC, t_range=(-np.inf, np.inf))
    f = intersect_lines(cage, org, dirs, PREC, t_range=(-np.inf, np.inf), mode="first")
    firsts = np.r_[True, a.line[1:] != a.line[:-1]]
    np.testing.assert_array_equal(f.line, a.line[firsts])
    np.testing.assert_allclose(f.t, a.t[firsts], atol=1e-12)
    np.testing.assert_array_equal(f.tangent, a.tangent[firsts])
    assert a.tangent[firsts][a.line[firsts] >= 300].sum() >= 8
    # and it stopped early: fewer leaves than the full descent
    a = intersect_lines(cage, org[:300], dirs[:300], PREC, t_range=(-np.inf, np.inf))
    f = intersect_lines(cage, org[:300], dirs[:300], PREC, t_range=(-np.inf, np.inf),
                        mode="first")
    assert f.stats["leaves"] < 0.8 * a.stats["leaves"]


def test_memory_does_not_follow_precision(icosahedron):
    rng = np.random.default_rng(3)
    org = rng.uniform(-0.5, 0.5, (50, 3))
    dirs = rng.normal(size=(50, 3))
    counts = {}
    for prec in (1e-2, 1e-5, 1e-8):
        h = intersect_lines(icosahedron, org, dirs, prec, t_range=(-np.inf, np.inf))
        P = icosahedron.evaluate(h.ptex, h.uv)[0]
        assert np.linalg.norm(P - h.point, axis=1).max() <= prec
        counts[prec] = h.stats["items"]
    # the isolation adds a ring of pieces per level at each extraordinary vertex: items grow
    # with log(1 / precision), while the flat leaves' level (log4) is never stored
    assert counts[1e-8] < 4 * counts[1e-5] < 16 * counts[1e-2]


def test_setup_is_cached_on_the_cage(icosahedron):
    cage = subtrace.make_cage(icosahedron.points, icosahedron.face_sizes,
                              icosahedron.face_verts, scheme="loop")
    o, d = [[0.1, 0.2, 2.0]], [[0.0, 0.0, -1.0]]
    h1 = intersect_lines(cage, o, d, PREC, t_range=(-np.inf, np.inf))
    store = cage._cache["lines"]
    items = store["items"][PREC]
    h2 = intersect_lines(cage, o, d, PREC, t_range=(-np.inf, np.inf))
    assert store["items"][PREC] is items  # the same items, not built again
    np.testing.assert_array_equal(h1.t, h2.t)
    for prec in (1e-2, 1e-4, 1e-5, 1e-6, 1e-7):
        intersect_lines(cage, o, d, prec)
    assert len(store["items"]) == 4 and PREC not in store["items"]


def test_cli_intersect_loop_cage(tmp_path, icosahedron):
    from subtrace.cli import main

    cage = tmp_path / "ico.obj"
    fv = icosahedron.face_verts.reshape(-1, 3) + 1
    cage.write_text("".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in icosahedron.points.tolist())
                    + "".join(f"f {a} {b} {c}\n" for a, b, c in fv.tolist()))
    lines = tmp_path / "lines.csv"
    lines.write_text("ox,oy,oz,dx,dy,dz\n0,0,3,0,0,-1\n3,3,3,1,0,0\n")
    out = tmp_path / "hits.csv"
    assert main(["intersect", str(cage), "--lines", str(lines), "--precision", "0.001",
                 "-o", str(out)]) == 0
    rows = [r.split(",") for r in out.read_text().splitlines()[1:]]
    assert [r[0] for r in rows] == ["0", "0"]  # in and out on the z axis, nothing for line 1
    ref = intersect_lines(icosahedron, [[0, 0, 3]], [[0, 0, -1]], 1e-3)
    np.testing.assert_allclose([float(r[1]) for r in rows], ref.t, rtol=1e-12)


@pytest.mark.parametrize("name", ["loop_saddle_edgecorner", "loop_cube_creases1",
                                  "loop_cubes_infsharp", "loop_triangle_edgeonly",
                                  "loop_fvar_bound0"])
def test_boundary_recipes_equal_the_plain_python_oracle(name):
    """The jitted phantom-point recipes (patches.boxspline._boundary_recipes) equal the plain
    Python oracle (tests/naive.py) triangle by triangle, regular or not, on cages with
    boundaries and infinitely sharp creases, at levels 0-2."""
    from naive import boundary_recipe

    from subtrace.patches.boxspline import _boundary_recipes

    cage = subtrace.load_cage(ORACLE / "shapes" / f"{name}.obj")
    checked = made = 0
    for k in range(3):
        lev = cage.level_topology(k)
        sharp = lev.edge_sharpness >= INF_SHARP
        faces = np.nonzero(np.diff(lev.face_offsets) == 3)[0]
        ok, abr = _boundary_recipes(lev, faces, sharp)
        for m, f in enumerate(faces):
            want = boundary_recipe(lev, int(f), sharp)
            assert ok[m] == (want is not None), (k, f)
            if want is not None:
                assert all(np.array_equal(abr[m, c], want[c]) for c in range(3)), (k, f)
                made += 1
        checked += len(faces)
    assert made > 0 and checked > made  # both outcomes occur
