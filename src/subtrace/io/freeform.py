"""OBJ free-form geometry: the statements of trimmed (rational) B-spline and Bezier surfaces.

Owns the text of ``vp``, ``cstype``, ``deg``, ``curv2``, ``surf``, their bodies (``parm``,
``trim``, ``hole``, ``scrv``, ``sp``, ``end``) and ``con``, as the Wavefront OBJ
specification (version 3.0, "Free-form curve/surface attributes" and after) defines them;
:class:`subtrace.io.obj.ObjReader` hands these statements over one by one
(:meth:`FreeFormReader.statement`) and asks for the result once the file is read
(:meth:`FreeFormReader.finish`). The geometry itself (knot checks, Bezier extraction, trim
loops) is :mod:`subtrace.nurbs`; every problem it finds is raised here as an ObjError naming
the statement's line.

What is read: ``cstype [rat] bezier|bspline`` (other types are an error naming the type),
``deg du [dv]``, ``surf s0 s1 t0 t1 v/vt/vn ...`` (control points u fastest; a rational
surface takes the weights of ``v x y z w``, 1 where a v line has no w) with ``parm u`` /
``parm v`` (B-spline knots, or the segment joins of a Bezier surface), ``curv2 vp ...``
(trimming curves over ``vp u v [w]`` points) with ``parm u``, ``trim`` / ``hole`` loops of
``u0 u1 curv2`` triples, and ``end``. ``scrv``, ``sp``, ``con``, ``bmat``, ``step`` and 3-D
``curv`` elements (with their bodies) are read and ignored with one warning per keyword.
Free-form attributes with no element after them (a stray ``cstype``) are ignored likewise.
Indices follow the polygon rules: 1-based, negative counts back from the statements read so
far, positive may name a later statement.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from subtrace.errors import NurbsError
from subtrace.nurbs.knots import (
    bezier_knots,
    check_bezier_params,
    check_degree,
    check_knots,
    check_nondecreasing,
)
from subtrace.nurbs.surface import NurbsSurface, make_surface
from subtrace.nurbs.trim import TrimCurve, make_curve, make_loop

# statements this module reads (the OBJ reader sends them here)
STATEMENTS = frozenset(
    "vp cstype deg bmat step curv curv2 surf parm trim hole scrv sp end con".split())
_TYPES = ("bezier", "bspline")
_OTHER_TYPES = ("bmatrix", "cardinal", "taylor")
_IGNORED = ("scrv", "sp", "con", "bmat", "step")  # read and ignored (one warning each)


@dataclass(frozen=True, eq=False)
class FreeForm:
    """The free-form content of an OBJ file.

    surfaces: validated surfaces with their oriented trim loops, in file order;
    surface_lines: the line of each ``surf``; curves: every ``curv2``, in file order;
    param_points (P, 3) float64: the ``vp`` lines (u, v, w)."""

    surfaces: tuple[NurbsSurface, ...]
    surface_lines: tuple[int, ...]
    curves: tuple[TrimCurve, ...]
    param_points: np.ndarray


@dataclass
class _Element:
    """An open ``curv2`` / ``surf`` / ``curv`` and its body, as read."""

    kind: str
    line: int
    rational: bool
    basis: str  # "bezier" | "bspline"
    degree: tuple
    refs: list  # control point indices as written (int, 1-based or negative)
    known: int  # v (surf) or vp (curv2) statements read before it
    domain: tuple = ()  # surf: (s0, s1, t0, t1)
    material: str | None = None
    parms: dict = field(default_factory=dict)  # "u" / "v" -> (line, values)
    loops: list = field(default_factory=list)  # (line, hole, [(u0, u1, index)], curv2 known)


class FreeFormReader:
    """Collects free-form statements during the OBJ pass, validates them at the end.

    fail(line, problem) raises the reader's ObjError; ignored(keyword, line) records a
    statement ignored with the reader's one warning per keyword."""

    def __init__(self, fail, ignored):
        self.fail = fail
        self.ignored = ignored
        self.vp_tokens: list[list[str]] = []
        self.vp_lines: list[int] = []
        self.cstype = None  # (rational, basis, line)
        self.deg = None  # (degrees tuple, line)
        self.attributes: dict[str, list] = {}  # keyword -> [first line, count]
        self.elements: list[_Element] = []
        self.open: _Element | None = None
        self.num_curves = 0

    @property
    def has_surfaces(self) -> bool:
        """A ``surf`` was read (closed or still open)."""
        return any(e.kind == "surf" for e in self.elements) or (
            self.open is not None and self.open.kind == "surf")

    # -- the pass ------------------------------------------------------------------------

    def statement(self, number, parts, num_points, material):
        """One statement (``parts`` split, comment removed); ``num_points``: v lines read so
        far; ``material``: the active usemtl name (None without)."""
        keyword = parts[0]
        if keyword == "vp":
            if len(parts) < 2 or len(parts) > 4:
                self.fail(number, f"vp needs 1 to 3 numbers u [v [w]], got {len(parts) - 1}")
            self.vp_tokens.append(parts[1:])
            self.vp_lines.append(number)
            self._attribute(keyword, number)
        elif keyword == "cstype":
            self._cstype(number, parts)
        elif keyword == "deg":
            self._deg(number, parts)
        elif keyword in ("surf", "curv2", "curv"):
            self._element(number, parts, num_points, material)
        elif keyword == "parm":
            self._parm(number, parts)
        elif keyword in ("trim", "hole"):
            self._loop(number, parts)
        elif keyword == "end":
            if self.open is None:
                self.fail(number, "end without a curv2 or surf to close")
            if self.open.kind != "curv":
                self.elements.append(self.open)
            self.open = None
        else:  # scrv, sp, con, bmat, step
            self.ignored(keyword, number)

    def _attribute(self, keyword, number):
        seen = self.attributes.setdefault(keyword, [number, 0])
        seen[1] += 1

    def _cstype(self, number, parts):
        words = parts[1:]
        rational = bool(words) and words[0] == "rat"
        if rational:
            words = words[1:]
        if len(words) != 1:
            self.fail(number, "cstype needs a type: cstype [rat] bezier|bspline")
        basis = words[0]
        if basis not in _TYPES:
            known = basis in _OTHER_TYPES
            self.fail(number, f"cstype '{basis}' is {'not supported' if known else 'unknown'}: "
                              "subtrace reads bezier and bspline curves and surfaces (each "
                              "optionally rat)")
        self.cstype = (rational, basis, number)
        self._attribute("cstype", number)

    def _deg(self, number, parts):
        if len(parts) not in (2, 3):
            self.fail(number, f"deg needs 1 or 2 degrees: deg du [dv], got {len(parts) - 1}")
        degrees = []
        for token in parts[1:]:
            try:
                value = int(token)
            except ValueError:
                self.fail(number, f"deg: '{token}' is not a whole number")
            try:
                check_degree(value)
            except NurbsError as err:
                self.fail(number, f"deg: {err}")
            degrees.append(value)
        self.deg = (tuple(degrees), number)
        self._attribute("deg", number)

    def _element(self, number, parts, num_points, material):
        keyword = parts[0]
        if self.open is not None and self.open.kind != "curv":
            self.fail(number, f"{keyword} inside the {self.open.kind} of line "
                              f"{self.open.line}: close that one with `end` first")
        self.open = None
        if keyword == "curv":
            self.ignored(keyword, number)
            self.open = _Element("curv", number, False, "", (), [], 0)
            return
        if self.cstype is None:
            self.fail(number, f"{keyword} before any cstype: add `cstype bspline` (or "
                              "`cstype bezier`, `cstype rat bspline`) before it")
        if self.deg is None:
            self.fail(number, f"{keyword} before any deg: add `deg du dv` (surf) or "
                              "`deg d` (curv2) before it")
        rational, basis, _ = self.cstype
        degrees, deg_line = self.deg
        if keyword == "surf":
            if len(degrees) != 2:
                self.fail(number, f"surf needs two degrees (`deg du dv`); the deg of line "
                                  f"{deg_line} gives one")
            if len(parts) < 6:
                self.fail(number, "surf needs s0 s1 t0 t1 and control points v1 v2 ...")
            domain = tuple(self._number(number, "surf", token) for token in parts[1:5])
            refs = [self._index(number, "surf", "vertex", token.split("/")[0])
                    for token in parts[5:]]
            self.open = _Element("surf", number, rational, basis, degrees, refs, num_points,
                                 domain, material)
        else:
            if len(parts) < 2:
                self.fail(number, "curv2 needs control points vp1 vp2 ...")
            refs = [self._index(number, "curv2", "parameter vertex", token)
                    for token in parts[1:]]
            self.open = _Element("curv2", number, rational, basis, degrees[:1], refs,
                                 len(self.vp_lines))
            self.num_curves += 1

    def _parm(self, number, parts):
        if self.open is None:
            self.fail(number, "parm outside a curv2 or surf: it belongs between the element "
                              "and its `end`")
        if len(parts) < 2 or parts[1] not in ("u", "v"):
            self.fail(number, "parm needs a direction u or v: parm u p1 p2 ...")
        if self.open.kind == "curv2" and parts[1] == "v":
            self.fail(number, "parm v in a curv2: a curve has only parm u")
        values = [self._number(number, "parm", token) for token in parts[2:]]
        if parts[1] in self.open.parms:
            self.fail(number, f"second parm {parts[1]} for the {self.open.kind} of line "
                              f"{self.open.line}")
        self.open.parms[parts[1]] = (number, values)

    def _loop(self, number, parts):
        keyword = parts[0]
        if self.open is None or self.open.kind != "surf":
            self.fail(number, f"{keyword} outside a surf: it belongs between a surf and its "
                              "`end`")
        triples = parts[1:]
        if not triples or len(triples) % 3:
            self.fail(number, f"{keyword} needs triples u0 u1 curv2 (start, end, curve), "
                              f"got {len(triples)} values")
        pieces = []
        for k in range(0, len(triples), 3):
            u0 = self._number(number, keyword, triples[k])
            u1 = self._number(number, keyword, triples[k + 1])
            pieces.append((u0, u1, self._index(number, keyword, "curv2", triples[k + 2])))
        self.open.loops.append((number, keyword == "hole", pieces, self.num_curves))

    def _number(self, number, keyword, token) -> float:
        try:
            value = float(token)
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            self.fail(number, f"{keyword}: '{token}' is not a finite number")
        return value

    def _index(self, number, keyword, what, token) -> int:
        try:
            index = int(token)
        except ValueError:
            self.fail(number, f"{keyword}: {what} index '{token}' is not an integer")
        if index == 0:
            self.fail(number, f"{keyword}: {what} index 0 is invalid: OBJ indices start at 1")
        return index

    # -- the end of the file -------------------------------------------------------------

    def finish(self, points, point_lines, weight_tokens, material_ids) -> FreeForm | None:
        """Validate and convert everything read; None for a file without elements.

        points (V, 3): the v coordinates, point_lines their lines; weight_tokens: v index
        (0-based) -> the w token of v lines with one; material_ids: usemtl name -> material
        index."""
        if self.open is not None and self.open.kind != "curv":
            self.fail(self.open.line, f"{self.open.kind} has no `end`")
        if not self.elements:
            for keyword, (line, count) in self.attributes.items():
                for _ in range(count):
                    self.ignored(keyword, line)
            return None
        vp = self._param_points()
        # every curv2 first (trim loops may name later ones), then the surfaces
        curves = [self._curve(e, vp) for e in self.elements if e.kind == "curv2"]
        surfaces = [e for e in self.elements if e.kind == "surf"]
        return FreeForm(
            tuple(self._surface(e, points, point_lines, weight_tokens, material_ids, curves)
                  for e in surfaces),
            tuple(e.line for e in surfaces), tuple(curves), vp)

    def _param_points(self) -> np.ndarray:
        vp = np.zeros((len(self.vp_tokens), 3))
        vp[:, 2] = 1.0
        for row, (tokens, line) in enumerate(zip(self.vp_tokens, self.vp_lines)):
            for col, token in enumerate(tokens):
                vp[row, col] = self._number(line, "vp", token)
        return vp

    def _resolve(self, element, total, what, keyword) -> np.ndarray:
        """0-based indices of an element's control points; ObjError for one out of range."""
        out = []
        for index in element.refs:
            resolved = index - 1 if index > 0 else element.known + index
            if resolved < 0 or resolved >= total:
                self.fail(element.line, f"{element.kind}: {what} index {index} out of range: "
                                        f"the file has {total} {keyword} lines")
            out.append(resolved)
        return np.array(out, dtype=np.int64)

    def _parm_values(self, element, direction):
        """(line, values) of an element's ``parm`` in one direction, checked on its own: at
        least 2 values, strictly increasing (Bezier joins) or non-decreasing (knots)."""
        if direction not in element.parms:
            self.fail(element.line, f"{element.kind} has no `parm {direction}` before its "
                                    "`end`")
        line, values = element.parms[direction]
        try:
            if element.basis == "bezier" or len(values) < 2:
                check_bezier_params(values, direction)
            check_nondecreasing(values, direction)
        except NurbsError as err:
            self.fail(line, f"{element.kind}: {err}")
        return line, values

    def _curve(self, element, vp) -> TrimCurve:
        idx = self._resolve(element, len(vp), "parameter vertex", "vp")
        line, values = self._parm_values(element, "u")
        degree = element.degree[0]
        if element.basis == "bezier":
            need = (len(values) - 1) * degree + 1
            if need != len(idx):
                self.fail(line, f"curv2: parm u has {len(values)} values ({len(values) - 1} "
                                f"segments), so a degree-{degree} Bezier curve needs {need} "
                                f"control points (segments x degree + 1); the curv2 has "
                                f"{len(idx)}")
            knots = bezier_knots(values, degree)
        else:
            knots = np.array(values, dtype=np.float64)
            try:
                check_knots(knots, degree, len(idx), "u")
            except NurbsError as err:
                self.fail(line, f"curv2: {err}")
        if element.rational:
            self._check_weights(element, vp[idx, 2], idx, self.vp_lines, "vp", "curve")
        try:
            return make_curve(degree, knots, vp[idx, :2], vp[idx, 2] if element.rational
                              else None)
        except NurbsError as err:
            self.fail(element.line, f"curv2: {err}")

    def _check_weights(self, element, weights, idx, lines, keyword, what):
        """ObjError at the element for the first weight that is not a positive number."""
        bad = np.nonzero(~(weights > 0) | ~np.isfinite(weights))[0]
        if len(bad):
            k = int(bad[0])
            self.fail(element.line, f"{element.kind}: control point {k + 1} (the {keyword} of "
                                    f"line {lines[idx[k]]}) has weight {weights[k]:g}; weights "
                                    f"of a rational {what} must be positive")

    def _surface(self, element, points, point_lines, weight_tokens, material_ids, curves):
        idx = self._resolve(element, len(points), "vertex", "v")
        _, params_u = self._parm_values(element, "u")
        _, params_v = self._parm_values(element, "v")
        weights = None
        if element.rational:
            weights = np.ones(len(idx))
            for k, index in enumerate(idx.tolist()):
                token = weight_tokens.get(index)
                if token is not None:
                    try:
                        weights[k] = float(token)
                    except ValueError:
                        weights[k] = math.nan
            self._check_weights(element, weights, idx, point_lines, "v", "surface")
        try:
            surface = make_surface(element.degree, params_u, params_v, points[idx], weights,
                                   element.domain, bezier=element.basis == "bezier")
        except NurbsError as err:
            self.fail(element.line, str(err) if str(err).startswith("surf ")
                      else f"surf: {err}")
        loops = []
        for line, hole, pieces, known in element.loops:
            keyword = "hole" if hole else "trim"
            chain = []
            for u0, u1, index in pieces:
                resolved = index - 1 if index > 0 else known + index
                if resolved < 0 or resolved >= len(curves):
                    self.fail(line, f"{keyword}: curv2 index {index} out of range: the file "
                                    f"has {len(curves)} curv2 statements")
                chain.append((u0, u1, curves[resolved]))
            try:
                loops.append(make_loop(chain, hole, surface.domain))
            except NurbsError as err:
                self.fail(line, f"{keyword}: {err}")
        material = -1 if element.material is None else material_ids[element.material]
        return NurbsSurface(surface.degree, surface.knots_u, surface.knots_v, surface.control,
                            surface.domain, surface.rational, tuple(loops), material)
