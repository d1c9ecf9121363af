"""Per-face classifications of a refined level, kept with the level.

The depth choice (``patches.isolate.isolated_depths``), the build of the requested patches
(``isolated_parts``), the edge sampling (``patches.crease.cell_free_depths``) and the exact
cell normals (``shade.exact_cell_normals``) ask the same levels which of their faces the
fixed maps serve (``crease.crease_faces``, ``stencil.stencil_faces``,
``gridmaps.grid_faces``), mostly for faces
asked before: the patch level's irregular quads, and the frontier faces of the levels the
depth choice recorded for the build. :class:`FaceMemo` answers each face of a level once
and keeps the answers as long as the level lives (a weak reference: a level cut out for
one patch goes with it).
"""

from __future__ import annotations

import weakref

import numpy as np


class FaceMemo:
    """``memo(level, options, faces)``: ``compute(level, options, faces)``'s per-face
    arrays (one of each of ``dtypes``: a dtype, or ``(dtype, row shape)``) for ``faces``,
    each face of a level computed once for the same ``options``. ``compute`` must give a
    face the same answer whichever other faces it is asked with."""

    def __init__(self, compute, dtypes):
        self._compute = compute
        self._dtypes = dtypes
        self._levels = weakref.WeakKeyDictionary()

    def __call__(self, level, options, faces):
        faces = np.asarray(faces, dtype=np.int64)
        kept = self._levels.get(level)
        if kept is None or kept[0] != options:
            n = level.n_faces
            kept = (options, np.zeros(n, bool),
                    [np.zeros((n, *d[1]), d[0]) if isinstance(d, tuple) else np.zeros(n, d)
                     for d in self._dtypes])
            self._levels[level] = kept
        _, known, arrays = kept
        fresh = faces[~known[faces]]
        if len(fresh):
            mark = np.zeros(len(known), bool)
            mark[fresh] = True
            fresh = np.nonzero(mark)[0]
            for array, part in zip(arrays, self._compute(level, options, fresh)):
                array[fresh] = part
            known[fresh] = True
        return tuple(array[faces] for array in arrays)
