"""Every intersection of many lines with a Catmull-Clark or Loop limit surface, to a given
precision (free-form NURBS surfaces: :mod:`subtrace.lines.nurbs`).

The method of the "Chinese paper" (docs/seeds.md section 1: patch grids, multi-level 1-to-4
segmentation with AABBs of index ranges), with the patch grid replaced by the exact Bezier
net of each patch: a sub-patch is a de Casteljau sub-net made on a stack while a line
descends, so nothing is stored per level and memory does not grow with the precision.

* Items (:mod:`subtrace.lines.kernels`): the regular patches' Bezier nets (bicubic for
  Catmull-Clark; quartic triangular for Loop, :mod:`subtrace.lines.items`); irregular patches
  (an extraordinary vertex, a crease, a boundary) whose shell some line meets are isolated
  into regular Bezier pieces plus *cells* of exact limit points at the feature (bilinear
  quads, or flat triangles), each within ``precision / 2`` of the surface over it:
  Catmull-Clark by :func:`subtrace.patches.isolate.build_isolated`, Loop by
  :func:`subtrace.lines.items.isolate_loop`, down to the depth where every cell's one-ring
  box has a diagonal of at most ``precision / 2`` (proven: the cell's surface and its flat
  stand-in both lie in that hull; Chaikin creases above sharpness 1, which can leave it, are
  given ``config.SHELL_CHAIKIN_MARGIN`` as the shells are); for Loop, triangles along
  boundaries and infinitely sharp creases are regular pieces too (phantom points), and
  so are Catmull-Clark quads there (:mod:`subtrace.patches.bspline`). Only lines'
  candidates are kept, never a refined mesh.
* Depth is set per sub-net by its flatness bound (``tol_flat = precision / 2``, see
  :mod:`subtrace.lines.kernels`); hits are found by Newton on the exact net from the flat
  leaf's triangles (a point within rounding of the surface), or kept from the triangle
  (within ``tol_flat``) where Newton fails or the item is a cell.
* Hits found from several leaves or patches (shared sides and corners) are merged; a line
  that passes within ``precision`` of the surface without crossing it (tangent) gives one hit
  with ``tangent`` True at its closest approach; one that enters and leaves within
  ``precision`` gives one tangent hit; one lying in a flat region gives one tangent hit per
  contact run (the closest point found; every point of the run is as good).
* ``mode="first"`` visits boxes nearest first and stops entering those beyond the first
  crossing found plus the distance within which a later candidate could merge with it.
* A cage's items are kept on the cage for the latest ``CACHED_PRECISIONS`` precisions
  (:func:`subtrace.lines.items.items_for`): a repeated call skips the patch table, the
  Bezier conversion and the isolation done before.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from subtrace.accel.bvh import padded
from subtrace.errors import SubtraceError, SubtraceWarning
from subtrace.lines.items import MAX_ISOLATION, items_for
from subtrace.lines.nurbs import nurbs_line_hits
from subtrace.lines.kernels import (
    C_A, C_B, C_ITEM, C_T, N_FIELDS, lines_task, merge_candidates,
)
from subtrace.nurbs.model import NurbsModel
from subtrace.patches.basis import (
    TRI_MONO, bez_normals, tri_normals,
)
from subtrace.runtime.threads import run_tasks, set_threads, thread_count, usable_threads

# Lines per kernel call: bounds the candidate buffer (CHUNK x cap x 8 doubles).
CHUNK = 4096
# Candidate rows per line at first; lines with more are run again with room for all.
CAP = 16
MODES = ("all", "first")


@dataclass(frozen=True, eq=False)
class Hits:
    """Intersections, one entry per hit, sorted by line then ``t``.

    ``line`` (k,) int64, ``t`` (k,), ``point`` (k,3) (``origin + t * direction``), ``ptex``
    (k,) int32 and ``uv`` (k,2) (``cage.evaluate(ptex, uv)`` is within ``precision`` of
    ``point``), ``normal`` (k,3) unit limit normal (ptex orientation), ``tangent`` (k,) bool.
    ``stats``: items (patches and isolated pieces), items entered and leaves reached per line.
    """

    line: np.ndarray
    t: np.ndarray
    point: np.ndarray
    ptex: np.ndarray
    uv: np.ndarray
    normal: np.ndarray
    tangent: np.ndarray
    n_lines: int
    precision: float
    stats: dict

    def __len__(self) -> int:
        return len(self.t)

    def of_line(self, i: int) -> np.ndarray:
        """Indices of line ``i``'s hits."""
        a, b = np.searchsorted(self.line, [i, i + 1])
        return np.arange(a, b)


def _as_lines(a, name):
    try:
        arr = np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise SubtraceError(f"{name}: expected numbers, (n,3): {exc}") from None
    if arr.ndim == 1 and arr.shape[0] == 3:
        arr = arr[None]
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise SubtraceError(f"{name}: expected an array of shape (n,3), got {arr.shape}")
    if not np.isfinite(arr).all():
        raise SubtraceError(f"{name}: every component must be finite")
    return np.ascontiguousarray(arr)


def intersect_lines(cage, origins, directions, precision, t_range=(0.0, math.inf),
                    mode="all", threads=None) -> Hits:
    """Every intersection of the lines ``origins + t * directions`` (t in ``t_range``) with
    the limit surface of ``cage`` (Catmull-Clark or Loop), to ``precision`` (model units): each
    ``point`` lies within ``precision`` of the surface and of ``cage.evaluate(ptex, uv)``.
    ``mode="first"`` keeps each line's nearest hit. ``threads``: worker threads (default all
    cores). See the module doc for tangent lines and flat regions. Returns :class:`Hits`."""
    nurbs = isinstance(cage, NurbsModel)
    if not nurbs and getattr(cage, "scheme", None) not in ("catmark", "loop"):
        raise SubtraceError("intersect_lines: expected a Catmull-Clark or Loop cage "
                            "(subtrace.load_cage / make_cage) or free-form surfaces "
                            "(subtrace.nurbs.model.load_model)")
    org = _as_lines(origins, "origins")
    dirs = _as_lines(directions, "directions")
    if len(org) != len(dirs):
        raise SubtraceError(f"origins and directions differ in length: {len(org)} vs {len(dirs)}")
    if (np.abs(dirs).sum(axis=1) == 0).any():
        raise SubtraceError("directions: every direction must be non-zero")
    try:
        precision = float(precision)
    except (TypeError, ValueError):
        raise SubtraceError(f"precision: expected a number > 0, got {precision!r}") from None
    if not (precision > 0 and math.isfinite(precision)):
        raise SubtraceError(f"precision: expected a finite number > 0, got {precision!r}")
    try:
        t_lo, t_hi = (float(x) for x in t_range)
    except (TypeError, ValueError):
        raise SubtraceError(f"t_range: expected (t_min, t_max), got {t_range!r}") from None
    if not t_lo < t_hi or math.isnan(t_lo) or math.isnan(t_hi):
        raise SubtraceError(f"t_range: expected t_min < t_max, got {t_range!r}")
    if mode not in MODES:
        raise SubtraceError(f"mode: expected one of {', '.join(MODES)}, got {mode!r}")
    if nurbs:
        return _nurbs_hits(cage, org, dirs, precision, t_lo, t_hi, mode, threads)

    items = items_for(cage, precision)
    tol_flat = 0.5 * precision
    touch_tol = precision
    scale = float(np.abs(items.table.shell_max).max(initial=1.0)
                  + np.abs(items.table.shell_min).max(initial=0.0))
    floor = 64 * np.finfo(float).eps * scale
    res_tol = max(1e-3 * precision, floor)
    if precision < floor:
        warnings.warn(SubtraceWarning(
            f"precision {precision:g} is below what double precision resolves for this cage "
            f"(about {floor:.3g} at its scale {scale:.3g}): hits are as exact as floating "
            "point allows, not within the precision asked"), stacklevel=2)
    n_lines = len(org)
    dlen = np.linalg.norm(dirs, axis=1)
    out_rows, out_tan, out_line = [], [], []
    entered = leaves = 0
    threads = usable_threads(threads)
    old = thread_count() if threads is not None else None
    if threads is not None:
        set_threads(threads)
    try:
        for a in range(0, n_lines, CHUNK):
            b = min(a + CHUNK, n_lines)
            o, d = org[a:b], dirs[a:b]
            items.need(o, d, t_lo, t_hi, touch_tol)
            if items.bvh is None:
                break
            bv = items.bvh
            cap = CAP
            sel = np.arange(b - a)
            while len(sel):
                oo, dd = np.ascontiguousarray(o[sel]), np.ascontiguousarray(d[sel])
                cand = np.empty((len(sel), cap, N_FIELDS))
                count = np.empty(len(sel), np.int64)
                stats = np.empty((len(sel), 2), np.int64)
                run_tasks(lines_task, oo, dd, t_lo, t_hi, items.all_nets, items.all_tnets,
                          items.all_exact,
                          items.item_min - touch_tol, items.item_max + touch_tol,
                          padded(bv, touch_tol), tol_flat, touch_tol, res_tol,
                          mode == "first", cap, cand, count, stats)
                over = count > cap
                done = ~over
                keep = np.zeros((len(sel), cap), bool)
                tan = np.zeros((len(sel), cap), bool)
                merge_candidates(cand, count, dlen[a:b][sel], precision, keep, tan,
                                 items.all_ptex)
                rows_valid = np.arange(cap)[None, :] < np.minimum(count, cap)[:, None]
                k = keep & rows_valid & done[:, None]
                li, ci = np.nonzero(k)
                out_rows.append(cand[li, ci])
                out_tan.append(tan[li, ci])
                out_line.append(a + sel[li])
                entered += int(stats[done, 0].sum())
                leaves += int(stats[done, 1].sum())
                cap = int(count[over].max(initial=0)) + 1
                sel = sel[over]
    finally:
        if threads is not None:
            set_threads(old)
    if items.capped:
        warnings.warn(SubtraceWarning(
            f"precision {precision:g}: some irregular patches stopped at {MAX_ISOLATION} "
            "levels of isolation, where their cells are still coarser than the precision; "
            "hits there are within the cells' bound, not the precision"), stacklevel=2)
    return _hits(items, org, dirs, out_rows, out_tan, out_line, mode, n_lines, precision,
                 dict(items=len(items.all_exact), items_entered=entered, leaves=leaves))


def _nurbs_hits(model, org, dirs, precision, t_lo, t_hi, mode, threads) -> Hits:
    """:func:`intersect_lines` for free-form surfaces (:mod:`subtrace.lines.nurbs`): ``ptex``
    is the surface index and ``uv`` its parameters; ``tangent`` is always False."""
    old = thread_count() if threads is not None else None
    if threads is not None:
        set_threads(threads)
    try:
        line, t, point, surface, uv, normal = nurbs_line_hits(model, org, dirs, precision, t_lo,
                                                              t_hi, mode == "first")
    finally:
        if threads is not None:
            set_threads(old)
    return Hits(line=line, t=t, point=point, ptex=surface, uv=uv, normal=normal,
                tangent=np.zeros(len(t), bool), n_lines=len(org), precision=precision,
                stats={"items": model.n_patches})


def _hits(items, org, dirs, rows, tans, lines, mode, n_lines, precision, stats) -> Hits:
    rows = np.concatenate(rows) if rows else np.zeros((0, 8))
    tan = np.concatenate(tans) if tans else np.zeros(0, bool)
    line = np.concatenate(lines).astype(np.int64) if lines else np.zeros(0, np.int64)
    order = np.lexsort((rows[:, C_T], line))
    rows, tan, line = rows[order], tan[order], line[order]
    if mode == "first" and len(line):
        first = np.r_[True, line[1:] != line[:-1]]
        rows, tan, line = rows[first], tan[first], line[first]
    t = rows[:, C_T].copy()
    item = rows[:, C_ITEM].astype(np.int64)
    ab = rows[:, [C_A, C_B]]
    uv = items.all_uv0[item] + items.all_scale[item, None] * ab
    point = org[line] + t[:, None] * dirs[line]
    normal = np.empty((len(item), 3))
    quad = item < len(items.all_nets)
    # unit limit normals from the nets, at the parameters clipped onto the item
    nrm = np.empty((int(quad.sum()), 3))
    bez_normals(items.all_nets, item[quad], np.clip(ab[quad], 0.0, 1.0), nrm)
    normal[quad] = nrm
    if not quad.all():
        st = np.maximum(ab[~quad], 0.0)
        st -= np.maximum(st.sum(axis=1) - 1.0, 0.0)[:, None] / 2
        nrm = np.empty((len(st), 3))
        tri_normals(items.all_tnets, item[~quad] - len(items.all_nets), st, TRI_MONO, nrm)
        normal[~quad] = nrm
    cell = np.nonzero(~items.all_exact[item])[0]
    if len(cell):
        # a cell is a flat stand-in: the limit normal from the exact evaluator instead
        cage = items.table.objects[0].cage
        _, du, dv = cage.evaluate(items.all_ptex[item[cell]],
                                  np.clip(uv[cell], 0.0, 1.0))
        n = np.cross(du, dv)
        ln = np.linalg.norm(n, axis=1)
        ok = ln > 0
        normal[cell[ok]] = n[ok] / ln[ok, None]
    return Hits(line=line, t=t, point=point, ptex=items.all_ptex[item].astype(np.int32),
                uv=uv, normal=normal, tangent=tan.astype(bool), n_lines=n_lines,
                precision=precision, stats=stats)
