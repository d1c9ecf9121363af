"""Quartic triangular Bezier nets for the line kernels (:mod:`subtrace.lines.kernels`): Loop items.

A regular Loop patch is a quartic box spline, i.e. one quartic polynomial over its triangle;
it is stored as its *triangular Bezier net* of 15 control points ``b[j, k]`` (``j + k <= 4``,
at flat index :func:`tri_index`), over the item's parameters ``(s, t)``, ``s, t >= 0``,
``s + t <= 1``: ``P(s, t) = sum 4!/(i! j! k!) (1-s-t)^i s^j t^k b[j, k]`` with
``i = 4 - j - k``. Corner ``(0,0)`` is ``b[0]``, ``(1,0)`` is ``b[4]``, ``(0,1)`` is ``b[14]``.

* **1-to-4 segmentation**: the children are the triangles of the midpoint split, in Loop's
  child order (child 3, the middle one, turned half a turn: its (s, t) run opposite to the
  parent's). Each child's net is a fixed linear map of the parent's (``TRI_SPLIT`` (4,15,15),
  dyadic weights, exact in binary); the patch lies in the convex hull of each net.
* **Flatness**: ``L`` (the linear interpolant of the three corners) degree-elevated to 4 has
  control points ``L(j/4, k/4)``, so ``|P - L| <= max |b[j,k] - L(j/4, k/4)|`` over the whole
  triangle (convex hull of the difference net): a proven distance bound between the patch and
  its corner triangle, a second difference that each halving divides by about 4.
* **Evaluation** for Newton: the net's monomial coefficients (``TRI_MONO`` (15,15), integer
  weights) give the point and its first and second derivatives at (s, t).

The matrices are built here once, from the Bernstein basis; kernels take them as arguments.
"""

from __future__ import annotations

import math

import numpy as np

from subtrace.trace.prims import leaf_njit

DEGREE = 4
N_TRI = 15  # control points of a quartic triangular net
# children of the midpoint split in Loop's order: corners (0,0), (1,0), (0,1) of each child
# in the parent's (s, t); child c covers parent (s, t) = ORIGIN[c] + SCALE[c] * (child s, t)
CHILD_ORIGIN = np.array([[0.0, 0.0], [0.5, 0.0], [0.0, 0.5], [0.5, 0.5]])
CHILD_SCALE = np.array([0.5, 0.5, 0.5, -0.5])


def tri_index(j: int, k: int) -> int:
    """Flat index of control point ``b[j, k]`` (row ``k`` of ``5 - k`` points)."""
    return k * (DEGREE + 1) - k * (k - 1) // 2 + j


TRI_JK = np.array([(j, k) for k in range(DEGREE + 1) for j in range(DEGREE + 1 - k)],
                  dtype=np.int64)
assert all(tri_index(j, k) == i for i, (j, k) in enumerate(TRI_JK))
# the domain points (j/4, k/4), the place each control point belongs to
TRI_PARAMS = TRI_JK / float(DEGREE)


def bernstein(st: np.ndarray) -> np.ndarray:
    """(m, 15) quartic triangular Bernstein basis at parameters ``st`` (m, 2)."""
    s, t = st[:, 0:1], st[:, 1:2]
    w = 1.0 - s - t
    j, k = TRI_JK[:, 0], TRI_JK[:, 1]
    i = DEGREE - j - k
    coef = np.array([math.factorial(DEGREE) / (math.factorial(a) * math.factorial(b)
                                               * math.factorial(c)) for a, b, c in zip(i, j, k)])
    return coef * w**i * s**j * t**k


def monomials(st: np.ndarray) -> np.ndarray:
    """(m, 15) monomials ``s^j t^k`` (flat order of :func:`tri_index`) at ``st`` (m, 2)."""
    return st[:, 0:1] ** TRI_JK[:, 0] * st[:, 1:2] ** TRI_JK[:, 1]


def _exact(a: np.ndarray, unit: float) -> np.ndarray:
    """``a`` rounded to multiples of ``unit`` (its entries are such multiples in exact
    arithmetic; the solve only adds rounding)."""
    r = np.round(a / unit) * unit
    assert np.abs(r - a).max() < 1e-9
    return r


_V = bernstein(TRI_PARAMS)  # collocation matrix: unisolvent at the domain points
# child nets from the parent's: the parent's polynomial at the child's domain points
TRI_SPLIT = np.ascontiguousarray(np.stack([
    _exact(np.linalg.solve(_V, bernstein(CHILD_ORIGIN[c] + CHILD_SCALE[c] * TRI_PARAMS)),
           2.0**-DEGREE) for c in range(4)]))
# its nonzero weights, row 15 c + p (child c, point p) in CSR form, for the kernels
_nz = TRI_SPLIT.reshape(4 * N_TRI, N_TRI) != 0
SPLIT_PTR = np.concatenate([[0], np.cumsum(_nz.sum(axis=1))]).astype(np.int64)
SPLIT_COL = np.ascontiguousarray(np.nonzero(_nz)[1], dtype=np.int64)
SPLIT_W = np.ascontiguousarray(TRI_SPLIT.reshape(4 * N_TRI, N_TRI)[_nz])
# monomial coefficients from a net (integer weights)
TRI_MONO = np.ascontiguousarray(_exact(np.linalg.solve(monomials(TRI_PARAMS), _V), 1.0))


@leaf_njit
def tri_flatness(w, q):
    """Distance bound between net ``w[q]``'s patch and its corner triangle (module doc)."""
    e = 0.0
    p = 0
    for k in range(DEGREE + 1):
        t = k / DEGREE
        for j in range(DEGREE + 1 - k):
            s = j / DEGREE
            d2 = 0.0
            for c in range(3):
                L = (1.0 - s - t) * w[q, 0, c] + s * w[q, DEGREE, c] + t * w[q, N_TRI - 1, c]
                d = w[q, p, c] - L
                d2 += d * d
            e = max(e, d2)
            p += 1
    return math.sqrt(e)


@leaf_njit
def tri_box(w, q):
    """Box of the control points of net ``w[q]`` (it contains the patch)."""
    lo0 = lo1 = lo2 = np.inf
    hi0 = hi1 = hi2 = -np.inf
    for p in range(N_TRI):
        x, y, z = w[q, p, 0], w[q, p, 1], w[q, p, 2]
        lo0, hi0 = min(lo0, x), max(hi0, x)
        lo1, hi1 = min(lo1, y), max(hi1, y)
        lo2, hi2 = min(lo2, z), max(hi2, z)
    return lo0, lo1, lo2, hi0, hi1, hi2


@leaf_njit
def tri_split(w, q, split_ptr, split_col, split_w, d0):
    """Child ``c`` of net ``w[q]`` into ``w[d0 + c]`` (c = 0..3; ``d0 > q``): row
    ``15 c + p`` of ``TRI_SPLIT`` as its nonzero weights (CSR: ``SPLIT_PTR``,
    ``SPLIT_COL``, ``SPLIT_W``)."""
    for row in range(4 * N_TRI):
        x = y = z = 0.0
        for i in range(split_ptr[row], split_ptr[row + 1]):
            r = split_col[i]
            a = split_w[i]
            x += a * w[q, r, 0]
            y += a * w[q, r, 1]
            z += a * w[q, r, 2]
        c = d0 + row // N_TRI
        p = row % N_TRI
        w[c, p, 0] = x
        w[c, p, 1] = y
        w[c, p, 2] = z


@leaf_njit
def tri_monomials(w, q, mono_from_net, out):
    """Monomial coefficients (15,3) of net ``w[q]`` into ``out``."""
    for m in range(N_TRI):
        x = y = z = 0.0
        for r in range(N_TRI):
            a = mono_from_net[m, r]
            if a != 0.0:
                x += a * w[q, r, 0]
                y += a * w[q, r, 1]
                z += a * w[q, r, 2]
        out[m, 0] = x
        out[m, 1] = y
        out[m, 2] = z


@leaf_njit
def _mono_sums(c, ps, pt, a1, b1, a2, b2, a3, b3, out, row):
    """``out[row + r]``: the (ar, br)-th derivative (in s, t) of the quartic with monomial
    coefficients ``c``, for r = 0, 1, 2, from the powers ``ps``, ``pt`` (scalar sums)."""
    px = py = pz = ux = uy = uz = vx = vy = vz = 0.0
    m = 0
    for k in range(DEGREE + 1):
        for j in range(DEGREE + 1 - k):
            x, y, z = c[m, 0], c[m, 1], c[m, 2]
            f = _deriv(ps, j, a1) * _deriv(pt, k, b1)
            fs = _deriv(ps, j, a2) * _deriv(pt, k, b2)
            ft = _deriv(ps, j, a3) * _deriv(pt, k, b3)
            px += f * x
            py += f * y
            pz += f * z
            ux += fs * x
            uy += fs * y
            uz += fs * z
            vx += ft * x
            vy += ft * y
            vz += ft * z
            m += 1
    out[row, 0], out[row, 1], out[row, 2] = px, py, pz
    out[row + 1, 0], out[row + 1, 1], out[row + 1, 2] = ux, uy, uz
    out[row + 2, 0], out[row + 2, 1], out[row + 2, 2] = vx, vy, vz


@leaf_njit
def _deriv(p, j, a):
    """The a-th derivative of x^j (a <= 2) from the powers ``p`` of x."""
    if a == 0:
        return p[j]
    if a == 1:
        return j * p[j - 1] if j > 0 else 0.0
    return j * (j - 1) * p[j - 2] if j > 1 else 0.0


@leaf_njit
def mono_eval(c, s, t, out, second):
    """Point, first and (with ``second``) second derivatives of the quartic with monomial
    coefficients ``c`` (15,3) at (s, t) into ``out`` rows P, Ps, Pt, Pss, Pst, Ptt
    (Newton's inner loop)."""
    s2, t2 = s * s, t * t
    ps = (1.0, s, s2, s2 * s, s2 * s2)
    pt = (1.0, t, t2, t2 * t, t2 * t2)
    _mono_sums(c, ps, pt, 0, 0, 1, 0, 0, 1, out, 0)
    if second:
        _mono_sums(c, ps, pt, 2, 0, 1, 1, 0, 2, out, 3)
