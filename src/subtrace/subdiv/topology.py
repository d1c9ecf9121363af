"""Topology of one subdivision level: integer relations in CSR form, plus the crease tags.

A :class:`Level` owns everything the subdivision rules need to know about the connectivity of a
mesh, and nothing about its positions (habit 1 of ``docs/style.md``). Relations are flat arrays
named ``<from>_<to>`` with ``<from>_<to>_offsets`` (OpenSubdiv Vtr's layout):

* ``face_verts`` / ``face_offsets`` (F+1)    -- the corners of each face, as given;
* ``face_edges``  aligned with ``face_verts`` -- edge k of a face joins corners k and k+1;
* ``edge_verts`` (E,2)                       -- endpoints, in the orientation of first use;
* ``edge_faces`` / ``edge_face_offsets``     -- one entry per use of the edge by a face;
  ``edge_face_corner`` gives the corner k of that face the use starts at;
* ``vert_faces`` / ``vert_face_offsets``     -- one entry per corner, ``vert_face_corner`` the
  corner's index in its face; ordered counter-clockwise for manifold vertices;
* ``vert_edges`` / ``vert_edge_offsets``     -- incident edges, ordered to match ``vert_faces``
  for manifold vertices (edge i leads face i), a degenerate edge is listed twice.

Tags follow OpenSubdiv's Far factory: boundary and non-manifold edges are infinitely sharp,
non-manifold vertices (except those on a plain non-manifold crease) and, in edge-and-corner
mode, topological corners are sharpened; with boundary interpolation ``none`` the faces at
non-sharpened boundary vertices become holes. Sharpness is float32 like OpenSubdiv's, and
every sharpness computation is done in float32 so fractional crease weights match it exactly;
``INF_SHARP`` (``config.SHARPNESS_INFINITE`` in float32) is the infinite sharpness every
module compares with. :func:`gather` / :func:`compact` are the CSR helpers (rows of a
relation, distinct ids and their ranks) the local cuts of ``subdiv`` and ``patches`` use.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from subtrace import config
from subtrace.runtime.jit import callee_njit, nb

INF_SHARP = np.float32(config.SHARPNESS_INFINITE)

# Boundary interpolation modes, numbered as OpenSubdiv's OBJ tag (and Sdc) numbers them.
BOUNDARY_NONE = 0
BOUNDARY_EDGE_AND_CORNER = 1
BOUNDARY_EDGE_ONLY = 2


@dataclass(frozen=True)
class Options:
    """Subdivision options (OpenSubdiv's ``Sdc::Options`` for the vertex data we use)."""

    scheme: str = "catmark"  # "catmark" or "loop"
    boundary: int = BOUNDARY_EDGE_ONLY
    chaikin: bool = False  # crease method: False = uniform ("normal"), True = Chaikin
    smooth_triangles: bool = False  # Catmark triangle rule: False = "catmark", True = "smooth"

    @property
    def regular_face_size(self) -> int:
        return 4 if self.scheme == "catmark" else 3


@dataclass(frozen=True, eq=False)
class Level:
    """Connectivity and crease tags of one refinement level (see the module comment)."""

    n_verts: int
    face_offsets: np.ndarray  # (F+1,) int64
    face_verts: np.ndarray  # (C,) int32
    face_edges: np.ndarray  # (C,) int32
    face_edge_forward: np.ndarray  # (C,) bool: edge_verts[face_edges[c]] == (v_c, v_c+1)
    edge_verts: np.ndarray  # (E,2) int32
    edge_face_offsets: np.ndarray  # (E+1,) int64
    edge_faces: np.ndarray  # int32
    edge_face_corner: np.ndarray  # int32, corner index of the use within its face
    vert_face_offsets: np.ndarray  # (V+1,) int64
    vert_faces: np.ndarray  # int32
    vert_face_corner: np.ndarray  # int32
    vert_edge_offsets: np.ndarray  # (V+1,) int64
    vert_edges: np.ndarray  # int32
    vert_manifold: np.ndarray  # (V,) bool: faces form one ordered fan (or disc)
    edge_nonmanifold: np.ndarray  # (E,) bool
    edge_sharpness: np.ndarray  # (E,) float32, after boundary / non-manifold sharpening
    vert_sharpness: np.ndarray  # (V,) float32
    face_hole: np.ndarray  # (F,) bool

    @property
    def n_faces(self) -> int:
        return len(self.face_offsets) - 1

    @property
    def n_edges(self) -> int:
        return len(self.edge_verts)

    @property
    def face_sizes(self) -> np.ndarray:
        return np.diff(self.face_offsets).astype(np.int32)

    def vert_boundary(self) -> np.ndarray:
        """(V,) bool: the vertex lies on an edge used by a single face."""
        n_uses = np.diff(self.edge_face_offsets)
        bnd_edges = np.nonzero(n_uses == 1)[0]
        out = np.zeros(self.n_verts, dtype=bool)
        out[self.edge_verts[bnd_edges].ravel()] = True
        return out


# --------------------------------------------------------------------------------------
# CSR helpers
# --------------------------------------------------------------------------------------


def compact(ids: np.ndarray, n: int):
    """The distinct values of ``ids`` (all in 0..n-1) in increasing order, and the map from
    each value to its rank (-1 for values absent); O(n), no sort."""
    mask = np.zeros(n, dtype=bool)
    mask[ids] = True
    kept = np.nonzero(mask)[0]
    rank = np.full(n, -1, dtype=np.int64)
    rank[kept] = np.arange(len(kept))
    return kept, rank


def gather_index(offsets: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Positions in a CSR relation's flat list of the entries of ``rows``, row after row."""
    starts = offsets[rows]
    counts = offsets[rows + 1] - starts
    if counts.sum() == 0:
        return np.zeros(0, dtype=np.int64)
    idx = np.repeat(starts - np.cumsum(np.r_[0, counts[:-1]]), counts)
    return idx + np.arange(counts.sum())


def gather(offsets: np.ndarray, values: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """The entries of ``rows`` of the CSR relation ``(offsets, values)``, concatenated."""
    return values[gather_index(offsets, rows)]


def base_edges(face_offsets: np.ndarray, face_verts: np.ndarray, n_verts: int):
    """Edges of a base mesh, numbered by first appearance when walking faces in order.

    Returns (edge_verts (E,2), face_edges (C,), face_edge_forward (C,)).
    """
    face_offsets = np.ascontiguousarray(face_offsets, dtype=np.int64)
    face_verts = np.ascontiguousarray(face_verts, dtype=np.int32)
    n_corners = len(face_verts)
    edge_verts = np.empty((n_corners, 2), dtype=np.int32)
    face_edges = np.empty(n_corners, dtype=np.int32)
    forward = np.empty(n_corners, dtype=np.bool_)
    n_edges = _topology(0, face_offsets, face_verts, int(n_verts), edge_verts, face_edges,
                        forward, *_NO_RELATIONS)
    return edge_verts[:n_edges].copy(), face_edges, forward


# the relations' arrays for :func:`_topology`'s step 0, which fills none
_NO_RELATIONS = (np.zeros(0, np.int64), np.zeros(0, np.int32), np.zeros(0, np.int32),
                 np.zeros(0, np.int64), np.zeros(0, np.int32), np.zeros(0, np.int32),
                 np.zeros(0, np.int64), np.zeros(0, np.int32), False, np.zeros(0, np.bool_),
                 np.zeros(0, np.bool_))


@nb.njit(cache=True, nogil=True)
def _topology(step, face_offsets, face_verts, n_verts, edge_verts, face_edges, forward,
              edge_face_offsets, edge_faces, edge_face_corner, vert_face_offsets, vert_faces,
              vert_face_corner, vert_edge_offsets, vert_edges, detect, edge_nonmanifold,
              vert_manifold):
    """A level's topology, in one kernel for its two steps (a kernel load less in a
    render): step 0, a base level's edges (:func:`_base_edges`; returns their count); step
    1, the relations of any level from its faces and edges (:func:`_relations`)."""
    if step == 0:
        return _base_edges(face_offsets, face_verts, n_verts, edge_verts, face_edges, forward)
    _relations(face_offsets, face_verts, face_edges, edge_verts, forward, edge_face_offsets,
               edge_faces, edge_face_corner, vert_face_offsets, vert_faces, vert_face_corner,
               vert_edge_offsets, vert_edges, detect, edge_nonmanifold, vert_manifold)
    return 0


@callee_njit
def _base_edges(face_offsets, face_verts, n_verts, edge_verts, face_edges, forward):
    """Number the edges of the faces' corners (corner k -> k+1) in order of first use; each
    distinct vertex pair is one edge, except that, as in OpenSubdiv, a degenerate edge (a
    face repeating a vertex) is never shared and a face using a pair again gets a new edge
    for that use. Fills edge_verts (orientation of first use, at least E rows), face_edges
    and forward; returns E.
    """
    n_faces = len(face_offsets) - 1
    # the edges seen so far from each lower vertex: a bucket per vertex, at most its uses
    # (np.empty and a fill, not np.zeros: a cold render compiles one allocator fewer)
    start = np.empty(n_verts + 1, dtype=np.int64)
    start[:] = 0
    for f in range(n_faces):
        f0 = face_offsets[f]
        n = face_offsets[f + 1] - f0
        for k in range(n):
            a = face_verts[f0 + k]
            b = face_verts[f0 + k + 1 if k + 1 < n else f0]
            start[min(a, b) + 1] += 1
    for v in range(n_verts):
        start[v + 1] += start[v]
    filled = np.empty(n_verts, dtype=np.int64)
    filled[:] = 0
    bucket_hi = np.empty(start[n_verts], dtype=np.int32)
    bucket_edge = np.empty(start[n_verts], dtype=np.int32)
    last_face = np.empty(start[n_verts], dtype=np.int64)  # of each bucket entry's edge
    n_edges = 0
    for f in range(n_faces):
        f0 = face_offsets[f]
        n = face_offsets[f + 1] - f0
        for k in range(n):
            c = f0 + k
            a = face_verts[c]
            b = face_verts[f0 + k + 1 if k + 1 < n else f0]
            lo, hi = min(a, b), max(a, b)
            # an edge already used by an earlier face
            e = -1
            seen = False
            if a != b:
                for j in range(start[lo], start[lo] + filled[lo]):
                    if bucket_hi[j] == hi:
                        seen = True
                        if last_face[j] != f:
                            e = bucket_edge[j]
                            last_face[j] = f
                        break
            if e < 0:
                e = n_edges
                n_edges += 1
                edge_verts[e, 0] = a
                edge_verts[e, 1] = b
                if a != b and not seen:
                    j = start[lo] + filled[lo]
                    bucket_hi[j] = hi
                    bucket_edge[j] = e
                    last_face[j] = f
                    filled[lo] += 1
            face_edges[c] = e
            forward[c] = edge_verts[e, 0] == a and edge_verts[e, 1] == b
    return n_edges


def build_level(
    n_verts: int,
    face_offsets: np.ndarray,
    face_verts: np.ndarray,
    edge_verts: np.ndarray,
    face_edges: np.ndarray,
    face_edge_forward: np.ndarray,
    edge_sharpness: np.ndarray,
    vert_sharpness: np.ndarray,
    face_hole: np.ndarray,
    edge_nonmanifold: np.ndarray | None = None,
    vert_nonmanifold: np.ndarray | None = None,
) -> Level:
    """Complete the relations of a level from its faces and edges, and order vertex rings.

    ``edge_nonmanifold`` / ``vert_nonmanifold`` may be passed down from the parent level
    (refinement preserves them); when None they are detected from the topology.
    Sharpness arrays are taken as given (see :func:`tag_base_level` for the base level).
    """
    face_offsets = np.ascontiguousarray(face_offsets, dtype=np.int64)
    face_verts = np.ascontiguousarray(face_verts, dtype=np.int32)
    face_edges = np.ascontiguousarray(face_edges, dtype=np.int32)
    edge_verts = np.ascontiguousarray(edge_verts, dtype=np.int32).reshape(-1, 2)
    face_edge_forward = np.ascontiguousarray(face_edge_forward, dtype=np.bool_)
    n_edges = len(edge_verts)
    n_corners = len(face_verts)

    # edge -> face uses in face order, vertex -> face corners, vertex -> edges
    edge_face_offsets = np.zeros(n_edges + 1, dtype=np.int64)
    edge_faces = np.empty(n_corners, dtype=np.int32)
    edge_face_corner = np.empty(n_corners, dtype=np.int32)
    vert_face_offsets = np.zeros(n_verts + 1, dtype=np.int64)
    vert_faces = np.empty(n_corners, dtype=np.int32)
    vert_face_corner = np.empty(n_corners, dtype=np.int32)
    vert_edge_offsets = np.zeros(n_verts + 1, dtype=np.int64)
    vert_edges = np.empty(2 * n_edges, dtype=np.int32)
    detect = edge_nonmanifold is None
    edge_nonmanifold = (np.empty(n_edges, dtype=np.bool_) if detect
                        else np.ascontiguousarray(edge_nonmanifold, dtype=np.bool_))
    vert_manifold = np.empty(n_verts, dtype=np.bool_)
    _topology(1, face_offsets, face_verts, int(n_verts), edge_verts, face_edges,
              face_edge_forward, edge_face_offsets, edge_faces, edge_face_corner,
              vert_face_offsets, vert_faces, vert_face_corner, vert_edge_offsets, vert_edges,
              detect, edge_nonmanifold, vert_manifold)
    if vert_nonmanifold is not None:
        vert_manifold &= ~vert_nonmanifold

    return Level(
        n_verts=int(n_verts),
        face_offsets=face_offsets,
        face_verts=face_verts,
        face_edges=face_edges,
        face_edge_forward=np.ascontiguousarray(face_edge_forward, dtype=np.bool_),
        edge_verts=edge_verts,
        edge_face_offsets=edge_face_offsets,
        edge_faces=edge_faces,
        edge_face_corner=edge_face_corner,
        vert_face_offsets=vert_face_offsets,
        vert_faces=vert_faces,
        vert_face_corner=vert_face_corner,
        vert_edge_offsets=vert_edge_offsets,
        vert_edges=vert_edges,
        vert_manifold=vert_manifold,
        edge_nonmanifold=edge_nonmanifold,
        edge_sharpness=np.ascontiguousarray(edge_sharpness, dtype=np.float32),
        vert_sharpness=np.ascontiguousarray(vert_sharpness, dtype=np.float32),
        face_hole=np.ascontiguousarray(face_hole, dtype=np.bool_),
    )


@callee_njit
def _relations(face_offsets, face_verts, face_edges, edge_verts, face_edge_forward,
               edge_face_offsets, edge_faces, edge_face_corner, vert_face_offsets, vert_faces,
               vert_face_corner, vert_edge_offsets, vert_edges, detect, edge_nonmanifold,
               vert_manifold):
    """The CSR relations of a level from its faces and edges (offset arrays zeroed on
    entry), each list in face / edge order (stable counting sorts), then the vertex rings
    ordered (see below) and ``vert_manifold`` set.

    With ``detect``, also flags the non-manifold edges: used by more than two faces or
    none, joining a vertex to itself, or used twice in the same direction or by one face
    (OpenSubdiv cannot orient those).

    Rings, as in OpenSubdiv: edge i of the ring is the *leading* edge of face i at the
    vertex (the edge leaving it, corner k -> k+1), and the next face counter-clockwise is
    the one whose leading edge is this face's trailing edge (corner k-1 -> k). A boundary
    vertex starts at the face whose leading edge is a boundary, and has one more edge than
    faces: the last is the trailing edge of the last face. Vertices whose faces do not form
    a single fan keep their unordered lists and are flagged non-manifold.
    """
    _offsets(face_verts, face_edges, edge_verts, edge_face_offsets, vert_face_offsets,
             vert_edge_offsets)
    slot = _entries(face_offsets, face_verts, face_edges, edge_verts, edge_face_offsets,
                    edge_faces, edge_face_corner, vert_face_offsets, vert_edge_offsets,
                    vert_edges)
    if detect:
        _nonmanifold_edges(face_offsets, edge_verts, face_edge_forward, edge_face_offsets,
                           edge_faces, edge_face_corner, edge_nonmanifold)
    _order_rings(slot, edge_face_offsets, vert_face_offsets, vert_faces, vert_face_corner,
                 vert_edge_offsets, vert_edges, edge_nonmanifold, vert_manifold)


@callee_njit
def _offsets(face_verts, face_edges, edge_verts, edge_face_offsets, vert_face_offsets,
             vert_edge_offsets):
    """The offsets of the edge -> faces, vertex -> faces and vertex -> edges lists (zeroed
    on entry)."""
    n_edges = len(edge_verts)
    n_verts = len(vert_face_offsets) - 1
    # sizes of the lists, then their offsets
    for c in range(len(face_verts)):
        edge_face_offsets[face_edges[c] + 1] += 1
        vert_face_offsets[face_verts[c] + 1] += 1
    for e in range(n_edges):
        vert_edge_offsets[edge_verts[e, 0] + 1] += 1
        vert_edge_offsets[edge_verts[e, 1] + 1] += 1
    for e in range(n_edges):
        edge_face_offsets[e + 1] += edge_face_offsets[e]
    for v in range(n_verts):
        vert_face_offsets[v + 1] += vert_face_offsets[v]
        vert_edge_offsets[v + 1] += vert_edge_offsets[v]


@callee_njit
def _entries(face_offsets, face_verts, face_edges, edge_verts, edge_face_offsets, edge_faces,
             edge_face_corner, vert_face_offsets, vert_edge_offsets, vert_edges):
    """Fill edge -> faces and vertex -> edges in corner / edge order; return each vertex's
    corners ``slot`` (corners, 4) int32 (face, corner, leading edge, trailing edge), in
    vertex order, for :func:`_order_rings`."""
    n_faces = len(face_offsets) - 1
    n_edges = len(edge_verts)
    n_verts = len(vert_face_offsets) - 1
    # the entries, in corner order (edge order for vertex -> edges); a vertex's corners go to
    # `slot` first, with their leading and trailing edges for the ring walk, and reach
    # vert_faces / vert_face_corner in ring order (one row per corner: one cache line)
    slot = np.empty((len(face_verts), 4), dtype=np.int32)  # face, corner, lead, trail
    edge_fill = np.empty(n_edges, dtype=np.int64)
    for e in range(n_edges):
        edge_fill[e] = edge_face_offsets[e]
    vert_fill = np.empty(n_verts, dtype=np.int64)
    for v in range(n_verts):
        vert_fill[v] = vert_face_offsets[v]
    for f in range(n_faces):
        c0 = face_offsets[f]
        c1 = face_offsets[f + 1]
        for c in range(c0, c1):
            e = face_edges[c]
            j = edge_fill[e]
            edge_faces[j] = f
            edge_face_corner[j] = c - c0
            edge_fill[e] = j + 1
            v = face_verts[c]
            j = vert_fill[v]
            slot[j, 0] = f
            slot[j, 1] = c - c0
            slot[j, 2] = e
            slot[j, 3] = face_edges[c - 1 if c > c0 else c1 - 1]
            vert_fill[v] = j + 1
    for v in range(n_verts):
        vert_fill[v] = vert_edge_offsets[v]
    for e in range(n_edges):
        for i in range(2):
            v = edge_verts[e, i]
            vert_edges[vert_fill[v]] = e
            vert_fill[v] += 1
    return slot


@callee_njit
def _nonmanifold_edges(face_offsets, edge_verts, face_edge_forward, edge_face_offsets,
                       edge_faces, edge_face_corner, edge_nonmanifold):
    """Flag the edges used by more than two faces or none, joining a vertex to itself, or
    used twice in the same direction or by one face."""
    n_edges = len(edge_verts)
    for e in range(n_edges):
        u0 = edge_face_offsets[e]
        uses = edge_face_offsets[e + 1] - u0
        bad = uses > 2 or uses < 1 or edge_verts[e, 0] == edge_verts[e, 1]
        if uses == 2:
            f0 = edge_faces[u0]
            f1 = edge_faces[u0 + 1]
            c0 = face_offsets[f0] + edge_face_corner[u0]
            c1 = face_offsets[f1] + edge_face_corner[u0 + 1]
            bad = bad or face_edge_forward[c0] == face_edge_forward[c1] or f0 == f1
        edge_nonmanifold[e] = bad


@callee_njit
def _order_rings(slot, edge_face_offsets, vert_face_offsets, vert_faces, vert_face_corner,
                 vert_edge_offsets, vert_edges, edge_nonmanifold, vert_manifold):
    """Order each vertex's faces and edges counter-clockwise (see :func:`_relations`) from
    its corners ``slot``; set ``vert_manifold``."""
    n_verts = len(vert_face_offsets) - 1
    # scratch buffers sized for the largest valence
    max_nf = 1
    for v in range(n_verts):
        max_nf = max(max_nf, vert_face_offsets[v + 1] - vert_face_offsets[v])
    used = np.empty(max_nf, np.bool_)
    order = np.empty(max_nf, np.int64)
    for v in range(n_verts):
        f0 = vert_face_offsets[v]
        nf = vert_face_offsets[v + 1] - f0
        e0 = vert_edge_offsets[v]
        ne = vert_edge_offsets[v + 1] - e0
        ok = nf > 0 and (ne == nf or ne == nf + 1)
        for j in range(ne):
            if edge_nonmanifold[vert_edges[e0 + j]]:
                ok = False
        # a boundary ring starts at the face whose leading edge is used only once
        is_boundary = ne == nf + 1
        start = 0
        if ok:
            n_start = 0
            for j in range(nf):
                e = slot[f0 + j, 2]
                if edge_face_offsets[e + 1] - edge_face_offsets[e] == 1:
                    start = j
                    n_start += 1
            ok = n_start == (1 if is_boundary else 0)
        # walk counter-clockwise: the next face leads with this face's trailing edge
        if ok:
            for j in range(nf):
                used[j] = False
            order[0] = start
            used[start] = True
            for i in range(1, nf):
                e = slot[f0 + order[i - 1], 3]
                nxt = -1
                for j in range(nf):
                    if (not used[j]) and slot[f0 + j, 2] == e:
                        nxt = j
                        break
                if nxt < 0:
                    ok = False
                    break
                order[i] = nxt
                used[nxt] = True
            if ok and not is_boundary:
                ok = slot[f0 + order[nf - 1], 3] == slot[f0 + order[0], 2]
        vert_manifold[v] = ok
        if not ok:
            # not a single fan: the corners stay in face order
            for j in range(nf):
                vert_faces[f0 + j] = slot[f0 + j, 0]
                vert_face_corner[f0 + j] = slot[f0 + j, 1]
            continue
        for i in range(nf):
            r = f0 + order[i]
            vert_faces[f0 + i] = slot[r, 0]
            vert_face_corner[f0 + i] = slot[r, 1]
            vert_edges[e0 + i] = slot[r, 2]
        if is_boundary:
            vert_edges[e0 + nf] = slot[f0 + order[nf - 1], 3]




def tag_base_level(
    level: Level,
    options: Options,
    crease_edges: np.ndarray,
    crease_sharpness: np.ndarray,
    corner_verts: np.ndarray,
    corner_sharpness: np.ndarray,
    hole_faces: np.ndarray,
) -> Level:
    """Apply tags and OpenSubdiv's boundary / non-manifold sharpening to a base level."""
    n_verts = level.n_verts
    edge_sharp = np.zeros(level.n_edges, dtype=np.float32)
    if len(crease_edges):
        # map vertex pairs to edge ids; tags naming a non-edge are ignored, as OpenSubdiv does
        lo = np.minimum(level.edge_verts[:, 0], level.edge_verts[:, 1]).astype(np.int64)
        hi = np.maximum(level.edge_verts[:, 0], level.edge_verts[:, 1]).astype(np.int64)
        keys = lo * n_verts + hi
        sorter = np.argsort(keys)
        ce = np.asarray(crease_edges, dtype=np.int64).reshape(-1, 2)
        qk = np.minimum(ce[:, 0], ce[:, 1]) * n_verts + np.maximum(ce[:, 0], ce[:, 1])
        pos = np.searchsorted(keys, qk, sorter=sorter)
        pos = np.minimum(pos, len(keys) - 1)
        found = keys[sorter[pos]] == qk
        # a later tag on the same edge overrides an earlier one
        edge_sharp[sorter[pos[found]]] = np.asarray(crease_sharpness, dtype=np.float32)[found]
    vert_sharp = np.zeros(n_verts, dtype=np.float32)
    if len(corner_verts):
        vert_sharp[np.asarray(corner_verts, dtype=np.int64)] = np.asarray(
            corner_sharpness, dtype=np.float32
        )
    face_hole = np.zeros(level.n_faces, dtype=bool)
    if len(hole_faces):
        face_hole[np.asarray(hole_faces, dtype=np.int64)] = True

    n_uses = np.diff(level.edge_face_offsets)
    vert_nonman = ~level.vert_manifold & (np.diff(level.vert_face_offsets) > 0)
    # isolated vertices (no faces) are non-manifold in OpenSubdiv too
    vert_nonman |= np.diff(level.vert_face_offsets) == 0
    if (options.boundary != BOUNDARY_NONE and not np.any(level.edge_nonmanifold)
            and not np.any(vert_nonman)):
        # a manifold cage outside boundary mode "none": what the kernel does comes to
        # its steps 2 and 3 below for boundary edges and one-face corners, done here
        # without the kernel being run, loaded or, on a cold cache, compiled
        edge_sharp[n_uses < 2] = INF_SHARP
        if options.boundary == BOUNDARY_EDGE_AND_CORNER:
            corner = ((np.diff(level.vert_face_offsets) == 1)
                      & (np.diff(level.vert_edge_offsets) == 2))
            vert_sharp[corner] = INF_SHARP
    else:
        _tag_kernel(
            level.vert_face_offsets,
            level.vert_faces,
            level.vert_edge_offsets,
            level.vert_edges,
            n_uses.astype(np.int64),
            level.edge_nonmanifold,
            vert_nonman,
            edge_sharp,
            vert_sharp,
            face_hole,
            options.boundary,
        )
    return Level(
        **{
            **{f: getattr(level, f) for f in level.__dataclass_fields__},
            "edge_sharpness": edge_sharp,
            "vert_sharpness": vert_sharp,
            "face_hole": face_hole,
            "vert_manifold": level.vert_manifold & ~vert_nonman,
        }
    )


@nb.njit(cache=True, nogil=True)
def _tag_kernel(
    vert_face_offsets,
    vert_faces,
    vert_edge_offsets,
    vert_edges,
    edge_n_uses,
    edge_nonman,
    vert_nonman,
    edge_sharp,
    vert_sharp,
    face_hole,
    boundary_mode,
):
    n_verts = len(vert_face_offsets) - 1
    # 1. with boundary interpolation "none", faces at boundary vertices having a boundary
    #    edge that is not (tagged) infinitely sharp become holes -- before any sharpening
    if boundary_mode == 0:
        for v in range(n_verts):
            nf = vert_face_offsets[v + 1] - vert_face_offsets[v]
            ne = vert_edge_offsets[v + 1] - vert_edge_offsets[v]
            if ne == nf and not vert_nonman[v]:
                continue
            exclude = False
            for j in range(vert_edge_offsets[v], vert_edge_offsets[v + 1]):
                e = vert_edges[j]
                if edge_n_uses[e] == 1 and edge_sharp[e] < INF_SHARP:
                    exclude = True
            if exclude:
                for j in range(vert_face_offsets[v], vert_face_offsets[v + 1]):
                    face_hole[vert_faces[j]] = True
    # 2. boundary and non-manifold edges are infinitely sharp
    for e in range(len(edge_sharp)):
        if edge_n_uses[e] < 2 or edge_nonman[e]:
            edge_sharp[e] = INF_SHARP
    # 3. corners (edge-and-corner mode) and non-manifold vertices are sharpened
    for v in range(n_verts):
        nf = vert_face_offsets[v + 1] - vert_face_offsets[v]
        ne = vert_edge_offsets[v + 1] - vert_edge_offsets[v]
        n_bnd = 0
        n_nonman = 0
        for j in range(vert_edge_offsets[v], vert_edge_offsets[v + 1]):
            e = vert_edges[j]
            if edge_n_uses[e] < 2:
                n_bnd += 1
            if edge_nonman[e]:
                n_nonman += 1
        if nf == 1 and ne == 2 and boundary_mode == 1:
            vert_sharp[v] = INF_SHARP
        elif vert_nonman[v]:
            # a plain non-manifold crease (two non-manifold edges, extra fins, no boundary)
            # keeps its sharpness
            if not (n_nonman == 2 and n_bnd == 0 and nf > ne):
                vert_sharp[v] = INF_SHARP


_NO_TAGS = (np.zeros((0, 2), np.int64), np.zeros(0, np.float32), np.zeros(0, np.int64),
            np.zeros(0, np.float32), np.zeros(0, np.int64))


def cage_level(n_verts: int, face_offsets: np.ndarray, face_verts: np.ndarray,
               options: Options, tags=None) -> Level:
    """The topology of a cage's faces (``face_offsets`` (F+1,) int64, ``face_verts`` int32)
    with its ``tags`` applied: (crease edges (k,2) int64, their sharpness (k,) float32,
    corner vertices (m,) int64, theirs (m,) float32, hole faces (h,) int64), None for none
    (``mesh.cage.Cage.base``)."""
    edge_verts, face_edges, forward = base_edges(face_offsets, face_verts, n_verts)
    level = build_level(
        n_verts,
        face_offsets,
        face_verts,
        edge_verts,
        face_edges,
        forward,
        np.zeros(len(edge_verts), np.float32),
        np.zeros(n_verts, np.float32),
        np.zeros(len(face_offsets) - 1, bool),
    )
    return tag_base_level(level, options, *(_NO_TAGS if tags is None else tags))


# rings of faces a restricted cage (``mesh.cage.Cage.restricted``) keeps around the faces it
# is for: the patch table's cut
# (``patches/table.py``: config.GRID_RINGS + 1 rings, refined to the patch level) and one
# more, so that every face of the cut has all the faces around its vertices, hence the whole
# cage's topology and tags (the faces beyond see a boundary that is not the cage's)
RESTRICT_RINGS = config.GRID_RINGS + 2


def face_rings(cage, faces: np.ndarray, rings: int) -> np.ndarray:
    """(F,) bool: the faces ``faces`` ((F,) bool) and every face within ``rings`` rings of
    them (a ring: the faces sharing a vertex with those before), from ``cage``'s face lists
    alone (no topology: ``mesh.cage.Cage``'s ``points``, ``face_offsets``, ``face_verts``)."""
    sel = np.array(faces, dtype=bool)
    if not len(sel):
        return sel
    mark = np.zeros(len(cage.points), bool)
    _grow_rings(cage.face_offsets, cage.face_verts, rings, sel, mark)
    return sel



@nb.njit(cache=True, nogil=True)
def _grow_rings(offsets, verts, rings, sel, mark):
    """Grow the faces ``sel`` ((F,) bool, in place) by ``rings`` rings: each ring marks the
    vertices of the faces selected (``mark``, (V,) bool, all False on entry) and selects
    every face with a marked vertex. (NumPy's repeat, gathers and reduceat over the face
    lists took 29 ms for four rings on the sword refined twice.)"""
    for _ in range(rings):
        for f in range(len(sel)):
            if sel[f]:
                for k in range(offsets[f], offsets[f + 1]):
                    mark[verts[k]] = True
        for f in range(len(sel)):
            if not sel[f]:
                for k in range(offsets[f], offsets[f + 1]):
                    if mark[verts[k]]:
                        sel[f] = True
                        break
