"""Every intersection of many lines with trimmed NURBS surfaces, to a given precision.

The per-ray refinement of :mod:`subtrace.nurbs.trace` with the line kernels' stopping rule:
a line walks the BVH over the patches' shells over its whole parameter range; inside a
patch the sub-patches it enters are halved until their projected control points lie within
``precision / 2`` of the bilinear interpolant of their corners (so distinct crossings
farther apart than the precision fall in distinct leaves), and each leaf's root is found
by Newton's method on the rational surface (exact to rounding), kept when the trim keeps
it (:func:`subtrace.nurbs.trace.line_roots_task`). Roots found from several leaves or
patches (near shared sides) are merged when within ``precision`` of each other. A line
tangent to a surface, where Newton's method has no regular root, gives no hit.

:func:`nurbs_line_hits` returns flat arrays (line, t, point, surface, uv, normal), which
:func:`subtrace.lines.api.intersect_lines` wraps into its ``Hits``.
"""

from __future__ import annotations

import numpy as np

from subtrace.nurbs.trace import hit_geometry, line_roots_task, patch_bvh, trim_arrays
from subtrace.runtime.threads import run_tasks

CHUNK = 4096  # lines per kernel call
CAP = 16  # roots per line at first; lines with more are run again with room for all


def _roots(model, bvh, o, d, tlo, thi, tol_flat):
    """(line (k,), t (k,), patch (k,), st (k, 2)) of every root of the lines (o, unit d)."""
    tables = (model.surface_trim, model.surface_trim_invert, trim_arrays(model))
    lines, rows = [], []
    cap = CAP
    sel = np.arange(len(o))
    while len(sel):
        out = np.empty((len(sel), cap, 4))
        count = np.empty(len(sel), np.int64)
        run_tasks(line_roots_task, np.ascontiguousarray(o[sel]), np.ascontiguousarray(d[sel]),
                  tlo, thi, bvh, model.nets, model.patch_degree, model.patch_rect,
                  model.patch_surface, tol_flat, tables, out, count)
        done = count <= cap
        li, ci = np.nonzero(np.arange(cap)[None, :] < np.where(done, count, 0)[:, None])
        lines.append(sel[li])
        rows.append(out[li, ci])
        cap = int(count[~done].max(initial=0)) + 1
        sel = sel[~done]
    rows = np.concatenate(rows) if rows else np.zeros((0, 4))
    return (np.concatenate(lines) if lines else np.zeros(0, np.int64), rows[:, 0],
            rows[:, 1].astype(np.int64), rows[:, 2:4])


def _merge(line, t, point, precision):
    """Mask of the roots kept: sorted by (line, t), a root within ``precision`` of the
    previous kept one of its line is the same crossing found twice."""
    keep = np.ones(len(t), dtype=bool)
    last = -1
    for k in range(len(t)):
        if last >= 0 and line[k] == line[last] and \
                np.linalg.norm(point[k] - point[last]) <= precision:
            keep[k] = False
        else:
            last = k
    return keep


def nurbs_line_hits(model, origins, directions, precision, t_lo, t_hi, first):
    """Every hit of the lines ``origins + t directions`` (t in [t_lo, t_hi]) with the
    surfaces of ``model`` (a :class:`subtrace.nurbs.model.NurbsModel`), to ``precision``:
    (line (k,), t (k,), point (k, 3), surface (k,), uv (k, 2), normal (k, 3)), sorted by
    line then t; ``first``: each line's nearest only. Inputs already checked."""
    bvh = patch_bvh(model)
    dlen = np.linalg.norm(directions, axis=1)
    unit = directions / dlen[:, None]
    parts = []
    for a in range(0, len(origins), CHUNK):
        b = min(a + CHUNK, len(origins))
        # the kernel's parameter is the distance along the unit direction: scale the range
        # per line by |d| (each chunk runs with the widest range; roots outside are dropped)
        scale = dlen[a:b]
        lo = np.where(np.isfinite(t_lo), t_lo * scale, t_lo)
        hi = np.where(np.isfinite(t_hi), t_hi * scale, t_hi)
        line, dist, patch, st = _roots(model, bvh, origins[a:b], unit[a:b], float(lo.min()),
                                       float(hi.max()), 0.5 * precision)
        inside = (dist >= lo[line]) & (dist <= hi[line])
        parts.append((line[inside] + a, dist[inside] / scale[line[inside]], patch[inside],
                      st[inside]))
    line = np.concatenate([p[0] for p in parts]).astype(np.int64)
    t = np.concatenate([p[1] for p in parts])
    patch = np.concatenate([p[2] for p in parts])
    st = np.concatenate([p[3] for p in parts]).reshape(-1, 2)
    order = np.lexsort((t, line))
    line, t, patch, st = line[order], t[order], patch[order], st[order]
    point = origins[line] + t[:, None] * directions[line]
    keep = _merge(line, t, point, precision)
    if first and len(line):
        keep &= np.r_[True, line[1:] != line[:-1]]  # (the first root of a line is kept)
    line, t, patch, st, point = line[keep], t[keep], patch[keep], st[keep], point[keep]
    _, normal, uv = hit_geometry(model, patch, st)
    return line, t, point, model.patch_surface[patch].astype(np.int32), uv, normal
