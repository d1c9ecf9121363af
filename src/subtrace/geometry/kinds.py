"""One enum of every item a ray can meet in the pieces' store (``trace.pools.Pieces``, its
``kind`` column, int8), and plain-int names of its members for the jitted kernels (which
take module globals as compile-time constants).

* ``BEZIER``: a bicubic Bezier net over a dyadic square of a Catmull-Clark patch (a regular
  patch is one, a piece of an isolated one another), split per ray (``geometry/bezier.py``);
* ``CELL``: a cell of exact limit points of an isolated Catmull-Clark patch, where no level
  down to its depth is regular (two triangles of its corners);
* ``TRI``: a quartic triangular Bezier net of a Loop patch or piece (``geometry/tris.py``);
* ``LOOP_CELL``: a micro-triangle of exact limit points of an isolated Loop patch;
* ``GROUP``: a group row of an isolated patch's items, depth first in its split tree: a
  ray that misses its box skips the rows it spans (``patches/groups.py``).

Each kind's operations live in a module of this room: the ray / Bezier-piece and cell
intersection and the per-patch walk over a patch's items (``geometry/bezier.py``), the
Loop triangles and cells (``geometry/tris.py``: intersection, points, normals,
derivatives), with the primitives they share (``geometry/prims.py``: ray setup, the
watertight ray / triangle test, the hit record and memo layout; ``geometry/snap.py``:
snapped sides). The patch table's patch types (one code per patch) are the table's own
vocabulary, named in ``patches.table.Patch``: the table is built below this room.
"""

from __future__ import annotations

import enum


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

