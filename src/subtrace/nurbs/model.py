"""The flat tables of a file's trimmed NURBS surfaces, as a trace kernel takes them.

:func:`build_model` converts every surface to rational Bezier patches
(:func:`subtrace.nurbs.surface.bezier_patches`) and every surface's trim loops to one trim
kd-tree (:func:`subtrace.nurbs.trimtree.build_tree`), then concatenates them (layout in
:class:`NurbsModel` and the package comment of :mod:`subtrace.nurbs`).

The rectangle of a surface is never a loop of its tree: an outer loop that runs along the
rectangle's sides only (CAD exporters write one for untrimmed faces) is dropped, and a
surface with holes but no other outer loop gets a tree of its holes whose answer is
inverted (``surface_trim_invert``): inside a hole means cut away. So points on the
rectangle's sides, where patches of a closed surface meet, are always kept (a point on a
loop could go either way under the parity rule). A surface without loops has no tree
(``surface_trim`` -1: all of its rectangle is kept).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from subtrace.config import TRIM_CLOSURE_TOL
from subtrace.errors import ObjError
from subtrace.io.obj import read_obj
from subtrace.nurbs.freeform import freeform_of
from subtrace.nurbs.surface import bezier_patches
from subtrace.nurbs.trim import Units, monotone_units, project
from subtrace.nurbs.trimtree import TrimTree, build_tree, classify_kernel


@dataclass(frozen=True, eq=False)
class NurbsModel:
    """Rational Bezier patches and trim trees of a set of surfaces (m patches, S surfaces,
    k tree nodes, n curve units; every array C-contiguous)."""

    nets: np.ndarray  # (m, Du+1, Dv+1, 4) f8 homogeneous; entries past a patch's degree 0
    patch_degree: np.ndarray  # (m, 2) i4 (du, dv)
    patch_rect: np.ndarray  # (m, 4) f8 (u0, u1, v0, v1) in its surface's parameters
    patch_surface: np.ndarray  # (m,) i4
    surface_domain: np.ndarray  # (S, 4) f8 (u0, u1, v0, v1): the surf's parameter range
    surface_material: np.ndarray  # (S,) i4, -1: none
    surface_trim: np.ndarray  # (S,) i4 root node of the surface's trim tree, -1: untrimmed
    surface_trim_invert: np.ndarray  # (S,) bool: kept where the tree says outside (holes only)
    surface_loops: np.ndarray  # (S, 2) i4 outer loops, holes (as in the file)
    trim: TrimTree  # all surfaces' trees in one: node and unit indices absolute

    @property
    def n_patches(self) -> int:
        return len(self.patch_surface)

    @property
    def n_units(self) -> int:
        return len(self.trim.units)

    def inside(self, surface_ids, uv) -> np.ndarray:
        """(n,) bool: parameter points uv (n, 2) of surfaces ``surface_ids`` (n,) are kept by
        their trim loops (points of untrimmed surfaces always are)."""
        surface_ids = np.asarray(surface_ids, dtype=np.int64)
        uv = np.ascontiguousarray(uv, dtype=np.float64).reshape(-1, 2)
        roots = self.surface_trim[surface_ids].astype(np.int64)
        out = np.ones(len(uv), dtype=np.bool_)
        trimmed = np.nonzero(roots >= 0)[0]
        if len(trimmed):
            t = self.trim
            answer = np.empty(len(trimmed), dtype=np.bool_)
            classify_kernel(t.node_box, t.node_axis, t.node_split, t.node_child, t.node_count,
                            t.node_inside, t.units.ctrl, t.units.degree, t.units.p0,
                            t.units.p1, roots[trimmed], np.ascontiguousarray(uv[trimmed]),
                            answer)
            out[trimmed] = answer ^ self.surface_trim_invert[surface_ids[trimmed]]
        return out


def load_model(path) -> NurbsModel:
    """The :class:`NurbsModel` of the free-form surfaces of the OBJ file ``path`` (ObjError
    when it has none)."""
    data = read_obj(path)
    freeform = freeform_of(data)
    if freeform is None or not freeform.surfaces:
        raise ObjError(data.path, None, "no free-form surfaces (surf ... end) in the file")
    return build_model(freeform.surfaces)


def on_rectangle(loop, domain) -> bool:
    """The loop runs along the sides of the rectangle (u0, u1, v0, v1) only: every segment's
    control points lie on one side (to TRIM_CLOSURE_TOL of the rectangle's larger side)."""
    u0, u1, v0, v1 = domain
    tol = TRIM_CLOSURE_TOL * max(u1 - u0, v1 - v0)
    for seg in loop.segments:
        p = project(seg)
        if not any(np.all(np.abs(p[:, axis] - side) <= tol)
                   for axis, side in ((0, u0), (0, u1), (1, v0), (1, v1))):
            return False
    return True


def surface_units(surface):
    """(units, invert) of a surface's trim test (see the module comment): the monotone
    units of its loops, and whether the answer is inverted; (None, False) without loops."""
    holes = [loop for loop in surface.loops if loop.hole]
    outer = [loop for loop in surface.loops
             if not loop.hole and not on_rectangle(loop, surface.domain)]
    if not outer and not holes:
        return None, False
    return monotone_units(outer + holes), not outer


def build_model(surfaces) -> NurbsModel:
    """Patches and trim trees of ``surfaces`` (NurbsSurface sequence) in flat tables."""
    nets, degrees, rects, owner, trees, roots, invert = [], [], [], [], [], [], []
    nodes = 0
    for s, surface in enumerate(surfaces):
        n, r = bezier_patches(surface)
        nets.append(n)
        degrees.append(np.tile(np.array(surface.degree, dtype=np.int32), (len(n), 1)))
        rects.append(r)
        owner.append(np.full(len(n), s, dtype=np.int32))
        units, flip = surface_units(surface)
        invert.append(flip)
        if units is None:
            roots.append(-1)
            continue
        tree = build_tree(units)
        trees.append(tree)
        roots.append(nodes)
        nodes += len(tree.node_axis)
    du = max((d[0, 0] for d in degrees if len(d)), default=1)
    dv = max((d[0, 1] for d in degrees if len(d)), default=1)
    table = np.zeros((sum(len(n) for n in nets), du + 1, dv + 1, 4))
    start = 0
    for n in nets:
        table[start : start + len(n), : n.shape[1], : n.shape[2]] = n
        start += len(n)

    def cat(parts, shape, dtype):
        return (np.ascontiguousarray(np.concatenate(parts), dtype=dtype) if parts
                else np.zeros(shape, dtype=dtype))

    return NurbsModel(
        nets=table,
        patch_degree=cat(degrees, (0, 2), np.int32),
        patch_rect=cat(rects, (0, 4), np.float64),
        patch_surface=cat(owner, (0,), np.int32),
        surface_domain=np.array([s.domain for s in surfaces], dtype=np.float64).reshape(-1, 4),
        surface_material=np.array([s.material for s in surfaces], dtype=np.int32),
        surface_trim=np.array(roots, dtype=np.int32),
        surface_trim_invert=np.array(invert, dtype=np.bool_),
        surface_loops=np.array([(sum(not lp.hole for lp in s.loops),
                                 sum(lp.hole for lp in s.loops)) for s in surfaces],
                               dtype=np.int32).reshape(-1, 2),
        trim=merge_trees(trees),
    )


def merge_trees(trees) -> TrimTree:
    """One :class:`TrimTree` holding ``trees`` one after another (node and unit indices
    shifted; tree k's root is the sum of the earlier trees' node counts)."""
    if not trees:
        empty_units = Units(np.zeros((0, 2, 3)), np.zeros(0, np.int32), np.zeros((0, 2)),
                            np.zeros((0, 2)), np.zeros(0, np.int32))
        return TrimTree(np.zeros((0, 4)), np.zeros(0, np.int32), np.zeros(0),
                        np.zeros(0, np.int32), np.zeros(0, np.int32), np.zeros(0, np.bool_),
                        empty_units)
    width = max(t.units.ctrl.shape[1] for t in trees)
    child, ctrl = [], []
    node_base = unit_base = 0
    for t in trees:
        inner = t.node_axis >= 0
        child.append(np.where(inner, t.node_child + node_base, t.node_child + unit_base))
        c = np.zeros((len(t.units), width, 3))
        c[:, : t.units.ctrl.shape[1]] = t.units.ctrl
        ctrl.append(c)
        node_base += len(t.node_axis)
        unit_base += len(t.units)
    units = Units(np.concatenate(ctrl), np.concatenate([t.units.degree for t in trees]),
                  np.concatenate([t.units.p0 for t in trees]),
                  np.concatenate([t.units.p1 for t in trees]),
                  np.concatenate([t.units.loop for t in trees]))
    return TrimTree(np.concatenate([t.node_box for t in trees]),
                    np.concatenate([t.node_axis for t in trees]),
                    np.concatenate([t.node_split for t in trees]),
                    np.concatenate(child).astype(np.int32),
                    np.concatenate([t.node_count for t in trees]),
                    np.concatenate([t.node_inside for t in trees]), units)
