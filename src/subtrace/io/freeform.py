"""OBJ free-form geometry: the statements of trimmed (rational) B-spline and Bezier surfaces.

Owns the text of ``vp``, ``cstype``, ``deg``, ``curv2``, ``surf``, their bodies (``parm``,
``trim``, ``hole``, ``scrv``, ``sp``, ``end``) and ``con``, as the Wavefront OBJ
specification (version 3.0, "Free-form curve/surface attributes" and after) defines them;
:class:`subtrace.io.obj.ObjReader` hands these statements over one by one
(:meth:`FreeFormReader.statement`) and asks for the result once the file is read
(:meth:`FreeFormReader.finish`): plain records (:class:`FreeFormRecords`: each element's
numbers and indices as written, with its lines). The geometry itself (index ranges, knot
checks, Bezier extraction, trim loops) is :mod:`subtrace.nurbs`, which makes the records
into surfaces (:func:`subtrace.nurbs.freeform.freeform_of`) and raises every problem it
finds as an ObjError naming the statement's line.

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

from subtrace.config import NURBS_MAX_DEGREE

# statements this module reads (the OBJ reader sends them here)
STATEMENTS = frozenset(
    "vp cstype deg bmat step curv curv2 surf parm trim hole scrv sp end con".split())
_TYPES = ("bezier", "bspline")
_OTHER_TYPES = ("bmatrix", "cardinal", "taylor")
_IGNORED = ("scrv", "sp", "con", "bmat", "step")  # read and ignored (one warning each)


@dataclass
class Element:
    """A ``curv2`` / ``surf`` / ``curv`` and its body, as read."""

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


@dataclass(frozen=True, eq=False)
class FreeFormRecords:
    """The free-form content of an OBJ file as read, for :mod:`subtrace.nurbs` to make into
    surfaces (:func:`subtrace.nurbs.freeform.freeform_of`).

    path: the file; elements: every ``curv2`` and ``surf``, in file order; param_points
    (P, 3) float64: the ``vp`` lines (u, v, w; w 1 where not given), vp_lines their lines;
    points (V, 3): the v coordinates, point_lines their lines; weight_tokens: v index
    (0-based) -> the w token of v lines with one; material_ids: usemtl name -> material
    index."""

    path: str
    elements: tuple[Element, ...]
    param_points: np.ndarray
    vp_lines: tuple[int, ...]
    points: np.ndarray
    point_lines: list
    weight_tokens: dict
    material_ids: dict


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
        self.elements: list[Element] = []
        self.open: Element | None = None
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
            if not 1 <= value <= NURBS_MAX_DEGREE:  # (nurbs.knots.check_degree's message)
                self.fail(number, f"deg: degree {value} is not supported: degrees 1 to "
                                  f"{NURBS_MAX_DEGREE} are")
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
            self.open = Element("curv", number, False, "", (), [], 0)
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
            self.open = Element("surf", number, rational, basis, degrees, refs, num_points,
                                 domain, material)
        else:
            if len(parts) < 2:
                self.fail(number, "curv2 needs control points vp1 vp2 ...")
            refs = [self._index(number, "curv2", "parameter vertex", token)
                    for token in parts[1:]]
            self.open = Element("curv2", number, rational, basis, degrees[:1], refs,
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

    def finish(self, path, points, point_lines, weight_tokens,
               material_ids) -> FreeFormRecords | None:
        """The records of everything read (:class:`FreeFormRecords`); None for a file
        without elements.

        path: the file; points (V, 3): the v coordinates, point_lines their lines;
        weight_tokens: v index (0-based) -> the w token of v lines with one; material_ids:
        usemtl name -> material index."""
        if self.open is not None and self.open.kind != "curv":
            self.fail(self.open.line, f"{self.open.kind} has no `end`")
        if not self.elements:
            for keyword, (line, count) in self.attributes.items():
                for _ in range(count):
                    self.ignored(keyword, line)
            return None
        return FreeFormRecords(str(path), tuple(self.elements), self._param_points(),
                               tuple(self.vp_lines), points, point_lines, weight_tokens,
                               material_ids)

    def _param_points(self) -> np.ndarray:
        vp = np.zeros((len(self.vp_tokens), 3))
        vp[:, 2] = 1.0
        for row, (tokens, line) in enumerate(zip(self.vp_tokens, self.vp_lines)):
            for col, token in enumerate(tokens):
                vp[row, col] = self._number(line, "vp", token)
        return vp
