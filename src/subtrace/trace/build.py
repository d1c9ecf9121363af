"""Between rounds: the patches that rays asked for, built into the pools the kernels read
(``trace/pools.py``). What is built is counted in the render's statistics."""

from __future__ import annotations

import numpy as np

from subtrace.patches.basis import BOX_PAD
from subtrace.patches.boxspline import box_nets, loop_regular
from subtrace.patches.isolate import isolated_parts
from subtrace.patches.isolate_loop import build_loop_isolated
from subtrace.subdiv.topology import compact
from subtrace.geometry.tris import tri_nets_as_pieces


def build_requested(table, requested, depths, edge_depth, iso, round_no, stats, eye, tol_rad,
                    record, patch_side=None):
    """Build the patches ``requested`` (sorted ids) in round ``round_no`` into ``iso`` (a
    :class:`~subtrace.trace.pools.Pieces`), all of an object's at once: irregular
    Catmull-Clark patches into pieces (one isolation, taking what ``record[object id]``
    kept of the depth choice's isolation), regular Loop triangles into triangular Bezier
    nets traced per ray, irregular ones isolated into such nets and cells
    (``patches/isolate_loop.py``), their sides shared with a coarser neighbour snapped onto
    its polyline (``edge_depth``). An irregular Catmull-Clark patch's pieces sample each of
    its sides at least as ``patch_side`` (P,4) says (``criterion.edge_sampling``; None: at
    its depth). Counts go to ``stats``."""
    obj = table.object_id[requested]
    dep = depths[requested]
    quad = table.is_quad[requested]
    order = np.lexsort((requested, obj))
    requested, obj, dep, quad = requested[order], obj[order], dep[order], quad[order]
    starts = np.r_[0, np.nonzero(np.diff(obj))[0] + 1]
    ends = np.r_[starts[1:], len(requested)]
    for s, e in zip(starts, ends):
        ids = requested[s:e]
        o = table.objects[int(obj[s])]
        if quad[s]:
            # (as made: the pool puts the pieces in order, their nets stay where they are)
            subs, cells = isolated_parts(o, table.face[ids], dep[s:e], eye, tol_rad,
                                         record.get(int(obj[s])))
            side = np.repeat(dep[s:e], 4) if patch_side is None else patch_side[ids]
            n_sub, n_cell = iso.append(ids, dep[s:e], side, subs, cells, round_no)
            stats.pieces += n_sub + n_cell
            stats.micro_triangles += 2 * n_cell
            continue
        reg = loop_regular(o.level, o.cage.options, table.face[ids])
        _loop_nets(o, table, ids[reg], dep[s:e][reg], edge_depth, iso, round_no)
        stats.pieces += int(np.count_nonzero(reg))
        ids, d = ids[~reg], dep[s:e][~reg]
        if len(ids):
            subs, cells = build_loop_isolated(o, table.face[ids], d)
            n_sub, n_cell = iso.append_loop(ids, d, _sides(table, ids, edge_depth), subs, cells,
                                            round_no)
            stats.pieces += n_sub + n_cell
            stats.micro_triangles += n_cell
    stats.patches_refined += len(requested)


def _loop_nets(o, table, ids, depth, edge_depth, iso, round_no):
    """Put the regular Loop triangles ``ids`` (object ``o``, grid depths ``depth``) into
    ``iso`` as triangular Bezier nets traced per ray (``geometry/tris.py``), each side sampled
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


def cut_to_loop_nets(table, lo, hi):
    """Cut the boxes ``lo``, ``hi`` (P,3) of the table's regular Loop triangles, in place, to
    their quartic nets' boxes (padded as the pieces' are): about half as wide as the union
    of their children's one-ring boxes that the table gives the rays (``table.ray_min``)."""
    for o in table.objects:
        if o.cage.scheme != "loop" or not len(o.patch_faces):
            continue
        ids = o.first_patch + np.nonzero(
            loop_regular(o.level, o.cage.options, o.patch_faces))[0]
        if not len(ids):
            continue
        nets = box_nets(o.level, o.points, table.face[ids])
        nlo, nhi = nets.min(axis=1), nets.max(axis=1)
        pad = BOX_PAD * np.maximum(np.abs(nlo), np.abs(nhi)).max(axis=1, keepdims=True)
        lo[ids] = np.maximum(lo[ids], nlo - pad)
        hi[ids] = np.minimum(hi[ids], nhi + pad)


def build_loop_regular(table, depths, edge_depth, iso):
    """Before the first round: the regular Loop triangles of the table as triangular Bezier
    nets (round -1), as the regular Catmull-Clark patches' nets are. Their refinement is per
    ray, so this is a few hundred bytes per patch and no subdivision; without it each ray
    would ask for the next patch it reaches, one round each (a torus seen through its hole
    took 14 rounds, each tracing its rays again). A patch counts as refined once a ray
    descends into it. Returns the number of nets built."""
    ids = np.nonzero(~table.is_quad)[0]
    built = 0
    obj = table.object_id[ids]
    for k in compact(obj, len(table.objects))[0]:  # (np.unique would import numpy.ma)
        o = table.objects[int(k)]
        sel = ids[obj == k]
        reg = sel[loop_regular(o.level, o.cage.options, table.face[sel])]
        _loop_nets(o, table, reg, depths[reg], edge_depth, iso, -1)
        built += len(reg)
    return built
