"""Trimming curves and loops in a surface's parameter plane, and their monotone units.

A :class:`TrimCurve` is a 2-D (rational) B-spline, OBJ ``curv2``: ``control (n, 3)`` float64
homogeneous ``(u w, v w, w)``. A :class:`TrimLoop` is a closed chain of pieces of such
curves (OBJ ``trim`` / ``hole``), converted to rational Bezier segments
(``segments[k] (d_k + 1, 3)``, homogeneous) with the loop's joints ``joints (K, 2)``:
``joints[k]`` is the start of segment k and the end of segment k - 1 (exactly the same
numbers, so the parity rule of the trim test sees a closed loop). Outer loops run
counter-clockwise, holes clockwise (the reader turns loops that do not).

:func:`monotone_units` splits every segment at the parameters where ``u`` or ``v`` has a
derivative of zero: each *unit* is then monotone in both coordinates, so the box of its two
end points is its bounding box, and a horizontal line meets it at most once. Units are
returned as flat arrays (:class:`Units`) for the trim kd-tree (:mod:`subtrace.nurbs.trimtree`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from subtrace.config import TRIM_CLOSURE_TOL
from subtrace.errors import NurbsError
from subtrace.nurbs.knots import (
    bezier_segments,
    check_degree,
    check_knots,
    split_bezier,
)

_ROOT_EDGE = 1e-9  # extrema closer than this to a segment's end (in its [0,1]) are its end
_ROOT_DEPTH = 40  # halvings of the root search before a tangency is taken as one root
_AREA_SAMPLES = 16  # points per segment of the polygon whose area gives a loop's orientation


@dataclass(frozen=True, eq=False)
class TrimCurve:
    """A 2-D B-spline in a surface's parameter plane (OBJ ``curv2``)."""

    degree: int
    knots: np.ndarray  # (n + degree + 1,) float64
    control: np.ndarray  # (n, 3) float64, homogeneous (u w, v w, w)
    rational: bool

    @property
    def domain(self) -> tuple[float, float]:
        return float(self.knots[self.degree]), float(self.knots[len(self.control)])


@dataclass(frozen=True, eq=False)
class TrimLoop:
    """A closed loop of rational Bezier segments (see the module comment)."""

    hole: bool
    segments: tuple  # of (d + 1, 3) float64 arrays, homogeneous, in loop order
    joints: np.ndarray  # (K, 2) float64: start of segment k = end of segment k - 1


@dataclass(frozen=True, eq=False)
class Units:
    """Monotone curve units of a set of loops, flat (the trim kd-tree's input).

    ctrl (n, D+1, 3) float64 homogeneous Bezier points (rows past a unit's degree are 0);
    degree (n,) int32; p0 / p1 (n, 2) float64 the exact end points (shared bit for bit with
    the neighbouring units); loop (n,) int32 the loop index."""

    ctrl: np.ndarray
    degree: np.ndarray
    p0: np.ndarray
    p1: np.ndarray
    loop: np.ndarray

    def __len__(self) -> int:
        return len(self.degree)


def make_curve(degree: int, knots, points, weights=None) -> TrimCurve:
    """A validated :class:`TrimCurve` from a knot vector, ``points (n, 2)`` and optional
    positive ``weights (n,)`` (None: polynomial)."""
    check_degree(degree)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(points) < degree + 1:
        raise NurbsError(f"a degree-{degree} curve needs at least {degree + 1} control "
                         f"points, got {len(points)}")
    check_knots(knots, degree, len(points), "u")
    w = np.ones(len(points)) if weights is None else np.asarray(weights, dtype=np.float64)
    bad = np.nonzero(~(w > 0) | ~np.isfinite(w))[0]
    if len(bad):
        raise NurbsError(f"control point {bad[0] + 1} has weight {w[bad[0]]:g}; weights of a "
                         "rational curve must be positive")
    control = np.column_stack([points * w[:, None], w])
    return TrimCurve(degree, np.asarray(knots, dtype=np.float64), control, weights is not None)


def project(h: np.ndarray) -> np.ndarray:
    """Homogeneous (..., 3) -> points (..., 2)."""
    return h[..., :2] / h[..., 2:3]


def curve_piece(curve: TrimCurve, t0: float, t1: float) -> list:
    """Bezier segments of ``curve`` from parameter t0 to t1 (reversed when t0 > t1)."""
    lo, hi = curve.domain
    a, b = min(t0, t1), max(t0, t1)
    if a < lo or b > hi:
        raise NurbsError(f"curve range [{t0:g}, {t1:g}] leaves the curve's domain "
                         f"[{lo:g}, {hi:g}]")
    if a == b:
        raise NurbsError(f"curve range [{t0:g}, {t1:g}] is empty")
    segments, _ = bezier_segments(curve.knots, curve.control, curve.degree, a, b)
    segs = [s.copy() for s in segments]
    if t0 > t1:
        segs = [s[::-1].copy() for s in reversed(segs)]
    return segs


def make_loop(pieces, hole: bool, domain) -> TrimLoop:
    """A validated, closed and oriented :class:`TrimLoop`.

    pieces: (t0, t1, TrimCurve) in loop order; domain: the surface's parameter rectangle
    (u0, u1, v0, v1). NurbsError when consecutive pieces leave a gap above TRIM_CLOSURE_TOL
    of the rectangle's larger side, or the loop leaves the rectangle by more than that.
    """
    segments = []
    starts = []  # (index of the piece's first segment, piece number)
    for number, (t0, t1, curve) in enumerate(pieces, 1):
        try:
            segs = curve_piece(curve, t0, t1)
        except NurbsError as err:
            raise NurbsError(f"curve {number} of the loop: {err}") from None
        starts.append(len(segments))
        segments += segs
    u0, u1, v0, v1 = domain
    tol = TRIM_CLOSURE_TOL * max(u1 - u0, v1 - v0)
    ends = np.array([project(s[-1]) for s in segments])
    begins = np.array([project(s[0]) for s in segments])
    previous = np.roll(ends, 1, axis=0)
    gaps = np.hypot(*(begins - previous).T)
    worst = int(np.argmax(gaps))
    if gaps[worst] > tol:
        if worst in starts:  # between two curves of the loop
            k = starts.index(worst)
            after, before = f"curve {k + 1}", f"curve {k if k else len(pieces)}"
        else:  # inside one curve (a knot of multiplicity degree + 1 breaks it)
            k = max(i for i, s in enumerate(starts) if s <= worst)
            after, before = f"a segment of curve {k + 1}", "its previous segment"
        raise NurbsError(
            f"trim loop is not closed: {after} starts at ({begins[worst][0]:g}, "
            f"{begins[worst][1]:g}), {gaps[worst]:.3g} away from the end of {before} "
            f"({previous[worst][0]:g}, {previous[worst][1]:g}); the closure tolerance is "
            f"{tol:.3g} ({TRIM_CLOSURE_TOL:g} of the surface's parameter range)")
    joints = previous.copy()  # each segment starts exactly where the previous one ends
    units = monotone_units([TrimLoop(hole, tuple(segments), joints)])
    lo = np.minimum(units.p0, units.p1).min(axis=0)
    hi = np.maximum(units.p0, units.p1).max(axis=0)
    if lo[0] < u0 - tol or hi[0] > u1 + tol or lo[1] < v0 - tol or hi[1] > v1 + tol:
        raise NurbsError(
            f"trim loop spans [{lo[0]:g}, {hi[0]:g}] x [{lo[1]:g}, {hi[1]:g}] in parameter "
            f"space, outside the surface's domain [{u0:g}, {u1:g}] x [{v0:g}, {v1:g}]")
    loop = TrimLoop(hole, tuple(segments), joints)
    if (signed_area(loop) < 0) != hole:
        loop = reverse_loop(loop)
    return loop


def signed_area(loop: TrimLoop) -> float:
    """Area enclosed by the loop, positive when counter-clockwise (shoelace formula over
    _AREA_SAMPLES points of each segment)."""
    t = np.linspace(0.0, 1.0, _AREA_SAMPLES, endpoint=False)
    pts = np.concatenate([project(bezier_points(seg, t)) for seg in loop.segments])
    x, y = pts[:, 0], pts[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def reverse_loop(loop: TrimLoop) -> TrimLoop:
    """The same loop run the other way."""
    segments = tuple(s[::-1].copy() for s in reversed(loop.segments))
    # segment k of the reversed loop starts where old segment K-1-k ended = old joint K-k
    joints = np.roll(loop.joints[::-1], 1, axis=0).copy()
    return TrimLoop(loop.hole, segments, joints)


def bezier_points(ctrl: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Homogeneous points (len(t), k) of the Bezier curve ``ctrl (d+1, k)`` at parameters t
    (de Casteljau, vectorised over t)."""
    t = np.asarray(t, dtype=np.float64)[:, None, None]
    work = np.broadcast_to(ctrl, (t.shape[0],) + ctrl.shape).copy()
    for r in range(len(ctrl) - 1, 0, -1):
        work = (1.0 - t) * work[:, :r] + t * work[:, 1 : r + 1]
    return work[:, 0]


def derivative_numerator(ctrl: np.ndarray, axis: int) -> np.ndarray:
    """Bernstein coefficients (degree 2d - 1) of A'(t) W(t) - A(t) W'(t), the numerator of
    the derivative of coordinate ``axis`` of the rational Bezier ``ctrl (d+1, 3)``: the
    product rule B_i,m B_j,n = C(m,i) C(n,j) / C(m+n,i+j) B_i+j,m+n."""
    d = len(ctrl) - 1
    a, w = ctrl[:, axis], ctrl[:, 2]
    da, dw = d * np.diff(a), d * np.diff(w)
    out = np.zeros(2 * d)
    for i in range(d):
        for j in range(d + 1):
            c = math.comb(d - 1, i) * math.comb(d, j) / math.comb(2 * d - 1, i + j)
            out[i + j] += c * (da[i] * w[j] - dw[i] * a[j])
    return out


def bernstein_roots(coef: np.ndarray, lo: float = 0.0, hi: float = 1.0, depth: int = 0,
                    zero: float | None = None) -> list:
    """Roots in [lo, hi] of the polynomial with Bernstein coefficients ``coef`` over that
    interval, by subdivision: no sign change among the coefficients means no root (the
    curve of the polynomial lies in their hull); one sign change and ends of opposite signs
    mean one root, found by bisection; anything else is halved (de Casteljau)."""
    if zero is None:  # coefficients this small are zero (rounding of the products)
        zero = 1e-14 * float(np.abs(coef).max())
        if zero == 0.0:
            return []  # identically zero: a constant coordinate, no extremum to split at
    c = np.where(np.abs(coef) <= zero, 0.0, coef)
    if np.all(c >= 0) or np.all(c <= 0):
        # no sign change: a root only where the polynomial touches zero at an end
        return []
    changes = int(np.count_nonzero(np.diff(np.sign(c[c != 0])) != 0))
    if (changes == 1 and c[0] * c[-1] < 0) or depth >= _ROOT_DEPTH:
        return [_bisect_root(coef, lo, hi) if c[0] * c[-1] < 0 else 0.5 * (lo + hi)]
    left, right = split_bezier(coef[:, None], 0.5)
    mid = 0.5 * (lo + hi)
    return (bernstein_roots(left[:, 0], lo, mid, depth + 1, zero)
            + bernstein_roots(right[:, 0], mid, hi, depth + 1, zero))


def _bisect_root(coef, lo, hi) -> float:
    """The root in [lo, hi] of the Bernstein polynomial ``coef`` (over [lo, hi]) whose end
    values differ in sign: bisection to the last bit of the parameter."""
    a, b = 0.0, 1.0
    fa = coef[0]
    for _ in range(80):
        m = 0.5 * (a + b)
        if m <= a or m >= b:
            break
        fm = split_bezier(coef[:, None], m)[0][-1, 0]
        if (fm < 0) == (fa < 0):
            a, fa = m, fm
        else:
            b = m
    return lo + 0.5 * (a + b) * (hi - lo)


def extrema(ctrl: np.ndarray) -> np.ndarray:
    """Sorted parameters in (0, 1) where u'(t) or v'(t) of the rational Bezier ``ctrl
    (d+1, 3)`` vanishes (:func:`bernstein_roots` of :func:`derivative_numerator`), those
    within _ROOT_EDGE of an end left out."""
    # a coordinate whose projected control points are monotone is monotone on the curve
    # (positive weights: the curve crosses a line no more often than its control polygon)
    steps = np.diff(project(ctrl), axis=0)
    axes = [axis for axis in (0, 1)
            if not (np.all(steps[:, axis] >= 0) or np.all(steps[:, axis] <= 0))]
    roots = [t for axis in axes for t in bernstein_roots(derivative_numerator(ctrl, axis))
             if _ROOT_EDGE < t < 1.0 - _ROOT_EDGE]
    roots = np.array(sorted(set(roots)), dtype=np.float64)  # (np.unique: numpy.ma)
    if len(roots) > 1:
        roots = roots[np.concatenate(([True], np.diff(roots) > _ROOT_EDGE))]
    return roots


def monotone_units(loops) -> Units:
    """Split every segment of ``loops`` at its extrema (:func:`extrema`) into units monotone
    in u and v; flat :class:`Units` in loop order."""
    ctrls, p0s, p1s, loop_ids = [], [], [], []
    for index, loop in enumerate(loops):
        count = len(loop.segments)
        for k, seg in enumerate(loop.segments):
            start, end = loop.joints[k], loop.joints[(k + 1) % count]
            rest = seg
            done = 0.0
            for t in extrema(seg):
                left, rest = split_bezier(rest, (t - done) / (1.0 - done))
                done = t
                cut = project(left[-1])
                ctrls.append(left)
                p0s.append(start)
                p1s.append(cut)
                start = cut
            ctrls.append(rest)
            p0s.append(start)
            p1s.append(end)
            loop_ids += [index] * (len(ctrls) - len(loop_ids))
    return pack_units(ctrls, p0s, p1s, loop_ids)


def pack_units(ctrls, p0s, p1s, loop_ids) -> Units:
    """Flat :class:`Units` from lists of per-unit control points and end points."""
    n = len(ctrls)
    width = max((len(c) for c in ctrls), default=1)
    ctrl = np.zeros((n, width, 3), dtype=np.float64)
    degree = np.empty(n, dtype=np.int32)
    for k, c in enumerate(ctrls):
        ctrl[k, : len(c)] = c
        degree[k] = len(c) - 1
    return Units(ctrl, degree, np.array(p0s, dtype=np.float64).reshape(n, 2),
                 np.array(p1s, dtype=np.float64).reshape(n, 2),
                 np.array(loop_ids, dtype=np.int32))
