"""Tensor-product (rational) B-spline surfaces and their rational Bezier patches.

A :class:`NurbsSurface` holds ``control (nv, nu, 4)`` float64 homogeneous points
``(x w, y w, z w, w)``, row ``j`` along v, column ``i`` along u (the OBJ ``surf`` order: u
varies fastest), knot vectors in u and v, its degrees, the parameter rectangle it is used
over (``domain`` = (u0, u1, v0, v1), OBJ ``surf s0 s1 t0 t1``) and its trim loops.

:func:`bezier_patches` cuts it into rational Bezier patches by knot insertion (Boehm, in
homogeneous coordinates, so exact for rational surfaces): ``nets (m, du+1, dv+1, 4)``
with ``net[i, j]`` the coefficient of ``B_i(s) B_j(t)`` (``s`` along u over the patch's
[0, 1]), and ``rects (m, 4)`` = (u0, u1, v0, v1) of each patch in the surface's
parameters, patches ordered v-major (u fastest). With positive weights each patch lies in
the convex hull of its projected control points (tests/test_nurbs.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from subtrace.errors import NurbsError
from subtrace.nurbs.knots import (
    bezier_knots,
    bezier_segments,
    check_bezier_params,
    check_degree,
    check_knots,
    check_nondecreasing,
    control_count,
)


@dataclass(frozen=True, eq=False)
class NurbsSurface:
    """A (rational) B-spline surface with its trim loops (see the module comment)."""

    degree: tuple[int, int]  # (du, dv)
    knots_u: np.ndarray  # (nu + du + 1,) float64
    knots_v: np.ndarray  # (nv + dv + 1,) float64
    control: np.ndarray  # (nv, nu, 4) float64 homogeneous
    domain: tuple[float, float, float, float]  # (u0, u1, v0, v1)
    rational: bool
    loops: tuple = ()  # TrimLoop, outer loops counter-clockwise, holes clockwise
    material: int = -1  # index into the OBJ file's materials, -1: none


def make_surface(degree, params_u, params_v, points, weights=None, domain=None,
                 bezier: bool = False) -> NurbsSurface:
    """A validated :class:`NurbsSurface` without trim loops.

    degree: (du, dv); params_u / params_v: knot vectors (``bezier``: segment joins, OBJ
    ``cstype bezier``); points (nu * nv, 3) in OBJ order (u fastest); weights (nu * nv,)
    positive, None for a polynomial surface; domain (u0, u1, v0, v1), None for the whole
    knot domain. Raises NurbsError naming the problem.
    """
    du, dv = degree
    check_degree(du, "degree in u")
    check_degree(dv, "degree in v")
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = len(points)
    if n < (du + 1) * (dv + 1):
        raise NurbsError(f"surf has {n} control points; a degree {du} x {dv} surface needs at "
                         f"least {(du + 1) * (dv + 1)} ((du + 1) x (dv + 1))")
    knots = []
    for direction, params, d in (("u", params_u, du), ("v", params_v, dv)):
        params = np.asarray(params, dtype=np.float64)
        if bezier:
            check_bezier_params(params, direction)
        else:
            check_nondecreasing(params, direction)
        if not bezier and len(params) < 2 * d + 2:
            raise NurbsError(f"parm {direction} has {len(params)} knots; a degree-{d} "
                             f"B-spline needs at least {2 * d + 2}")
        knots.append(params)
    nu = control_count(knots[0], du, bezier)
    nv = control_count(knots[1], dv, bezier)
    if nu * nv != n:
        kind = "segment joins" if bezier else "knots"
        raise NurbsError(
            f"surf has {n} control points, but parm u ({len(knots[0])} {kind}, degree {du}: "
            f"{nu} columns) and parm v ({len(knots[1])} {kind}, degree {dv}: {nv} rows) "
            f"need {nu * nv}")
    if bezier:
        knots = [bezier_knots(knots[0], du), bezier_knots(knots[1], dv)]
    check_knots(knots[0], du, nu, "u")
    check_knots(knots[1], dv, nv, "v")
    w = np.ones(n) if weights is None else np.asarray(weights, dtype=np.float64)
    bad = np.nonzero(~(w > 0) | ~np.isfinite(w))[0]
    if len(bad):
        raise NurbsError(f"control point {bad[0] + 1} has weight {w[bad[0]]:g}; weights of a "
                         "rational surface must be positive")
    full = (knots[0][du], knots[0][nu], knots[1][dv], knots[1][nv])
    if domain is None:
        domain = full
    domain = tuple(float(x) for x in domain)
    if not (full[0] <= domain[0] < domain[1] <= full[1]
            and full[2] <= domain[2] < domain[3] <= full[3]):
        raise NurbsError(
            f"surf range [{domain[0]:g}, {domain[1]:g}] x [{domain[2]:g}, {domain[3]:g}] is "
            f"empty or outside the knot domain [{full[0]:g}, {full[1]:g}] x "
            f"[{full[2]:g}, {full[3]:g}]")
    control = np.column_stack([points * w[:, None], w]).reshape(nv, nu, 4)
    return NurbsSurface((du, dv), knots[0], knots[1], np.ascontiguousarray(control), domain,
                        weights is not None)


def bezier_patches(surface: NurbsSurface):
    """(nets (m, du+1, dv+1, 4), rects (m, 4)) of the surface over its domain (see the
    module comment)."""
    du, dv = surface.degree
    u0, u1, v0, v1 = surface.domain
    nv, nu, _ = surface.control.shape
    # along u: every row of the grid is one curve with nv * 4 coordinates
    by_u = surface.control.transpose(1, 0, 2).reshape(nu, nv * 4)
    seg_u, breaks_u = bezier_segments(surface.knots_u, by_u, du, u0, u1)
    mu = len(seg_u)
    seg_u = seg_u.reshape(mu, du + 1, nv, 4)
    # along v: the columns of all u segments at once
    by_v = seg_u.transpose(2, 0, 1, 3).reshape(nv, mu * (du + 1) * 4)
    seg_v, breaks_v = bezier_segments(surface.knots_v, by_v, dv, v0, v1)
    mv = len(seg_v)
    nets = seg_v.reshape(mv, dv + 1, mu, du + 1, 4).transpose(0, 2, 3, 1, 4)
    nets = np.ascontiguousarray(nets.reshape(mv * mu, du + 1, dv + 1, 4))
    a = np.tile(np.arange(mu), mv)
    b = np.repeat(np.arange(mv), mu)
    rects = np.column_stack([breaks_u[a], breaks_u[a + 1], breaks_v[b], breaks_v[b + 1]])
    return nets, np.ascontiguousarray(rects)
