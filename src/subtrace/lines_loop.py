"""Loop cages as line-query items: quartic triangular Bezier nets (:mod:`subtrace.trace.lines_loop`).

A Loop patch is a triangle of the cage. It is *regular* when its three corners are smooth,
of valence 6 and crease-free (the exact evaluator's test, :mod:`subtrace.patches.evaluate`):
its limit surface is then the quartic box spline of the 12 points around it, which is one
quartic polynomial, converted here to its 15-point triangular Bezier net (``BOX_TO_TRI``).

Any other patch (an extraordinary vertex, a crease, a boundary, a semi-sharp feature) is
*isolated* as OpenSubdiv's feature-adaptive refinement does, only for the patches whose shell
a line meets: the faces around it are refined one level at a time (locally, with the
subdivision core itself, so every rule is honoured); the children that are regular become
Bezier items; the others are refined again until the box of their one-ring control points
has a diagonal of at most ``allowed``. Such a *cell* becomes a flat item, the triangle of
its corners' exact limit points: the cell's limit surface lies in the convex hull of its
one-ring points (non-negative masks), and so does that triangle, so every point of the
triangle lies within the box diagonal of the surface over the cell and of every point of it
(a proven bound, not a measured one). Near an extraordinary vertex the one-ring shrinks by
the subdominant eigenvalue per level, so a cell is reached after a few levels; along a
boundary or a crease it shrinks by 1/2 per level and the cells there number about
``edge length / allowed`` per edge of a patch a line meets.

Item parameters: an item covers the triangle ``uv0 + scale * (s, t)`` (``s, t >= 0``,
``s + t <= 1``) of its ptex face, ``scale`` negative for a turned (middle) child.
"""

from __future__ import annotations

import numpy as np

import numba as nb

from .patches.evaluate import _BOX_COEF, _BOX_MONO, _BOX_POINTS, _LATTICE_DIRS, _TRI_CORNER, _TRI_LEAD
from .subdiv.limit import _SMOOTH, classify, limit_points
from .trace.lines_loop import CHILD_ORIGIN, CHILD_SCALE, TRI_JK, TRI_MONO, TRI_PARAMS, bernstein

# Bezier net (15) from the 12 box-spline points: the box spline's polynomial at the domain
# points, fitted in the Bernstein basis
_box_at = (TRI_PARAMS[:, 0:1] ** _BOX_MONO[:, 0] * TRI_PARAMS[:, 1:2] ** _BOX_MONO[:, 1]) @ _BOX_COEF
BOX_TO_TRI = np.ascontiguousarray(np.linalg.solve(bernstein(TRI_PARAMS), _box_at))
# a flat triangle of corners A (0,0), B (1,0), C (0,1) as a quartic net: L(j/4, k/4)
FLAT_TO_TRI = np.ascontiguousarray(np.stack(
    [1.0 - TRI_PARAMS.sum(axis=1), TRI_PARAMS[:, 0], TRI_PARAMS[:, 1]], axis=1))

REGULAR_VALENCE = 6


def loop_regular(level, options, faces) -> np.ndarray:
    """(len(faces),) bool: the triangles of ``level`` that are regular quartic box splines."""
    faces = np.asarray(faces, dtype=np.int64)
    if len(faces) == 0:
        return np.zeros(0, dtype=bool)
    fo = level.face_offsets
    tri = (fo[faces + 1] - fo[faces]) == 3
    corners = level.face_verts[np.minimum(fo[faces][:, None] + np.arange(3),
                                          len(level.face_verts) - 1)]
    cls = classify(level, options, corners)
    ok = ((cls[corners] == _SMOOTH)
          & (np.diff(level.vert_edge_offsets)[corners] == REGULAR_VALENCE)
          & (np.diff(level.vert_face_offsets)[corners] == REGULAR_VALENCE))
    return tri & ok.all(axis=1) & ~level.face_hole[faces]


def box_nets(level, points, faces) -> np.ndarray:
    """(m,15,3) triangular Bezier nets of the regular triangles ``faces`` of ``level``."""
    ids = np.empty((len(faces), len(_BOX_POINTS)), dtype=np.int64)
    _box_points(level.face_offsets, level.face_verts, level.vert_face_offsets, level.vert_faces,
                level.vert_edge_offsets, level.vert_edges, level.edge_verts,
                np.asarray(faces, dtype=np.int64), _RING_SLOT, ids)
    return np.ascontiguousarray(np.einsum("pk,mkx->mpx", BOX_TO_TRI, points[ids]))


def _ring_slots():
    """(3, 7) position in ``_BOX_POINTS`` of corner k's t-th edge end (t < 6; the evaluator's
    layout, :func:`subtrace.patches.evaluate._grid12`) and of corner k itself (t = 6)."""
    where = {tuple(q): i for i, q in enumerate(_BOX_POINTS.tolist())}
    out = np.empty((3, 7), dtype=np.int64)
    for k in range(3):
        for t in range(6):
            q = _TRI_CORNER[k] + _LATTICE_DIRS[(_TRI_LEAD[k] + t) % 6]
            out[k, t] = where[tuple(q.tolist())]
        out[k, 6] = where[tuple(_TRI_CORNER[k].tolist())]
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


def isolate_loop(obj, faces, allowed, max_level):
    """Items of the irregular Loop patches ``faces`` of ``obj``'s patch level (the cage):
    ``(root (n,), uv0 (n,2), scale (n,), nets (n,15,3), exact (n,) bool)``, ``root``
    indexing ``faces``, ``uv0``/``scale`` in the patch's parameters (module doc). Cells are
    left at ``max_level`` whatever their size (a measured stop, never reached in practice)."""
    from .patches.isolate import _children
    from .patches.table import one_ring_shells

    options = obj.cage.options
    out = [[], [], [], [], []]
    cur, pts = obj.level, obj.points
    root = np.arange(len(faces))
    start = np.asarray(faces, dtype=np.int64)
    org = np.zeros((len(faces), 2))
    scale = np.ones(len(faces))
    level = 0
    while len(root):
        lo, hi, _, _ = one_ring_shells(cur, start, pts)
        small = (np.linalg.norm(hi - lo, axis=1) <= allowed) | (level >= max_level)
        if small.any():
            # cells: the flat triangles of their corners' exact limit points
            fo = cur.face_offsets
            corners = cur.face_verts[fo[start[small]][:, None] + np.arange(3)]
            P = limit_points(cur, pts, options, which=corners.ravel())[0].reshape(-1, 3, 3)
            _append(out, root[small], org[small], scale[small],
                    np.einsum("pc,mcx->mpx", FLAT_TO_TRI, P), False)
        keep = ~small
        if not keep.any():
            break
        root, org, scale = root[keep], org[keep], scale[keep]
        cur, pts, kids, _ = _children(cur, pts, start[keep], options)
        # children c = 0..3 of each frontier face (Loop's order), in the patch's parameters
        root = np.repeat(root, 4)
        org = (org[:, None, :] + scale[:, None, None] * CHILD_ORIGIN[None]).reshape(-1, 2)
        scale = (scale[:, None] * CHILD_SCALE[None]).ravel()
        reg = loop_regular(cur, options, kids)
        if reg.any():
            _append(out, root[reg], org[reg], scale[reg], box_nets(cur, pts, kids[reg]), True)
        root, org, scale, start = root[~reg], org[~reg], scale[~reg], kids[~reg]
        level += 1
    if not out[0]:
        return (np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros(0), np.zeros((0, 15, 3)),
                np.zeros(0, bool))
    return tuple(np.concatenate(a) for a in out)


def _append(out, root, org, scale, nets, exact):
    for lst, a in zip(out, (root, org, scale, nets, np.full(len(root), exact))):
        lst.append(a)


def tri_normals(nets, rows, st):
    """Unit normals (m,3) of triangle nets ``nets[rows]`` at item parameters ``st`` (m,2)
    (orientation of the ptex (u, v)); where they vanish (an extraordinary corner), the
    normal a little inside."""
    out = np.full((len(rows), 3), np.nan)
    todo = np.arange(len(rows))
    j, k = TRI_JK[:, 0], TRI_JK[:, 1]
    for step in (0.0, 1e-6, 1e-4):
        if not len(todo):
            break
        s = np.clip(st[todo, 0], step, 1.0)
        t = np.clip(st[todo, 1], step, 1.0)
        over = np.maximum(s + t - (1.0 - step), 0.0) / 2
        s, t = (s - over)[:, None], (t - over)[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            ds = np.where(j > 0, j * s ** np.maximum(j - 1, 0) * t ** k, 0.0)
            dt = np.where(k > 0, k * s ** j * t ** np.maximum(k - 1, 0), 0.0)
        mono = np.einsum("mp,npx->nmx", TRI_MONO, nets[rows[todo]])
        n = np.cross(np.einsum("nm,nmx->nx", ds, mono), np.einsum("nm,nmx->nx", dt, mono))
        ln = np.linalg.norm(n, axis=1)
        ok = ln > 0
        out[todo[ok]] = n[ok] / ln[ok, None]
        todo = todo[~ok]
    return out
