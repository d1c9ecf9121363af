"""One level of uniform refinement: the child topology (scheme-independent splitting) and the
child points (rules from ``catmark.py`` / ``loop.py`` with OpenSubdiv's crease handling).

Child numbering is OpenSubdiv's default (``orderVerticesFromFacesFirst = false``):

* vertices: children of parent vertices (same index), then of faces (Catmark only), then of
  edges;
* faces: grouped by parent face, child j at parent corner j (quads keep the parent's (u,v)
  orientation: child j has corner j at position j; n-gon child j is
  [v_j, e_j, face, e_j-1]; Loop children [v0,e0,e2], [e0,v1,e1], [e2,e1,v2], [e1,e2,e0]);
* edges: interior edges of each face first (Catmark: face point -> edge point j; Loop:
  e_j -> e_j-1), then two children per parent edge (at its first, then second vertex).

Points are any (n, d) float64 array: positions, or an identity matrix to get stencils.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from subtrace.runtime.jit import callee_njit, nb
from subtrace.subdiv import catmark, loop
from subtrace.subdiv.creases import (
    F0,
    RULE_CREASE,
    RULE_DART,
    RULE_SMOOTH,
    child_edge_sharpness_at_vertex,
    vertex_rules,
)
from subtrace.subdiv.topology import INF_SHARP, Level, Options, build_level


@dataclass(frozen=True, eq=False)
class Refinement:
    """A parent level, its child level and what the point rules need from both."""

    parent: Level
    child: Level
    options: Options
    edge_child_sharpness: np.ndarray  # (E,2) float32: child sharpness at each end of each edge
    vert_child_sharpness: np.ndarray  # (V,) float32


def refine_level(parent: Level, options: Options) -> Refinement:
    """Split the topology of ``parent`` once and subdivide its sharpness."""
    edge_child = _child_edge_sharpness(parent, options.chaikin)
    vert_child = _decrement_all(parent.vert_sharpness)
    if options.scheme == "catmark":
        child = _split_quads(parent, edge_child, vert_child)
    else:
        child = _split_triangles(parent, edge_child, vert_child)
    return Refinement(parent, child, options, edge_child, vert_child)


def scheme_flag(scheme: str):
    """The scheme as the subdivision kernels take it: True for Loop, None for Catmull-Clark.
    Not a bool: Numba prunes a branch on an argument that is None before typing it, so a
    Catmull-Clark render compiles these kernels without Loop's masks (as
    ``geometry.bezier.loop_flag`` does for the trace kernel); a Loop render compiles both."""
    return True if scheme == "loop" else None


def refine_points(ref: Refinement, points: np.ndarray) -> np.ndarray:
    """Child points of ``ref.child`` from parent ``points`` (n, d) float64."""
    p = ref.parent
    pts = np.ascontiguousarray(points, dtype=np.float64)
    squeeze = pts.ndim == 1
    if squeeze:
        pts = pts[:, None]
    out = np.empty((ref.child.n_verts, pts.shape[1]), dtype=np.float64)
    _refine_points_kernel(
        scheme_flag(ref.options.scheme),
        ref.options.smooth_triangles,
        ref.options.chaikin,
        p.face_offsets,
        p.face_verts,
        p.edge_verts,
        p.edge_face_offsets,
        p.edge_faces,
        p.edge_face_corner,
        p.edge_sharpness,
        ref.edge_child_sharpness,
        p.vert_face_offsets,
        p.vert_faces,
        p.vert_edge_offsets,
        p.vert_edges,
        p.vert_sharpness,
        ref.vert_child_sharpness,
        pts,
        out,
    )
    return out[:, 0] if squeeze else out


# --------------------------------------------------------------------------------------
# sharpness
# --------------------------------------------------------------------------------------


def _decrement_all(s: np.ndarray) -> np.ndarray:
    s = s.astype(np.float32)
    out = np.where(s >= INF_SHARP, s, s - np.float32(1.0)).astype(np.float32)
    out[out <= 0] = 0
    out[s <= 1] = 0
    out[s >= INF_SHARP] = INF_SHARP
    return out


@nb.njit(cache=True, nogil=True)
def _child_edge_sharpness_kernel(edge_verts, edge_sharp, vert_edge_offsets, vert_edges, chaikin, out):
    for e in range(len(edge_sharp)):
        s = edge_sharp[e]
        for j in range(2):
            v = edge_verts[e, j]
            a = vert_edge_offsets[v]
            b = vert_edge_offsets[v + 1]
            around = np.empty(b - a, np.float32)
            for i in range(b - a):
                around[i] = edge_sharp[vert_edges[a + i]]
            out[e, j] = child_edge_sharpness_at_vertex(s, around, chaikin)


def _child_edge_sharpness(level: Level, chaikin: bool) -> np.ndarray:
    out = np.empty((level.n_edges, 2), dtype=np.float32)
    s = level.edge_sharpness
    if not np.any((s > 0) & (s < INF_SHARP)):
        # no semi-sharp edge: under either rule an infinitely sharp edge's halves stay so
        # and the others smooth (creases.child_edge_sharpness_at_vertex), with no kernel
        # to run, load or (on a cold cache) compile: cages with boundaries or infinitely
        # sharp creases alone, and the isolation's stencil meshes
        out[:] = np.where(s >= INF_SHARP, INF_SHARP, np.float32(0.0))[:, None]
        return out
    _child_edge_sharpness_kernel(
        level.edge_verts,
        level.edge_sharpness,
        level.vert_edge_offsets,
        level.vert_edges,
        chaikin,
        out,
    )
    return out


# --------------------------------------------------------------------------------------
# topology splitting
# --------------------------------------------------------------------------------------


def _corners(level: Level):
    sizes = np.diff(level.face_offsets)
    face_of = np.repeat(np.arange(level.n_faces, dtype=np.int64), sizes)
    off = level.face_offsets[face_of]
    k = np.arange(level.face_offsets[-1], dtype=np.int64) - off
    n = sizes[face_of]
    prev = off + (k - 1) % n
    return face_of, k, n, prev


def _child_level(p: Level, n_verts, offsets, child_fv, ev, child_fe, child_fwd, edge_child,
                 vert_child, face_hole) -> Level:
    """The child level of either split: the child faces and edges given, the sharpness of
    the parent edges' halves (``edge_child`` (E,2)) and of the parent vertices' children
    (``vert_child`` (V,)), non-manifold flags carried to the halves, the face holes given."""
    C = len(p.face_verts)
    E = p.n_edges
    esharp = np.zeros(C + 2 * E, dtype=np.float32)
    esharp[C:] = edge_child.ravel()
    enonman = np.zeros(C + 2 * E, dtype=bool)
    enonman[C:] = np.repeat(p.edge_nonmanifold, 2)
    vsharp = np.zeros(n_verts, dtype=np.float32)
    vsharp[: p.n_verts] = vert_child
    return build_level(n_verts, offsets, child_fv, ev, child_fe, child_fwd, esharp, vsharp,
                       face_hole, edge_nonmanifold=enonman)


def _split_quads(p: Level, edge_child: np.ndarray, vert_child: np.ndarray) -> Level:
    V, F, E = p.n_verts, p.n_faces, p.n_edges
    C = len(p.face_verts)
    face_of, k, n, prev = _corners(p)
    fe = p.face_edges.astype(np.int64)
    fwd = p.face_edge_forward
    # the unrotated child of corner c: [v_j, e_j, face, e_j-1] and its four edges
    L = np.empty((C, 4), dtype=np.int64)
    L[:, 0] = p.face_verts
    L[:, 1] = V + F + fe
    L[:, 2] = V + face_of
    L[:, 3] = V + F + fe[prev]
    LE = np.empty((C, 4), dtype=np.int64)
    LE[:, 0] = C + 2 * fe + np.where(fwd, 0, 1)
    LE[:, 1] = np.arange(C)
    LE[:, 2] = prev
    LE[:, 3] = C + 2 * fe[prev] + np.where(fwd[prev], 1, 0)
    LF = np.array([False, False, True, True])
    # quad parents keep their orientation: rotate child j so that v_j sits at position j
    rot = np.where(n == 4, k, 0)
    pos = (np.arange(4)[None, :] - rot[:, None]) % 4
    child_fv = np.take_along_axis(L, pos, axis=1).ravel().astype(np.int32)
    child_fe = np.take_along_axis(LE, pos, axis=1).ravel().astype(np.int32)
    child_fwd = LF[pos].ravel()
    # child edges: face point -> edge point per corner, then two halves per parent edge
    ev = np.empty((C + 2 * E, 2), dtype=np.int32)
    ev[:C, 0] = V + face_of
    ev[:C, 1] = V + F + fe
    eidx = np.arange(E)
    ev[C::2, 0] = V + F + eidx
    ev[C::2, 1] = p.edge_verts[:, 0]
    ev[C + 1 :: 2, 0] = V + F + eidx
    ev[C + 1 :: 2, 1] = p.edge_verts[:, 1]
    offsets = np.arange(0, 4 * C + 1, 4, dtype=np.int64)
    return _child_level(p, V + F + E, offsets, child_fv, ev, child_fe, child_fwd, edge_child,
                        vert_child, p.face_hole[face_of])


def _split_triangles(p: Level, edge_child: np.ndarray, vert_child: np.ndarray) -> Level:
    V, F, E = p.n_verts, p.n_faces, p.n_edges
    fv = p.face_verts.reshape(F, 3).astype(np.int64)
    fe = p.face_edges.reshape(F, 3).astype(np.int64)
    fwd = p.face_edge_forward.reshape(F, 3)
    e0, e1, e2 = (V + fe[:, i] for i in range(3))
    v0, v1, v2 = fv[:, 0], fv[:, 1], fv[:, 2]
    child_fv = np.stack(
        [v0, e0, e2, e0, v1, e1, e2, e1, v2, e1, e2, e0], axis=1
    ).ravel().astype(np.int32)
    C = 3 * F
    fidx = np.arange(F)
    inner = 3 * fidx[:, None] + np.arange(3)[None, :]  # interior edge k: e_k -> e_k-1

    def half(i, at_second):
        # child of face edge i at its first (corner i) or second (corner i+1) vertex
        end = np.where(fwd[:, i], 1 if at_second else 0, 0 if at_second else 1)
        return C + 2 * fe[:, i] + end

    child_fe = np.stack(
        [
            half(0, False), inner[:, 0], half(2, True),
            half(0, True), half(1, False), inner[:, 1],
            inner[:, 2], half(1, True), half(2, False),
            inner[:, 2], inner[:, 0], inner[:, 1],
        ],
        axis=1,
    ).ravel().astype(np.int32)
    pattern = np.array([False, True, True, True, False, True, True, True, False, False, False, False])
    child_fwd = np.tile(pattern, F)
    ev = np.empty((C + 2 * E, 2), dtype=np.int32)
    ev[:C, 0] = (V + fe).ravel()
    ev[:C, 1] = (V + fe[:, [2, 0, 1]]).ravel()
    eidx = np.arange(E)
    ev[C::2, 0] = V + eidx
    ev[C::2, 1] = p.edge_verts[:, 0]
    ev[C + 1 :: 2, 0] = V + eidx
    ev[C + 1 :: 2, 1] = p.edge_verts[:, 1]
    offsets = np.arange(0, 12 * F + 1, 3, dtype=np.int64)
    return _child_level(p, V + E, offsets, child_fv, ev, child_fe, child_fwd, edge_child,
                        vert_child, np.repeat(p.face_hole, 4))


# --------------------------------------------------------------------------------------
# point rules
# --------------------------------------------------------------------------------------


@callee_njit
def _other_end(edge_verts, e, v):
    a = edge_verts[e, 0]
    return edge_verts[e, 1] if a == v else a


@callee_njit
def _crease_ends(edge_sharp_around):
    """Positions of the first and last sharp edge around a vertex (Sdc's crease pair)."""
    n = len(edge_sharp_around)
    i0 = 0
    while i0 < n and edge_sharp_around[i0] <= F0:
        i0 += 1
    i1 = n - 1
    while i1 >= 0 and edge_sharp_around[i1] <= F0:
        i1 -= 1
    return i0, i1


@nb.njit(cache=True, nogil=True)
def _refine_points_kernel(
    is_loop,
    smooth_triangles,
    chaikin,
    face_offsets,
    face_verts,
    edge_verts,
    edge_face_offsets,
    edge_faces,
    edge_face_corner,
    edge_sharp,
    edge_child_sharp,
    vert_face_offsets,
    vert_faces,
    vert_edge_offsets,
    vert_edges,
    vert_sharp,
    vert_child_sharp,
    P,
    Q,
):
    """Child points ``Q`` (child verts, d) from parent points ``P`` (parent verts, d): vertex
    points first (rows 0 .. n_v - 1), then face points (Catmull-Clark), then edge points, as
    OpenSubdiv numbers the child vertices. Face points come first: edge and vertex points
    use them. ``is_loop``: :func:`scheme_flag` (True or None)."""
    n_v = len(vert_face_offsets) - 1
    n_f = len(face_offsets) - 1
    face_base = n_v
    edge_base = n_v if is_loop is not None else n_v + n_f
    if is_loop is None:
        _face_points(face_offsets, face_verts, P, Q, face_base)
    _edge_points(is_loop, smooth_triangles, face_offsets, face_verts, edge_verts,
                 edge_face_offsets, edge_faces, edge_face_corner, edge_sharp, edge_child_sharp,
                 P, Q, face_base, edge_base)
    _vertex_points(is_loop, chaikin, edge_verts, edge_sharp, edge_child_sharp,
                   vert_face_offsets, vert_faces, vert_edge_offsets, vert_edges, vert_sharp,
                   vert_child_sharp, P, Q, face_base)


@callee_njit
def _face_points(face_offsets, face_verts, P, Q, face_base):
    """Catmull-Clark face points (centroids) into ``Q[face_base + f]``."""
    n_f = len(face_offsets) - 1
    d = P.shape[1]
    # face points (Catmark): centroids
    for f in range(n_f):
        a = face_offsets[f]
        b = face_offsets[f + 1]
        w = 1.0 / (b - a)
        for c in range(d):
            acc = 0.0
            for i in range(a, b):
                acc += P[face_verts[i], c]
            Q[face_base + f, c] = acc * w


@callee_njit
def _edge_points(is_loop, smooth_triangles, face_offsets, face_verts, edge_verts,
                 edge_face_offsets, edge_faces, edge_face_corner, edge_sharp, edge_child_sharp,
                 P, Q, face_base, edge_base):
    """Edge points into ``Q[edge_base + e]``: crease midpoints, smooth masks, and their blend
    where a crease turns smooth."""
    n_e = len(edge_verts)
    d = P.shape[1]
    # edge points
    for e in range(n_e):
        q = edge_base + e
        v0 = edge_verts[e, 0]
        v1 = edge_verts[e, 1]
        s = edge_sharp[e]
        crease = False
        if s > F0:
            crease = edge_child_sharp[e, 0] > F0 and edge_child_sharp[e, 1] > F0
        if crease:
            for c in range(d):
                Q[q, c] = 0.5 * (P[v0, c] + P[v1, c])
            continue
        ua = edge_face_offsets[e]
        ub = edge_face_offsets[e + 1]
        nfe = ub - ua
        tri0 = False
        tri1 = False
        if nfe == 2:
            f0 = edge_faces[ua]
            f1 = edge_faces[ua + 1]
            tri0 = face_offsets[f0 + 1] - face_offsets[f0] == 3
            tri1 = face_offsets[f1 + 1] - face_offsets[f1] == 3
        if is_loop is not None:
            vw, fw = loop.smooth_edge_weights(nfe, tri0, tri1, smooth_triangles)
        else:
            vw, fw = catmark.smooth_edge_weights(nfe, tri0, tri1, smooth_triangles)
        if s > F0:
            # transition from a crease to smooth: blend with the parent's sharpness
            pw = np.float64(s)
            vw = pw * 0.5 + (1.0 - pw) * vw
            fw = fw * (1.0 - pw)
        for c in range(d):
            acc = vw * (P[v0, c] + P[v1, c])
            for u in range(ua, ub):
                f = edge_faces[u]
                if is_loop is not None:
                    k = edge_face_corner[u]
                    opp = face_verts[face_offsets[f] + (k + 2) % 3]
                    acc += fw * P[opp, c]
                else:
                    acc += fw * Q[face_base + f, c]
            Q[q, c] = acc


@callee_njit
def _vertex_points(is_loop, chaikin, edge_verts, edge_sharp, edge_child_sharp,
                   vert_face_offsets, vert_faces, vert_edge_offsets, vert_edges, vert_sharp,
                   vert_child_sharp, P, Q, face_base):
    """Vertex points into ``Q[v]``: the parent's rule (smooth / dart, crease, corner),
    blended with the child's by the fractional weight where the rule changes."""
    n_v = len(vert_face_offsets) - 1
    d = P.shape[1]
    # vertex points
    for v in range(n_v):
        fa = vert_face_offsets[v]
        fb = vert_face_offsets[v + 1]
        ea = vert_edge_offsets[v]
        eb = vert_edge_offsets[v + 1]
        ne = eb - ea
        if fb == fa:
            for c in range(d):
                Q[v, c] = P[v, c]
            continue
        p_es = np.empty(ne, np.float32)
        c_es = np.empty(ne, np.float32)
        for i in range(ne):
            e = vert_edges[ea + i]
            p_es[i] = edge_sharp[e]
            c_es[i] = edge_child_sharp[e, 0] if edge_verts[e, 0] == v else edge_child_sharp[e, 1]
        p_rule, c_rule, pw = vertex_rules(vert_sharp[v], vert_child_sharp[v], p_es, c_es,
                                          chaikin)
        for c in range(d):
            Q[v, c] = 0.0
        for which in range(2):
            rule = p_rule if which == 0 else c_rule
            w = pw if which == 0 else 1.0 - pw
            if which == 1 and c_rule == p_rule:
                break
            if rule == RULE_SMOOTH or rule == RULE_DART:
                nfv = fb - fa
                if is_loop is not None:
                    vw, ew, fw = loop.smooth_vertex_weights(nfv)
                else:
                    vw, ew, fw = catmark.smooth_vertex_weights(nfv)
                for c in range(d):
                    acc = vw * P[v, c]
                    for i in range(ea, eb):
                        acc += ew * P[_other_end(edge_verts, vert_edges[i], v), c]
                    if is_loop is None:
                        for i in range(fa, fb):
                            acc += fw * Q[face_base + vert_faces[i], c]
                    Q[v, c] += w * acc
            elif rule == RULE_CREASE:
                i0, i1 = _crease_ends(p_es if which == 0 else c_es)
                a = _other_end(edge_verts, vert_edges[ea + i0], v)
                b = _other_end(edge_verts, vert_edges[ea + i1], v)
                for c in range(d):
                    Q[v, c] += w * (0.75 * P[v, c] + 0.125 * (P[a, c] + P[b, c]))
            else:
                for c in range(d):
                    Q[v, c] += w * P[v, c]
