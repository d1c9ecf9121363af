"""The refinement criterion: each patch's grid depth from the eye, and the memory it costs.

A grid cell of a patch at depth ``n`` is no longer than ``edge_bound * rate^n``
(:mod:`subtrace.patches.table`); :func:`choose_depths` takes the smallest ``n`` at which
that is within ``tol_rad`` (radians) times the distance from the eye to the patch's shell
(design invariant 3), isolating irregular Catmull-Clark patches for a tighter answer
(:mod:`subtrace.patches.isolate`). :func:`memory_estimate` and :func:`depth_cap` bound the
render's memory for those depths, :func:`edge_sampling` makes both sides of every edge
sample it alike (design invariant 4). Depths are (P,) int32 per patch of the table.
"""

from __future__ import annotations

import numpy as np

from subtrace import config
from subtrace.patches.crease import CELLS_AT_ANY_DEPTH, cell_free_depths
from subtrace.patches.isolate import isolated_depths
from subtrace.patches.shells import eye_point, sight_distance
from subtrace.runtime.jit import nb
from subtrace.subdiv import catmark, loop


INT32_MAX = 2**31 - 1  # np.iinfo(np.int32).max


def subdominant(valence: np.ndarray, quad: bool) -> np.ndarray:
    """Per-level contraction of control edges at a vertex of this valence (at least 1/2)."""
    scheme = catmark if quad else loop
    return np.maximum(scheme.subdominant_eigenvalue(np.maximum(valence, 3)), 0.5)


def wanted_depths(table, eye, tol_rad: float) -> np.ndarray:
    """(P,) float64: the conservative depth each patch's tolerance asks for, uncapped (the
    smallest n with ``edge_bound * rate^n`` at most ``tol_rad`` times the distance from
    the eye to the shell: ``shells.sight_distance``, ``eye`` a point or a ``Sight``); inf
    where the eye is inside the shell."""
    d = sight_distance(table.shell_min, table.shell_max, eye)
    allowed = d * tol_rad
    with np.errstate(divide="ignore", invalid="ignore"):
        n = np.log(allowed / table.edge_bound) / np.log(table.rate)
    n = np.where(allowed >= table.edge_bound, 0.0, np.ceil(n - 1e-9))
    return np.where(np.isnan(n), np.inf, n)


def precision_depths(table, eye: np.ndarray) -> np.ndarray:
    """(P,) int32: the deepest grid each patch can be refined to before its cells fall below
    what double precision resolves at its coordinates (``config.PRECISION_BITS``): cells of
    a patch of extent ``e`` (its shell's diagonal) are about ``e * 2^-n`` at depth ``n``,
    kept at least ``2^-PRECISION_BITS`` of the largest coordinate magnitude of its shell and
    the eye. At most ``PRECISION_BITS + 2`` (the extent is at most ``2 sqrt(3)`` times that
    magnitude); 0 for a patch of no extent."""
    lo, hi = table.shell_min, table.shell_max
    extent = np.linalg.norm(hi - lo, axis=1)
    scale = np.maximum(np.maximum(np.abs(lo), np.abs(hi)).max(axis=1, initial=0.0),
                       np.abs(np.asarray(eye_point(eye), dtype=np.float64)).max())
    with np.errstate(divide="ignore", invalid="ignore"):
        n = config.PRECISION_BITS + np.floor(np.log2(extent / scale))
    n = np.where(np.isfinite(n), n, 0.0)
    return np.clip(n, 0, config.PRECISION_BITS + 2).astype(np.int32)


def choose_depths(table, eye: np.ndarray, tol_rad: float, max_depth,
                  record=None, shells=None, max_faces=None, wanted=None):
    """Grid depth of every patch: the smallest n with ``edge_bound * rate^n`` at most
    ``tol_rad`` times the distance from the eye to the patch's shell (:func:`wanted_depths`),
    capped at ``max_depth`` (an int, or (P,) per patch: :func:`precision_depths`); irregular
    quads needing more than depth 0 are then isolated (:mod:`subtrace.patches.isolate`).
    With a dict ``record``, ``record[object id]`` keeps what the isolation made (see
    :func:`~subtrace.patches.isolate.isolated_depths`). ``shells`` = (lo, hi), each (P,3),
    the shells to tighten: an isolated patch's shell becomes the box of what its isolation
    ended in (intersected with its own shell); the others' are left as they are.
    ``max_faces``: the isolations' limit (:func:`~subtrace.patches.isolate.isolated_depths`,
    each object's; :class:`~subtrace.patches.isolate.IsolationTooLarge` past it).
    ``wanted``: :func:`wanted_depths` of these arguments where the caller has them."""
    n = wanted_depths(table, eye, tol_rad) if wanted is None else wanted
    n = np.where(np.isfinite(n), n, max_depth)
    depths = np.clip(n, 0, max_depth).astype(np.int32)
    for oid, o in enumerate(table.objects):
        if o.cage.scheme != "catmark":
            continue
        sel = np.nonzero((table.object_id == oid) & ~table.regular)[0]
        if record is None:
            sel = sel[depths[sel] > 0]
        if len(sel) and depths[sel].max() > 0:
            rec = record.setdefault(oid, {}) if record is not None else None
            boxes = None
            if shells is not None:
                boxes = (np.full((len(sel), 3), np.inf), np.full((len(sel), 3), -np.inf))
            # (the record holds what the depth choice refines, no more: a patch raised
            # later, to a neighbour's depth, is refined further only when a ray asks for
            # it, ``build_isolated``; refining every irregular patch for the record down to
            # the deepest depth made sword's refine 0.049 s, 0.041 s without)
            depths[sel] = isolated_depths(o, table.face[sel], depths[sel], eye, tol_rad, rec,
                                          0, boxes, max_faces)
            if shells is not None:
                done = np.isfinite(boxes[0]).all(axis=1)
                at = sel[done]
                shells[0][at] = np.maximum(shells[0][at], boxes[0][done])
                shells[1][at] = np.minimum(shells[1][at], boxes[1][done])
    return depths


def memory_estimate(table, depths, n_pixels: int, isolated=None) -> int:
    """A conservative estimate (bytes) of a render's memory with grid depths ``depths``:
    the image's per-pixel buffers, the patch table, and every irregular patch isolated to
    its depth, as if rays reached them all. An isolation follows only the irregular
    remainder of its patch, one level at a time (``patches/isolate.py``,
    ``patches/isolate_loop.py``), so it costs per level, not per cell, plus an isolated Loop
    patch's exact side samples (2^depth a side at most). ``isolated`` (P,)
    bool: the patches isolated so (None: the irregular Catmull-Clark ones); the others are
    Bezier nets split per ray (``geometry/bezier.py``, ``geometry/tris.py``), one net and item
    each (in the per-patch figure): what rays split of them lives in the per-thread memos,
    which are kept within what is left (``trace.pools.Memos``), so their depth costs
    nothing here. The constants are ``config.MEMORY_*``."""
    iso = table.is_quad & ~table.regular if isolated is None else isolated
    iso_levels = float((depths[iso].astype(np.float64) + 1.0).sum())
    # an isolated Loop patch keeps the exact samples of each side it snaps onto a coarser
    # neighbour's polyline (``isolate_loop.side_samples``): up to 2^(depth-1) + 1 a side
    d_loop = depths[iso & ~table.is_quad].astype(np.float64)
    side_samples = float((3.0 * (np.exp2(np.maximum(d_loop - 1.0, 0.0)) + 1.0)).sum())
    total = (config.MEMORY_BYTES_PER_PIXEL * float(n_pixels)
             + config.MEMORY_BYTES_PER_PATCH * float(table.n_patches)
             + config.MEMORY_BYTES_PER_ISOLATED_LEVEL * iso_levels
             + config.MEMORY_BYTES_PER_SIDE_SAMPLE * side_samples)
    return int(min(total, 2.0**62))


def depth_cap(table, depths, n_pixels: int, budget: int, isolated=None):
    """The deepest grid depth ``cap`` at which ``np.minimum(depths, cap)`` fits ``budget``
    bytes (:func:`memory_estimate`, ``isolated`` as there), or None when ``depths`` fit as
    they are; -1 when nothing fits (not even depth 0)."""
    if memory_estimate(table, depths, n_pixels, isolated) <= budget:
        return None
    for cap in range(int(depths.max(initial=0)) - 1, -1, -1):
        if memory_estimate(table, np.minimum(depths, cap), n_pixels, isolated) <= budget:
            return cap
    return -1


def edge_sampling(table, depths):
    """Make both sides of every edge sample it alike (design invariant 4); raises ``depths``
    in place and returns ``(edge_depth, side)``.

    * An edge beside an irregular Catmull-Clark patch whose isolation leaves cells of exact
      limit points at its depth (their sides have no points but their corners: they cannot
      fan) is sampled at the coarsest such patch's depth on it; every patch beside it that
      is finer snaps its side onto that polyline (``geometry/snap.py``), every coarser one
      (which fans) is raised to within ``config.FAN_LEVELS`` of it. Such patches are never
      raised. (Raising them to the depth of every neighbour, repeatedly, carried a
      crease's deepest patch along the crease: the chess pieces' cell-bearing
      extraordinary, boundary and crossing-crease patches, 776 of 2,823 irregular ones,
      ended at depth 7, most needing 3 to 4.) Where all of them are deeper than
      ``config.SNAP_MAX_DEPTH`` (a snapped side keeps every sample of the polyline), the
      edge is sampled as any other and they are raised to it, but not past their
      :func:`~subtrace.patches.crease.cell_free_depths`.
    * Any other edge is sampled at the finest patch's depth on it: a patch of Bezier pieces
      alone (a regular patch, intersected directly, or an irregular one refined past its
      semi-sharp creases, :func:`~subtrace.patches.crease.cell_free_depths`) fans its
      cells there and is raised to within ``config.FAN_LEVELS`` of it, so a cell side
      carries at most ``2^FAN_LEVELS`` samples.
    * Loop grids snap a side to the coarsest depth on its edge (``edge_depth``, per edge).

    ``side`` (P,4): the depth at which each patch samples each of its sides, in its own
    units (its depth where the side has no neighbour).

    Depths compare in the units of the edge: a patch of level 1 whose side lies on a side
    of a cage quad patch (``table.side_shift`` 1) samples half of that cage edge, so its
    depth ``d`` samples the edge as depth ``d + 1`` of the cage quad does.
    """
    n_e = max(table.n_edges, 1)
    iso = table.is_quad & ~table.regular
    target = np.empty(table.edges.shape, dtype=np.int64)
    edge_depth = np.empty(n_e, dtype=np.int64)
    _sample_edges(table.edges, table.side_shift, depths, iso, table.regular,
                  cell_free(table, iso), config.FAN_LEVELS, config.SNAP_MAX_DEPTH, target,
                  edge_depth)
    side = np.where(target >= 0, target, depths.astype(np.int64)[:, None])
    return edge_depth, np.ascontiguousarray(side, dtype=np.int64)


def cell_free(table, iso):
    """(P,) int64: per patch, the depth from which its isolation leaves no cell
    (:func:`~subtrace.patches.crease.cell_free_depths` for the ``iso`` patches of
    Catmull-Clark objects; ``CELLS_AT_ANY_DEPTH`` for the rest)."""
    out = np.full(len(iso), CELLS_AT_ANY_DEPTH, np.int64)
    for oid, o in enumerate(table.objects):
        if o.cage.scheme != "catmark":
            continue
        sel = np.nonzero((table.object_id == oid) & iso)[0]
        if len(sel):
            out[sel] = cell_free_depths(o.level, o.cage.options, table.face[sel])
    return out


@nb.njit(cache=True, nogil=True)
def _sample_edges(edges, shift, depths, iso, regular, cell_free, fan_levels, snap_max,
                  target, edge_depth):
    """Raise the patches that fan (``regular`` ones, and ``iso`` ones at or past
    ``cell_free``, from where they have no cells) to within ``fan_levels`` of their edges'
    sampling until none changes (in place): an edge is sampled at the shallowest depth of
    the ``iso`` patches on it that keep cells (never raised), or where there is none, or
    all are deeper than ``snap_max`` (a snapped side keeps ``2^depth + 1`` samples), at the
    deepest depth on it, to which its cell-bearing patches are raised (but not past
    ``cell_free``). Fill each side's sampling (``target``, in the patch's units; -1 where
    the side has no edge) and the shallowest depth per edge (``edge_depth``, in the
    edge's: a patch's depth plus its side's ``shift``)."""
    # (np.empty and a fill, a constant for int32's largest: a cold render compiles neither
    # np.full nor np.iinfo for this kernel alone)
    best = np.empty(len(edge_depth), np.int64)
    best[:] = -1
    cells = np.empty(len(edge_depth), np.int64)  # the shallowest cell-bearing patch
    # a cell-bearing patch samples its edge at least as finely as the half side of a
    # patch of level 1 beside it can (depth 0 there): the only time one is raised below
    # snap_max
    for p in range(len(depths)):
        for k in range(4):
            e = edges[p, k]
            if e >= 0:
                best[e] = max(best[e], shift[p, k])
    for p in range(len(depths)):
        if iso[p] and depths[p] < cell_free[p]:
            for k in range(4):
                e = edges[p, k]
                if e >= 0:
                    depths[p] = max(depths[p], best[e] - shift[p, k])
    best[:] = -1
    for p in range(len(depths)):
        for k in range(4):
            e = edges[p, k]
            if e >= 0:
                best[e] = max(best[e], depths[p] + shift[p, k])
    changed = True
    while changed:
        changed = False
        _shallowest_cells(edges, shift, depths, iso, cell_free, snap_max, cells)
        for p in range(len(depths)):
            keeps = iso[p] and depths[p] < cell_free[p]
            if not (keeps or regular[p] or iso[p]):
                continue
            m = depths[p]
            for k in range(4):
                e = edges[p, k]
                if e < 0:
                    continue
                if keeps:
                    if cells[e] == INT32_MAX:  # sampled at the deepest: raised, no cells
                        m = max(m, min(best[e] - shift[p, k], cell_free[p]))
                else:
                    b = cells[e] if cells[e] < INT32_MAX else best[e]
                    m = max(m, b - shift[p, k] - fan_levels)
            if m > depths[p]:
                depths[p] = m
                changed = True
                for k in range(4):
                    e = edges[p, k]
                    if e >= 0:
                        best[e] = max(best[e], m + shift[p, k])
    edge_depth[:] = INT32_MAX
    for p in range(len(depths)):
        for k in range(4):
            e = edges[p, k]
            if e >= 0:
                b = cells[e] if cells[e] < INT32_MAX else best[e]
                target[p, k] = b - shift[p, k]
                edge_depth[e] = min(edge_depth[e], depths[p] + shift[p, k])
            else:
                target[p, k] = -1


@nb.njit(cache=True, nogil=True)
def _shallowest_cells(edges, shift, depths, iso, cell_free, snap_max, cells):
    """Per edge, the shallowest depth (in the edge's units) of the cell-bearing patches on
    it, ``INT32_MAX`` where there is none or it is deeper than ``snap_max``."""
    cells[:] = INT32_MAX
    for p in range(len(depths)):
        if iso[p] and depths[p] < cell_free[p]:
            for k in range(4):
                e = edges[p, k]
                if e >= 0:
                    cells[e] = min(cells[e], depths[p] + shift[p, k])
    for e in range(len(cells)):
        if cells[e] > snap_max:
            cells[e] = INT32_MAX
