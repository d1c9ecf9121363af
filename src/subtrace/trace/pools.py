"""What the trace kernels read and grow between rounds: growable stores with named kernel views.

* :class:`Pieces`: every patch built so far, as the kernels intersect it per ray. A *slot*
  per patch (its first item, item count, the round it was built in, whether a ray has
  tested it) and its *items* (contiguous): regular Bezier pieces over dyadic squares of the
  patch, and cells of exact limit points, each with its grid depth and how its four sides
  are sampled; for Loop patches, quartic triangular nets over dyadic sub-triangles and
  triangular cells (``geometry/tris.py``). A regular Catmull-Clark patch is one item, ready
  from the start (round -1); a regular Loop patch is one net, an irregular patch of either
  scheme several items (``patches/isolate.py``, ``patches/isolate_loop.py``), built on
  request. Kernel view: :class:`PieceArrays`.
* :class:`Memos`: each thread's memo of the Bezier nets its rays split
  (``geometry/bezier.py``); kernel view: one :class:`Memo` per thread.
* :class:`Candidates`: per ray, the unbuilt shells it entered before its best hit.
* :class:`Hits`: per ray, the closest hit (see its fields).

Kernel views are named tuples of arrays: Numba passes them as one argument and reads their
fields by name at no cost, so no kernel reads a bundle by position.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from subtrace import config
from subtrace.accel.projection import TILE
from subtrace.patches.basis import BOX_PAD, net_bounds
from subtrace.geometry.kinds import BEZIER, CELL, GROUP, LOOP_CELL, TRI
from subtrace.patches.groups import grouped_layout
from subtrace.patches.isolate import item_sides, packed_order, rows_in_order
from subtrace.geometry.bezier import M_CELLS, M_FULL, M_NETS, M_NODES
from subtrace.geometry.snap import snap_items
from subtrace.geometry.prims import (
    M_COUNTS, M_MADE, M_PEAK_CELLS, M_PEAK_NETS, M_PEAK_NODES, memo_restart,
)
from subtrace.runtime.jit import nb
from subtrace.runtime.memory import one_block, small_pages
from subtrace.patches.isolate_loop import sample_ranges, side_samples
from subtrace.geometry.tris import tri_nets_as_pieces

CANDIDATES = 4  # unbuilt shells a ray remembers between rounds (more: it traverses again)


class PieceArrays(NamedTuple):
    """The kernels' view of :class:`Pieces` (P patches, S slots, I items)."""

    patch_iso: np.ndarray  # (P,) int64: slot of each patch, -1 while unbuilt
    first: np.ndarray  # (S,) int64: first item of the slot
    count: np.ndarray  # (S,) int64: its item count
    round: np.ndarray  # (S,) int64: round it was built in (-1: from the start)
    # (S,4) int64: first row in ``samples`` of each snapped side's samples, -1 where the
    # side is not snapped (a Catmull-Clark patch's: ``geometry/snap.py``)
    snap: np.ndarray
    depth_i: np.ndarray  # (I,) int64: grid depth, in the patch's units
    side: np.ndarray  # (I,4) int64: sampling depth of each side, in the patch's units
    # (I,) int8: 0 Bezier piece, 1 cell, 2 (TRI) Loop triangular net, 3 (LOOP_CELL) Loop cell,
    # 4 (GROUP) a group of the rows after it (``patches/groups.py``)
    kind: np.ndarray
    # (I,) int64: row in nets (piece) or cells (cell, 4 rows each); a group's row span
    ref: np.ndarray
    level: np.ndarray  # (I,) int64: the item's level
    i0: np.ndarray  # (I,) int64: origin in units of 2^-level
    j0: np.ndarray  # (I,) int64
    lo: np.ndarray  # (I,3) float64: the item's box (a group's: of its items)
    hi: np.ndarray  # (I,3) float64
    nets: np.ndarray  # (., 4, 4, 3) float64: Bezier nets
    cells: np.ndarray  # (., 3) float64: cell corners, 4 rows per cell
    cell_normals: np.ndarray  # (., 4, 3) float64: exact limit normals at the corners
    touched: np.ndarray  # (S,) uint8: set when a ray tests the slot
    orient: np.ndarray  # (I,) int8: a Loop item's orientation, +1 upright, -1 turned
    # (., 3) float64: exact samples of snapped sides (isolated Loop patches', and the
    # Catmull-Clark patches' of ``snap``)
    samples: np.ndarray
    # (., 16, 3) float64: ``nets`` read as Loop items' triangular nets (geometry/tris.py),
    # a view made once: a reshape in a kernel calls into Numba's runtime, and the shading
    # made one per Loop hit (1-2 % of a Loop render's samples in perf)
    tri_nets: np.ndarray


class Memo(NamedTuple):
    """One thread's memo of split Bezier nets (``geometry/bezier.py`` says what it holds)."""

    root: np.ndarray  # (I,) int64: root node of each item or -1
    child: np.ndarray  # (N,) int64: first of the four children of each node, or -1
    box: np.ndarray  # (N,6) float64: each node's padded box
    # (N,6) float64: a block's slab (normal and range; any-hit rays': every node's); a
    # Loop root's bound; column 5: a Catmull-Clark node's own bound (its frame's,
    # bezier._interpolation_bound) where it is a root block or any-hit rays test it
    slab: np.ndarray
    data: np.ndarray  # (N,) int64: each node's row in nets / cells, or a state code
    nets: np.ndarray  # (., 4, 4, 3) float64
    cells: np.ndarray  # (., 3) float64: cell corners, 4 rows per cell
    cnt: np.ndarray  # (4,) int64: nodes, nets and cells used; a flag set when one ran out


class Candidates(NamedTuple):
    """Per ray, the unbuilt shells it entered before its best hit: a ray traced again after
    they are built tests just those instead of traversing again.

    Only a ray that enters an unbuilt shell has a list. With projection tiles
    (``accel/projection``) those are the rays of tiles that list a shell, so the lists have
    rows for those tiles alone: ``tile_row[k]`` is tile k's first row (its ``TILE`` x
    ``TILE`` pixels row by row from there), -1 for a tile that lists none. Without tiles
    (``tile_row`` empty) ray r's row is r. (osd_catmark_nonquads at 1280x720: 152,156 rows
    instead of 921,600.) A render traced band by band, for its memory, gives rows only to
    the tiles whose list holds a patch still unbuilt (their rays meet built patches only
    and never ask for a build; a ray without a row that did would traverse its tile again):
    the tip of the sword refined twice, 5,560 rows in all its bands instead of 266,632.
    (Gathering the lists' flags took 17 ms of a render of gen_vase_loop, whose tiles list
    1.9 million entries: a render traced whole does without.)"""

    patch: np.ndarray  # (R, CANDIDATES) int32
    t: np.ndarray  # (R, CANDIDATES) float64: entry distances
    count: np.ndarray  # (R,) int8: how many, or -1 when there were more than CANDIDATES
    # (P,) uint8: 1 for each patch to build after the round (``trace/kernels.py``): the
    # rays' requests and the unbuilt shells they enter within their requests' reach
    wanted: np.ndarray
    tile_row: np.ndarray  # (T,) int64: each tile's first row, or -1; empty: ray r's row is r


class Hits(NamedTuple):
    """Per ray (pixel), its closest hit. A miss has t = inf and prim = -1 (nothing else is
    written for it)."""

    t: np.ndarray  # (R,) float64: distance from the eye along the unit direction
    prim: np.ndarray  # (R,) int32: -2 - the patch hit (-1: none)
    leaf: np.ndarray  # (R,) int32: the grid depth of the item hit (in its patch's units)
    item: np.ndarray  # (R,) int32: the item hit
    a: np.ndarray  # (R,) float64: the patch parameter u
    b: np.ndarray  # (R,) float64: the patch parameter v


def candidate_lists(n_rays: int, n_patches: int = 0, tiles=None, unbuilt=None) -> Candidates:
    """Empty candidate lists (round 0 sets every list it uses) among ``n_patches`` patches:
    for ``n_rays`` rays, or with ``tiles`` (the projection's :class:`Tiles`, its ``off``
    perhaps a window's), for the pixels of the tiles that list a patch for which
    ``unbuilt`` (P,) is true (None: any patch) (:class:`Candidates`)."""
    tile_row = np.zeros(0, np.int64)
    if tiles is not None and len(tiles.off) > 1:
        off = tiles.off
        listed = off[1:] != off[:-1]
        if unbuilt is not None and listed.any():  # (the window's entries, from its first)
            has = np.maximum.reduceat(unbuilt.view(np.uint8)[tiles.items[off[0]:off[-1]]],
                                      off[:-1][listed] - off[0])
            listed[listed] = has > 0
        tile_row = np.cumsum(listed) - 1
        n_rays = (int(tile_row[-1]) + 1) * TILE * TILE
        tile_row *= TILE * TILE
        tile_row[~listed] = -1
    return Candidates(np.empty((n_rays, CANDIDATES), np.int32),
                      np.empty((n_rays, CANDIDATES)), np.empty(n_rays, np.int8),
                      np.zeros(n_patches, np.uint8), tile_row)


# the dtypes of :class:`Hits`' fields: the ids and the depth as int32 (patches and items
# number far fewer than 2^31), 12 bytes a pixel fewer to touch than int64 (readers widen
# them before arithmetic)
_HIT_DTYPES = (np.float64, np.int32, np.int32, np.int32, np.float64, np.float64)


def hit_arrays(n_rays: int) -> Hits:
    """Hit records for ``n_rays`` rays (round 0 sets every ray's), in one allocation
    (``runtime.memory.one_block``)."""
    return Hits(*one_block(*(((n_rays,), d) for d in _HIT_DTYPES)))


def round_arrays(n_rays: int) -> tuple[Hits, np.ndarray]:
    """The rounds' per-ray arrays: the hit records (:func:`hit_arrays`) and the int32
    request of each ray, in one allocation."""
    *fields, request = one_block(*(((n_rays,), d) for d in _HIT_DTYPES + (np.int32,)))
    return Hits(*fields), request


def grown(a, n_used, size, small=False):
    """``a`` with room for ``size`` rows (``np.empty``: pages are touched as used; ``small``:
    in small pages, ``runtime.memory.small_pages``), its first ``n_used`` rows copied."""
    b = np.empty((size, *a.shape[1:]), a.dtype)
    if small:
        small_pages(b)
    b[:n_used] = a[:n_used]
    return b


class Growable:
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

    def adopt(self, group, used, **stores):
        """Take ``stores`` (name -> array, one per name of ``group``, which must be empty)
        as the group's storage, their first ``used`` rows already filled: no copy (e.g. the
        patch table's nets, made with room after them for what is appended later)."""
        assert self._used[group] == 0 and set(stores) == set(self.GROUPS[group])
        for name, store in stores.items():
            self._store[name] = store
        self._used[group] = int(used)
        self._refresh()

    def _grow(self, group, end):
        start = self._used[group]
        for name in self.GROUPS[group]:
            buf = self._store[name]
            if end > len(buf):
                self._store[name] = grown(buf, start, max(end, 2 * len(buf)))

    def room(self, group, n):
        """Append ``n`` rows to every array of ``group``, unwritten (the caller writes them
        all, in ``self._store``); returns the first new row."""
        start = self._used[group]
        self._grow(group, start + n)
        self._used[group] = start + n
        self._refresh()
        return start

    def put(self, group, order=None, **values):
        """Append rows to every array of ``group`` (zeros where no value is given); returns
        the first new row. A value may be a list of arrays, whose rows are taken one after
        another, or with ``order`` in that order (row k is their row ``order[k]``: each is
        written once, at its place)."""
        start = self._used[group]
        first = next(iter(values.values()))
        end = start + (sum(len(a) for a in first) if isinstance(first, list) else len(first))
        self._grow(group, end)
        at = None
        if order is not None:
            at = np.empty(len(order), np.int64)
            at[order] = np.arange(start, end)
        for name in self.GROUPS[group]:
            value = values.get(name, 0)
            if not isinstance(value, list):
                self._store[name][start:end] = value
                continue
            whole = self._store[name]
            width = int(np.prod(whole.shape[1:]))  # (not -1: a store or a part may be empty)
            store = whole.reshape(len(whole), width)
            row = start if at is None else 0
            for a in value:
                n = len(a)
                if at is None:
                    store[row:row + n] = a.reshape(n, width)
                else:
                    store[at[row:row + n]] = a.reshape(n, width)
                row += n
        self._used[group] = end
        self._refresh()
        return start


class Pieces(Growable):
    """Every patch built so far, in slots of items (module doc)."""

    GROUPS = {
        "slots": {"patch": ((), np.int64), "first": ((), np.int64), "count": ((), np.int64),
                  "round": ((), np.int64), "snap": ((4,), np.int64), "touched": ((), np.uint8)},
        "items": {"kind": ((), np.int8), "ref": ((), np.int64), "level": ((), np.int64),
                  "i0": ((), np.int64), "j0": ((), np.int64), "depth_i": ((), np.int64),
                  "side": ((4,), np.int64), "lo": ((3,), np.float64),
                  "hi": ((3,), np.float64), "orient": ((), np.int8)},
        "nets": {"nets": ((4, 4, 3), np.float64)},
        "cells": {"cells": ((4, 3), np.float64), "normals": ((4, 3), np.float64)},
        "samples": {"samples": ((3,), np.float64)},
    }

    def __init__(self, n_patches):
        super().__init__()
        self.patch_iso = np.full(n_patches, -1, dtype=np.int64)

    def append(self, patches, depth, side, subs, cells, round_no):
        """Slots for ``patches`` (grid depths ``depth`` (m,), how their sides are sampled
        ``side`` (m,4)) made of ``subs`` and ``cells`` (see
        :func:`~subtrace.patches.isolate.build_isolated`; or its lists as they were made,
        :func:`~subtrace.patches.isolate.isolated_parts`, whose nets, cell corners and
        normals are then written once, into the store at their places, not put in order
        first); each piece samples its sides as finely as the pieces beside it
        (:func:`~subtrace.patches.isolate.item_sides`)."""
        net_at = cell_at = None  # (the row of each piece's net, cell's corners, as made)
        if isinstance(subs[0], list):
            subs, cells, net_at, cell_at = _in_order(subs, cells)
        (sr, sl, si, sj, nets, sd, lo_s, hi_s), (cr, ci, cj, cp, cn) = subs, cells[:5]
        root = np.concatenate([sr, cr])
        order = np.argsort(root, kind="stable")
        level = np.r_[sl, depth[cr]][order]
        i0, j0 = np.r_[si, ci][order], np.r_[sj, cj][order]
        depth_i = np.r_[sd, depth[cr]][order].astype(np.int64)
        count = np.bincount(root, minlength=len(patches))
        first = np.cumsum(count) - count
        item_side = np.empty((len(root), 4), np.int64)
        patch_side = np.ascontiguousarray(np.asarray(side).reshape(-1, 4), dtype=np.int64)
        item_sides(first, count, level, i0, j0, depth_i, patch_side, item_side)
        # a Bezier piece is raised to within FAN_LEVELS of the pieces beside it, so its
        # fans keep within MAX_SIDE_SAMPLES (a raised piece may raise its neighbours' sides)
        piece = np.r_[np.ones(len(sr), bool), np.zeros(len(cr), bool)][order]
        while True:
            low = item_side.max(axis=1, initial=0) - config.FAN_LEVELS
            up = piece & (depth_i < low)
            if not up.any():
                break
            depth_i[up] = low[up]
            item_sides(first, count, level, i0, j0, depth_i, patch_side, item_side)
        # (the nets and corners as made go to their places in order: each patch's together)
        n0 = self.put("nets", net_at, nets=nets)
        c0 = self.put("cells", cell_at, cells=cp, normals=cn)
        # (the cells' boxes from the store, where their corners lie in order now: one
        # reduction, not one per array as made and a scatter of the results)
        placed = self.a["cells"][c0:c0 + len(cr)]
        c_lo, c_hi = placed.min(axis=1, initial=np.inf), placed.max(axis=1, initial=-np.inf)
        lo = np.concatenate([lo_s, c_lo])[order]
        hi = np.concatenate([hi_s, c_hi])[order]
        is_cell = np.r_[np.zeros(len(sr), bool), np.ones(len(cr), bool)][order]
        ref = np.r_[n0 + np.arange(len(sr)), c0 + np.arange(len(cr))][order]
        # sides snapped onto a coarser neighbour's polyline (their cells' corners moved)
        snap = self._snapped(first, count, is_cell, ref, level, i0, j0, depth_i, patch_side,
                             lo, hi)
        i_start, first, count = self._put_grouped(
            root[order], None, kind=np.where(is_cell, CELL, BEZIER).astype(np.int8), ref=ref,
            level=level, i0=i0, j0=j0, depth_i=depth_i, side=item_side, lo=lo, hi=hi,
            orient=np.ones(len(root), np.int8))
        s0 = self.put("slots", patch=patches, first=i_start + first, count=count,
                      round=np.full(len(patches), round_no), snap=snap)
        self.patch_iso[patches] = s0 + np.arange(len(patches))
        return len(sr), len(cr)

    def append_regular(self, patches, depth, side, nets, lo, hi):
        """Slots for regular patches, one Bezier piece each (the whole patch): what
        :meth:`append` makes of them, without its general work. ``lo``, ``hi``: their nets'
        boxes (the patch table's shells). ``nets``: their nets, or None when they are the
        first rows of the net store already (:meth:`adopt`)."""
        m = len(patches)
        z = np.zeros(m, np.int64)
        ar = np.arange(m, dtype=np.int64)
        n0 = 0 if nets is None else self.put("nets", nets=nets)
        side = np.ascontiguousarray(np.asarray(side).reshape(-1, 4), dtype=np.int64)
        depth = np.asarray(depth, dtype=np.int64)
        lo, hi = np.array(lo, dtype=np.float64), np.array(hi, dtype=np.float64)
        snap = self._snapped(ar, np.ones(m, np.int64), np.zeros(m, bool), n0 + ar, z, z, z,
                             depth, side, lo, hi)
        i_start = self.put("items", kind=np.full(m, BEZIER, np.int8), ref=n0 + ar, level=z, i0=z,
                           j0=z, depth_i=depth, side=side, lo=lo, hi=hi,
                           orient=np.ones(m, np.int8))
        s0 = self.put("slots", patch=patches, first=i_start + ar, count=np.ones(m, np.int64),
                      round=np.full(m, -1), snap=snap)
        self.patch_iso[patches] = s0 + ar

    def append_tris(self, patches, depth, side, nets, round_no):
        """Slots for regular Loop patches built in round ``round_no``, one triangular net
        each (item kind ``geometry.tris.TRI``; ``nets`` (m,4,4,3) from
        :func:`~subtrace.geometry.tris.tri_nets_as_pieces`), grid depths ``depth`` (m,) and
        the sampling depth of each side's edge ``side`` (m,4) (-1: none)."""
        m = len(patches)
        z = np.zeros(m, np.int64)
        ar = np.arange(m, dtype=np.int64)
        lo, hi = nets.min(axis=(1, 2)), nets.max(axis=(1, 2))
        pad = BOX_PAD * np.maximum(np.abs(lo), np.abs(hi)).max(axis=1, keepdims=True)
        lo, hi = lo - pad, hi + pad  # (widened for rounding, as basis.net_box)
        n0 = self.put("nets", nets=nets)
        i_start = self.put("items", kind=np.full(m, TRI, np.int8), ref=n0 + ar, level=z, i0=z,
                           j0=z, depth_i=depth, side=side, lo=lo, hi=hi,
                           orient=np.ones(m, np.int8))
        s0 = self.put("slots", patch=patches, first=i_start + ar, count=np.ones(m, np.int64),
                      round=np.full(m, round_no), snap=-1)
        self.patch_iso[patches] = s0 + ar

    def append_loop(self, patches, depth, side, subs, cells, round_no):
        """Slots for irregular Loop patches isolated to grid depths ``depth`` (m,) in round
        ``round_no``: ``subs`` and ``cells`` from
        :func:`~subtrace.patches.isolate_loop.build_loop_isolated` (pieces: item kind
        ``TRI``, traced per ray; cells: ``LOOP_CELL``), ``side`` (m,3) the sampling depth
        of each side's edge (-1: none). A side sampled more coarsely than ``depth`` is
        snapped onto the coarse polyline through its exact samples
        (:func:`~subtrace.patches.isolate_loop.side_samples`, kept in ``samples``). Items
        go depth first in the patch's split tree, with group rows (:meth:`_put_grouped`).
        Returns the numbers of pieces and cells."""
        (sr, sl, si, sj, sg, nets15), (cr, ci, cj, cg, cp, cn) = subs, cells
        side = np.asarray(side, dtype=np.int64).reshape(-1, 3)
        depth = np.asarray(depth, dtype=np.int64)
        samples, offset = side_samples(depth, side, subs, cells)  # (moves cp's corners)
        s_lo, s_hi = sample_ranges(subs, cells, depth, side, offset, samples)
        nets = tri_nets_as_pieces(nets15)
        cp4 = np.concatenate([cp, cp[:, 2:3]], axis=1)  # (4 rows a cell; the 4th repeats)
        cn4 = np.concatenate([cn, cn[:, 2:3]], axis=1)
        # (the nets' boxes by a kernel: NumPy's reduction over 16 points of 3 coordinates
        # each took 0.35 us a net, about 5 ms of a render of osd_loop_icos_semisharp)
        n_lo, n_hi, _ = net_bounds(nets)
        lo = np.concatenate([n_lo, cp.min(axis=1)])
        hi = np.concatenate([n_hi, cp.max(axis=1)])
        lo, hi = np.minimum(lo, s_lo), np.maximum(hi, s_hi)
        pad = BOX_PAD * np.maximum(np.abs(lo), np.abs(hi)).max(axis=1, keepdims=True)
        lo, hi = lo - pad, hi + pad  # (widened for rounding, as basis.net_box)
        root = np.r_[sr, cr]
        s0 = self.put("samples", samples=samples) if len(samples) else 0
        item_side = np.empty((len(root), 4), np.int64)
        item_side[:, :3] = side[root]
        item_side[:, 3] = np.where(offset >= 0, s0 + offset, -1)[root]
        n0 = self.put("nets", nets=nets)
        c0 = self.put("cells", cells=cp4, normals=cn4)
        i_start, first, count = self._put_grouped(
            root, np.r_[sg, cg],
            kind=np.r_[np.full(len(sr), TRI, np.int8), np.full(len(cr), LOOP_CELL, np.int8)],
            ref=np.r_[n0 + np.arange(len(sr)), c0 + np.arange(len(cr))],
            level=np.r_[sl, depth[cr]], i0=np.r_[si, ci], j0=np.r_[sj, cj],
            depth_i=depth[root], side=item_side, lo=lo, hi=hi,
            orient=np.r_[sg, cg].astype(np.int8))
        s0 = self.put("slots", patch=patches, first=i_start + first, count=count,
                      round=np.full(len(patches), round_no), snap=-1)
        self.patch_iso[patches] = s0 + np.arange(len(patches))
        return len(sr), len(cr)

    def _snapped(self, first, count, is_cell, ref, level, i0, j0, depth_i, side, lo, hi):
        """The ``snap`` rows (m,4) of a batch of Catmull-Clark slots whose items (rows of
        ``first``, ``count``; their nets and cells in the stores at ``ref``) sample their
        sides as ``side`` (m,4) says: the samples of the snapped ones go to the sample
        store, the cells' corners there are moved onto the polylines and the items' boxes
        ``lo``, ``hi`` set to hold what they test (:func:`~subtrace.geometry.snap.snap_items`)."""
        samples, offset = snap_items(first, count, is_cell, ref, level, i0, j0, depth_i, side,
                                     self.a["nets"], self.a["cells"].reshape(-1, 3), lo, hi)
        if not len(samples):
            return np.full((len(first), 4), -1, np.int64)
        s0 = self.put("samples", samples=samples)
        return np.where(offset >= 0, offset + s0, -1)

    def _put_grouped(self, root, split_orient, **items):
        """Append the items of a batch of isolated patches (item k of patch ``root[k]``)
        depth first in each patch's split tree, with their group rows
        (:func:`~subtrace.patches.groups.grouped_layout`; ``split_orient``: the
        sub-triangles' orientations, None for sub-squares). Returns (first new row, each patch's first
        row relative to it, its row count)."""
        take, g_level, g_lo, g_hi, g_span, first, count = grouped_layout(
            root, items["level"], items["i0"], items["j0"], split_orient, items["lo"],
            items["hi"])
        # (straight into the store: no array of the rows first, copied in after)
        start = self.room("items", len(take))
        g_values = {"kind": GROUP, "ref": g_span, "level": g_level, "lo": g_lo, "hi": g_hi,
                    "side": -1, "orient": 1}
        n_g = len(g_level)
        for name, (shape, dtype) in self.GROUPS["items"].items():
            rows = self._store[name][start:start + len(take)]
            src = np.broadcast_to(np.asarray(items[name], dtype), (len(root),) + shape)
            g_src = np.broadcast_to(np.asarray(g_values.get(name, 0), dtype), (n_g,) + shape)
            _take_rows(_as_bytes(rows), _as_bytes(np.ascontiguousarray(src)),
                       _as_bytes(np.ascontiguousarray(g_src)), take)
        return start, first, count

    def item_boxes(self, patches):
        """(lo (n,3), hi (n,3)): per built patch of ``patches``, the union of its items'
        boxes, which hold everything a ray tests of it."""
        slot = self.patch_iso[patches]
        first, count = self.a["first"][slot], self.a["count"][slot]
        starts = np.cumsum(count) - count
        rows = np.repeat(first - starts, count) + np.arange(int(count.sum()))
        return (np.minimum.reduceat(self.a["lo"][rows], starts),
                np.maximum.reduceat(self.a["hi"][rows], starts))

    def view(self) -> PieceArrays:
        a = self.a
        return PieceArrays(self.patch_iso, a["first"], a["count"], a["round"], a["snap"],
                           a["depth_i"],
                           a["side"], a["kind"], a["ref"], a["level"], a["i0"], a["j0"],
                           a["lo"], a["hi"], a["nets"],
                           a["cells"].reshape(-1, 3), a["normals"], a["touched"], a["orient"],
                           a["samples"], a["nets"].reshape(-1, 16, 3))


_NO_BOX = np.zeros((0, 3))


def _as_bytes(a):
    """The rows of ``a`` (n, ...) as bytes (n, row bytes): a view."""
    return a.reshape(len(a), int(np.prod(a.shape[1:]))).view(np.uint8)


@nb.njit(cache=True, nogil=True)
def _take_rows(out, items, groups, take):
    """Row r of ``out`` (rows as bytes, :func:`_as_bytes`) from row ``take[r]`` of
    ``items``, or where that is negative from the next row of ``groups``: the gathers and
    scatters of ``Pieces._put_grouped`` in one pass a field (in NumPy: 19 ms of the chess
    pieces' 6 builds)."""
    g = 0
    width = out.shape[1]
    for r in range(len(take)):
        if take[r] >= 0:
            k = take[r]
            for b in range(width):
                out[r, b] = items[k, b]
        else:
            for b in range(width):
                out[r, b] = groups[g, b]
            g += 1


def _in_order(subs, cells):
    """``(subs, cells, net_at, cell_at)``: :func:`~subtrace.patches.isolate.isolated_parts`'
    lists as :func:`~subtrace.patches.isolate.build_isolated`'s arrays in order, but the
    nets, the cells' corners and normals left as lists as made (``net_at``, ``cell_at``:
    the row in those of each piece and cell in order, for ``Growable.put``)."""
    order, cell_order = packed_order(subs, cells)
    empty = np.zeros(0, np.int64)
    subs = tuple(a if k == 4 else rows_in_order(a, order) if a else
                 (_NO_BOX if k >= 6 else empty) for k, a in enumerate(subs))
    cells = tuple(a if k in (3, 4) else rows_in_order(a, cell_order) if a else empty
                  for k, a in enumerate(cells))
    return subs, cells, order, cell_order


class Memos:
    """Each thread's memo of the Bezier nets its rays split (``geometry.bezier``: item roots,
    node children, boxes and rows, the net store, the cell-corner store, counts). The stores
    are allocated lazily by the OS (``np.empty``); one that ran out during a round (its rays
    went on without storing) is doubled before the next."""

    # virtual: touched as used. A Catmull-Clark memo keeps the net of every node its rays
    # split but those whose children are blocks (their blocks' frames instead) and the
    # corners of its blocks of 2 x 2 cells (geometry/bezier.py); a Loop memo
    # the six points of every node split (two cells' room in the cell store, geometry/tris.py)
    START = {"child": 1 << 22, "nets": 1 << 21, "cells": 1 << 20}
    # rows per unit of START (a cell has 4 corner rows) and bytes per row: a node (child,
    # box, slab, data), a net, a cell corner
    ROWS = {"child": 1, "nets": 1, "cells": 4}
    ROW_BYTES = {"child": 8 + 48 + 48 + 8, "nets": 4 * 4 * 3 * 8, "cells": 3 * 8}
    MIN_ROWS = 64  # rows of a store at least, whatever the budget

    def __init__(self, n_threads, max_bytes=None):
        # each store at most its share (that of START) of max_bytes per thread
        start = {k: self.START[k] * self.ROWS[k] for k in self.START}
        total = sum(start[k] * self.ROW_BYTES[k] for k in start)
        self.max_rows = {k: (None if max_bytes is None else
                             max(self.MIN_ROWS, int(max_bytes * start[k] / total)))
                         for k in start}
        self.max_bytes = max_bytes
        self.m = [self._grow(None, 0, "child", "nets", "cells") for _ in range(n_threads)]
        self.full = 0

    def _rows(self, name, current):
        """Rows of store ``name`` after a growth from ``current`` rows: double (at least
        START), within the budget's share."""
        n = max(2 * current, self.START[name] * self.ROWS[name])
        cap = self.max_rows[name]
        return n if cap is None else max(current, min(n, cap))

    def _grow(self, old, n_items, *which) -> Memo:
        """A memo with room for ``n_items`` items, the stores named in ``which`` doubled."""
        if old is None:
            # (the counts, stored at every split, on a cache line of their own, not one
            # that another thread's arrays may share)
            cnt = one_block(((M_COUNTS,), np.int64))[0]
            cnt[:] = 0
            old = Memo(np.full(0, -1, np.int64), np.empty(0, np.int64), np.empty((0, 6)),
                       np.empty((0, 6)), np.empty(0, np.int64), np.empty((0, 4, 4, 3)),
                       np.empty((0, 3)), cnt)
        root, child, box, slab, data, nets, cells, cnt = old
        if len(root) < n_items:
            root = np.concatenate([root, np.full(max(n_items, 2 * len(root)) - len(root), -1)])
        n = self._rows("child", len(child))
        if "child" in which and n > len(child):
            used = cnt[M_NODES]
            child, box, slab, data = (grown(child, used, n, True), grown(box, used, n, True),
                                      grown(slab, used, n, True), grown(data, used, n, True))
        n = self._rows("nets", len(nets))
        if "nets" in which and n > len(nets):
            nets = grown(nets, cnt[M_NETS], n, True)
        n = 4 * (self._rows("cells", len(cells)) // 4)
        if "cells" in which and n > len(cells):
            cells = grown(cells, 4 * cnt[M_CELLS], n, True)
        cnt[M_FULL] = 0
        return Memo(root, child, box, slab, data, nets, cells, cnt)

    def views(self, n_items) -> tuple:
        """One :class:`Memo` per thread with room for ``n_items`` items (a store that ran
        out during the last round doubled)."""
        # every memo grows when one ran out: a chunk of rays finds the same room on any
        # thread, so its work and counts do not depend on which thread took it
        full = any(m.cnt[M_FULL] for m in self.m)
        for k, m in enumerate(self.m):
            self.full += int(m.cnt[M_FULL])
            if full or len(m.root) < n_items:
                self.m[k] = self._grow(m, n_items, *(("child", "nets", "cells")
                                                     if full else ()))
        return tuple(self.m)

    def finish(self, stats):
        """Count what the memos made and held into ``stats``: memo_nodes (nodes made over
        every chunk of rays), memo_bytes (the most each memo held at once, summed over the
        threads), memo_full."""
        for m in self.m:
            # (folds what the last chunk held; the function's Python, not a kernel to load)
            memo_restart.py_func(m.root, m.cnt)
        stats.memo_nodes = int(sum(m.cnt[M_MADE] for m in self.m))
        stats.memo_bytes = int(sum(
            m.cnt[M_PEAK_NODES] * self.ROW_BYTES["child"]
            + m.cnt[M_PEAK_NETS] * self.ROW_BYTES["nets"]
            + 4 * m.cnt[M_PEAK_CELLS] * self.ROW_BYTES["cells"] for m in self.m))
        stats.memo_full = self.full + int(sum(m.cnt[M_FULL] for m in self.m))
