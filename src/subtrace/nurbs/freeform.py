"""The free-form surfaces of an OBJ file: the reader's plain records
(:class:`subtrace.io.freeform.FreeFormRecords`) made into validated surfaces with their
oriented trim loops (:func:`freeform_of`).

Every ``curv2`` first (trim loops may name later ones), then the surfaces, in file order:
their control point indices resolved, their ``parm`` values and knots checked
(:mod:`~subtrace.nurbs.knots`), rational weights checked, the surfaces and curves made
(:mod:`~subtrace.nurbs.surface`, :mod:`~subtrace.nurbs.trim`); the first problem is an
ObjError naming the file and the statement's line, as the reader's own errors do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from subtrace.errors import NurbsError, ObjError
from subtrace.nurbs.knots import (bezier_knots, check_bezier_params, check_knots,
                                   check_nondecreasing)
from subtrace.nurbs.surface import NurbsSurface, make_surface
from subtrace.nurbs.trim import TrimCurve, make_curve, make_loop


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


def freeform_of(data) -> FreeForm | None:
    """The free-form surfaces of ``data`` (what :func:`subtrace.io.obj.read_obj` returns),
    validated (module doc), or None when the file has no free-form elements."""
    if data.freeform is None:
        return None
    return _Maker(data.freeform).freeform()


class _Maker:
    """Makes one file's records into its :class:`FreeForm` (ObjError at the first problem)."""

    def __init__(self, records):
        self.records = records

    def fail(self, line, problem):
        raise ObjError(self.records.path, line, problem)

    def freeform(self) -> FreeForm:
        r = self.records
        vp = r.param_points
        curves = [self._curve(e, vp) for e in r.elements if e.kind == "curv2"]
        surfaces = [e for e in r.elements if e.kind == "surf"]
        return FreeForm(
            tuple(self._surface(e, r.points, r.point_lines, r.weight_tokens, r.material_ids,
                                curves) for e in surfaces),
            tuple(e.line for e in surfaces), tuple(curves), vp)

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
            self._check_weights(element, vp[idx, 2], idx, self.records.vp_lines, "vp", "curve")
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
