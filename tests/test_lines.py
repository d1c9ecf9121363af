"""Line / surface intersection (subtrace.lines.api, subtrace.lines.items): the paper's Table 1
situations built on real patches, random lines against a brute-force reference (the
ray / triangle oracle of tests/naive.py), hit points against the exact evaluator, memory
that does not grow with the precision, and the CLI."""

from __future__ import annotations

import json

import naive
import numpy as np
import pytest
from shared_data import MODELS, SHAPES

import subtrace
from subtrace.cli import main
from subtrace.errors import SubtraceError
from subtrace.lines.api import intersect_lines
from subtrace.lines.items import items_for
from subtrace.shapes import torus_cage


PREC = 1e-3


@pytest.fixture(scope="module")
def torus():
    return torus_cage()


@pytest.fixture(scope="module")
def cube():
    pts = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    return subtrace.make_cage(pts, [4] * 6, np.ravel(faces), scheme="catmark")


def reference_hits(cage, level, org, dirs):
    """Brute force: the line parameters of every hit with every triangle (Loop) or two
    triangles per quad (Catmull-Clark) of the level-``level`` uniform refinement with its
    vertices pushed to the limit (exact limit masks); hits on shared edges (equal t)
    counted once."""
    mesh = cage.refine(level)
    P = cage.limit(level)[0]
    keep = ~mesh.face_hole
    if cage.scheme == "loop":
        tris = mesh.face_verts.reshape(-1, 3)[keep]
    else:
        q = mesh.face_verts.reshape(-1, 4)[keep]
        tris = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
    A, B, C = P[tris[:, 0]], P[tris[:, 1]], P[tris[:, 2]]
    out = []
    for o, d in zip(org, dirs):
        ts, _ = naive.ray_triangle_hits(o, d, A, B, C)
        out.append(ts[np.r_[True, np.diff(ts) > 1e-9]] if len(ts) else ts)
    return out


def check_random_lines(cage, level, n, seed, precision=PREC, ref_tol=None):
    """``n`` random lines through ``cage``'s box against :func:`reference_hits` at ``level``:
    equal hit counts and ``t`` within ``ref_tol`` (default ``REF_TOL``) on every line that
    crosses at more than 0.1 rad (at least half of them); returns (org, dirs, hits)."""
    rng = np.random.default_rng(seed)
    lo, hi = cage.bounds()
    org = rng.uniform(lo, hi, (n, 3))
    dirs = rng.normal(size=(n, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    h = intersect_lines(cage, org, dirs, precision, t_range=(-np.inf, np.inf))
    ref = reference_hits(cage, level, org, dirs)
    compared = 0
    for i in range(n):
        idx = h.of_line(i)
        if h.tangent[idx].any() or np.any(np.abs((h.normal[idx] * dirs[i]).sum(1)) < 0.1):
            continue  # grazing: the reference's chords may pass either side
        assert len(idx) == len(ref[i]), (i, h.t[idx], ref[i])
        np.testing.assert_allclose(h.t[idx], ref[i], atol=REF_TOL if ref_tol is None else ref_tol)
        compared += 1
    assert compared >= n // 2
    return org, dirs, h


def _surface(cage, ptex, uv):
    P, du, dv = cage.evaluate(np.array([ptex]), np.array([uv], float))
    n = np.cross(du[0], dv[0])
    return P[0], du[0], dv[0], n / np.linalg.norm(n)


# ---------------------------------------------------------------------------------------
# the paper's Table 1 situations, on real patches of the torus (outer, convex side)
# ---------------------------------------------------------------------------------------

# ptex 0's neighbourhood at uv (0.5, 0.5) is on the outer equator side (convex)
def test_table1_one_intersection_along_the_normal(torus):
    for uv in ((0.5, 0.5), (0.3, 0.7)):  # cases 1 and 2
        P, _, _, n = _surface(torus, 0, uv)
        h = intersect_lines(torus, [P + 0.05 * n], [-n], PREC, t_range=(0, 0.1))
        assert len(h) == 1 and not h.tangent[0]
        # Newton on the exact net: far inside the precision
        assert np.linalg.norm(h.point[0] - P) < 1e-9
        assert h.t[0] == pytest.approx(0.05, abs=1e-9)
        assert np.dot(h.normal[0], n) > 1 - 1e-9


def test_table1_tangent_line(torus):
    P, du, _, n = _surface(torus, 0, (0.5, 0.5))
    e = du / np.linalg.norm(du)
    h = intersect_lines(torus, [P - 0.2 * e], [e], PREC, t_range=(0, 0.4))
    assert len(h) == 1 and h.tangent[0]
    # the reported point is within precision of the surface and of its own (ptex, uv)
    assert np.linalg.norm(h.point[0] - P) < 0.05
    Q = torus.evaluate(h.ptex, h.uv)[0][0]
    assert np.linalg.norm(Q - h.point[0]) <= PREC


def test_table1_two_intersections(torus):
    P1 = _surface(torus, 0, (0.2, 0.3))[0]
    P2 = _surface(torus, 0, (0.8, 0.9))[0]
    h = intersect_lines(torus, [P1], [P2 - P1], PREC, t_range=(-0.5, 1.5))
    assert len(h) == 2 and not h.tangent.any()
    np.testing.assert_allclose(h.t, [0.0, 1.0], atol=1e-9)
    np.testing.assert_allclose(h.point, [P1, P2], atol=1e-9)


def test_table1_misses(torus):
    P, du, _, n = _surface(torus, 0, (0.5, 0.5))
    e = du / np.linalg.norm(du)
    # case 5: a tangent line moved off the convex surface by twice the precision
    Q = P + 2 * PREC * n
    h = intersect_lines(torus, [Q - 0.2 * e], [e], PREC, t_range=(0, 0.4))
    assert len(h) == 0
    # within the precision it touches
    Q = P + 0.5 * PREC * n
    h = intersect_lines(torus, [Q - 0.2 * e], [e], PREC, t_range=(0, 0.4))
    assert len(h) == 1 and h.tangent[0]
    # case 6: far away: rejected by the patch boxes, nothing refined
    h = intersect_lines(torus, [[5.0, 5.0, 5.0]], [[0.0, 0.0, 1.0]], PREC,
                        t_range=(-np.inf, np.inf))
    assert len(h) == 0 and h.stats["items_entered"] == 0


def test_shared_edges_and_vertices_counted_once(torus):
    # the x axis passes through patch corners (torus vertices on the x-z plane)
    h = intersect_lines(torus, [[-3.0, 0, 0]], [[1.0, 0, 0]], PREC)
    assert len(h) == 4
    np.testing.assert_allclose(np.abs(h.point[:, 0]), [1.294263748, 0.639715497,
                                                       0.639715497, 1.294263748], atol=1e-8)
    np.testing.assert_allclose(h.normal[:, 0], [-1, 1, -1, 1], atol=1e-9)


def test_flat_region_line_lying_in_it():
    # a plane of regular patches (a 6 x 6 grid, the middle 2 x 2 faces are regular and flat)
    g = np.array([[x, y, 0.0] for y in range(7) for x in range(7)], float)
    faces = [[y * 7 + x, y * 7 + x + 1, (y + 1) * 7 + x + 1, (y + 1) * 7 + x]
             for y in range(6) for x in range(6)]
    cage = subtrace.make_cage(g, [4] * 36, np.ravel(faces), scheme="catmark")
    h = intersect_lines(cage, [[2.2, 3.1, 0.0]], [[1.0, 0.0, 0.0]], PREC, t_range=(0, 2.5))
    assert len(h) == 1 and h.tangent[0]
    assert abs(h.point[0, 2]) < 1e-12
    # crossing the plane: one transverse hit
    h = intersect_lines(cage, [[3.1, 3.2, 1.0]], [[0.1, 0.0, -1.0]], PREC)
    assert len(h) == 1 and not h.tangent[0]
    np.testing.assert_allclose(h.point[0], [3.2, 3.2, 0.0], atol=1e-12)


# ---------------------------------------------------------------------------------------
# random lines against the brute-force reference
# ---------------------------------------------------------------------------------------

# Reference error: the level-5 limit mesh of the torus deviates from the surface by at most
# its chord error, about h^2 k / 8 = (0.45/32)^2 * 3 / 8 < 1e-4; along a line crossing at
# angle theta that is 1e-4 / sin(theta) in t: lines crossing below 0.1 rad are left out.
REF_TOL = PREC + 1e-3


@pytest.mark.parametrize("which", ["torus", "cube"])
def test_random_lines_against_brute_force(which, torus, cube):
    cage = torus if which == "torus" else cube
    org, dirs, h = check_random_lines(cage, 5 if which == "torus" else 6, 24, seed=7)
    assert len(h) > len(org)  # the lines do hit
    # every hit: its (ptex, uv) evaluates within precision of its point; crossings exactly
    P = cage.evaluate(h.ptex, h.uv)[0]
    err = np.linalg.norm(P - h.point, axis=1)
    assert err.max() <= PREC
    assert np.median(err[~h.tangent]) < 1e-9
    # sorted by line then t
    assert np.all(np.diff(h.line) >= 0)
    same = np.diff(h.line) == 0
    assert np.all(np.diff(h.t)[same] > 0)
    # the first mode keeps each line's nearest hit
    f = intersect_lines(cage, org, dirs, PREC, t_range=(-np.inf, np.inf), mode="first")
    firsts = np.r_[True, h.line[1:] != h.line[:-1]]
    np.testing.assert_array_equal(f.line, h.line[firsts])
    np.testing.assert_allclose(f.t, h.t[firsts])


def test_precision_changes_depth_not_memory(torus):
    rng = np.random.default_rng(3)
    org = rng.uniform(-1, 1, (50, 3))
    dirs = rng.normal(size=(50, 3))
    coarse = intersect_lines(torus, org, dirs, 1e-2, t_range=(-np.inf, np.inf))
    fine = intersect_lines(torus, org, dirs, 1e-8, t_range=(-np.inf, np.inf))
    # the same items (patch nets) whatever the precision: nothing refined is stored (one
    # net per face: every quad of this torus is regular, a patch of its own)
    assert coarse.stats["items"] == fine.stats["items"] == 196
    P = torus.evaluate(fine.ptex, fine.uv)[0]
    assert np.linalg.norm(P - fine.point, axis=1).max() <= 1e-8
    assert len(fine.line) == len(coarse.line) or coarse.tangent.any()


def test_bad_input(torus):
    with pytest.raises(SubtraceError, match="precision"):
        intersect_lines(torus, [[0, 0, 0]], [[1, 0, 0]], 0.0)
    with pytest.raises(SubtraceError, match="non-zero"):
        intersect_lines(torus, [[0, 0, 0]], [[0, 0, 0]], 1e-3)
    with pytest.raises(SubtraceError, match="shape"):
        intersect_lines(torus, [[0, 0]], [[1, 0]], 1e-3)
    with pytest.raises(SubtraceError, match="mode"):
        intersect_lines(torus, [[0, 0, 0]], [[1, 0, 0]], 1e-3, mode="nearest")
    assert subtrace.intersect_lines is intersect_lines


# ---------------------------------------------------------------------------------------
# CLI
# ---------------------------------------------------------------------------------------


def _write_cage(path, cage):
    fv = cage.face_verts.reshape(-1, 4) + 1
    path.write_text("".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in cage.points.tolist())
                    + "".join(f"f {a} {b} {c} {d}\n" for a, b, c, d in fv.tolist()))


def test_cli_intersect(tmp_path, torus, capsys):
    cage = tmp_path / "torus.obj"
    _write_cage(cage, torus)
    lines = tmp_path / "lines.csv"
    lines.write_text("ox,oy,oz,dx,dy,dz\n-3,0,0,1,0,0\n0,0,5,0,0,-1\n")
    out = tmp_path / "hits.csv"
    assert main(["intersect", str(cage), "--lines", str(lines), "--precision", "0.001",
                 "-o", str(out)]) == 0
    rows = out.read_text().splitlines()
    assert rows[0] == "line,t,x,y,z,ptex,u,v,nx,ny,nz,tangent"
    assert len(rows) == 5 and all(r.startswith("0,") for r in rows[1:])
    # with -o, one line says what was written
    said = capsys.readouterr().out
    assert said == f"{out}: 4 hits on 1 of 2 lines (precision 0.001)\n"
    js = tmp_path / "hits.json"
    assert main(["intersect", str(cage), "--lines", str(lines), "--precision", "0.001",
                 "--json", "-o", str(js)]) == 0
    data = json.loads(js.read_text())
    assert len(data["hits"]) == 4 and data["hits"][0]["line"] == 0
    # bad input: one line on stderr, exit 2, no output file
    capsys.readouterr()
    bad = tmp_path / "bad.csv"
    for args in (["--precision", "-1"], ["--precision", "x"]):
        assert main(["intersect", str(cage), "--lines", str(lines), "-o", str(bad)]
                    + args) == 2
    lines.write_text("ox,oy,dx\n1,2,3\n")
    assert main(["intersect", str(cage), "--lines", str(lines), "--precision", "0.01",
                 "-o", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and all(e.startswith("subtrace: error: ") for e in err)
    assert "missing column" in err[-1]
    assert not bad.exists()


def _cell_errors(cage, precision):
    """Isolate every irregular patch of ``cage`` at ``precision`` and return, per cell (a
    flat stand-in of exact limit corners), the largest distance between the exact surface
    (``cage.evaluate``) and the cell's bilinear patch at the same parameters (3 x 3
    samples inside; at most 300 cells), the number of cells, and the largest proven bound
    (one-ring box diagonal) of the interior cells."""
    items = items_for(cage, precision)
    items._isolate(items.irregular)
    items._finish()
    cell = np.nonzero(~items.all_exact)[0]
    if len(cell) > 300:  # (a fixed sample: the evaluator's cost)
        cell = np.random.default_rng(0).choice(cell, 300, replace=False)
    g = np.array([0.25, 0.5, 0.75])  # (the corners are exact)
    s, t = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    net = items.all_nets[cell]
    c0, c1, c2, c3 = net[:, 0, 0], net[:, 3, 0], net[:, 3, 3], net[:, 0, 3]
    w = [((1 - s) * (1 - t))[None, :, None], (s * (1 - t))[None, :, None],
         (s * t)[None, :, None], ((1 - s) * t)[None, :, None]]
    bil = w[0] * c0[:, None] + w[1] * c1[:, None] + w[2] * c2[:, None] + w[3] * c3[:, None]
    uv = items.all_uv0[cell][:, None] + items.all_scale[cell][:, None, None] * np.stack(
        [s, t], axis=1)[None]
    P, _, _ = cage.evaluate(np.repeat(items.all_ptex[cell], len(s)), uv.reshape(-1, 2))
    err = np.linalg.norm(P.reshape(bil.shape) - bil, axis=2).max(axis=1)
    return err, len(cell), items.cell_bound


@pytest.mark.parametrize("path, precision", [(MODELS / "spot_control_mesh.obj", 3e-2),
                                             (SHAPES / "catmark_pole8.obj", 3e-2),
                                             (SHAPES / "catmark_fan.obj", 3e-2)],
                         ids=["spot_control_mesh", "catmark_pole8", "catmark_fan"])
def test_cells_lie_within_half_the_precision_of_the_surface(path, precision):
    """A Catmull-Clark cell (the flat stand-in next to an extraordinary vertex or a feature)
    is refined until its one-ring box's diagonal is at most precision / 2, a proven bound:
    the exact surface at any parameter of the cell is that close to the cell's bilinear
    patch at the same parameter (here at a coarse precision, where cells are large). The
    errors measured are far below it (1-3 % of precision / 2): the bound is what guarantees
    them, so it is checked itself."""
    err, n, bound = _cell_errors(subtrace.load_cage(path), precision)
    assert n > 0
    assert 0.0 < bound <= 0.5 * precision
    assert err.max() <= 0.5 * precision


@pytest.mark.parametrize("scheme", ["catmark", "loop"])
def test_shared_edge_hit_depends_on_the_line_alone(torus, scheme):
    """A line through patch corners and edges (shared by several ptex faces) reports the same
    hits, ptex faces included, whether it is asked alone or among other lines (which change
    which items get built, and in what order): of duplicates the lowest ptex face is kept."""
    cage = torus if scheme == "catmark" else subtrace.make_cage(
        torus.points, [3] * (2 * len(torus.face_sizes)),
        np.ravel([[q[0], q[1], q[2], q[0], q[2], q[3]]
                  for q in torus.face_verts.reshape(-1, 4)]), scheme="loop")
    # lines along the axes and diagonals through the torus's vertices and edge midpoints
    lines = [([-3.0, 0, 0], [1.0, 0, 0]), ([0, -3.0, 0], [0, 1.0, 0]),
             ([-3.0, -3.0, 0], [1.0, 1.0, 0]), ([-3.0, 0, 0.2], [1.0, 0, 0])]
    rng = np.random.default_rng(7)
    lo, hi = cage.bounds()
    others_o = rng.uniform(lo, hi, (300, 3))
    others_d = rng.normal(size=(300, 3))
    for o, d in lines:
        alone = intersect_lines(cage, [o], [d], PREC)
        at = 137
        org = np.insert(others_o, at, o, axis=0)
        dirs = np.insert(others_d, at, d, axis=0)
        among = intersect_lines(cage, org, dirs, PREC)
        idx = among.of_line(at)
        assert len(alone) == len(idx) and len(alone) > 0
        np.testing.assert_array_equal(alone.ptex, among.ptex[idx])
        np.testing.assert_allclose(alone.t, among.t[idx], atol=PREC)


def test_precision_below_floating_point_is_said(torus):
    """A precision finer than double precision resolves at the cage's scale is not silently
    ignored: one warning says what the hits are within instead."""
    import warnings

    from subtrace.errors import SubtraceWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        h = intersect_lines(torus, [[-3.0, 0.1, 0.05]], [[1.0, 0, 0]], 1e-17)
    said = [w for w in caught if issubclass(w.category, SubtraceWarning)]
    assert len(said) == 1 and "double precision" in str(said[0].message)
    assert len(h) > 0
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        intersect_lines(torus, [[-3.0, 0.1, 0.05]], [[1.0, 0, 0]], 1e-6)
    assert not [w for w in caught if issubclass(w.category, SubtraceWarning)]
