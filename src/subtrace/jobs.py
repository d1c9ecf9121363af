"""What every way of rendering frames shares (``frames.render_frames`` here, ``cluster.py``
on Dask): the result of a frame, writing a frame's files, and an image rendered as tiles one
after another (``render --tile N`` without Dask). Its own module so that neither of the two
imports the other's callers.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from subtrace.tiles import assemble, merge_stats, tile_grid


@dataclass
class FrameResult:
    """One frame of :func:`subtrace.frames.render_frames`: its number (None: the one
    image), its output and preview paths, its statistics (``dataclasses.asdict(RenderStats)``;
    empty for a frame left out), whether it was left out (``resume``), the render (a local
    one's :class:`subtrace.render.RenderResult`, else None) and the seconds its files took
    to write."""

    frame: int | None
    path: str
    preview: str | None
    stats: dict = field(default_factory=dict)
    skipped: bool = False
    result: object = None
    time_write: float = 0.0


def write_frame(out, png, picture, bits, channels, attributes, transparent) -> float:
    """Write one frame's output (an EXR with ``attributes``, or the ``picture`` format of
    ``out`` at ``bits`` per channel: colour over the background unless ``transparent``) and
    its preview ``png``; returns the seconds it took. ``attributes`` may hold
    ``window`` = (x, y, width, height): the channels are that tile of the image."""
    import time

    from subtrace.io.exr import write_exr, write_picture, write_png

    t0 = time.perf_counter()
    attributes = dict(attributes)
    window = attributes.pop("window", None)
    if picture is None:
        write_exr(out, channels, attributes, png_path=png, window=window)
    else:
        ch = channels if transparent else {c: channels[c] for c in "RGB"}
        write_picture(out, ch, bits)
        if png:
            write_png(png, np.stack([channels[c] for c in "RGB"], axis=-1))
    return time.perf_counter() - t0


def result_files(result, scene) -> dict:
    """The header of a render's output (``render.result_attributes``), with the data window
    of a tile (``result.crop``) as ``window``, for :func:`write_frame`."""
    from subtrace.render import result_attributes

    attributes = result_attributes(result, scene)
    if result.crop is not None:
        x0, y0 = result.crop[:2]
        attributes["window"] = (x0, y0, result.camera.width, result.camera.height)
    return attributes


def render_tiled(scene, size: int, cages=None, threads=None, accel=None, progress=None):
    """Render ``scene`` as tiles of at most ``size`` x ``size`` pixels, one after another,
    and put them together: a :class:`subtrace.render.RenderResult` whose channels are the
    whole render's, bit for bit, and whose statistics are the tiles'
    (:func:`subtrace.tiles.merge_stats`). Only one tile's rays, hits and pools are held at
    a time."""
    from subtrace.render import RenderStats, render_scene

    width, height = scene.camera.width, scene.camera.height
    parts, stats, first = [], [], None
    for crop in tile_grid(width, height, size):
        result = render_scene(scene, cages=cages, threads=threads, accel=accel,
                              progress=progress, crop=crop)
        parts.append((crop, result.channels))
        stats.append(dataclasses.asdict(result.stats))
        first = first or result
    return dataclasses.replace(first, channels=assemble(width, height, parts),
                               stats=RenderStats(**merge_stats(stats)), crop=None)


__all__ = ["FrameResult", "write_frame", "result_files", "render_tiled"]
