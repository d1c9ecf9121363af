"""The trim test: is a point of a surface's parameter plane inside its trim loops?

The answer is the parity of the crossings of the loops with the ray from the point towards
+u (horizontal in the (u, v) plane). The loops are cut into monotone curve units
(:func:`subtrace.nurbs.trim.monotone_units`); a unit with end points p0, p1 counts when

* ``min(p0.v, p1.v) <= v < max(p0.v, p1.v)`` (half-open: at a loop vertex the ray passes
  through, exactly one of the two units counts; at a vertex where the loop turns back, both
  or neither; horizontal units never count), and
* its crossing with the line lies right of the point: by its box alone when the box is
  wholly right (``min u > u_p``: counts) or wholly left (``max u <= u_p``: does not);
  only a unit whose box straddles the point is intersected exactly, by bisection on the
  monotone unit (:func:`crosses`): each halving keeps the crossing's parameter interval,
  whose u-range (the unit is monotone in u) soon lies on one side of the point.

A kd-tree over the units (:func:`build_tree`) makes this fast, after the patent of
docs/seeds.md section 4: nodes split the longer side of their units' box at its middle, and
units straddling the plane are cut there (so each unit lies in exactly one leaf and no
crossing is counted twice); empty space wider than TRIM_EMPTY_FRACTION of a node is cut off
first as an empty leaf, whose inside / outside answer is computed once at build time (its
interior meets no curve, so one answer holds for all of it). A query descends to its leaf
(an empty leaf answers at once), else walks the ray through the tree, visiting only nodes
whose units' box the ray meets with the same half-open rule, and tests their units as above.
:func:`classify_naive` applies the same unit test to every unit (the benchmark's baseline).

Flat layout (:class:`TrimTree`), every array C-contiguous:
  node_box (k, 4) f8 (u_min, v_min, u_max, v_max) of the node's units (empty: +inf, -inf);
  node_axis (k,) i4: 0 (u) / 1 (v) for an inner node, -1 for a leaf; node_split (k,) f8;
  node_child (k,) i4: inner: left child (right = left + 1); leaf: its first unit;
  node_count (k,) i4: a leaf's units (0: empty leaf); node_inside (k,) bool: an empty leaf's
  answer. Units (n,...) as :class:`subtrace.nurbs.trim.Units`, in leaf order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from subtrace.config import (
    TRIM_BISECT_STEPS,
    TRIM_EMPTY_FRACTION,
    TRIM_LEAF_UNITS,
    TRIM_MAX_DEPTH,
    TRIM_MIN_AREA,
    TRIM_MIN_SIDE,
    TRIM_STACK_SIZE,
)
from subtrace.nurbs.bezier import curve_point
from subtrace.nurbs.knots import split_bezier
from subtrace.nurbs.trim import Units, pack_units, project
from subtrace.runtime.jit import inline_njit, leaf_njit, nb


@dataclass(frozen=True, eq=False)
class TrimTree:
    """A built trim kd-tree (see the module comment for the layout)."""

    node_box: np.ndarray
    node_axis: np.ndarray
    node_split: np.ndarray
    node_child: np.ndarray
    node_count: np.ndarray
    node_inside: np.ndarray
    units: Units

    def classify(self, points) -> np.ndarray:
        """(n,) bool: each point (n, 2) of the parameter plane is inside the loops."""
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
        out = np.empty(len(points), dtype=np.bool_)
        u = self.units
        roots = np.zeros(len(points), dtype=np.int64)
        classify_kernel(self.node_box, self.node_axis, self.node_split, self.node_child,
                        self.node_count, self.node_inside, u.ctrl, u.degree, u.p0, u.p1,
                        roots, points, out)
        return out

    @property
    def depth(self) -> int:
        """Nodes on the longest root-to-leaf path."""
        depth = np.zeros(len(self.node_axis), dtype=np.int64)
        for k in range(len(self.node_axis)):
            if self.node_axis[k] >= 0:
                depth[self.node_child[k]: self.node_child[k] + 2] = depth[k] + 1
        return int(depth.max()) + 1


# ------------------------------------------------------------------------------------------
# the unit test and the queries (kernels)
# ------------------------------------------------------------------------------------------

@inline_njit
def crosses(ctrl, degree, p0, p1, px, py):
    """True when the monotone unit (ctrl (D+1, 3), its degree, end points p0 / p1 (2,))
    crosses the ray from (px, py) towards +u (the half-open rule of the module comment)."""
    if p0[1] <= p1[1]:
        y_lo, y_hi, t_lo, t_hi = p0[1], p1[1], 0.0, 1.0
        x_lo, x_hi = p0[0], p1[0]
    else:
        y_lo, y_hi, t_lo, t_hi = p1[1], p0[1], 1.0, 0.0
        x_lo, x_hi = p1[0], p0[0]
    if not (y_lo <= py < y_hi):
        return False
    # bisection on the parameter: the crossing stays between t_lo (v <= py) and t_hi
    for _ in range(TRIM_BISECT_STEPS):
        if min(x_lo, x_hi) > px:
            return True
        if max(x_lo, x_hi) <= px:
            return False
        t = 0.5 * (t_lo + t_hi)
        x, y = curve_point(ctrl, degree, t)
        if y <= py:
            t_lo, x_lo = t, x
        else:
            t_hi, x_hi = t, x
    return 0.5 * (x_lo + x_hi) > px


@leaf_njit
def _ray_parity(node_box, node_axis, node_child, node_count, ctrl, degree, p0, p1, root, px,
                py, stack):
    """Parity of the units of the tree at ``root`` crossing the ray from (px, py) towards
    +u; stack: int64 scratch of TRIM_STACK_SIZE."""
    inside = False
    stack[0] = root
    top = 1
    while top > 0:
        top -= 1
        k = stack[top]
        # the ray meets the node's units' box (half-open in v, as the unit test)
        if not (node_box[k, 1] <= py < node_box[k, 3] and node_box[k, 2] > px):
            continue
        if node_axis[k] < 0:
            first = node_child[k]
            for i in range(first, first + node_count[k]):
                if crosses(ctrl[i], degree[i], p0[i], p1[i], px, py):
                    inside = not inside
        else:
            stack[top] = node_child[k]
            stack[top + 1] = node_child[k] + 1
            top += 2
    return inside


@leaf_njit
def trim_inside(node_box, node_axis, node_split, node_child, node_count, node_inside, ctrl,
                degree, p0, p1, root, px, py, stack):
    """True when (px, py) is inside the loops of the tree at node ``root`` (the per-point
    test a trace kernel calls; arrays as :class:`TrimTree` lays them out, node and unit
    indices absolute so several trees can share them); stack: TRIM_STACK_SIZE int64."""
    # outside the units' box (half-open in v, as the unit test): no loop around the point
    if not (node_box[root, 0] <= px <= node_box[root, 2]
            and node_box[root, 1] <= py < node_box[root, 3]):
        return False
    # descend to the leaf holding the point: an empty leaf knows its answer
    k = root
    while node_axis[k] >= 0:
        coordinate = px if node_axis[k] == 0 else py
        k = node_child[k] + (0 if coordinate < node_split[k] else 1)
    if node_count[k] == 0:
        return node_inside[k]
    return _ray_parity(node_box, node_axis, node_child, node_count, ctrl, degree, p0, p1,
                       root, px, py, stack)


@nb.njit(cache=True)
def classify_kernel(node_box, node_axis, node_split, node_child, node_count, node_inside,
                    ctrl, degree, p0, p1, roots, points, out):
    """out[q] = :func:`trim_inside` of points[q] in the tree at roots[q]."""
    stack = np.empty(TRIM_STACK_SIZE, dtype=np.int64)
    for q in range(len(points)):
        out[q] = trim_inside(node_box, node_axis, node_split, node_child, node_count,
                             node_inside, ctrl, degree, p0, p1, roots[q], points[q, 0],
                             points[q, 1], stack)


@nb.njit(cache=True)
def _classify_all(ctrl, degree, p0, p1, points, out):
    for q in range(len(points)):
        px, py = points[q, 0], points[q, 1]
        inside = False
        for i in range(len(degree)):
            if crosses(ctrl[i], degree[i], p0[i], p1[i], px, py):
                inside = not inside
        out[q] = inside


def classify_naive(units: Units, points) -> np.ndarray:
    """(n,) bool by the unit test over every unit (no tree): the baseline of the kd-tree."""
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
    out = np.empty(len(points), dtype=np.bool_)
    _classify_all(units.ctrl, units.degree, units.p0, units.p1, points, out)
    return out


@leaf_njit
def _coordinate_param(ctrl, degree, axis, value, t0, t1):
    """The parameter in (t0, t1) where the unit's coordinate ``axis`` equals ``value``
    (monotone unit: bisection to the last bit)."""
    a, b = t0, t1
    xa = curve_point(ctrl, degree, a)[axis]
    rising = curve_point(ctrl, degree, b)[axis] >= xa
    for _ in range(TRIM_BISECT_STEPS):
        m = 0.5 * (a + b)
        if m == a or m == b:
            break
        c = curve_point(ctrl, degree, m)[axis]
        if (c <= value) == rising:
            a = m
        else:
            b = m
    return 0.5 * (a + b)


@nb.njit(cache=True)
def coordinate_param(ctrl, degree, axis, value):
    """Parameter in (0, 1) where the monotone unit's coordinate ``axis`` equals ``value``."""
    return _coordinate_param(ctrl, degree, axis, value, 0.0, 1.0)


# ------------------------------------------------------------------------------------------
# building
# ------------------------------------------------------------------------------------------

class _Builder:
    """Top-down build into growing lists; units are (ctrl (d+1,3), p0 (2,), p1 (2,), loop)."""

    def __init__(self, min_area=0.0, min_side=0.0):
        self.box, self.axis, self.split, self.child, self.count = [], [], [], [], []
        self.leaf_units: list = []  # (node, units) of full leaves, in node order
        self.min_area = min_area  # absolute leaf stops (the patent's; 0: off)
        self.min_side = min_side

    def node(self) -> int:
        self.box.append((np.inf, np.inf, -np.inf, -np.inf))
        self.axis.append(-1)
        self.split.append(0.0)
        self.child.append(0)
        self.count.append(0)
        return len(self.axis) - 1

    def build(self, units, cell):
        work = [(self.node(), units, cell, 1)]
        while work:
            k, units, cell, depth = work.pop()
            if not units:
                continue  # an empty leaf
            ends = np.array([np.concatenate((u[1], u[2])) for u in units])
            lo = np.minimum(ends[:, :2], ends[:, 2:]).min(axis=0)
            hi = np.maximum(ends[:, :2], ends[:, 2:]).max(axis=0)
            self.box[k] = (lo[0], lo[1], hi[0], hi[1])
            cut = self._empty_cut(cell, lo, hi) if depth < TRIM_MAX_DEPTH else None
            small = ((hi[0] - lo[0]) * (hi[1] - lo[1]) < self.min_area
                     or max(hi - lo) < self.min_side)
            if cut is None and (len(units) <= TRIM_LEAF_UNITS or depth >= TRIM_MAX_DEPTH
                                or small):
                self.leaf_units.append((k, units))
                continue
            if cut is not None:
                axis, value, empty_left = cut
                left, right = ([], units) if empty_left else (units, [])
            else:
                axis = int(np.argmax(hi - lo))
                value = 0.5 * (lo[axis] + hi[axis])
                if not lo[axis] < value < hi[axis]:  # a box too small to halve
                    self.leaf_units.append((k, units))
                    continue
                left, right = _partition(units, axis, value)
            first = self.node()
            self.node()
            self.axis[k], self.split[k], self.child[k] = axis, value, first
            cell_l, cell_r = list(cell), list(cell)
            cell_l[2 + axis] = value
            cell_r[axis] = value
            work.append((first, left, tuple(cell_l), depth + 1))
            work.append((first + 1, right, tuple(cell_r), depth + 1))

    @staticmethod
    def _empty_cut(cell, lo, hi):
        """(axis, value, empty_left) cutting off the widest empty margin of the cell, when it
        exceeds TRIM_EMPTY_FRACTION of the cell's side; None otherwise."""
        best = None
        for axis in (0, 1):
            side = cell[2 + axis] - cell[axis]
            if side <= 0:
                continue
            for margin, value, empty_left in ((lo[axis] - cell[axis], lo[axis], True),
                                              (cell[2 + axis] - hi[axis], hi[axis], False)):
                if margin > TRIM_EMPTY_FRACTION * side and (best is None or margin / side
                                                            > best[0]):
                    best = (margin / side, axis, float(value), empty_left)
        return None if best is None else best[1:]


def _partition(units, axis, value):
    """Units left / right of the plane coordinate[axis] = value; a unit crossing it is cut
    there (its two parts share the cut point bit for bit)."""
    left, right = [], []
    for unit in units:
        ctrl, p0, p1, loop = unit
        a, b = p0[axis], p1[axis]
        if max(a, b) <= value:
            left.append(unit)
        elif min(a, b) >= value:
            right.append(unit)
        else:
            t = coordinate_param(ctrl, len(ctrl) - 1, axis, value)
            first, second = split_bezier(ctrl, t)
            cut = project(first[-1])
            cut[axis] = value  # on the plane exactly: each part stays in its cell
            (left if a < value else right).append((first, p0, cut, loop))
            (right if a < value else left).append((second, cut, p1, loop))
    return left, right


def build_tree(units: Units, min_area: float = TRIM_MIN_AREA,
               min_side: float = TRIM_MIN_SIDE) -> TrimTree:
    """The trim kd-tree over ``units`` (see the module comment). min_area / min_side: a
    node whose units' box has less area than this fraction of the whole box's, or a longer
    side below this fraction of its diagonal, is a leaf (the patent's stops; 0: off)."""
    items = [(units.ctrl[i, : units.degree[i] + 1].copy(), units.p0[i].copy(),
              units.p1[i].copy(), int(units.loop[i])) for i in range(len(units))]
    lo = np.minimum(units.p0, units.p1).min(axis=0) if items else np.zeros(2)
    hi = np.maximum(units.p0, units.p1).max(axis=0) if items else np.zeros(2)
    size = hi - lo
    builder = _Builder(min_area * size[0] * size[1], min_side * float(np.hypot(*size)))
    if items:
        builder.build(items, (lo[0], lo[1], hi[0], hi[1]))
    else:
        builder.node()
    ctrls, p0s, p1s, loops = [], [], [], []
    for k, leaf in builder.leaf_units:
        builder.child[k] = len(ctrls)
        builder.count[k] = len(leaf)
        for ctrl, p0, p1, loop in leaf:
            ctrls.append(ctrl)
            p0s.append(p0)
            p1s.append(p1)
            loops.append(loop)
    tree_units = pack_units(ctrls, p0s, p1s, loops)
    if not ctrls:
        tree_units = Units(np.zeros((0, 1, 3)), np.zeros(0, np.int32), np.zeros((0, 2)),
                           np.zeros((0, 2)), np.zeros(0, np.int32))
    node_box = np.array(builder.box, dtype=np.float64).reshape(-1, 4)
    node_axis = np.array(builder.axis, dtype=np.int32)
    node_split = np.array(builder.split, dtype=np.float64)
    node_child = np.array(builder.child, dtype=np.int32)
    node_count = np.array(builder.count, dtype=np.int32)
    node_inside = np.zeros(len(node_axis), dtype=np.bool_)
    _classify_empty_leaves(node_box, node_axis, node_split, node_child, node_count,
                           node_inside, tree_units)
    return TrimTree(node_box, node_axis, node_split, node_child, node_count, node_inside,
                    tree_units)


def _classify_empty_leaves(node_box, node_axis, node_split, node_child, node_count,
                           node_inside, units):
    """node_inside of every empty leaf: the answer at its cell's centre, by the ray."""
    cells = np.zeros((len(node_axis), 4))
    cells[0] = node_box[0]
    empty = []
    for k in range(len(node_axis)):
        if node_axis[k] >= 0:
            a, s, c = node_axis[k], node_split[k], node_child[k]
            cells[c] = cells[k]
            cells[c + 1] = cells[k]
            cells[c, 2 + a] = s
            cells[c + 1, a] = s
        elif node_count[k] == 0 and node_box[k, 0] > node_box[k, 2] and k > 0:
            empty.append(k)
    if not empty:
        return
    centres = 0.5 * (cells[empty, :2] + cells[empty, 2:])
    answer = np.empty(len(empty), dtype=np.bool_)
    stack = np.empty(TRIM_STACK_SIZE, dtype=np.int64)
    _ray_parities(node_box, node_axis, node_child, node_count, units.ctrl, units.degree,
                  units.p0, units.p1, centres, stack, answer)
    node_inside[empty] = answer


@nb.njit(cache=True)
def _ray_parities(node_box, node_axis, node_child, node_count, ctrl, degree, p0, p1, points,
                  stack, out):
    for q in range(len(points)):
        out[q] = _ray_parity(node_box, node_axis, node_child, node_count, ctrl, degree, p0,
                             p1, 0, points[q, 0], points[q, 1], stack)
