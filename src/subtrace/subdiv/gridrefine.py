"""One level of Catmull-Clark refinement of a patch's 4x4 control grid under any pattern
of semi-sharp edges, in a kernel (the refinement step of ``patches/gridmaps.py``).

A quad whose four corners are inside the mesh, of valence 4 with quads around them,
refines from its 4x4 control grid alone: its four children's control grids are a window
each of the inner 5x5 points of the child level's 7x7 lattice over the grid, and those are
the corners' vertex points (their one-rings are in the grid), the edge points of the edges
with both faces in the grid and the nine face points. Every rule that makes them reads the
sharpness of the grid's 24 edges and its corners' vertex sharpness only, and (with uniform
creases, not Chaikin's) so does the children's sharpness. So whatever the creases do along
and across the patch (a crease that ends inside it, two that cross, sharpness changing
along a line), the patch's descendants follow from its grid and those 28 numbers level by
level, as ``patches/crease.py``'s maps do for one crease of constant sharpness along a
side, without the local topology that ``patches/isolate.py`` builds for the rest.

The rules are subtrace's own (``subdiv/refine.py`` and ``subdiv/creases.py``'s helpers:
the crease and smooth edge points and their blend, the smooth, crease and corner vertex
rules and the fractional weight between a parent's and a child's rule); the sums run in
another order than the topological refinement's, so the points equal its to rounding
(tests/test_gridrefine.py compares them): float64's, but float32's at a vertex whose rule
changes, as its fractional weight is a float32 mean of its edges' sharpness (as
OpenSubdiv's), summed in the order each visits the edges.

:func:`ring_limit` does the same for one vertex of any valence with quads around: its
ring (its edges' far ends, its faces' opposite corners, the edges' sharpness) refines from
itself alone until the vertex and its edges are smooth, and the smooth limit masks there
give its exact limit point and tangents (``subdiv/limit.py``'s semi-sharp vertices, the
corners of ``patches/gridmaps.py``'s cells).

The grid: point (i, j) at row ``4 i + j`` (``i`` along ``u``), as
``bspline.control_grids`` lays it. Its edges: ``H(i, j)`` from (i, j) to (i + 1, j) in
rows 0 .. 11 (``i * 4 + j``, i < 3), ``V(i, j)`` from (i, j) to (i, j + 1) in rows
12 .. 23 (``12 + i * 3 + j``, j < 3). The corners' vertex sharpness: (1,1), (2,1),
(2,2), (1,2) (the patch's corners 0 .. 3).
"""

from __future__ import annotations

import numpy as np

from subtrace.runtime.jit import nb
from subtrace.subdiv.catmark import smooth_limit_weights, smooth_vertex_weights
from subtrace.subdiv.creases import (
    F0, RULE_CREASE, RULE_DART, RULE_SMOOTH, decrement, vertex_rules,
)

# the children in the patch's corner order, each as the lower-left lattice point of its
# 4x4 window of the inner lattice (child q at corner q of the patch)
CHILD_AT = np.array([[1, 1], [2, 1], [2, 2], [1, 2]], dtype=np.int64)
# the patch's corners (grid points) in corner order
CORNERS = np.array([[1, 1], [2, 1], [2, 2], [1, 2]], dtype=np.int64)

def _corner_edges():
    """(4,4) the edge rows of each patch corner's four edges (+u, +v, -u, -v)."""
    out = np.empty((4, 4), np.int64)
    for q, (i, j) in enumerate(CORNERS):
        out[q] = (i * 4 + j, 12 + i * 3 + j, (i - 1) * 4 + j, 12 + i * 3 + j - 1)
    return out


CORNER_EDGES = _corner_edges()

# the smooth edge rule between two quads (catmark.smooth_edge_weights): endpoint, face point
_EDGE_VW, _EDGE_FW = 0.25, 0.25


@nb.njit(cache=True, inline="always")
def _h(i, j):
    return i * 4 + j


@nb.njit(cache=True, inline="always")
def _v(i, j):
    return 12 + i * 3 + j


@nb.njit(cache=True, nogil=True)
def refine_grids(P, es, vs, out_P, out_es, out_vs):
    """Refine the grids ``P`` (m,16,3) with edge sharpness ``es`` (m,24) float32 and corner
    vertex sharpness ``vs`` (m,4) float32 once: the children's grids into ``out_P``
    (m,4,16,3), their edges' sharpness into ``out_es`` (m,4,24) and their corners' into
    ``out_vs`` (m,4,4) (module doc's layouts; child q at the patch's corner q, in the
    patch's orientation)."""
    L = np.empty((7, 7, 3))
    for r in range(len(P)):
        refine_grid(P[r], es[r], vs[r], L, out_P[r], out_es[r], out_vs[r])


@nb.njit(cache=True, nogil=True)
def refine_grid(G, es, vs, L, out_P, out_es, out_vs):
    """:func:`refine_grids` of one grid ``G`` (16,3), ``es`` (24,), ``vs`` (4,) into
    ``out_P`` (4,16,3), ``out_es`` (4,24), ``out_vs`` (4,4); ``L`` (7,7,3) scratch."""
    _lattice(G, es, vs, L)
    for q in range(4):
        a0, b0 = CHILD_AT[q, 0], CHILD_AT[q, 1]
        for i in range(4):
            for j in range(4):
                for c in range(3):
                    out_P[q, 4 * i + j, c] = L[a0 + i, b0 + j, c]
        _child_sharpness(es, vs, a0, b0, out_es[q], out_vs[q])


@nb.njit(cache=True, nogil=True)
def ring_limit(c, E, D, s, vs, n, tw, fw, F, M, P, du, dv):
    """The exact limit point and tangents (up to a positive factor, du along edge 0, dv
    along edge 1) of a vertex of valence ``n`` inside the mesh with quads around, into
    ``P``, ``du``, ``dv`` (3,): its ring (point ``c`` (3,), its edges' far ends ``E``
    (n,3), its faces' opposite corners ``D`` (n,3), face i between edges i and i + 1, the
    edges' sharpness ``s`` (n,) float32, its own ``vs``) refined in place (the vertex
    point, its edges' and faces' points, as ``subdiv/refine.py``'s rules make them, and the
    sharpness one level down: a vertex's next ring is made from its ring alone) until the
    vertex and its edges are smooth, then the smooth limit masks there (``tw``, ``fw``:
    ``limit.tangent_tables``' rows; position: ``catmark.smooth_limit_weights``). ``F``,
    ``M`` (n,3) scratch."""
    for _ in range(64):  # (semi-sharpness runs out: one level a unit)
        smooth = vs <= F0
        for i in range(n):
            smooth = smooth and s[i] <= F0
        if smooth:
            break
        for i in range(n):
            j = (i + 1) % n
            for k in range(3):
                F[i, k] = 0.25 * (c[k] + E[i, k] + D[i, k] + E[j, k])
        for i in range(n):
            h = (i - 1 + n) % n
            if s[i] > F0 and decrement(s[i]) > F0:
                for k in range(3):
                    M[i, k] = 0.5 * (c[k] + E[i, k])
                continue
            vw, ew = _EDGE_VW, _EDGE_FW
            if s[i] > F0:
                pw = np.float64(s[i])
                vw = pw * 0.5 + (1.0 - pw) * vw
                ew = ew * (1.0 - pw)
            for k in range(3):
                M[i, k] = vw * (c[k] + E[i, k]) + ew * F[h, k] + ew * F[i, k]
        child = np.empty(n, np.float32)
        for i in range(n):
            child[i] = decrement(s[i])
        out = np.zeros(3)
        _ring_vertex_point(c, E, F, s[:n], child, vs, n, out)
        for k in range(3):
            c[k] = out[k]
        for i in range(n):
            for k in range(3):
                E[i, k] = M[i, k]
                D[i, k] = F[i, k]
            s[i] = child[i]
        vs = decrement(vs)
    a, b, f = smooth_limit_weights(n)
    for k in range(3):
        P[k] = a * c[k]
        du[k] = 0.0
        dv[k] = 0.0
    for i in range(n):
        h = (i - 1 + n) % n
        for k in range(3):
            P[k] += b * E[i, k] + f * D[i, k]
            du[k] += tw[i] * E[i, k] + fw[i] * D[i, k]
            dv[k] += tw[h] * E[i, k] + fw[h] * D[i, k]


@nb.njit(cache=True)
def corner_smooth(es, vs, q):
    """Whether corner ``q`` of a grid of edge sharpness ``es`` (24,) and corner sharpness
    ``vs`` (4,) is smooth (no sharpness on it or its four edges: ``CORNER_EDGES``)."""
    if vs[q] > F0:
        return False
    for k in range(4):
        if es[CORNER_EDGES[q, k]] > F0:
            return False
    return True


@nb.njit(cache=True)
def grid_regular(es, vs):
    """Whether a grid's patch is a regular bicubic one: its four corners smooth
    (:func:`corner_smooth`; the rules its descendants use read no other edge)."""
    for q in range(4):
        if not corner_smooth(es, vs, q):
            return False
    return True


@nb.njit(cache=True)
def _edge_sharpness(es, a, b, c, d):
    """The sharpness of the lattice edge from (a, b) to (c, d) (neighbours: one of the two
    steps is 1), a half of a grid edge (its decrement) or inside a face (0)."""
    if a == c:  # along v
        a, b, d = a, min(b, d), max(b, d)
        if a % 2 == 1:  # between a face point and an edge point
            return F0
        return decrement(es[_v(a // 2, b // 2)])
    a, c = min(a, c), max(a, c)
    if b % 2 == 1:
        return F0
    return decrement(es[_h(a // 2, b // 2)])


@nb.njit(cache=True)
def _child_sharpness(es, vs, a0, b0, out_es, out_vs):
    """The 24 edges' and 4 corners' sharpness of the child whose window of the lattice
    starts at (a0, b0)."""
    for i in range(3):
        for j in range(4):
            out_es[_h(i, j)] = _edge_sharpness(es, a0 + i, b0 + j, a0 + i + 1, b0 + j)
    for i in range(4):
        for j in range(3):
            out_es[_v(i, j)] = _edge_sharpness(es, a0 + i, b0 + j, a0 + i, b0 + j + 1)
    for k in range(4):
        a, b = a0 + CORNERS[k, 0], b0 + CORNERS[k, 1]
        s = F0
        if a % 2 == 0 and b % 2 == 0:  # a vertex point: of a patch corner, the inner ones
            for m in range(4):
                if 2 * CORNERS[m, 0] == a and 2 * CORNERS[m, 1] == b:
                    s = decrement(vs[m])
        out_vs[k] = s


@nb.njit(cache=True)
def _lattice(G, es, vs, L):
    """The inner 5x5 points (rows and columns 1 .. 5) of the child lattice ``L`` (7,7,3)
    over grid ``G`` (16,3): face points, then edge points, then the corners' vertex
    points."""
    for i in range(3):
        for j in range(3):
            for c in range(3):
                L[2 * i + 1, 2 * j + 1, c] = 0.25 * (G[4 * i + j, c] + G[4 * i + 4 + j, c]
                                                     + G[4 * i + 5 + j, c] + G[4 * i + j + 1, c])
    # edge points of the edges with both faces in the grid
    for i in range(3):
        for j in range(1, 3):  # H(i, j): faces (i, j - 1) and (i, j)
            _edge_point(G, L, es[_h(i, j)], 4 * i + j, 4 * i + 4 + j, 2 * i + 1, 2 * j - 1,
                        2 * i + 1, 2 * j + 1, 2 * i + 1, 2 * j)
    for i in range(1, 3):
        for j in range(3):  # V(i, j): faces (i - 1, j) and (i, j)
            _edge_point(G, L, es[_v(i, j)], 4 * i + j, 4 * i + j + 1, 2 * i - 1, 2 * j + 1,
                        2 * i + 1, 2 * j + 1, 2 * i, 2 * j + 1)
    for k in range(4):
        _vertex_point(G, L, es, vs[k], CORNERS[k, 0], CORNERS[k, 1])


@nb.njit(cache=True)
def _edge_point(G, L, s, p0, p1, fa, fb, ga, gb, a, b):
    """The point of the edge from grid point ``p0`` to ``p1`` of sharpness ``s``, whose
    faces' points are ``L[fa, fb]`` and ``L[ga, gb]``, into ``L[a, b]``."""
    if s > F0 and decrement(s) > F0:
        for c in range(3):
            L[a, b, c] = 0.5 * (G[p0, c] + G[p1, c])
        return
    vw, fw = _EDGE_VW, _EDGE_FW
    if s > F0:
        pw = np.float64(s)
        vw = pw * 0.5 + (1.0 - pw) * vw
        fw = fw * (1.0 - pw)
    for c in range(3):
        L[a, b, c] = vw * (G[p0, c] + G[p1, c]) + fw * L[fa, fb, c] + fw * L[ga, gb, c]


@nb.njit(cache=True)
def _vertex_point(G, L, es, vsharp, i, j):
    """The vertex point of grid point (i, j) (a corner of the patch: its four faces and
    edges in the grid) into ``L[2 i, 2 j]``: :func:`_ring_vertex_point` of its ring (edges
    +u, +v, -u, -v; face k between edges k and k + 1)."""
    edges = np.empty(4, np.float32)
    edges[0], edges[1] = es[_h(i, j)], es[_v(i, j)]
    edges[2], edges[3] = es[_h(i - 1, j)], es[_v(i, j - 1)]
    far = (4 * (i + 1) + j, 4 * i + j + 1, 4 * (i - 1) + j, 4 * i + j - 1)
    faces = ((1, 1), (-1, 1), (-1, -1), (1, -1))
    E = np.empty((4, 3))
    F = np.empty((4, 3))
    child = np.empty(4, np.float32)
    for k in range(4):
        child[k] = decrement(edges[k])
        for c in range(3):
            E[k, c] = G[far[k], c]
            F[k, c] = L[2 * i + faces[k][0], 2 * j + faces[k][1], c]
    out = np.zeros(3)
    _ring_vertex_point(G[4 * i + j], E, F, edges, child, vsharp, 4, out)
    for c in range(3):
        L[2 * i, 2 * j, c] = out[c]


@nb.njit(cache=True)
def _ring_vertex_point(c, E, F, s, child, vs, n, out):
    """The vertex point (into ``out`` (3,), zeros) of a vertex of valence ``n`` with quads
    around: point ``c`` (3,), its edges' far ends ``E`` (n,3) and its faces' points ``F``
    (n,3) of the child level, in ring order, its edges' sharpness ``s`` (n,) and one level
    down ``child``, its own ``vs``: the parent's rule, and the child's blended in by the
    fractional weight where they differ (``creases.vertex_rules``)."""
    p_rule, c_rule, pw = vertex_rules(vs, decrement(vs), s, child, False)
    for which in range(2):
        rule = p_rule if which == 0 else c_rule
        w = pw if which == 0 else 1.0 - pw
        if which == 1 and c_rule == p_rule:
            break
        if rule == RULE_SMOOTH or rule == RULE_DART:
            a, b, f = smooth_vertex_weights(n)
            for k in range(3):
                acc = a * c[k]
                for i in range(n):
                    acc += b * E[i, k]
                for i in range(n):
                    acc += f * F[i, k]
                out[k] += w * acc
        elif rule == RULE_CREASE:
            sharp = s if which == 0 else child
            k0 = 0
            while sharp[k0] <= F0:
                k0 += 1
            k1 = n - 1
            while sharp[k1] <= F0:
                k1 -= 1
            for k in range(3):
                out[k] += w * (0.75 * c[k] + 0.125 * (E[k0, k] + E[k1, k]))
        else:
            for k in range(3):
                out[k] += w * c[k]
