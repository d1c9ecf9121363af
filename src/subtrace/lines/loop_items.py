"""Loop cages as line-query items: quartic triangular Bezier nets
(:mod:`subtrace.lines.tri_nets`).

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

from subtrace.runtime.jit import nb

from subtrace.patches.evaluate import (
    _BOX_COEF, _BOX_MONO, _BOX_POINTS, _LATTICE_DIRS, _TRI_CORNER, _TRI_LEAD,
)
from subtrace.subdiv.creases import F_INF
from subtrace.subdiv.limit import _CREASE, _SMOOTH, classify, limit_points
from subtrace.lines.tri_nets import CHILD_ORIGIN, CHILD_SCALE, TRI_JK, TRI_MONO, TRI_PARAMS, bernstein

# Bezier net (15) from the 12 box-spline points: the box spline's polynomial at the domain
# points, fitted in the Bernstein basis
_box_at = (TRI_PARAMS[:, 0:1] ** _BOX_MONO[:, 0]
           * TRI_PARAMS[:, 1:2] ** _BOX_MONO[:, 1]) @ _BOX_COEF
BOX_TO_TRI = np.ascontiguousarray(np.linalg.solve(bernstein(TRI_PARAMS), _box_at))
# a flat triangle of corners A (0,0), B (1,0), C (0,1) as a quartic net: L(j/4, k/4)
FLAT_TO_TRI = np.ascontiguousarray(np.stack(
    [1.0 - TRI_PARAMS.sum(axis=1), TRI_PARAMS[:, 0], TRI_PARAMS[:, 1]], axis=1))

REGULAR_VALENCE = 6


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
    inner = ((cls[corners] == _SMOOTH) & (n_edges == REGULAR_VALENCE)
             & (n_faces == REGULAR_VALENCE))
    ok = tri & inner.all(axis=1) & ~level.face_hole[faces]
    # crease vertices (a boundary, or an infinitely sharp crease): _boundary_recipe decides
    border = (cls[corners] == _CREASE) & level.vert_manifold[corners]
    maybe = np.nonzero(tri & ~ok & (inner | border).all(axis=1) & border.any(axis=1)
                       & ~level.face_hole[faces])[0]
    if len(maybe):
        sharp = level.edge_sharpness >= F_INF
        for i in maybe:
            ok[i] = _boundary_recipe(level, int(faces[i]), sharp) is not None
    return ok


def box_nets(level, points, faces) -> np.ndarray:
    """(m,15,3) triangular Bezier nets of the regular triangles ``faces`` of ``level``."""
    faces = np.asarray(faces, dtype=np.int64)
    fo = level.face_offsets
    corners = level.face_verts[fo[faces][:, None] + np.arange(3)]
    sharp = level.edge_sharpness >= F_INF
    on_crease = np.zeros(level.n_verts, dtype=bool)
    on_crease[level.edge_verts[sharp].ravel()] = True
    inner = ~on_crease[corners].any(axis=1)  # else a crease corner: phantom points
    X = np.empty((len(faces), len(_BOX_POINTS), 3))
    rows = np.nonzero(inner)[0]
    ids = np.empty((len(rows), len(_BOX_POINTS)), dtype=np.int64)
    _box_points(level.face_offsets, level.face_verts, level.vert_face_offsets, level.vert_faces,
                level.vert_edge_offsets, level.vert_edges, level.edge_verts,
                faces[rows], _RING_SLOT, ids)
    X[rows] = points[ids]
    for i in np.nonzero(~inner)[0]:
        a, b, r = _boundary_recipe(level, int(faces[i]), sharp)
        X[i] = points[a] + np.where(b[:, None] >= 0, points[b] - points[r], 0.0)
    return np.ascontiguousarray(np.matmul(BOX_TO_TRI, X))


def _boundary_recipe(level, f, sharp_edge):
    """The 12 box-spline points of triangle ``f`` with corners on a boundary or an
    infinitely sharp crease, or None.

    A *regular crease vertex* has 3 faces on the triangle's side, between its two sharp
    edges (a boundary vertex of 4 edges, or an interior one of 6 whose sharp edges are
    opposite), and no other sharp edge. The lattice points beyond the crease are replaced by
    the *phantom* points that mirror the triangle's side across a sharp edge (a, b):
    ``a + b - r``, r the lattice point across (a, b) from it, so that the box spline's
    smooth rules reproduce the crease rules there (edge: (3/8)(a + b) + (1/8)(r + a + b - r)
    = (a + b) / 2; vertex: the ring's two phantoms add up to what the rule 3/4, 1/8, 1/8
    needs), and the side's surface is that box spline (checked against the exact evaluator
    in the tests). Returns ``(a, b, r)`` (12,) int64 each, the point ``a`` (b = r = -1) or
    the phantom ``a + b - r``; None where some point cannot be so made (the triangle is
    then isolated further)."""
    fo, fv = level.face_offsets, level.face_verts
    ve, veo = level.vert_edges, level.vert_edge_offsets
    vf, vfo = level.vert_faces, level.vert_face_offsets
    ev = level.edge_verts
    at = {}
    for k in range(3):
        c = int(fv[fo[f] + k])
        ring = ve[veo[c]:veo[c + 1]]
        n = len(ring)
        slot = int(np.nonzero(vf[vfo[c]:vfo[c + 1]] == f)[0][0])
        cut = np.nonzero(sharp_edge[ring])[0]
        if len(cut) == 0 and n == 6:
            fan = np.roll(ring, -slot)  # a smooth regular corner: the whole ring
            lead = 0
        elif len(cut) == 2 and (n == 4 and list(cut) == [0, 3] or n == 6 and cut[1] - cut[0] == 3):
            # the triangle's side: edges from the sharp one before the face to the next
            s0 = cut[0] if cut[0] <= slot < cut[1] else cut[1]
            fan = np.roll(ring, -s0)[:4]
            lead = (slot - s0) % n
        else:
            return None
        at[tuple(_TRI_CORNER[k])] = c
        for t in range(6):
            m = lead + t if lead + t < len(fan) else lead + t - 6
            if len(fan) == 4 and not 0 <= m < 4:
                continue  # beyond the crease
            e = fan[m % 6]
            far = int(ev[e, 1] if ev[e, 0] == c else ev[e, 0])
            q = tuple(_TRI_CORNER[k] + _LATTICE_DIRS[(_TRI_LEAD[k] + t) % 6])
            if at.setdefault(q, far) != far:
                return None  # the ring does not lie on one lattice (not regular)
    out = np.full((3, len(_BOX_POINTS)), -1, dtype=np.int64)
    for i, q in enumerate(_BOX_POINTS.tolist()):
        if tuple(q) in at:
            out[0, i] = at[tuple(q)]
            continue
        for d in range(6):
            a = tuple(np.add(q, _LATTICE_DIRS[d]))
            b = tuple(np.add(q, _LATTICE_DIRS[(d + 1) % 6]))
            r = tuple(np.add(a, _LATTICE_DIRS[(d + 1) % 6]))
            if a in at and b in at and r in at and _edge_is(level, at[a], at[b], sharp_edge):
                out[:, i] = at[a], at[b], at[r]
                break
        else:
            return None
    return out[0], out[1], out[2]


def _edge_is(level, a, b, flag):
    """``flag`` of the edge joining vertices a and b (False if there is none)."""
    for e in level.vert_edges[level.vert_edge_offsets[a]:level.vert_edge_offsets[a + 1]]:
        if b in level.edge_verts[e]:
            return bool(flag[e])
    return False


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
    from subtrace.patches.isolate import _children
    from subtrace.patches.table import one_ring_shells

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
                    np.matmul(FLAT_TO_TRI, P), False)
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
