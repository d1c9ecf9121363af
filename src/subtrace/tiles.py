"""Tiles of an image: ``render --crop X0 Y0 X1 Y1`` renders one, ``render --tile N`` renders
an image as tiles of at most N x N pixels (one after another, or on a Dask cluster one task
each: ``cluster.py``) and puts them together.

A tile is rendered by ``render.render_scene(crop=...)``: everything that depends on the
whole image (the camera, the tolerance, the patch table of the faces in view, the depths,
the projection's tile lists) is the whole image's, and only the rays of the tile (and of a
pixel around it, for anti-aliasing's neighbour test) are traced, so its pixels are the
whole render's, bit for bit, and tiles put together are the whole image. The memory budget
holds the tile's own per-pixel arrays (a tile of an image too large to render whole
renders): only where the whole image's would make the budget cap depths do its tiles
differ from it, refined further.

Layout: a crop is (x0, y0, x1, y1), pixels, x1 and y1 excluded; channels are name -> (H,W)
float32, row 0 at the top. A tile on disk (a task's output, waiting to be put together) is
a ``.npz`` of its channels (float32, so colour is not rounded to half before a picture
output is encoded), written atomically beside the frame it belongs to.
"""

from __future__ import annotations

import os

import numpy as np

from subtrace.errors import SceneError

# RenderStats fields that are not a sum over tiles but the largest of them: one value of
# the whole render that every tile has (the table's patches, the faces culled, the
# fallback), the deepest (grid, level, cap, secondary rays' grid), and the most at once
# (rounds, the memos' peak bytes). The others are counts and times, summed: the pixels
# covered are the image's (a tile counts its own pixels), the rest what the tiles did (a
# patch two tiles reach is built twice; rays of the pixels around a tile are traced again)
_MAX_FIELDS = frozenset(("patches", "faces_culled", "max_depth", "max_level", "depth_cap",
                         "accel_fallback", "rounds", "memo_bytes", "secondary_max_depth"))


def check_tile(n) -> int:
    """--tile N: a whole number of pixels, at least 16 (smaller tiles trace mostly the
    pixel around them)."""
    try:
        value = int(str(n).strip())
    except (TypeError, ValueError):
        value = 0
    if value < 16 or str(n).strip() != str(value):
        raise SceneError(f"expected a tile size in pixels >= 16, got {n!r}", key="--tile")
    return value


def check_crop(crop, width: int, height: int) -> tuple[int, int, int, int]:
    """--crop X0 Y0 X1 Y1: whole numbers with 0 <= X0 < X1 <= width, 0 <= Y0 < Y1 <= height
    (pixel bounds, X1 and Y1 excluded); SceneError naming --crop."""
    try:
        values = tuple(int(str(v).strip()) for v in crop)
        if len(values) != 4 or any(str(v).strip() != str(w) for v, w in zip(crop, values)):
            raise ValueError
    except (TypeError, ValueError):
        raise SceneError(f"expected four whole numbers X0 Y0 X1 Y1, got "
                         f"{' '.join(map(str, crop))!r}", key="--crop") from None
    x0, y0, x1, y1 = values
    if not (0 <= x0 < x1 <= width and 0 <= y0 < y1 <= height):
        raise SceneError(f"{x0} {y0} {x1} {y1} is not a window of the {width}x{height} image "
                         f"(0 <= X0 < X1 <= {width}, 0 <= Y0 < Y1 <= {height})", key="--crop")
    return values


def tile_grid(width: int, height: int, size: int) -> list[tuple[int, int, int, int]]:
    """The crops (x0, y0, x1, y1) of a ``width`` x ``height`` image cut into tiles of at
    most ``size`` x ``size`` pixels, row by row; they cover every pixel once."""
    return [(x, y, min(x + size, width), min(y + size, height))
            for y in range(0, height, size) for x in range(0, width, size)]


def assemble(width: int, height: int, parts) -> dict:
    """The channels of the whole ``width`` x ``height`` image from ``parts``, pairs (crop,
    channels of that tile) that cover it. ValueError if a pixel is left out."""
    out = {}
    seen = np.zeros((height, width), np.bool_)
    for (x0, y0, x1, y1), channels in parts:
        for name, plane in channels.items():
            if name not in out:
                out[name] = np.empty((height, width), np.float32)
            out[name][y0:y1, x0:x1] = plane
        seen[y0:y1, x0:x1] = True
    if not seen.all():
        raise ValueError(f"the tiles leave {int((~seen).sum())} pixels out")
    return out


def merge_stats(stats: list[dict]) -> dict:
    """The statistics of a render made of tiles (``dataclasses.asdict(RenderStats)`` each):
    counts and times summed; the table's size, deepest depth and level, caps and rounds
    the largest; cap reasons joined."""
    merged = dict(stats[0])
    for s in stats[1:]:
        for k, v in s.items():
            if isinstance(v, str):
                reasons = [r for r in (merged[k] + "," + v).split(",") if r != "none"]
                merged[k] = ",".join(dict.fromkeys(reasons)) or "none"
            elif k in _MAX_FIELDS:
                merged[k] = max(merged[k], v)
            else:
                merged[k] = merged[k] + v
    return merged


def tile_path(out: str, crop) -> str:
    """Where the tile ``crop`` of the frame written to ``out`` waits to be put together: a
    hidden file beside it."""
    folder, name = os.path.split(os.path.abspath(out))
    return os.path.join(folder, ".{}.{}-{}-{}-{}.tile.npz".format(name, *crop))


def write_tile(path: str, channels: dict) -> None:
    """Write a tile's channels (float32) to ``path``, whole or not at all."""
    from subtrace.runtime.atomic import atomic_paths, open_temp

    with atomic_paths([path]) as temps:
        with open_temp(temps[0], "wb") as f:
            np.savez(f, **{k: np.asarray(v, np.float32) for k, v in channels.items()})


def read_tile(path: str) -> dict:
    """The channels :func:`write_tile` wrote."""
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


__all__ = ["check_crop", "check_tile", "tile_grid", "assemble", "merge_stats"]
