"""Feature-adaptive isolation of patches under any pattern of semi-sharp creases, by their
4x4 control grids alone.

A Catmull-Clark quad whose four corners are inside the mesh, of valence 4 with quads
around them, refines from its 4x4 control grid and the sharpness of the twelve edges at its
corners (and the corners' own), whatever those are: a crease that ends inside it, two that
cross or meet, sharpness changing along a line (``subdiv/gridrefine.py``: one level, in a
kernel). Its children are such quads again, so the patch's whole isolation follows from
its grid level by level, as ``patches/crease.py``'s maps do for one crease of constant
sharpness along a side, without the local topology that ``patches/isolate.py`` builds for
the rest. These are the maps for the crease ends and junctions of hard-surface cages (and
for the frontier faces beside them one level below an extraordinary vertex), the patches
:mod:`~subtrace.patches.crease` and :mod:`~subtrace.patches.stencil` do not take.

Each level does what the topological path does (:func:`~subtrace.patches.isolate.
isolated_depths`, ``build_isolated``): a child whose four corners and their edges have no
sharpness left is a regular bicubic patch (its Bezier net, box and derivative bound as
``basis.bezier_nets_and_bounds`` make them, its need from the eye); the others are refined
further, the depth choice stopping where the one-ring shell (the grid) is within the
tolerance; the squares left at a patch's depth are cells, whose corners' exact limit points
come from refining each corner's ring, level by level, until the corner and its four
edges are smooth, and the smooth limit masks there, as ``subdiv/limit.py``
does through topology. The sums run in another order, so the results
equal the topological path's to rounding (tests/test_gridmaps.py compares them, and the
pieces with OpenSubdiv's limit surface). Chaikin's crease method averages a vertex's other
edges into a child edge's sharpness, which the grid does not hold: its cages go through
topology. ``ENABLED`` False sends every patch through topology.
"""

from __future__ import annotations

import numpy as np

from subtrace.config import IRREGULAR_MARGIN
from subtrace.patches.basis import TO_BEZIER
from subtrace.patches.bspline import control_grids
from subtrace.patches.facememo import FaceMemo
from subtrace.subdiv.gridrefine import (
    CORNER_EDGES, CORNERS, grid_regular, refine_grid, ring_limit,
)
from subtrace.patches.grids import unit_normals
from subtrace.patches.squares import (
    bezier, distance, in_chunks, nan_max, nan_min, needed, net_bounds, sight,
    square_shell,
)
from subtrace.runtime.jit import nb
from subtrace.subdiv.limit import tangent_tables
from subtrace.subdiv.topology import INF_SHARP

ENABLED = True  # False: these patches through local topology (tests compare the two)


def grid_faces(level, options, faces):
    """Which of the irregular quads ``faces`` of ``level`` the grid maps serve: ``(ok (m,)
    bool, es (m,24) float32, vs (m,4) float32)``, the sharpness of the grid's edges (the
    twelve at its corners; the outer lines', which no rule of its descendants reads, 0) and
    of its corners (``subdiv/gridrefine.py``'s layouts). A face qualifies when it is a
    quad whose corners are inside the mesh (one fan of four faces and four edges), the
    faces around them all quads and none a hole, with some semi-sharp sharpness at its
    corners and none infinite there; Catmull-Clark with uniform creases only."""
    faces = np.asarray(faces, dtype=np.int64)
    if (options.scheme != "catmark" or options.chaikin or len(faces) == 0
            or not ENABLED):
        m = len(faces)
        return np.zeros(m, bool), np.zeros((m, 24), np.float32), np.zeros((m, 4), np.float32)
    return _GRID_FACES(level, options, faces)


def _grid_faces(level, options, faces):
    """:func:`grid_faces` of each of ``faces`` (distinct), computed."""
    m = len(faces)
    ok = np.zeros(m, bool)
    es, vs = np.zeros((m, 24), np.float32), np.zeros((m, 4), np.float32)
    at = np.empty(m, np.int64)
    n = _candidates(faces, level.face_offsets, level.face_verts, level.face_edges,
                    level.edge_sharpness, level.vert_face_offsets, level.vert_faces,
                    level.vert_edge_offsets, level.vert_edges, level.vert_manifold,
                    level.vert_sharpness, level.face_hole, np.float32(INF_SHARP), at)
    at = at[:n]
    if len(at):
        grid = np.ascontiguousarray(control_grids(level, faces[at]).reshape(-1, 16))
        e_at, v_at = np.zeros((n, 24), np.float32), np.zeros((n, 4), np.float32)
        _grid_sharpness(grid, CORNERS, CORNER_EDGES, level.vert_edge_offsets, level.vert_edges,
                        level.edge_verts, level.edge_sharpness, level.vert_sharpness,
                        e_at, v_at)
        ok[at], es[at], vs[at] = True, e_at, v_at
    return ok, es, vs


@nb.njit(cache=True, nogil=True)
def _candidates(faces, fo, fv, fe, es, vfo, vf, veo, ve, manifold, vsharp, hole, inf_sharp,
                out):
    """The rows of ``faces`` the grid maps serve (:func:`grid_faces`' conditions), into
    ``out``; returns their count."""
    n = 0
    for r in range(len(faces)):
        f = faces[r]
        if fo[f + 1] - fo[f] != 4:
            continue
        good = True
        semi = False
        for k in range(4):
            v = fv[fo[f] + k]
            if (not manifold[v] or vfo[v + 1] - vfo[v] != 4 or veo[v + 1] - veo[v] != 4
                    or vsharp[v] >= inf_sharp):
                good = False
                break
            if vsharp[v] > 0:
                semi = True
            for a in range(vfo[v], vfo[v + 1]):
                g = vf[a]
                if fo[g + 1] - fo[g] != 4 or hole[g]:
                    good = False
            for a in range(veo[v], veo[v + 1]):
                x = es[ve[a]]
                if x >= inf_sharp:
                    good = False
                elif x > 0:
                    semi = True
            if not good:
                break
        if good and semi:
            out[n] = r
            n += 1
    return n


@nb.njit(cache=True, nogil=True)
def _grid_sharpness(grid, corners, corner_edges, veo, ve, ev, es, vsharp, out_es, out_vs):
    """The sharpness of the twelve edges at the corners of the grids ``grid`` (n,16) (point
    ids) and of the corners, into ``out_es`` (n,24) and ``out_vs`` (n,4): each edge found
    among its corner's edges by its other end."""
    for r in range(len(grid)):
        for q in range(4):
            i, j = corners[q, 0], corners[q, 1]
            c = grid[r, 4 * i + j]
            out_vs[r, q] = vsharp[c]
            for k in range(4):
                # +u, +v, -u, -v: the other end's grid position
                oi = i + 1 if k == 0 else (i - 1 if k == 2 else i)
                oj = j + 1 if k == 1 else (j - 1 if k == 3 else j)
                o = grid[r, 4 * oi + oj]
                for a in range(veo[c], veo[c + 1]):
                    g = ve[a]
                    far = ev[g, 1] if ev[g, 0] == c else ev[g, 0]
                    if far == o:
                        out_es[r, corner_edges[q, k]] = es[g]
                        break


_GRID_FACES = FaceMemo(_grid_faces, (bool, (np.float32, (24,)), (np.float32, (4,))))


def grid_where(level, options, faces, levels):
    """:func:`grid_faces` for the ``faces`` with ``levels`` (m,) >= 0 to go below them (the
    others: not ok, unexamined)."""
    m = len(faces)
    ok, es, vs = np.zeros(m, bool), np.zeros((m, 24), np.float32), np.zeros((m, 4), np.float32)
    live = np.nonzero(np.asarray(levels) >= 0)[0]
    if len(live):
        ok[live], es[live], vs[live] = grid_faces(level, options, np.asarray(faces)[live])
    return ok, es, vs


# ------------------------------------------------------------------------------------------
# the isolation
# ------------------------------------------------------------------------------------------

# squares of one call of the kernel at most where there are more (a chunk of the thread
# pool's)
_SQUARES_PER_CHUNK = 16


def _isolate(grids, es, vs, limit, eye, tol_rad, pieces, k0=0, i0=None, j0=None, boxes=None):
    """Every level of the isolation of the squares of control grids ``grids`` (m,16,3)
    (sharpness ``es`` (m,24), ``vs`` (m,4)) by :func:`_isolate_kernel`, in chunks of
    squares on the thread pool, the chunks' results one after another (each square's own
    in the order of one call: the callers order them by square first, so the result does
    not depend on the chunks or the threads). ``pieces`` False: the depth choice, ``limit``
    each square's cap of levels below it; True: the pieces, ``limit`` the patches' depths,
    the squares of level ``k0`` at ``i0``, ``j0``."""
    m = len(grids)
    z = np.zeros(m, np.int64)
    eye_p, near, seen_min, seen_max, cone = sight(eye)
    lo, hi = (np.full((m, 3), np.inf), np.full((m, 3), -np.inf)) if boxes is None else boxes
    per = (np.ascontiguousarray(grids, dtype=np.float64), np.ascontiguousarray(es, np.float32),
           np.ascontiguousarray(vs, np.float32), np.ascontiguousarray(limit, np.int64),
           z if i0 is None else np.ascontiguousarray(i0, np.int64),
           z if j0 is None else np.ascontiguousarray(j0, np.int64))
    rest = (eye_p, near, seen_min, seen_max, cone, eye is not None,
            float(tol_rad if tol_rad is not None else 0.0), pieces, int(k0), TO_BEZIER,
            float(IRREGULAR_MARGIN))

    def call(a, b):
        return _isolate_kernel(*(x[a:b] for x in per), *rest, lo[a:b], hi[a:b])

    return in_chunks(call, m, _SQUARES_PER_CHUNK, (1, 9))


@nb.njit(cache=True)
def _grown(a, n):
    """``a`` in a new array of ``n`` rows (its rows first)."""
    b = np.empty((n,) + a.shape[1:], a.dtype)
    b[:len(a)] = a
    return b


# _isolate_kernel (about 130 lines) is not split: its steps share one square's frontier,
# the scratch of its children and the growing outputs
@nb.njit(cache=True, nogil=True)
def _isolate_kernel(grids, es, vs, limit, i0, j0, eye, near, seen_min, seen_max, cone,
                    sighted, tol_rad, pieces, k0, to_bez, margin, box_lo, box_hi):
    """Every level of the isolation of the squares ``grids[m]`` (16,3), square by square,
    each level by level: a square's four children by ``gridrefine.refine_grid``, in the
    order of their corners; a child with no sharpness left at its corners
    (``gridrefine.grid_regular``) is regular: its Bezier net (``squares.bezier``), box and
    derivative bound (``squares.net_bounds``); the others are refined further.

    ``pieces`` False (the depth choice): square m's levels are capped at ``limit[m]``; a
    regular child at level k needs k + ``levels_needed`` of its bound seen from the eye, an
    irregular one k, and is refined no further where its one-ring shell (the grid:
    ``squares.square_shell``) is within ``margin`` of the tolerance; ``box_lo``,
    ``box_hi`` (m,3) grow to hold what each square's refinement ended in. Returns ``need``
    (m,) int64 (the most of those, before the cap) and the rest empty.

    ``pieces`` True: the squares (level ``k0`` of their patches at ``i0``, ``j0``) are
    refined down to their patches' depth ``limit[m]``; returns ``(need, root, level, i, j,
    nets, own, lo, hi, c_root, c_grid, c_es, c_vs, c_i, c_j)``: the regular children
    (their square's row, level, position, net, own depth ``levels_needed`` from the eye
    clipped to [level, depth], or the depth where not ``sighted``, box), and the squares
    left at the depth (row, grid, sharpness, position), each square's level by level and
    a level's in the order they were made (the topological path's order)."""
    m = grids.shape[0]
    need = np.zeros(m, np.int64)
    p_root = np.empty(16, np.int64)
    p_level = np.empty(16, np.int64)
    p_i = np.empty(16, np.int64)
    p_j = np.empty(16, np.int64)
    p_own = np.empty(16, np.int64)
    p_nets = np.empty((16, 4, 4, 3))
    p_lo = np.empty((16, 3))
    p_hi = np.empty((16, 3))
    n_p = 0
    c_root = np.empty(4, np.int64)
    c_grid = np.empty((4, 16, 3))
    c_es = np.empty((4, 24), np.float32)
    c_vs = np.empty((4, 4), np.float32)
    c_i = np.empty(4, np.int64)
    c_j = np.empty(4, np.int64)
    n_c = 0
    # one square's frontier (this level's and the next's)
    f_grid, x_grid = np.empty((4, 16, 3)), np.empty((4, 16, 3))
    f_es, x_es = np.empty((4, 24), np.float32), np.empty((4, 24), np.float32)
    f_vs, x_vs = np.empty((4, 4), np.float32), np.empty((4, 4), np.float32)
    f_i, x_i = np.empty(4, np.int64), np.empty(4, np.int64)
    f_j, x_j = np.empty(4, np.int64), np.empty(4, np.int64)
    L = np.empty((7, 7, 3))
    kids = np.empty((4, 16, 3))
    kids4 = kids.reshape((4, 4, 4, 3))
    k_es = np.empty((4, 24), np.float32)
    k_vs = np.empty((4, 4), np.float32)
    tmp = np.empty((4, 4, 3))
    bez = np.empty((4, 4, 3))
    b_lo = np.empty((4, 3))
    b_hi = np.empty((4, 3))
    b_bound = np.empty(4)
    for r in range(m):
        if not pieces and limit[r] <= 0:  # (no levels below it: not refined)
            continue
        f_grid[0], f_es[0], f_vs[0] = grids[r], es[r], vs[r]
        f_i[0], f_j[0] = i0[r], j0[r]
        n_f = 1
        k = k0
        while n_f > 0:
            if pieces and limit[r] == k:  # the squares at the patch's depth: cells
                if n_c + n_f > len(c_root):
                    size = 2 * (n_c + n_f)
                    c_root, c_grid = _grown(c_root, size), _grown(c_grid, size)
                    c_es, c_vs = _grown(c_es, size), _grown(c_vs, size)
                    c_i, c_j = _grown(c_i, size), _grown(c_j, size)
                for a in range(n_f):
                    c_root[n_c], c_grid[n_c] = r, f_grid[a]
                    c_es[n_c], c_vs[n_c] = f_es[a], f_vs[a]
                    c_i[n_c], c_j[n_c] = f_i[a], f_j[a]
                    n_c += 1
                break
            k += 1
            if 4 * n_f > len(x_i):
                size = 8 * n_f
                x_grid, x_es = _grown(x_grid, size), _grown(x_es, size)
                x_vs = _grown(x_vs, size)
                x_i, x_j = _grown(x_i, size), _grown(x_j, size)
            if pieces and n_p + 4 * n_f > len(p_root):
                size = 2 * (n_p + 4 * n_f)
                p_root, p_level = _grown(p_root, size), _grown(p_level, size)
                p_i = _grown(p_i, size)
                p_j, p_own = _grown(p_j, size), _grown(p_own, size)
                p_nets = _grown(p_nets, size)
                p_lo, p_hi = _grown(p_lo, size), _grown(p_hi, size)
            n_x = 0
            for a in range(n_f):
                refine_grid(f_grid[a], f_es[a], f_vs[a], L, kids, k_es, k_vs)
                for q in range(4):
                    ki = 2 * f_i[a] + (1 if q == 1 or q == 2 else 0)
                    kj = 2 * f_j[a] + (1 if q >= 2 else 0)
                    if not grid_regular(k_es[q], k_vs[q]):
                        if not pieces:
                            need[r] = max(need[r], k)
                            square_shell(kids4, q, b_lo, b_hi, b_bound)
                            dist = distance(b_lo, b_hi, q, eye, near, seen_min, seen_max, cone)
                            if margin * b_bound[q] <= tol_rad * dist or k >= limit[r]:
                                for c3 in range(3):  # (refined no further)
                                    box_lo[r, c3] = nan_min(box_lo[r, c3], b_lo[q, c3])
                                    box_hi[r, c3] = nan_max(box_hi[r, c3], b_hi[q, c3])
                                continue
                        x_grid[n_x], x_es[n_x], x_vs[n_x] = kids[q], k_es[q], k_vs[q]
                        x_i[n_x], x_j[n_x] = ki, kj
                        n_x += 1
                        continue
                    bezier(kids4[q], to_bez, tmp, bez)
                    net_bounds(bez, q, b_lo, b_hi, b_bound)
                    n = needed(b_bound[q], distance(b_lo, b_hi, q, eye, near, seen_min,
                                                    seen_max, cone), tol_rad)
                    if not pieces:
                        need[r] = max(need[r], k + np.int64(n))
                        for c3 in range(3):
                            box_lo[r, c3] = nan_min(box_lo[r, c3], b_lo[q, c3])
                            box_hi[r, c3] = nan_max(box_hi[r, c3], b_hi[q, c3])
                        continue
                    p_root[n_p], p_level[n_p], p_i[n_p], p_j[n_p] = r, k, ki, kj
                    p_nets[n_p] = bez
                    p_lo[n_p], p_hi[n_p] = b_lo[q], b_hi[q]
                    # (np.clip of the float k + n, then to int64)
                    own = min(max(np.float64(k) + n, np.float64(k)), np.float64(limit[r]))
                    p_own[n_p] = np.int64(own) if sighted else limit[r]
                    n_p += 1
            f_grid, x_grid, f_es, x_es, f_vs, x_vs = x_grid, f_grid, x_es, f_es, x_vs, f_vs
            f_i, x_i, f_j, x_j = x_i, f_i, x_j, f_j
            n_f = n_x
    return (need, p_root[:n_p], p_level[:n_p], p_i[:n_p], p_j[:n_p], p_nets[:n_p],
            p_own[:n_p], p_lo[:n_p], p_hi[:n_p], c_root[:n_c], c_grid[:n_c], c_es[:n_c],
            c_vs[:n_c], c_i[:n_c], c_j[:n_c])


def _grids_of(level, points, faces):
    """(m,16,3) the control points of ``faces``' grids."""
    ids = control_grids(level, np.asarray(faces, np.int64)).reshape(-1, 16)
    return np.asarray(points, dtype=np.float64)[ids]


def grid_depths(level, points, faces, es, vs, cap, eye, tol_rad, boxes=None):
    """:func:`~subtrace.patches.isolate.isolated_depths` for qualifying ``faces`` (their
    sharpness ``es``, ``vs``: :func:`grid_faces`) by the grid maps: (m,) int32 depths, none
    above ``cap``; ``boxes`` = (lo, hi) (m,3) grown to what each face's isolation ended in,
    as there."""
    cap = np.asarray(cap, dtype=np.int64)
    own = None
    if boxes is not None:
        own = tuple(np.ascontiguousarray(b, dtype=np.float64) for b in boxes)
    need = _isolate(_grids_of(level, points, faces), es, vs, cap, eye, tol_rad, False,
                    boxes=own)[0]
    if boxes is not None:
        for b, o in zip(boxes, own):
            if o is not b:
                b[...] = o
    return np.minimum(need, cap).astype(np.int32)


def grid_pieces(level, points, options, faces, es, vs, depth, eye=None, tol_rad=None,
                ring=False, k0=0, i0=None, j0=None):
    """:func:`~subtrace.patches.isolate.build_isolated`'s ``(subs, cells)`` lists for
    qualifying ``faces`` (their sharpness ``es``, ``vs``) refined down to ``depth`` (m,) by
    the grid maps; the root indices index ``faces``. The faces are squares of level ``k0``
    of their patches at ``i0, j0`` (in units of 2^-k0; default 0: the patches themselves),
    ``depth`` in the patches' units."""
    depth = np.asarray(depth, dtype=np.int64)
    got = _isolate(_grids_of(level, points, faces), es, vs, depth, eye, tol_rad, True, k0,
                   i0, j0)
    subs = [[] for _ in range(8)]  # (isolate.build_isolated's)
    cells = [[] for _ in range(7 if ring else 5)]
    if len(got[1]):
        for lst, a in zip(subs, got[1:9]):
            lst.append(a)
    c_root, c_grid, c_es, c_vs, c_i, c_j = got[9:]
    if len(c_root):
        P, du, dv = (np.empty((len(c_root), 4, 3)) for _ in range(3))
        tw, fw = tangent_tables(False, 4)
        _corner_limits(c_grid, c_es, c_vs, tw[4], fw[4], P, du, dv)
        for lst, a in zip(cells, (c_root, c_i, c_j, P, unit_normals(du, dv))):
            lst.append(a)
        if ring:  # (a grid is its square's one-ring; no corner on the mesh's boundary)
            cells[5].append(np.linalg.norm(c_grid.max(axis=1) - c_grid.min(axis=1), axis=1))
            cells[6].append(np.zeros(len(c_root), dtype=bool))
    return subs, cells


@nb.njit(cache=True, nogil=True)
def _corner_limits(grids, es, vs, tw, fw, P, du, dv):
    """The exact limit points and tangents (along u and v, up to a positive factor) of the
    four corners of the squares of grids ``grids`` (m,16,3), sharpness ``es`` (m,24), ``vs``
    (m,4), into ``P``, ``du``, ``dv`` (m,4,3): each corner's ring (+u, +v, -u, -v) by
    ``gridrefine.ring_limit`` (``tw``, ``fw``: the valence-4 rows of
    ``limit.tangent_tables``)."""
    c = np.empty(3)
    E = np.empty((4, 3))
    D = np.empty((4, 3))
    F = np.empty((4, 3))
    M = np.empty((4, 3))
    s = np.empty(4, np.float32)
    for m in range(grids.shape[0]):
        for q in range(4):
            a, b = CORNERS[q, 0], CORNERS[q, 1]
            for i in range(4):
                # edge i's far end and face i's (between edges i and i + 1) opposite corner
                ea = a + (1 if i == 0 else (-1 if i == 2 else 0))
                eb = b + (1 if i == 1 else (-1 if i == 3 else 0))
                da = a + (1 if i == 0 or i == 3 else -1)
                db = b + (1 if i <= 1 else -1)
                for k in range(3):
                    E[i, k] = grids[m, 4 * ea + eb, k]
                    D[i, k] = grids[m, 4 * da + db, k]
                s[i] = es[m, CORNER_EDGES[q, i]]
            for k in range(3):
                c[k] = grids[m, 4 * a + b, k]
            ring_limit(c, E, D, s, vs[m, q], 4, tw, fw, F, M, P[m, q], du[m, q], dv[m, q])
