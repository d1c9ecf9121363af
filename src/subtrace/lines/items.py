"""The items of line queries: Bezier nets over parts of a cage's patches, per cage and
precision (:mod:`subtrace.lines.api` queries them, :mod:`subtrace.lines.kernels` intersects
them).

Two kinds of item, each a net of :mod:`subtrace.patches.basis` over part of a ptex face
(``uv0 + scale * (s, t)``; ``scale`` negative for a turned Loop middle child), and *exact*
(the limit surface itself) or a *cell* (a flat stand-in within ``precision / 2`` of it):

* bicubic nets (m,4,4,3) (Catmull-Clark): the regular patches' nets from the patch table;
  irregular patches some line's shell test asked for are isolated into regular pieces
  (:func:`subtrace.patches.isolate.build_isolated`) plus cells of exact limit points at the
  feature, degree-elevated bilinear nets (``Items._isolate``);
* quartic triangular nets (m,15,3) (Loop): a triangle of the cage is *regular* when its
  three corners are smooth, of valence 6 and crease-free (the exact evaluator's test,
  :mod:`subtrace.patches.evaluate`), or a regular boundary (:func:`_boundary_recipe`): its
  limit surface is then the quartic box spline of the 12 points around it, which is one
  quartic polynomial, converted to its 15-point triangular Bezier net (``BOX_TO_TRI``).
  Any other patch (an extraordinary vertex, a crease, a boundary, a semi-sharp feature) is
  *isolated* as OpenSubdiv's feature-adaptive refinement does, only for the patches whose
  shell a line meets (:func:`isolate_loop`): the faces around it are refined one level at a
  time (locally, with the subdivision core itself, so every rule is honoured); the children
  that are regular become Bezier items; the others are refined again until the box of their
  one-ring control points has a diagonal of at most ``allowed``. Such a cell becomes a flat
  item, the triangle of its corners' exact limit points: the cell's limit surface lies in
  the convex hull of its one-ring points (non-negative masks), and so does that triangle, so
  every point of the triangle lies within the box diagonal of the surface over the cell (a
  proven bound, not a measured one). Near an extraordinary vertex the one-ring shrinks by
  the subdominant eigenvalue per level, so a cell is reached after a few levels; along a
  boundary or a crease it shrinks by 1/2 per level and the cells there number about
  ``edge length / allowed`` per edge of a patch a line meets (for Catmull-Clark only at
  semi-sharp creases: quads along boundaries and infinitely sharp creases are regular).

A cage's items live on the cage (:func:`items_for`): :class:`CageItems` what every precision
shares (the patch table, the regular nets), :class:`Items` one precision's (isolated
lazily, per line batch, kept for later calls), for the latest ``CACHED_PRECISIONS``.
"""

from __future__ import annotations

import numpy as np

from subtrace import config
from subtrace.accel.bvh import build_bvh, padded
from subtrace.lines.kernels import mark_shells
from subtrace.mesh.topology import INF_SHARP
from subtrace.patches.basis import (
    BOX_POINTS, BOX_TO_TRI, CHILD_ORIGIN, CHILD_SCALE, FLAT_TO_TRI, LATTICE_DIRS, N_TRI,
    TRI_CORNER, TRI_LEAD,
)
from subtrace.patches.grids import refine_children
from subtrace.patches.isolate import build_isolated
from subtrace.patches.shells import one_ring_shells
from subtrace.patches.table import build_patch_table
from subtrace.runtime.jit import leaf_njit, nb
from subtrace.subdiv.limit import CREASE, SMOOTH, classify, limit_points
from subtrace.subdiv.loop import REGULAR_VALENCE

# An irregular Catmull-Clark patch is isolated at most this deep (2^-40 of its side is below
# what double parameters resolve).
MAX_ISOLATION = 40


class CageItems:
    """What a cage's line queries share whatever the precision (kept on the cage, see
    :func:`items_for`): the patch table and the regular patches' Bezier nets."""

    def __init__(self, cage):
        self.table = tb = build_patch_table([cage])
        self.loop = cage.scheme == "loop"
        if self.loop:
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


class Items:
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
        self.capped = False  # isolation stopped at MAX_ISOLATION above the precision
        # the largest proven bound (one-ring box diagonal) of an interior Catmull-Clark cell
        self.cell_bound = 0.0
        self._finish()

    def _add(self, tri, nets, exact, ptex, uv0, scale):
        for lst, x in zip(self.parts[tri], (nets, np.full(len(nets), exact), ptex, uv0,
                                            scale)):
            lst.append(x)

    def _finish(self):
        cat = {tri: [np.concatenate(x) if x else None for x in self.parts[tri]]
               for tri in (False, True)}
        q, t = cat[False], cat[True]
        self.all_nets = np.ascontiguousarray(q[0]) if q[0] is not None else \
            np.zeros((0, 4, 4, 3))
        self.all_tnets = np.ascontiguousarray(t[0]) if t[0] is not None else \
            np.zeros((0, N_TRI, 3))
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
        todo = ~self.built
        if not todo.any():
            return
        if self.shell_bvh is None:
            self.shell_min = np.ascontiguousarray(self.table.shell_min[self.irregular])
            self.shell_max = np.ascontiguousarray(self.table.shell_max[self.irregular])
            self.shell_bvh = build_bvh(self.shell_min, self.shell_max)
        bv = self.shell_bvh
        hit = np.zeros(len(self.irregular), bool)
        mark_shells(org, dirs, t_lo, t_hi, self.shell_min - pad, self.shell_max + pad,
                    padded(bv, pad), self.built, hit)
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
        tb = self.table
        obj = tb.objects[0]
        bound = config.IRREGULAR_MARGIN * tb.edge_bound[rows]
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
        # proven bound) is above precision / 2, until none is, on the mesh's boundary too:
        # boundary and infinitely sharp crease quads are regular pieces (phantom points,
        # patches.bspline), so cells remain only at irregular boundary vertices and do not
        # double along the boundary (catmark_edgeonly at 1e-3: 482 items, 446 with the first
        # guess kept there as before)
        subs, cells = [[] for _ in range(5)], [[] for _ in range(4)]
        todo = np.arange(len(rows))
        while len(todo):
            (root, level, i0, j0, bez, *_), (croot, ci, cj, cpts, _, diag, _) = \
                build_isolated(obj, tb.face[rows[todo]], d[todo], ring=True)
            again = np.zeros(len(todo), bool)
            again[croot[grow * diag > allowed]] = True
            if np.any(again & (d[todo] >= MAX_ISOLATION)):
                self.capped = True  # (said by intersect_lines: a limit is never silent)
            again &= d[todo] < MAX_ISOLATION
            # what the patches done now were built into
            keep_s, keep_c = ~again[root], ~again[croot]
            for lst, a in zip(subs, (todo[root], level, i0, j0, bez)):
                lst.append(a[keep_s])
            for lst, a in zip(cells, (todo[croot], ci, cj, cpts)):
                lst.append(a[keep_c])
            kept = (grow * diag)[keep_c]
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


def items_for(cage, precision) -> Items:
    """The cage's items at ``precision``, kept on the cage (its ``_cache``, which lives and
    dies with the immutable cage) so that repeated calls skip the patch table, the Bezier
    conversion and the isolation already done; the latest ``CACHED_PRECISIONS`` are kept."""
    store = cage._cache.setdefault("lines", {})
    if "base" not in store:
        store["base"] = CageItems(cage)
    by_prec = store.setdefault("items", {})
    items = by_prec.pop(precision, None)
    if items is None:
        items = Items(store["base"], precision)
    by_prec[precision] = items  # most recent last
    while len(by_prec) > CACHED_PRECISIONS:
        by_prec.pop(next(iter(by_prec)))
    return items


# ------------------------------------------------------------------------------------------
# Loop items
# ------------------------------------------------------------------------------------------

def loop_regular(level, options, faces) -> np.ndarray:
    """(len(faces),) bool: the triangles of ``level`` that are regular quartic box splines:
    three smooth, valence-6, crease-free corners, or a regular boundary (see
    :func:`_boundary_recipe`)."""
    faces = np.asarray(faces, dtype=np.int64)
    if len(faces) == 0:
        return np.zeros(0, dtype=bool)
    fo = level.face_offsets
    tri = (fo[faces + 1] - fo[faces]) == 3
    corners = level.face_verts[np.minimum(fo[faces][:, None] + np.arange(3),
                                          len(level.face_verts) - 1)]
    cls = classify(level, options, corners)
    n_edges = np.diff(level.vert_edge_offsets)[corners]
    n_faces = np.diff(level.vert_face_offsets)[corners]
    inner = ((cls[corners] == SMOOTH) & (n_edges == REGULAR_VALENCE)
             & (n_faces == REGULAR_VALENCE))
    ok = tri & inner.all(axis=1) & ~level.face_hole[faces]
    # crease vertices (a boundary, or an infinitely sharp crease): _boundary_recipe decides
    border = (cls[corners] == CREASE) & level.vert_manifold[corners]
    maybe = np.nonzero(tri & ~ok & (inner | border).all(axis=1) & border.any(axis=1)
                       & ~level.face_hole[faces])[0]
    if len(maybe):
        ok[maybe] = _boundary_recipes(level, faces[maybe], level.edge_sharpness >= INF_SHARP)[0]
    return ok


def box_nets(level, points, faces) -> np.ndarray:
    """(m,15,3) triangular Bezier nets of the regular triangles ``faces`` of ``level``."""
    faces = np.asarray(faces, dtype=np.int64)
    fo = level.face_offsets
    corners = level.face_verts[fo[faces][:, None] + np.arange(3)]
    sharp = level.edge_sharpness >= INF_SHARP
    on_crease = np.zeros(level.n_verts, dtype=bool)
    on_crease[level.edge_verts[sharp].ravel()] = True
    inner = ~on_crease[corners].any(axis=1)  # else a crease corner: phantom points
    X = np.empty((len(faces), len(BOX_POINTS), 3))
    rows = np.nonzero(inner)[0]
    ids = np.empty((len(rows), len(BOX_POINTS)), dtype=np.int64)
    _box_points(level.face_offsets, level.face_verts, level.vert_face_offsets, level.vert_faces,
                level.vert_edge_offsets, level.vert_edges, level.edge_verts,
                faces[rows], _RING_SLOT, ids)
    X[rows] = points[ids]
    border = np.nonzero(~inner)[0]
    if len(border):
        _, abr = _boundary_recipes(level, faces[border], sharp)
        a, b, r = abr[:, 0], abr[:, 1], abr[:, 2]
        X[border] = points[a] + np.where(b[..., None] >= 0, points[b] - points[r], 0.0)
    return np.ascontiguousarray(np.matmul(BOX_TO_TRI, X))


def _boundary_recipe(level, f, sharp_edge):
    """The 12 box-spline points of triangle ``f`` with corners on a boundary or an
    infinitely sharp crease, or None (:func:`_boundary_recipes` for one triangle)."""
    ok, out = _boundary_recipes(level, np.array([f], np.int64), sharp_edge)
    return (out[0, 0], out[0, 1], out[0, 2]) if ok[0] else None


def _boundary_recipes(level, faces, sharp_edge):
    """Per triangle of ``faces`` with corners on a boundary or an infinitely sharp crease:
    whether its 12 box-spline points can be made, and ``(a, b, r)`` for each (m,3,12).

    A *regular crease vertex* has 3 faces on the triangle's side, between its two sharp
    edges (a boundary vertex of 4 edges, or an interior one of 6 whose sharp edges are
    opposite), and no other sharp edge. The lattice points beyond the crease are replaced by
    the *phantom* points that mirror the triangle's side across a sharp edge (a, b):
    ``a + b - r``, r the lattice point across (a, b) from it, so that the box spline's
    smooth rules reproduce the crease rules there (edge: (3/8)(a + b) + (1/8)(r + a + b - r)
    = (a + b) / 2; vertex: the ring's two phantoms add up to what the rule 3/4, 1/8, 1/8
    needs), and the side's surface is that box spline (checked against the exact evaluator
    in the tests). Point k is ``a`` (b = r = -1) or the phantom ``a + b - r``; a triangle
    where some point cannot be so made is not regular (it is isolated further)."""
    faces = np.asarray(faces, dtype=np.int64)
    out = np.full((len(faces), 3, len(BOX_POINTS)), -1, dtype=np.int64)
    ok = np.zeros(len(faces), dtype=np.bool_)
    _recipes(level.face_offsets, level.face_verts, level.vert_face_offsets, level.vert_faces,
             level.vert_edge_offsets, level.vert_edges, level.edge_verts,
             np.ascontiguousarray(sharp_edge, dtype=np.bool_), faces, _LATTICE, out, ok)
    return ok, out


# lattice constants of _recipes: corners, directions, each corner's leading direction, the
# box points; coordinates reach -3 .. 4 (a phantom's r), offset by _AT_OFF in its table
_LATTICE = (TRI_CORNER.astype(np.int64), LATTICE_DIRS.astype(np.int64),
            TRI_LEAD.astype(np.int64), BOX_POINTS.astype(np.int64))
_AT_OFF = 4


@nb.njit(cache=True)
def _recipes(fo, fv, vfo, vf, veo, ve, ev, sharp, faces, lattice, out, ok):
    """:func:`_boundary_recipes`: per face, the lattice point -> vertex table ``at`` of its
    corners' rings (the whole ring of a smooth valence-6 corner, the triangle's side of a
    regular crease vertex), then each box point from it or as a phantom."""
    corner, dirs, lead_dir, box = lattice
    at = np.empty((2 * _AT_OFF + 2, 2 * _AT_OFF + 2), np.int64)
    fan = np.empty(6, np.int64)
    for m in range(len(faces)):
        f = faces[m]
        at[:] = -1
        good = True
        for k in range(3):
            c = fv[fo[f] + k]
            r0, n = veo[c], veo[c + 1] - veo[c]
            slot = 0
            while vf[vfo[c] + slot] != f:
                slot += 1
            n_cut = 0
            cut0 = cut1 = -1
            for t in range(n):
                if sharp[ve[r0 + t]]:
                    n_cut += 1
                    if cut0 < 0:
                        cut0 = t
                    else:
                        cut1 = t
            if n_cut == 0 and n == 6:  # a smooth regular corner: the whole ring
                n_fan = 6
                for t in range(6):
                    fan[t] = ve[r0 + (slot + t) % n]
                lead = 0
            elif n_cut == 2 and ((n == 4 and cut0 == 0 and cut1 == 3)
                                 or (n == 6 and cut1 - cut0 == 3)):
                # the triangle's side: edges from the sharp one before the face to the next
                s0 = cut0 if cut0 <= slot < cut1 else cut1
                n_fan = 4
                for t in range(4):
                    fan[t] = ve[r0 + (s0 + t) % n]
                lead = (slot - s0) % n
            else:
                good = False
                break
            at[corner[k, 0] + _AT_OFF, corner[k, 1] + _AT_OFF] = c
            for t in range(6):
                mm = lead + t if lead + t < n_fan else lead + t - 6
                if n_fan == 4 and not 0 <= mm < 4:
                    continue  # beyond the crease
                e = fan[mm % 6]
                far = ev[e, 1] if ev[e, 0] == c else ev[e, 0]
                d = (lead_dir[k] + t) % 6
                qi = corner[k, 0] + dirs[d, 0] + _AT_OFF
                qj = corner[k, 1] + dirs[d, 1] + _AT_OFF
                if at[qi, qj] < 0:
                    at[qi, qj] = far
                elif at[qi, qj] != far:
                    good = False  # the ring does not lie on one lattice (not regular)
                    break
            if not good:
                break
        if not good:
            continue
        for i in range(len(box)):
            qi, qj = box[i, 0] + _AT_OFF, box[i, 1] + _AT_OFF
            if at[qi, qj] >= 0:
                out[m, 0, i] = at[qi, qj]
                continue
            found = False
            for d in range(6):
                d1 = (d + 1) % 6
                a = at[qi + dirs[d, 0], qj + dirs[d, 1]]
                b = at[qi + dirs[d1, 0], qj + dirs[d1, 1]]
                r = at[qi + dirs[d, 0] + dirs[d1, 0], qj + dirs[d, 1] + dirs[d1, 1]]
                if a >= 0 and b >= 0 and r >= 0 and _edge_is(veo, ve, ev, a, b, sharp):
                    out[m, 0, i], out[m, 1, i], out[m, 2, i] = a, b, r
                    found = True
                    break
            if not found:
                good = False
                break
        ok[m] = good


@leaf_njit
def _edge_is(veo, ve, ev, a, b, flag):
    """``flag`` of the edge joining vertices a and b (False if there is none)."""
    for k in range(veo[a], veo[a + 1]):
        e = ve[k]
        if ev[e, 0] == b or ev[e, 1] == b:
            return flag[e]
    return False


def _ring_slots():
    """(3, 7) position in ``BOX_POINTS`` of corner k's t-th edge end (t < 6; the evaluator's
    layout, ``_grid12`` of :mod:`subtrace.patches.evaluate`) and of corner k itself (t = 6)."""
    where = {tuple(q): i for i, q in enumerate(BOX_POINTS.tolist())}
    out = np.empty((3, 7), dtype=np.int64)
    for k in range(3):
        for t in range(6):
            q = TRI_CORNER[k] + LATTICE_DIRS[(TRI_LEAD[k] + t) % 6]
            out[k, t] = where[tuple(q.tolist())]
        out[k, 6] = where[tuple(TRI_CORNER[k].tolist())]
    return out


_RING_SLOT = _ring_slots()


@nb.njit(cache=True)
def _box_points(fo, fv, vfo, vf, veo, ve, ev, faces, slot_of, out):
    """The 12 box-spline point ids of each regular triangle of ``faces`` into ``out``: each
    corner's six edge ends, counter-clockwise from the face's own leading edge."""
    for m in range(len(faces)):
        f = faces[m]
        for k in range(3):
            c = fv[fo[f] + k]
            slot = 0
            for a in range(vfo[c], vfo[c + 1]):
                if vf[a] == f:
                    slot = a - vfo[c]
            out[m, slot_of[k, 6]] = c
            for t in range(6):
                e = ve[veo[c] + (slot + t) % 6]
                out[m, slot_of[k, t]] = ev[e, 1] if ev[e, 0] == c else ev[e, 0]


def isolate_loop(obj, faces, allowed, max_level):
    """Items of the irregular Loop patches ``faces`` of ``obj``'s patch level (the cage):
    ``(root (n,), uv0 (n,2), scale (n,), nets (n,15,3), exact (n,) bool)``, ``root``
    indexing ``faces``, ``uv0``/``scale`` in the patch's parameters (module doc). Cells are
    left at ``max_level`` whatever their size (a measured stop, never reached in practice)."""
    options = obj.cage.options
    out = [[], [], [], [], []]
    cur, pts = obj.level, obj.points
    root = np.arange(len(faces))
    start = np.asarray(faces, dtype=np.int64)
    org = np.zeros((len(faces), 2))
    scale = np.ones(len(faces))
    level = 0
    while len(root):
        lo, hi, _, _ = one_ring_shells(cur, start, pts)
        small = (np.linalg.norm(hi - lo, axis=1) <= allowed) | (level >= max_level)
        if small.any():
            # cells: the flat triangles of their corners' exact limit points
            fo = cur.face_offsets
            corners = cur.face_verts[fo[start[small]][:, None] + np.arange(3)]
            P = limit_points(cur, pts, options, which=corners.ravel())[0].reshape(-1, 3, 3)
            _append(out, root[small], org[small], scale[small],
                    np.matmul(FLAT_TO_TRI, P), False)
        keep = ~small
        if not keep.any():
            break
        root, org, scale = root[keep], org[keep], scale[keep]
        cur, pts, kids, _ = refine_children(cur, pts, start[keep], options)
        # children c = 0..3 of each frontier face (Loop's order), in the patch's parameters
        root = np.repeat(root, 4)
        org = (org[:, None, :] + scale[:, None, None] * CHILD_ORIGIN[None]).reshape(-1, 2)
        scale = (scale[:, None] * CHILD_SCALE[None]).ravel()
        reg = loop_regular(cur, options, kids)
        if reg.any():
            _append(out, root[reg], org[reg], scale[reg], box_nets(cur, pts, kids[reg]), True)
        root, org, scale, start = root[~reg], org[~reg], scale[~reg], kids[~reg]
        level += 1
    if not out[0]:
        return (np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros(0), np.zeros((0, N_TRI, 3)),
                np.zeros(0, bool))
    return tuple(np.concatenate(a) for a in out)


def _append(out, root, org, scale, nets, exact):
    for lst, a in zip(out, (root, org, scale, nets, np.full(len(root), exact))):
        lst.append(a)
