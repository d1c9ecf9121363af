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
  :mod:`subtrace.patches.evaluate`), or a regular boundary: its limit surface is then the
  quartic box spline of the 12 points around it, which is one quartic polynomial, converted
  to its 15-point triangular Bezier net (:mod:`subtrace.patches.boxspline`).
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
from subtrace.patches.basis import CHILD_ORIGIN, CHILD_SCALE, FLAT_TO_TRI, N_TRI
from subtrace.patches.boxspline import box_nets, loop_regular
from subtrace.patches.grids import refine_children
from subtrace.patches.isolate import build_isolated
from subtrace.patches.shells import one_ring_shells
from subtrace.patches.table import build_patch_table
from subtrace.subdiv.limit import limit_points

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
