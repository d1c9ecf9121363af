"""Regular Catmull-Clark patches as bicubic B-splines: which faces are, and their control grids.

A quad of the patch level whose four corners are smooth, valence 4 and crease-free is a
uniform bicubic B-spline patch of the 16 points around it (the same test and the same
control grid as the exact evaluator, :mod:`subtrace.patches.evaluate`). So is a quad whose
corners are regular boundary, infinitely sharp crease or sharp corner vertices
(:func:`regular_mask`), with phantom points beyond its sharp sides (:func:`phantom_grids`;
the exact evaluator keeps its own path for those, and agrees). For such a patch:

* :func:`control_grids` gathers the 16 point ids of a smooth patch (:func:`phantom_grids`
  those of any regular patch, phantom points appended to the level's points), ``[u index][v index]``, with ``u`` running
  from corner 0 to corner 1 and ``v`` from corner 0 to corner 3 (the grid layout of
  :mod:`subtrace.patches.grids`);
* :func:`subtrace.patches.basis.bezier_nets` converts them to the patch's bicubic Bezier
  control net. The patch lies in the net's convex hull, so the net's box is a containing
  shell much tighter than the box of the 16 B-spline points (design invariant 2), and the
  partial derivatives are Bezier patches with control points ``3 (b[i+1, j] - b[i, j])``
  (resp. ``j``), so :func:`~subtrace.patches.basis.net_bounds` gives the box and a bound on
  ``|dP/du|`` and ``|dP/dv|`` over the whole patch: a grid cell at depth ``n`` has sides no
  longer than ``bound * 2^-n`` (the refinement criterion, design invariant 3).

The renderer evaluates the nets themselves (``geometry/bezier.py``).
"""

from __future__ import annotations

import numpy as np

from subtrace.patches.basis import B_CORNER, LEAD, TRAIL
from subtrace.runtime.jit import nb
from subtrace.runtime.threads import run_tasks
from subtrace.subdiv.limit import CORNER, CREASE, SMOOTH, classify
from subtrace.subdiv.topology import INF_SHARP, compact


def regular_mask(level, options, faces) -> np.ndarray:
    """(len(faces),) bool: the faces of ``level`` that are regular bicubic patches.

    A Catmull-Clark quad is one when each corner is regular: smooth of valence 4, a boundary
    or infinitely sharp crease vertex that is regular there (2 faces and 3 edges, or 4 faces
    with its two sharp edges opposite each other), or a sharp corner with one face (what
    OpenSubdiv's Far takes as regular boundary patches). A valence-2 boundary vertex that is
    not sharpened (boundary interpolation "edge only", no corner tag) takes the crease rule
    and is not regular; semi-sharp features make the vertex hard and the patch irregular.
    """
    faces = np.asarray(faces, dtype=np.int64)
    if options.scheme != "catmark" or len(faces) == 0:
        return np.zeros(len(faces), dtype=bool)
    fo = level.face_offsets
    quad = (fo[faces + 1] - fo[faces]) == 4
    corners = level.face_verts[np.minimum(fo[faces][:, None] + np.arange(4), len(level.face_verts) - 1)]
    # per vertex, not per corner (the conditions are the vertex's): the level's vertices at
    # once, or the corners' alone when they are few (classify's entries for the others are
    # undefined, and so are theirs here: only the corners' are read)
    cls = classify(level, options, corners)
    if corners.size < level.n_verts:
        verts = compact(corners.ravel(), level.n_verts)[0]
    else:
        verts = np.arange(level.n_verts)
    ok = np.zeros(level.n_verts, dtype=bool)
    c = cls[verts]
    ne = np.diff(level.vert_edge_offsets)[verts]
    nf = np.diff(level.vert_face_offsets)[verts]
    good = (c == SMOOTH) & (ne == 4)
    # boundary and crease vertices, sharp corners
    manifold = level.vert_manifold[verts]
    crease = (c == CREASE) & manifold
    good |= crease & (nf == 2) & (ne == 3)
    four = crease & (nf == 4) & (ne == 4)
    if four.any():
        ring = level.vert_edges[level.vert_edge_offsets[verts[four]][:, None] + np.arange(4)]
        sharp = level.edge_sharpness[ring] >= INF_SHARP
        good[four] |= (sharp[:, 0] == sharp[:, 2]) & (sharp[:, 1] == sharp[:, 3])
    good |= (c == CORNER) & manifold & (nf == 1) & (ne == 2)
    ok[verts] = good
    return quad & ok[corners].all(axis=1)


def smooth_mask(level, faces) -> np.ndarray:
    """(len(faces),) bool: which of the regular quads ``faces`` have no boundary or
    infinitely sharp edge at a corner (their 16 control points are all points of ``level``):
    each corner has four edges and four faces, none of the edges sharp."""
    faces = np.asarray(faces, dtype=np.int64)
    fo = level.face_offsets
    corners = level.face_verts[fo[faces][:, None] + np.arange(4)]
    ok = ((np.diff(level.vert_edge_offsets) == 4) & (np.diff(level.vert_face_offsets) == 4))
    ok[level.edge_verts[level.edge_sharpness > 0].ravel()] = False
    return ok[corners].all(axis=1)


def control_points(level, faces, points) -> np.ndarray:
    """(m, 4, 4, 3) float64 B-spline control points of the regular quads ``faces`` of
    ``level`` with points ``points`` (phantom points where a side is a boundary or crease)."""
    grids, ext = phantom_grids(level, faces, points)
    return ext[grids]


def phantom_grids(level, faces, points):
    """Control grids of the regular quads ``faces``: ``(grids, ext)`` with ``grids``
    (m, 4, 4) int64 ids into ``ext`` (V', 3), the points of the level followed by the
    control points of the patches that have a boundary or infinitely sharp side.

    Smooth patches gather their 16 points by id (:func:`control_grids`, ``ext`` is
    ``points`` itself when every patch is smooth). A patch with a sharp side has the row
    beyond that side replaced by phantom points mirrored through the side's row,
    ``2 P_side - P_inner``; a grid corner beyond two sharp sides is mirrored twice,
    ``4 P_c - 2 P_a - 2 P_b + P_d``. Uniform B-spline subdivision of those points gives
    Catmull-Clark's boundary and crease rules (edge point the midpoint, vertex point
    ``(e0 + 6 v + e1) / 8``, a sharp corner kept), so the bicubic is the limit surface.
    """
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    smooth = smooth_mask(level, faces) if len(faces) else np.zeros(0, dtype=bool)
    if smooth.all():
        return control_grids(level, faces), points
    grids = np.empty((len(faces), 4, 4), dtype=np.int64)
    grids[smooth] = control_grids(level, faces[smooth])
    rest = faces[~smooth]
    ids = np.full((len(rest), 4, 4), -1, dtype=np.int64)
    cut = np.zeros((len(rest), 4), dtype=np.bool_)
    _grids(0, 1, 1, *_grid_arrays(level), rest, B_CORNER, LEAD, TRAIL, ids, cut)
    cv = np.asarray(points, dtype=np.float64)[np.maximum(ids, 0)]
    _mirror(cv, cut)
    n = len(points)
    grids[~smooth] = n + np.arange(16 * len(rest)).reshape(-1, 4, 4)
    return grids, np.concatenate([np.asarray(points, dtype=np.float64), cv.reshape(-1, 3)])


def _mirror(cv, cut):
    """Phantom rows of control points ``cv`` (m,4,4,3) beyond sharp sides ``cut`` (m,4):
    side 0 is the row v = 0, side 1 u = 3, side 2 v = 3, side 3 u = 0. The v rows first,
    where the u side beside them is real, then whole u columns."""
    for side, (row, inner) in ((0, (0, 2)), (2, (3, 1))):
        m = cut[:, side]
        for u in range(4):
            keep = m.copy()
            if u == 0:
                keep &= ~cut[:, 3]
            elif u == 3:
                keep &= ~cut[:, 1]
            cv[keep, u, row] = 2.0 * cv[keep, u, (row + inner) // 2] - cv[keep, u, inner]
    for side, (row, inner) in ((3, (0, 2)), (1, (3, 1))):
        m = cut[:, side]
        cv[m, row, :] = 2.0 * cv[m, (row + inner) // 2, :] - cv[m, inner, :]


def control_grids(level, faces) -> np.ndarray:
    """(m, 4, 4) int64 point ids of the control grids of regular quads ``faces``."""
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    out = np.empty((len(faces), 4, 4), dtype=np.int64)
    run_tasks(_grids, 0, *_grid_arrays(level), faces, B_CORNER, LEAD, TRAIL, out, _NO_CUT,
              n=None if len(faces) >= _GRID_PARALLEL_MIN else 1)
    return out


_NO_CUT = np.zeros((0, 4), dtype=np.bool_)  # (the smooth grids' step marks no side)


def _grid_arrays(level):
    """The topology :func:`_grids` reads, in its order."""
    return (level.face_offsets, level.face_verts, level.face_edges, level.edge_face_offsets,
            level.edge_faces, level.edge_sharpness, level.vert_face_offsets, level.vert_faces,
            level.vert_face_corner, level.vert_edge_offsets, level.vert_edges,
            level.edge_verts)


_GRID_BLOCK = 256  # faces a task gathers at a time
_GRID_PARALLEL_MIN = 8 * _GRID_BLOCK  # fewer faces than this: one thread


@nb.njit(cache=True, nogil=True)
def _grids(task, n_tasks, step, fo, fv, fe, efo, ef, es, vfo, vf, vfc, veo, ve, ev, faces, bc,
           lead, trail, ids, cut):
    """The control grids (point ids, (m,4,4)) ``ids`` of quads ``faces`` (topology as
    :func:`_grid_arrays` lists it), in one kernel for the table's two kinds (a kernel load
    less in a render):

    step 0, regular quads (:func:`control_grids`): task ``task`` of ``n_tasks``
    (tasks.run_tasks) takes blocks of ``_GRID_BLOCK`` faces, every n_tasks-th;

    step 1 (one task), regular quads with sharp sides (:func:`phantom_grids`): the real
    point ids (-1 where a phantom point goes) and which sides are sharp (``cut`` (m,4))."""
    if step == 1:
        for m in range(len(faces)):
            f = faces[m]
            for k in range(4):
                c = fv[fo[f] + k]
                ids[m, bc[k, 0], bc[k, 1]] = c
                cut[m, k] = es[fe[fo[f] + k]] >= INF_SHARP
            for k in range(4):
                if cut[m, k]:
                    continue
                # the face across side k and its two points off the side
                a, b = fv[fo[f] + k], fv[fo[f] + (k + 1) % 4]
                e = fe[fo[f] + k]
                g = ef[efo[e]] if ef[efo[e]] != f else ef[efo[e] + 1]
                for end in range(2):
                    c = a if end == 0 else b
                    o = b if end == 0 else a
                    ia = 0
                    for i in range(4):
                        if fv[fo[g] + i] == c:
                            ia = i
                    nxt = fv[fo[g] + (ia + 1) % 4]
                    out = fv[fo[g] + (ia + 3) % 4] if nxt == o else nxt
                    kc = (k + end) % 4
                    ids[m, bc[kc, 0] - trail[k, 0], bc[kc, 1] - trail[k, 1]] = out
            for k in range(4):
                # the grid corner beyond corner k: real when neither side at k is sharp (the
                # corner is then smooth of valence 4), the diagonal of the opposite face
                if cut[m, k] or cut[m, (k + 3) % 4]:
                    continue
                c = fv[fo[f] + k]
                a = vfo[c]
                pos = 0
                for j in range(4):
                    if vf[a + j] == f:
                        pos = j
                g = vf[a + (pos + 2) % 4]
                kk = vfc[a + (pos + 2) % 4]
                d = fv[fo[g] + (kk + 2) % 4]
                ids[m, 2 * bc[k, 0] - bc[(k + 2) % 4, 0], 2 * bc[k, 1] - bc[(k + 2) % 4, 1]] = d
        return
    dirs = np.empty((4, 2), dtype=np.int64)
    for b0 in range(task * _GRID_BLOCK, len(faces), n_tasks * _GRID_BLOCK):
        for m in range(b0, min(b0 + _GRID_BLOCK, len(faces))):
            f = faces[m]
            for i in range(4):
                c = fv[fo[f] + i]
                x0, y0 = bc[i, 0], bc[i, 1]
                ids[m, x0, y0] = c
                a = vfo[c]
                pos = 0
                for j in range(4):
                    if vf[a + j] == f:
                        pos = j
                # the other three faces around the corner, counter-clockwise from f
                for q in range(2):
                    dirs[0, q] = trail[i, q]
                    dirs[1, q] = -lead[i, q]
                    dirs[2, q] = -trail[i, q]
                    dirs[3, q] = lead[i, q]
                for k in range(1, 4):
                    j = (pos + k) % 4
                    g = vf[a + j]
                    kk = vfc[a + j]
                    diag = fv[fo[g] + (kk + 2) % 4]
                    x1, y1 = x0 + dirs[k - 1, 0], y0 + dirs[k - 1, 1]
                    ids[m, x1 + dirs[k, 0], y1 + dirs[k, 1]] = diag
                    if k >= 2:
                        e = ve[veo[c] + j]
                        other = ev[e, 1] if ev[e, 0] == c else ev[e, 0]
                        ids[m, x1, y1] = other
