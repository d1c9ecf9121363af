"""Between rounds: the patches that rays asked for, built into the pools the kernels read
(``trace/pools.py``). What is built is counted in the render's statistics."""

from __future__ import annotations

import numpy as np

from subtrace import config
from subtrace.lines.items import box_nets, loop_regular
from subtrace.patches.grids import build_grids, node_boxes, snap_sides
from subtrace.patches.isolate import build_isolated
from subtrace.patches.isolate_loop import build_loop_isolated
from subtrace.trace.tris import tri_nets_as_pieces


def build_requested(table, requested, depths, edge_depth, grids, iso, round_no, stats, eye,
                    tol_rad, record):
    """Build the patches ``requested`` (sorted ids) in round ``round_no``: irregular
    Catmull-Clark patches into pieces (``iso``, a :class:`~subtrace.trace.pools.Pieces`;
    all of an object's in one isolation, taking what ``record[object id]`` kept of the depth
    choice's isolation), regular Loop triangles into triangular Bezier nets traced per ray
    (also in ``iso``, with ``config.LOOP_PER_RAY``), other Loop patches into grids (``grids``, a
    :class:`~subtrace.trace.pools.LoopGrids`) whose sides shared with a coarser neighbour
    are snapped onto its polyline (``edge_depth``). Counts go to ``stats``."""
    obj = table.object_id[requested]
    dep = depths[requested]
    quad = table.is_quad[requested]
    # an object's patches built per ray in one group (an isolation of all of them), Loop
    # grids one group per depth
    per_ray = quad | config.LOOP_PER_RAY
    order = np.lexsort((requested, np.where(per_ray, 0, dep), obj))
    requested, obj, dep, quad = requested[order], obj[order], dep[order], quad[order]
    keys = np.stack([obj, np.where(per_ray[order], -1, dep)], axis=1)
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
        if config.LOOP_PER_RAY:
            reg = loop_regular(o.level, o.cage.options, table.face[ids])
            _loop_nets(o, table, ids[reg], dep[s:e][reg], edge_depth, iso, round_no)
            stats.pieces += int(np.count_nonzero(reg))
            ids, d = ids[~reg], dep[s:e][~reg]
            if len(ids):
                subs, cells = build_loop_isolated(o, table.face[ids], d)
                n_sub, n_cell = iso.append_loop(ids, d, _sides(table, ids, edge_depth), subs,
                                                cells, round_no)
                stats.pieces += n_sub + n_cell
                stats.micro_triangles += n_cell
            continue
        d = int(dep[s])
        P, N = build_grids(o.level, o.points, o.cage.options, table.face[ids], d)
        side_depth = np.where(table.edges[ids, :3] >= 0, edge_depth[table.edges[ids, :3]], -1)
        snap_sides(P, d, False, side_depth)
        lo, hi = node_boxes(P, d, False)
        grids.append(ids, d, False, P, N, lo, hi, round_no)
        stats.micro_triangles += len(ids) * (1 << (2 * d))
        stats.grid_points += P.shape[0] * P.shape[1]
    stats.patches_refined += len(requested)


def _loop_nets(o, table, ids, depth, edge_depth, iso, round_no):
    """Put the regular Loop triangles ``ids`` (object ``o``, grid depths ``depth``) into
    ``iso`` as triangular Bezier nets traced per ray (``trace/tris.py``), each side sampled
    at its edge's depth."""
    if len(ids):
        nets = tri_nets_as_pieces(box_nets(o.level, o.points, table.face[ids]))
        side = np.full((len(ids), 4), -1, np.int64)
        side[:, :3] = _sides(table, ids, edge_depth)
        iso.append_tris(ids, np.asarray(depth, np.int64), side, nets, round_no)


def _sides(table, ids, edge_depth):
    """(len(ids),3) the sampling depth of each side's edge of the Loop patches ``ids``
    (-1: no edge)."""
    e = table.edges[ids, :3]
    return np.where(e >= 0, edge_depth[np.maximum(e, 0)], -1)
