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

import math

import numpy as np

from subtrace.config import IRREGULAR_MARGIN
from subtrace.mesh.topology import INF_SHARP, gather_index
from subtrace.patches.basis import TO_BEZIER
from subtrace.patches.bspline import control_grids
from subtrace.patches.grids import levels_needed, unit_normals
from subtrace.patches.shells import sight_distance
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
    m = len(faces)
    ok = np.zeros(m, dtype=bool)
    side = np.zeros(m, np.int64)
    s_lo, s_hi = np.zeros(m, np.float32), np.zeros(m, np.float32)
    if options.scheme != "catmark" or m == 0 or not ENABLED:
        return ok, side, s_lo, s_hi
    # (first the quads with a semi-sharp side: the others, most of a frontier around
    # extraordinary vertices, cost one look at their sides)
    fo = level.face_offsets
    sides = level.edge_sharpness[level.face_edges[np.minimum(
        fo[faces][:, None] + np.arange(4), len(level.face_edges) - 1)]]
    at = np.nonzero(((sides > 0) & (sides < INF_SHARP)).any(axis=1))[0]
    at = at[_plain_corners(level, faces[at])]
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


def _plain_corners(level, faces):
    """(m,) bool: quads whose corners are inside the mesh (one fan of four faces and four
    edges), without vertex sharpness, every face around them a quad and not a hole."""
    fo, vfo, veo = level.face_offsets, level.vert_face_offsets, level.vert_edge_offsets
    quad = np.diff(fo)[faces] == 4
    corners = level.face_verts[np.minimum(fo[faces][:, None] + np.arange(4),
                                          len(level.face_verts) - 1)]
    good = level.vert_manifold[corners] & (vfo[corners + 1] - vfo[corners] == 4)
    good &= (veo[corners + 1] - veo[corners] == 4) & (level.vert_sharpness[corners] == 0)
    ok = quad & good.all(axis=1)
    c = corners[ok]
    around = level.vert_faces[vfo[c][..., None] + np.arange(4)]  # (n,4,4)
    plain = (np.diff(fo)[around] == 4) & ~level.face_hole[around]
    ok[ok] = plain.reshape(len(c), 16).all(axis=1)
    return ok


def _line_sharpness(level, grid):
    """(n,4,3) float32: the sharpness of the edges of each line (``LINES``) of the grids
    ``grid`` (n,16) (point ids, ``[u][v]`` flat), found among the edges of the line's corner
    end of each edge (every edge of a line has one end at a corner of the patch)."""
    veo, ev = level.vert_edge_offsets, level.edge_verts
    pos = LINES[..., 0] * 4 + LINES[..., 1]  # (4,3,2) flat grid positions
    # the end at a corner: the second of the first edge, the first of the others
    at_corner = np.where(np.arange(3)[None, :, None] == 0, pos[:, :, 1:2], pos[:, :, 0:1])[..., 0]
    other = np.where(np.arange(3)[None, :] == 0, pos[:, :, 0], pos[:, :, 1])
    c, o = grid[:, at_corner], grid[:, other]  # (n,4,3)
    edges = level.vert_edges[veo[c][..., None] + np.arange(4)]  # (n,4,3,4)
    ends = ev[edges]
    far = np.where(ends[..., 0] == c[..., None], ends[..., 1], ends[..., 0])
    hit = np.argmax(far == o[..., None], axis=-1)
    e = np.take_along_axis(edges, hit[..., None], axis=-1)[..., 0]
    return level.edge_sharpness[e]


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


def _level(grids, s_lo, s_hi, side, with_nets):
    """One level of the isolation of canonical squares of control grids ``grids`` (n,4,4,3)
    (``[u][v]``, sharpness ``s_lo``, ``s_hi`` at their points 1 and 2 across, patches
    creased on ``side`` (n,)): their four children each, in the order of their corners in
    the patch's frame (corner q is the canonical corner q - side), the regular ones (whose
    crease has run out) first, then the irregular ones. Returns ``(reg (n,4) bool, nets
    (r,4,4,3) in the patches' frames or None, lo, hi (r,3), bound (r,), kids (i,4,4,3)
    canonical grids, their sharpness kid_lo, kid_hi (i,), ring_lo, ring_hi (i,3),
    ring_bound (i,))``: the regular children's Bezier nets (``with_nets``), boxes and
    derivative bounds (``basis.net_bounds``), the irregular ones' grids and one-ring shells
    (``shells.one_ring_shells``'s box and length bound), children in order."""
    n = len(grids)
    z = np.zeros(n, np.float32)
    lo, hi = _decayed(s_lo), _decayed(s_hi)
    turn = (np.arange(4)[None, :] - side[:, None]) % 4  # the canonical corner of each
    kid_lo = np.stack([lo, lo, z, z], axis=1)[np.arange(n)[:, None], turn]
    kid_hi = np.stack([z, z, hi, hi], axis=1)[np.arange(n)[:, None], turn]
    reg = (kid_lo <= 0) & (kid_hi <= 0)
    flat = reg.ravel()
    r, i = int(flat.sum()), int((~flat).sum())
    slot = np.where(flat, np.cumsum(flat) - 1, -np.cumsum(~flat)).reshape(n, 4)
    nets = np.empty((r if with_nets else 0, 4, 4, 3))
    out = (np.empty((r, 3)), np.empty((r, 3)), np.empty(r), np.empty((i, 4, 4, 3)),
           np.empty((i, 3)), np.empty((i, 3)), np.empty(i))
    weights = np.ascontiguousarray(np.stack([_weights(s_lo), _weights(s_hi)], axis=1))
    _refine_level(np.ascontiguousarray(grids), weights, np.ascontiguousarray(side), HALVES,
                  FROM_CANON, TO_BEZIER, np.ascontiguousarray(slot), with_nets, nets, *out)
    return (reg, nets if with_nets else None, *out[:4], kid_lo[~reg], kid_hi[~reg], *out[4:])


@nb.njit(cache=True, nogil=True)
def _refine_level(grids, weights, side, halves, from_canon, to_bez, slot, with_nets, nets,
                  net_lo, net_hi, net_bound, kids, ring_lo, ring_hi, ring_bound):
    """:func:`_level`'s children of the canonical squares ``grids[m]`` (4,4,3): the uniform
    split ``halves`` (2,4,4) along ``u``, across ``v`` the same with its points 1 and 2
    taking the crease rule of weight ``weights[m]`` (2,) (``w`` the point itself, ``1 - w``
    the smooth rule); the child at the patch's corner q goes to ``slot[m, q]`` of the
    regular ones (>= 0: its net, turned into the patch's frame by ``from_canon[side[m]]``
    and converted by ``to_bez`` as ``basis.bspline_nets`` does (:func:`_bezier`,
    :func:`_net_bounds`), into ``nets`` where ``with_nets``, and its bounds) or to ``-1 - slot[m, q]`` of the irregular ones (its
    grid and one-ring shell)."""
    across = np.empty((2, 4, 4))
    along = np.empty((4, 4, 3))
    child = np.empty((1, 4, 4, 3))
    turned = np.empty((4, 4, 3))
    tmp = np.empty((4, 4, 3))
    bez = np.empty((4, 4, 3))
    for m in range(grids.shape[0]):
        # the halves across: rows 1 and 3 of the left, 0 and 2 of the right are the rules
        # at points 1 and 2
        for g in range(2):
            for b in range(4):
                for q in range(4):
                    across[g, b, q] = halves[g, b, q]
        for point in range(2):
            w = weights[m, point]
            for q in range(4):
                rule = (1.0 - w) * halves[0, 2 * point + 1, q]
                if q == point + 1:
                    rule += w
                across[0, 2 * point + 1, q] = rule
                across[1, 2 * point, q] = rule
        for h in range(2):
            for a in range(4):  # the u half's rows
                for q in range(4):
                    for k in range(3):
                        x = 0.0
                        for p in range(4):
                            x += halves[h, a, p] * grids[m, p, q, k]
                        along[a, q, k] = x
            for g in range(2):
                # canonical corner c is the (u, v) half (0,0), (1,0), (1,1), (0,1)
                c = (1 if g == 0 else 2) if h == 1 else (0 if g == 0 else 3)
                for a in range(4):
                    for b in range(4):
                        for k in range(3):
                            x = 0.0
                            for q in range(4):
                                x += across[g, b, q] * along[a, q, k]
                            child[0, a, b, k] = x
                s = slot[m, (c + side[m]) % 4]
                if s < 0:
                    kids[-1 - s] = child[0]
                    _square_shell(kids, -1 - s, ring_lo, ring_hi, ring_bound)
                    continue
                for f in range(16):  # the patch's grid point f is canonical from_canon[f]
                    t = from_canon[side[m], f]
                    for k in range(3):
                        turned[f // 4, f % 4, k] = child[0, t // 4, t % 4, k]
                _bezier(turned, to_bez, tmp, bez)
                _net_bounds(bez, s, net_lo, net_hi, net_bound)
                if with_nets:
                    nets[s] = bez


@leaf_njit
def _bezier(cv, M, tmp, out):
    """The Bezier net ``out`` (4,4,3) of the B-spline grid ``cv`` (4,4,3), ``M`` =
    ``basis.TO_BEZIER``: ``basis.to_bezier``'s sums in its order (so the same bits), with
    its scratch ``tmp`` (4,4,3) given (``to_bezier`` allocates its own per call: half the
    time of the maps' kernel)."""
    for a in range(4):
        for j in range(4):
            for k in range(3):
                tmp[a, j, k] = (M[a, 0] * cv[0, j, k] + M[a, 1] * cv[1, j, k]
                                + M[a, 2] * cv[2, j, k] + M[a, 3] * cv[3, j, k])
    for a in range(4):
        for b in range(4):
            for k in range(3):
                out[a, b, k] = (M[b, 0] * tmp[a, 0, k] + M[b, 1] * tmp[a, 1, k]
                                + M[b, 2] * tmp[a, 2, k] + M[b, 3] * tmp[a, 3, k])


@leaf_njit
def _net_bounds(bez, s, lo, hi, bound):
    """Row ``s`` of the box ``lo``, ``hi`` and derivative bound ``bound`` of the net
    ``bez`` (4,4,3), as ``basis.net_summary`` makes them."""
    for k in range(3):
        lo[s, k] = np.inf
        hi[s, k] = -np.inf
    best = 0.0
    for a in range(4):
        for b in range(4):
            for k in range(3):
                lo[s, k] = min(lo[s, k], bez[a, b, k])
                hi[s, k] = max(hi[s, k], bez[a, b, k])
            if a < 3:
                dx = bez[a + 1, b, 0] - bez[a, b, 0]
                dy = bez[a + 1, b, 1] - bez[a, b, 1]
                dz = bez[a + 1, b, 2] - bez[a, b, 2]
                best = max(best, math.sqrt(dx * dx + dy * dy + dz * dz))
            if b < 3:
                dx = bez[a, b + 1, 0] - bez[a, b, 0]
                dy = bez[a, b + 1, 1] - bez[a, b, 1]
                dz = bez[a, b + 1, 2] - bez[a, b, 2]
                best = max(best, math.sqrt(dx * dx + dy * dy + dz * dz))
    bound[s] = 3.0 * best


@leaf_njit
def _square_shell(grids, m, lo, hi, bound):
    """Box and length bound of the one-ring of square ``m`` whose one-ring is its grid
    ``grids[m]`` (4,4,3), as ``shells.one_ring_shells`` makes them: the grid's box, and
    ``(4 own + 5 most) / 9`` of the longest of its own sides and of every edge of the
    grid."""
    for k in range(3):
        lo[m, k], hi[m, k] = np.inf, -np.inf
    own = 0.0
    most = 0.0
    for a in range(4):
        for b in range(4):
            for k in range(3):
                lo[m, k] = min(lo[m, k], grids[m, a, b, k])
                hi[m, k] = max(hi[m, k], grids[m, a, b, k])
            for da, db in ((1, 0), (0, 1)):
                if a + da > 3 or b + db > 3:
                    continue
                d = 0.0
                for k in range(3):
                    x = grids[m, a + da, b + db, k] - grids[m, a, b, k]
                    d += x * x
                d = math.sqrt(d)
                most = max(most, d)
                # the square's own sides: between its corners, points 1 and 2
                if 1 <= a <= 2 and 1 <= b <= 2 and a + da <= 2 and b + db <= 2:
                    own = max(own, d)
    bound[m] = (4.0 * own + 5.0 * most) / 9.0


def _canonical(level, points, faces, side):
    """(m,4,4,3) the control points of ``faces`` in their canonical frames (``TO_CANON``)."""
    grid = control_grids(level, faces).reshape(-1, 16)
    ids = grid[np.arange(len(faces))[:, None], TO_CANON[side]]
    return np.asarray(points, dtype=np.float64)[ids].reshape(-1, 4, 4, 3)


def crease_depths(level, points, faces, side, s_lo, s_hi, cap, eye, tol_rad, boxes=None):
    """:func:`~subtrace.patches.isolate.isolated_depths` for qualifying ``faces`` (their
    creased ``side`` and sharpness ``s_lo``, ``s_hi``, :func:`crease_faces`) with the maps:
    (m,) int32 depths, none above ``cap``; ``boxes`` = (lo, hi) (m,3) grown to what each
    face's isolation ended in, as there."""
    cap = np.asarray(cap, dtype=np.int64)
    need = np.zeros(len(faces), dtype=np.int64)
    rows = np.nonzero(cap > 0)[0]  # (those of depth 0 are not refined)
    grids = _canonical(level, points, np.asarray(faces)[rows], side[rows])
    lo, hi = s_lo[rows], s_hi[rows]
    k = 0
    while len(rows):
        k += 1
        reg, _, blo, bhi, bound, grids, lo, hi, smin, smax, ebound = _level(
            grids, lo, hi, side[rows], False)
        root = np.repeat(rows, 4).reshape(-1, 4)
        if len(blo):
            n = levels_needed(bound, sight_distance(blo, bhi, eye), tol_rad)
            np.maximum.at(need, root[reg], k + n.astype(np.int64))
            if boxes is not None:
                np.minimum.at(boxes[0], root[reg], blo)
                np.maximum.at(boxes[1], root[reg], bhi)
        rows = root[~reg]
        flat = IRREGULAR_MARGIN * ebound <= tol_rad * sight_distance(smin, smax, eye)
        np.maximum.at(need, rows, k)
        more = ~flat & (k < cap[rows])
        if boxes is not None:  # the irregular children refined no further
            np.minimum.at(boxes[0], rows[~more], smin[~more])
            np.maximum.at(boxes[1], rows[~more], smax[~more])
        rows, grids, lo, hi = rows[more], grids[more], lo[more], hi[more]
    return np.minimum(need, cap).astype(np.int32)


def _turned(i, j, n, side):
    """The patch-frame position of canonical squares at ``i, j`` (units 1/n) of patches
    creased on ``side``."""
    return (np.select([side == 0, side == 1, side == 2], [i, n - 1 - j, n - 1 - i], j),
            np.select([side == 0, side == 1, side == 2], [j, i, n - 1 - j], n - 1 - i))


def crease_pieces(level, points, options, faces, side, s_lo, s_hi, depth, eye=None,
                  tol_rad=None, ring=False, k0=0, i0=None, j0=None):
    """:func:`~subtrace.patches.isolate.build_isolated`'s ``(subs, cells)`` lists for
    qualifying ``faces`` (their creased ``side`` and sharpness ``s_lo``, ``s_hi``) refined
    down to ``depth`` (m,), with the maps; the root indices index ``faces``. The faces are
    squares of level ``k0`` of their patches at ``i0, j0`` (in units of 2^-k0; default 0:
    the patches themselves), ``depth`` in the patches' units. The pieces of a level come
    square by square in the order of the squares' corners, as the topological path lists
    them."""
    depth = np.asarray(depth, dtype=np.int64)
    m = len(faces)
    i0 = np.zeros(m, np.int64) if i0 is None else np.asarray(i0, np.int64)
    j0 = np.zeros(m, np.int64) if j0 is None else np.asarray(j0, np.int64)
    subs = [[] for _ in range(8)]  # (isolate.build_isolated's)
    cells = [[] for _ in range(7 if ring else 5)]
    rows = np.arange(m)
    grids = _canonical(level, points, np.asarray(faces), side)
    lo, hi = s_lo.astype(np.float32), s_hi.astype(np.float32)
    ci = cj = np.zeros(m, np.int64)  # canonical positions, units 2^-(k - k0)
    k = k0
    while len(rows):
        done = depth[rows] == k
        if done.any():
            _add_cells(cells, grids[done], lo[done], hi[done], side[rows[done]], rows[done],
                       *_absolute(ci[done], cj[done], k - k0, side[rows[done]],
                                  i0[rows[done]], j0[rows[done]]))
            keep = ~done
            rows, grids, lo, hi, ci, cj = (a[keep] for a in (rows, grids, lo, hi, ci, cj))
            if not len(rows):
                break
        reg, nets, blo, bhi, bound, grids, lo, hi, _, _, _ = _level(grids, lo, hi, side[rows],
                                                                    True)
        # the children's canonical corners and positions, in the patch's corner order
        turn = (np.arange(4)[None, :] - side[rows][:, None]) % 4
        ki = 2 * ci[:, None] + ((turn == 1) | (turn == 2))
        kj = 2 * cj[:, None] + (turn >= 2)
        root = np.repeat(rows, 4).reshape(-1, 4)
        k += 1
        if len(nets):
            r = root[reg]
            own = depth[r]
            if eye is not None:
                n = levels_needed(bound, sight_distance(blo, bhi, eye), tol_rad)
                own = np.clip(k + n, k, own).astype(np.int64)
            pi, pj = _absolute(ki[reg], kj[reg], k - k0, side[r], i0[r], j0[r])
            for lst, a in zip(subs, (r, np.full(len(r), k), pi, pj, nets, own, blo, bhi)):
                lst.append(np.asarray(a))
        rows, ci, cj = root[~reg], ki[~reg], kj[~reg]
    return subs, cells


def _absolute(ci, cj, d, side, i0, j0):
    """The patch-frame positions (units 2^-(k0 + d)) of canonical squares at ``ci, cj``
    (units 2^-d) of the squares of origin ``i0, j0`` (units 2^-k0)."""
    i, j = _turned(ci, cj, 1 << d, side)
    return (i0 << d) + i, (j0 << d) + j


def _curve_masks(s_lo, s_hi, point):
    """(limit (n,4), slope (n,4)): the limit and derivative masks, over the four points of
    the curves across the crease, at their point ``point`` (1 or 2), whose sharpness is
    ``s_lo`` (point 1) or ``s_hi`` (point 2): the curve refined, its half that keeps the
    point each time, until the point is smooth, then the smooth masks there (the derivative
    up to a positive factor)."""
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


def _add_cells(cells, grids, lo, hi, side, root, i, j):
    """Append the irregular cells of canonical grids ``grids`` (n,4,4,3) (sharpness ``lo``,
    ``hi`` at their points 1 and 2 across the crease) to the lists ``cells``
    (``isolate.build_isolated``'s: the corners' limit points and unit normals in the
    patches' corner order, NaN where undefined; with seven lists, the diagonals of their
    grids' boxes, their one-rings, and no boundary)."""
    across = [_curve_masks(lo, hi, 1), _curve_masks(lo, hi, 2)]
    P, du, dv = (np.empty((len(root), 4, 3)) for _ in range(3))
    for c, (x, y) in enumerate(_CORNER_AT):
        lim, slope = across[y - 1]
        P[:, c] = np.einsum("a,mb,mabk->mk", LIMIT[x - 1], lim, grids)
        du[:, c] = np.einsum("a,mb,mabk->mk", SLOPE[x - 1], lim, grids)
        dv[:, c] = np.einsum("a,mb,mabk->mk", LIMIT[x - 1], slope, grids)
    turn = (np.arange(4)[None, :] - side[:, None]) % 4  # patch corner q: canonical q - side
    at = np.arange(len(root))[:, None]
    P, du, dv = P[at, turn], du[at, turn], dv[at, turn]
    for lst, a in zip(cells, (root, i, j, P, unit_normals(du, dv))):
        lst.append(a)
    if len(cells) > 5:
        cells[5].append(np.linalg.norm(grids.max(axis=(1, 2)) - grids.min(axis=(1, 2)), axis=1))
        cells[6].append(np.zeros(len(root), dtype=bool))
