"""Knot vectors of B-spline curves and surfaces: checks, Boehm knot insertion, Bezier
extraction and degree elevation (numpy, build time only; no kernels).

Control points are rows of a float64 array ``ctrl (n, k)``: homogeneous coordinates for
rational data (``(x w, y w, [z w,] w)``), so every operation here is linear and exact up to
rounding for rational and polynomial curves alike. A knot vector of a degree-``p`` B-spline
with ``n`` control points has ``n + p + 1`` non-decreasing knots; its domain is
``[knots[p], knots[n]]``. Problems are raised as :class:`subtrace.errors.NurbsError` with
the bare problem text (the OBJ reader adds the file and line).
"""

from __future__ import annotations

import numpy as np

from subtrace.config import NURBS_MAX_DEGREE
from subtrace.errors import NurbsError


def check_degree(degree: int, what: str = "degree") -> None:
    """NurbsError unless 1 <= degree <= NURBS_MAX_DEGREE."""
    if not 1 <= degree <= NURBS_MAX_DEGREE:
        raise NurbsError(f"{what} {degree} is not supported: degrees 1 to "
                         f"{NURBS_MAX_DEGREE} are")


def check_knots(knots, degree: int, n_ctrl: int, direction: str = "u") -> None:
    """NurbsError unless ``knots`` is a valid knot vector for ``n_ctrl`` control points of
    ``degree``: finite, non-decreasing, ``n_ctrl + degree + 1`` long, no knot repeated more
    than ``degree + 1`` times, and a domain of positive length."""
    knots = np.asarray(knots, dtype=np.float64)
    name = f"parm {direction}"
    check_nondecreasing(knots, direction)
    need = n_ctrl + degree + 1
    if len(knots) != need:
        raise NurbsError(f"{name} has {len(knots)} knots; a degree-{degree} B-spline with "
                         f"{n_ctrl} control points needs {need} (control points + degree + 1)")
    _, counts = np.unique(knots, return_counts=True)
    if counts.max() > degree + 1:
        raise NurbsError(f"{name}: a knot is repeated {counts.max()} times; at most degree + 1 "
                         f"= {degree + 1} are allowed")
    if not knots[n_ctrl] > knots[degree]:
        raise NurbsError(f"{name}: the domain [knot {degree + 1}, knot {n_ctrl + 1}] = "
                         f"[{knots[degree]:g}, {knots[n_ctrl]:g}] is empty")


def check_nondecreasing(knots, direction: str = "u") -> None:
    """NurbsError unless the knots are finite and never decrease."""
    knots = np.asarray(knots, dtype=np.float64)
    name = f"parm {direction}"
    if not np.all(np.isfinite(knots)):
        raise NurbsError(f"{name}: knots must be finite numbers")
    down = np.nonzero(np.diff(knots) < 0)[0]
    if len(down):
        k = int(down[0])
        raise NurbsError(f"{name}: knot {k + 2} ({knots[k + 1]:g}) is below knot {k + 1} "
                         f"({knots[k]:g}); knots must not decrease")


def bezier_knots(params, degree: int) -> np.ndarray:
    """The B-spline knot vector of a piecewise Bezier curve (OBJ ``cstype bezier``) whose
    segments join at the increasing global parameters ``params`` (``len(params) - 1``
    segments, ``(len(params) - 1) * degree + 1`` control points): ends repeated
    ``degree + 1`` times, inner joins ``degree`` times."""
    params = np.asarray(params, dtype=np.float64)
    reps = np.full(len(params), degree)
    reps[0] = reps[-1] = degree + 1
    return np.repeat(params, reps)


def check_bezier_params(params, direction: str = "u") -> None:
    """NurbsError unless ``params`` (the segment joins of a Bezier curve or surface, OBJ
    ``parm``) are at least 2 finite, strictly increasing values."""
    params = np.asarray(params, dtype=np.float64)
    name = f"parm {direction}"
    if not np.all(np.isfinite(params)):
        raise NurbsError(f"{name}: parameter values must be finite numbers")
    if len(params) < 2:
        raise NurbsError(f"{name} needs at least 2 parameter values, got {len(params)}")
    down = np.nonzero(np.diff(params) <= 0)[0]
    if len(down):
        k = int(down[0])
        raise NurbsError(f"{name}: value {k + 2} ({params[k + 1]:g}) does not exceed value "
                         f"{k + 1} ({params[k]:g}); Bezier segment joins must increase")


def control_count(params_or_knots, degree: int, bezier: bool) -> int:
    """Control points along one direction that a Bezier ``parm`` list (segment joins) or a
    B-spline knot vector implies: ``(joins - 1) * degree + 1`` or ``knots - degree - 1``."""
    n = len(params_or_knots)
    return (n - 1) * degree + 1 if bezier else n - degree - 1


def insert_knot(knots: np.ndarray, ctrl: np.ndarray, degree: int, t: float):
    """Insert ``t`` once (Boehm): returns (knots', ctrl') describing the same curve.

    ``t`` must lie in the domain ``[knots[degree], knots[n]]``."""
    n = len(ctrl)
    p = degree
    # the span knots[k] <= t < knots[k+1] (the last non-empty span at the domain's end)
    k = int(np.searchsorted(knots, t, side="right")) - 1
    k = min(max(k, p), n - 1)
    out = np.empty((n + 1,) + ctrl.shape[1:], dtype=np.float64)
    out[: k - p + 1] = ctrl[: k - p + 1]
    out[k + 1 :] = ctrl[k:]
    for i in range(k - p + 1, k + 1):
        a = (t - knots[i]) / (knots[i + p] - knots[i])
        out[i] = a * ctrl[i] + (1.0 - a) * ctrl[i - 1]
    return np.insert(knots, k + 1, t), out


def bezier_segments(knots, ctrl, degree: int, lo: float | None = None,
                    hi: float | None = None):
    """Bezier control points of the B-spline (knots, ctrl) restricted to [lo, hi].

    ``lo`` / ``hi`` default to the domain's ends and must lie in the domain. Every knot
    strictly inside (lo, hi) and both ends are inserted until they are ``degree``-fold; then
    each non-empty span's ``degree + 1`` control points are its Bezier points. Returns
    (segments (m, degree+1, k) float64, breaks (m+1,) float64): segment ``i`` runs over
    ``[breaks[i], breaks[i+1]]`` in the curve's own parameter.
    """
    knots = np.asarray(knots, dtype=np.float64)
    ctrl = np.asarray(ctrl, dtype=np.float64)
    p = degree
    n = len(ctrl)
    lo = knots[p] if lo is None else float(lo)
    hi = knots[n] if hi is None else float(hi)
    inner = knots[(knots > lo) & (knots < hi)]
    for t in [lo, *sorted(set(inner.tolist())), hi]:  # (np.unique would import numpy.ma)
        have = int(np.count_nonzero(knots == t))
        for _ in range(p - have):
            knots, ctrl = insert_knot(knots, ctrl, p, t)
    segments, breaks = [], []
    for i in range(p, len(ctrl)):
        a, b = knots[i], knots[i + 1]
        if a < b and lo <= a and b <= hi:
            segments.append(ctrl[i - p : i + 1])
            breaks.append(a)
            last = b
    if not segments:
        raise NurbsError(f"the range [{lo:g}, {hi:g}] holds no span of the curve")
    breaks.append(last)
    return np.stack(segments), np.array(breaks, dtype=np.float64)


def elevate(ctrl: np.ndarray) -> np.ndarray:
    """Bezier control points (d+1, k) -> the same curve's (d+2, k) of degree d + 1."""
    d = len(ctrl) - 1
    out = np.empty((d + 2,) + ctrl.shape[1:], dtype=np.float64)
    out[0] = ctrl[0]
    out[d + 1] = ctrl[d]
    for i in range(1, d + 1):
        a = i / (d + 1)
        out[i] = a * ctrl[i - 1] + (1.0 - a) * ctrl[i]
    return out


def split_bezier(ctrl: np.ndarray, t: float):
    """De Casteljau: Bezier points (d+1, k) -> (left, right) halves at parameter ``t``; the
    shared point is the same array row in both (left[-1] is right[0], bit for bit)."""
    work = np.array(ctrl, dtype=np.float64)
    d = len(work) - 1
    left = np.empty_like(work)
    right = np.empty_like(work)
    left[0] = work[0]
    right[d] = work[d]
    for r in range(1, d + 1):
        work[: d - r + 1] = (1.0 - t) * work[: d - r + 1] + t * work[1 : d - r + 2]
        left[r] = work[0]
        right[d - r] = work[d - r]
    return left, right
