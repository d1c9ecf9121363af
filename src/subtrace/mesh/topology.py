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
every sharpness computation is done in float32 so fractional crease weights match it exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from .. import config

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


def _csr_from_keys(keys: np.ndarray, n: int):
    """Group positions 0..len(keys)-1 by key (stable). Returns (offsets (n+1,), order)."""
    offsets = np.zeros(n + 1, dtype=np.int64)
    order = np.empty(len(keys), dtype=np.int32)
    _counting_sort(np.ascontiguousarray(keys), offsets, order)
    return offsets, order


@nb.njit(cache=True)
def _counting_sort(keys, offsets, order):
    """Stable counting sort of small non-negative integer keys: offsets[k] is the start of
    key k's run in ``order``, which lists the positions of the keys in increasing key order."""
    for i in range(len(keys)):
        offsets[keys[i] + 1] += 1
    for k in range(1, len(offsets)):
        offsets[k] += offsets[k - 1]
    cursor = offsets[:-1].copy()
    for i in range(len(keys)):
        k = keys[i]
        order[cursor[k]] = i
        cursor[k] += 1


def _compact(ids: np.ndarray, n: int):
    """The distinct values of ``ids`` (all in 0..n-1) in increasing order, and the map from
    each value to its rank (-1 for values absent); O(n), no sort."""
    mask = np.zeros(n, dtype=bool)
    mask[ids] = True
    kept = np.nonzero(mask)[0]
    rank = np.full(n, -1, dtype=np.int64)
    rank[kept] = np.arange(len(kept))
    return kept, rank


def _corner_faces(face_offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For every corner c: its face and its index k within the face."""
    sizes = np.diff(face_offsets)
    face_of = np.repeat(np.arange(len(sizes), dtype=np.int32), sizes)
    k = (np.arange(face_offsets[-1], dtype=np.int64) - face_offsets[face_of]).astype(np.int32)
    return face_of, k


def _next_corner(face_offsets: np.ndarray, face_of: np.ndarray, k: np.ndarray) -> np.ndarray:
    sizes = np.diff(face_offsets)
    s = sizes[face_of]
    return (face_offsets[face_of] + (k + 1) % s).astype(np.int64)


def base_edges(face_offsets: np.ndarray, face_verts: np.ndarray, n_verts: int):
    """Edges of a base mesh, numbered by first appearance when walking faces in order.

    Returns (edge_verts (E,2), face_edges (C,), face_edge_forward (C,)).
    """
    face_of, k = _corner_faces(face_offsets)
    a = face_verts.astype(np.int64)
    b = face_verts[_next_corner(face_offsets, face_of, k)].astype(np.int64)
    lo = np.minimum(a, b)
    hi = np.maximum(a, b)
    keys = lo * np.int64(n_verts) + hi
    # as in OpenSubdiv, a degenerate edge (a face repeating a vertex) is never shared, and a
    # face that uses an edge a second time gets a new edge for that use
    unique_use = a == b
    order = np.lexsort((np.arange(len(keys)), face_of, keys))
    same = (keys[order][1:] == keys[order][:-1]) & (face_of[order][1:] == face_of[order][:-1])
    unique_use[order[1:][same]] = True
    if unique_use.any():
        keys[unique_use] = np.int64(n_verts) * n_verts + np.nonzero(unique_use)[0]
    uniq, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    # renumber the unique edges by first appearance
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    face_edges = rank[inverse].astype(np.int32)
    first_sorted = first[order]
    edge_verts = np.stack([a[first_sorted], b[first_sorted]], axis=1).astype(np.int32)
    forward = (edge_verts[face_edges, 0] == a) & (edge_verts[face_edges, 1] == b)
    return edge_verts, face_edges, forward


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
    n_edges = len(edge_verts)
    face_of, k = _corner_faces(face_offsets)

    # edge -> face uses, in face order
    edge_face_offsets, order = _csr_from_keys(face_edges, n_edges)
    edge_faces = face_of[order]
    edge_face_corner = k[order]

    # vertex -> face corners, and vertex -> edges
    vert_face_offsets, order = _csr_from_keys(face_verts, n_verts)
    vert_faces = face_of[order]
    vert_face_corner = k[order]
    ev = edge_verts.ravel()
    vert_edge_offsets, order = _csr_from_keys(ev, n_verts)
    vert_edges = (order // 2).astype(np.int32)

    if edge_nonmanifold is None:
        edge_nonmanifold = _detect_nonmanifold_edges(
            edge_verts, edge_face_offsets
        )
        edge_nonmanifold |= _same_direction_uses(
            edge_face_offsets, edge_faces, edge_face_corner, face_offsets, face_edge_forward
        )
    vert_manifold = np.empty(n_verts, dtype=np.bool_)
    _order_vertex_rings(
        face_offsets,
        face_verts,
        face_edges,
        edge_verts,
        edge_face_offsets,
        edge_faces,
        edge_nonmanifold,
        vert_face_offsets,
        vert_faces,
        vert_face_corner,
        vert_edge_offsets,
        vert_edges,
        vert_manifold,
    )
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
        edge_nonmanifold=np.ascontiguousarray(edge_nonmanifold, dtype=np.bool_),
        edge_sharpness=np.ascontiguousarray(edge_sharpness, dtype=np.float32),
        vert_sharpness=np.ascontiguousarray(vert_sharpness, dtype=np.float32),
        face_hole=np.ascontiguousarray(face_hole, dtype=np.bool_),
    )


def _detect_nonmanifold_edges(edge_verts, edge_face_offsets):
    """Edges with more than two uses, none, or both ends at one vertex."""
    n_uses = np.diff(edge_face_offsets)
    nonman = (n_uses > 2) | (n_uses < 1) | (edge_verts[:, 0] == edge_verts[:, 1])
    return nonman


def _same_direction_uses(edge_face_offsets, edge_faces, edge_face_corner, face_offsets, forward):
    """Edges used twice in the same direction (faces of opposite orientation), or twice by
    one face: OpenSubdiv cannot orient these and treats them as non-manifold."""
    n_uses = np.diff(edge_face_offsets)
    two = np.nonzero(n_uses == 2)[0]
    if len(two) == 0:
        return np.zeros(len(n_uses), dtype=bool)
    u0 = edge_face_offsets[two]
    f0, f1 = edge_faces[u0], edge_faces[u0 + 1]
    c0 = face_offsets[f0] + edge_face_corner[u0]
    c1 = face_offsets[f1] + edge_face_corner[u0 + 1]
    bad = (forward[c0] == forward[c1]) | (f0 == f1)
    out = np.zeros(len(n_uses), dtype=bool)
    out[two[bad]] = True
    return out


@nb.njit(cache=True)
def _order_vertex_rings(
    face_offsets,
    face_verts,
    face_edges,
    edge_verts,
    edge_face_offsets,
    edge_faces,
    edge_nonmanifold,
    vert_face_offsets,
    vert_faces,
    vert_face_corner,
    vert_edge_offsets,
    vert_edges,
    vert_manifold,
):
    """Order each manifold vertex's faces counter-clockwise and its edges to match.

    As in OpenSubdiv: edge i of the ring is the *leading* edge of face i at the vertex (the
    edge leaving it, corner k -> k+1), and the next face counter-clockwise is the one whose
    leading edge is this face's trailing edge (corner k-1 -> k). A boundary vertex starts at
    the face whose leading edge is a boundary, and has one more edge than faces: the last is
    the trailing edge of the last face. Vertices whose faces do not form a single fan keep
    their unordered lists and are flagged non-manifold.
    """
    n_verts = len(vert_face_offsets) - 1
    # scratch buffers sized for the largest valence, allocated once
    max_nf = 1
    for v in range(n_verts):
        max_nf = max(max_nf, vert_face_offsets[v + 1] - vert_face_offsets[v])
    lead = np.empty(max_nf, np.int32)
    trail = np.empty(max_nf, np.int32)
    used = np.empty(max_nf, np.bool_)
    order = np.empty(max_nf, np.int32)
    tmp_f = np.empty(max_nf, np.int32)
    tmp_c = np.empty(max_nf, np.int32)
    for v in range(n_verts):
        f0 = vert_face_offsets[v]
        nf = vert_face_offsets[v + 1] - f0
        e0 = vert_edge_offsets[v]
        ne = vert_edge_offsets[v + 1] - e0
        if nf == 0:
            vert_manifold[v] = False
            continue
        ok = True
        for j in range(ne):
            if edge_nonmanifold[vert_edges[e0 + j]]:
                ok = False
        if not ok or (ne != nf and ne != nf + 1):
            vert_manifold[v] = False
            continue
        # leading edge (corner k -> k+1) and trailing edge (k-1 -> k) of each incident corner
        for j in range(nf):
            f = vert_faces[f0 + j]
            k = vert_face_corner[f0 + j]
            off = face_offsets[f]
            n = face_offsets[f + 1] - off
            lead[j] = face_edges[off + k]
            trail[j] = face_edges[off + (k - 1 + n) % n]
        # a boundary ring starts at the face whose leading edge is used only once
        start = 0
        n_start = 0
        for j in range(nf):
            e = lead[j]
            if edge_face_offsets[e + 1] - edge_face_offsets[e] == 1:
                start = j
                n_start += 1
        is_boundary = ne == nf + 1
        if (is_boundary and n_start != 1) or ((not is_boundary) and n_start != 0):
            vert_manifold[v] = False
            continue
        # walk counter-clockwise: the next face leads with this face's trailing edge
        used[:nf] = False
        order[0] = start
        used[start] = True
        for i in range(1, nf):
            e = trail[order[i - 1]]
            nxt = -1
            for j in range(nf):
                if (not used[j]) and lead[j] == e:
                    nxt = j
                    break
            if nxt < 0:
                ok = False
                break
            order[i] = nxt
            used[nxt] = True
        if ok and not is_boundary:
            ok = trail[order[nf - 1]] == lead[order[0]]
        if not ok:
            vert_manifold[v] = False
            continue
        vert_manifold[v] = True
        for i in range(nf):
            tmp_f[i] = vert_faces[f0 + order[i]]
            tmp_c[i] = vert_face_corner[f0 + order[i]]
        for i in range(nf):
            vert_faces[f0 + i] = tmp_f[i]
            vert_face_corner[f0 + i] = tmp_c[i]
            vert_edges[e0 + i] = lead[order[i]]
        if is_boundary:
            vert_edges[e0 + nf] = trail[order[nf - 1]]


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


@nb.njit(cache=True)
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
    inf = np.float32(10.0)
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
                if edge_n_uses[e] == 1 and edge_sharp[e] < inf:
                    exclude = True
            if exclude:
                for j in range(vert_face_offsets[v], vert_face_offsets[v + 1]):
                    face_hole[vert_faces[j]] = True
    # 2. boundary and non-manifold edges are infinitely sharp
    for e in range(len(edge_sharp)):
        if edge_n_uses[e] < 2 or edge_nonman[e]:
            edge_sharp[e] = inf
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
            vert_sharp[v] = inf
        elif vert_nonman[v]:
            # a plain non-manifold crease (two non-manifold edges, extra fins, no boundary)
            # keeps its sharpness
            if not (n_nonman == 2 and n_bnd == 0 and nf > ne):
                vert_sharp[v] = inf
