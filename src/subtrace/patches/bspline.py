"""Regular Catmull-Clark patches as bicubic B-splines: which faces are, and their control grids.

A quad of the patch level whose four corners are smooth, valence 4 and crease-free is a
uniform bicubic B-spline patch of the 16 points around it (the same test and the same
control grid as the exact evaluator, :mod:`subtrace.patches.evaluate`). For such a patch:

* :func:`control_grids` gathers the 16 point ids, ``[u index][v index]``, with ``u`` running
  from corner 0 to corner 1 and ``v`` from corner 0 to corner 3 (the grid layout of
  :mod:`subtrace.patches.grids`);
* :func:`subtrace.patches.basis.bezier_nets` converts them to the patch's bicubic Bezier
  control net. The patch lies in the net's convex hull, so the net's box is a containing
  shell much tighter than the box of the 16 B-spline points (design invariant 2), and the
  partial derivatives are Bezier patches with control points ``3 (b[i+1, j] - b[i, j])``
  (resp. ``j``), so :func:`~subtrace.patches.basis.net_bounds` gives the box and a bound on
  ``|dP/du|`` and ``|dP/dv|`` over the whole patch: a grid cell at depth ``n`` has sides no
  longer than ``bound * 2^-n`` (the refinement criterion, design invariant 3).

The renderer evaluates the nets themselves (``trace/bezier.py``).
"""

from __future__ import annotations

import numpy as np

from subtrace.patches.basis import B_CORNER, LEAD, TRAIL
from subtrace.runtime.jit import nb
from subtrace.runtime.threads import run_tasks
from subtrace.subdiv.limit import SMOOTH, classify


def regular_mask(level, options, faces) -> np.ndarray:
    """(len(faces),) bool: the faces of ``level`` that are regular bicubic patches."""
    faces = np.asarray(faces, dtype=np.int64)
    if options.scheme != "catmark" or len(faces) == 0:
        return np.zeros(len(faces), dtype=bool)
    fo = level.face_offsets
    quad = (fo[faces + 1] - fo[faces]) == 4
    corners = level.face_verts[np.minimum(fo[faces][:, None] + np.arange(4), len(level.face_verts) - 1)]
    cls = classify(level, options, corners)
    ok = (cls[corners] == SMOOTH) & (np.diff(level.vert_edge_offsets)[corners] == 4)
    return quad & ok.all(axis=1)


def control_grids(level, faces) -> np.ndarray:
    """(m, 4, 4) int64 point ids of the control grids of regular quads ``faces``."""
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    out = np.empty((len(faces), 4, 4), dtype=np.int64)
    run_tasks(
        _control_grids, level.face_offsets, level.face_verts, level.vert_face_offsets,
        level.vert_faces, level.vert_face_corner, level.vert_edge_offsets, level.vert_edges,
        level.edge_verts, faces, B_CORNER, LEAD, TRAIL, out,
        n=None if len(faces) >= _GRID_PARALLEL_MIN else 1,
    )
    return out


_GRID_BLOCK = 256  # faces a task gathers at a time
_GRID_PARALLEL_MIN = 8 * _GRID_BLOCK  # fewer faces than this: one thread


@nb.njit(cache=True, nogil=True)
def _control_grids(task, n_tasks, fo, fv, vfo, vf, vfc, veo, ve, ev, faces, bc, lead, trail,
                   out):
    """Task ``task`` of ``n_tasks`` (tasks.run_tasks): blocks of _GRID_BLOCK faces, every
    n_tasks-th."""
    dirs = np.empty((4, 2), dtype=np.int64)
    for b0 in range(task * _GRID_BLOCK, len(faces), n_tasks * _GRID_BLOCK):
        for m in range(b0, min(b0 + _GRID_BLOCK, len(faces))):
            f = faces[m]
            for i in range(4):
                c = fv[fo[f] + i]
                x0, y0 = bc[i, 0], bc[i, 1]
                out[m, x0, y0] = c
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
                    out[m, x1 + dirs[k, 0], y1 + dirs[k, 1]] = diag
                    if k >= 2:
                        e = ve[veo[c] + j]
                        other = ev[e, 1] if ev[e, 0] == c else ev[e, 0]
                        out[m, x1, y1] = other
