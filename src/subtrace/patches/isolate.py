"""Grid depths of irregular patches by feature-adaptive isolation.

A patch with an extraordinary (or crease, boundary, ...) corner is not one polynomial, so the
tight Bezier bound of regular patches (:mod:`subtrace.patches.bspline`) does not apply to it
directly. Its conservative depth from the control edges and the subdominant eigenvalue
(:func:`subtrace.patches.table.choose_depths`) overshoots: the eigenvalue governs only the
shrinking corner next to the feature, not the rest of the patch.

:func:`isolated_depths` refines such patches locally, one level at a time, the way
OpenSubdiv's feature-adaptive refinement does: after ``k`` levels, the descendants that are
regular are bicubic patches whose own Bezier bound says how many more levels they need
(``k`` plus that); the irregular ones are refined again, until their own control-edge bound
is within the tolerance at depth 0 (they become single grid cells) or ``k`` reaches the
conservative depth. The patch's depth is the largest need found, never more than the
conservative depth. Its grid is still uniform, so every cell satisfies the criterion.
"""

from __future__ import annotations

import numpy as np

from .bspline import bezier_nets, control_grids, derivative_bounds, hull_boxes, regular_mask


def _levels_needed(bound, dist, tol_rad):
    """Smallest n >= 0 with ``bound * 2^-n <= tol_rad * dist`` (elementwise)."""
    allowed = tol_rad * dist
    with np.errstate(divide="ignore", invalid="ignore"):
        n = np.ceil(np.log2(bound / allowed) - 1e-9)
    n = np.where(bound <= allowed, 0.0, n)
    return np.where(np.isfinite(n), n, 1e9)


def box_distance(bmin, bmax, p):
    q = np.maximum(np.maximum(bmin - p, 0.0), p - bmax)
    return np.sqrt((q * q).sum(axis=1))


def isolated_depths(obj, faces, cap, eye, tol_rad):
    """Depths (len(faces),) int32 of the irregular quads ``faces`` of ``obj``'s patch level,
    none above ``cap`` (their conservative depths, (len(faces),) int)."""
    from .grids import _cut_around
    from ..subdiv.refine import refine_level, refine_points
    from .table import _shells

    faces = np.asarray(faces, dtype=np.int64)
    cap = np.asarray(cap, dtype=np.int64)
    need = np.zeros(len(faces), dtype=np.int64)
    options = obj.cage.options
    # frontier: (root index, face in the current level)
    root = np.nonzero(cap > 0)[0]
    cur, cur_pts, start = obj.level, obj.points, faces[root]
    k = 0
    while len(root):
        cur, cur_pts, start = _cut_around(cur, cur_pts, start, 1)
        ref = refine_level(cur, options)
        cur_pts = refine_points(ref, cur_pts)
        cur = ref.child
        k += 1
        kids = (4 * start[:, None] + np.arange(4)).ravel()
        kid_root = np.repeat(root, 4)
        reg = regular_mask(cur, options, kids)
        if reg.any():
            bez = bezier_nets(cur_pts[control_grids(cur, kids[reg])])
            lo, hi = hull_boxes(bez)
            n = _levels_needed(derivative_bounds(bez), box_distance(lo, hi, eye), tol_rad)
            np.maximum.at(need, kid_root[reg], k + n.astype(np.int64))
        irr = np.nonzero(~reg)[0]
        smin = np.empty((len(irr), 3))
        smax = np.empty((len(irr), 3))
        ebound = np.empty(len(irr))
        valence = np.empty(len(irr), dtype=np.int64)
        _shells(kids[irr], cur.face_offsets, cur.face_verts, cur.vert_face_offsets,
                cur.vert_faces, cur_pts, smin, smax, ebound, valence)
        flat = ebound <= tol_rad * box_distance(smin, smax, eye)
        np.maximum.at(need, kid_root[irr], k)
        go = irr[~flat & (k < cap[kid_root[irr]])]
        root, start = kid_root[go], kids[go]
    return np.minimum(need, cap).astype(np.int32)
