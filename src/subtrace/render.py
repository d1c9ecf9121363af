"""Rendering: orchestration only (the maths lives in patches/, accel/, trace/, shade.py).

``render_scene(scene)`` loads the cages, builds the patch table, bins the patch shells into
image tiles (or builds their BVH), chooses each patch's grid depth from the angular tolerance and makes neighbours sample their
shared edges alike, then runs rounds of ``trace.kernels.trace_round``. Regular Catmull-Clark
patches are refined per ray inside the kernel, each thread keeping what its rays split
(``_Memos``). After each round the patches that rays asked for are built: irregular
Catmull-Clark patches into Bezier pieces (each with its own depth) and cells (``_Pieces``),
Loop patches into grids with snapped sides and quadtree boxes (``_Pools``). The rays that asked are then traced again. Patches no ray reaches before a
closer hit are never refined. Finally ``shade.py`` turns hits into image channels.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, field

import numpy as np

from subtrace import config
from subtrace.accel.bvh import build_bvh, no_bvh
from subtrace.patches.basis import net_bounds
from subtrace.patches.criterion import choose_depths, depth_cap, edge_sampling, memory_estimate
from subtrace.patches.isolate import build_isolated
from subtrace.patches.grids import build_grids, grid_params, leaf_corners
from subtrace.patches.table import build_patch_table
from subtrace.trace.kernels import HIT_FIELDS, candidate_lists, trace_round


@dataclass
class RenderStats:
    time_load: float = 0.0
    time_preprocess: float = 0.0
    time_refine: float = 0.0
    time_trace: float = 0.0
    time_shade: float = 0.0
    time_total: float = 0.0
    patches: int = 0
    patches_refined: int = 0
    # built: 2 per cell a thread evaluated first (kept, or a fan counted once) or isolated
    # (threads take bands as they are free, so with several threads the count may differ
    # slightly between runs)
    micro_triangles: int = 0
    grid_points: int = 0
    pieces: int = 0  # regular sub-patches and cells of the isolated irregular patches
    memo_nodes: int = 0  # quadtree nodes of Bezier pieces split and kept by the threads
    memo_full: int = 0  # times a thread's memo ran out during a round (rays split on the spot)
    memo_bytes: int = 0  # bytes of the memos' stores in use at the end
    rounds: int = 0
    max_depth: int = 0
    depth_cap: int = -1  # the grid depth the memory budget capped refinement at (-1: none)
    # 1: the projection's tile lists did not fit the memory budget, so rays walked the BVH
    accel_fallback: int = 0
    pixels_covered: int = 0
    rays: int = 0

    def as_attributes(self) -> dict:
        return {f"subtrace:{k}": v for k, v in self.__dict__.items()}


@dataclass
class RenderResult:
    channels: dict  # name -> (H,W) float32
    stats: RenderStats
    camera: object
    tolerance_rad: float
    schemes: tuple
    refined_objects: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    accel: str = "projection"  # how rays found the shells they enter
    # object id of every refined patch (what was built, for tests and reports)


# --------------------------------------------------------------------------------------
# static tables
# --------------------------------------------------------------------------------------


class _LeafTables:
    """Leaf corners and grid parameters of every (depth, quad), concatenated for kernels."""

    def __init__(self, max_depth: int):
        D = max_depth + 1
        self.lc_off = np.zeros((D, 2), dtype=np.int64)
        self.uv_off = np.zeros((D, 2), dtype=np.int64)
        lcs, uvs = [], []
        n_lc = n_uv = 0
        for d in range(D):
            for q in (0, 1):
                lc = leaf_corners(d, bool(q))
                pad = np.full((len(lc), 4), -1, dtype=np.int32)
                pad[:, : lc.shape[1]] = lc
                self.lc_off[d, q] = n_lc
                self.uv_off[d, q] = n_uv
                lcs.append(pad)
                uvs.append(grid_params(d, bool(q)))
                n_lc += len(pad)
                n_uv += len(uvs[-1])
        self.lc_data = np.ascontiguousarray(np.concatenate(lcs))
        self.uv_data = np.ascontiguousarray(np.concatenate(uvs))


@functools.lru_cache(maxsize=4)
def _leaf_tables(max_depth: int) -> _LeafTables:
    """The (read-only) tables up to ``max_depth``, made once per process."""
    return _LeafTables(max_depth)


def _side_indices(depth: int, quad: bool) -> np.ndarray:
    """(k, N+1) grid indices along each side, from corner k to corner k+1."""
    N = 1 << depth
    t = np.arange(N + 1)
    if quad:
        W = N + 1
        return np.stack([t, N + t * W, (N - t) + N * W, (N - t) * W])
    row = lambda j: j * (N + 1) - j * (j - 1) // 2  # noqa: E731
    return np.stack([t, row(t) + (N - t), row(N - t)])


def _grown(a, n_used, size):
    """``a`` with room for ``size`` rows (``np.empty``: pages are touched as used), its
    first ``n_used`` rows copied."""
    b = np.empty((size, *a.shape[1:]), a.dtype)
    b[:n_used] = a[:n_used]
    return b


class _Growable:
    """Named arrays in groups that grow together (a group's arrays have one length). Storage
    grows by doubling, so appending round after round copies each element O(1) times;
    ``self.a[name]`` is a view of the filled part (a kernel's writes into it persist)."""

    GROUPS: dict = {}  # group -> {name: (trailing shape, dtype)}

    def __init__(self):
        self._store = {}
        self._used = {}
        for group, names in self.GROUPS.items():
            self._used[group] = 0
            for name, (shape, dtype) in names.items():
                self._store[name] = np.zeros((0, *shape), dtype=dtype)
        self._refresh()

    def _refresh(self):
        self.a = {name: self._store[name][: self._used[group]]
                  for group, names in self.GROUPS.items() for name in names}

    def reserve(self, group, n):
        """Make room for ``n`` rows of ``group`` in all (no copy later until they are used)."""
        self._grow(group, n)

    def _grow(self, group, end):
        start = self._used[group]
        for name in self.GROUPS[group]:
            buf = self._store[name]
            if end > len(buf):
                self._store[name] = _grown(buf, start, max(end, 2 * len(buf)))

    def _put(self, group, **values):
        """Append rows to every array of ``group`` (zeros where no value is given); returns
        the first new row."""
        start = self._used[group]
        end = start + len(next(iter(values.values())))
        self._grow(group, end)
        for name in self.GROUPS[group]:
            self._store[name][start:end] = values.get(name, 0)
        self._used[group] = end
        self._refresh()
        return start


class _Pools(_Growable):
    """Grid points, normals and quadtree boxes of built Loop patches, and their slots."""

    GROUPS = {
        "rows": {"verts": ((3,), np.float64), "normals": ((3,), np.float32)},
        "nodes": {"node_lo": ((3,), np.float64), "node_hi": ((3,), np.float64)},
        "slots": {"slot_patch": ((), np.int64), "slot_depth": ((), np.int64),
                  "slot_quad": ((), np.bool_), "slot_vert_off": ((), np.int64),
                  "slot_node_off": ((), np.int64), "slot_round": ((), np.int64)},
    }

    def __init__(self, n_patches):
        super().__init__()
        self.patch_slot = np.full(n_patches, -1, dtype=np.int64)

    def append(self, patches, depth, quad, P, N, lo, hi, round_no):
        m = len(patches)
        G = P.shape[1]
        K = lo.shape[1]
        v0 = self._put("rows", verts=P.reshape(-1, 3), normals=N.reshape(-1, 3))
        n0 = self._put("nodes", node_lo=lo.reshape(-1, 3), node_hi=hi.reshape(-1, 3))
        ar = np.arange(m, dtype=np.int64)
        s0 = self._put("slots", slot_patch=patches, slot_depth=np.full(m, depth),
                       slot_quad=np.full(m, quad), slot_vert_off=v0 + G * ar,
                       slot_node_off=n0 + K * ar, slot_round=np.full(m, round_no))
        self.patch_slot[patches] = s0 + ar


# --------------------------------------------------------------------------------------
# refinement of requested patches
# --------------------------------------------------------------------------------------


def _node_boxes(P: np.ndarray, depth: int, quad: bool):
    """Quadtree boxes (m, K, 3) of grids P (m, G, 3): leaves from their corners, then up."""
    lc = leaf_corners(depth, quad)
    corners = P[:, lc]  # (m, 4^n, k, 3)
    lo = [corners.min(axis=2)]
    hi = [corners.max(axis=2)]
    while lo[0].shape[1] > 1:
        m, n = lo[0].shape[:2]
        lo.insert(0, lo[0].reshape(m, n // 4, 4, 3).min(axis=2))
        hi.insert(0, hi[0].reshape(m, n // 4, 4, 3).max(axis=2))
    return np.concatenate(lo, axis=1), np.concatenate(hi, axis=1)


def _snap_sides(P: np.ndarray, depth: int, quad: bool, side_depth: np.ndarray):
    """Move boundary points of sides shared with a coarser patch onto the coarser
    patch's polyline (linear interpolation of the points it shares), in place."""
    sides = _side_indices(depth, quad)
    N = 1 << depth
    for k in range(sides.shape[0]):
        for de in np.unique(side_depth[:, k]):
            if de >= depth or de < 0:
                continue
            rows = np.nonzero(side_depth[:, k] == de)[0]
            r = 1 << (depth - de)
            t = np.arange(N + 1)
            t0 = (t // r) * r
            t1 = np.minimum(t0 + r, N)
            w = ((t - t0) / r)[None, :, None]
            idx = sides[k]
            Q = P[rows][:, idx]
            P[rows[:, None], idx[None, :]] = (1.0 - w) * Q[:, t0] + w * Q[:, t1]


def _refine(table, requested, depths, edge_depth, pools, iso, round_no, stats, eye, tol_rad,
            record):
    """Build the requested patches: irregular Catmull-Clark patches into pieces (``iso``,
    all of an object's in one isolation, taking what ``record[object id]`` kept of the
    depth choice's isolation), Loop patches into grids (``pools``)."""
    obj = table.object_id[requested]
    dep = depths[requested]
    quad = table.is_quad[requested]
    order = np.lexsort((requested, np.where(quad, 0, dep), obj))
    requested, obj, dep, quad = requested[order], obj[order], dep[order], quad[order]
    keys = np.stack([obj, np.where(quad, -1, dep)], axis=1)
    starts = np.r_[0, np.nonzero(np.any(np.diff(keys, axis=0) != 0, axis=1))[0] + 1]
    ends = np.r_[starts[1:], len(requested)]
    for s, e in zip(starts, ends):
        ids = requested[s:e]
        o = table.objects[int(obj[s])]
        if quad[s]:
            subs, cells = build_isolated(o, table.face[ids], dep[s:e], eye, tol_rad,
                                         record.get(int(obj[s])))
            n_sub, n_cell = iso.append(ids, dep[s:e], np.repeat(dep[s:e], 4), subs, cells,
                                       round_no)
            stats.pieces += n_sub + n_cell
            stats.micro_triangles += 2 * n_cell
            continue
        d = int(dep[s])
        P, N = build_grids(o.level, o.points, o.cage.options, table.face[ids], d)
        side_depth = np.where(table.edges[ids, :3] >= 0, edge_depth[table.edges[ids, :3]], -1)
        _snap_sides(P, d, False, side_depth)
        lo, hi = _node_boxes(P, d, False)
        pools.append(ids, d, False, P, N, lo, hi, round_no)
        stats.micro_triangles += len(ids) * (1 << (2 * d))
        stats.grid_points += P.shape[0] * P.shape[1]
    stats.patches_refined += len(requested)


# --------------------------------------------------------------------------------------
# the renderer
# --------------------------------------------------------------------------------------


class _Pieces(_Growable):
    """What the kernels intersect per ray, for every Catmull-Clark patch built so far, in the
    layout of ``trace_round``'s ``iso`` tuple: a *slot* per patch (the round it was built
    in, whether a ray has tested it) and its *items* (contiguous): regular Bezier pieces over
    dyadic squares of the patch, and cells of exact limit points, each with its grid depth
    and how its four sides are sampled. A regular patch is one item, ready from the start (round -1); an
    irregular patch is built on request into pieces (``patches/isolate.py``)."""

    GROUPS = {
        "slots": {"patch": ((), np.int64), "first": ((), np.int64), "count": ((), np.int64),
                  "round": ((), np.int64), "touched": ((), np.uint8)},
        "items": {"kind": ((), np.int8), "ref": ((), np.int64), "level": ((), np.int64),
                  "i0": ((), np.int64), "j0": ((), np.int64), "depth_i": ((), np.int64),
                  "side": ((4,), np.int64), "lo": ((3,), np.float64),
                  "hi": ((3,), np.float64), "rest_lo": ((3,), np.float64),
                  "rest_hi": ((3,), np.float64)},
        "nets": {"nets": ((4, 4, 3), np.float64)},
        "cells": {"cells": ((4, 3), np.float64), "normals": ((4, 3), np.float64)},
    }

    def __init__(self, n_patches):
        super().__init__()
        self.patch_iso = np.full(n_patches, -1, dtype=np.int64)

    def append(self, patches, depth, side, subs, cells, round_no):
        """Slots for ``patches`` (grid depths ``depth`` (m,), how their sides are sampled
        ``side`` (m,4)) made of ``subs`` and ``cells`` (see
        :func:`~subtrace.patches.isolate.build_isolated`); each piece samples its sides as
        finely as the pieces beside it (:func:`~subtrace.patches.isolate.item_sides`)."""
        from subtrace.patches.isolate import item_sides, rest_boxes

        (sr, sl, si, sj, nets, sd), (cr, ci, cj, cp, cn) = subs, cells
        lo_s, hi_s, _ = net_bounds(nets)
        root = np.concatenate([sr, cr])
        order = np.argsort(root, kind="stable")
        level = np.r_[sl, depth[cr]][order]
        i0, j0 = np.r_[si, ci][order], np.r_[sj, cj][order]
        depth_i = np.r_[sd, depth[cr]][order].astype(np.int64)
        count = np.bincount(root, minlength=len(patches))
        first = np.cumsum(count) - count
        item_side = np.empty((len(root), 4), np.int64)
        item_sides(first, count, level, i0, j0, depth_i,
                   np.ascontiguousarray(np.asarray(side).reshape(-1, 4), dtype=np.int64),
                   item_side)
        n0 = self._put("nets", nets=nets)
        c0 = self._put("cells", cells=cp, normals=cn)
        lo = np.concatenate([lo_s, cp.min(axis=1)])[order]
        hi = np.concatenate([hi_s, cp.max(axis=1)])[order]
        rest_lo, rest_hi = np.empty_like(lo), np.empty_like(hi)
        rest_boxes(first, count, lo, hi, rest_lo, rest_hi)
        i_start = self._put(
            "items",
            kind=np.r_[np.zeros(len(sr), np.int8), np.ones(len(cr), np.int8)][order],
            ref=np.r_[n0 + np.arange(len(sr)), c0 + np.arange(len(cr))][order],
            level=level, i0=i0, j0=j0, depth_i=depth_i, side=item_side, lo=lo, hi=hi,
            rest_lo=rest_lo, rest_hi=rest_hi,
        )
        s0 = self._put("slots", patch=patches, first=i_start + first, count=count,
                       round=np.full(len(patches), round_no))
        self.patch_iso[patches] = s0 + np.arange(len(patches))
        return len(sr), len(cr)

    def append_regular(self, patches, depth, side, nets, lo, hi):
        """Slots for regular patches, one Bezier piece each (the whole patch): what
        :meth:`append` makes of them, without its general work. ``lo``, ``hi``: their nets'
        boxes (the patch table's shells)."""
        m = len(patches)
        z = np.zeros(m, np.int64)
        ar = np.arange(m, dtype=np.int64)
        n0 = self._put("nets", nets=nets)
        i_start = self._put("items", kind=np.zeros(m, np.int8), ref=n0 + ar, level=z, i0=z,
                            j0=z, depth_i=depth, side=side, lo=lo, hi=hi, rest_lo=lo,
                            rest_hi=hi)
        s0 = self._put("slots", patch=patches, first=i_start + ar, count=np.ones(m, np.int64),
                       round=np.full(m, -1))
        self.patch_iso[patches] = s0 + ar

    def kernel_tuple(self):
        a = self.a
        return (self.patch_iso, a["first"], a["count"], a["round"], a["depth_i"], a["side"],
                a["kind"], a["ref"], a["level"], a["i0"], a["j0"], a["lo"], a["hi"],
                a["rest_lo"], a["rest_hi"],
                a["nets"], a["cells"].reshape(-1, 3), a["touched"])


class _Memos:
    """Each thread's memo of the Bezier nets its rays split (``trace.bezier``: item roots,
    node children, boxes and rows, the net store, the cell-corner store, counts). The stores
    are allocated lazily by the OS (``np.empty``); one that ran out during a round (its rays
    went on without storing) is doubled before the next."""

    START = {"child": 1 << 22, "nets": 1 << 19, "cells": 1 << 20}  # virtual: touched as used
    # rows per unit of START (a cell has 4 corner rows) and bytes per row: a node (child,
    # box, slab, data), a net, a cell corner
    ROWS = {"child": 1, "nets": 1, "cells": 4}
    ROW_BYTES = {"child": 8 + 48 + 40 + 8, "nets": 4 * 4 * 3 * 8, "cells": 3 * 8}

    def __init__(self, n_threads, max_bytes=None):
        # each store at most its share (that of START) of max_bytes per thread
        start = {k: self.START[k] * self.ROWS[k] for k in self.START}
        total = sum(start[k] * self.ROW_BYTES[k] for k in start)
        self.max_rows = {k: (None if max_bytes is None else
                             max(64, int(max_bytes * start[k] / total)))
                         for k in start}
        self.m = [self._grow(None, 0, "child", "nets", "cells") for _ in range(n_threads)]
        self.full = 0

    def _rows(self, name, current):
        """Rows of store ``name`` after a growth from ``current`` rows: double (at least
        START), within the budget's share."""
        n = max(2 * current, self.START[name] * self.ROWS[name])
        cap = self.max_rows[name]
        return n if cap is None else max(current, min(n, cap))

    def _grow(self, old, n_items, *which):
        """A memo with room for ``n_items`` items, the stores named in ``which`` doubled."""
        from subtrace.trace.bezier import M_CELLS, M_FULL, M_NETS, M_NODES

        if old is None:
            root = np.full(0, -1, np.int64)
            child, box, data = np.empty(0, np.int64), np.empty((0, 6)), np.empty(0, np.int64)
            slab = np.empty((0, 5))
            nets, cells, cnt = np.empty((0, 4, 4, 3)), np.empty((0, 3)), np.zeros(4, np.int64)
        else:
            root, child, box, slab, data, nets, cells, cnt = old
        if len(root) < n_items:
            root = np.concatenate([root, np.full(max(n_items, 2 * len(root)) - len(root), -1)])
        n = self._rows("child", len(child))
        if "child" in which and n > len(child):
            used = cnt[M_NODES]
            child, box, slab, data = (_grown(child, used, n), _grown(box, used, n),
                                      _grown(slab, used, n), _grown(data, used, n))
        n = self._rows("nets", len(nets))
        if "nets" in which and n > len(nets):
            nets = _grown(nets, cnt[M_NETS], n)
        n = 4 * (self._rows("cells", len(cells)) // 4)
        if "cells" in which and n > len(cells):
            cells = _grown(cells, 4 * cnt[M_CELLS], n)
        cnt[M_FULL] = 0
        return root, child, box, slab, data, nets, cells, cnt

    def kernel_tuple(self, n_items):
        from subtrace.trace.bezier import M_FULL

        for k, m in enumerate(self.m):
            self.full += int(m[-1][M_FULL])
            if m[-1][M_FULL] or len(m[0]) < n_items:
                self.m[k] = self._grow(m, n_items, *(("child", "nets", "cells") if m[-1][M_FULL]
                                                     else ()))
        return tuple(self.m)

    def finish(self, stats):
        from subtrace.trace.bezier import M_CELLS, M_FULL, M_NETS, M_NODES

        stats.memo_nodes = int(sum(m[-1][M_NODES] for m in self.m))
        stats.memo_bytes = int(sum(
            m[-1][M_NODES] * self.ROW_BYTES["child"] + m[-1][M_NETS] * self.ROW_BYTES["nets"]
            + 4 * m[-1][M_CELLS] * self.ROW_BYTES["cells"] for m in self.m))
        stats.memo_full = self.full + int(sum(m[-1][M_FULL] for m in self.m))


def trace_hits(table, camera, tol_rad, stats, max_depth=None, compiling=None, accel=None,
               progress=None, max_memory=None):
    """Run the refinement rounds; returns (hits (6, H*W): ``prims.H_*`` rows; a miss has
    only H_T = inf and H_SLOT = -1; grid pools, isolated pieces, leaf
    tables, every patch refined). ``compiling``: the process compiling the trace kernels
    (``warmup.start``), waited for before the first round. ``accel``: how a ray finds the
    shells it enters, ``"projection"`` (the shells binned into image tiles,
    ``accel/projection.py``) or ``"bvh"`` (``accel/bvh.py``); default
    ``config.PRIMARY_ACCEL``. Either structure is built here (preprocess time).
    ``progress(done, total, label)``: told after each round how many rays are final.
    ``max_memory``: a budget in bytes (None: none); depths whose estimate
    (``patches.table.memory_estimate``) exceeds it are capped, with a warning, and the
    threads' memos are kept within what is left."""
    from subtrace.runtime import threads as tasks, warmup
    from subtrace.accel.projection import no_tiles, project_shells, tiles_bytes
    from subtrace.camera import camera_frame

    max_depth = config.MAX_GRID_DEPTH if max_depth is None else max_depth
    W, H = camera.width, camera.height
    frame = camera_frame(camera)
    eye = frame[0]
    t0 = time.perf_counter()

    def depth_choice(cap):
        # (isolates: refinement); the isolation also tightens the irregular patches' shells
        record = {}
        shells = table.shell_min.copy(), table.shell_max.copy()
        return choose_depths(table, eye, tol_rad, cap, record, shells), record, shells

    depths, record, (shell_min, shell_max) = depth_choice(max_depth)
    n_threads = tasks.thread_count()
    left = None  # bytes of the budget left for the tile lists and the memos
    if max_memory is not None:
        left = max_memory - config.MEMORY_MEMO_MIN_BYTES * n_threads
        cap = depth_cap(table, depths, W * H, left)
        if cap is not None:
            _warn_capped(max_memory, cap, depths, memory_estimate(table, depths, W * H))
            depths, record, (shell_min, shell_max) = depth_choice(max(cap, 0))
            stats.depth_cap = max(cap, 0)
        left = max(left - memory_estimate(table, depths, W * H), 0)
    edge_depth, reg_side = edge_sampling(table, depths)
    stats.time_refine += time.perf_counter() - t0
    t0 = time.perf_counter()
    accel = config.PRIMARY_ACCEL if accel is None else accel
    if accel not in ("projection", "bvh"):
        raise ValueError(f"unknown acceleration {accel!r}")
    tiles = None
    if accel == "projection":
        projected = project_shells(shell_min, shell_max, frame, W, H, max_bytes=left)
        if projected is None:  # the lists would not fit the budget: the BVH's do (O(N))
            _warn_tiles(max_memory)
            stats.accel_fallback = 1
        else:
            tiles = projected.kernel_tuple()
            if left is not None:
                left -= tiles_bytes(len(projected.items), len(projected.off) - 1)
        bvh = no_bvh()
    if tiles is None:
        tiles = no_tiles()
        bvh = build_bvh(shell_min, shell_max)
    memo_bytes = None if left is None else config.MEMORY_MEMO_MIN_BYTES + left // n_threads
    stats.time_preprocess += time.perf_counter() - t0
    tested = np.empty(W * H, dtype=np.int64)  # (round 0 writes every ray's entries)
    tables = _leaf_tables(int(depths[~table.is_quad].max(initial=0)))  # (Loop grids only)
    pools = _Pools(table.n_patches)
    iso = _Pieces(table.n_patches)
    memos = _Memos(tasks.thread_count(), memo_bytes)
    reg = np.nonzero(table.regular)[0]
    n_irr = int(np.count_nonzero(table.is_quad & ~table.regular))
    iso.reserve("items", len(reg) + 16 * n_irr)
    iso.reserve("nets", len(reg) + 16 * n_irr)
    iso.append_regular(reg, depths[reg], reg_side, table.nets, table.shell_min[reg],
                       table.shell_max[reg])
    hits = np.empty((HIT_FIELDS, W * H))
    request = np.empty(W * H, dtype=np.int64)
    cands = candidate_lists(W * H)
    rays = np.arange(W * H, dtype=np.int64)
    round_no = 0
    if compiling is not None:
        # a cold cache: while the trace kernels compile elsewhere, compile what the rounds
        # need here (exact limit points of isolated cells), on inputs of the same types
        from subtrace.subdiv.limit import limit_points

        for o in table.objects[:1]:
            limit_points(o.level, o.points, o.cage.options, which=np.zeros(0, np.int64))
    warmup.wait(compiling)
    while len(rays):
        t0 = time.perf_counter()
        g = pools.a
        trace_round(
            rays, frame, W, round_no,
            bvh.node_min, bvh.node_max, bvh.node_first, bvh.node_count,
            bvh.prims, tiles, shell_min, shell_max, pools.patch_slot,
            g["slot_depth"], g["slot_vert_off"], g["slot_node_off"], g["slot_quad"],
            g["slot_round"], g["verts"], g["node_lo"], g["node_hi"],
            tables.lc_off, tables.lc_data, iso.kernel_tuple(),
            memos.kernel_tuple(len(iso.a["kind"])), cands, config.TRI_SLACK, hits, request,
            tested,
        )
        stats.time_trace += time.perf_counter() - t0
        req = request[rays]
        asked = req >= 0
        rays = rays[asked]
        if progress is not None:
            progress(W * H - len(rays), W * H, f"round {round_no + 1}")
        if not len(rays):
            break
        t0 = time.perf_counter()
        flag = np.zeros(table.n_patches, bool)
        flag[req[asked]] = True
        new = np.nonzero(flag)[0]  # (np.unique, sorted: it hashes every request)
        _refine(table, new, depths, edge_depth, pools, iso, round_no, stats, eye, tol_rad,
                record)
        stats.time_refine += time.perf_counter() - t0
        round_no += 1
    stats.rounds = round_no + 1
    memos.finish(stats)
    stats.micro_triangles += int(tested.sum())
    # regular patches count as refined once a ray has descended into them
    direct = iso.a["patch"][(iso.a["round"] < 0) & (iso.a["touched"] > 0)]
    stats.patches_refined += len(direct)
    stats.max_depth = int(max(pools.a["slot_depth"].max(initial=0), iso.a["depth_i"].max(initial=0)))
    built = np.concatenate([pools.a["slot_patch"], iso.a["patch"][iso.a["round"] >= 0], direct])
    return hits, pools, iso, tables, built


# --------------------------------------------------------------------------------------
# scenes
# --------------------------------------------------------------------------------------


def _mib(n: int) -> str:
    return f"{n / 2**30:.1f} GiB" if n >= 10 * 2**30 else f"{n / 2**20:.0f} MiB"


def _warn_capped(budget, cap, depths, estimate):
    """The one warning of a render whose refinement the memory budget capped."""
    import warnings

    from subtrace.errors import SubtraceWarning

    warnings.warn(SubtraceWarning(
        f"memory budget {_mib(budget)}: refinement capped at depth {max(cap, 0)} below the "
        f"patches (the tolerance needs depth {int(depths.max(initial=0))}, an estimated "
        f"{_mib(estimate)}), so the image is coarser than the tolerance; raise --max-memory "
        "(or [render] max_memory in the scene) to refine fully"), stacklevel=2)


def _warn_tiles(budget):
    """The one warning of a render whose tile lists the memory budget refused."""
    import warnings

    from subtrace.errors import SubtraceWarning

    warnings.warn(SubtraceWarning(
        f"memory budget {_mib(budget)}: the projection's tile lists would not fit (many "
        "shells reach the eye plane, e.g. with the eye inside a model), so rays walk the "
        "shells' BVH instead (same image, slower); raise --max-memory to project"),
        stacklevel=2)


def check_memory(table, n_pixels: int, budget: int, width: int, height: int):
    """Raise SceneError when even unrefined patches (depth 0) would not fit ``budget``."""
    from subtrace.runtime import threads as tasks
    from subtrace.errors import SceneError

    need = (memory_estimate(table, np.zeros(table.n_patches, np.int32), n_pixels)
            + config.MEMORY_MEMO_MIN_BYTES * tasks.thread_count())
    if need > budget:
        raise SceneError(
            f"a {width}x{height} render of {table.n_patches} patches needs at least "
            f"{_mib(need)} ({config.MEMORY_BYTES_PER_PIXEL} bytes per pixel, "
            f"{config.MEMORY_BYTES_PER_PATCH} per patch) but the "
            f"memory budget is {_mib(budget)}: lower the resolution or raise --max-memory "
            "(or [render] max_memory in the scene)")


def load_objects(scene):
    """Cages of the scene's objects (scheme / boundary overrides applied)."""
    from subtrace.mesh.cage import load_cage

    return [load_cage(o.mesh, scheme=o.scheme, boundary=o.boundary_code) for o in scene.objects]


def _patch_colors(table, scene):
    from subtrace.io.obj import DEFAULT_DIFFUSE

    colors = np.empty((table.n_patches, 3))
    for oid, o in enumerate(table.objects):
        sl = slice(o.first_patch, o.first_patch + len(o.patch_faces))
        override = scene.objects[oid].color
        if override is not None:
            colors[sl] = override
            continue
        mats = o.cage.materials
        table_rgb = np.array([m.diffuse for m in mats] + [DEFAULT_DIFFUSE], dtype=np.float64)
        mat = table.material[sl]
        colors[sl] = table_rgb[np.where(mat >= 0, mat, len(mats))]
    return colors


def render_scene(scene, cages=None, threads=None, progress=None, accel=None) -> RenderResult:
    """Render a :class:`subtrace.io.scene.Scene`; returns the channels and statistics.
    ``accel``: how rays find the shells they enter (see :func:`trace_hits`). ``progress``:
    None, or called as ``progress(done, total, label)`` with the rays whose hits are final
    out of all (e.g. :class:`subtrace.runtime.progress.ProgressBar`); it reaches done == total."""
    from subtrace.runtime import threads as tasks, warmup
    from subtrace.shade import CHANNELS, miss_values, shade_kernel
    from subtrace.camera import camera_frame

    t_start = time.perf_counter()
    if threads is not None:
        from subtrace.errors import SceneError

        n_max = tasks.max_threads()
        if not 1 <= int(threads) <= n_max:
            raise SceneError(f"expected a thread count from 1 to {n_max}, got {threads}",
                             key="--threads")
    accel = config.PRIMARY_ACCEL if accel is None else accel
    if accel not in ("projection", "bvh"):
        from subtrace.errors import SceneError

        raise SceneError(f"expected projection or bvh, got {accel!r}", key="--accel")
    tasks.set_threads(threads)
    stats = RenderStats()
    compiling = warmup.start(tasks.thread_count())  # on a cold cache only
    try:
        if cages is None:
            cages = load_objects(scene)
        from subtrace.io.obj import check_coordinates, check_valences

        for c in cages:
            check_coordinates(c.path, c.points, config.MAX_COORDINATE)
            check_valences(c.path, c.face_sizes, np.diff(c.base.vert_edge_offsets),
                           config.MAX_VALENCE, c.scheme == "catmark")
        stats.time_load = time.perf_counter() - t_start

        t0 = time.perf_counter()
        table = build_patch_table(cages)
        lo = table.shell_min.min(axis=0)
        hi = table.shell_max.max(axis=0)
        if scene.camera.is_auto:
            # frame the limit surface: the bounds of the level-1 limit points of every object
            bounds = [c.bounds() for c in cages]
            lo = np.min([b[0] for b in bounds], axis=0)
            hi = np.max([b[1] for b in bounds], axis=0)
        camera = scene.make_camera(lo, hi)
        budget = scene.render.max_memory
        budget = config.default_max_memory() if budget is None else budget
        check_memory(table, camera.width * camera.height, budget, camera.width, camera.height)
        tol_rad = scene.render.tolerance_rad(camera)
        stats.patches = table.n_patches
        stats.rays = camera.width * camera.height
        stats.time_preprocess = time.perf_counter() - t0
        if progress is not None:
            progress(0, stats.rays, "tracing")
        hits, pools, iso, tables, built = trace_hits(table, camera, tol_rad, stats,
                                                     compiling=compiling, accel=accel,
                                                     progress=progress, max_memory=budget)
    except BaseException:
        warmup.stop(compiling)
        raise

    t0 = time.perf_counter()
    W, H = camera.width, camera.height
    n = W * H
    # the channels as float32 planes, written in place by the kernel (no conversion pass)
    planes = np.empty((len(CHANNELS), n), dtype=np.float32)
    covered = np.zeros(tasks.thread_count(), np.int64)
    lights = np.array(
        [[*l.direction, *(np.asarray(l.color) * l.intensity)] for l in scene.lights],
        dtype=np.float64,
    ).reshape(-1, 6)
    headlight = np.array([scene.render.headlight_intensity if scene.render.headlight else 0.0])
    g, q = pools.a, iso.a
    shade_kernel(
        camera_frame(camera), W, hits, g["slot_patch"], g["slot_depth"], g["slot_quad"],
        g["slot_vert_off"], g["verts"], g["normals"], tables.lc_off, tables.lc_data,
        tables.uv_off, tables.uv_data, table.object_id, table.ptex, table.ptex_uv0,
        table.ptex_scale, table.level0, _patch_colors(table, scene), q["kind"], q["ref"],
        q["level"], q["i0"], q["j0"], q["nets"], q["normals"], q["cells"], lights, headlight,
        miss_values(scene.render.background), planes, covered,
    )
    stats.pixels_covered = int(covered.sum())
    channels = {name: planes[k].reshape(H, W) for k, name in enumerate(CHANNELS)}
    stats.time_shade = time.perf_counter() - t0
    stats.time_total = time.perf_counter() - t_start
    schemes = tuple(c.scheme for c in cages)
    refined = table.object_id[built]
    used = "bvh" if stats.accel_fallback else accel
    return RenderResult(channels, stats, camera, tol_rad, schemes, refined, used)


def result_attributes(result: RenderResult, scene) -> dict:
    """EXR header attributes of a render: camera, tolerance, schemes, timings and counts."""
    attrs = dict(result.camera.header_attributes())
    attrs["subtrace:tolerance_rad"] = float(result.tolerance_rad)
    attrs["subtrace:tolerance_px"] = float(result.tolerance_rad / result.camera.pixel_angle())
    attrs["subtrace:scheme"] = ",".join(result.schemes)
    attrs["subtrace:meshes"] = ";".join(o.mesh for o in scene.objects)
    attrs["subtrace:accel"] = result.accel
    for k, v in result.stats.__dict__.items():
        attrs[f"subtrace:{k}"] = float(v) if isinstance(v, float) else int(v)
    return attrs
