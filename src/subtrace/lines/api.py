"""Every intersection of many lines with a Catmull-Clark or Loop limit surface, to a given
precision.

The method of the "Chinese paper" (docs/seeds.md section 1: patch grids, multi-level 1-to-4
segmentation with AABBs of index ranges), with the patch grid replaced by the exact Bezier
net of each patch: a sub-patch is a de Casteljau sub-net made on a stack while a line
descends, so nothing is stored per level and memory does not grow with the precision.

* Items (:mod:`subtrace.lines.kernels`): the regular patches' Bezier nets (bicubic for
  Catmull-Clark; quartic triangular for Loop, :mod:`subtrace.lines.loop_items`); irregular patches
  (an extraordinary vertex, a crease, a boundary) whose shell some line meets are isolated
  into regular Bezier pieces plus *cells* of exact limit points at the feature (bilinear
  quads, or flat triangles), each within ``precision / 2`` of the surface over it:
  Catmull-Clark by :func:`subtrace.patches.isolate.build_isolated`, Loop by
  :func:`subtrace.lines.loop_items.isolate_loop`, down to the depth where every cell's one-ring
  box has a diagonal of at most ``precision / 2`` (proven: the cell's surface and its flat
  stand-in both lie in that hull; Chaikin creases above sharpness 1, which can leave it, are
  given ``config.SHELL_CHAIKIN_MARGIN`` as the shells are); for Loop, triangles along
  boundaries and infinitely sharp creases are regular pieces too (phantom points). (For
  Catmull-Clark, cells touching the mesh's boundary keep a measured bound: see
  ``_Items._isolate``.) Only lines' candidates are kept, never a refined
  mesh.
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
  (:func:`_items_for`): a repeated call skips the patch table, the Bezier conversion and the
  isolation done before.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from subtrace.errors import SubtraceError

# Lines per kernel call: bounds the candidate buffer (CHUNK x cap x 8 doubles).
CHUNK = 4096
# Candidate rows per line at first; lines with more are run again with room for all.
CAP = 16
# A Catmull-Clark patch's isolation depth is first guessed from IRREGULAR_MARGIN x its
# control-edge bound (as patches/isolate.py; measured, not proven, at extraordinary
# vertices), then deepened until every cell's proven bound holds; deepest level:
IRREGULAR_MARGIN = 1.25
MAX_ISOLATION = 40
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


class _Base:
    """What a cage's line queries share whatever the precision (kept on the cage, see
    :func:`_items_for`): the patch table and the regular patches' Bezier nets."""

    def __init__(self, cage):
        from subtrace.patches.table import build_patch_table

        self.table = tb = build_patch_table([cage])
        self.loop = cage.scheme == "loop"
        if self.loop:
            from subtrace.lines.loop_items import box_nets, loop_regular

            obj = tb.objects[0]
            regular = loop_regular(obj.level, cage.options, tb.face)
            reg = np.nonzero(regular)[0]
            self.nets = box_nets(obj.level, obj.points, tb.face[reg])
        else:
            regular = tb.regular
            reg = np.nonzero(regular)[0]
            self.nets = tb.nets
        self.reg = reg
        self.irregular = np.nonzero(~regular)[0]


class _Items:
    """The Bezier items of a cage for one precision: the regular patches' nets, and the
    pieces and cells of the irregular patches some line's shell test asked for (isolated
    lazily, per line batch, and kept for later calls at the same precision)."""

    def __init__(self, base, precision):
        tb = self.table = base.table
        self.base = base
        reg = base.reg
        # per kind (quads, triangles): nets, exact, ptex, uv0, scale
        self.parts = {False: [[], [], [], [], []], True: [[], [], [], [], []]}
        self._add(base.loop, base.nets, True, tb.ptex[reg], tb.ptex_uv0[reg],
                  tb.ptex_scale[reg])
        self.irregular = base.irregular
        self.built = np.zeros(len(self.irregular), bool)
        self.shell_bvh = None  # over the irregular patches' shells, made at first need
        self.precision = precision
        # the largest proven bound (one-ring box diagonal) of an interior Catmull-Clark cell
        self.cell_bound = 0.0
        self._finish()

    def _add(self, tri, nets, exact, ptex, uv0, scale):
        for lst, x in zip(self.parts[tri], (nets, np.full(len(nets), exact), ptex, uv0,
                                            scale)):
            lst.append(x)

    def _finish(self):
        from subtrace.accel.bvh import build_bvh

        cat = {tri: [np.concatenate(x) if x else None for x in self.parts[tri]]
               for tri in (False, True)}
        q, t = cat[False], cat[True]
        self.all_nets = np.ascontiguousarray(q[0]) if q[0] is not None else \
            np.zeros((0, 4, 4, 3))
        self.all_tnets = np.ascontiguousarray(t[0]) if t[0] is not None else \
            np.zeros((0, 15, 3))
        nq, nt = len(self.all_nets), len(self.all_tnets)
        both = [x for x in (q, t) if x[0] is not None]
        self.all_exact = np.concatenate([x[1] for x in both]).astype(bool)
        self.all_ptex = np.concatenate([x[2] for x in both]).astype(np.int32)
        self.all_uv0 = np.concatenate([x[3] for x in both])
        self.all_scale = np.concatenate([x[4] for x in both])
        pts = np.concatenate([self.all_nets.reshape(nq, 16, 3),
                              np.pad(self.all_tnets, ((0, 0), (0, 1), (0, 0)), mode="edge")])
        n = nq + nt
        self.item_min = np.ascontiguousarray(pts.min(axis=1)) if n else np.zeros((0, 3))
        self.item_max = np.ascontiguousarray(pts.max(axis=1)) if n else np.zeros((0, 3))
        # cells are flat stand-ins: their boxes grow by the cell bound, within which the
        # true surface lies
        cell = ~self.all_exact
        self.item_min[cell] -= 0.5 * self.precision
        self.item_max[cell] += 0.5 * self.precision
        self.bvh = build_bvh(self.item_min, self.item_max) if n else None

    def need(self, org, dirs, t_lo, t_hi, pad):
        """Isolate the irregular patches whose shells these lines meet (once each)."""
        from subtrace.lines.kernels import mark_shells

        todo = ~self.built
        if not todo.any():
            return
        if self.shell_bvh is None:
            from subtrace.accel.bvh import build_bvh

            self.shell_min = np.ascontiguousarray(self.table.shell_min[self.irregular])
            self.shell_max = np.ascontiguousarray(self.table.shell_max[self.irregular])
            self.shell_bvh = build_bvh(self.shell_min, self.shell_max)
        hit = np.zeros(len(self.irregular), bool)
        mark_shells(org, dirs, t_lo, t_hi, pad, self.shell_min, self.shell_max, self.shell_bvh,
                    self.built, hit)
        hit = hit[todo]
        sel = np.nonzero(todo)[0][hit]
        if not len(sel):
            return
        self.built[sel] = True
        if self.base.loop:
            self._isolate_loop(self.irregular[sel])
        else:
            self._isolate(self.irregular[sel])
        self._finish()

    def _isolate_loop(self, rows):
        from subtrace.lines.loop_items import isolate_loop

        tb = self.table
        root, org, sc, nets, exact = isolate_loop(tb.objects[0], tb.face[rows],
                                                  0.5 * self.precision, MAX_ISOLATION)
        p = rows[root]
        for ex in (True, False):
            k = exact == ex
            self._add(True, nets[k], ex, tb.ptex[p[k]],
                      tb.ptex_uv0[p[k]] + tb.ptex_scale[p[k], None] * org[k],
                      tb.ptex_scale[p[k]] * sc[k])

    def _isolate(self, rows):
        from subtrace import config
        from subtrace.patches.isolate import build_isolated

        tb = self.table
        obj = tb.objects[0]
        bound = IRREGULAR_MARGIN * tb.edge_bound[rows]
        allowed = 0.5 * self.precision
        # a first guess of each patch's depth from the control-edge bound (measured)
        with np.errstate(divide="ignore", invalid="ignore"):
            d = np.ceil(np.log(allowed / bound) / np.log(tb.rate[rows]) - 1e-9)
        d = np.where(bound <= allowed, 0, d)
        d = np.clip(np.where(np.isfinite(d), d, MAX_ISOLATION), 0, MAX_ISOLATION).astype(np.int64)
        # Chaikin creases above sharpness 1 may leave the one-ring hull (as the shells allow)
        grow = 1.0
        if obj.cage.options.chaikin and np.any(obj.level.edge_sharpness > 1.0):
            grow += 2.0 * np.sqrt(3.0) * config.SHELL_CHAIKIN_MARGIN
        # then one level more for every patch with a cell whose one-ring box diagonal (the
        # proven bound) is above precision / 2, until none is; cells on the mesh's boundary
        # keep the first guess (along a boundary every level doubles the cells: the proven
        # bound there would cost 4-8x the items until boundary patches become regular pieces)
        subs, cells = [[] for _ in range(5)], [[] for _ in range(4)]
        todo = np.arange(len(rows))
        while len(todo):
            (root, level, i0, j0, bez, _), (croot, ci, cj, cpts, _, diag, edge) = \
                build_isolated(obj, tb.face[rows[todo]], d[todo], ring=True)
            again = np.zeros(len(todo), bool)
            again[croot[(grow * diag > allowed) & ~edge]] = True
            again &= d[todo] < MAX_ISOLATION
            # what the patches done now were built into
            keep_s, keep_c = ~again[root], ~again[croot]
            for lst, a in zip(subs, (todo[root], level, i0, j0, bez)):
                lst.append(a[keep_s])
            for lst, a in zip(cells, (todo[croot], ci, cj, cpts)):
                lst.append(a[keep_c])
            kept = (grow * diag)[keep_c & ~edge]
            self.cell_bound = max(self.cell_bound, float(kept.max(initial=0.0)))
            d[todo[again]] += 1
            todo = todo[again]
        root, level, i0, j0, bez = (np.concatenate(a) for a in subs)
        croot, ci, cj, cpts = (np.concatenate(a) for a in cells)
        # pieces: the patch parameters (i0 + s, j0 + t) / 2^level
        if len(root):
            p = rows[root]
            sc = 0.5 ** level.astype(np.float64)
            self._add(False, bez, True, tb.ptex[p], tb.ptex_uv0[p] + tb.ptex_scale[p, None]
                      * np.stack([i0 * sc, j0 * sc], axis=1), tb.ptex_scale[p] * sc)
        if len(croot):
            p = rows[croot]
            sc = 0.5 ** d[croot].astype(np.float64)
            # a cell's corners (0,0) (1,0) (1,1) (0,1) as a degree-elevated bilinear net
            g = np.arange(4) / 3.0
            s, t = g[:, None, None], g[None, :, None]
            c = cpts[:, None, None]  # (c,1,1,4,3)
            net = ((1 - s) * (1 - t) * c[..., 0, :] + s * (1 - t) * c[..., 1, :]
                   + s * t * c[..., 2, :] + (1 - s) * t * c[..., 3, :])
            self._add(False, np.ascontiguousarray(net), False, tb.ptex[p], tb.ptex_uv0[p]
                      + tb.ptex_scale[p, None] * np.stack([ci * sc, cj * sc], axis=1),
                      tb.ptex_scale[p] * sc)


# precisions whose items a cage keeps (the most recently used)
CACHED_PRECISIONS = 4


def _items_for(cage, precision) -> _Items:
    """The cage's items at ``precision``, kept on the cage (its ``_cache``, which lives and
    dies with the immutable cage) so that repeated calls skip the patch table, the Bezier
    conversion and the isolation already done; the latest ``CACHED_PRECISIONS`` are kept."""
    store = cage._cache.setdefault("lines", {})
    if "base" not in store:
        store["base"] = _Base(cage)
    by_prec = store.setdefault("items", {})
    items = by_prec.pop(precision, None)
    if items is None:
        items = _Items(store["base"], precision)
    by_prec[precision] = items  # most recent last
    while len(by_prec) > CACHED_PRECISIONS:
        by_prec.pop(next(iter(by_prec)))
    return items


def intersect_lines(cage, origins, directions, precision, t_range=(0.0, math.inf),
                    mode="all", threads=None) -> Hits:
    """Every intersection of the lines ``origins + t * directions`` (t in ``t_range``) with
    the limit surface of ``cage`` (Catmull-Clark or Loop), to ``precision`` (model units): each
    ``point`` lies within ``precision`` of the surface and of ``cage.evaluate(ptex, uv)``.
    ``mode="first"`` keeps each line's nearest hit. ``threads``: worker threads (default all
    cores). See the module doc for tangent lines and flat regions. Returns :class:`Hits`."""
    from subtrace.runtime.threads import run_tasks, set_threads, thread_count
    from subtrace.lines.kernels import N_FIELDS, lines_task, merge_candidates
    from subtrace.lines.tri_nets import SPLIT_COL, SPLIT_PTR, SPLIT_W

    if getattr(cage, "scheme", None) not in ("catmark", "loop"):
        raise SubtraceError("intersect_lines: expected a Catmull-Clark or Loop cage "
                            "(subtrace.load_cage / make_cage)")
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

    items = _items_for(cage, precision)
    tol_flat = 0.5 * precision
    touch_tol = precision
    scale = float(np.abs(items.table.shell_max).max(initial=1.0)
                  + np.abs(items.table.shell_min).max(initial=0.0))
    res_tol = max(1e-3 * precision, 64 * np.finfo(float).eps * scale)
    n_lines = len(org)
    dlen = np.linalg.norm(dirs, axis=1)
    out_rows, out_tan, out_line = [], [], []
    entered = leaves = 0
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
                          SPLIT_PTR, SPLIT_COL, SPLIT_W, items.all_exact,
                          items.item_min, items.item_max, bv, tol_flat, touch_tol, res_tol,
                          mode == "first", cap, cand, count, stats)
                over = count > cap
                done = ~over
                keep = np.zeros((len(sel), cap), bool)
                tan = np.zeros((len(sel), cap), bool)
                merge_candidates(cand, count, dlen[a:b][sel], precision, keep, tan)
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
    return _hits(items, org, dirs, out_rows, out_tan, out_line, mode, n_lines, precision,
                 dict(items=len(items.all_exact), items_entered=entered, leaves=leaves))


def _hits(items, org, dirs, rows, tans, lines, mode, n_lines, precision, stats) -> Hits:
    from subtrace.lines.kernels import C_A, C_B, C_ITEM, C_T

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
    normal[quad] = _normals(items.all_nets, item[quad], ab[quad])
    if not quad.all():
        from subtrace.lines.loop_items import tri_normals

        normal[~quad] = tri_normals(items.all_tnets, item[~quad] - len(items.all_nets),
                                    ab[~quad])
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


def _normals(nets, item, ab):
    """Unit normals of items ``item`` at parameters ``ab`` (vectorised Bernstein
    derivatives); where they vanish (an extraordinary corner), the normal a little inside."""
    out = np.full((len(item), 3), np.nan)
    todo = np.arange(len(item))
    for step in (0.0, 1e-6, 1e-4):
        if not len(todo):
            break
        a = np.clip(ab[todo, 0], step, 1 - step)
        b = np.clip(ab[todo, 1], step, 1 - step)
        ba, da = _bernstein(a)
        bb, db = _bernstein(b)
        N = nets[item[todo]]  # (m,4,4,3)
        du = np.einsum("mi,mj,mijk->mk", da, bb, N)
        dv = np.einsum("mi,mj,mijk->mk", ba, db, N)
        n = np.cross(du, dv)
        ln = np.linalg.norm(n, axis=1)
        ok = ln > 0
        out[todo[ok]] = n[ok] / ln[ok, None]
        todo = todo[~ok]
    return out


def _bernstein(x):
    """Cubic Bernstein values and derivatives at x (m,): two (m,4) arrays."""
    y = 1.0 - x
    b = np.stack([y**3, 3 * x * y**2, 3 * x**2 * y, x**3], axis=1)
    d = np.stack([-3 * y**2, 3 * y * (y - 2 * x), 3 * x * (2 * y - x), 3 * x**2], axis=1)
    return b, d


def torus_cage(n_major: int = 14, n_minor: int = 14, R: float = 1.0, r: float = 0.35):
    """A closed torus cage of ``n_major x n_minor`` quads (every vertex of valence 4, so
    every patch is a regular bicubic), centred at the origin around the z axis. 14 x 14 gives
    the 196 patches of the paper's second experiment."""
    from subtrace.mesh.cage import make_cage

    i, j = np.meshgrid(np.arange(n_major), np.arange(n_minor), indexing="ij")
    a = 2 * np.pi * i / n_major
    b = 2 * np.pi * j / n_minor
    pts = np.stack([(R + r * np.cos(b)) * np.cos(a), (R + r * np.cos(b)) * np.sin(a),
                    r * np.sin(b)], axis=-1).reshape(-1, 3)
    vid = lambda p, q: (p % n_major) * n_minor + (q % n_minor)  # noqa: E731
    faces = np.stack([vid(i, j), vid(i + 1, j), vid(i + 1, j + 1), vid(i, j + 1)],
                     axis=-1).reshape(-1, 4)
    return make_cage(pts, np.full(len(faces), 4), faces.ravel(), scheme="catmark")
