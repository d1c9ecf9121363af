"""Bezier and box-spline bases of patch geometry: evaluate, split, bound (no topology).

Every net here is a flat float64 array of control points with xyz last:

* **bicubic Bezier nets** ``(..., 4, 4, 3)``, ``net[i, j]`` the control point of
  ``B_i(u) B_j(v)`` (cubic Bernstein ``B``), ``u`` along the first index. A regular
  Catmull-Clark patch is one (:func:`bezier_nets` converts its uniform B-spline grid, laid out
  as ``B_CORNER`` / ``LEAD`` / ``TRAIL`` say); kernels take a stack ``nets`` and an index.
  :func:`bez_point` is the renderer's point evaluator (one code path, so shared corners are
  bit-identical), :func:`bez_eval` the point, first and second derivatives (line queries'
  Newton), :func:`bez_derivatives` / :func:`bez_normal` the shading frame. De Casteljau
  halving (:func:`split_net`, :func:`quadrant`), the padded box of a net (:func:`net_box`),
  a flatness bound (:func:`net_flatness`) and per-net box and derivative bound
  (:func:`net_bounds`) follow from the convex-hull property of the Bernstein basis.
* **quartic box splines** (regular Loop patches) over the 12 lattice points ``BOX_POINTS``:
  ``BOX_MONO`` / ``BOX_COEF`` give the basis as polynomials (:func:`box_spline_basis`), and
  the uniform cubic B-spline basis of Catmull-Clark grids is :func:`bspline_basis`.
* **quartic triangular Bezier nets** ``(..., 15, 3)``, ``b[j, k]`` (``j + k <= 4``) at flat
  index :func:`tri_index`, over ``(s, t)``, ``s, t >= 0``, ``s + t <= 1``:
  ``P(s, t) = sum 4!/(i! j! k!) (1-s-t)^i s^j t^k b[j, k]`` with ``i = 4 - j - k``. Corner
  ``(0,0)`` is ``b[0]``, ``(1,0)`` is ``b[4]``, ``(0,1)`` is ``b[14]``. A regular Loop patch
  is one (``BOX_TO_TRI``); so is a flat triangle (``FLAT_TO_TRI``).

  - 1-to-4 segmentation: the children are the triangles of the midpoint split, in Loop's
    child order (child 3, the middle one, turned half a turn: its (s, t) run opposite to
    the parent's). Each child's net is a fixed linear map of the parent's (``TRI_SPLIT``
    (4,15,15), dyadic weights, exact in binary); the patch lies in the convex hull of each.
  - Flatness: ``L`` (the linear interpolant of the three corners) degree-elevated to 4 has
    control points ``L(j/4, k/4)``, so ``|P - L| <= max |b[j,k] - L(j/4, k/4)|`` over the
    whole triangle (convex hull of the difference net): a proven distance bound between the
    patch and its corner triangle, a second difference that each halving divides by about 4.
  - Evaluation for Newton: the net's monomial coefficients (``TRI_MONO`` (15,15), integer
    weights) give the point and its first and second derivatives at (s, t).

The matrices are built here once; kernels take them as arguments (habit 9: no captured
global arrays). A degenerate normal (zero cross product of the derivatives: a collapsed
cage, an extraordinary corner) is taken a little way towards the net's centre, by one rule
for both net kinds (:func:`unit_normal`).
"""

from __future__ import annotations

import math

import numpy as np

from subtrace.runtime.jit import callee_njit, leaf_njit, llvm_inline_njit, nb

# ------------------------------------------------------------------------------------------
# bicubic nets
# ------------------------------------------------------------------------------------------

BOX_PAD = 1e-12  # a net's box is widened by this much of its largest coordinate (rounding)

# uniform cubic B-spline control points -> Bezier control points of the middle span
TO_BEZIER = np.array(
    [[1.0, 4.0, 1.0, 0.0], [0.0, 4.0, 2.0, 0.0], [0.0, 2.0, 4.0, 0.0], [0.0, 1.0, 4.0, 1.0]]
) / 6.0

# The 4x4 B-spline grid of a regular quad, ``[u index][v index]``: grid position of face
# corner i, and the directions of its leading / trailing edges
B_CORNER = np.array([[1, 1], [2, 1], [2, 2], [1, 2]], dtype=np.int64)
LEAD = np.array([[1, 0], [0, 1], [-1, 0], [0, -1]], dtype=np.int64)
TRAIL = np.array([[0, 1], [-1, 0], [0, -1], [1, 0]], dtype=np.int64)

# bez_point is kept apart from bez_sums (which the derivative evaluators share): it is the
# renderer's per-ray corner evaluator, and a point through bez_sums cost 272-335 ns against
# 53-107 ns (2M points, jitted loop, 2 shared cores): three sums instead of one, and a
# different summation order, which would move every corner point (and image) in the last bit.
@leaf_njit
def bez_point(nets, k, u, v):
    """Point of the Bezier patch ``nets[k]`` (4,4,3) at (u, v): one code path for every
    caller, so a point shared by cells is computed bit-identically by each (its rows at v,
    :func:`bez_rows`, then their sum at u, :func:`bez_across`: points of one v may share
    the rows)."""
    return bez_across(bez_rows(nets, k, v), u)


@llvm_inline_njit
def bez_rows(nets, k, v):
    """The four rows of ``nets[k]`` as cubic curves in v, at v: 12 numbers, (x, y, z) of
    row 0, then 1, 2, 3 (for :func:`bez_across`)."""
    sv = 1.0 - v
    b0, b1, b2, b3 = sv * sv * sv, 3.0 * v * sv * sv, 3.0 * v * v * sv, v * v * v
    n = nets
    return (b0 * n[k, 0, 0, 0] + b1 * n[k, 0, 1, 0] + b2 * n[k, 0, 2, 0] + b3 * n[k, 0, 3, 0],
            b0 * n[k, 0, 0, 1] + b1 * n[k, 0, 1, 1] + b2 * n[k, 0, 2, 1] + b3 * n[k, 0, 3, 1],
            b0 * n[k, 0, 0, 2] + b1 * n[k, 0, 1, 2] + b2 * n[k, 0, 2, 2] + b3 * n[k, 0, 3, 2],
            b0 * n[k, 1, 0, 0] + b1 * n[k, 1, 1, 0] + b2 * n[k, 1, 2, 0] + b3 * n[k, 1, 3, 0],
            b0 * n[k, 1, 0, 1] + b1 * n[k, 1, 1, 1] + b2 * n[k, 1, 2, 1] + b3 * n[k, 1, 3, 1],
            b0 * n[k, 1, 0, 2] + b1 * n[k, 1, 1, 2] + b2 * n[k, 1, 2, 2] + b3 * n[k, 1, 3, 2],
            b0 * n[k, 2, 0, 0] + b1 * n[k, 2, 1, 0] + b2 * n[k, 2, 2, 0] + b3 * n[k, 2, 3, 0],
            b0 * n[k, 2, 0, 1] + b1 * n[k, 2, 1, 1] + b2 * n[k, 2, 2, 1] + b3 * n[k, 2, 3, 1],
            b0 * n[k, 2, 0, 2] + b1 * n[k, 2, 1, 2] + b2 * n[k, 2, 2, 2] + b3 * n[k, 2, 3, 2],
            b0 * n[k, 3, 0, 0] + b1 * n[k, 3, 1, 0] + b2 * n[k, 3, 2, 0] + b3 * n[k, 3, 3, 0],
            b0 * n[k, 3, 0, 1] + b1 * n[k, 3, 1, 1] + b2 * n[k, 3, 2, 1] + b3 * n[k, 3, 3, 1],
            b0 * n[k, 3, 0, 2] + b1 * n[k, 3, 1, 2] + b2 * n[k, 3, 2, 2] + b3 * n[k, 3, 3, 2])


@llvm_inline_njit
def bez_across(c, u):
    """The point at u of the curve whose four control points are the rows ``c`` at some v
    (:func:`bez_rows`)."""
    su = 1.0 - u
    bu = (su * su * su, 3.0 * u * su * su, 3.0 * u * u * su, u * u * u)
    x = y = z = 0.0
    for a in range(4):
        x += bu[a] * c[3 * a]
        y += bu[a] * c[3 * a + 1]
        z += bu[a] * c[3 * a + 2]
    return x, y, z


@leaf_njit
def bez_sums(net, a1, b1, a2, b2, a3, b3):
    """``sum_ij ar[i] br[j] net[i, j]`` for r = 1, 2, 3 (three 3-tuples): the tensor-product
    sums behind every derivative evaluator of a bicubic net ``net`` (4,4,3), in one pass."""
    px = py = pz = ux = uy = uz = vx = vy = vz = 0.0
    for i in range(4):
        for j in range(4):
            x, y, z = net[i, j, 0], net[i, j, 1], net[i, j, 2]
            f, fu, fv = a1[i] * b1[j], a2[i] * b2[j], a3[i] * b3[j]
            px += f * x
            py += f * y
            pz += f * z
            ux += fu * x
            uy += fu * y
            uz += fu * z
            vx += fv * x
            vy += fv * y
            vz += fv * z
    return (px, py, pz), (ux, uy, uz), (vx, vy, vz)


@leaf_njit
def _cubic(s):
    """Cubic Bernstein values and derivatives at s: two 4-tuples."""
    ss = 1.0 - s
    b = (ss * ss * ss, 3.0 * s * ss * ss, 3.0 * s * s * ss, s * s * s)
    db = (-3.0 * ss * ss, 3.0 * ss * (ss - 2.0 * s), 3.0 * s * (2.0 * ss - s), 3.0 * s * s)
    return b, db


@leaf_njit
def bez_eval(w, q, s, t, out, second):
    """Point, first and (with ``second``) second derivatives of bicubic net ``w[q]`` at
    (s, t) into ``out`` rows P, Ps, Pt, Pss, Pst, Ptt (the line queries' Newton)."""
    net = w[q]
    b, db = _cubic(s)
    c, dc = _cubic(t)
    _rows(out, 0, bez_sums(net, b, c, db, c, b, dc))
    if second:
        ss, st = 1.0 - s, 1.0 - t
        ddb = (6.0 * ss, 6.0 * (3.0 * s - 2.0), 6.0 * (1.0 - 3.0 * s), 6.0 * s)
        ddc = (6.0 * st, 6.0 * (3.0 * t - 2.0), 6.0 * (1.0 - 3.0 * t), 6.0 * t)
        _rows(out, 3, bez_sums(net, ddb, c, db, dc, b, ddc))


@leaf_njit
def _rows(out, row, sums):
    """Three 3-tuples ``sums`` into rows ``row .. row + 2`` of ``out``."""
    for r in range(3):
        out[row + r, 0], out[row + r, 1], out[row + r, 2] = sums[r]


@leaf_njit
def bez_derivatives(net, u, v):
    """dP/du and dP/dv of the Bezier patch ``net`` (4,4,3) at (u, v): two 3-tuples."""
    bu, du = _cubic(u)
    bv, dv = _cubic(v)
    _, pu, pv = bez_sums(net, bu, bv, du, bv, bu, dv)
    return pu, pv


@leaf_njit
def unit_normal(pu, pv):
    """``(nx, ny, nz, ok)``: the unit cross product of two 3-tuples; ok False (and a zero
    vector) where it vanishes."""
    nx = pu[1] * pv[2] - pu[2] * pv[1]
    ny = pu[2] * pv[0] - pu[0] * pv[2]
    nz = pu[0] * pv[1] - pu[1] * pv[0]
    ln = math.sqrt(nx * nx + ny * ny + nz * nz)
    if ln > 0.0:
        return nx / ln, ny / ln, nz / ln, True
    return 0.0, 0.0, 0.0, False


NORMAL_STEP = 1e-6  # a degenerate normal is retaken this fraction of the way to the centre
NORMAL_TRIES = 3


@leaf_njit
def bez_normal(net, u, v):
    """Unit limit normal of the bicubic net ``net`` (4,4,3) at (u, v); where the derivatives
    vanish (a degenerate cage), the normal a little way towards the patch centre (zero if
    it still vanishes)."""
    for step in range(NORMAL_TRIES):
        pu, pv = bez_derivatives(net, u, v)
        nx, ny, nz, ok = unit_normal(pu, pv)
        if ok:
            return nx, ny, nz
        u += (0.5 - u) * NORMAL_STEP
        v += (0.5 - v) * NORMAL_STEP
    return 0.0, 0.0, 0.0


@nb.njit(cache=True)
def bez_normals(nets, rows, ab, out):
    """:func:`bez_normal` of nets ``nets[rows]`` at parameters ``ab`` (m,2) into ``out``
    (m,3)."""
    for m in range(len(rows)):
        out[m, 0], out[m, 1], out[m, 2] = bez_normal(nets[rows[m]], ab[m, 0], ab[m, 1])


@leaf_njit
def split_row(a, b, c, d):
    """De Casteljau halving of one cubic row ``a, b, c, d``: ``ab, abc, m, bcd, cd`` (the
    left half is ``a, ab, abc, m``, the right half ``m, bcd, cd, d``)."""
    ab = 0.5 * (a + b)
    bc = 0.5 * (b + c)
    cd = 0.5 * (c + d)
    abc = 0.5 * (ab + bc)
    bcd = 0.5 * (bc + cd)
    m = 0.5 * (abc + bcd)
    return ab, abc, m, bcd, cd

@leaf_njit
def copy_net(dst, d, src, s):
    """``dst[d] = src[s]`` for Bezier nets (4,4,3), element by element (no array views)."""
    for a in range(4):
        for c in range(4):
            for k in range(3):
                dst[d, a, c, k] = src[s, a, c, k]

@leaf_njit
def split_net(src, s, w, d0):
    """Write the four child nets of net ``src[s]`` into ``w[d0 .. d0+3]`` (child ``cu + 2 cv``
    covers the half cu in u and cv in v), using ``w[d0-2]``, ``w[d0-1]`` as scratch."""
    h0 = d0 - 2
    for c in range(4):  # halve along u (first index)
        for k in range(3):
            p0, p1, p2, p3 = src[s, 0, c, k], src[s, 1, c, k], src[s, 2, c, k], src[s, 3, c, k]
            ab, abc, m, bcd, cd = split_row(p0, p1, p2, p3)
            w[h0, 0, c, k], w[h0, 1, c, k], w[h0, 2, c, k], w[h0, 3, c, k] = p0, ab, abc, m
            w[h0 + 1, 0, c, k], w[h0 + 1, 1, c, k] = m, bcd
            w[h0 + 1, 2, c, k], w[h0 + 1, 3, c, k] = cd, p3
    for h in range(2):  # then along v
        src_h = h0 + h
        lo = d0 + h
        hi = d0 + h + 2
        for a in range(4):
            for k in range(3):
                p0, p1 = w[src_h, a, 0, k], w[src_h, a, 1, k]
                p2, p3 = w[src_h, a, 2, k], w[src_h, a, 3, k]
                ab, abc, m, bcd, cd = split_row(p0, p1, p2, p3)
                w[lo, a, 0, k], w[lo, a, 1, k], w[lo, a, 2, k], w[lo, a, 3, k] = p0, ab, abc, m
                w[hi, a, 0, k], w[hi, a, 1, k], w[hi, a, 2, k], w[hi, a, 3, k] = m, bcd, cd, p3

@leaf_njit
def quadrant(src, s, cu, cv, w, d):
    """Write child ``cu + 2 cv`` of net ``src[s]`` (as :func:`split_net` makes it) into
    ``w[d]``, using ``w[d + 1]`` as scratch."""
    for c in range(4):  # halve along u, keep half cu
        for k in range(3):
            p0, p1, p2, p3 = src[s, 0, c, k], src[s, 1, c, k], src[s, 2, c, k], src[s, 3, c, k]
            ab, abc, m, bcd, cd = split_row(p0, p1, p2, p3)
            if cu == 0:
                w[d + 1, 0, c, k], w[d + 1, 1, c, k], w[d + 1, 2, c, k], w[d + 1, 3, c, k] = (
                    p0, ab, abc, m)
            else:
                w[d + 1, 0, c, k], w[d + 1, 1, c, k], w[d + 1, 2, c, k], w[d + 1, 3, c, k] = (
                    m, bcd, cd, p3)
    for a in range(4):  # then along v, keep half cv
        for k in range(3):
            p0, p1 = w[d + 1, a, 0, k], w[d + 1, a, 1, k]
            p2, p3 = w[d + 1, a, 2, k], w[d + 1, a, 3, k]
            ab, abc, m, bcd, cd = split_row(p0, p1, p2, p3)
            if cv == 0:
                w[d, a, 0, k], w[d, a, 1, k], w[d, a, 2, k], w[d, a, 3, k] = p0, ab, abc, m
            else:
                w[d, a, 0, k], w[d, a, 1, k], w[d, a, 2, k], w[d, a, 3, k] = m, bcd, cd, p3

@leaf_njit
def pad_box(lo0, lo1, lo2, hi0, hi1, hi2):
    """A box widened by ``BOX_PAD`` of its largest coordinate (for rounding)."""
    pad = BOX_PAD * max(max(abs(lo0), abs(hi0)), max(max(abs(lo1), abs(hi1)),
                                                     max(abs(lo2), abs(hi2))))
    return lo0 - pad, lo1 - pad, lo2 - pad, hi0 + pad, hi1 + pad, hi2 + pad

@leaf_njit
def net_box(net, s):
    """Padded box of the control points of ``net[s]`` (it contains the patch)."""
    lo0 = lo1 = lo2 = np.inf
    hi0 = hi1 = hi2 = -np.inf
    for a in range(4):
        for c in range(4):
            x, y, z = net[s, a, c, 0], net[s, a, c, 1], net[s, a, c, 2]
            lo0, hi0 = min(lo0, x), max(hi0, x)
            lo1, hi1 = min(lo1, y), max(hi1, y)
            lo2, hi2 = min(lo2, z), max(hi2, z)
    return pad_box(lo0, lo1, lo2, hi0, hi1, hi2)

@leaf_njit
def net_flatness(w, q):
    """Distance bound between net ``w[q]``'s patch and its corner triangles (module doc)."""
    e = 0.0
    for i in range(4):
        s = i / 3.0
        for j in range(4):
            t = j / 3.0
            d2 = 0.0
            for k in range(3):
                L = ((1 - s) * (1 - t) * w[q, 0, 0, k] + s * (1 - t) * w[q, 3, 0, k]
                     + (1 - s) * t * w[q, 0, 3, k] + s * t * w[q, 3, 3, k])
                d = w[q, i, j, k] - L
                d2 += d * d
            e = max(e, math.sqrt(d2))
    tw = 0.0
    for k in range(3):
        d = w[q, 0, 0, k] - w[q, 3, 0, k] - w[q, 0, 3, k] + w[q, 3, 3, k]
        tw += d * d
    return e + 0.25 * math.sqrt(tw)

def bezier_nets(cv: np.ndarray) -> np.ndarray:
    """(m,4,4,3) Bezier control nets of B-spline control grids ``cv`` (m,4,4,3)."""
    return bezier_nets_and_bounds(cv)[0]


def bezier_nets_and_bounds(cv: np.ndarray):
    """``(nets, lo, hi, bound)``: :func:`bezier_nets` of ``cv`` and their
    :func:`net_bounds`, in one pass through the patch table's kernel (:func:`bspline_nets`,
    the same conversion and bounds), which a render has loaded already, not a kernel of its
    own to load."""
    m = len(cv)
    pts = np.ascontiguousarray(cv, dtype=np.float64).reshape(-1, 3)
    out = np.empty((m, 4, 4, 3))
    rows = np.arange(m, dtype=np.int64)
    lo, hi, bound = np.empty((m, 3)), np.empty((m, 3)), np.empty(m)
    bspline_nets(0, 1, np.arange(16 * m, dtype=np.int64).reshape(m, 4, 4), pts, TO_BEZIER,
                 rows, NET_CHUNK, out, lo, hi, bound)
    return out, lo, hi, bound


@callee_njit  # (from bspline_nets)
def to_bezier(cv, M, out):
    """Bezier nets ``out`` (m,4,4,3) of B-spline grids ``cv`` (m,4,4,3); ``M`` = TO_BEZIER."""
    tmp = np.empty((4, 4, 3))
    for m in range(cv.shape[0]):
        for a in range(4):
            for j in range(4):
                for k in range(3):
                    tmp[a, j, k] = (M[a, 0] * cv[m, 0, j, k] + M[a, 1] * cv[m, 1, j, k]
                                    + M[a, 2] * cv[m, 2, j, k] + M[a, 3] * cv[m, 3, j, k])
        for a in range(4):
            for b in range(4):
                for k in range(3):
                    out[m, a, b, k] = (M[b, 0] * tmp[a, 0, k] + M[b, 1] * tmp[a, 1, k]
                                       + M[b, 2] * tmp[a, 2, k] + M[b, 3] * tmp[a, 3, k])

def net_bounds(bez: np.ndarray):
    """``(lo, hi, bound)`` of Bezier nets (m,4,4,3): their boxes (each (m,3)), which contain
    the patches, and (m,) a bound on |dP/du| and |dP/dv| over each patch (the largest
    control point of the derivative nets)."""
    lo = np.empty((len(bez), 3))
    hi = np.empty((len(bez), 3))
    bound = np.empty(len(bez))
    net_summary(np.ascontiguousarray(bez), lo, hi, bound)
    return lo, hi, bound

@nb.njit(cache=True, nogil=True)  # (also from Python)
def net_summary(bez, lo, hi, bound):
    """Box of each net, and 3 max |b[i+1,j] - b[i,j]| over both directions."""
    for m in range(bez.shape[0]):
        for k in range(3):
            lo[m, k] = np.inf
            hi[m, k] = -np.inf
        best = 0.0
        for a in range(4):
            for b in range(4):
                for k in range(3):
                    x = bez[m, a, b, k]
                    lo[m, k] = min(lo[m, k], x)
                    hi[m, k] = max(hi[m, k], x)
                if a < 3:
                    dx = bez[m, a + 1, b, 0] - bez[m, a, b, 0]
                    dy = bez[m, a + 1, b, 1] - bez[m, a, b, 1]
                    dz = bez[m, a + 1, b, 2] - bez[m, a, b, 2]
                    best = max(best, math.sqrt(dx * dx + dy * dy + dz * dz))
                if b < 3:
                    dx = bez[m, a, b + 1, 0] - bez[m, a, b, 0]
                    dy = bez[m, a, b + 1, 1] - bez[m, a, b, 1]
                    dz = bez[m, a, b + 1, 2] - bez[m, a, b, 2]
                    best = max(best, math.sqrt(dx * dx + dy * dy + dz * dz))
        bound[m] = 3.0 * best


# patches converted to Bezier nets per call of bspline_nets' inner kernels: their B-spline
# points stay in cache
NET_CHUNK = 64


@nb.njit(cache=True, nogil=True)
def bspline_nets(task, n_tasks, grids, pts, bspline_to_bezier, rows, chunk, nets, smin, smax,
                 ebound):
    """Bezier nets (R,4,4,3) of bicubic B-spline patches from their control grids (R,4,4)
    of ids into ``pts`` (the table's regular patches; :func:`bezier_nets`' grids), and each
    net's box and derivative bound (:func:`net_summary`) written to rows ``rows`` of
    ``smin``, ``smax``, ``ebound``.

    The conversion and the bounds are :func:`to_bezier` and :func:`net_summary`, called on
    ``chunk`` patches at a time so that neither the B-spline points nor the nets make a pass
    through memory; task ``task`` of ``n_tasks`` (tasks.run_tasks) takes chunks task,
    task + n_tasks, ...
    """
    cv = np.empty((chunk, 4, 4, 3))
    lo = np.empty((chunk, 3))
    hi = np.empty((chunk, 3))
    bound = np.empty(chunk)
    for a in range(task * chunk, len(grids), n_tasks * chunk):
        m = min(chunk, len(grids) - a)
        # the chunk's B-spline control points
        for i in range(m):
            for u in range(4):
                for v in range(4):
                    p = grids[a + i, u, v]
                    cv[i, u, v, 0] = pts[p, 0]
                    cv[i, u, v, 1] = pts[p, 1]
                    cv[i, u, v, 2] = pts[p, 2]
        to_bezier(cv[:m], bspline_to_bezier, nets[a : a + m])
        net_summary(nets[a : a + m], lo[:m], hi[:m], bound[:m])
        # scattered to the patches' rows
        for i in range(m):
            r = rows[a + i]
            smin[r, 0], smin[r, 1], smin[r, 2] = lo[i, 0], lo[i, 1], lo[i, 2]
            smax[r, 0], smax[r, 1], smax[r, 2] = hi[i, 0], hi[i, 1], hi[i, 2]
            ebound[r] = bound[i]


def bspline_basis(t):
    """Uniform cubic B-spline basis and derivative at t (arrays (m,)) -> (m,4), (m,4)."""
    s = 1.0 - t
    b = np.stack([s**3, 3 * t**3 - 6 * t**2 + 4, -3 * t**3 + 3 * t**2 + 3 * t + 1, t**3], 1) / 6
    d = np.stack([-(s**2), 3 * t**2 - 4 * t, -3 * t**2 + 2 * t + 1, t**2], 1) / 2
    return b, d

# ------------------------------------------------------------------------------------------
# quartic box splines (regular Loop patches)
# ------------------------------------------------------------------------------------------

# A Loop triangle whose three corners are smooth, valence 6 and crease-free is a quartic box
# spline of the 12 points around it. Lattice offsets of those points from corner 0, with
# corner 1 at (1, 0) and corner 2 at (0, 1) (the triangle's own (u, v)):
BOX_POINTS = np.array(
    [[-1, 0], [-1, 1], [-1, 2], [0, -1], [0, 0], [0, 1], [0, 2], [1, -1], [1, 0], [1, 1],
     [2, -1], [2, 0]]
)  # fmt: skip
# the six lattice directions counter-clockwise, and where each corner's leading edge points
LATTICE_DIRS = np.array([[1, 0], [0, 1], [-1, 1], [-1, 0], [0, -1], [1, -1]])
TRI_CORNER = np.array([[0, 0], [1, 0], [0, 1]])
TRI_LEAD = np.array([0, 2, 4])
# Basis: the weight of point k is sum over monomials u^a v^b (a + b <= 4, in this order) of
# BOX_COEF[monomial, k] / 24. It is the quartic that takes the exact limit values at the 15
# vertices of the triangle's level-2 refinement (limit mask 1/2, 1/12 x 6 of a regular
# vertex after two uniform steps); a quartic box-spline patch is fixed by them. The test
# suite re-derives it that way (tests/test_limit_tangents.py).
BOX_MONO = np.array([(a, b) for a in range(5) for b in range(5 - a)])
BOX_COEF = np.array(
    [
        [2, 2, 0, 2, 12, 2, 0, 2, 2, 0, 0, 0],
        [-4, 4, 0, -8, 0, 8, 0, -4, 4, 0, 0, 0],
        [0, 0, 0, 12, -24, 12, 0, 0, 0, 0, 0, 0],
        [4, -8, 4, -8, 16, -8, 0, 4, -8, 4, 0, 0],
        [-2, 4, -2, 2, -2, -2, 2, -2, 4, -2, 0, 0],
        [-8, -4, 0, -4, 0, 4, 0, 4, 8, 0, 0, 0],
        [12, -12, 0, 12, -24, 12, 0, -12, 12, 0, 0, 0],
        [0, 0, 0, -12, 24, -12, 0, 12, -24, 12, 0, 0],
        [-4, 8, -4, 4, -4, -4, 4, -4, 8, -4, 0, 0],
        [12, 0, 0, 0, -24, 0, 0, 0, 12, 0, 0, 0],
        [-12, 12, 0, 0, 24, -24, 0, 0, -12, 12, 0, 0],
        [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
        [-8, 4, 0, 4, 16, -8, 0, -8, -8, 4, 4, 0],
        [4, -4, 0, -4, -4, 8, 0, 8, -4, -4, -4, 4],
        [2, -2, 0, -2, -2, 4, 0, 4, -2, -2, -2, 2],
    ],
    dtype=np.float64,
) / 24.0


def box_spline_basis(u, v):
    """Quartic box-spline basis and its u, v derivatives at (u, v): three (12,) arrays."""
    a, b = BOX_MONO[:, 0], BOX_MONO[:, 1]
    m = u**a * v**b
    mu = np.where(a > 0, a * u ** np.maximum(a - 1, 0) * v**b, 0.0)
    mv = np.where(b > 0, b * u**a * v ** np.maximum(b - 1, 0), 0.0)
    return m @ BOX_COEF, mu @ BOX_COEF, mv @ BOX_COEF

# ------------------------------------------------------------------------------------------
# quartic triangular Bezier nets
# ------------------------------------------------------------------------------------------

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


def tri_bernstein(st: np.ndarray) -> np.ndarray:
    """(m, 15) quartic triangular Bernstein basis at parameters ``st`` (m, 2)."""
    s, t = st[:, 0:1], st[:, 1:2]
    w = 1.0 - s - t
    j, k = TRI_JK[:, 0], TRI_JK[:, 1]
    i = DEGREE - j - k
    coef = np.array([math.factorial(DEGREE) / (math.factorial(a) * math.factorial(b)
                                               * math.factorial(c)) for a, b, c in zip(i, j, k)])
    return coef * w**i * s**j * t**k


def tri_powers(st: np.ndarray) -> np.ndarray:
    """(m, 15) monomials ``s^j t^k`` (flat order of :func:`tri_index`) at ``st`` (m, 2)."""
    return st[:, 0:1] ** TRI_JK[:, 0] * st[:, 1:2] ** TRI_JK[:, 1]


def _exact(a: np.ndarray, unit: float) -> np.ndarray:
    """``a`` rounded to multiples of ``unit`` (its entries are such multiples in exact
    arithmetic; the solve only adds rounding)."""
    r = np.round(a / unit) * unit
    assert np.abs(r - a).max() < 1e-9
    return r


_V = tri_bernstein(TRI_PARAMS)  # collocation matrix: unisolvent at the domain points
# child nets from the parent's: the parent's polynomial at the child's domain points
TRI_SPLIT = np.ascontiguousarray(np.stack([
    _exact(np.linalg.solve(_V, tri_bernstein(CHILD_ORIGIN[c] + CHILD_SCALE[c] * TRI_PARAMS)),
           2.0**-DEGREE) for c in range(4)]))
# its nonzero weights, row 15 c + p (child c, point p) in CSR form, for the kernels
_nz = TRI_SPLIT.reshape(4 * N_TRI, N_TRI) != 0
SPLIT_PTR = np.concatenate([[0], np.cumsum(_nz.sum(axis=1))]).astype(np.int64)
SPLIT_COL = np.ascontiguousarray(np.nonzero(_nz)[1], dtype=np.int64)
SPLIT_W = np.ascontiguousarray(TRI_SPLIT.reshape(4 * N_TRI, N_TRI)[_nz])
# monomial coefficients from a net (integer weights)
TRI_MONO = np.ascontiguousarray(_exact(np.linalg.solve(tri_powers(TRI_PARAMS), _V), 1.0))


# the 12 box-spline points of a regular Loop patch -> its triangular net (15): the box
# spline's polynomial at the domain points, fitted in the Bernstein basis
BOX_TO_TRI = np.ascontiguousarray(np.linalg.solve(
    _V, (TRI_PARAMS[:, 0:1] ** BOX_MONO[:, 0] * TRI_PARAMS[:, 1:2] ** BOX_MONO[:, 1]) @ BOX_COEF))
# a flat triangle of corners A (0,0), B (1,0), C (0,1) as a quartic net: L(j/4, k/4)
FLAT_TO_TRI = np.ascontiguousarray(np.stack(
    [1.0 - TRI_PARAMS.sum(axis=1), TRI_PARAMS[:, 0], TRI_PARAMS[:, 1]], axis=1))

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
def tri_split(w, q, d0):
    """Child ``c`` of net ``w[q]`` into ``w[d0 + c]`` (c = 0..3; ``d0 > q``)."""
    for c in range(4):
        tri_child(w, q, c, w, d0 + c)


@leaf_njit
def tri_child(w, q, c, out, o):
    """Child ``c`` (Loop's child order) of net ``w[q]`` into ``out[o]`` (not ``w[q]``): row
    ``15 c + p`` of ``TRI_SPLIT`` as its nonzero weights (CSR: ``SPLIT_PTR``,
    ``SPLIT_COL``, ``SPLIT_W``, read as globals: Numba compiles them in as constants, 1.6x
    faster than the same arrays passed in)."""
    for p in range(N_TRI):
        row = c * N_TRI + p
        x = y = z = 0.0
        for i in range(SPLIT_PTR[row], SPLIT_PTR[row + 1]):
            r = SPLIT_COL[i]
            a = SPLIT_W[i]
            x += a * w[q, r, 0]
            y += a * w[q, r, 1]
            z += a * w[q, r, 2]
        out[o, p, 0] = x
        out[o, p, 1] = y
        out[o, p, 2] = z


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
    coefficients ``c``, for r = 0, 1, 2, from the powers ``ps``, ``pt`` (scalar sums).
    (The same three running sums as :func:`bez_sums`, over another basis: a triangle's 15
    monomials instead of a 4x4 tensor product; one generic sum would need the weights
    gathered into arrays first, on Newton's innermost loop.)"""
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
def tri_mono_eval(c, s, t, out, second):
    """Point, first and (with ``second``) second derivatives of the quartic with monomial
    coefficients ``c`` (15,3) at (s, t) into ``out`` rows P, Ps, Pt, Pss, Pst, Ptt
    (Newton's inner loop)."""
    s2, t2 = s * s, t * t
    ps = (1.0, s, s2, s2 * s, s2 * s2)
    pt = (1.0, t, t2, t2 * t, t2 * t2)
    _mono_sums(c, ps, pt, 0, 0, 1, 0, 0, 1, out, 0)
    if second:
        _mono_sums(c, ps, pt, 2, 0, 1, 1, 0, 2, out, 3)


@nb.njit(cache=True)
def tri_normals(nets, rows, st, mono_from_net, out):
    """Unit normals of triangular nets ``nets[rows]`` at parameters ``st`` (m,2) into ``out``
    (m,3) (orientation of (s, t)); where the derivatives vanish (an extraordinary corner),
    the normal a little way towards the triangle's centre, as :func:`bez_normal`."""
    mono = np.empty((N_TRI, 3))
    D = np.empty((6, 3))
    third = 1.0 / 3.0
    for m in range(len(rows)):
        tri_monomials(nets, rows[m], mono_from_net, mono)
        s, t = st[m, 0], st[m, 1]
        nx = ny = nz = 0.0
        for step in range(NORMAL_TRIES):
            tri_mono_eval(mono, s, t, D, False)
            nx, ny, nz, ok = unit_normal((D[1, 0], D[1, 1], D[1, 2]), (D[2, 0], D[2, 1], D[2, 2]))
            if ok:
                break
            s += (third - s) * NORMAL_STEP
            t += (third - t) * NORMAL_STEP
        out[m, 0], out[m, 1], out[m, 2] = nx, ny, nz
