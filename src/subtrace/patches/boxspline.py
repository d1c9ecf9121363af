"""Regular Loop patches: which triangles are quartic box splines, and their Bezier nets.

A triangle of a Loop level is *regular* (:func:`loop_regular`) when its three corners are
smooth, of valence 6 and crease-free (the exact evaluator's test,
:mod:`subtrace.patches.evaluate`), or when it is a regular boundary (:func:`_boundary_recipe`):
its limit surface is then the quartic box spline of the 12 points around it, which is one
quartic polynomial, converted to its 15-point triangular Bezier net (:func:`box_nets`,
``basis.BOX_TO_TRI``). The trace (``trace/build.py``, ``trace/budget.py``), the isolation of
irregular Loop patches (``patches/isolate_loop.py``) and the line queries
(``lines/items.py``) all take their regular Loop nets from here.
"""

from __future__ import annotations

import numpy as np

from subtrace.patches.basis import BOX_POINTS, BOX_TO_TRI, LATTICE_DIRS, TRI_CORNER, TRI_LEAD
from subtrace.runtime.jit import leaf_njit, nb
from subtrace.subdiv.limit import CREASE, SMOOTH, classify
from subtrace.subdiv.loop import REGULAR_VALENCE
from subtrace.subdiv.topology import INF_SHARP


def loop_regular(level, options, faces) -> np.ndarray:
    """(len(faces),) bool: the triangles of ``level`` that are regular quartic box splines:
    three smooth, valence-6, crease-free corners, or a regular boundary (see
    :func:`_boundary_recipe`)."""
    faces = np.asarray(faces, dtype=np.int64)
    if len(faces) == 0:
        return np.zeros(0, dtype=bool)
    fo = level.face_offsets
    tri = (fo[faces + 1] - fo[faces]) == 3
    corners = level.face_verts[np.minimum(fo[faces][:, None] + np.arange(3),
                                          len(level.face_verts) - 1)]
    cls = classify(level, options, corners)
    n_edges = np.diff(level.vert_edge_offsets)[corners]
    n_faces = np.diff(level.vert_face_offsets)[corners]
    inner = ((cls[corners] == SMOOTH) & (n_edges == REGULAR_VALENCE)
             & (n_faces == REGULAR_VALENCE))
    ok = tri & inner.all(axis=1) & ~level.face_hole[faces]
    # crease vertices (a boundary, or an infinitely sharp crease): _boundary_recipe decides
    border = (cls[corners] == CREASE) & level.vert_manifold[corners]
    maybe = np.nonzero(tri & ~ok & (inner | border).all(axis=1) & border.any(axis=1)
                       & ~level.face_hole[faces])[0]
    if len(maybe):
        ok[maybe] = _boundary_recipes(level, faces[maybe], level.edge_sharpness >= INF_SHARP)[0]
    return ok


def box_nets(level, points, faces) -> np.ndarray:
    """(m,15,3) triangular Bezier nets of the regular triangles ``faces`` of ``level``."""
    faces = np.asarray(faces, dtype=np.int64)
    fo = level.face_offsets
    corners = level.face_verts[fo[faces][:, None] + np.arange(3)]
    sharp = level.edge_sharpness >= INF_SHARP
    on_crease = np.zeros(level.n_verts, dtype=bool)
    on_crease[level.edge_verts[sharp].ravel()] = True
    inner = ~on_crease[corners].any(axis=1)  # else a crease corner: phantom points
    X = np.empty((len(faces), len(BOX_POINTS), 3))
    rows = np.nonzero(inner)[0]
    ids = np.empty((len(rows), len(BOX_POINTS)), dtype=np.int64)
    _box_points(level.face_offsets, level.face_verts, level.vert_face_offsets, level.vert_faces,
                level.vert_edge_offsets, level.vert_edges, level.edge_verts,
                faces[rows], _RING_SLOT, ids)
    X[rows] = points[ids]
    border = np.nonzero(~inner)[0]
    if len(border):
        _, abr = _boundary_recipes(level, faces[border], sharp)
        a, b, r = abr[:, 0], abr[:, 1], abr[:, 2]
        X[border] = points[a] + np.where(b[..., None] >= 0, points[b] - points[r], 0.0)
    return np.ascontiguousarray(np.matmul(BOX_TO_TRI, X))


def _boundary_recipe(level, f, sharp_edge):
    """The 12 box-spline points of triangle ``f`` with corners on a boundary or an
    infinitely sharp crease, or None (:func:`_boundary_recipes` for one triangle)."""
    ok, out = _boundary_recipes(level, np.array([f], np.int64), sharp_edge)
    return (out[0, 0], out[0, 1], out[0, 2]) if ok[0] else None


def _boundary_recipes(level, faces, sharp_edge):
    """Per triangle of ``faces`` with corners on a boundary or an infinitely sharp crease:
    whether its 12 box-spline points can be made, and ``(a, b, r)`` for each (m,3,12).

    A *regular crease vertex* has 3 faces on the triangle's side, between its two sharp
    edges (a boundary vertex of 4 edges, or an interior one of 6 whose sharp edges are
    opposite), and no other sharp edge. The lattice points beyond the crease are replaced by
    the *phantom* points that mirror the triangle's side across a sharp edge (a, b):
    ``a + b - r``, r the lattice point across (a, b) from it, so that the box spline's
    smooth rules reproduce the crease rules there (edge: (3/8)(a + b) + (1/8)(r + a + b - r)
    = (a + b) / 2; vertex: the ring's two phantoms add up to what the rule 3/4, 1/8, 1/8
    needs), and the side's surface is that box spline (checked against the exact evaluator
    in the tests). Point k is ``a`` (b = r = -1) or the phantom ``a + b - r``; a triangle
    where some point cannot be so made is not regular (it is isolated further)."""
    faces = np.asarray(faces, dtype=np.int64)
    out = np.full((len(faces), 3, len(BOX_POINTS)), -1, dtype=np.int64)
    ok = np.zeros(len(faces), dtype=np.bool_)
    _recipes(level.face_offsets, level.face_verts, level.vert_face_offsets, level.vert_faces,
             level.vert_edge_offsets, level.vert_edges, level.edge_verts,
             np.ascontiguousarray(sharp_edge, dtype=np.bool_), faces, _LATTICE, out, ok)
    return ok, out


# lattice constants of _recipes: corners, directions, each corner's leading direction, the
# box points; coordinates reach -3 .. 4 (a phantom's r), offset by _AT_OFF in its table
_LATTICE = (TRI_CORNER.astype(np.int64), LATTICE_DIRS.astype(np.int64),
            TRI_LEAD.astype(np.int64), BOX_POINTS.astype(np.int64))
_AT_OFF = 4


@nb.njit(cache=True)
def _recipes(fo, fv, vfo, vf, veo, ve, ev, sharp, faces, lattice, out, ok):
    """:func:`_boundary_recipes`: per face, the lattice point -> vertex table ``at`` of its
    corners' rings (the whole ring of a smooth valence-6 corner, the triangle's side of a
    regular crease vertex), then each box point from it or as a phantom."""
    corner, dirs, lead_dir, box = lattice
    at = np.empty((2 * _AT_OFF + 2, 2 * _AT_OFF + 2), np.int64)
    fan = np.empty(6, np.int64)
    for m in range(len(faces)):
        f = faces[m]
        at[:] = -1
        good = True
        for k in range(3):
            c = fv[fo[f] + k]
            r0, n = veo[c], veo[c + 1] - veo[c]
            slot = 0
            while vf[vfo[c] + slot] != f:
                slot += 1
            n_cut = 0
            cut0 = cut1 = -1
            for t in range(n):
                if sharp[ve[r0 + t]]:
                    n_cut += 1
                    if cut0 < 0:
                        cut0 = t
                    else:
                        cut1 = t
            if n_cut == 0 and n == 6:  # a smooth regular corner: the whole ring
                n_fan = 6
                for t in range(6):
                    fan[t] = ve[r0 + (slot + t) % n]
                lead = 0
            elif n_cut == 2 and ((n == 4 and cut0 == 0 and cut1 == 3)
                                 or (n == 6 and cut1 - cut0 == 3)):
                # the triangle's side: edges from the sharp one before the face to the next
                s0 = cut0 if cut0 <= slot < cut1 else cut1
                n_fan = 4
                for t in range(4):
                    fan[t] = ve[r0 + (s0 + t) % n]
                lead = (slot - s0) % n
            else:
                good = False
                break
            at[corner[k, 0] + _AT_OFF, corner[k, 1] + _AT_OFF] = c
            for t in range(6):
                mm = lead + t if lead + t < n_fan else lead + t - 6
                if n_fan == 4 and not 0 <= mm < 4:
                    continue  # beyond the crease
                e = fan[mm % 6]
                far = ev[e, 1] if ev[e, 0] == c else ev[e, 0]
                d = (lead_dir[k] + t) % 6
                qi = corner[k, 0] + dirs[d, 0] + _AT_OFF
                qj = corner[k, 1] + dirs[d, 1] + _AT_OFF
                if at[qi, qj] < 0:
                    at[qi, qj] = far
                elif at[qi, qj] != far:
                    good = False  # the ring does not lie on one lattice (not regular)
                    break
            if not good:
                break
        if not good:
            continue
        for i in range(len(box)):
            qi, qj = box[i, 0] + _AT_OFF, box[i, 1] + _AT_OFF
            if at[qi, qj] >= 0:
                out[m, 0, i] = at[qi, qj]
                continue
            found = False
            for d in range(6):
                d1 = (d + 1) % 6
                a = at[qi + dirs[d, 0], qj + dirs[d, 1]]
                b = at[qi + dirs[d1, 0], qj + dirs[d1, 1]]
                r = at[qi + dirs[d, 0] + dirs[d1, 0], qj + dirs[d, 1] + dirs[d1, 1]]
                if a >= 0 and b >= 0 and r >= 0 and _edge_is(veo, ve, ev, a, b, sharp):
                    out[m, 0, i], out[m, 1, i], out[m, 2, i] = a, b, r
                    found = True
                    break
            if not found:
                good = False
                break
        ok[m] = good


@leaf_njit
def _edge_is(veo, ve, ev, a, b, flag):
    """``flag`` of the edge joining vertices a and b (False if there is none)."""
    for k in range(veo[a], veo[a + 1]):
        e = ve[k]
        if ev[e, 0] == b or ev[e, 1] == b:
            return flag[e]
    return False


def _ring_slots():
    """(3, 7) position in ``BOX_POINTS`` of corner k's t-th edge end (t < 6; the evaluator's
    layout, ``_grid12`` of :mod:`subtrace.patches.evaluate`) and of corner k itself (t = 6)."""
    where = {tuple(q): i for i, q in enumerate(BOX_POINTS.tolist())}
    out = np.empty((3, 7), dtype=np.int64)
    for k in range(3):
        for t in range(6):
            q = TRI_CORNER[k] + LATTICE_DIRS[(TRI_LEAD[k] + t) % 6]
            out[k, t] = where[tuple(q.tolist())]
        out[k, 6] = where[tuple(TRI_CORNER[k].tolist())]
    return out


_RING_SLOT = _ring_slots()


@nb.njit(cache=True)
def _box_points(fo, fv, vfo, vf, veo, ve, ev, faces, slot_of, out):
    """The 12 box-spline point ids of each regular triangle of ``faces`` into ``out``: each
    corner's six edge ends, counter-clockwise from the face's own leading edge."""
    for m in range(len(faces)):
        f = faces[m]
        for k in range(3):
            c = fv[fo[f] + k]
            slot = 0
            for a in range(vfo[c], vfo[c + 1]):
                if vf[a] == f:
                    slot = a - vfo[c]
            out[m, slot_of[k, 6]] = c
            for t in range(6):
                e = ve[veo[c] + (slot + t) % 6]
                out[m, slot_of[k, t]] = ev[e, 1] if ev[e, 0] == c else ev[e, 0]
