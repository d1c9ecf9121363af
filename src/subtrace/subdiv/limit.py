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

Tangents use OpenSubdiv's masks where those apply; elsewhere their directions span the true
tangent plane and ``du x dv`` points to the side the faces wind counter-clockwise around.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..mesh.topology import Level, Options, build_level
from . import catmark, loop
from .creases import F0, F_INF, RULE_CORNER, RULE_CREASE, RULE_SMOOTH, rule_of

# vertex classes
_ISOLATED = 0
_SMOOTH = 1
_CREASE = 2
_CORNER = 3
_HARD_SHARP = -1  # semi-sharp features remain: refine further
_HARD_STATIONARY = -2  # nothing semi-sharp, but no exact closed-form mask: eigen-analysis


def limit_points(level: Level, points: np.ndarray, options: Options, which=None):
    """(P, du, dv), each (k,3) float64, for the vertices ``which`` (default all) of ``level``
    at ``points``."""
    points = np.ascontiguousarray(points, dtype=np.float64)
    which = np.arange(level.n_verts) if which is None else np.asarray(which, dtype=np.int64)
    n = len(which)
    P = np.zeros((n, 3))
    du = np.zeros((n, 3))
    dv = np.zeros((n, 3))
    cls = classify(level, options)
    _closed_form(level, points, options, cls, which, np.arange(n), P, du, dv)
    hard = np.nonzero(cls[which] < 0)[0]
    if len(hard):
        _hard_limits(level, points, options, which[hard], P, du, dv, rows=hard)
    return P, du, dv


def classify(level: Level, options: Options) -> np.ndarray:
    """(V,) int8 vertex classes (see the constants above)."""
    out = np.empty(level.n_verts, dtype=np.int8)
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
        out,
    )
    return out


@nb.njit(cache=True)
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
    out,
):
    for v in range(len(vert_face_offsets) - 1):
        fa, fb = vert_face_offsets[v], vert_face_offsets[v + 1]
        ea, eb = vert_edge_offsets[v], vert_edge_offsets[v + 1]
        if fa == fb:
            out[v] = _ISOLATED
            continue
        es = np.empty(eb - ea, np.float32)
        semi = vert_sharp[v] > F0 and vert_sharp[v] < F_INF
        for i in range(eb - ea):
            s = edge_sharp[vert_edges[ea + i]]
            es[i] = s
            if s > F0 and s < F_INF:
                semi = True
        if semi:
            out[v] = _HARD_SHARP
            continue
        rule = rule_of(vert_sharp[v], es)
        if rule == RULE_CORNER:
            out[v] = _CORNER
        elif rule == RULE_CREASE:
            out[v] = _CREASE
        elif rule == RULE_SMOOTH:
            ok = vert_manifold[v] and (eb - ea) == (fb - fa) and (fb - fa) >= 3
            for i in range(fa, fb):
                f = vert_faces[i]
                if face_offsets[f + 1] - face_offsets[f] != reg_size:
                    ok = False
            out[v] = _SMOOTH if ok else _HARD_STATIONARY
        else:  # dart
            out[v] = _HARD_STATIONARY


# --------------------------------------------------------------------------------------
# closed-form masks
# --------------------------------------------------------------------------------------


def _closed_form(level, points, options, cls, which, dest, P, du, dv):
    """Closed-form limits of vertices ``which`` of ``level`` into rows ``dest`` of P, du, dv."""
    is_loop = options.scheme == "loop"
    max_val = int(np.max(np.diff(level.vert_edge_offsets), initial=0)) + 2
    tw = np.zeros((max_val + 1, max_val), dtype=np.float64)  # smooth tangent edge weights
    fw = np.zeros((max_val + 1, max_val), dtype=np.float64)  # smooth tangent diagonal weights
    for n in range(3, max_val + 1):
        scheme = loop if is_loop else catmark
        e, f = scheme.smooth_tangent_weights(n)
        tw[n, :n] = e
        if f is not None:
            fw[n, :n] = f
    _closed_form_kernel(
        is_loop,
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
        np.ascontiguousarray(which, dtype=np.int64),
        np.ascontiguousarray(dest, dtype=np.int64),
        tw,
        fw,
        points,
        P,
        du,
        dv,
    )


@nb.njit(cache=True)
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


@nb.njit(cache=True)
def _closed_form_kernel(
    is_loop,
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
        if c == _ISOLATED:
            for k in range(3):
                P[r, k] = X[v, k]
                du[r, k] = 0.0
                dv[r, k] = 0.0
        elif c == _CORNER:
            for k in range(3):
                P[r, k] = X[v, k]
            if ne >= 2:
                a = _far(edge_verts, vert_edges[ea], v)
                b = _far(edge_verts, vert_edges[ea + 1], v)
                for k in range(3):
                    du[r, k] = X[a, k] - X[v, k]
                    dv[r, k] = X[b, k] - X[v, k]
        elif c == _CREASE:
            i0 = 0
            while edge_sharp[vert_edges[ea + i0]] <= F0:
                i0 += 1
            i1 = ne - 1
            while edge_sharp[vert_edges[ea + i1]] <= F0:
                i1 -= 1
            a = _far(edge_verts, vert_edges[ea + i0], v)
            b = _far(edge_verts, vert_edges[ea + i1], v)
            for k in range(3):
                P[r, k] = (4.0 * X[v, k] + X[a, k] + X[b, k]) / 6.0
                du[r, k] = 0.5 * (X[a, k] - X[b, k])
                dv[r, k] = 0.0
            # cross tangent over the interior span between the crease edges (faces i0..i1-1)
            m = i1 - i0  # faces in the span
            if m >= 1 and i1 - i0 <= fb - fa:
                theta = math.pi / m
                for i in range(1, m):
                    w = math.sin(i * theta)
                    e = _far(edge_verts, vert_edges[ea + i0 + i], v)
                    for k in range(3):
                        dv[r, k] += w * (X[e, k] - X[v, k])
                for i in range(m):
                    if fa + i0 + i >= fb:
                        break
                    f = vert_faces[fa + i0 + i]
                    kk = vert_face_corner[fa + i0 + i]
                    off = face_offsets[f]
                    n = face_offsets[f + 1] - off
                    w = 0.5 * (math.sin(i * theta) + math.sin((i + 1) * theta))
                    if m == 1:
                        w = 1.0
                    for j in range(2, n - 1):
                        q = face_verts[off + (kk + j) % n]
                        for k in range(3):
                            dv[r, k] += w * (X[q, k] - X[v, k])
        elif c == _SMOOTH:
            n = ne
            if is_loop:
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
                if not is_loop:
                    f = vert_faces[fa + i]
                    kk = vert_face_corner[fa + i]
                    off = face_offsets[f]
                    q = face_verts[off + (kk + 2) % 4]
                    _add3(P, du, dv, r, X, q, dw, fw[n, i], fw[n, (i - 1 + n) % n])


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
        fmask[_gather(vf_off, vf, vs)] = True
        vmask[_gather(fo, fv, np.nonzero(fmask)[0])] = True
    faces = np.nonzero(fmask)[0]
    return _cut(level, faces)


def _cut(level: Level, faces: np.ndarray):
    """The sub-level made of ``faces`` (see :func:`extract`); also returns ``faces``."""
    fo, fv = level.face_offsets, level.face_verts
    corners = _gather_index(fo, faces)
    sizes = np.diff(fo)[faces]
    old_v = np.unique(fv[corners])
    vmap = np.full(level.n_verts, -1, dtype=np.int64)
    vmap[old_v] = np.arange(len(old_v))
    old_e = np.unique(level.face_edges[corners])
    emap = np.full(level.n_edges, -1, dtype=np.int64)
    emap[old_e] = np.arange(len(old_e))
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


def _gather(offsets, values, rows):
    return values[_gather_index(offsets, rows)]


def _gather_index(offsets, rows):
    starts = offsets[rows]
    counts = offsets[rows + 1] - starts
    if counts.sum() == 0:
        return np.zeros(0, dtype=np.int64)
    idx = np.repeat(starts - np.cumsum(np.r_[0, counts[:-1]]), counts)
    return idx + np.arange(counts.sum())


def _hard_limits(level, points, options, hard, P, du, dv, rows):
    from .refine import refine_level, refine_points

    cur_level, cur_pts = level, points
    ids = hard.astype(np.int64)  # vertex ids in the current level
    owners = np.asarray(rows, dtype=np.int64)  # rows of P they fill
    for _ in range(64):
        sub, sub_to_cur, cur_to_sub, _ = extract(cur_level, ids, rings=2)
        sub_pts = cur_pts[sub_to_cur]
        sid = cur_to_sub[ids]
        cls = classify(sub, options)
        c = cls[sid]
        done = c >= 0
        if done.any():
            _closed_form(sub, sub_pts, options, cls, sid[done], owners[done], P, du, dv)
        stationary = c == _HARD_STATIONARY
        for s, o in zip(sid[stationary], owners[stationary]):
            _eigen_limit(sub, sub_pts, options, int(s), int(o), P, du, dv)
        keep = c == _HARD_SHARP
        if not keep.any():
            return
        ref = refine_level(sub, options)
        cur_pts = refine_points(ref, sub_pts)
        cur_level = ref.child
        ids, owners = sid[keep], owners[keep]
    raise RuntimeError("limit: sharpness did not decay")  # pragma: no cover


def ring_of(level: Level, v: int) -> np.ndarray:
    """The one-ring of ``v`` in a fixed order: v, far ends of its edges, then the remaining
    vertices of each incident face (from the corner after the leading edge's far end)."""
    out = [v]
    for e in level.vert_edges[level.vert_edge_offsets[v] : level.vert_edge_offsets[v + 1]]:
        a, b = level.edge_verts[e]
        out.append(int(b if a == v else a))
    fo, fv = level.face_offsets, level.face_verts
    for j in range(level.vert_face_offsets[v], level.vert_face_offsets[v + 1]):
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
    """Subdivision matrix of ``v``'s one-ring after ``depth`` levels: (A, ring, child level,
    child ring) with child_ring_points = A @ ring_points."""
    from .refine import refine_level, refine_points

    sub, sub_to_cur, cur_to_sub, _ = extract(level, np.array([v]), rings=2)
    sv = int(cur_to_sub[v])
    ring = ring_of(sub, sv)
    W = np.eye(sub.n_verts)
    lev = sub
    for _ in range(depth):
        ref = refine_level(lev, options)
        W = refine_points(ref, W)
        lev = ref.child
    cring = ring_of(lev, sv)
    return W[np.ix_(cring, ring)], ring, sub_to_cur, lev, cring


def _eigen_limit(level, points, options, v, row, P, du, dv):
    """Exact limit of a vertex with a stationary neighbourhood from its ring eigenvectors."""
    A, ring, sub_to_cur, _, cring = ring_matrix(level, options, v, depth=1)
    if A.shape[0] != A.shape[1]:
        # the ring changes shape once (n-gons at level 0): refine one level first
        from .refine import refine_level, refine_points

        sub, s2c, c2s, _ = extract(level, np.array([v]), rings=2)
        ref = refine_level(sub, options)
        pts = refine_points(ref, points[s2c])
        _eigen_limit(ref.child, pts, options, int(c2s[v]), row, P, du, dv)
        return
    X = points[sub_to_cur[ring]]
    w, vl = np.linalg.eig(A.T)
    order = np.argsort(-np.abs(w))
    i1 = order[0]
    l1 = np.real(vl[:, i1])
    l1 = l1 / l1.sum()
    P[row] = l1 @ X
    # tangent plane: the subdominant left eigenvectors (real and imaginary parts if complex)
    vecs = []
    for i in order[1:]:
        if abs(w[i]) < 1e-12:
            break
        vecs.append(np.real(vl[:, i]))
        if np.iscomplexobj(vl) and np.abs(np.imag(vl[:, i])).max() > 1e-12:
            vecs.append(np.imag(vl[:, i]))
        if len(vecs) >= 2:
            break
    if len(vecs) >= 2:
        t1, t2 = vecs[0] @ X, vecs[1] @ X
        # orient du x dv like the faces around the vertex (a fan of cross products)
        ref_n = np.zeros(3)
        c = X[0]
        for i in range(1, len(X) - 1):
            ref_n += np.cross(X[i] - c, X[i + 1] - c)
        if np.dot(np.cross(t1, t2), ref_n) < 0:
            t2 = -t2
        du[row] = t1
        dv[row] = t2
