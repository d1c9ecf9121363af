"""Exact evaluation of rational Bezier patches and curves (Numba kernels).

Patch nets are ``(du+1, dv+1, 4)`` float64 homogeneous points (x w, y w, z w, w), padded
into a table ``nets (m, Du+1, Dv+1, 4)`` with ``degrees (m, 2)`` int32 (entries past a
patch's degrees are unused). The point and both first derivatives come from one tensor
de Casteljau pass in homogeneous coordinates (:func:`patch_eval`, a ``leaf_njit`` helper
that takes its scratch buffer from :func:`patch_work`, so a kernel allocates it once), then
the quotient rule: ``P = H / w``, ``P_s = (H_s - P w_s) / w``. :func:`evaluate` is the
batch wrapper in the surface's own parameters (patch rectangle ``rects (m, 4)``, chain rule
``1 / (u1 - u0)``).

Curves are ``(d+1, 3)`` homogeneous 2-D points (u w, v w, w); :func:`curve_point` evaluates
one (the trim test's exact crossing search).
"""

from __future__ import annotations

import numpy as np

from subtrace.config import NURBS_MAX_DEGREE
from subtrace.runtime.jit import leaf_njit, nb

_MAX_POINTS = NURBS_MAX_DEGREE + 1  # de Casteljau buffers hold a row of this many points


@leaf_njit
def _casteljau_row(row, n, t, dst, k):
    """Point and derivative (d/dt) at t of the Bezier curve with the ``n`` homogeneous
    points ``row[:n]`` (4 coordinates) into ``dst[k]`` and ``dst[k + 1]``; ``row`` is
    overwritten."""
    d = n - 1
    for r in range(d, 1, -1):
        for i in range(r):
            for c in range(4):
                row[i, c] = (1.0 - t) * row[i, c] + t * row[i + 1, c]
    for c in range(4):
        if d == 0:
            dst[k, c] = row[0, c]
            dst[k + 1, c] = 0.0
        else:
            dst[k, c] = (1.0 - t) * row[0, c] + t * row[1, c]
            dst[k + 1, c] = d * (row[1, c] - row[0, c])


def patch_work():
    """The scratch buffer :func:`patch_eval` takes: (4, NURBS_MAX_DEGREE + 1, 4) float64."""
    return np.empty((4, _MAX_POINTS, 4))


@leaf_njit
def patch_eval(net, du, dv, s, t, work, out):
    """Point and first derivatives of the rational Bezier patch ``net (>=du+1, >=dv+1, 4)``
    at local (s, t) in [0,1]^2: out (3, 3) rows P, dP/ds, dP/dt. work: :func:`patch_work`."""
    col, cols, dcols, h = work[0], work[1], work[2], work[3]
    # along v: each u index's column at t (into cols[i]) and its t-derivative (dcols[i])
    for i in range(du + 1):
        for j in range(dv + 1):
            for c in range(4):
                col[j, c] = net[i, j, c]
        _casteljau_row(col, dv + 1, t, h, 0)
        for c in range(4):
            cols[i, c] = h[0, c]
            dcols[i, c] = h[1, c]
    # along u: H and H_s from the columns (h[0], h[1]), H_t from the derivatives (h[2])
    _casteljau_row(cols, du + 1, s, h, 0)
    _casteljau_row(dcols, du + 1, s, h, 2)
    # quotient rule: P = H / w, P_s = (H_s - P w_s) / w
    inv = 1.0 / h[0, 3]
    for c in range(3):
        p = h[0, c] * inv
        out[0, c] = p
        out[1, c] = (h[1, c] - p * h[1, 3]) * inv
        out[2, c] = (h[2, c] - p * h[2, 3]) * inv


@nb.njit(cache=True)
def _evaluate(nets, degrees, rects, ids, uv, points, d_du, d_dv):
    out = np.empty((3, 3))
    work = np.empty((4, _MAX_POINTS, 4))
    for k in range(len(ids)):
        p = ids[k]
        u0, u1, v0, v1 = rects[p, 0], rects[p, 1], rects[p, 2], rects[p, 3]
        s = (uv[k, 0] - u0) / (u1 - u0)
        t = (uv[k, 1] - v0) / (v1 - v0)
        patch_eval(nets[p], degrees[p, 0], degrees[p, 1], s, t, work, out)
        for c in range(3):
            points[k, c] = out[0, c]
            d_du[k, c] = out[1, c] / (u1 - u0)
            d_dv[k, c] = out[2, c] / (v1 - v0)


def evaluate(nets, degrees, rects, ids, uv):
    """Points and first derivatives of patches at surface parameters.

    nets (m, Du+1, Dv+1, 4) f8, degrees (m, 2) i4, rects (m, 4) f8 (u0, u1, v0, v1);
    ids (n,) patch indices, uv (n, 2) parameters in the patches' surfaces (inside each
    patch's rectangle). Returns (P, dP/du, dP/dv), each (n, 3) float64.
    """
    ids = np.ascontiguousarray(ids, dtype=np.int64)
    uv = np.ascontiguousarray(uv, dtype=np.float64).reshape(-1, 2)
    if len(ids) != len(uv):
        raise ValueError(f"{len(ids)} patch ids for {len(uv)} parameter pairs")
    n = len(ids)
    points, d_du, d_dv = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3))
    _evaluate(np.ascontiguousarray(nets, dtype=np.float64),
              np.ascontiguousarray(degrees, dtype=np.int32),
              np.ascontiguousarray(rects, dtype=np.float64), ids, uv, points, d_du, d_dv)
    return points, d_du, d_dv


@leaf_njit
def curve_point(ctrl, degree, t):
    """(u, v) at t of the rational Bezier curve ``ctrl[:degree+1] (., 3)`` (homogeneous):
    the Bernstein sum, each weight C(d,i) t^i (1-t)^(d-i) formed by products (exact
    binomials, no division by 1 - t)."""
    s = 1.0 - t
    x = y = w = 0.0
    binom = 1.0
    for i in range(degree + 1):
        b = binom
        for _ in range(i):
            b *= t
        for _ in range(degree - i):
            b *= s
        x += b * ctrl[i, 0]
        y += b * ctrl[i, 1]
        w += b * ctrl[i, 2]
        binom = binom * (degree - i) / (i + 1)
    return x / w, y / w
