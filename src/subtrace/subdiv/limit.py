"""Exact limit positions and tangents of the vertices of a refined level.

OpenSubdiv's closed-form limit masks are exact only for "suitably isolated" vertices. Here:

* smooth manifold vertices of valence >= 3 whose faces all have the scheme's regular size,
  crease vertices (two infinitely sharp edges) and corners take the closed-form masks
  (``catmark.py`` / ``loop.py``), vectorised in one kernel;
* vertices with semi-sharp features still alive are refined further, locally: the faces
  within two rings of them are cut out, refined once, and the same is repeated on their
  children until the sharpness has decayed (a vertex keeps its index through refinement);
* what is left once everything is stationary (darts, interior valence 2, irregular
  non-manifold cases) gets the exact limit from the left eigenvectors of its stationary
  one-ring subdivision matrix: eigenvalue 1 gives the limit point, the subdominant pair the
  tangent plane.

Tangents are OpenSubdiv's masks where those apply: du x dv points to the side the faces
wind counter-clockwise around. At a crease or boundary vertex du runs along the crease towards
its first sharp edge and dv across the span of faces from there to the second one (Biermann
et al.'s masks, as OpenSubdiv weights them). Those are the exact tangent plane only for the
regular spans and smaller (Catmark 1-2 faces, Loop 1-3); for wider spans they are
OpenSubdiv's approximation, a few degrees off on a coarse cage and converging with the level
(``Limit()`` in OpenSubdiv gives the same values). Elsewhere (the eigen-analysis) du and dv
span the true tangent plane, oriented from the topology alone (see :func:`_eigen_limit`).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from subtrace.runtime.jit import callee_njit, leaf_njit, nb
from subtrace.subdiv import catmark, loop
from subtrace.subdiv.creases import F0, RULE_CORNER, RULE_CREASE, RULE_SMOOTH, rule_of
from subtrace.subdiv.gridrefine import ring_limit
from subtrace.subdiv.refine import refine_level, refine_points, scheme_flag
from subtrace.subdiv.topology import (
    INF_SHARP, Level, Options, build_level, compact, gather, gather_index,
)

# vertex classes
ISOLATED = 0
SMOOTH = 1
CREASE = 2
CORNER = 3
HARD_SHARP = -1  # semi-sharp features remain: refine further
HARD_STATIONARY = -2  # nothing semi-sharp, but no exact closed-form mask: eigen-analysis

GRID_LIMITS = True  # False: every hard vertex through one-ring cuts (tests compare the two)


def limit_points(level: Level, points: np.ndarray, options: Options, which=None):
    """(P, du, dv), each (k,3) float64, for the vertices ``which`` (default all) of ``level``
    at ``points``."""
    points = np.ascontiguousarray(points, dtype=np.float64)
    which = np.arange(level.n_verts) if which is None else np.asarray(which, dtype=np.int64)
    n = len(which)
    P = np.zeros((n, 3))
    du = np.zeros((n, 3))
    dv = np.zeros((n, 3))
    cls = classify(level, options, which)
    _closed_form(level, points, options, cls, which, np.arange(n), P, du, dv)
    hard = np.nonzero(cls[which] < 0)[0]
    if len(hard):
        _hard_limits(level, points, options, which[hard], P, du, dv, rows=hard)
    return P, du, dv


def least_limit_height(level: Level, points: np.ndarray, options: Options, up) -> float:
    """The least ``P . up`` over the limit points of ``level``'s vertices: that of
    :func:`limit_points` to rounding, its costly part (the vertices whose limit takes
    repeated refinement: semi-sharp creases, ...) only for those that can lie lower than the
    least of the others. A vertex's limit point is a convex combination of the points of
    its incident faces (every Catmull-Clark and Loop mask, sharp, semi-sharp and
    boundary ones included, has non-negative weights; not Chaikin's creases nor the smooth
    triangle rule, which callers keep to :func:`limit_points`), so one whose faces' points
    all lie no lower than that least does not lower it."""
    points = np.ascontiguousarray(points, dtype=np.float64)
    up = np.asarray(up, np.float64)
    cls = classify(level, options)
    easy = np.nonzero(cls >= 0)[0]
    hard = np.nonzero(cls < 0)[0]
    least = np.inf
    if len(easy):
        P = np.zeros((len(easy), 3))
        du, dv = np.zeros_like(P), np.zeros_like(P)
        _closed_form(level, points, options, cls, easy, np.arange(len(easy)), P, du, dv)
        least = float((P @ up).min())
    if len(hard):
        h = points @ up
        fo, vfo = level.face_offsets, level.vert_face_offsets
        face_low = (np.minimum.reduceat(h[level.face_verts], fo[:-1]) if level.n_faces
                    else np.zeros(0))
        star_low = h.copy()
        has = np.diff(vfo) > 0
        if has.any() and len(level.vert_faces):
            low = np.minimum.reduceat(face_low[level.vert_faces], vfo[:-1][has])
            star_low[has] = np.minimum(star_low[has], low)
        hard = hard[star_low[hard] < least]
        if len(hard):
            P = np.zeros((len(hard), 3))
            du, dv = np.zeros_like(P), np.zeros_like(P)
            _hard_limits(level, points, options, hard, P, du, dv, rows=np.arange(len(hard)))
            least = min(least, float((P @ up).min()))
    return least


def classify(level: Level, options: Options, which=None) -> np.ndarray:
    """(V,) int8 vertex classes (see the constants above); with ``which``, only those
    vertices are classified (the others' entries are undefined)."""
    out = np.empty(level.n_verts, dtype=np.int8)
    if which is None or np.size(which) >= level.n_verts:  # (repeats: all at once is cheaper)
        verts = np.arange(level.n_verts)
    else:
        verts = np.ascontiguousarray(which, dtype=np.int64).ravel()
    _classify_kernel(
        options.regular_face_size,
        level.face_offsets,
        level.vert_face_offsets,
        level.vert_faces,
        level.vert_edge_offsets,
        level.vert_edges,
        level.vert_manifold,
        level.edge_sharpness,
        level.vert_sharpness,
        verts,
        out,
    )
    return out


@nb.njit(cache=True, nogil=True)
def _classify_kernel(
    reg_size,
    face_offsets,
    vert_face_offsets,
    vert_faces,
    vert_edge_offsets,
    vert_edges,
    vert_manifold,
    edge_sharp,
    vert_sharp,
    verts,
    out,
):
    n_max = 0
    for v in verts:
        n_max = max(n_max, vert_edge_offsets[v + 1] - vert_edge_offsets[v])
    buf = np.empty(n_max, np.float32)  # one buffer for every vertex's edge sharpnesses
    for v in verts:
        fa, fb = vert_face_offsets[v], vert_face_offsets[v + 1]
        ea, eb = vert_edge_offsets[v], vert_edge_offsets[v + 1]
        if fa == fb:
            out[v] = ISOLATED
            continue
        semi = vert_sharp[v] > F0 and vert_sharp[v] < INF_SHARP
        for i in range(eb - ea):
            s = edge_sharp[vert_edges[ea + i]]
            buf[i] = s
            if s > F0 and s < INF_SHARP:
                semi = True
        if semi:
            out[v] = HARD_SHARP
            continue
        rule = rule_of(vert_sharp[v], buf[: eb - ea])
        if rule == RULE_CORNER:
            out[v] = CORNER
        elif rule == RULE_CREASE:
            out[v] = CREASE
        elif rule == RULE_SMOOTH:
            ok = vert_manifold[v] and (eb - ea) == (fb - fa) and (fb - fa) >= 3
            for i in range(fa, fb):
                f = vert_faces[i]
                if face_offsets[f + 1] - face_offsets[f] != reg_size:
                    ok = False
            out[v] = SMOOTH if ok else HARD_STATIONARY
        else:  # dart
            out[v] = HARD_STATIONARY


# --------------------------------------------------------------------------------------
# closed-form masks
# --------------------------------------------------------------------------------------


def _closed_form(level, points, options, cls, which, dest, P, du, dv):
    """Closed-form limits of vertices ``which`` of ``level`` into rows ``dest`` of P, du, dv."""
    is_loop = options.scheme == "loop"
    max_val = int(np.max(np.diff(level.vert_edge_offsets), initial=0)) + 2
    tw, fw = tangent_tables(is_loop, max_val)
    which = np.ascontiguousarray(which, dtype=np.int64)
    # (None: no crease vertex among them, whose rule the kernel then compiles without)
    crease = True if np.any(np.asarray(cls)[which] == CREASE) else None
    _closed_form_kernel(
        scheme_flag(options.scheme),
        crease,
        level.face_offsets,
        level.face_verts,
        level.edge_verts,
        level.vert_face_offsets,
        level.vert_faces,
        level.vert_face_corner,
        level.vert_edge_offsets,
        level.vert_edges,
        level.edge_sharpness,
        cls,
        which,
        np.ascontiguousarray(dest, dtype=np.int64),
        tw,
        fw,
        points,
        P,
        du,
        dv,
    )


@functools.lru_cache(maxsize=16)
def tangent_tables(is_loop: bool, max_val: int):
    """(edge, diagonal) weights (max_val + 1, max_val) float64 of the smooth limit tangent
    of each valence from 3 to ``max_val`` (row n, its first n columns), made once a process
    for each scheme and largest valence (shared: the kernels only read them; left writable,
    as Numba types a read-only array apart and would compile the kernel again)."""
    tw = np.zeros((max_val + 1, max_val), dtype=np.float64)  # smooth tangent edge weights
    fw = np.zeros((max_val + 1, max_val), dtype=np.float64)  # smooth tangent diagonal weights
    scheme = loop if is_loop else catmark
    for n in range(3, max_val + 1):
        e, f = scheme.smooth_tangent_weights(n)
        tw[n, :n] = e
        if f is not None:
            fw[n, :n] = f
    return tw, fw


def smooth_edge_tangents(level: Level, points: np.ndarray, options: Options, verts, slots):
    """Limit tangents along ring edge ``slots[i]`` of the smooth vertices ``verts[i]``.

    The smooth tangent mask turned to begin at that edge (slot 0 is ``limit_points``' du):
    the derivative of the limit surface along the limit curve of the edge, up to a factor
    that depends on the valence only (regular vertices: 12x the derivative per unit edge
    of a bicubic B-spline patch for Catmark, 3x that of a quartic box-spline patch for Loop).
    Every vertex must be of class ``SMOOTH``. Returns (k,3) float64.
    """
    scheme = loop if options.scheme == "loop" else catmark
    X = np.asarray(points, dtype=np.float64)
    fo, fv = level.face_offsets, level.face_verts
    out = np.zeros((len(verts), 3))
    for t, (v, s) in enumerate(zip(verts, slots)):
        ea, eb = level.vert_edge_offsets[v], level.vert_edge_offsets[v + 1]
        fa = level.vert_face_offsets[v]
        n = eb - ea
        ew, fw = scheme.smooth_tangent_weights(n)
        ew, fw = np.roll(ew, s), None if fw is None else np.roll(fw, s)
        for i in range(n):
            a, b = level.edge_verts[level.vert_edges[ea + i]]
            out[t] += ew[i] * X[b if a == v else a]
            if fw is not None:
                f, k = level.vert_faces[fa + i], level.vert_face_corner[fa + i]
                out[t] += fw[i] * X[fv[fo[f] + (k + 2) % (fo[f + 1] - fo[f])]]
    return out


@leaf_njit
def _far(edge_verts, e, v):
    a = edge_verts[e, 0]
    return edge_verts[e, 1] if a == v else a


@nb.njit(cache=True, inline="always")
def _add3(P, du, dv, r, X, q, w, w1, w2):
    """Add point q of X with weights w (position), w1 (du) and w2 (dv) to row r."""
    for k in range(3):
        P[r, k] += w * X[q, k]
        du[r, k] += w1 * X[q, k]
        dv[r, k] += w2 * X[q, k]


@nb.njit(cache=True, nogil=True)
def _closed_form_kernel(
    is_loop,
    crease,
    face_offsets,
    face_verts,
    edge_verts,
    vert_face_offsets,
    vert_faces,
    vert_face_corner,
    vert_edge_offsets,
    vert_edges,
    edge_sharp,
    cls,
    which,
    dest,
    tw,
    fw,
    X,
    P,
    du,
    dv,
):
    for t in range(len(which)):
        v = which[t]
        r = dest[t]
        c = cls[v]
        ea, eb = vert_edge_offsets[v], vert_edge_offsets[v + 1]
        fa, fb = vert_face_offsets[v], vert_face_offsets[v + 1]
        ne = eb - ea
        if c == ISOLATED:
            for k in range(3):
                P[r, k] = X[v, k]
                du[r, k] = 0.0
                dv[r, k] = 0.0
        elif c == CORNER:
            for k in range(3):
                P[r, k] = X[v, k]
            if ne >= 2:
                # along the first two edges (OpenSubdiv scales Loop's by 3)
                s = 3.0 if is_loop is not None else 1.0
                a = _far(edge_verts, vert_edges[ea], v)
                b = _far(edge_verts, vert_edges[ea + 1], v)
                for k in range(3):
                    du[r, k] = s * (X[a, k] - X[v, k])
                    dv[r, k] = s * (X[b, k] - X[v, k])
        elif c == CREASE:
            if crease is not None:  # (None: the caller found no crease vertex)
                # the first two sharp edges in ring order lead and trail the span of faces
                # i0 .. i1-1 that the tangents describe (OpenSubdiv's "crease ends")
                i0 = 0
                while edge_sharp[vert_edges[ea + i0]] <= F0:
                    i0 += 1
                i1 = i0 + 1
                while edge_sharp[vert_edges[ea + i1]] <= F0:
                    i1 += 1
                a = _far(edge_verts, vert_edges[ea + i0], v)
                b = _far(edge_verts, vert_edges[ea + i1], v)
                for k in range(3):
                    P[r, k] = (4.0 * X[v, k] + X[a, k] + X[b, k]) / 6.0
                # along the crease, towards the leading edge
                s = 1.5 if is_loop is not None else 0.5
                for k in range(3):
                    du[r, k] = s * (X[a, k] - X[b, k])
                    dv[r, k] = 0.0
                # across the span, pointing into it (Biermann et al.'s masks as OpenSubdiv
                # weights them); an unordered non-manifold ring may list fewer faces than the
                # span claims: those faces are left out
                m = i1 - i0  # faces in the span
                if is_loop is not None:
                    wv, wc, wi = _loop_cross_tangent(m)
                else:
                    wv, wc, wi = _catmark_cross_tangent(m)
                for k in range(3):
                    dv[r, k] = wv * X[v, k] + wc * (X[a, k] + X[b, k])
                for i in range(1, m):
                    e = _far(edge_verts, vert_edges[ea + i0 + i], v)
                    w = wi * _cross_edge_weight(is_loop, m, i)
                    for k in range(3):
                        dv[r, k] += w * X[e, k]
                if is_loop is None and m >= 2:
                    for i in range(m):
                        if fa + i0 + i >= fb:
                            break
                        f = vert_faces[fa + i0 + i]
                        kk = vert_face_corner[fa + i0 + i]
                        off = face_offsets[f]
                        q = face_verts[off + (kk + 2) % (face_offsets[f + 1] - off)]
                        w = wi * _catmark_cross_face_weight(m, i)
                        for k in range(3):
                            dv[r, k] += w * X[q, k]
        elif c == SMOOTH:
            n = ne
            if is_loop is not None:
                vw, ew, dw = loop.smooth_limit_weights(n)
            else:
                vw, ew, dw = catmark.smooth_limit_weights(n)
            for k in range(3):
                P[r, k] = vw * X[v, k]
                du[r, k] = 0.0
                dv[r, k] = 0.0
            for i in range(n):
                e = _far(edge_verts, vert_edges[ea + i], v)
                # the second tangent mask is the first rotated by one ring position
                _add3(P, du, dv, r, X, e, ew, tw[n, i], tw[n, (i - 1 + n) % n])
                if is_loop is None:
                    f = vert_faces[fa + i]
                    kk = vert_face_corner[fa + i]
                    off = face_offsets[f]
                    q = face_verts[off + (kk + 2) % 4]
                    _add3(P, du, dv, r, X, q, dw, fw[n, i], fw[n, (i - 1 + n) % n])


# --------------------------------------------------------------------------------------
# crease cross-tangent masks
#
# The tangent across a crease or boundary at a vertex whose span (the faces between its
# two sharp edges, counter-clockwise from the leading one) has m faces: Biermann et al.'s
# masks, as OpenSubdiv's Sdc::Scheme<...>::assignCreaseLimitTangentMasks weights them.
# Each mask is (vertex weight, weight of both crease ends, scale of the interior weights);
# interior edge i (1 <= i < m) of the span and, for Catmark, the diagonal vertex of span
# face i (0 <= i < m) get that scale times _cross_edge_weight / _catmark_cross_face_weight.
# They belong with the other masks in catmark.py / loop.py.
# --------------------------------------------------------------------------------------


@callee_njit
def _catmark_cross_tangent(m):
    if m == 1:  # a single face: from the vertex to the average of the crease ends
        return -6.0, 3.0, 0.0
    if m == 2:  # the regular boundary: the uniform B-spline cross derivative
        return -4.0 / 6.0, -1.0 / 6.0, 1.0 / 6.0
    theta = math.pi / m
    c = math.cos(theta)
    r = (c + 1.0) / math.sin(theta)
    denom = 1.0 / (m * (3.0 + c))
    return 4.0 * r * (c - 1.0) * denom, -r * (1.0 + 2.0 * c) * denom, denom


@callee_njit
def _loop_cross_tangent(m):
    if m == 1:  # a single face
        return -6.0, 3.0, 0.0
    if m == 2:  # one interior edge
        return -3.0, 0.0, 3.0
    if m == 3:  # the regular boundary (OpenSubdiv's weights omit a factor sqrt(3)/2)
        r3 = math.sqrt(3.0)
        return -r3, -0.5 * r3, r3
    theta = math.pi / m
    return 0.0, -3.0 * math.sin(theta), 6.0 * (1.0 - math.cos(theta))


@callee_njit
def _cross_edge_weight(is_loop, m, i):
    """Relative weight of interior edge i of an m-face span (see the masks above)."""
    if is_loop is not None:
        return 1.0 if m <= 3 else math.sin(i * math.pi / m)
    if m == 2:
        return 4.0
    return 4.0 * math.sin(i * math.pi / m)


@callee_njit
def _catmark_cross_face_weight(m, i):
    """Relative weight of the diagonal vertex of face i of an m-face span (m >= 2)."""
    if m == 2:
        return 1.0
    theta = math.pi / m
    return math.sin(i * theta) + math.sin((i + 1) * theta)


# --------------------------------------------------------------------------------------
# vertices without an exact closed form
# --------------------------------------------------------------------------------------


def extract(level: Level, verts: np.ndarray, rings: int = 2):
    """Cut out the faces within ``rings`` face-rings of ``verts``.

    Returns (sub Level, sub->parent vertex map, parent->sub vertex map (-1 outside), the
    parent face of each sub face). Edge
    identities, sharpness and non-manifold flags are carried over unchanged, so every vertex
    whose faces are all inside the cut keeps its rules.
    """
    vf_off, vf = level.vert_face_offsets, level.vert_faces
    fo, fv = level.face_offsets, level.face_verts
    vmask = np.zeros(level.n_verts, dtype=bool)
    vmask[verts] = True
    fmask = np.zeros(level.n_faces, dtype=bool)
    for _ in range(rings):
        vs = np.nonzero(vmask)[0]
        fmask[gather(vf_off, vf, vs)] = True
        vmask[gather(fo, fv, np.nonzero(fmask)[0])] = True
    faces = np.nonzero(fmask)[0]
    return cut_level(level, faces)


def cut_level(level: Level, faces: np.ndarray):
    """The sub-level made of ``faces`` (see :func:`extract`), with the same returns: the
    face-varying channel (``subdiv.facevarying``) is cut by the faces its cage's level was."""
    fo, fv = level.face_offsets, level.face_verts
    corners = gather_index(fo, faces)
    sizes = np.diff(fo)[faces]
    old_v, vmap = compact(fv[corners], level.n_verts)
    old_e, emap = compact(level.face_edges[corners], level.n_edges)
    offsets = np.zeros(len(faces) + 1, dtype=np.int64)
    np.cumsum(sizes, out=offsets[1:])
    sub = build_level(
        len(old_v),
        offsets,
        vmap[fv[corners]],
        vmap[level.edge_verts[old_e]],
        emap[level.face_edges[corners]],
        level.face_edge_forward[corners],
        level.edge_sharpness[old_e],
        level.vert_sharpness[old_v],
        level.face_hole[faces],
        edge_nonmanifold=level.edge_nonmanifold[old_e],
        vert_nonmanifold=~level.vert_manifold[old_v],
    )
    return sub, old_v, vmap, faces


def _hard_limits(level, points, options, hard, P, du, dv, rows):
    """The limits of the vertices ``hard`` of ``level`` whose semi-sharp features need
    refinement (or eigen-analysis), into rows ``rows`` of P, du, dv: inside the mesh with
    quads around, by their rings alone (:func:`_grid_limits`), the others by refining
    one-ring cuts through topology."""
    if options.scheme == "catmark" and not options.chaikin and GRID_LIMITS:
        done = _grid_limits(level, points, hard, P, du, dv, rows)
        hard, rows = hard[~done], np.asarray(rows)[~done]
        if not len(hard):
            return
    cur_level, cur_pts = level, points
    ids = hard.astype(np.int64)  # vertex ids in the current level
    owners = np.asarray(rows, dtype=np.int64)  # rows of P they fill
    # A vertex's next one-ring (its vertex point, its edges' and faces' points) and its
    # edges' next sharpness are made from its one-ring alone under uniform creases, so a cut
    # of one ring refines it exactly (the same sums, so the same bits); Chaikin's sharpness
    # averages the edges at the ring's far ends too, which need the second ring.
    rings = 2 if options.chaikin else 1
    for _ in range(64):
        sub, sub_to_cur, cur_to_sub, _ = extract(cur_level, ids, rings=rings)
        sub_pts = cur_pts[sub_to_cur]
        sid = cur_to_sub[ids]
        cls = classify(sub, options)
        c = cls[sid]
        done = c >= 0
        if done.any():
            _closed_form(sub, sub_pts, options, cls, sid[done], owners[done], P, du, dv)
        stationary = c == HARD_STATIONARY
        for s, o in zip(sid[stationary], owners[stationary]):
            _eigen_limit(sub, sub_pts, options, int(s), int(o), P, du, dv)
        keep = c == HARD_SHARP
        if not keep.any():
            return
        ref = refine_level(sub, options)
        cur_pts = refine_points(ref, sub_pts)
        cur_level = ref.child
        ids, owners = sid[keep], owners[keep]
    raise RuntimeError("limit: sharpness did not decay")  # pragma: no cover


def _grid_limits(level, points, hard, P, du, dv, rows):
    """(len(hard),) bool: which of the vertices ``hard`` of ``level`` (Catmull-Clark,
    uniform creases) are inside the mesh with quads around, none a hole, and no infinite
    sharpness on them or their edges; their limit points and tangents go to rows ``rows``
    of P, du, dv: their rings (the vertex, its edges' far ends and its faces' opposite
    corners, in ring order) refined in a kernel (``gridrefine.ring_limit``: a vertex's
    next ring and its edges' next sharpness come from its own ring, as the one-ring cut
    below makes them through topology) until the vertex and its edges are smooth, then
    the smooth limit masks there (OpenSubdiv's convention: du along the first edge of the
    ring, du x dv the outward normal)."""
    ok = np.zeros(len(hard), dtype=bool)
    n_max = int(np.diff(level.vert_edge_offsets).max(initial=0))
    tw, fw = tangent_tables(False, max(n_max, 3))
    _grid_limits_kernel(level.face_offsets, level.face_verts, level.edge_verts,
                        level.vert_face_offsets, level.vert_faces, level.vert_face_corner,
                        level.vert_edge_offsets, level.vert_edges, level.vert_manifold,
                        level.edge_sharpness, level.vert_sharpness, level.face_hole,
                        np.float32(INF_SHARP), np.ascontiguousarray(hard, dtype=np.int64),
                        np.ascontiguousarray(rows, dtype=np.int64), points, tw, fw, n_max,
                        P, du, dv, ok)
    return ok


@nb.njit(cache=True, nogil=True)
def _grid_limits_kernel(fo, fv, ev, vfo, vf, vfc, veo, ve, manifold, es, vsharp, hole,
                        inf_sharp, which, rows, X, tw, fw, n_max, P, du, dv, ok):
    """:func:`_grid_limits`' kernel: ``ok[t]`` set for each vertex ``which[t]`` it takes."""
    c = np.empty(3)
    E = np.empty((n_max, 3))
    D = np.empty((n_max, 3))
    F = np.empty((n_max, 3))
    M = np.empty((n_max, 3))
    s = np.empty(n_max, np.float32)
    for t in range(len(which)):
        p = which[t]
        n = veo[p + 1] - veo[p]
        if not manifold[p] or n < 3 or vfo[p + 1] - vfo[p] != n or vsharp[p] >= inf_sharp:
            continue
        good = True
        for i in range(n):
            f = vf[vfo[p] + i]
            if fo[f + 1] - fo[f] != 4 or hole[f] or es[ve[veo[p] + i]] >= inf_sharp:
                good = False
        if not good:
            continue
        for k in range(3):
            c[k] = X[p, k]
        for i in range(n):
            g = ve[veo[p] + i]
            far = ev[g, 1] if ev[g, 0] == p else ev[g, 0]
            f = vf[vfo[p] + i]
            diag = fv[fo[f] + (vfc[vfo[p] + i] + 2) % 4]
            for k in range(3):
                E[i, k] = X[far, k]
                D[i, k] = X[diag, k]
            s[i] = es[g]
        r = rows[t]
        ring_limit(c, E, D, s, vsharp[p], n, tw[n], fw[n], F, M, P[r], du[r], dv[r])
        ok[t] = True


def ring_of(level: Level, v: int, start: int = 0) -> np.ndarray:
    """The one-ring of ``v`` in a fixed order: v, far ends of its edges, then the remaining
    vertices of each incident face (from the corner after the leading edge's far end).

    ``start`` rotates an interior ring to begin at its face (and leading edge) ``start``."""
    ea, eb = level.vert_edge_offsets[v], level.vert_edge_offsets[v + 1]
    fa, fb = level.vert_face_offsets[v], level.vert_face_offsets[v + 1]
    edges = np.roll(level.vert_edges[ea:eb], -start)
    slots = np.roll(np.arange(fa, fb), -start)
    out = [v]
    for e in edges:
        a, b = level.edge_verts[e]
        out.append(int(b if a == v else a))
    fo, fv = level.face_offsets, level.face_verts
    for j in slots:
        f = level.vert_faces[j]
        k = level.vert_face_corner[j]
        n = fo[f + 1] - fo[f]
        for i in range(2, n - 1):
            out.append(int(fv[fo[f] + (k + i) % n]))
    seen = set()
    uniq = []
    for x in out:
        if x not in seen:
            seen.add(x)
            uniq.append(x)
    return np.array(uniq, dtype=np.int64)


def ring_matrix(level: Level, options: Options, v: int, depth: int = 1):
    """Subdivision matrix of ``v``'s one-ring after ``depth`` levels: (A, ring, sub->level
    vertex map, child level, child ring) with child_ring_points = A @ ring_points."""
    sub, sub_to_cur, cur_to_sub, _ = extract(level, np.array([v]), rings=2)
    A, ring, lev, cring = _sub_ring_matrix(sub, options, int(cur_to_sub[v]), depth)
    return A, ring, sub_to_cur, lev, cring


def _sub_ring_matrix(sub: Level, options: Options, sv: int, depth: int):
    ring = ring_of(sub, sv)
    W = np.eye(sub.n_verts)
    lev = sub
    start = 0
    for _ in range(depth):
        ref = refine_level(lev, options)
        W = refine_points(ref, W)
        # the child ring must list the children of the parent ring slot by slot: it begins
        # at the child of the first face (child j of a face lies at its corner j, and the
        # vertex keeps its index), wherever the child level's own ordering begins
        j = lev.vert_face_offsets[sv] + start
        f, k = lev.vert_faces[j], lev.vert_face_corner[j]
        first = 4 * f + k if options.scheme == "loop" else lev.face_offsets[f] + k
        child = ref.child
        faces = child.vert_faces[child.vert_face_offsets[sv] : child.vert_face_offsets[sv + 1]]
        hit = np.nonzero(faces == first)[0]
        start = int(hit[0]) if len(hit) else 0
        lev = child
    cring = ring_of(lev, sv, start)
    return W[np.ix_(cring, ring)], ring, lev, cring


def ring_polygon(level: Level, v: int, ring: np.ndarray) -> np.ndarray:
    """Positions in ``ring`` (see :func:`ring_of`) of the closed polygon of ``v``'s one-ring
    in counter-clockwise order: the far end of edge i, then the other corners of face i."""
    pos = {int(x): i for i, x in enumerate(ring)}
    fo, fv = level.face_offsets, level.face_verts
    out = []
    for j in range(level.vert_face_offsets[v], level.vert_face_offsets[v + 1]):
        f = level.vert_faces[j]
        k = level.vert_face_corner[j]
        n = fo[f + 1] - fo[f]
        for i in range(1, n - 1):
            out.append(pos[int(fv[fo[f] + (k + i) % n])])
    return np.array(out, dtype=np.int64)


def _eigen_limit(level, points, options, v, row, P, du, dv, _refined=0):
    """Exact limit of a vertex with a stationary neighbourhood from its ring eigenvectors.

    The limit point is the dominant left eigenvector applied to the ring; the tangents are
    the two subdominant ones. Their orientation comes from the topology alone: the ring
    polygon, written in the coordinates of the matching right eigenvectors (the control net
    of the characteristic map), must turn counter-clockwise, so du x dv points to the side
    the faces wind counter-clockwise around whatever the geometry (and an affine map of the
    cage moves the normal by its cofactor matrix, flipping it under a reflection).
    """
    sub, sub_to_cur, cur_to_sub, _ = extract(level, np.array([v]), rings=2)
    sv = int(cur_to_sub[v])
    A, ring, _, _ = _sub_ring_matrix(sub, options, sv, depth=1)
    fs = sub.vert_faces[sub.vert_face_offsets[sv] : sub.vert_face_offsets[sv + 1]]
    sizes = np.diff(sub.face_offsets)[fs]
    n_edges = sub.vert_edge_offsets[sv + 1] - sub.vert_edge_offsets[sv]
    changes = np.any(sizes != options.regular_face_size)
    changes |= len(ring) != 1 + n_edges + np.sum(sizes - 3)
    if changes and _refined < 8:
        # the ring changes shape once (n-gons at level 0, or a ring that touches itself on
        # a small cage and lists a vertex twice): refine first, until it is stationary
        ref = refine_level(sub, options)
        pts = refine_points(ref, points[sub_to_cur])
        _eigen_limit(ref.child, pts, options, sv, row, P, du, dv, _refined + 1)
        return
    if A.shape[0] != A.shape[1]:  # pragma: no cover - a ring that never settles
        return
    X = points[sub_to_cur[ring]]
    w, vl = np.linalg.eig(A.T)
    order = np.argsort(-np.abs(w))
    l1 = np.real(vl[:, order[0]])
    P[row] = (l1 / l1.sum()) @ X
    if len(w) < 3 or abs(w[order[2]]) < 1e-12:
        return
    # the subdominant pair lam2, lam3 (complex conjugates, or two reals, possibly equal and
    # then possibly defective): its left and right invariant subspaces are the left and right
    # null spaces of the real matrix (A - lam2)(A - lam3), which handles all three cases alike
    lam2, lam3 = w[order[1]], w[order[2]]
    n = len(A)
    M = A @ A - np.real(lam2 + lam3) * A + np.real(lam2 * lam3) * np.eye(n)
    U, _, Vh = np.linalg.svd(M)
    L = U[:, -2:].T  # (2, n): the tangent masks
    R = Vh[-2:].T  # (n, 2)
    # scaled so that L @ R is the identity, the rows of R are the ring points' coordinates
    # in the basis the tangents L @ X are written in (the characteristic map's control net)
    R = R @ np.linalg.inv(L @ R)
    poly = R[ring_polygon(sub, sv, ring)]
    area = np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1])
    du[row] = L[0] @ X
    dv[row] = (L[1] if area >= 0 else -L[1]) @ X
