"""``subtrace intersect CAGE.obj --lines LINES.csv --precision D``: every hit of the lines
of a CSV with a cage's limit surface, or with the trimmed NURBS surfaces of an OBJ file of
free-form surfaces (:func:`subtrace.lines.api.intersect_lines`; ``ptex`` is then the
surface index, ``u, v`` its parameters), written as CSV or JSON to stdout or, through a
temporary and a rename, to a file."""

from __future__ import annotations

import json
import math
import os
import sys
import warnings

import numpy as np

from subtrace import config
from subtrace.cli.common import boundary_code, set_up_numba
from subtrace.errors import SubtraceError, SubtraceWarning
from subtrace.io.limits import check_coordinates, check_valences
from subtrace.io.lines_csv import read_lines_csv
from subtrace.io.obj import read_obj
from subtrace.lines.api import intersect_lines
from subtrace.mesh.cage import cage_from_obj, load_cage
from subtrace.nurbs.freeform import freeform_of
from subtrace.nurbs.model import load_model
from subtrace.nurbs.scene import has_faces, has_surfaces
from subtrace.runtime.atomic import write_text

HIT_COLUMNS = "line,t,x,y,z,ptex,u,v,nx,ny,nz,tangent"


def execute(args) -> int:
    """Check the options and inputs, intersect, write the hits."""
    precision, t_range = _check_options(args)
    data = read_lines_csv(args.lines)
    cage = _target(args)
    out = args.output
    if out is not None:
        folder = os.path.dirname(os.path.abspath(out))
        if not os.path.isdir(folder):
            raise SubtraceError(f"{out}: no such folder {folder}")
    set_up_numba(args)
    hits = intersect_lines(cage, data[:, :3], data[:, 3:], precision, t_range=t_range,
                           mode="first" if args.first else "all", threads=args.threads)
    text = hits_json(hits, precision, len(data)) if args.json else hits_csv(hits)
    if out is None:
        sys.stdout.write(text)
    else:
        write_text(out, text)
        n_hit = len(np.unique(hits.line))
        print(f"{out}: {len(hits)} hit{'s' if len(hits) != 1 else ''} on {n_hit} of "
              f"{len(data)} line{'s' if len(data) != 1 else ''} (precision {precision:g})")
    return 0


def _target(args):
    """What the lines meet: the file's free-form surfaces (a NurbsModel) when it has no
    polygon faces, else its subdivision cage (a file with both: its cage, as for render's
    cages; the surfaces are reported by a warning, not intersected)."""
    if has_surfaces(args.cage) and not has_faces(args.cage):
        model = load_model(args.cage)
        check_coordinates(args.cage, model.nets[..., :3].reshape(-1, 3), config.MAX_COORDINATE)
        return model
    if has_surfaces(args.cage):  # (an OBJ file) its surfaces checked, as a render checks them
        data = read_obj(args.cage)
        freeform_of(data)
        cage = cage_from_obj(data, scheme=args.scheme, boundary=boundary_code(args))
    else:
        cage = load_cage(args.cage, scheme=args.scheme, boundary=boundary_code(args))
    check_coordinates(cage.path, cage.points, config.MAX_COORDINATE)
    check_valences(cage.path, cage.face_sizes, np.diff(cage.base.vert_edge_offsets),
                   config.MAX_VALENCE, cage.scheme == "catmark")
    if has_surfaces(args.cage):
        warnings.warn(f"{args.cage}: its free-form surfaces are not intersected (a file with "
                      "polygon faces is intersected as a cage)", SubtraceWarning, stacklevel=2)
    return cage


def _check_options(args) -> tuple[float, tuple[float, float]]:
    """--precision (finite, > 0) and the (t-min, t-max) range (not NaN, t-min < t-max)."""

    def number(text, key):
        try:
            return float(text)
        except ValueError:
            raise SubtraceError(f"--{key} {text}: expected a number") from None

    precision = number(args.precision, "precision")
    if not (precision > 0 and math.isfinite(precision)):
        raise SubtraceError(f"--precision {args.precision}: expected a finite number > 0")
    t_range = (number(args.t_min, "t-min"), number(args.t_max, "t-max"))
    for value, key in zip(t_range, ("t-min", "t-max")):
        if math.isnan(value):
            raise SubtraceError(f"--{key} {value}: expected a number (or -inf / inf), not nan")
    if not t_range[0] < t_range[1]:
        raise SubtraceError(f"--t-max {args.t_max}: expected a number above --t-min "
                            f"{args.t_min}")
    return precision, t_range


def hits_json(hits, precision: float, n_lines: int) -> str:
    """The hits as the JSON document ``--json`` writes."""
    return json.dumps({
        "precision": precision, "lines": int(n_lines),
        "hits": [{"line": int(hits.line[k]), "t": float(hits.t[k]),
                  "point": hits.point[k].tolist(), "ptex": int(hits.ptex[k]),
                  "uv": hits.uv[k].tolist(), "normal": hits.normal[k].tolist(),
                  "tangent": bool(hits.tangent[k])} for k in range(len(hits))],
    }, indent=1) + "\n"


def hits_csv(hits) -> str:
    """The hits as CSV: a header of HIT_COLUMNS, a row per hit (floats as repr: exact)."""
    lines = [HIT_COLUMNS]
    ln, tt, pt = hits.line.tolist(), hits.t.tolist(), hits.point.tolist()
    px, uvs, nrm = hits.ptex.tolist(), hits.uv.tolist(), hits.normal.tolist()
    for k in range(len(hits)):
        p, uv, nr = pt[k], uvs[k], nrm[k]
        lines.append(f"{ln[k]},{tt[k]!r},{p[0]!r},{p[1]!r},{p[2]!r},"
                     f"{px[k]},{uv[0]!r},{uv[1]!r},{nr[0]!r},{nr[1]!r},{nr[2]!r},"
                     f"{int(hits.tangent[k])}")
    return "\n".join(lines) + "\n"
