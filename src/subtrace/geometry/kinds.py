"""One enum of every item a ray can meet in the pieces' store (``trace.pools.Pieces``, its
``kind`` column, int8), one of the patch table's patch types (``patches.table.PatchTable``,
its ``patch_type`` column, int8), and plain-int names of their members for the jitted
kernels (which take module globals as compile-time constants).

* ``BEZIER``: a bicubic Bezier net over a dyadic square of a Catmull-Clark patch (a regular
  patch is one, a piece of an isolated one another), split per ray (``trace/bezier.py``);
* ``CELL``: a cell of exact limit points of an isolated Catmull-Clark patch, where no level
  down to its depth is regular (two triangles of its corners);
* ``TRI``: a quartic triangular Bezier net of a Loop patch or piece (``trace/tris.py``);
* ``LOOP_CELL``: a micro-triangle of exact limit points of an isolated Loop patch;
* ``GROUP``: a group row of an isolated patch's items, depth first in its split tree: a
  ray that misses its box skips the rows it spans (``patches/groups.py``).

The patch types:

* ``CATMARK_REGULAR``: a regular bicubic Catmull-Clark patch (one Bezier net, its table's);
* ``CATMARK_IRREGULAR``: any other Catmull-Clark quad of the patch level (isolated into
  pieces and cells when a ray first asks for it);
* ``LOOP``: a Loop triangle (a regular one becomes one triangular net, the others are
  isolated, both when the trace starts or a ray asks: ``patches.boxspline.loop_regular``).
"""

from __future__ import annotations

import enum

import numpy as np


class Item(enum.IntEnum):
    """The kinds of the pieces' items (module doc)."""

    BEZIER = 0
    CELL = 1
    TRI = 2
    LOOP_CELL = 3
    GROUP = 4


BEZIER = int(Item.BEZIER)
CELL = int(Item.CELL)
TRI = int(Item.TRI)
LOOP_CELL = int(Item.LOOP_CELL)
GROUP = int(Item.GROUP)


class Patch(enum.IntEnum):
    """The patch table's patch types (module doc)."""

    CATMARK_REGULAR = 0
    CATMARK_IRREGULAR = 1
    LOOP = 2


CATMARK_REGULAR = int(Patch.CATMARK_REGULAR)
CATMARK_IRREGULAR = int(Patch.CATMARK_IRREGULAR)
LOOP = int(Patch.LOOP)


def patch_types(quad: bool, regular) -> np.ndarray:
    """(n,) int8 patch types of an object's patches: Loop triangles, or Catmull-Clark quads
    regular where ``regular`` (n,) bool says."""
    regular = np.asarray(regular, dtype=bool)
    if not quad:
        return np.full(len(regular), LOOP, np.int8)
    return np.where(regular, CATMARK_REGULAR, CATMARK_IRREGULAR).astype(np.int8)
