"""The range checks a render or a line query applies to a cage before any work: coordinates
small enough that squared distances stay finite, and valences small enough that refinement
ends in reasonable time (``config.MAX_COORDINATE``, ``config.MAX_VALENCE``).

:func:`subtrace.load_cage` does not run them: a cage outside these ranges is valid, only
too large to render. Errors are ObjError naming the line of the offending statement.
"""

from __future__ import annotations

import numpy as np

from subtrace.errors import ObjError
from subtrace.io.obj import statement_line


def check_coordinates(path, points, limit: float, box=None) -> None:
    """Raise ObjError naming the line of the first vertex of ``points`` (V,3) with a
    coordinate of magnitude above ``limit`` (``config.MAX_COORDINATE``). ``box``: the box
    of ``points`` where the caller has it (``Cage.points_box``): within the limit, no
    vertex is looked at."""
    if box is not None and max(np.abs(box[0]).max(), np.abs(box[1]).max()) <= limit:
        return
    big = np.nonzero(np.abs(points).max(axis=1, initial=0.0) > limit)[0] if len(points) else []
    if len(big):
        i = int(big[0])
        value = float(np.abs(points[i]).max())
        raise ObjError(
            path, statement_line(path, "v", i) if path else None,
            f"vertex {i + 1} has a coordinate of magnitude {value:.3g}; subtrace renders "
            f"coordinates up to {limit:.0e} (beyond, squared distances overflow double "
            "precision): scale the model down")


def check_valences(path, face_sizes, valence, limit: int, catmark: bool) -> None:
    """Raise ObjError naming the line of the first face with more than ``limit`` vertices
    (Catmull-Clark: its centre becomes a vertex of that valence) or of the first vertex
    of valence above ``limit`` (``config.MAX_VALENCE``)."""
    hint = (f"subtrace renders valences up to {limit} (refining around such a vertex takes "
            "minutes and more): split the face or the fan")
    if catmark:
        big = np.nonzero(np.asarray(face_sizes) > limit)[0]
        if len(big):
            f = int(big[0])
            raise ObjError(path, statement_line(path, "f", f) if path else None,
                           f"face {f + 1} has {int(face_sizes[f])} vertices, so its centre "
                           f"has valence {int(face_sizes[f])}; {hint}")
    big = np.nonzero(np.asarray(valence) > limit)[0]
    if len(big):
        v = int(big[0])
        raise ObjError(path, statement_line(path, "v", v) if path else None,
                       f"vertex {v + 1} has valence {int(valence[v])}; {hint}")
