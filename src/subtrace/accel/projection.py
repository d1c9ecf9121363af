"""Primary-ray acceleration: the shells projected onto the image, binned into pixel tiles.

Every primary ray leaves the eye through a pixel centre. A shell's box seen from the eye
covers the convex hull of its eight corners' projections (a perspective map keeps convex
sets convex while the box stays in front of the eye plane), so its bounding rectangle,
widened by a pixel for rounding, holds every pixel whose ray can enter the box. Each
``TILE`` x ``TILE`` tile of the image lists the shells whose rectangles reach it, nearest
box first (``key``: the distance from the eye to the box, a lower bound on every ray's
entry distance). A ray walks its tile's list and stops at the first shell whose key is not
below its best hit: no later shell can hold a nearer one. A box that reaches the eye plane
(or the eye) is listed in every tile; one wholly behind it in none.

``boxes_in_view`` asks the same question of boxes without listing them: whether any
primary ray can enter each (the renderer's view cull of cage faces, ``render.py``).

``project_shells(bmin, bmax, frame, width, height)`` returns :class:`Tiles`:

* ``off`` (T+1,) int64 and ``items`` (E,) int32: tile ``t``'s shells are
  ``items[off[t]:off[t+1]]``, tiles row by row (``per_row`` of them per row);
* ``key`` (N,) float64: the distance from the eye to each shell's box.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from subtrace.runtime import threads as tasks
from subtrace.runtime.jit import inline_njit, nb

TILE = 2  # pixels per tile side


class Tiles(NamedTuple):
    """Per tile of ``TILE`` x ``TILE`` pixels (row-major, ``per_row`` tiles a row), the boxes
    a ray through it may enter, nearest box first: ``items[off[k]:off[k+1]]`` (int32), and
    each box's distance from the eye ``key`` (N,) float64. Passed to the kernels as is."""

    off: np.ndarray
    items: np.ndarray
    key: np.ndarray
    per_row: np.int64


def no_tiles() -> Tiles:
    """The kernels' tile arguments when rays traverse the BVH instead."""
    return Tiles(np.zeros(1, np.int64), np.zeros(0, np.int32), np.zeros(0), np.int64(0))


def project_shells(bmin, bmax, frame, width: int, height: int,
                   max_bytes: int | None = None, image=None) -> Tiles | None:
    """Bin the boxes ``[bmin, bmax]`` (N,3) into the tiles of a ``width`` x ``height`` image
    seen through ``frame`` (``trace.camera.camera_frame``). With ``max_bytes``: None, and
    nothing allocated, when the tile lists would take more (boxes that reach the eye plane
    are listed in every tile: with the eye inside a model they can be many).

    ``image``: (width, height) of the whole image when ``frame`` is a window's
    (``camera.CameraWindow``: its offset, even, in a fifth row): only the window's tiles
    are listed (and held against ``max_bytes``), each exactly as the whole image lists it:
    the same boxes, in the same order."""
    bmin, bmax = _boxes(bmin, bmax)
    eye = frame[0]
    inv = _pixel_map(frame)
    key = np.empty(len(bmin))
    full_w, full_h = (int(width), int(height)) if image is None else map(int, image)
    col0, row0 = (int(frame[4, 0]), int(frame[4, 1])) if len(frame) > 4 else (0, 0)
    if col0 % TILE or row0 % TILE:
        raise ValueError(f"a window's offset must be a multiple of {TILE}, got {col0, row0}")
    a0, b0 = col0 // TILE, row0 // TILE  # the window's first tile in the image's
    tx = -(-int(width) // TILE)
    ty = -(-int(height) // TILE)
    rect = np.empty((len(bmin), 4), np.int64)  # (in the image's tiles)
    n_tasks = tasks.thread_count() if len(bmin) >= _PARALLEL_MIN else 1
    count = np.zeros((n_tasks, tx * ty + 1), np.int64)
    eye = np.ascontiguousarray(eye)
    none = np.zeros(0, np.int64)
    tasks.run_tasks(_tiles, 0, bmin, bmax, eye, inv, full_w, full_h, a0, b0, tx, ty, rect,
                    count, key, none, none, np.zeros(0, np.int32), n=n_tasks)
    off = np.zeros(tx * ty + 1, np.int64)
    np.cumsum(count.sum(axis=0)[:-1], out=off[1:])
    if max_bytes is not None and tiles_bytes(int(off[-1]), tx * ty) > max_bytes:
        return None
    seen = np.nonzero(rect[:, 0] <= rect[:, 2])[0]  # (the others are in no tile)
    items = np.empty(int(off[-1]), np.int32)
    # each box's tiles within the window, in the window's tiles (empty: none)
    local = np.empty_like(rect)
    np.maximum(rect[:, 0:2] - (a0, b0), 0, out=local[:, 0:2])
    np.minimum(rect[:, 2:4] - (a0, b0), (tx - 1, ty - 1), out=local[:, 2:4])
    # nearest first (ties: any fixed order will do; a window's is its image's: the order of
    # the image's boxes in view)
    _tiles(0, 1, 1, bmin, bmax, eye, inv, full_w, full_h, a0, b0, tx, ty, local, count, key,
           seen[np.argsort(key[seen])], off.copy(), items)
    return Tiles(off, items, key, np.int64(tx))


def boxes_in_view(bmin, bmax, frame, width: int, height: int) -> np.ndarray:
    """(N,) bool: whether any primary ray of a ``width`` x ``height`` image seen through
    ``frame`` can enter the box ``[bmin[i], bmax[i]]``: the box's pixel rectangle, as the
    tiles list it (a pixel wider on each side), is not empty. A box for which this is False
    is in no tile's list, so a surface inside it is never seen by a primary ray."""
    bmin, bmax = _boxes(bmin, bmax)
    rect = np.empty((len(bmin), 4), np.int64)
    n_tasks = tasks.thread_count() if len(bmin) >= _PARALLEL_MIN else 1
    # (the tile lists' own kernel, over no tiles: one kernel fewer to load in a render)
    none = np.zeros(0, np.int64)
    tasks.run_tasks(_tiles, 0, bmin, bmax, np.ascontiguousarray(frame[0]), _pixel_map(frame),
                    int(width), int(height), 0, 0, 0, 0, rect, np.zeros((n_tasks, 1), np.int64),
                    np.empty(len(bmin)), none, none, np.zeros(0, np.int32), n=n_tasks)
    return rect[:, 0] <= rect[:, 2]


def _boxes(bmin, bmax):
    """``bmin``, ``bmax`` as :func:`_tiles` reads them: contiguous float64, read-only views
    (shared boxes are read-only, ``mesh.cage``: one signature of the kernel for both)."""
    out = []
    for b in (bmin, bmax):
        b = np.ascontiguousarray(b, dtype=np.float64).view()
        b.flags.writeable = False
        out.append(b)
    return out


def _pixel_map(frame) -> np.ndarray:
    """(3,3) inverse of the basis [p00, dx, dy]: a point X maps to (a0, a1, a2) with
    X - eye = a0 * p00 + a1 * dx + a2 * dy, at pixel (col, row) = (a1 / a0, a2 / a0)."""
    basis = np.stack([frame[3], frame[1], frame[2]], axis=1)
    return np.ascontiguousarray(np.linalg.inv(basis))


def tiles_bytes(n_items: int, n_tiles: int) -> int:
    """Bytes of the tile lists of ``n_items`` entries over ``n_tiles`` tiles."""
    return 4 * n_items + 8 * (n_tiles + 1)


_BLOCK = 256  # boxes a task projects at a time
_PARALLEL_MIN = 16 * _BLOCK  # fewer boxes than this: projected on one thread


@inline_njit
def _box_rect(i, bmin, bmax, eye, inv, width, height):
    """Pixel rectangle (x0, y0, x1, y1), inclusive, of box ``i`` seen from ``eye``: the
    bounding rectangle of its corners' projections widened by a pixel for rounding, the
    whole image when the box reaches the eye plane, empty (x0 > x1) when it lies behind the
    eye plane or outside the image."""
    c0 = r0 = np.inf
    c1 = r1 = -np.inf
    front = 0
    behind = 0
    for k in range(8):
        x = (bmax[i, 0] if k & 1 else bmin[i, 0]) - eye[0]
        y = (bmax[i, 1] if k & 2 else bmin[i, 1]) - eye[1]
        z = (bmax[i, 2] if k & 4 else bmin[i, 2]) - eye[2]
        a0 = inv[0, 0] * x + inv[0, 1] * y + inv[0, 2] * z
        a1 = inv[1, 0] * x + inv[1, 1] * y + inv[1, 2] * z
        a2 = inv[2, 0] * x + inv[2, 1] * y + inv[2, 2] * z
        scale = abs(x) + abs(y) + abs(z)
        if a0 > 1e-9 * scale:
            front += 1
            c0 = min(c0, a1 / a0)
            c1 = max(c1, a1 / a0)
            r0 = min(r0, a2 / a0)
            r1 = max(r1, a2 / a0)
        elif a0 <= 0.0:
            behind += 1
    if behind == 8:
        return 0, 0, -1, -1
    if front < 8:  # reaches the eye plane: every pixel
        c0, r0, c1, r1 = 0.0, 0.0, width - 1.0, height - 1.0
    # pixel centres are at integer (col, row); one pixel more on each side for rounding
    x0 = max(int(np.floor(max(c0, -2.0))) - 1, 0)
    y0 = max(int(np.floor(max(r0, -2.0))) - 1, 0)
    x1 = min(int(np.ceil(min(c1, width + 1.0))) + 1, width - 1)
    y1 = min(int(np.ceil(min(r1, height + 1.0))) + 1, height - 1)
    if x0 > x1 or y0 > y1:
        return 0, 0, -1, -1
    return x0, y0, x1, y1


@nb.njit(cache=True, nogil=True)
def _tiles(task, n_tasks, step, bmin, bmax, eye, inv, width, height, tile_a0, tile_b0, tx, ty,
           rect, count, key, order, cursor, items):
    """The tile lists' two steps, one kernel (one load in a render).

    Step 0: each box's tile rectangle ``rect[i]`` = (x0, y0, x1, y1), inclusive, empty
    (x0 > x1) when it lies behind the eye plane or outside the ``width`` x ``height`` image,
    in the image's tiles; counts per tile of the window (``tx`` x ``ty`` tiles from tile
    (tile_a0, tile_b0); the whole image: 0, 0 and all its tiles) into ``count[task]``; the
    distance from the eye to each box into ``key``. Task ``task`` of ``n_tasks``
    (tasks.run_tasks) takes every n_tasks-th block of ``_BLOCK`` boxes.

    Step 1 (one task): append the boxes ``order`` (nearest first) to the lists ``items``
    of the tiles of their rectangles ``rect`` (in the window's tiles), at ``cursor``."""
    if step == 1:
        for i in order:
            for b in range(rect[i, 1], rect[i, 3] + 1):
                for a in range(rect[i, 0], rect[i, 2] + 1):
                    t = b * tx + a
                    items[cursor[t]] = i
                    cursor[t] += 1
        return
    for b0 in range(task * _BLOCK, len(bmin), n_tasks * _BLOCK):
        for i in range(b0, min(b0 + _BLOCK, len(bmin))):
            d2 = 0.0
            for k in range(3):
                g = max(max(bmin[i, k] - eye[k], 0.0), eye[k] - bmax[i, k])
                d2 += g * g
            key[i] = np.sqrt(d2)
            x0, y0, x1, y1 = _box_rect(i, bmin, bmax, eye, inv, width, height)
            if x0 > x1:
                rect[i, 0], rect[i, 1], rect[i, 2], rect[i, 3] = 0, 0, -1, -1
                continue
            rect[i, 0], rect[i, 1] = x0 // TILE, y0 // TILE
            rect[i, 2], rect[i, 3] = x1 // TILE, y1 // TILE
            for b in range(max(rect[i, 1] - tile_b0, 0), min(rect[i, 3] - tile_b0, ty - 1) + 1):
                for a in range(max(rect[i, 0] - tile_a0, 0),
                               min(rect[i, 2] - tile_a0, tx - 1) + 1):
                    count[task, b * tx + a] += 1
