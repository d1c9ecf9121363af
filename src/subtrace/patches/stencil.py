"""Feature-adaptive isolation of smooth extraordinary patches by fixed linear maps.

An irregular Catmull-Clark patch whose one irregularity is an extraordinary vertex of valence
``n`` at one corner, with only smooth quads around its corners (no crease, corner, boundary
or hole), refines the same way at every level: one level turns the ``K = 2n + 8`` points of
its one-ring into the one-ring of the child at the extraordinary vertex (the same
configuration one level down) and the control grids of its three regular children, all by
fixed linear maps of the ``K`` points (Stam 1998, "Exact evaluation of Catmull-Clark
subdivision surfaces at arbitrary parameter values"; OpenSubdiv's stencil tables). So does
the limit point and tangents of each corner of the last irregular cell.

:mod:`subtrace.patches.isolate` refines such patches through local topology, level after
level (a cut around the frontier, its refinement, the children's control grids), which costs
far more than the arithmetic. :func:`stencil_depths` and :func:`stencil_pieces` do the same
refinement with the maps, derived once per valence (:func:`stencil`) by running subtrace's
own refinement, control grids and limit masks on a synthetic cage of that valence, with
one ring point at a time set to 1: the rules are subtrace's, only applied once. The ``K`` points of a patch are
gathered in one canonical order (:func:`ev_rings`): the faces around each corner of the
patch, counter-clockwise from the patch, corners from the extraordinary one on, each face's
points from that corner on; the child at the extraordinary vertex lists its one-ring in the
same order, and its corner there is the patch's (children keep their parent's orientation,
``subdiv/refine.py``). The results equal :mod:`subtrace.patches.isolate`'s to rounding
(tests/test_stencil.py compares them).
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from subtrace import config
from subtrace.config import IRREGULAR_MARGIN
from subtrace.errors import SubtraceError
from subtrace.patches.basis import bezier_nets_and_bounds
from subtrace.patches.facememo import FaceMemo
from subtrace.patches.grids import levels_needed, refine_children, unit_normals
from subtrace.patches.shells import sight_distance
from subtrace.runtime.atomic import write_bytes
from subtrace.subdiv.topology import Level, Options, cage_level, compact, gather_index

MAX_VALENCE = 32  # extraordinary vertices of higher valence take the topological path
# the fewest levels below a patch for which the maps pay for their set-up (a patch isolated
# one level deep costs the topological path less: the sword's 1,810 such patches, measured)
MIN_LEVELS = 3


def stencil_faces(level, options, faces):
    """Which of the irregular quads ``faces`` of ``level`` (Catmull-Clark) the maps serve:
    ``(ok (m,) bool, corner (m,) int64, valence (m,) int64)``, the corner of the
    extraordinary vertex and its valence where ``ok``. A face qualifies when it is a quad,
    exactly one of its corners has a valence other than 4 (at most ``MAX_VALENCE``), and
    every face around its corners is a quad, not a hole, with no sharp edge or vertex at
    those corners and each corner inside the mesh (as many faces as edges, one fan)."""
    faces = np.asarray(faces, dtype=np.int64)
    m = len(faces)
    if options.scheme != "catmark" or m == 0 or not config.STENCIL_ISOLATION:
        return np.zeros(m, dtype=bool), np.zeros(m, np.int64), np.zeros(m, np.int64)
    return _STENCIL_FACES(level, options, faces)


def _stencil_faces(level, options, faces):
    """:func:`stencil_faces` of each of ``faces`` (distinct), computed."""
    faces = np.asarray(faces, dtype=np.int64)
    m = len(faces)
    if options.scheme != "catmark" or m == 0 or not config.STENCIL_ISOLATION:
        return np.zeros(m, dtype=bool), np.zeros(m, np.int64), np.zeros(m, np.int64)
    fo = level.face_offsets
    vfo, veo = level.vert_face_offsets, level.vert_edge_offsets
    corners = level.face_verts[np.minimum(fo[faces][:, None] + np.arange(4),
                                          len(level.face_verts) - 1)]
    val = vfo[corners + 1] - vfo[corners]
    odd = val != 4
    corner = np.argmax(odd, axis=1).astype(np.int64)
    valence = val[np.arange(m), corner].astype(np.int64)
    ok = (np.diff(fo)[faces] == 4) & (odd.sum(axis=1) == 1)
    ok &= (valence >= 3) & (valence <= MAX_VALENCE)
    # the candidates' corners (numpy: no kernel to load): inside, one fan, nothing sharp,
    # only quads that are not holes around them
    at = np.nonzero(ok)[0]
    c = corners[at].ravel()
    good = level.vert_manifold[c] & (veo[c + 1] - veo[c] == val[at].ravel())
    good &= level.vert_sharpness[c] == 0
    for offsets, items, bad in (
            (veo, level.vert_edges, level.edge_sharpness != 0),
            (vfo, level.vert_faces, (np.diff(fo) != 4) | level.face_hole)):
        hits = bad[items[gather_index(offsets, c)]]
        starts = np.r_[0, np.cumsum(offsets[c + 1] - offsets[c])[:-1]]
        good &= np.add.reduceat(np.r_[hits, False].astype(np.int64), starts) == 0
    ok[at] = good.reshape(-1, 4).all(axis=1)
    return ok, np.where(ok, corner, 0), np.where(ok, valence, 0)


# each face of a level classified once (as crease._CREASE_FACES)
_STENCIL_FACES = FaceMemo(_stencil_faces, (bool, np.int64, np.int64))


def stencil_where(level, options, faces, levels):
    """:func:`stencil_faces` for the ``faces`` with at least ``MIN_LEVELS`` ``levels`` (m,)
    to go below them (the others: not ok, unexamined)."""
    m = len(faces)
    ok, corner, valence = np.zeros(m, bool), np.zeros(m, np.int64), np.zeros(m, np.int64)
    deep = np.nonzero(np.asarray(levels) >= MIN_LEVELS)[0]
    if len(deep):
        ok[deep], corner[deep], valence[deep] = stencil_faces(level, options,
                                                              np.asarray(faces)[deep])
    return ok, corner, valence


def ev_rings(level, faces, corner, n) -> np.ndarray:
    """(m, 2n + 8) int64: the one-ring points of the qualifying ``faces`` (valence ``n`` at
    ``corner``) in the canonical order of the module doc: their walks (:func:`_walk`) at
    the positions where each point first appears, the same for every face of valence n
    (stored with its maps, :attr:`Stencil.first`)."""
    return _walk(level, faces, corner, n)[:, stencil(n).first]


def _walk(level, faces, corner, n) -> np.ndarray:
    """(m, 4 (n + 12)) the points met walking around the corners of the qualifying
    ``faces`` (module doc: corners from the extraordinary one, of valence ``n``, on; the
    faces around each counter-clockwise from the face; each face's points from that corner
    on), repeats included."""
    fo, fv = level.face_offsets, level.face_verts
    vfo, vf, vfc = level.vert_face_offsets, level.vert_faces, level.vert_face_corner
    faces = np.asarray(faces, dtype=np.int64)
    corner = np.asarray(corner, dtype=np.int64)
    parts = []
    for k in range(4):
        v = fv[fo[faces] + (corner + k) % 4]
        nf = n if k == 0 else 4
        first = vfo[v]
        fan = vf[first[:, None] + np.arange(nf)]
        pos = np.argmax(fan == faces[:, None], axis=1)
        at = first[:, None] + (pos[:, None] + np.arange(nf)) % nf
        g, kk = vf[at].astype(np.int64), vfc[at].astype(np.int64)
        parts.append(fv[fo[g][:, :, None] + (kk[:, :, None] + np.arange(4)) % 4]
                     .reshape(len(faces), -1))
    return np.concatenate(parts, axis=1).astype(np.int64)


@dataclass(frozen=True)
class Stencil:
    """The maps of valence ``n`` (``K = 2n + 8`` ring points, rows of each map weight them):
    ``ring`` (K,K) the ring of the child at the extraordinary vertex; ``grids`` (4,3,16,K)
    the control grids (4x4, row-major, as ``bspline.control_grids`` lays them: their
    orientation follows the patch's corners) of the three other children of a patch whose
    extraordinary corner is c, in ``grids[c]``; ``kids`` (3,) their corners relative to the
    extraordinary one (1, 2, 3: the child at corner ``(c + kids[q]) % 4``);
    ``P``, ``du``, ``dv`` (4,K) the limit point and tangents of the corners of the patch
    itself, corner ``(c + j) % 4`` in row j; ``edges`` (E,2) the ring's edges (every side of
    every face of the ring, as ``shells.one_ring_shells`` visits them) and ``own`` (4,2) the
    patch's own sides, both as ring indices; ``first`` (K,) where each ring point first
    appears in a face's walk (:func:`_walk`)."""

    n: int
    ring: np.ndarray
    grids: np.ndarray
    kids: np.ndarray
    P: np.ndarray
    du: np.ndarray
    dv: np.ndarray
    edges: np.ndarray
    own: np.ndarray
    first: np.ndarray


def synthetic_cage(n: int, corner: int = 0, rings: int = 3):
    """(points (V,3), face sizes, face vertices) of a disc of quads around one vertex of
    valence ``n`` (vertex 0), every other inner vertex of valence 4: ``n`` sectors of
    ``rings`` x ``rings`` quads. Face 0 is the sector-0 quad at the centre, its corner
    ``corner`` the extraordinary vertex."""
    ids = {}

    def vid(s, i, j):
        if i == 0 and j == 0:
            key = (0,)
        elif j == 0:
            key = ("ray", s % n, i)
        elif i == 0:
            key = ("ray", (s + 1) % n, j)
        else:
            key = ("in", s, i, j)
        return ids.setdefault(key, len(ids))

    faces = []
    for s in range(n):
        for i in range(rings):
            for j in range(rings):
                faces.append([vid(s, i, j), vid(s, i + 1, j), vid(s, i + 1, j + 1),
                              vid(s, i, j + 1)])
    faces[0] = faces[0][-corner:] + faces[0][:-corner] if corner else faces[0]
    pts = np.zeros((len(ids), 3))
    for key, v in ids.items():  # a cone: sector s spans the angles s and s + 1 of n
        if key[0] == "ray":
            a, r = 2 * np.pi * key[1] / n, key[2]
            pts[v] = r * np.cos(a), r * np.sin(a), 0.1 * r
        elif key[0] == "in":
            s, i, j = key[1:]
            a0, a1 = 2 * np.pi * s / n, 2 * np.pi * (s + 1) / n
            p = i * np.array([np.cos(a0), np.sin(a0)]) + j * np.array([np.cos(a1), np.sin(a1)])
            pts[v] = p[0], p[1], 0.1 * (i + j)
    return pts, np.full(len(faces), 4, np.int32), np.array(faces, np.int32).ravel()


@lru_cache(maxsize=None)
def stencil(n: int) -> Stencil:
    """The maps of valence ``n``: read from the kernel cache's folder, where the first
    process that needs them stores them (:func:`derive_stencil`; the folder's name follows
    the sources, so an edit of the rules derives them again)."""
    from subtrace.runtime.jit import KERNEL_DIR

    path = KERNEL_DIR / "stencils" / f"valence-{n}.npy"
    try:
        return _unpacked(n, np.load(path))
    except (OSError, ValueError):
        pass
    s = derive_stencil(n)
    flat = io.BytesIO()
    np.save(flat, np.concatenate([np.ravel(getattr(s, name)).astype(np.float64)
                                  for name in _STORED]))
    try:  # (atomically: processes deriving it at once each write a whole file)
        path.parent.mkdir(parents=True, exist_ok=True)
        write_bytes(path, flat.getvalue())
    except (OSError, SubtraceError):
        pass
    return s


_STORED = ("ring", "grids", "kids", "P", "du", "dv", "edges", "own", "first")


def _unpacked(n: int, flat) -> Stencil:
    """The :class:`Stencil` of valence ``n`` stored flat (``_STORED``'s arrays in order,
    their shapes following from ``n``; the index arrays as exact floats)."""
    K = 2 * n + 8
    shapes = ((K, K), (4, 3, 16, K), (3,), (4, K), (4, K), (4, K), (4 * (n + 12), 2), (4, 2),
              (K,))
    if len(flat) != sum(int(np.prod(sh)) for sh in shapes):
        raise ValueError(f"stored maps of valence {n} have another size")
    out, at = [], 0
    for name, sh in zip(_STORED, shapes):
        a = flat[at:at + int(np.prod(sh))].reshape(sh)
        at += a.size
        out.append(a.astype(np.int64) if name in ("kids", "edges", "own", "first") else a)
    return Stencil(n, *out)


def _cage_level(points, face_sizes, face_verts, options) -> Level:
    """The topology of the synthetic cage's faces (as a :class:`subtrace.mesh.cage.Cage` of
    them builds it: its ``base``)."""
    sizes = np.ascontiguousarray(face_sizes, dtype=np.int32)
    offsets = np.zeros(len(sizes) + 1, np.int64)
    np.cumsum(sizes, out=offsets[1:])
    return cage_level(len(points), offsets, np.ascontiguousarray(face_verts, dtype=np.int32),
                      options)


def derive_stencil(n: int) -> Stencil:
    """The maps of valence ``n``, derived on :func:`synthetic_cage` (module doc): the ring
    points as the columns of an identity, refined once (a column a point; once for each
    corner the extraordinary vertex may have, since the children's grids follow the
    patch's corners), and their limit masks at the patch's corners."""
    from subtrace.patches.bspline import control_grids
    from subtrace.subdiv.limit import limit_points

    options = Options()
    K = 2 * n + 8
    zero = np.zeros(1, np.int64)
    grids = []
    for c in range(4):
        pts, sizes, fverts = synthetic_cage(n, c)
        level = _cage_level(pts, sizes, fverts, options)
        walk = _walk(level, zero, np.full(1, c), n)[0]
        first = np.sort(np.unique(walk, return_index=True)[1])
        if len(first) != K:
            raise AssertionError(f"the synthetic cage of valence {n} has no regular one-ring")
        ring = walk[first]
        basis = np.zeros((level.n_verts, K))
        basis[ring, np.arange(K)] = 1.0
        child, weights, kids, _ = refine_children(level, basis, zero, options)  # (., K)
        others = kids[(c + np.arange(1, 4)) % 4]
        grids.append(weights[control_grids(child, others).reshape(3, 16)])
        if c:
            continue
        # the rest does not depend on the corner's label
        kid_ring = weights[_walk(child, kids[:1], zero, n)[0][first]]
        fo = level.face_offsets
        corners = level.face_verts[fo[0]:fo[0] + 4].astype(np.int64)
        P, du, dv = (np.zeros((4, K)) for _ in range(3))
        for j0 in range(0, K, 3):  # (limit_points takes three coordinates)
            cols = np.arange(j0, min(j0 + 3, K))
            unit = np.zeros((level.n_verts, 3))
            unit[ring[cols], np.arange(len(cols))] = 1.0
            p, a, b = limit_points(level, unit, options, which=corners)
            P[:, cols], du[:, cols], dv[:, cols] = (x[:, :len(cols)] for x in (p, a, b))
        slot = {int(v): k for k, v in enumerate(ring)}
        edges = []
        for v in corners:
            for a in range(level.vert_face_offsets[v], level.vert_face_offsets[v + 1]):
                gv = level.face_verts[fo[level.vert_faces[a]]:fo[level.vert_faces[a] + 1]]
                edges.extend((slot[int(gv[b])], slot[int(gv[(b + 1) % 4])]) for b in range(4))
        own = [(slot[int(corners[b])], slot[int(corners[(b + 1) % 4])]) for b in range(4)]
    return Stencil(n, kid_ring, np.stack(grids), np.arange(1, 4), P, du, dv,
                   np.array(edges, np.int64), np.array(own, np.int64), first)


def _groups(level, points, faces, corner, valence):
    """Per valence of the qualifying ``faces``: ``(rows into faces, their corners, the maps,
    the sides' map (E+4,K): differences along the ring's edges, then along the face's own
    four sides, ring points (K,m,3))``, points first: each level's maps are then one
    matrix product for the whole group."""
    points = np.asarray(points, dtype=np.float64)
    for n in compact(valence, MAX_VALENCE + 1)[0]:  # (np.unique would import numpy.ma)
        n = int(n)
        rows = np.nonzero(valence == n)[0]
        ids = ev_rings(level, faces[rows], corner[rows], n)
        yield (rows, corner[rows], stencil(n), _sides(n),
               np.ascontiguousarray(points[ids.T]))


@lru_cache(maxsize=None)
def _sides(n: int) -> np.ndarray:
    """(E+4, K) the differences along the ring's edges, then along the face's own four
    sides, of valence ``n``'s rings (:func:`_ring_shells`)."""
    st = stencil(n)
    edges = np.concatenate([st.edges, st.own])
    sides = np.zeros((len(edges), 2 * n + 8))
    sides[np.arange(len(edges)), edges[:, 1]] += 1.0
    sides[np.arange(len(edges)), edges[:, 0]] -= 1.0
    return sides


def _times(m, pts):
    """The map ``m`` (R,K) applied to each patch's ring ``pts`` (K,m,3): (R,m,3)."""
    return (m @ pts.reshape(len(pts), -1)).reshape(len(m), -1, 3)


def _ring_shells(pts, sides):
    """(lo, hi, length bound) of the rings ``pts`` (K,m,3) with their ``sides`` map: as
    ``shells.one_ring_shells`` makes them for these faces (each difference is exact: one
    weight +1, one -1, the others 0)."""
    length = np.sqrt((_times(sides, pts) ** 2).sum(axis=2))
    own, emax = length[-4:].max(axis=0), length[:-4].max(axis=0)
    return pts.min(axis=0), pts.max(axis=0), (4.0 * own + 5.0 * emax) / 9.0


def _kid_origin(i0, j0, corner):
    """The dyadic origin, one level down, of the child at ``corner`` of squares at i0, j0."""
    return 2 * i0 + ((corner == 1) | (corner == 2)), 2 * j0 + (corner >= 2)


def _nets(grids, pts):
    """``(nets, lo, hi, bound)``: the Bezier nets (m*3, 4,4,3) of the three regular children
    of each ring ``pts`` (K,m,3), their grids' map ``grids`` (48,K), and their
    :func:`~subtrace.patches.basis.net_bounds`."""
    g = _times(grids, pts).transpose(1, 0, 2)  # (m, 48, 3)
    return bezier_nets_and_bounds(g.reshape(-1, 4, 4, 3))


def stencil_depths(level, points, faces, corner, valence, cap, eye, tol_rad, boxes=None):
    """:func:`~subtrace.patches.isolate.isolated_depths` for qualifying ``faces`` (their
    extraordinary ``corner`` and ``valence``, :func:`stencil_faces`) with the maps: (m,)
    int32 depths, none above ``cap``; ``boxes`` = (lo, hi) (m,3) grown to what each face's
    isolation ended in, as there."""
    cap = np.asarray(cap, dtype=np.int64)
    need = np.zeros(len(faces), dtype=np.int64)
    live = np.nonzero(cap > 0)[0]  # (those of depth 0 are not refined)
    for rows, _, st, sides, pts in _groups(level, points, faces[live], corner[live],
                                           valence[live]):
        rows = live[rows]
        k = 0
        while len(rows):
            k += 1
            # (the nets' bounds do not depend on their orientation: corner 0's grids)
            _, lo, hi, bound = _nets(st.grids[0].reshape(48, -1), pts)
            n = levels_needed(bound, sight_distance(lo, hi, eye), tol_rad).reshape(-1, 3)
            need[rows] = np.maximum(need[rows], k + n.max(axis=1).astype(np.int64))
            if boxes is not None:
                boxes[0][rows] = np.minimum(boxes[0][rows], lo.reshape(-1, 3, 3).min(axis=1))
                boxes[1][rows] = np.maximum(boxes[1][rows], hi.reshape(-1, 3, 3).max(axis=1))
            pts = _times(st.ring, pts)  # the child at the extraordinary vertex
            smin, smax, ebound = _ring_shells(pts, sides)
            flat = IRREGULAR_MARGIN * ebound <= tol_rad * sight_distance(smin, smax, eye)
            need[rows] = np.maximum(need[rows], k)
            more = ~flat & (k < cap[rows])
            if boxes is not None:  # the irregular children refined no further
                stop = rows[~more]
                boxes[0][stop] = np.minimum(boxes[0][stop], smin[~more])
                boxes[1][stop] = np.maximum(boxes[1][stop], smax[~more])
            rows, pts = rows[more], pts[:, more]
    return np.minimum(need, cap).astype(np.int32)


def stencil_pieces(level, points, options, faces, corner, valence, depth, eye=None,
                   tol_rad=None, ring=False, k0=0, i0=None, j0=None):
    """:func:`~subtrace.patches.isolate.build_isolated`'s ``(subs, cells)`` lists for
    qualifying ``faces`` (their extraordinary ``corner`` and ``valence``) refined down to
    ``depth`` (m,), with the maps; the root indices index ``faces``. The faces are squares
    of level ``k0`` of their patches at ``i0, j0`` (in units of 2^-k0; default 0: the
    patches themselves), ``depth`` in the patches' units."""
    depth = np.asarray(depth, dtype=np.int64)
    m = len(faces)
    i0 = np.zeros(m, np.int64) if i0 is None else np.asarray(i0, np.int64)
    j0 = np.zeros(m, np.int64) if j0 is None else np.asarray(j0, np.int64)
    subs = [[] for _ in range(8)]  # (isolate.build_isolated's)
    cells = [[] for _ in range(7 if ring else 5)]
    for rows, cor, st, _, pts in _groups(level, points, faces, corner, valence):
        gi, gj = i0[rows], j0[rows]
        k = k0
        while len(rows):
            done = depth[rows] == k
            if done.any():
                _corner_cells(cells, st, pts[:, done], cor[done], rows[done], gi[done],
                              gj[done])
                keep = ~done
                rows, cor, pts, gi, gj = rows[keep], cor[keep], pts[:, keep], gi[keep], gj[keep]
                if not len(rows):
                    break
            # the children in the order of their corners, as the topological path lists them
            nets = np.empty((len(rows), 3, 4, 4, 3))
            lo, hi = np.empty((len(rows), 3, 3)), np.empty((len(rows), 3, 3))
            bound = np.empty((len(rows), 3))
            for c in compact(cor, 4)[0]:  # (the grids follow the corners)
                at = cor == c
                grids = st.grids[c][np.argsort((c + st.kids) % 4)]
                got = _nets(grids.reshape(48, -1), pts[:, at])
                nets[at] = got[0].reshape(-1, 3, 4, 4, 3)
                lo[at], hi[at] = got[1].reshape(-1, 3, 3), got[2].reshape(-1, 3, 3)
                bound[at] = got[3].reshape(-1, 3)
            nets = nets.reshape(-1, 4, 4, 3)
            lo, hi, bound = lo.reshape(-1, 3), hi.reshape(-1, 3), bound.ravel()
            kid_corner = np.sort((cor[:, None] + st.kids[None, :]) % 4, axis=1).ravel()
            ki, kj = _kid_origin(np.repeat(gi, 3), np.repeat(gj, 3), kid_corner)
            root = np.repeat(rows, 3)
            own = depth[root]
            if eye is not None:
                n = levels_needed(bound, sight_distance(lo, hi, eye), tol_rad)
                own = np.clip(k + 1 + n, k + 1, own).astype(np.int64)
            for lst, a in zip(subs, (root, np.full(len(root), k + 1), ki, kj, nets, own, lo,
                                     hi)):
                lst.append(np.asarray(a))
            pts = _times(st.ring, pts)
            gi, gj = _kid_origin(gi, gj, cor)
            k += 1
    return subs, cells


def _corner_cells(cells, st, pts, corner, root, i0, j0):
    """Append the irregular cells whose rings are ``pts`` (K,m,3) (maps ``st``) to the lists
    ``cells`` (``isolate.build_isolated``'s: the corners' limit points and unit normals, NaN
    where undefined, corner t from the map row ``(t - corner) % 4``; with seven lists, the
    diagonals of the rings' boxes and no boundary)."""
    turn = (np.arange(4)[None, :] - corner[:, None]) % 4  # (m,4)
    cols = np.arange(len(root))[:, None]
    P, du, dv = (_times(a, pts)[turn, cols] for a in (st.P, st.du, st.dv))  # (m,4,3)
    for lst, a in zip(cells, (root, i0, j0, P, unit_normals(du, dv))):
        lst.append(a)
    if len(cells) > 5:
        cells[5].append(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0), axis=1))
        cells[6].append(np.zeros(len(root), dtype=bool))
