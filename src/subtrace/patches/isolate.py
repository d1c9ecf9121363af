"""Grid depths of irregular patches by feature-adaptive isolation.

A patch with an extraordinary (or crease, boundary, ...) corner is not one polynomial, so the
tight Bezier bound of regular patches (:mod:`subtrace.patches.bspline`) does not apply to it
directly. Its conservative depth from the control edges and the subdominant eigenvalue
(:func:`subtrace.patches.criterion.choose_depths`) overshoots: the eigenvalue governs only the
shrinking corner next to the feature, not the rest of the patch.

:func:`isolated_depths` refines such patches locally, one level at a time, the way
OpenSubdiv's feature-adaptive refinement does: after ``k`` levels, the descendants that are
regular are bicubic patches whose own Bezier bound says how many more levels they need
(``k`` plus that); the irregular ones are refined again, until their own control-edge bound
is within the tolerance at depth 0 (they become single grid cells) or ``k`` reaches the
conservative depth. The patch's depth is the largest need found, never more than the
conservative depth. Its grid is still uniform, so every cell satisfies the criterion.

A patch (or, from the level where it becomes one, a patch's frontier face) that is smooth
with one extraordinary vertex refines the same way at every level: it goes on by fixed
linear maps instead of local topology (:mod:`subtrace.patches.stencil`; the same depths,
pieces and cells to rounding, at a fraction of the cost), where at least
``stencil.MIN_LEVELS`` levels remain below it. So does one whose only features are
semi-sharp creases along a side (or two opposite sides) of its grid
(:mod:`subtrace.patches.crease`), at any level: a crease's ends and junctions go through
topology, the faces along it that each level leaves by the maps (:class:`_Maps`).
"""

from __future__ import annotations

import numpy as np

from subtrace import config

from subtrace.config import IRREGULAR_MARGIN
from subtrace.patches.basis import bezier_nets_and_bounds
from subtrace.patches.bspline import control_points
from subtrace.patches.crease import crease_depths, crease_pieces, crease_where
from subtrace.patches.gridmaps import grid_depths, grid_pieces, grid_where
from subtrace.patches.grids import levels_needed, refine_children, unit_normals
from subtrace.patches.shells import one_ring_shells, sight_distance
from subtrace.patches.stencil import stencil_depths, stencil_pieces, stencil_where
from subtrace.runtime.jit import nb
from subtrace.runtime.threads import run_tasks, thread_count
from subtrace.subdiv.limit import limit_points


class IsolationTooLarge(Exception):
    """:func:`isolated_depths` stopped: the next level's frontier would pass ``max_faces``;
    ``level`` levels were refined within it (a cap of that depth everywhere fits)."""

    def __init__(self, level: int):
        super().__init__(f"isolation frontier too large below level {level}")
        self.level = level


def isolated_depths(obj, faces, cap, eye, tol_rad, record=None, record_depth=0, boxes=None,
                    max_faces=None):
    """Depths (len(faces),) int32 of the irregular quads ``faces`` of ``obj``'s patch level,
    none above ``cap`` (their conservative depths, (len(faces),) int). With a dict
    ``record``, what each level's refinement made is kept in it (see :class:`_Level`), for
    :func:`build_isolated` to take instead of refining the same faces again; the irregular
    corners are then refined down to ``record_depth`` at least (a patch's depth may be
    raised later, to its neighbours', and its pieces are built down to it).

    ``boxes`` = (lo, hi), each (len(faces),3) float64 filled with +inf / -inf: each face
    refined at least once gets the union of the boxes of what its refinement ended in (the
    Bezier nets of its regular descendants, the control-point boxes of the one-rings of the
    irregular ones it stopped at), a bound of its limit surface far tighter than its own
    one-ring's box; the others are left as they are.

    ``max_faces``: the most faces the refinement may take over all its levels (None: no
    limit from memory), and never more than ``config.ISOLATION_FACES_PER_PATCH_LEVEL`` per
    face and level of ``cap`` (at least ``config.ISOLATION_MIN_FACES``). An irregular
    corner keeps its frontier at a face or so per level, but a feature along an edge that
    no level makes regular (a non-manifold edge) doubles it at every level; before a level
    would pass the limit, :class:`IsolationTooLarge` is raised."""
    faces = np.asarray(faces, dtype=np.int64)
    cap = np.asarray(cap, dtype=np.int64)
    options = obj.cage.options
    # smooth patches of one extraordinary vertex, patches along creases: by the maps
    # (patches/stencil.py, patches/crease.py); the others through local topology below
    maps = _Maps(obj.level, options, faces, cap)
    if maps.ok.any():
        ok = maps.ok
        out = np.empty(len(faces), dtype=np.int32)
        rest = None if boxes is None else tuple(b[~ok] for b in boxes)
        out[ok] = _map_depths(maps, obj.level, obj.points, faces, cap, eye, tol_rad, boxes)[ok]
        # (called with no faces too: the record gets its levels, empty ones)
        out[~ok] = isolated_depths(obj, faces[~ok], cap[~ok], eye, tol_rad, record,
                                   record_depth, rest, max_faces)
        if boxes is not None:
            for b, other in zip(boxes, rest):
                b[~ok] = other
        return out
    need = np.zeros(len(faces), dtype=np.int64)
    levels = []
    if record is not None:
        record.update(faces=faces, levels=levels)
    # frontier: (root index, face in the current level, whether it still sets the need);
    # patches of depth 0 are only recorded (a neighbour may raise them)
    root = np.nonzero((cap > 0) | (record is not None and record_depth > 0))[0]
    active = cap[root] > 0
    cur, cur_pts, start = obj.level, obj.points, faces[root]
    k = 0
    taken = 0
    most = max(config.ISOLATION_MIN_FACES,
               config.ISOLATION_FACES_PER_PATCH_LEVEL * len(faces) * int(cap.max(initial=0)))
    if max_faces is not None:
        most = min(most, max_faces)
    while len(root):
        taken += len(start)
        if taken > most:
            raise IsolationTooLarge(k)
        parent_start = start
        cur, cur_pts, kids, reg = refine_children(cur, cur_pts, start, options)
        k += 1
        kid_root = np.repeat(root, 4)
        kid_active = np.repeat(active, 4)
        bez, n = np.zeros((0, 4, 4, 3)), np.zeros(0)
        lo = hi = np.zeros((0, 3))
        if reg.any():
            bez, lo, hi, bound = bezier_nets_and_bounds(control_points(cur, kids[reg], cur_pts))
            n = levels_needed(bound, sight_distance(lo, hi, eye), tol_rad)
            if boxes is not None:
                np.minimum.at(boxes[0], kid_root[reg], lo)
                np.maximum.at(boxes[1], kid_root[reg], hi)
            sets = kid_active[reg]
            np.maximum.at(need, kid_root[reg][sets], k + n[sets].astype(np.int64))
        if record is not None:
            levels.append(_Level(parent_start, cur, cur_pts, kids, reg, bez, n, lo, hi))
        irr = np.nonzero(~reg)[0]
        smin, smax, ebound, _ = one_ring_shells(cur, kids[irr], cur_pts)
        flat = IRREGULAR_MARGIN * ebound <= tol_rad * sight_distance(smin, smax, eye)
        np.maximum.at(need, kid_root[irr][kid_active[irr]], k)
        more = kid_active[irr] & ~flat & (k < cap[kid_root[irr]])
        keep = more | (k < record_depth if record is not None else False)
        if boxes is not None:  # the irregular children refined no further
            np.minimum.at(boxes[0], kid_root[irr[~keep]], smin[~keep])
            np.maximum.at(boxes[1], kid_root[irr[~keep]], smax[~keep])
        root, start, active = kid_root[irr[keep]], kids[irr[keep]], more[keep]
        # the children that the maps serve go on by them
        maps = _Maps(cur, options, start, np.where(active, cap[root] - k, -1))
        if maps.ok.any():
            ok = maps.ok
            r = root[ok]
            sub = None if boxes is None else (np.full((len(start), 3), np.inf),
                                              np.full((len(start), 3), -np.inf))
            d = _map_depths(maps, cur, cur_pts, start, cap[root] - k, eye, tol_rad, sub)[ok]
            np.maximum.at(need, r, k + d.astype(np.int64))
            if boxes is not None:
                np.minimum.at(boxes[0], r, sub[0][ok])
                np.maximum.at(boxes[1], r, sub[1][ok])
            root, start, active = root[~ok], start[~ok], active[~ok]
    return np.minimum(need, cap).astype(np.int32)


class _Maps:
    """Which of the faces ``faces`` of ``level``, with ``levels`` (m,) to go below them,
    refine by fixed linear maps instead of local topology: ``stencil`` =
    :func:`~subtrace.patches.stencil.stencil_where`'s ``(ok, corner, valence)``, ``crease``
    = :func:`~subtrace.patches.crease.crease_where`'s ``(ok, side, s_lo, s_hi)`` (disjoint:
    a stencil patch has no sharp edge at its corners, a crease patch no extraordinary
    one), ``grid`` = :func:`~subtrace.patches.gridmaps.grid_where`'s ``(ok, es, vs)`` for
    the others (any creases at valence-4 corners), ``ok`` any."""

    def __init__(self, level, options, faces, levels):
        self.stencil = stencil_where(level, options, faces, levels)
        self.crease = crease_where(level, options, faces, levels)
        self.ok = self.stencil[0] | self.crease[0]
        rest = np.where(self.ok, -1, levels)
        self.grid = grid_where(level, options, faces, rest)
        self.ok = self.ok | self.grid[0]

    def parts(self):
        """``(ok, depths, pieces, args)`` of each kind: its faces, its modules' functions
        and their per-face arguments."""
        (st, corner, valence), (cr, side, s_lo, s_hi) = self.stencil, self.crease
        gr, es, vs = self.grid
        return ((st, stencil_depths, stencil_pieces, (corner, valence)),
                (cr, crease_depths, crease_pieces, (side, s_lo, s_hi)),
                (gr, grid_depths, grid_pieces, (es, vs)))


def _map_depths(maps, level, points, faces, cap, eye, tol_rad, boxes):
    """Depths (m,) int32 of the ``faces`` of ``level`` that ``maps`` serves (0 at the
    others), none above ``cap`` (m,), as :func:`isolated_depths` chooses them; their rows
    of ``boxes`` grown as there."""
    out = np.zeros(len(faces), dtype=np.int32)
    for ok, depths, _, args in maps.parts():
        if ok.any():
            sub = None if boxes is None else tuple(b[ok] for b in boxes)
            out[ok] = depths(level, points, faces[ok], *(a[ok] for a in args), cap[ok], eye,
                             tol_rad, sub)
            if boxes is not None:
                for b, part in zip(boxes, sub):
                    b[ok] = part
    return out


def _map_pieces(maps, level, points, options, faces, depth, eye, tol_rad, ring, k0=0,
                i0=None, j0=None):
    """``[(part, rows)]``: :func:`build_isolated`'s ``(subs, cells)`` lists of each kind of
    the ``faces`` that ``maps`` serves (squares of level ``k0`` at ``i0, j0``, their
    patches' ``depth``), by the maps, and their rows in ``faces``."""
    out = []
    for ok, _, pieces, args in maps.parts():
        if ok.any():
            at = () if i0 is None else (i0[ok], j0[ok])
            out.append((pieces(level, points, options, faces[ok], *(a[ok] for a in args),
                               depth[ok], eye, tol_rad, ring, k0, *at), np.nonzero(ok)[0]))
    return out


class _Level:
    """One level of :func:`isolated_depths`' refinement: the faces it refined (``start``,
    in the previous level), the refined cut ``cur`` with its points, their four children
    each (``kids``, in ``cur``), which are regular, and those's Bezier nets, levels
    needed beyond this one and boxes (``bez``, ``n``, ``lo``, ``hi``)."""

    def __init__(self, start, cur, pts, kids, reg, bez, n, lo, hi):
        self.start, self.cur, self.pts, self.kids, self.reg = start, cur, pts, kids, reg
        self.bez, self.n, self.lo, self.hi = bez, n, lo, hi
        self.reg_rank = np.cumsum(reg) - 1
        self.lut = np.full(int(start.max(initial=-1)) + 1, -1, np.int64)
        self.lut[start] = np.arange(len(start))

    def regular(self, kid_rows):
        """``(bez, n, lo, hi)`` of the regular ones of the children ``kid_rows``."""
        at = self.reg_rank[kid_rows[self.reg[kid_rows]]]
        return self.bez[at], self.n[at], self.lo[at], self.hi[at]

    def find(self, faces):
        """Row of each of ``faces`` (in the previous level) in ``start``, or -1."""
        out = np.full(len(faces), -1, np.int64)
        ok = faces < len(self.lut)
        out[ok] = self.lut[faces[ok]]
        return out


_SUBS = 8  # the lists of build_isolated's pieces (its ``subs``)


def build_isolated(obj, faces, depth, eye=None, tol_rad=None, record=None, ring=False):
    """Feature-adaptive pieces of the irregular quads ``faces`` of ``obj``'s patch level,
    refined down to grid depth ``depth`` (a scalar, or one per face): every grid cell of a
    patch is covered either by a regular sub-patch (a bicubic Bezier net over a dyadic
    square) or, where no level down to the depth is regular, by a cell of exact limit points.
    ``record``: what :func:`isolated_depths` made for the same eye and tolerance (its levels
    are taken where they reach, and refined further where they do not).

    Returns ``(subs, cells)``:
    ``subs`` = (root index (s,), level (s,), origin i0, j0 (s,) in units of 2^-level,
    Bezier nets (s,4,4,3), grid depth (s,) in the patch's units: the piece's own need from
    its Bezier bound as seen from ``eye`` at ``tol_rad`` (as :func:`isolated_depths`), at
    least its level and at most its patch's depth; the patch's depth without an eye; the
    boxes of the nets' control points, lo and hi (s,3), as ``basis.net_bounds`` makes
    them);
    ``cells`` = (root index (c,), cell i, j (c,) in units of 2^-depth, corner points (c,4,3),
    corner unit normals (c,4,3), NaN where undefined), and with ``ring`` the diagonal (c,)
    of the box of each cell's one-ring control points and whether the cell touches the
    mesh's boundary (c,) bool: the cell's limit surface and its corners' bilinear patch both
    lie in their convex hull (every rule's weights are non-negative, save Chaikin creases
    above sharpness 1: ``config.SHELL_CHAIKIN_MARGIN``), so no point of either is farther
    than the diagonal from the other.
    """
    return _packed(*isolated_parts(obj, faces, depth, eye, tol_rad, record, ring), ring)


def isolated_parts(obj, faces, depth, eye=None, tol_rad=None, record=None, ring=False):
    """:func:`build_isolated`'s result before it is put in order: ``(subs, cells)``, a list
    per array of its layout, the arrays of each as they were made (:func:`packed_order`
    gives the order, :func:`rows_in_order` the rows): for a caller that copies the nets
    somewhere anyway (``trace.pools.Pieces.append`` writes each once, at its place)."""
    options = obj.cage.options
    faces = np.asarray(faces, dtype=np.int64)
    depth = np.broadcast_to(np.asarray(depth, dtype=np.int64), faces.shape)
    subs = [[] for _ in range(_SUBS)]
    cells = [[] for _ in range(7 if ring else 5)]
    # (patches/stencil.py, patches/crease.py, as in isolated_depths)
    maps = _Maps(obj.level, options, faces, depth)
    for part, at in _map_pieces(maps, obj.level, obj.points, options, faces, depth, eye,
                                tol_rad, ring):
        _add_part(subs, cells, part, at)
    rest = np.nonzero(~maps.ok)[0]
    if len(rest):
        _by_topology(obj, faces, depth, rest, eye, tol_rad, record, subs, cells)
    return subs, cells


def _by_topology(obj, faces, depth, rest, eye, tol_rad, record, subs, cells):
    """:func:`build_isolated`'s pieces and cells of its ``faces[rest]`` through local
    topology, level by level, into ``subs``, ``cells`` (the frontier's faces that the maps
    serve from some level on by them)."""
    options = obj.cage.options
    ring = len(cells) > 5
    zero = np.zeros(len(rest), dtype=np.int64)
    levels = record["levels"] if record is not None and eye is not None else []
    # groups of the frontier: (level, points, root index, face in the level, i0, j0, whether
    # the level is the record's)
    groups = [(obj.level, obj.points, rest, faces[rest], zero, zero, bool(levels))]
    k = 0
    while groups:
        nxt = []
        for cur, cur_pts, root, start, i0, j0, recorded in groups:
            done = depth[root] == k
            if done.any():
                # the irregular cells left at their patch's depth: exact limit points
                _add_cells(cells, cur, cur_pts, options, start[done], root[done], i0[done],
                           j0[done])
                keep = ~done
                root, start, i0, j0 = root[keep], start[keep], i0[keep], j0[keep]
                if not len(root):
                    continue
            rows = levels[k].find(start) if recorded and k < len(levels) else np.full(len(start), -1)
            have = rows >= 0
            if have.any():
                lv = levels[k]
                kid_rows = (4 * rows[have, None] + np.arange(4)).ravel()
                nxt.append(_next_level(subs, k + 1, lv.cur, lv.pts, lv.kids[kid_rows],
                                       lv.reg[kid_rows], root[have], i0[have], j0[have], depth,
                                       eye, tol_rad, True,
                                       *lv.regular(kid_rows)))
            if not have.all():
                fresh = ~have
                ref, ref_pts, kids, reg = refine_children(cur, cur_pts, start[fresh], options)
                nxt.append(_next_level(subs, k + 1, ref, ref_pts, kids, reg, root[fresh],
                                       i0[fresh], j0[fresh], depth, eye, tol_rad, False))
        k += 1
        groups = [_by_maps(g, k, options, depth, eye, tol_rad, ring, subs, cells)
                  for g in nxt if len(g[2])]
        groups = [g for g in groups if len(g[2])]


def _by_maps(group, k, options, depth, eye, tol_rad, ring, subs, cells):
    """Build the faces of a frontier group at level ``k`` that the maps serve (smooth
    patches of one extraordinary vertex, patches along creases: :class:`_Maps`) by them,
    into ``subs``, ``cells``; return the group of the others."""
    cur, cur_pts, root, start, i0, j0, recorded = group
    maps = _Maps(cur, options, start, depth[root] - k)
    if not maps.ok.any():
        return group
    for part, at in _map_pieces(maps, cur, cur_pts, options, start, depth[root], eye, tol_rad,
                                ring, k, i0, j0):
        _add_part(subs, cells, part, root[at])
    ok = maps.ok
    return cur, cur_pts, root[~ok], start[~ok], i0[~ok], j0[~ok], recorded


def _add_part(subs, cells, part, roots):
    """Add ``part`` = (subs, cells) of :func:`build_isolated`'s layout (lists of arrays, or
    arrays) to the lists ``subs``, ``cells``, its root indices mapped through ``roots``."""
    for out, got in zip((subs, cells), part):
        for j, a in enumerate(got):
            arrays = a if isinstance(a, list) else [a]
            out[j].extend(roots[x] if j == 0 else x for x in arrays)


def _packed(subs, cells, ring):
    """:func:`build_isolated`'s result from its lists of arrays ``subs``, ``cells``
    (:func:`isolated_parts`), in :func:`packed_order`. Each array is written once, each
    list's rows scattered to their places (concatenating the pieces' nets and then taking
    them in order cost twice as much on the chess pieces' 331,283)."""
    order, cell_order = packed_order(subs, cells)
    if subs[0]:
        out_subs = tuple(rows_in_order(a, order) for a in subs)
    else:
        empty = np.zeros(0, np.int64)
        out_subs = (empty,) * 4 + (np.zeros((0, 4, 4, 3)), empty, np.zeros((0, 3)),
                    np.zeros((0, 3)))
    if cells[0]:
        out_cells = tuple(rows_in_order(a, cell_order) for a in cells)
    else:
        empty = np.zeros(0, np.int64)
        out_cells = ((empty,) * 3 + (np.zeros((0, 4, 3)), np.zeros((0, 4, 3)))
                     + ((np.zeros(0), np.zeros(0, bool)) if ring else ()))
    return out_subs, out_cells


def packed_order(subs, cells):
    """``(order, cell_order)``: the rows (in the concatenation of each list of
    :func:`isolated_parts`' ``subs``, ``cells``) of :func:`build_isolated`'s pieces, level
    by level, each level's by patch and then by corner in their parent (those of one corner
    in the order they were made: the topological path's order, save for the patches that
    the maps take over below their root), and of its cells, by patch."""
    if subs[0]:
        root, level, i0, j0 = (np.concatenate(a) for a in subs[:4])
        order = np.lexsort(((i0 & 1) + 3 * (j0 & 1) - 2 * (i0 & j0 & 1), root, level))
    else:
        order = np.zeros(0, np.int64)
    cell_order = (np.argsort(np.concatenate(cells[0]), kind="stable") if cells[0]
                  else np.zeros(0, np.int64))
    return order, cell_order


def rows_in_order(arrays, order):
    """The rows of the concatenation of ``arrays`` (a list of arrays) taken in ``order``."""
    first = np.asarray(arrays[0])
    out = np.empty((len(order),) + first.shape[1:], dtype=first.dtype)
    flat = out.reshape(len(order), -1)
    at = np.empty(len(order), np.int64)
    at[order] = np.arange(len(order))
    start = 0
    for a in arrays:
        n = len(a)
        flat[at[start:start + n]] = np.asarray(a).reshape(n, -1)
        start += n
    return out


def _next_level(subs, k, cur, cur_pts, kids, reg, root, i0, j0, depth, eye, tol_rad, recorded,
                bez=None, n=None, lo=None, hi=None):
    """Append the regular children ``kids[reg]`` (level ``k`` of ``cur``; four per frontier
    face of roots ``root`` at origins ``i0, j0``) to ``subs`` as pieces; return the group of
    the irregular ones. ``bez``, ``n``, ``lo``, ``hi``: the regular ones' nets, needs and
    boxes, when known (all four, from the depth choice's record)."""
    q = np.arange(4)
    kid_root = np.repeat(root, 4)
    ki = (2 * i0[:, None] + (q == 1) + (q == 2)).ravel()
    kj = (2 * j0[:, None] + (q >= 2)).ravel()
    if reg.any():
        subs[0].append(kid_root[reg])
        subs[1].append(np.full(int(reg.sum()), k))
        subs[2].append(ki[reg])
        subs[3].append(kj[reg])
        if bez is None:
            bez, lo, hi, bound = bezier_nets_and_bounds(control_points(cur, kids[reg], cur_pts))
            if eye is not None:
                n = levels_needed(bound, sight_distance(lo, hi, eye), tol_rad)
        subs[4].append(bez)
        own = depth[kid_root[reg]]
        if eye is not None:
            own = np.clip(k + n, k, own).astype(np.int64)
        subs[5].append(own)
        subs[6].append(lo)
        subs[7].append(hi)
    irr = ~reg
    return cur, cur_pts, kid_root[irr], kids[irr], ki[irr], kj[irr], recorded


def corner_limits(level, points, options, faces, n):
    """The corners (f,n) of the ``n``-sided ``faces`` of ``level``, their exact limit
    points (f,n,3) and unit limit normals (f,n,3), NaN where a normal is undefined."""
    fo = level.face_offsets
    corners = level.face_verts[fo[faces][:, None] + np.arange(n)]
    P, du, dv = limit_points(level, points, options, which=corners.ravel())
    return corners, P.reshape(-1, n, 3), unit_normals(du, dv).reshape(-1, n, 3)


def _add_cells(cells, level, points, options, faces, root, i0, j0):
    """Append the cells ``faces`` of ``level`` (exact limit points and unit normals of their
    corners, NaN normals where undefined, and, when ``cells`` has seven lists, the
    diagonals of their one-rings' boxes and whether they touch the mesh's boundary) to the
    lists ``cells``."""
    corners, P, nrm = corner_limits(level, points, options, faces, 4)
    for lst, a in zip(cells, (root, i0, j0, P, nrm)):
        lst.append(a)
    if len(cells) > 5:
        lo, hi, _, _ = one_ring_shells(level, faces, points)
        cells[5].append(np.linalg.norm(hi - lo, axis=1))
        # (a cut's own outer edges lie beyond the cells' one-rings: not their boundary)
        cells[6].append(level.vert_boundary()[corners].any(axis=1))


_PATCHES_PER_THREAD = 256  # (fewer patches: one thread, not worth starting the others)


def item_sides(first, count, level, i0, j0, depth, patch_side, out):
    """:func:`_item_sides` of every patch, on the thread pool where there are enough
    (each patch's rows of ``out`` are its own)."""
    n = thread_count() if len(first) >= _PATCHES_PER_THREAD else 1
    run_tasks(_item_sides, first, count, level, i0, j0, depth, patch_side, out, n=n)


@nb.njit(cache=True, nogil=True)
def _item_sides(task, n_tasks, first, count, level, i0, j0, depth, patch_side, out):
    """How finely each side of each piece is sampled, for watertight pieces of different
    depths: patch ``p``'s pieces are ``first[p] .. first[p] + count[p] - 1`` (dyadic squares
    at ``level``, origin ``i0, j0``, grid ``depth``, all in the patch's units); ``out`` (n,4)
    receives, per side (0: v = v0, 1: u = u1, 2: v = v1, 3: u = u0), the deepest grid among
    the pieces that share a stretch of it (itself included), and ``patch_side[p, k]`` on
    the patch's side k (finer than the piece's grid: a fan; coarser: a snapped side,
    ``geometry/snap.py``). A large piece's side spans several small pieces, which must then
    all sample their stretches as the large one does: so the sides along one line of the
    patch that overlap, directly or through others, all take the deepest of them. Per
    line, its sides in order along it (sorted: n log n a patch; comparing every pair of
    pieces until nothing changed took 1.2 s of a 4 s refinement on the chess pieces'
    331,283 pieces, about 80 a patch). Task ``task`` of ``n_tasks`` takes a contiguous
    share of the patches."""
    n_p = len(first)
    lo_p, hi_p = task * n_p // n_tasks, (task + 1) * n_p // n_tasks
    most = 0
    for p in range(lo_p, hi_p):
        most = max(most, count[p])
    # per side: its line and stretch along it as one key (line, then begin: at most
    # 2^(2 top + 2), top the patch's deepest level), its end, and 4 piece + side; made
    # once for the task's patches (one sort of the keys, not two stable ones per line
    # direction of each patch: 17 ms of the chess pieces' 6 builds; the sort need not be
    # stable: stretches that begin together join one run in either order)
    key = np.empty(2 * most, np.int64)
    end = np.empty(2 * most, np.int64)
    which = np.empty(2 * most, np.int64)
    for p in range(lo_p, hi_p):
        f, c = first[p], count[p]
        top = 0
        for a in range(f, f + c):
            top = max(top, level[a])
        full = 1 << top
        for a in range(f, f + c):
            sc = 1 << (top - level[a])
            u0, v0 = i0[a] * sc, j0[a] * sc
            for k in range(4):
                out[a, k] = depth[a]
            # (a patch side is sampled as the patch's: finer, a fan; coarser, snapped)
            if v0 == 0:
                out[a, 0] = patch_side[p, 0]
            if u0 + sc == full:
                out[a, 1] = patch_side[p, 1]
            if v0 + sc == full:
                out[a, 2] = patch_side[p, 2]
            if u0 == 0:
                out[a, 3] = patch_side[p, 3]
        if c == 0:
            continue
        span = full + 1
        for across in range(2):  # lines v = const (sides 0 and 2), then u = const (3, 1)
            for a in range(f, f + c):
                sc = 1 << (top - level[a])
                low = (j0[a] if across == 0 else i0[a]) * sc  # the piece's low line
                along = (i0[a] if across == 0 else j0[a]) * sc
                for high in range(2):
                    e = 2 * (a - f) + high
                    key[e] = (low + high * sc) * span + along
                    end[e] = along + sc
                    which[e] = 4 * a + ((2 * high) if across == 0 else (3 - 2 * high))
            order = np.argsort(key[:2 * c])
            start, reach = 0, -1
            for t in range(2 * c + 1):
                e = order[min(t, 2 * c - 1)]
                if t < 2 * c and t > start and key[e] // span == key[order[start]] // span \
                        and key[e] % span < reach:
                    reach = max(reach, end[e])
                    continue
                # the stretches start .. t - 1 overlap, one after the other: one sampling
                best = out[which[order[start]] // 4, which[order[start]] % 4]
                for u in range(start, t):
                    best = max(best, out[which[order[u]] // 4, which[order[u]] % 4])
                for u in range(start, t):
                    out[which[order[u]] // 4, which[order[u]] % 4] = best
                start, reach = t, end[e]


@nb.njit(cache=True, nogil=True)
def rest_boxes(first, count, lo, hi, rest_lo, rest_hi):
    """Per item, the box of it and the items after it in its patch (patch ``p``'s items are
    ``first[p] .. first[p] + count[p] - 1``, coarse levels first): a ray that misses the box
    of the rest skips them all."""
    for p in range(len(first)):
        f, c = first[p], count[p]
        for a in range(f + c - 1, f - 1, -1):
            for k in range(3):
                rest_lo[a, k] = lo[a, k]
                rest_hi[a, k] = hi[a, k]
                if a + 1 < f + c:
                    rest_lo[a, k] = min(rest_lo[a, k], rest_lo[a + 1, k])
                    rest_hi[a, k] = max(rest_hi[a, k], rest_hi[a + 1, k])
