"""Feature-adaptive isolation of patches along semi-sharp creases by fixed linear maps.

A Catmull-Clark quad whose four corners are inside the mesh, of valence 4 with quads around
them, and whose only features are semi-sharp creases running along one of its sides (or two
opposite ones) from end to end of its 4x4 control grid is a tensor product (Niessner, Loop
and Greiner 2012, "Efficient evaluation of semi-smooth creases in Catmull-Clark subdivision
surfaces"; OpenSubdiv's single-crease patch): for valence-4 vertices every Catmull-Clark rule
is the tensor product of the cubic B-spline curve rules, the crease vertex rule
``(e0 + 6 v + e1) / 8`` is the curve's vertex rule along the crease times the identity across
it, the crease edge rule (the midpoint) the curve's midpoint times the identity, and the
fractional blend of a crease of sharpness ``s`` in (0, 1) is the rule along times
``s identity + (1 - s) smooth`` across, for vertices and edges alike. Along the crease (``u``
here) the patch refines as a uniform cubic B-spline; across it (``v``) as a subdivision curve
whose points on the crease take the sharp rule while the sharpness lasts. With the same
sharpness on the three edges of the crease's grid line, both crease methods give every edge
that the patch's descendants use the same sharpness one level down, less 1 (Chaikin's
average is then the value itself, exactly in float32; with Chaikin, the line's two end
points of the grid must have no other semi-sharp edge, or one of the same sharpness).

What the patch's descendants are is therefore fixed by the sharpness alone: each level of the
isolation (:mod:`subtrace.patches.isolate`) turns a square's 4x4 grid into its four children's
by two 4x4 matrices, the uniform split along ``u`` and the crease-aware split across, and a
child is regular once the crease's sharpness has run out on it (its Bezier net, bounds and
needs are those of its grid, as the topological path makes them). A crease on the grid's
outer line (row 0 or 3) does not change the patch at all: no rule that its descendants use
reads those edges (they are regular already, ``bspline.regular_mask``). The exact limit
points of the corners of the cells left at a patch's depth follow the same curves: the
smooth limit masks along ``u``, and across, the curve refined until its crease is smooth,
then its smooth mask (what ``subdiv/limit.py`` does through topology).

:func:`crease_where` finds the quads (and which side is creased, with the sharpness of each
of the two opposite sides), :func:`crease_depths` and :func:`crease_pieces` do the depth
choice's and the pieces' refinement with the maps, in each patch's canonical frame (turned so
that the crease is its side 0, the opposite one side 2: a rotation, which keeps the normals),
its results put back in the patch's own frame. Where a crease ends or meets another, the
patches there go through topology, and the maps take over their frontier's faces along the
crease level by level (``isolate._Maps``). (Creases on two opposite sides of a grid happen on
a cage's own quads only: one level down, the two creases are two quads apart.) The results
equal the topological path's to rounding (tests/test_crease.py compares them, and the
pieces with OpenSubdiv's limit surface); ``ENABLED`` False sends every patch through
topology.
"""

from __future__ import annotations

import numpy as np

from subtrace.config import IRREGULAR_MARGIN
from subtrace.subdiv.topology import INF_SHARP, gather_index
from subtrace.patches.basis import TO_BEZIER
from subtrace.patches.bspline import control_grids
from subtrace.patches.facememo import FaceMemo
from subtrace.patches.grids import unit_normals
from subtrace.patches.squares import (
    bezier, distance, in_chunks, nan_max, nan_min, needed, net_bounds, sight,
    square_shell,
)
from subtrace.runtime.jit import leaf_njit, nb

ENABLED = True  # False: every creased patch through local topology (tests compare the two)

F1 = np.float32(1.0)

# The four lines of a patch's 4x4 grid through its sides: line k runs along side k (which
# joins corners k and k + 1), its three edges as pairs of grid positions [u][v], the first
# and last from the corner outwards.
LINES = np.array([
    [[[0, 1], [1, 1]], [[1, 1], [2, 1]], [[2, 1], [3, 1]]],
    [[[2, 0], [2, 1]], [[2, 1], [2, 2]], [[2, 2], [2, 3]]],
    [[[3, 2], [2, 2]], [[2, 2], [1, 2]], [[1, 2], [0, 2]]],
    [[[1, 3], [1, 2]], [[1, 2], [1, 1]], [[1, 1], [1, 0]]],
], dtype=np.int64)


def _turns():
    """(4,16) ``to_canon[c]``: the flat grid index (u * 4 + v) in the patch's frame of each
    point of the canonical grid of a patch creased on side ``c`` (turned so that the side is
    side 0: canonical corner 0 is the patch's corner c); (4,16) ``from_canon[c]``: the
    inverse."""
    a, b = np.meshgrid(np.arange(4), np.arange(4), indexing="ij")
    # canonical (a, b) -> the patch's (p, q): c = 1: u = 1 - v', v = u'; c = 2: both
    # reversed; c = 3: u = v', v = 1 - u'
    maps = [(a, b), (3 - b, a), (3 - a, 3 - b), (b, 3 - a)]
    to_canon = np.stack([(p * 4 + q).ravel() for p, q in maps])
    from_canon = np.empty_like(to_canon)
    for c in range(4):
        from_canon[c, to_canon[c]] = np.arange(16)
    return to_canon, from_canon


TO_CANON, FROM_CANON = _turns()

# the uniform cubic B-spline split of 4 curve points into the 4 of each half (rows)
HALVES = np.array([
    [[4, 4, 0, 0], [1, 6, 1, 0], [0, 4, 4, 0], [0, 1, 6, 1]],
    [[1, 6, 1, 0], [0, 4, 4, 0], [0, 1, 6, 1], [0, 0, 4, 4]],
], dtype=np.float64) / 8.0
# the curves' smooth limit masks at points 1 and 2 of 4, and the derivative masks there
LIMIT = np.array([[1.0, 4.0, 1.0, 0.0], [0.0, 1.0, 4.0, 1.0]]) / 6.0
SLOPE = np.array([[-1.0, 0.0, 1.0, 0.0], [0.0, -1.0, 0.0, 1.0]]) / 2.0


def crease_faces(level, options, faces):
    """Which of the irregular quads ``faces`` of ``level`` (Catmull-Clark) the maps serve:
    ``(ok (m,) bool, side (m,) int64, s_lo (m,) float32, s_hi (m,) float32)``: the patch is
    creased along side ``side`` with sharpness ``s_lo`` and along the opposite side with
    ``s_hi`` (0: smooth there). A face qualifies when it is a quad whose corners are inside
    the mesh (one fan), of four edges and four faces, those all quads and no holes, with no
    vertex sharpness; each of the four lines of its grid through its sides (``LINES``) has
    either three smooth edges or three edges of one semi-sharp sharpness, and the creased
    lines are one or two opposite ones; with Chaikin creases, the module doc's conditions."""
    faces = np.asarray(faces, dtype=np.int64)
    if options.scheme != "catmark" or len(faces) == 0 or not ENABLED:
        m = len(faces)
        return np.zeros(m, bool), np.zeros(m, np.int64), np.zeros(m, np.float32), np.zeros(
            m, np.float32)
    return _CREASE_FACES(level, options, faces)


def _crease_faces(level, options, faces):
    """:func:`crease_faces` of each of ``faces`` (distinct), computed."""
    faces = np.asarray(faces, dtype=np.int64)
    m = len(faces)
    ok = np.zeros(m, dtype=bool)
    side = np.zeros(m, np.int64)
    s_lo, s_hi = np.zeros(m, np.float32), np.zeros(m, np.float32)
    if options.scheme != "catmark" or m == 0 or not ENABLED:
        return ok, side, s_lo, s_hi
    # (first the quads with a semi-sharp side and plain corners: the others, most of a
    # frontier around extraordinary vertices, cost one look at their sides)
    at = np.empty(m, np.int64)
    n = _candidates(faces, level.face_offsets, level.face_verts, level.face_edges,
                    level.edge_sharpness, level.vert_face_offsets, level.vert_faces,
                    level.vert_edge_offsets, level.vert_manifold, level.vert_sharpness,
                    level.face_hole, np.float32(INF_SHARP), at)
    at = at[:n]
    if not len(at):
        return ok, side, s_lo, s_hi
    grid = control_grids(level, faces[at]).reshape(-1, 16)
    sharp = _line_sharpness(level, grid)  # (n, 4 lines, 3 edges)
    first = sharp[:, :, 0]
    even = (sharp == first[:, :, None]).all(axis=2)
    creased = even & (first > 0) & (first < INF_SHARP)
    good = (even & ((first == 0) | creased)).all(axis=1) & creased.any(axis=1)
    good &= ~(creased & np.roll(creased, 1, axis=1)).any(axis=1)  # no two adjacent
    s = np.argmax(creased, axis=1)
    rows = np.arange(len(at))
    lo, hi = first[rows, s], np.where(creased[rows, (s + 2) % 4], first[rows, (s + 2) % 4], 0)
    if options.chaikin:
        good &= _chaikin_even(level, grid, creased, first)
    ok[at] = good
    side[at], s_lo[at], s_hi[at] = np.where(good, s, 0), np.where(good, lo, 0), np.where(
        good, hi, 0)
    return ok, side, s_lo, s_hi


@nb.njit(cache=True, nogil=True)
def _candidates(faces, fo, fv, fe, es, vfo, vf, veo, manifold, vsharp, hole, inf_sharp, out):
    """The rows of ``faces`` that may be crease patches, into ``out``; returns their count:
    quads with a semi-sharp side whose corners are inside the mesh (one fan of four faces
    and four edges), without vertex sharpness, every face around them a quad and not a hole
    (the maps' conditions on the corners, module doc), in one pass."""
    n = 0
    for r in range(len(faces)):
        f = faces[r]
        if fo[f + 1] - fo[f] != 4:
            continue
        semi = False
        for k in range(4):
            x = es[fe[fo[f] + k]]
            if x > 0 and x < inf_sharp:
                semi = True
        if not semi:
            continue
        good = True
        for k in range(4):
            v = fv[fo[f] + k]
            if (not manifold[v] or vfo[v + 1] - vfo[v] != 4 or veo[v + 1] - veo[v] != 4
                    or vsharp[v] != 0):
                good = False
                break
            for a in range(vfo[v], vfo[v + 1]):
                g = vf[a]
                if fo[g + 1] - fo[g] != 4 or hole[g]:
                    good = False
            if not good:
                break
        if good:
            out[n] = r
            n += 1
    return n


# each face of a level classified once (the depth choice, the build, the edge sampling and
# the exact normals ask the same faces)
_CREASE_FACES = FaceMemo(_crease_faces, (bool, np.int64, np.float32, np.float32))


# cell_free_depths of a patch whose isolation leaves cells at every depth
CELLS_AT_ANY_DEPTH = np.int64(1) << 40


def cell_free_depths(level, options, faces):
    """(m,) int64: for each irregular quad of ``faces`` of ``level`` that the maps serve
    (:func:`crease_faces`), the depth from which its isolation leaves no cell: the levels
    until the sharpness of both its creased lines has run out (:func:`_decayed`, in
    float32, as the kernel decays it), after which every square is regular, so its pieces
    are all Bezier nets, which sample a side as finely as a neighbour asks (fans); at a
    smaller depth the squares still creased there are cells of exact limit points, which
    sample their sides at the depth alone. ``CELLS_AT_ANY_DEPTH`` for the other faces (an
    extraordinary vertex stays irregular at every level)."""
    ok, _, s_lo, s_hi = crease_faces(level, options, faces)
    out = np.full(len(ok), CELLS_AT_ANY_DEPTH, np.int64)
    s = np.maximum(s_lo, s_hi)[ok]
    n = np.zeros(len(s), np.int64)
    while (s > 0).any():
        n[s > 0] += 1
        s = _decayed(s)
    out[ok] = n
    return out


def crease_where(level, options, faces, levels):
    """:func:`crease_faces` for the ``faces`` with ``levels`` (m,) >= 0 to go below them
    (the others: not ok, unexamined)."""
    m = len(faces)
    ok, side = np.zeros(m, bool), np.zeros(m, np.int64)
    s_lo, s_hi = np.zeros(m, np.float32), np.zeros(m, np.float32)
    live = np.nonzero(np.asarray(levels) >= 0)[0]
    if len(live):
        ok[live], side[live], s_lo[live], s_hi[live] = crease_faces(
            level, options, np.asarray(faces)[live])
    return ok, side, s_lo, s_hi


def _line_sharpness(level, grid):
    """(n,4,3) float32: the sharpness of the edges of each line (``LINES``) of the grids
    ``grid`` (n,16) (point ids, ``[u][v]`` flat), found among the edges of the line's corner
    end of each edge (every edge of a line has one end at a corner of the patch)."""
    out = np.empty((len(grid), 4, 3), np.float32)
    _lines(np.ascontiguousarray(grid, dtype=np.int64), _AT_CORNER, _OTHER,
           level.vert_edge_offsets, level.vert_edges, level.edge_verts, level.edge_sharpness,
           out)
    return out


def _line_ends():
    """(4,3) ``at_corner``, ``other``: the flat grid positions of each line edge's end at
    a patch corner (the second of the first edge, the first of the others) and its other
    end."""
    pos = LINES[..., 0] * 4 + LINES[..., 1]  # (4,3,2)
    first = np.arange(3)[None, :] == 0
    return (np.ascontiguousarray(np.where(first, pos[:, :, 1], pos[:, :, 0])),
            np.ascontiguousarray(np.where(first, pos[:, :, 0], pos[:, :, 1])))


_AT_CORNER, _OTHER = _line_ends()


@nb.njit(cache=True, nogil=True)
def _lines(grid, at_corner, other, veo, ve, ev, es, out):
    """:func:`_line_sharpness` into ``out``: each line edge found among the edges of its
    end at a corner by its other end."""
    for r in range(len(grid)):
        for k in range(4):
            for j in range(3):
                c = grid[r, at_corner[k, j]]
                o = grid[r, other[k, j]]
                e = ve[veo[c]]  # (a corner's edges always hold it: the grid's own)
                for a in range(veo[c], veo[c + 1]):
                    g = ve[a]
                    far = ev[g, 1] if ev[g, 0] == c else ev[g, 0]
                    if far == o:
                        e = g
                        break
                out[r, k, j] = es[e]


def _chaikin_even(level, grid, creased, sharp):
    """(n,) bool, for Chaikin creases: each creased line's two end points of the grid have
    no other semi-sharp edge but at most one of the line's sharpness (then every edge its
    descendants use takes ``t - 1`` at sharpness ``t``, as with uniform creases: Chaikin's
    ``0.75 t + 0.25 t`` is ``t`` in float32, the first product's rounding being below half
    a unit of ``t``'s last place; checked for every float32 from 2^-10 to 10)."""
    ok = np.ones(len(grid), dtype=bool)
    veo = level.vert_edge_offsets
    for k in range(4):
        rows = np.nonzero(creased[:, k])[0]
        if not len(rows):
            continue
        s = sharp[rows, k]
        for end in (LINES[k, 0, 0], LINES[k, 2, 1]):
            v = grid[rows, end[0] * 4 + end[1]]
            es = level.edge_sharpness[level.vert_edges[gather_index(veo, v)]]
            semi = (es > 0) & (es < INF_SHARP)
            owner = np.repeat(np.arange(len(rows)), veo[v + 1] - veo[v])
            count = np.bincount(owner, weights=semi, minlength=len(rows))
            same = np.bincount(owner, weights=semi & (es == s[owner]), minlength=len(rows))
            # the line's own edge, and at most one other: of the line's sharpness
            ok[rows] &= (count == 1) | ((count == 2) & (same == 2))
    return ok


# ------------------------------------------------------------------------------------------
# the maps
# ------------------------------------------------------------------------------------------


def _decayed(s):
    """The sharpness one level down (float32, as ``subdiv/creases.decrement``)."""
    return np.where(s > F1, s - F1, np.float32(0)).astype(np.float32)


def _weights(s):
    """(m,) float64: the crease rule's weight at a point of sharpness ``s`` (float32): 1
    from 1 on (sharp), the sharpness below it (the vertex and edge rules' fractional blend),
    0 at 0 (smooth)."""
    return np.where(s >= F1, 1.0, np.where(s > 0, s.astype(np.float64), 0.0))


def _across(s_lo, s_hi):
    """(m,2,4,4): the split of the curves across the crease into their two halves (rows: the
    half's points from the four), the points 1 and 2 taking the crease rule of sharpness
    ``s_lo`` and ``s_hi`` (:func:`_weights`: ``w`` sharp and ``1 - w`` smooth). Point 1 is
    the left half's point 1 and the right half's 0, point 2 the left's 3 and the right's 2."""
    out = np.broadcast_to(HALVES, (len(s_lo), 2, 4, 4)).copy()
    for point, s, rows in ((1, s_lo, (1, 0)), (2, s_hi, (3, 2))):
        w = _weights(s)
        sharp = np.zeros(4)
        sharp[point] = 1.0
        rule = w[:, None] * sharp + (1.0 - w)[:, None] * HALVES[0, 2 * point - 1]
        out[:, 0, rows[0]] = rule
        out[:, 1, rows[1]] = rule
    return out



# squares of one call of the kernel at most where there are more (a chunk of the thread
# pool's: the chess pieces' creased patches make some 100-500 pieces each)
_SQUARES_PER_CHUNK = 32


def _isolate(grids, s_lo, s_hi, side, limit, eye, tol_rad, pieces, k0=0, i0=None, j0=None,
             boxes=None):
    """Every level of the isolation of canonical squares of control grids ``grids``
    (m,4,4,3) (sharpness ``s_lo``, ``s_hi`` at their points 1 and 2 across, patches creased
    on ``side`` (m,)) by :func:`_isolate_kernel` (module doc; its results: there), in
    chunks of squares on the thread pool. ``pieces`` False: the depth choice, ``limit``
    each square's cap of levels below it; True: the pieces, ``limit`` the patches' depths,
    the squares of level ``k0`` at ``i0``, ``j0``.

    A chunk's pieces and cells come after the chunk before's, each chunk's level by level:
    a square's own come in the same order as from one call, and every caller orders them
    by square first (``isolate.packed_order``, the cells by root), so the result does not
    depend on the chunks or the threads."""
    m = len(grids)
    z = np.zeros(m, np.int64)
    eye_p, near, seen_min, seen_max, cone = sight(eye)
    lo, hi = (np.full((m, 3), np.inf), np.full((m, 3), -np.inf)) if boxes is None else boxes
    per = (np.ascontiguousarray(grids, dtype=np.float64), np.ascontiguousarray(s_lo, np.float32),
           np.ascontiguousarray(s_hi, np.float32), np.ascontiguousarray(side, np.int64),
           np.ascontiguousarray(limit, np.int64))
    at = (z if i0 is None else np.ascontiguousarray(i0, np.int64),
          z if j0 is None else np.ascontiguousarray(j0, np.int64))
    rest = (eye_p, near, seen_min, seen_max, cone, eye is not None,
            float(tol_rad if tol_rad is not None else 0.0), pieces, int(k0))
    tables = (HALVES, FROM_CANON, TO_BEZIER, float(IRREGULAR_MARGIN))

    def call(a, b):
        return _isolate_kernel(*(x[a:b] for x in per), *rest, *(x[a:b] for x in at),
                               *tables, lo[a:b], hi[a:b])

    return in_chunks(call, m, _SQUARES_PER_CHUNK, (1, 9))






@leaf_njit
def _crease_halves(halves, lo, hi, across):
    """``across`` (2,4,4): the split ``halves`` of the curve across the crease, its points 1
    and 2 taking the crease rule of sharpness ``lo``, ``hi`` (:func:`_across`, in a
    kernel): rows 1 and 3 of the left half, 0 and 2 of the right are those rules."""
    one, zero = np.float32(1.0), np.float32(0.0)
    for g in range(2):
        for b in range(4):
            for q in range(4):
                across[g, b, q] = halves[g, b, q]
    for point in range(2):
        s = lo if point == 0 else hi
        w = 1.0 if s >= one else (np.float64(s) if s > zero else 0.0)
        for q in range(4):
            rule = (1.0 - w) * halves[0, 2 * point + 1, q]
            if q == point + 1:
                rule += w
            across[0, 2 * point + 1, q] = rule
            across[1, 2 * point, q] = rule


# _isolate_kernel (about 190 lines) is not split: its steps share the level's frontier,
# the scratch of a child and the counts of what it made; helpers would take a dozen of
# those each, per child
@nb.njit(cache=True, nogil=True)
def _isolate_kernel(grids, s_lo, s_hi, side, limit, eye, near, seen_min, seen_max, cone,
                    sighted, tol_rad, pieces, k0, i0, j0, halves, from_canon, to_bez, margin, box_lo,
                    box_hi):
    """Every level of the isolation of the canonical squares ``grids[m]`` (4,4,3), level by
    level over all of them: each square's four children by the uniform split ``halves``
    (2,4,4) along ``u`` and, across ``v``, the same with its points 1 and 2 taking the
    crease rule (:func:`_weights` of the sharpness there, ``w`` the point itself, ``1 - w``
    the smooth rule), in the order of their corners in the patch's frame (corner q is the
    canonical corner q - side); a child whose crease has run out (its sharpness one level
    down, :func:`_decayed`, 0 on both lines) is regular: its net turned into the patch's
    frame by ``from_canon[side[m]]``, converted as ``basis.bspline_nets`` does
    (:func:`_bezier`), its box and derivative bound as ``basis.net_summary`` makes them;
    the others are refined further.

    ``pieces`` False (the depth choice): square m's levels are capped at ``limit[m]`` (> 0);
    a regular child at level k needs k + ``levels_needed`` of its bound seen from the eye,
    an irregular one k, and is refined no further where its one-ring shell
    (:func:`_square_shell`) is within ``margin`` of the tolerance; ``box_lo``, ``box_hi``
    (m,3) grow to hold what each square's refinement ended in. Returns ``need`` (m,) int64
    (the most of those, before the cap) and the rest empty.

    ``pieces`` True: the squares (level ``k0`` of their patches at ``i0``, ``j0``) are
    refined down to their patches' depth ``limit[m]``; returns ``(need, root, level, i, j,
    nets, own, lo, hi, c_root, c_grid, c_lo, c_hi, c_i, c_j)``: the regular children of
    every level (their square's row, level, patch-frame position, net, own depth
    ``levels_needed`` from the eye clipped to [level, depth], or the depth where not
    ``sighted``, box), level by level, each
    level's square by square in their corners' order (as :func:`crease_pieces` made them a
    level at a time), and the squares left at the depth (row, canonical grid, sharpness and
    patch-frame position at the depth: :func:`_add_cells`'s), in the same order."""
    m = grids.shape[0]
    need = np.zeros(m, np.int64)
    # the frontier: square row, canonical grid, sharpness, canonical position (units of
    # 2^-(k - k0))
    f_root = np.arange(m)
    f_grid = grids.copy()
    f_lo, f_hi = s_lo.copy(), s_hi.copy()
    f_i = np.zeros(m, np.int64)
    f_j = np.zeros(m, np.int64)
    n_f = m
    if not pieces:  # (the squares of no levels below them are not refined)
        n_f = 0
        for r in range(m):
            if limit[r] > 0:
                f_root[n_f] = r
                n_f += 1
        for a in range(n_f):
            f_grid[a] = grids[f_root[a]]
            f_lo[a], f_hi[a] = s_lo[f_root[a]], s_hi[f_root[a]]
    cap_p, cap_c = 0, 0
    if pieces:
        cap_p, cap_c = _counts(s_lo, s_hi, limit, k0, np.zeros(4, np.int64),
                               np.zeros(4, np.float32), np.zeros(4, np.float32))
    p_root = np.empty(cap_p, np.int64)
    p_level = np.empty(cap_p, np.int64)
    p_i = np.empty(cap_p, np.int64)
    p_j = np.empty(cap_p, np.int64)
    p_own = np.empty(cap_p, np.int64)
    p_nets = np.empty((cap_p, 4, 4, 3))
    p_lo = np.empty((cap_p, 3))
    p_hi = np.empty((cap_p, 3))
    n_p = 0
    c_root = np.empty(cap_c, np.int64)
    c_grid = np.empty((cap_c, 4, 4, 3))
    c_lo = np.empty(cap_c, np.float32)
    c_hi = np.empty(cap_c, np.float32)
    c_i = np.empty(cap_c, np.int64)
    c_j = np.empty(cap_c, np.int64)
    n_c = 0
    across = np.empty((2, 4, 4))
    along = np.empty((2, 4, 4, 3))
    child = np.empty((1, 4, 4, 3))
    turned = np.empty((4, 4, 3))
    tmp = np.empty((4, 4, 3))
    bez = np.empty((4, 4, 3))
    b_lo = np.empty((1, 3))
    b_hi = np.empty((1, 3))
    b_bound = np.empty(1)
    zero = np.float32(0.0)
    one = np.float32(1.0)
    k = k0
    while n_f > 0:
        if pieces:  # the squares at their patch's depth: cells
            keep = 0
            for a in range(n_f):
                r = f_root[a]
                if limit[r] != k:
                    if keep != a:
                        f_root[keep], f_grid[keep] = r, f_grid[a]
                        f_lo[keep], f_hi[keep] = f_lo[a], f_hi[a]
                        f_i[keep], f_j[keep] = f_i[a], f_j[a]
                    keep += 1
                    continue
                if n_c == len(c_root):  # (never: _counts is exact)
                    raise ValueError("crease maps: more cells than counted")
                c_root[n_c], c_grid[n_c] = r, f_grid[a]
                c_lo[n_c], c_hi[n_c] = f_lo[a], f_hi[a]
                c_i[n_c], c_j[n_c] = _absolute1(f_i[a], f_j[a], k - k0, side[r], i0[r], j0[r])
                n_c += 1
            n_f = keep
            if n_f == 0:
                break
        k += 1
        n_next = 0
        x_root = np.empty(4 * n_f, np.int64)
        x_grid = np.empty((4 * n_f, 4, 4, 3))
        x_lo = np.empty(4 * n_f, np.float32)
        x_hi = np.empty(4 * n_f, np.float32)
        x_i = np.empty(4 * n_f, np.int64)
        x_j = np.empty(4 * n_f, np.int64)
        for a in range(n_f):
            r = f_root[a]
            sd = side[r]
            lo_s, hi_s = f_lo[a], f_hi[a]
            lo_d = lo_s - one if lo_s > one else zero  # the sharpness one level down
            hi_d = hi_s - one if hi_s > one else zero
            _crease_halves(halves, lo_s, hi_s, across)
            for h in range(2):
                for u in range(4):  # the u half's rows
                    for q in range(4):
                        for c3 in range(3):
                            x = 0.0
                            for p in range(4):
                                x += halves[h, u, p] * f_grid[a, p, q, c3]
                            along[h, u, q, c3] = x
            for corner in range(4):
                c = (corner - sd) % 4  # canonical corner c: the (u, v) half (0,0), (1,0),
                h = 1 if c == 1 or c == 2 else 0  # (1,1), (0,1)
                g = 1 if c >= 2 else 0
                for u in range(4):
                    for b in range(4):
                        for c3 in range(3):
                            x = 0.0
                            for q in range(4):
                                x += across[g, b, q] * along[h, u, q, c3]
                            child[0, u, b, c3] = x
                kid_lo = lo_d if c < 2 else zero
                kid_hi = hi_d if c >= 2 else zero
                ki, kj = 2 * f_i[a] + h, 2 * f_j[a] + g
                if kid_lo > zero or kid_hi > zero:  # irregular: refined further
                    if not pieces:
                        square_shell(child, 0, b_lo, b_hi, b_bound)
                        need[r] = max(need[r], k)
                        dist = distance(b_lo, b_hi, 0, eye, near, seen_min, seen_max, cone)
                        if not (margin * b_bound[0] <= tol_rad * dist) and k < limit[r]:
                            pass
                        else:  # (refined no further)
                            for c3 in range(3):
                                box_lo[r, c3] = nan_min(box_lo[r, c3], b_lo[0, c3])
                                box_hi[r, c3] = nan_max(box_hi[r, c3], b_hi[0, c3])
                            continue
                    x_root[n_next], x_grid[n_next] = r, child[0]
                    x_lo[n_next], x_hi[n_next] = kid_lo, kid_hi
                    x_i[n_next], x_j[n_next] = ki, kj
                    n_next += 1
                    continue
                for f in range(16):  # the patch's grid point f is canonical from_canon[f]
                    t = from_canon[sd, f]
                    for c3 in range(3):
                        turned[f // 4, f % 4, c3] = child[0, t // 4, t % 4, c3]
                bezier(turned, to_bez, tmp, bez)
                net_bounds(bez, 0, b_lo, b_hi, b_bound)
                n = needed(b_bound[0], distance(b_lo, b_hi, 0, eye, near, seen_min,
                                                  seen_max, cone), tol_rad)
                if not pieces:
                    need[r] = max(need[r], k + np.int64(n))
                    for c3 in range(3):
                        box_lo[r, c3] = nan_min(box_lo[r, c3], b_lo[0, c3])
                        box_hi[r, c3] = nan_max(box_hi[r, c3], b_hi[0, c3])
                    continue
                if n_p == len(p_root):  # (never: _counts is exact)
                    raise ValueError("crease maps: more pieces than counted")
                p_root[n_p], p_level[n_p] = r, k
                p_i[n_p], p_j[n_p] = _absolute1(ki, kj, k - k0, sd, i0[r], j0[r])
                p_nets[n_p] = bez
                p_lo[n_p], p_hi[n_p] = b_lo[0], b_hi[0]
                # (np.clip of the float k + n, then to int64)
                own = min(max(np.float64(k) + n, np.float64(k)), np.float64(limit[r]))
                p_own[n_p] = np.int64(own) if sighted else limit[r]
                n_p += 1
        f_root, f_grid, f_lo, f_hi, f_i, f_j = x_root, x_grid, x_lo, x_hi, x_i, x_j
        n_f = n_next
    if n_p != len(p_root) or n_c != len(c_root):
        raise ValueError("crease maps: fewer pieces or cells than counted")
    return (need, p_root[:n_p], p_level[:n_p], p_i[:n_p], p_j[:n_p], p_nets[:n_p],
            p_own[:n_p], p_lo[:n_p], p_hi[:n_p], c_root[:n_c], c_grid[:n_c], c_lo[:n_c],
            c_hi[:n_c], c_i[:n_c], c_j[:n_c])


@leaf_njit
def _absolute1(ci, cj, d, side, i0, j0):
    """The patch-frame position (units 2^-(k0 + d)) of the canonical square at ``ci, cj``
    (units 2^-d) of a square of origin ``i0, j0`` (units 2^-k0) of a patch creased on
    ``side``."""
    n = np.int64(1) << d
    if side == 0:
        i, j = ci, cj
    elif side == 1:
        i, j = n - 1 - cj, ci
    elif side == 2:
        i, j = n - 1 - ci, n - 1 - cj
    else:
        i, j = cj, n - 1 - ci
    return (i0 << d) + i, (j0 << d) + j


@leaf_njit
def _counts(s_lo, s_hi, depth, k0, mult, lo, hi):
    """How many pieces and cells :func:`_isolate_kernel` makes of squares of sharpness
    ``s_lo``, ``s_hi`` at level ``k0`` refined down to ``depth``: what they are depends on
    the sharpness alone. Of a square's children, the two at canonical corners 0 and 1 take
    the low line's sharpness one level down and the high line none, the other two the
    reverse; so the squares of a level of one patch are of two kinds at most, counted
    with their multiplicity (``mult``, ``lo``, ``hi``: (4,) scratch)."""
    n_p, n_c = 0, 0
    zero, one = np.float32(0.0), np.float32(1.0)
    for r in range(len(s_lo)):
        # the kinds of square of the current level: multiplicity, sharpness
        mult[0], lo[0], hi[0], n_k = 1, s_lo[r], s_hi[r], 1
        k = k0
        while n_k > 0:
            if depth[r] == k:
                for a in range(n_k):
                    n_c += mult[a]
                break
            k += 1
            n_new = 0
            for a in range(n_k):
                lo_d = lo[a] - one if lo[a] > one else zero
                hi_d = hi[a] - one if hi[a] > one else zero
                for pair in range(2):  # corners 0 and 1, then 2 and 3
                    s = lo_d if pair == 0 else hi_d
                    if s > zero:
                        mult[2 + n_new] = 2 * mult[a]
                        lo[2 + n_new] = s if pair == 0 else zero
                        hi[2 + n_new] = zero if pair == 0 else s
                        n_new += 1
                    else:
                        n_p += 2 * mult[a]
            for a in range(n_new):
                mult[a], lo[a], hi[a] = mult[2 + a], lo[2 + a], hi[2 + a]
            n_k = n_new
    return n_p, n_c





def _canonical(level, points, faces, side):
    """(m,4,4,3) the control points of ``faces`` in their canonical frames (``TO_CANON``)."""
    grid = control_grids(level, faces).reshape(-1, 16)
    ids = grid[np.arange(len(faces))[:, None], TO_CANON[side]]
    return np.asarray(points, dtype=np.float64)[ids].reshape(-1, 4, 4, 3)


def crease_depths(level, points, faces, side, s_lo, s_hi, cap, eye, tol_rad, boxes=None):
    """:func:`~subtrace.patches.isolate.isolated_depths` for qualifying ``faces`` (their
    creased ``side`` and sharpness ``s_lo``, ``s_hi``, :func:`crease_faces`) with the maps:
    (m,) int32 depths, none above ``cap``; ``boxes`` = (lo, hi) (m,3) grown to what each
    face's isolation ended in, as there. Every level in one kernel call
    (:func:`_isolate_kernel`)."""
    cap = np.asarray(cap, dtype=np.int64)
    grids = _canonical(level, points, np.asarray(faces), side)
    own = None
    if boxes is not None:
        own = tuple(np.ascontiguousarray(b, dtype=np.float64) for b in boxes)
    need = _isolate(grids, s_lo, s_hi, side, cap, eye, tol_rad, False, boxes=own)[0]
    if boxes is not None:
        for b, o in zip(boxes, own):
            if o is not b:
                b[...] = o
    return np.minimum(need, cap).astype(np.int32)


def crease_pieces(level, points, options, faces, side, s_lo, s_hi, depth, eye=None,
                  tol_rad=None, ring=False, k0=0, i0=None, j0=None):
    """:func:`~subtrace.patches.isolate.build_isolated`'s ``(subs, cells)`` lists for
    qualifying ``faces`` (their creased ``side`` and sharpness ``s_lo``, ``s_hi``) refined
    down to ``depth`` (m,), with the maps; the root indices index ``faces``. The faces are
    squares of level ``k0`` of their patches at ``i0, j0`` (in units of 2^-k0; default 0:
    the patches themselves), ``depth`` in the patches' units. The pieces of a level come
    square by square in the order of the squares' corners, as the topological path lists
    them; every level in one kernel call (:func:`_isolate_kernel`)."""
    depth = np.asarray(depth, dtype=np.int64)
    side = np.asarray(side, dtype=np.int64)
    grids = _canonical(level, points, np.asarray(faces), side)
    got = _isolate(grids, s_lo, s_hi, side, depth, eye, tol_rad, True, k0, i0, j0)
    subs = [[] for _ in range(8)]  # (isolate.build_isolated's)
    cells = [[] for _ in range(7 if ring else 5)]
    if len(got[1]):
        for lst, a in zip(subs, got[1:9]):
            lst.append(a)
    c_root, c_grid, c_lo, c_hi, c_i, c_j = got[9:]
    if len(c_root):
        _add_cells(cells, c_grid, c_lo, c_hi, side[c_root], c_root, c_i, c_j)
    return subs, cells


def _curve_masks(s_lo, s_hi, point):
    """(limit (n,4), slope (n,4)): the limit and derivative masks, over the four points of
    the curves across the crease, at their point ``point`` (1 or 2), whose sharpness is
    ``s_lo`` (point 1) or ``s_hi`` (point 2): the curve refined, its half that keeps the
    point each time, until the point is smooth, then the smooth masks there (the derivative
    up to a positive factor). Made once in the process for each distinct pair of sharpness
    and point (a cage's creases have a few; :data:`_MASKS`)."""
    lo, hi = np.asarray(s_lo, np.float32), np.asarray(s_hi, np.float32)
    key = (lo.view(np.uint32).astype(np.int64) << 32) | hi.view(np.uint32).astype(np.int64)
    pairs, first, which = np.unique(key, return_index=True, return_inverse=True)
    new = [k for k, p in enumerate(pairs.tolist()) if (p, point) not in _MASKS]
    if new:
        at = first[new]
        limit, slope = _pair_masks(lo[at], hi[at], point)
        for r, k in enumerate(new):
            _MASKS[(int(pairs[k]), point)] = (limit[r], slope[r])
    got = [_MASKS[(p, point)] for p in pairs.tolist()]
    limit = np.array([g[0] for g in got]).reshape(-1, 4)
    slope = np.array([g[1] for g in got]).reshape(-1, 4)
    return limit[which.ravel()], slope[which.ravel()]


# (the float32 bits of s_lo << 32 | those of s_hi, point 1 or 2) -> (limit (4,), slope (4,))
_MASKS: dict = {}


def _pair_masks(s_lo, s_hi, point):
    """:func:`_curve_masks` of each pair."""
    n = len(s_lo)
    mat = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    lo, hi = s_lo.astype(np.float32), s_hi.astype(np.float32)
    half = point - 1  # (point 1 stays point 1 of the left half, point 2 of the right one)
    while True:
        live = (lo if point == 1 else hi) > 0
        if not live.any():
            break
        step = _across(lo[live], hi[live])[:, half]
        mat[live] = step @ mat[live]
        z = np.zeros(int(live.sum()), np.float32)
        lo[live], hi[live] = (_decayed(lo[live]), z) if point == 1 else (z, _decayed(hi[live]))
    return LIMIT[half] @ mat, SLOPE[half] @ mat


# canonical corner c of a square: its (u, v) points in the grid
_CORNER_AT = ((1, 1), (2, 1), (2, 2), (1, 2))


@nb.njit(cache=True, nogil=True)
def _corner_limits(grids, lim1, slope1, lim2, slope2, P, du, dv):
    """The limit points and tangents of the canonical corners of ``grids`` (m,4,4,3):
    along the crease the B-spline masks (``LIMIT``, ``SLOPE``) of the corner's point 1 or
    2, across it the curve masks of :func:`_curve_masks` at that point (``lim1``,
    ``slope1``: point 1; ``lim2``, ``slope2``: point 2; (m,4) each), summed a (along)
    outer, b (across) inner: the terms and order of ``einsum("a,mb,mabk->mk")``, one call
    for every cell of a batch instead of twelve."""
    for m in range(grids.shape[0]):
        for c in range(4):
            x = 1 if c == 1 or c == 2 else 0  # (_CORNER_AT: point 1 or 2 along / across)
            y = 1 if c >= 2 else 0
            for k in range(3):
                p = 0.0
                a_u = 0.0
                a_v = 0.0
                for a in range(4):
                    for b in range(4):
                        g = grids[m, a, b, k]
                        lim = lim2[m, b] if y else lim1[m, b]
                        slope = slope2[m, b] if y else slope1[m, b]
                        p += (LIMIT[x, a] * lim) * g
                        a_u += (SLOPE[x, a] * lim) * g
                        a_v += (LIMIT[x, a] * slope) * g
                P[m, c, k] = p
                du[m, c, k] = a_u
                dv[m, c, k] = a_v


def _add_cells(cells, grids, lo, hi, side, root, i, j):
    """Append the irregular cells of canonical grids ``grids`` (n,4,4,3) (sharpness ``lo``,
    ``hi`` at their points 1 and 2 across the crease) to the lists ``cells``
    (``isolate.build_isolated``'s: the corners' limit points and unit normals in the
    patches' corner order, NaN where undefined; with seven lists, the diagonals of their
    grids' boxes, their one-rings, and no boundary)."""
    (lim1, slope1), (lim2, slope2) = _curve_masks(lo, hi, 1), _curve_masks(lo, hi, 2)
    P, du, dv = (np.empty((len(root), 4, 3)) for _ in range(3))
    _corner_limits(np.ascontiguousarray(grids, dtype=np.float64), lim1, slope1, lim2, slope2,
                   P, du, dv)
    turn = (np.arange(4)[None, :] - side[:, None]) % 4  # patch corner q: canonical q - side
    at = np.arange(len(root))[:, None]
    P, du, dv = P[at, turn], du[at, turn], dv[at, turn]
    for lst, a in zip(cells, (root, i, j, P, unit_normals(du, dv))):
        lst.append(a)
    if len(cells) > 5:
        cells[5].append(np.linalg.norm(grids.max(axis=(1, 2)) - grids.min(axis=(1, 2)), axis=1))
        cells[6].append(np.zeros(len(root), dtype=bool))


# --------------------------------------------------------------------------------------
# exact normals inside a patch the maps serve
# --------------------------------------------------------------------------------------


def crease_normals(level, points, options, faces, uv):
    """The limit surface's normals (unnormalised, the patch's orientation) at the patch
    parameters ``uv`` (m,2) of the quads ``faces`` (m,) of ``level``: ``(ok (m,), n
    (m,3))``, ``ok`` where the maps serve the face (:func:`crease_faces`; elsewhere n is 0),
    ``du x dv`` of :func:`crease_derivatives`."""
    ok, _, _, _, n = _crease_eval(level, points, options, faces, uv)
    return ok, n


def crease_derivatives(level, points, options, faces, uv):
    """The limit surface at the patch parameters ``uv`` (m,2) of the quads ``faces`` (m,)
    of ``level``: ``(ok (m,), P, dP/du, dP/dv (m,3) each)``, ``ok`` where the maps serve
    the face (:func:`crease_faces`; elsewhere all 0). Such a patch is, along its crease,
    the uniform cubic B-spline of its grid's rows, and across it the curve whose points 1
    and 2 take the crease rule: the curve is split at the parameter, the half holding it
    kept, until its sharpness has run out (as :func:`_curve_masks` follows a point), then
    evaluated and differentiated as a B-spline there, the derivative across scaled back by
    the halvings."""
    return _crease_eval(level, points, options, faces, uv)[:4]


def _crease_eval(level, points, options, faces, uv):
    """:func:`crease_derivatives` and the normals of :func:`crease_normals` (m,3): ``du x
    dv`` of the last split's parameter."""
    faces = np.asarray(faces, np.int64)
    uv = np.asarray(uv, np.float64).reshape(-1, 2)
    m = len(faces)
    pos, du, dv, n = (np.zeros((m, 3)) for _ in range(4))
    ok, side, s_lo, s_hi = crease_faces(level, options, faces)
    at = np.nonzero(ok)[0]
    if len(at):
        grids = _canonical(level, points, faces[at], side[at])
        u, v = uv[at, 0], uv[at, 1]
        s = side[at]
        # the patch's (u, v) in the canonical frame (the inverse of _turns' maps)
        cu = np.select([s == 0, s == 1, s == 2], [u, v, 1.0 - u], 1.0 - v)
        cv = np.select([s == 0, s == 1, s == 2], [v, 1.0 - u, 1.0 - v], u)
        out = np.zeros((4, len(at), 3))
        _crease_derivatives(grids, s_lo[at], s_hi[at], cu, cv, HALVES, out)
        c_u, c_v = out[1], out[2]
        # back to the patch's frame: d/du and d/dv of the canonical (cu, cv) above
        pos[at] = out[0]
        s = s[:, None]
        du[at] = np.select([s == 0, s == 1, s == 2], [c_u, -c_v, -c_u], c_v)
        dv[at] = np.select([s == 0, s == 1, s == 2], [c_v, c_u, -c_v], -c_u)
        n[at] = out[3]
    return ok, pos, du, dv, n


@nb.njit(cache=True, nogil=True)
def _crease_derivatives(grids, s_lo, s_hi, cu, cv, halves, out):
    """:func:`crease_derivatives`' kernel: per sample, the curve across split at ``cv``
    down to where its sharpness has run out (its points as combinations ``mat`` of the
    grid's four columns, ``scale`` the parameter's stretch), then the B-spline along
    (``cu``) and across: ``out[0]`` the point, ``out[1]``, ``out[2]`` its derivatives in
    ``cu`` and ``cv``, ``out[3]`` the normal ``out[1] x out[2]`` as the last split's
    parameter has it (the scale left out)."""
    mat = np.empty((4, 4))
    across = np.empty((2, 4, 4))
    nxt = np.empty((4, 4))
    b_u, d_u, b_v, d_v = np.empty(4), np.empty(4), np.empty(4), np.empty(4)
    wb, wd = np.empty(4), np.empty(4)
    f0, f1 = np.float32(0.0), np.float32(1.0)
    for m in range(grids.shape[0]):
        mat[:, :] = 0.0
        for k in range(4):
            mat[k, k] = 1.0
        lo, hi = s_lo[m], s_hi[m]
        t = cv[m]
        scale = 1.0
        for _ in range(64):
            if not (lo > f0 or hi > f0):
                break
            half = 0 if t < 0.5 else 1
            _crease_halves(halves, lo, hi, across)
            for r in range(4):
                for c in range(4):
                    acc = 0.0
                    for k in range(4):
                        acc += across[half, r, k] * mat[k, c]
                    nxt[r, c] = acc
            mat[:, :] = nxt
            t = 2.0 * t - half
            scale *= 2.0
            if half == 0:
                lo, hi = (lo - f1 if lo > f1 else f0), f0
            else:
                lo, hi = f0, (hi - f1 if hi > f1 else f0)
        _cubic(t, b_v, d_v)
        _cubic(cu[m], b_u, d_u)
        # the masks across on the grid's columns
        for c in range(4):
            wb[c] = 0.0
            wd[c] = 0.0
            for k in range(4):
                wb[c] += b_v[k] * mat[k, c]
                wd[c] += d_v[k] * mat[k, c]
        for d in range(3):
            out[0, m, d] = 0.0
            out[1, m, d] = 0.0
            out[2, m, d] = 0.0
        for a in range(4):
            for c in range(4):
                for d in range(3):
                    g = grids[m, a, c, d]
                    out[0, m, d] += b_u[a] * wb[c] * g
                    out[1, m, d] += d_u[a] * wb[c] * g
                    out[2, m, d] += b_u[a] * wd[c] * g
        du0, du1, du2 = out[1, m, 0], out[1, m, 1], out[1, m, 2]
        dv0, dv1, dv2 = out[2, m, 0], out[2, m, 1], out[2, m, 2]
        out[3, m, 0] = du1 * dv2 - du2 * dv1
        out[3, m, 1] = du2 * dv0 - du0 * dv2
        out[3, m, 2] = du0 * dv1 - du1 * dv0
        for d in range(3):
            out[2, m, d] *= scale


@leaf_njit
def _cubic(t, b, d):
    """The uniform cubic B-spline basis and its derivative at ``t`` into ``b``, ``d``
    (4,)."""
    s = 1.0 - t
    b[0] = s * s * s / 6.0
    b[1] = (3.0 * t * t * t - 6.0 * t * t + 4.0) / 6.0
    b[2] = (-3.0 * t * t * t + 3.0 * t * t + 3.0 * t + 1.0) / 6.0
    b[3] = t * t * t / 6.0
    d[0] = -s * s / 2.0
    d[1] = (3.0 * t * t - 4.0 * t) / 2.0
    d[2] = (-3.0 * t * t + 2.0 * t + 1.0) / 2.0
    d[3] = t * t / 2.0
