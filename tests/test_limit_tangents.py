"""Limit tangents and normals: crease masks, the eigen-analysis, and the normals that
``evaluate`` gives at extraordinary ptex corners (``subdiv/limit.py``,
``patches/evaluate.py``). The comparison with OpenSubdiv itself is in ``test_oracle.py``.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from shared_data import COMPILE_LISTENER, run_fresh
from subtrace import make_cage
from subtrace.patches import basis, evaluate as ev
from subtrace.subdiv import limit
from subtrace.subdiv.refine import refine_level, refine_points
from test_properties import PROPS, _ptex_samples, cages


def _unit(a):
    return a / np.linalg.norm(a, axis=-1, keepdims=True)


@pytest.mark.parametrize("is_loop", [False, True])
@pytest.mark.parametrize("m", range(1, 13))
def test_cross_tangent_masks_annihilate_constants(is_loop, m):
    """A tangent mask's weights sum to 0 (the tangent of a translated cage is the same)."""
    if is_loop:
        wv, wc, wi = limit._loop_cross_tangent(m)
        total = wv + 2 * wc + wi * sum(limit._cross_edge_weight(True, m, i) for i in range(1, m))
    else:
        wv, wc, wi = limit._catmark_cross_tangent(m)
        total = wv + 2 * wc + wi * sum(limit._cross_edge_weight(None, m, i) for i in range(1, m))
        if m >= 2:
            total += wi * sum(limit._catmark_cross_face_weight(m, i) for i in range(m))
    # 1e-14: a dozen float64 sines and cosines summed
    assert abs(total) < 1e-14 * max(1.0, abs(wv), abs(wc))


def _cube(crease=None):
    """A unit cube around the origin, faces counter-clockwise seen from outside."""
    pts = np.array([[x, y, z] for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)], float)
    quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]]
    kw = {} if crease is None else dict(crease_edges=[crease], crease_sharpness=[np.inf])
    return pts, np.full(6, 4), np.concatenate(quads), kw


def _octahedron(crease=None):
    pts = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    tris = [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]
    kw = {} if crease is None else dict(crease_edges=[crease], crease_sharpness=[np.inf])
    return pts, np.full(8, 3), np.concatenate(tris), kw


@pytest.mark.parametrize("shape", [_cube, _octahedron])
@pytest.mark.parametrize("mirror", [False, True])
def test_dart_normals_follow_the_winding(shape, mirror):
    """One infinitely sharp edge makes both its ends darts, which take the eigen-analysis.
    Their normal points out of the convex cage, whose faces wind counter-clockwise seen from
    outside; mirroring the points (same faces) makes the winding clockwise seen from
    outside, so the normal must point in: the orientation comes from the ring order, not
    from the geometry."""
    pts, sizes, verts, kw = shape(crease=(0, 2))
    if mirror:
        pts = pts * np.array([-1.0, 1.0, 1.0])
    cage = make_cage(pts, sizes, verts, **kw)
    cls = limit.classify(cage.base, cage.options)
    assert cls[0] == cls[2] == limit.HARD_STATIONARY
    for level in (0, 1, 2):
        P, du, dv = cage.limit(level)
        n = np.cross(du, dv)
        out = np.einsum("ij,ij->i", _unit(n[[0, 2]]), _unit(P[[0, 2]]))
        # the tangent plane at a dart of a symmetric convex cage is not tilted far
        assert np.all(out < -0.5) if mirror else np.all(out > 0.5), out


_HEX_TORUS = [[0, 1, 2, 5, 4, 3], [2, 0, 3, 5], [3, 4, 7, 6], [4, 5, 8, 7], [5, 3, 6, 8],
              [6, 7, 8, 2, 1, 0], [8, 6, 0, 2]]  # fmt: skip


def test_ring_matrix_lists_the_child_ring_slot_by_slot():
    """The one-ring subdivision matrix of a regular vertex is the regular Catmull-Clark one
    (the child ring lists the children of the parent ring slot by slot), here on level 1 of
    a small torus with hexagons."""
    rng = np.random.default_rng(0)
    faces = _HEX_TORUS
    cage = make_cage(rng.normal(size=(9, 3)), [len(f) for f in faces], np.concatenate(faces))
    lev = cage.level_topology(1)
    expected = np.sort([1, 1 / 2, 1 / 2, 1 / 4, 1 / 4, 1 / 4, 1 / 8, 1 / 8, 1 / 16])
    regular = np.nonzero(np.diff(lev.vert_edge_offsets) == 4)[0]
    # (on this small cage some level-1 rings touch themselves: those list fewer points)
    regular = [v for v in regular if len(limit.ring_of(lev, int(v))) == 9]
    assert len(regular) > 0
    for v in regular:
        A, *_ = limit.ring_matrix(lev, cage.options, int(v))
        # 1e-12: eigenvalues of a 9x9 matrix of dyadic weights
        np.testing.assert_allclose(np.sort(np.abs(np.linalg.eigvals(A))), expected, atol=1e-12)


def _level_invariance(cage):
    """Limit points and normals of the base vertices whose tangents are exact (smooth and
    eigen-analysed ones) must not depend on the level they are computed from: a vertex
    keeps its index through refinement."""
    cls = limit.classify(cage.base, cage.options)
    keep = np.isin(cls, (limit.SMOOTH, limit.HARD_STATIONARY)) & cage.base.vert_manifold
    P0, du0, dv0 = cage.limit(0)
    P1, du1, dv1 = cage.limit(1)
    n = cage.base.n_verts
    scale = max(1.0, float(np.abs(cage.points).max()))
    # 1e-9: the same limit reached through different masks, up to rounding
    assert np.abs(P0[keep] - P1[:n][keep]).max(initial=0) <= 1e-9 * scale
    a, b = np.cross(du0, dv0)[keep], np.cross(du1, dv1)[:n][keep]
    tiny = 1e-9 * scale**2
    ok = (np.linalg.norm(a, axis=1) > tiny) & (np.linalg.norm(b, axis=1) > tiny)
    cos = np.einsum("ij,ij->i", _unit(a[ok]), _unit(b[ok]))
    assert np.all(cos > 1 - 1e-9), cos.min(initial=1)


def test_eigen_limit_refines_a_ring_that_changes_shape():
    """Vertex 0 of the hexagon torus has a level-0 ring of 9 distinct points (two hexagons
    and two quads on a cage so small that it touches itself) and a level-1 ring of 9 points
    too: a square "subdivision matrix" that maps the ring to a different one. Before the fix
    the eigen-analysis took it and gave a tangent plane 1 degree off the true one."""
    pts = np.array(
        [[2.83003016, 0.06856816, -0.09362968], [-1.53345601, 2.35736194, 0.0472299],
         [-1.3813203, -2.52985245, -0.02021076], [1.65078919, -0.0231646, 0.73277564],
         [-0.65976921, 1.44056009, 0.66030777], [-0.89382423, -1.43185245, 0.69614012],
         [1.71736282, 0.08266918, -0.74737634], [-0.67273493, 1.37691361, -0.63469267],
         [-0.91783781, -1.50427758, -0.78224809]]
    )  # fmt: skip
    faces = _HEX_TORUS
    _level_invariance(make_cage(pts, [len(f) for f in faces], np.concatenate(faces)))


@PROPS
@given(cages())
def test_limit_does_not_depend_on_the_level(spec):
    _level_invariance(spec.build())


def test_box_spline_basis_is_the_limit_at_dyadic_points():
    """Re-derive evaluate's quartic box-spline basis: on a regular triangle lattice whose
    points are the lattice coordinates (so that refined points sit at their parameters),
    the exact limit at the 15 vertices of the central triangle's level-2 refinement (the
    regular limit mask 1/2, 1/12 x 6) fixes the quartic of every control point."""
    R = 4
    ids = {}
    for i in range(-R, R + 1):
        for j in range(-R, R + 1):
            if abs(i + j) <= R:
                ids[(i, j)] = len(ids)
    tris = []
    for (i, j), a in ids.items():
        if (i + 1, j) in ids and (i, j + 1) in ids:
            tris.append([a, ids[(i + 1, j)], ids[(i, j + 1)]])
            if (i + 1, j + 1) in ids:
                tris.append([ids[(i + 1, j)], ids[(i + 1, j + 1)], ids[(i, j + 1)]])
    pts = np.array([[i, j, 0.0] for (i, j) in ids])
    cage = make_cage(pts, np.full(len(tris), 3), np.concatenate(tris), scheme="loop")
    lev, X, W = cage.base, pts, np.eye(len(pts))
    for _ in range(2):
        ref = refine_level(lev, cage.options)
        X, W, lev = refine_points(ref, X), refine_points(ref, W), ref.child
    rows, uv = [], []
    for a, b in basis.BOX_MONO:  # 15 points (a/4, b/4) with a + b <= 4
        q = np.array([a, b]) / 4.0
        v = int(np.argmin(np.linalg.norm(X[:, :2] - q, axis=1)))
        assert np.linalg.norm(X[v, :2] - q) < 1e-12
        ring = lev.vert_edges[lev.vert_edge_offsets[v] : lev.vert_edge_offsets[v + 1]]
        far = [y if x == v else x for x, y in lev.edge_verts[ring]]
        rows.append(0.5 * W[v] + W[far].sum(axis=0) / 12.0)
        uv.append(q)
    rows = np.array(rows)
    cols = [ids[tuple(p)] for p in basis.BOX_POINTS]
    # only the 12 points around the triangle carry weight
    others = np.delete(rows, cols, axis=1)
    assert np.abs(others).max() < 1e-15
    V = np.array([[u**a * v**b for a, b in basis.BOX_MONO] for u, v in uv])
    coef = np.linalg.solve(V, rows[:, cols])
    # 1e-12: a 15x15 solve at dyadic points; the table is exact (multiples of 1/24)
    np.testing.assert_allclose(coef, basis.BOX_COEF, atol=1e-12)


@PROPS
@given(cages(), st.integers(0, 2**32 - 1))
def test_corner_normals_are_the_limit_normals(spec, seed):
    """At a ptex corner on a smooth extraordinary vertex (on level 1, where every face has
    the scheme's size), evaluate's dP/du x dP/dv is the limit normal of that vertex, with
    the same orientation. Also, at random points the derivatives are finite."""
    cage = spec.build()
    lev1 = cage.level_topology(1)
    cls1 = limit.classify(lev1, cage.options)
    _, du, dv = cage.limit(1)
    n1 = np.cross(du, dv)
    is_loop = cage.scheme == "loop"
    table = ev._TRI_UV if is_loop else ev._QUAD_UV
    regular_valence = 6 if is_loop else 4
    valence = np.diff(lev1.vert_edge_offsets)
    base, subface, _ = ev.ptex_layout(cage)
    fo = cage.base.face_offsets
    faces, uvs, verts = [], [], []
    for ptex in range(len(base)):
        f, s = base[ptex], subface[ptex]
        if cage.face_hole[f]:
            continue
        for k, corner in enumerate(table):
            c = 4 * f + (k if s < 0 else s) if is_loop else fo[f] + (k if s < 0 else s)
            w = lev1.face_verts[lev1.face_offsets[c] + k]
            if cls1[w] == limit.SMOOTH and valence[w] != regular_valence:
                faces.append(ptex)
                uvs.append(corner)
                verts.append(w)
    if faces:
        _, dPdu, dPdv = cage.evaluate(np.array(faces), np.array(uvs, dtype=float))
        n = np.cross(dPdu, dPdv)
        cos = np.einsum("ij,ij->i", _unit(n), _unit(n1[verts]))
        # the same tangent masks on the same level-1 points: only rounding differs
        assert np.all(cos > 1 - 1e-9), cos.min()
    f, uv = _ptex_samples(cage, np.random.default_rng(seed), 16)
    if f is not None:
        _, dPdu, dPdv = cage.evaluate(f, uv)
        assert np.all(np.isfinite(dPdu)) and np.all(np.isfinite(dPdv))


_SCHEME_PROBE = COMPILE_LISTENER + """
import json, sys
import numpy as np
from subtrace import make_cage
from subtrace.subdiv.limit import limit_points
from subtrace.subdiv.refine import refine_level, refine_points
faces = {"catmark": [[0, 1, 2, 3], [3, 2, 4, 5]], "loop": [[0, 1, 2], [0, 2, 3], [2, 4, 3]]}
pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0.2], [0, 1, 0], [1, 2, 0.1], [0, 2, 0.3]], float)
f = faces[sys.argv[1]]
cage = make_cage(pts, [len(x) for x in f], np.concatenate(f), scheme=sys.argv[1])
ref = refine_level(cage.base, cage.options)
q = refine_points(ref, cage.points)
P, du, dv = limit_points(ref.child, q, cage.options)
print(json.dumps({"compiled": compiled, "finite": bool(np.isfinite(P).all())}))
"""


@pytest.mark.parametrize("scheme, other", [("catmark", "loop"), ("loop", None)])
def test_a_catmark_cage_compiles_none_of_loops_masks(tmp_path, scheme, other):
    """subdiv.refine.scheme_flag: refining and taking limits of a Catmull-Clark cage, in a
    fresh process on an empty cache, compiles none of Loop's weight functions (the kernels'
    branches on the scheme are pruned before typing); a Loop cage compiles Loop's."""
    import json

    out = json.loads(run_fresh(_SCHEME_PROBE, scheme, cache=tmp_path / "cache"))
    assert out["finite"]
    ours = [c for c in out["compiled"] if c.startswith(f"subtrace.subdiv.{scheme}.")]
    theirs = [c for c in out["compiled"] if other and c.startswith(f"subtrace.subdiv.{other}.")]
    assert ours and not theirs, out["compiled"]


_CREASE_PROBE = COMPILE_LISTENER + """
import json, sys
import numpy as np
from subtrace import make_cage
from subtrace.subdiv.limit import limit_points
pts = np.array([[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)])
cube = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
faces = cube if sys.argv[1] == "closed" else cube[:5]  # (open: a box without its lid)
cage = make_cage(pts, [4] * len(faces), np.concatenate(faces))
P, du, dv = limit_points(cage.base, cage.points, cage.options)
print(json.dumps({"compiled": compiled, "finite": bool(np.isfinite(P).all())}))
"""


@pytest.mark.parametrize("shape, creases", [("closed", False), ("open", True)])
def test_a_cage_without_crease_vertices_compiles_no_crease_rule(tmp_path, shape, creases):
    """subdiv.limit._closed_form: the closed-form limits of a closed smooth cage, in a fresh
    process on an empty cache, compile none of the crease rule's cross-tangent weights (the
    kernel's crease branch is pruned before typing); an open one (its boundary vertices
    are creases) compiles them."""
    import json

    out = json.loads(run_fresh(_CREASE_PROBE, shape, cache=tmp_path / "cache"))
    names = {c.rpartition(".")[2] for c in out["compiled"]}
    assert out["finite"] and "_closed_form_kernel" in names, out["compiled"]
    assert ("_catmark_cross_face_weight" in names) == creases, out["compiled"]
