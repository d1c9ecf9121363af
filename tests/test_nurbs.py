"""Tests of subtrace.nurbs: knot insertion and Bezier extraction against plain-Python de Boor
evaluation (tests/naive.py), exactness on a rational cylinder and sphere, the convex-hull
bound of rational patches, monotone curve units, and the trim kd-tree against two parity
oracles (the same unit test over all units, and polynomial roots over whole segments)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import naive
from subtrace.errors import NurbsError
from subtrace.nurbs.bezier import evaluate
from subtrace.nurbs.knots import bezier_segments, elevate, insert_knot, split_bezier
from subtrace.nurbs.model import build_model
from subtrace.nurbs.surface import NurbsSurface, bezier_patches, make_surface
from subtrace.nurbs.trim import (
    TrimLoop,
    make_curve,
    make_loop,
    monotone_units,
    project,
    signed_area,
)
from subtrace.nurbs.trimtree import build_tree, classify_naive

W45 = math.sqrt(0.5)  # weight of the middle point of a rational quadratic quarter circle
EPS = np.finfo(float).eps


# --------------------------------------------------------------------------------------
# random B-splines
# --------------------------------------------------------------------------------------


def random_knots(rng, n, p, clamped):
    """A valid knot vector for n control points of degree p: interior knots random in
    (0, 1) with some repeated up to p times; ends clamped (p + 1 fold) or random."""
    total = n + p + 1
    if clamped:
        inner = np.sort(rng.random(n - p - 1))
        if len(inner) > 1 and rng.random() < 0.5:  # a repeated inner knot
            k = rng.integers(0, len(inner) - 1)
            inner[k + 1] = inner[k]
        knots = np.concatenate([np.zeros(p + 1), inner, np.ones(p + 1)])
    else:
        knots = np.sort(rng.random(total)) * 2.0 - 0.5
    # at most p equal knots inside the domain, p + 1 at clamped ends
    _, counts = np.unique(knots, return_counts=True)
    assert counts.max() <= p + 1
    return knots


def random_surface(seed, rational=True):
    rng = np.random.default_rng(seed)
    du, dv = (int(x) for x in rng.integers(1, 5, size=2))
    nu, nv = du + 1 + int(rng.integers(0, 4)), dv + 1 + int(rng.integers(0, 4))
    ku = random_knots(rng, nu, du, rng.random() < 0.5)
    kv = random_knots(rng, nv, dv, rng.random() < 0.5)
    points = rng.normal(size=(nu * nv, 3)) * 3.0
    weights = rng.uniform(0.2, 5.0, nu * nv) if rational else None
    return make_surface((du, dv), ku, kv, points, weights), rng


def naive_eval(surface, u, v):
    du, dv = surface.degree
    return naive.nurbs_surface_eval(surface.knots_u.tolist(), surface.knots_v.tolist(), du, dv,
                                    surface.control.tolist(), u, v)


# --------------------------------------------------------------------------------------
# knots and Bezier extraction
# --------------------------------------------------------------------------------------


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_knot_insertion_keeps_the_curve(seed):
    rng = np.random.default_rng(seed)
    p = int(rng.integers(1, 6))
    n = p + 1 + int(rng.integers(0, 5))
    knots = random_knots(rng, n, p, rng.random() < 0.5)
    ctrl = np.column_stack([rng.normal(size=(n, 2)), rng.uniform(0.3, 3.0, n)])
    lo, hi = knots[p], knots[n]
    t_new = rng.uniform(lo, hi)
    k2, c2 = insert_knot(knots, ctrl, p, t_new)
    assert len(k2) == len(knots) + 1 and len(c2) == n + 1
    assert np.all(np.diff(k2) >= 0)
    for t in rng.uniform(lo, hi, 10):
        a = naive.deboor_curve(knots.tolist(), p, ctrl, t)
        b = naive.deboor_curve(k2.tolist(), p, c2, t)
        # a few convex combinations of O(1) numbers: rounding of a few ulps of the largest
        assert np.allclose(a, b, rtol=0, atol=1e-12 * np.abs(ctrl).max())


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rational=st.booleans())
def test_bezier_patches_match_de_boor(seed, rational):
    surface, rng = random_surface(seed, rational)
    nets, rects = bezier_patches(surface)
    du, dv = surface.degree
    assert nets.shape[1:] == (du + 1, dv + 1, 4)
    # the patches tile the domain
    u0, u1, v0, v1 = surface.domain
    assert math.isclose(np.sum((rects[:, 1] - rects[:, 0]) * (rects[:, 3] - rects[:, 2])),
                        (u1 - u0) * (v1 - v0), rel_tol=1e-12)
    ids = np.repeat(np.arange(len(nets)), 4)
    r = rects[ids]
    uv = np.column_stack([rng.uniform(r[:, 0], r[:, 1]), rng.uniform(r[:, 2], r[:, 3])])
    degrees = np.tile(np.array(surface.degree, dtype=np.int32), (len(nets), 1))
    P, Pu, Pv = evaluate(nets, degrees, rects, ids, uv)
    scale = np.abs(surface.control[..., :3] / surface.control[..., 3:]).max()
    for k in range(len(ids)):
        nP, nPu, nPv = naive_eval(surface, *uv[k])
        # knot insertion and de Casteljau: convex combinations; weights in [0.2, 5] amplify
        # rounding by at most their ratio (25), so 1e-9 of the net's size is generous
        assert np.allclose(P[k], nP, rtol=0, atol=1e-9 * scale), (P[k], nP)
        # derivatives scale with 1 / (knot span); compare relative to their own size
        for got, want in ((Pu[k], nPu), (Pv[k], nPv)):
            size = max(np.abs(want).max(), scale)
            assert np.allclose(got, want, rtol=0, atol=1e-7 * size), (got, want)


def quarter_cylinder(height=2.0):
    """Rational quadratic x linear: the quarter of the unit cylinder x, y >= 0, 0 <= z <= h."""
    points = []
    weights = []
    for z in (0.0, height):  # v rows
        for (x, y), w in (((1.0, 0.0), 1.0), ((1.0, 1.0), W45), ((0.0, 1.0), 1.0)):
            points.append((x, y, z))
            weights.append(w)
    return make_surface((2, 1), [0, 0, 0, 1, 1, 1], [0, 0, 1, 1], points, weights)


def unit_sphere():
    """The whole unit sphere as one rational biquadratic NURBS: a 9-point circle (u) swept
    along a 5-point half-circle meridian (v)."""
    circle = [((1, 0), 1.0), ((1, 1), W45), ((0, 1), 1.0), ((-1, 1), W45), ((-1, 0), 1.0),
              ((-1, -1), W45), ((0, -1), 1.0), ((1, -1), W45), ((1, 0), 1.0)]
    meridian = [((0, -1), 1.0), ((1, -1), W45), ((1, 0), 1.0), ((1, 1), W45), ((0, 1), 1.0)]
    points, weights = [], []
    for (r, z), wm in meridian:
        for (x, y), wc in circle:
            points.append((r * x, r * y, z))
            weights.append(wm * wc)
    ku = [0, 0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 4]
    kv = [0, 0, 0, 1, 1, 2, 2, 2]
    return make_surface((2, 2), ku, kv, points, weights)


def grid_uv(rects, n=9):
    s = np.linspace(0.0, 1.0, n)
    ids = np.repeat(np.arange(len(rects)), n * n)
    su, sv = np.meshgrid(s, s, indexing="ij")
    r = rects[ids]
    uv = np.column_stack([r[:, 0] + np.tile(su.ravel(), len(rects)) * (r[:, 1] - r[:, 0]),
                          r[:, 2] + np.tile(sv.ravel(), len(rects)) * (r[:, 3] - r[:, 2])])
    return ids, uv


def test_rational_quarter_cylinder_is_exact():
    surface = quarter_cylinder()
    nets, rects = bezier_patches(surface)
    assert len(nets) == 1
    ids, uv = grid_uv(rects, 33)
    P, Pu, Pv = evaluate(nets, np.array([[2, 1]], np.int32), rects, ids, uv)
    radius = np.hypot(P[:, 0], P[:, 1])
    # on the cylinder to rounding: a few ulps of 1
    assert np.abs(radius - 1.0).max() <= 8 * EPS
    assert P[:, 2].min() >= 0.0 and P[:, 2].max() <= 2.0
    # the u-derivative is tangent to the circle, the v-derivative the axis
    assert np.abs(np.einsum("ij,ij->i", Pu[:, :2], P[:, :2])).max() <= 16 * EPS * np.abs(
        Pu).max()
    assert np.allclose(Pv, [0.0, 0.0, 2.0], rtol=0, atol=8 * EPS)


def test_rational_sphere_is_exact():
    surface = unit_sphere()
    nets, rects = bezier_patches(surface)
    assert len(nets) == 8  # 4 quarter circles x 2 quarter meridians
    ids, uv = grid_uv(rects, 17)
    P, Pu, Pv = evaluate(nets, np.tile(np.array([[2, 2]], np.int32), (8, 1)), rects, ids, uv)
    assert np.abs(np.linalg.norm(P, axis=1) - 1.0).max() <= 8 * EPS
    # derivatives are tangent to the sphere (radial part 0 to rounding)
    for d in (Pu, Pv):
        assert np.abs(np.einsum("ij,ij->i", d, P)).max() <= 32 * EPS * np.abs(d).max()
    # and agree with the plain-Python de Boor evaluation of the whole NURBS
    for k in range(0, len(ids), 37):
        nP, nPu, nPv = naive_eval(surface, *uv[k])
        assert np.allclose(P[k], nP, atol=1e-14)
        assert np.allclose(Pu[k], nPu, atol=1e-12) and np.allclose(Pv[k], nPv, atol=1e-12)


@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_positive_weights_keep_the_patch_in_its_control_hull(seed):
    rng = np.random.default_rng(seed)
    du, dv = (int(x) for x in rng.integers(1, 6, size=2))
    points = rng.normal(size=(du + 1, dv + 1, 3))
    w = rng.uniform(0.05, 20.0, size=(du + 1, dv + 1, 1))
    net = np.concatenate([points * w, w], axis=-1)[None]
    ids = np.zeros(400, dtype=np.int64)
    uv = rng.random((400, 2))
    P, _, _ = evaluate(net, np.array([[du, dv]], np.int32), np.array([[0.0, 1.0, 0.0, 1.0]]),
                       ids, uv)
    # the convex hull is the intersection of all slabs: test many directions
    directions = rng.normal(size=(64, 3))
    proj_ctrl = points.reshape(-1, 3) @ directions.T
    proj_p = P @ directions.T
    slack = 1e-12 * np.abs(proj_ctrl).max()
    assert np.all(proj_p >= proj_ctrl.min(axis=0) - slack)
    assert np.all(proj_p <= proj_ctrl.max(axis=0) + slack)


def test_degree_elevation_and_split_keep_the_curve():
    rng = np.random.default_rng(7)
    ctrl = np.column_stack([rng.normal(size=(4, 2)), rng.uniform(0.5, 2.0, 4)])
    up = elevate(ctrl)
    left, right = split_bezier(ctrl, 0.3)
    assert left[-1].tobytes() == right[0].tobytes()
    for t in np.linspace(0, 1, 11):
        a = naive.bezier_curve_point(ctrl, t)
        assert np.allclose(naive.bezier_curve_point(up, t), a, atol=1e-14)
        half = naive.bezier_curve_point(left, t / 0.3) if t <= 0.3 else \
            naive.bezier_curve_point(right, (t - 0.3) / 0.7)
        assert np.allclose(half, a, atol=1e-14)


def test_bezier_segments_of_a_sub_range():
    rng = np.random.default_rng(3)
    knots = np.array([0, 0, 0, 0.3, 0.6, 0.6, 1, 1, 1.0])
    ctrl = np.column_stack([rng.normal(size=(6, 2)), rng.uniform(0.5, 2.0, 6)])
    segs, breaks = bezier_segments(knots, ctrl, 2, 0.1, 0.8)
    assert breaks.tolist() == [0.1, 0.3, 0.6, 0.8]
    for seg, a, b in zip(segs, breaks, breaks[1:]):
        for s in (0.0, 0.4, 1.0):
            want = naive.deboor_curve(knots.tolist(), 2, ctrl, a + s * (b - a))
            got = naive.bezier_curve_point(seg, s)
            assert np.allclose(got, (want[0] / want[2], want[1] / want[2]), atol=1e-13)


@pytest.mark.parametrize("kwargs, words", [
    (dict(params_u=[0, 0, 0.6, 0.4, 1]), "knots must not decrease"),
    (dict(params_u=[0, 0, 0.2, 0.4, 0.6, 1, 1]), "need 15"),
    (dict(params_u=[0, 0, 0, 1, 1]), "repeated 3 times"),
    (dict(weights=[1, 1, 0, 1, 1, 1, 1, 1, 1]), "weight 0"),
    (dict(points=np.zeros((3, 3)), weights=None), "needs at least 4"),
    (dict(domain=(0, 2, 0, 1)), "outside the knot domain"),
])
def test_bad_surfaces_raise(kwargs, words):
    args = dict(degree=(1, 1), params_u=[0, 0, 0.5, 1, 1], params_v=[0, 0, 0.5, 1, 1],
                points=np.zeros((9, 3)), weights=None)
    args.update(kwargs)
    with pytest.raises(NurbsError, match=words):
        make_surface(**args)


# --------------------------------------------------------------------------------------
# trim loops and units
# --------------------------------------------------------------------------------------


def circle_curve(cx, cy, r, clockwise=False):
    pts = np.array([[1, 0], [1, 1], [0, 1], [-1, 1], [-1, 0], [-1, -1], [0, -1], [1, -1],
                    [1, 0]], float)
    if clockwise:
        pts[:, 1] *= -1
    w = [1, W45, 1, W45, 1, W45, 1, W45, 1]
    return make_curve(2, [0, 0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 4], pts * r + [cx, cy], w)


def test_loops_are_oriented_and_closed():
    domain = (0.0, 1.0, 0.0, 1.0)
    cw = circle_curve(0.5, 0.5, 0.3, clockwise=True)
    outer = make_loop([(0, 4, cw)], False, domain)
    hole = make_loop([(0, 4, circle_curve(0.5, 0.5, 0.1))], True, domain)
    assert signed_area(outer) > 0 > signed_area(hole)
    # the area of the inscribed 64-gon: sin(2 pi / 64) * 64 / (2 pi) = 0.9984 of the disc's
    assert math.isclose(signed_area(outer), math.pi * 0.09, rel_tol=2e-3)
    for loop in (outer, hole):
        ends = np.array([project(s[-1]) for s in loop.segments])
        starts = np.array([project(s[0]) for s in loop.segments])
        assert np.allclose(np.roll(ends, 1, axis=0), starts, atol=1e-15)
        assert np.array_equal(np.roll(ends, 1, axis=0), loop.joints) or np.allclose(
            np.roll(ends, 1, axis=0), loop.joints, atol=1e-15)
    # a piece run backwards (u0 > u1) reverses it
    rev = make_loop([(4, 0, circle_curve(0.5, 0.5, 0.3))], True, domain)
    assert signed_area(rev) < 0


@pytest.mark.parametrize("pieces, words", [
    ([(0, 3, "c")], "trim loop is not closed"),
    ([(0, 5, "c")], "leaves the curve's domain"),
    ([(0, 4, "far")], "outside the surface's domain"),
])
def test_bad_loops_raise(pieces, words):
    curves = {"c": circle_curve(0.5, 0.5, 0.3), "far": circle_curve(1.5, 0.5, 0.3)}
    with pytest.raises(NurbsError, match=words):
        make_loop([(a, b, curves[c]) for a, b, c in pieces], False, (0, 1, 0, 1))


def test_closure_tolerance_snaps_small_gaps():
    a = make_curve(1, [0, 0, 1, 1], [[0.2, 0.2], [0.8, 0.2]])
    b = make_curve(1, [0, 0, 1, 1], [[0.8, 0.2 + 1e-7], [0.5, 0.8]])
    c = make_curve(1, [0, 0, 1, 1], [[0.5, 0.8], [0.2, 0.2]])
    loop = make_loop([(0, 1, a), (0, 1, b), (0, 1, c)], False, (0, 1, 0, 1))
    assert loop.joints[1].tolist() == [0.8, 0.2]  # the next curve starts where a ends
    with pytest.raises(NurbsError, match="not closed"):
        b2 = make_curve(1, [0, 0, 1, 1], [[0.8, 0.21], [0.5, 0.8]])
        make_loop([(0, 1, a), (0, 1, b2), (0, 1, c)], False, (0, 1, 0, 1))


def random_loop(rng, segments, degree_max=3):
    """A closed loop of random rational Bezier segments (possibly self-intersecting: the
    parity is defined all the same)."""
    joints = rng.random((segments, 2))
    segs = []
    for k in range(segments):
        d = int(rng.integers(1, degree_max + 1))
        a, b = joints[k], joints[(k + 1) % segments]
        inner = rng.random((d - 1, 2))
        pts = np.vstack([a, inner, b])
        w = rng.uniform(0.3, 3.0, d + 1)
        segs.append(np.column_stack([pts * w[:, None], w]))
    return TrimLoop(False, tuple(segs), joints)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_units_are_monotone(seed):
    rng = np.random.default_rng(seed)
    loop = random_loop(rng, int(rng.integers(1, 6)), degree_max=9)
    units = monotone_units([loop])
    t = np.linspace(0.0, 1.0, 201)
    for k in range(len(units)):
        ctrl = units.ctrl[k, : units.degree[k] + 1]
        pts = np.array([naive.bezier_curve_point(ctrl, s) for s in t])
        assert np.allclose(pts[0], units.p0[k], atol=1e-12)
        assert np.allclose(pts[-1], units.p1[k], atol=1e-12)
        for axis in (0, 1):
            steps = np.diff(pts[:, axis])
            # monotone up to the rounding of the cut at an extremum (found to ~1e-15 in t)
            assert np.all(steps >= -1e-12) or np.all(steps <= 1e-12), (axis, steps.min(),
                                                                        steps.max())
    # consecutive units join exactly
    nxt = np.roll(np.arange(len(units)), -1)
    assert np.array_equal(units.p1, units.p0[nxt])


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_tree_agrees_with_both_parity_oracles(seed):
    rng = np.random.default_rng(seed)
    loops = [random_loop(rng, int(rng.integers(1, 12))) for _ in range(int(rng.integers(1, 4)))]
    units = monotone_units(loops)
    tree = build_tree(units)
    points = rng.random((300, 2)) * 1.2 - 0.1
    fast = tree.classify(points)
    assert np.array_equal(fast, classify_naive(units, points))
    segments = [s for loop in loops for s in loop.segments]
    slow = np.array([naive.trim_parity(segments, *p) for p in points[:60]])
    assert np.array_equal(fast[:60], slow)


def flower_loop(n, k=7, amp=0.25):
    """A wavy closed loop of n cubic segments (Hermite), star-shaped around (0.5, 0.5)."""
    th = np.linspace(0, 2 * np.pi, n, endpoint=False)
    r = 0.35 * (1 + amp * np.sin(k * th))
    dr = 0.35 * amp * k * np.cos(k * th)
    P = np.column_stack([0.5 + r * np.cos(th), 0.5 + r * np.sin(th)])
    D = np.column_stack([dr * np.cos(th) - r * np.sin(th), dr * np.sin(th) + r * np.cos(th)])
    h = 2 * np.pi / n / 3
    segs = [np.column_stack([np.array([P[i], P[i] + h * D[i], P[(i + 1) % n] - h * D[(i + 1) % n],
                                       P[(i + 1) % n]]), np.ones(4)]) for i in range(n)]
    return TrimLoop(False, tuple(segs), P.copy())


def test_deep_tree_agrees_with_the_unit_test_over_all_units():
    rng = np.random.default_rng(11)
    units = monotone_units([flower_loop(2000)])
    tree = build_tree(units)
    assert tree.depth > 10 and len(tree.units) >= len(units)
    assert np.count_nonzero((tree.node_axis < 0) & (tree.node_count == 0)) > 10  # empty leaves
    points = rng.random((4000, 2))
    assert np.array_equal(tree.classify(points), classify_naive(units, points))


def test_points_near_curves_and_holes():
    domain = (0.0, 1.0, 0.0, 1.0)
    outer = make_loop([(0, 4, circle_curve(0.5, 0.5, 0.4))], False, domain)
    hole = make_loop([(0, 4, circle_curve(0.5, 0.5, 0.15))], True, domain)
    tree = build_tree(monotone_units([outer, hole]))
    rng = np.random.default_rng(5)
    theta = rng.uniform(0, 2 * np.pi, 2000)
    for radius, inside in ((0.4 * (1 - 1e-9), True), (0.4 * (1 + 1e-9), False),
                           (0.15 * (1 - 1e-9), False), (0.15 * (1 + 1e-9), True),
                           (0.3, True), (0.05, False), (0.6, False)):
        pts = np.column_stack([0.5 + radius * np.cos(theta), 0.5 + radius * np.sin(theta)])
        got = tree.classify(pts)
        # 1e-9 of the radius is far above the rounding of a rational quadratic (1e-16)
        assert np.all(got == inside), (radius, np.count_nonzero(got != inside))


def sawtooth_loop(teeth):
    """A polygon (linear segments) with vertices on the integer grid: base from (0,0) to
    (2*teeth, 0), then a sawtooth top with valleys at height 1 and peaks at height 2."""
    pts = [(0, 0), (2 * teeth, 0)]
    for k in range(teeth, 0, -1):
        pts += [(2 * k, 1), (2 * k - 1, 2)]
    pts.append((0, 1))
    pts = np.array(pts, dtype=float)
    segs = tuple(np.array([[*pts[i], 1.0], [*pts[(i + 1) % len(pts)], 1.0]])
                 for i in range(len(pts)))
    return TrimLoop(False, segs, pts)


def test_rays_through_loop_vertices():
    teeth = 50
    units = monotone_units([sawtooth_loop(teeth)])
    tree = build_tree(units)
    x = np.arange(-3, 2 * teeth + 3) + 0.25
    for y, inside in ((1.0, lambda x: (0 < x) & (x < 2 * teeth)),  # through the valleys
                      (2.0, lambda x: np.zeros_like(x, dtype=bool)),  # through the peaks
                      (0.5, lambda x: (0 < x) & (x < 2 * teeth)),
                      (1.5, lambda x: (0 < x) & (x < 2 * teeth)
                       & (np.abs((x % 2) - 1) < 0.5))):
        pts = np.column_stack([x, np.full_like(x, y)])
        want = inside(x)
        assert np.array_equal(tree.classify(pts), want), y
        assert np.array_equal(classify_naive(units, pts), want), y


def test_model_tables_and_trims():
    surface = quarter_cylinder()
    domain = surface.domain
    hole = make_loop([(0, 4, circle_curve(0.5, 0.5, 0.2))], True, domain)
    trimmed = NurbsSurface(surface.degree, surface.knots_u, surface.knots_v, surface.control,
                           domain, True, (hole,), 3)
    model = build_model([unit_sphere(), trimmed, quarter_cylinder()])
    assert model.nets.shape == (10, 3, 3, 4)
    assert model.patch_degree.tolist() == [[2, 2]] * 8 + [[2, 1]] * 2
    assert model.surface_trim.tolist()[0] == -1 and model.surface_trim[1] >= 0
    assert model.surface_trim[2] == -1 and model.surface_material.tolist() == [-1, 3, -1]
    assert model.surface_loops.tolist() == [[0, 0], [0, 1], [0, 0]]
    assert model.surface_trim_invert.tolist() == [False, True, False]
    # the padding does not change the cylinder's patch
    P, _, _ = evaluate(model.nets, model.patch_degree, model.patch_rect, [8], [[0.3, 0.4]])
    assert abs(math.hypot(P[0, 0], P[0, 1]) - 1.0) <= 8 * EPS
    uv = np.array([[0.5, 0.5], [0.9, 0.9], [0.5, 0.5], [0.5, 0.5]])
    got = model.inside([1, 1, 0, 2], uv)
    assert got.tolist() == [False, True, True, True]  # the hole, the rest, untrimmed


def test_the_rectangle_and_its_sides_are_always_kept():
    # an outer loop along the rectangle's sides is dropped; holes alone invert the tree:
    # points on the sides (where the patches of a closed surface meet) stay inside
    surface = quarter_cylinder()
    domain = surface.domain
    hole = make_loop([(0, 4, circle_curve(0.5, 0.5, 0.2))], True, domain)
    edges = [make_curve(1, [0, 0, 1, 1], [a, b]) for a, b in
             (([0, 0], [1, 0]), ([1, 0], [1, 1]), ([1, 1], [0, 1]), ([0, 1], [0, 0]))]
    outer = make_loop([(0, 1, c) for c in edges], False, domain)
    inner = make_loop([(0, 4, circle_curve(0.5, 0.5, 0.45))], False, domain)
    variants = {"holes": (hole,), "rect + hole": (outer, hole),
                "rect + loop + hole": (outer, inner, hole)}
    sides = np.array([[0.0, 0.3], [1.0, 0.3], [0.3, 0.0], [0.3, 1.0], [1.0, 1.0], [0.0, 0.0],
                      [0.5, 0.5], [0.5, 0.8]])
    for name, loops in variants.items():
        s = NurbsSurface(surface.degree, surface.knots_u, surface.knots_v, surface.control,
                         domain, True, loops)
        got = build_model([s]).inside(np.zeros(len(sides), np.int64), sides).tolist()
        if name == "rect + loop + hole":  # the circle of radius 0.45 is the outline now
            assert got == [False] * 6 + [False, True], name
        else:
            assert got == [True] * 6 + [False, True], name
