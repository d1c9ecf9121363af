"""Frames: a turntable camera path, frame ranges and numbered output names.

``subtrace render ... --turntable N`` renders N frames whose eyes orbit the target about the
camera's up axis through it, one full turn (frame k at 360 k / N degrees from the scene's
own eye, or from the automatic camera's); ``--frames A:B[:STEP]`` picks frames A, A+STEP,
... below B (Python's range; B may be left out: to the last frame). Outputs are numbered:
a run of ``#`` in the output name is the frame number padded to its length
(``spin.####.exr`` -> ``spin.0007.exr``), and a name without ``#`` gets ``.####`` before its
extension. One process renders every frame: the cages are read and checked once and the
kernels loaded once; each frame then builds what its view needs.

A scene of USD stages with time samples has frames of its own: without ``--turntable``,
``--frames A:B[:STEP]`` picks time codes of the stages' frame range (``A:B`` as above, with
A and B time codes; ``:`` all of them), and each frame reads the stages at its time code:
the meshes (read once for every frame when no mesh is animated), and the camera and
lights where the scene took them from a stage.

:func:`render_frames` is the Python API of all of it (``subtrace.render_frames``): frames
of a turntable or one image, a tile of each (``crop``) or each cut into tiles (``tile``),
here or on a Dask cluster (``dask``: ``cluster.py``), leaving out frames already written
(``resume``: an output is written whole or not at all, so one that is there and reads
back is complete).
"""

from __future__ import annotations

import dataclasses
import math
import os
import re

import numpy as np

from subtrace.errors import SceneError

PAD = 4  # digits of a frame number when the output name has no '#'


def parse_frames(text: str | None, n_frames: int, first: int = 0) -> range:
    """The frames ``A:B[:STEP]`` of the ``n_frames`` numbered from ``first`` (None: all);
    SceneError naming --frames."""
    end = first + n_frames
    if text is None:
        return range(first, end)
    parts = text.split(":")
    try:
        if len(parts) == 1:
            a = int(parts[0])
            frames = range(a, a + 1)
        elif len(parts) in (2, 3):
            a = int(parts[0]) if parts[0] else first
            b = int(parts[1]) if parts[1] else end
            step = int(parts[2]) if len(parts) == 3 and parts[2] else 1
            if step <= 0:
                raise ValueError
            frames = range(a, b, step)
        else:
            raise ValueError
    except ValueError:
        raise SceneError(f"expected A:B[:STEP] (frame numbers, a step > 0), got {text!r}",
                         key="--frames") from None
    if not frames or frames.start < first or frames[-1] >= end:
        raise SceneError(f"{text!r} selects no frames of {first}..{end - 1}"
                         if not frames or frames[-1] < first or frames.start >= end else
                         f"{text!r} goes beyond the frames {first}..{end - 1}", key="--frames")
    return frames


def usd_stages(scene) -> list[str]:
    """The USD stages of ``scene`` (its objects' and the one its camera or lights came
    from), each once."""
    from subtrace.io.usd import is_usd

    paths = [o.mesh for o in scene.objects if is_usd(o.mesh)]
    if scene.usd_source is not None:
        paths.append(scene.usd_source[0])
    return list(dict.fromkeys(os.path.abspath(p) for p in paths))


def stage_frames(scene, frames: str) -> range:
    """The time codes ``frames`` (A:B[:STEP]) picks of the frame range of ``scene``'s USD
    stages (the union of theirs); SceneError naming --frames where there is none."""
    from subtrace.io.usd import time_range

    stages = usd_stages(scene)
    spans = [s for s in map(time_range, stages) if s is not None]
    if not spans:
        raise SceneError("--frames picks frames of a camera path or of a USD stage's time "
                         "samples: give --turntable N" if not stages else
                         f"{stages[0]}: the stage has no time samples, so no frames: give "
                         "--turntable N for a camera path", key="--frames")
    first, last = min(a for a, _ in spans), max(b for _, b in spans)
    return parse_frames(frames, last - first + 1, first)


def scene_at_time(scene, time: float):
    """``scene`` at a USD time code: its stages' meshes read at ``time``, and its camera
    and lights too where they came from a stage."""
    from subtrace.io.scene import Light
    from subtrace.io.usd import is_usd, light_table, read_stage

    out = dataclasses.replace(scene, objects=tuple(
        dataclasses.replace(o, time=float(time)) if is_usd(o.mesh) else o
        for o in scene.objects))
    if scene.usd_source is None:
        return out
    stage, camera, lights = scene.usd_source
    content = read_stage(stage, time)
    cams = [c for c in content.cameras if c.prim == camera]
    if cams:  # (a camera hidden at this time keeps the last one seen)
        c = cams[0]
        out = dataclasses.replace(out, camera=dataclasses.replace(
            scene.camera, eye=c.eye, target=c.target, up=c.up, fov_deg=c.fov_deg))
    if lights and content.lights:
        tables = [light_table(light) for light in content.lights]
        out = dataclasses.replace(out, lights=tuple(
            Light(tuple(t["direction"]), tuple(t["color"]), t["intensity"],
                  angle=t.get("angle")) for t in tables))
    return out


def frame_numbers(scene, turntable=None, frames=None) -> range | None:
    """The frames to render: of the turntable (``turntable`` N), else of the USD stages'
    time samples (``frames`` given without a turntable); None for the one image."""
    if turntable is not None:
        return parse_frames(frames, check_turntable(turntable))
    if frames is not None:
        return stage_frames(scene, frames)
    return None


def frame_path(pattern: str, frame: int) -> str:
    """The output of ``frame``: the last run of '#' in the file name replaced by the frame
    number padded to its length, else ``.####`` inserted before the extension."""
    folder, name = os.path.split(pattern)
    runs = list(re.finditer(r"#+", name))
    if runs:
        m = runs[-1]
        name = f"{name[:m.start()]}{frame:0{len(m.group())}d}{name[m.end():]}"
    else:
        stem, ext = os.path.splitext(name)
        name = f"{stem}.{frame:0{PAD}d}{ext}"
    return os.path.join(folder, name)


def turntable_eye(eye, target, up, frame: int, n_frames: int) -> tuple:
    """The eye of turntable frame ``frame`` of ``n_frames``: ``eye`` turned about the axis
    through ``target`` along ``up`` by 360 frame / n_frames degrees (Rodrigues' formula)."""
    k = np.asarray(up, dtype=np.float64)
    k = k / np.linalg.norm(k)
    v = np.asarray(eye, dtype=np.float64) - np.asarray(target, dtype=np.float64)
    a = 2.0 * math.pi * frame / n_frames
    turned = v * math.cos(a) + np.cross(k, v) * math.sin(a) + k * np.dot(k, v) * (1 - math.cos(a))
    return tuple(float(x) for x in np.asarray(target, dtype=np.float64) + turned)


def check_turntable(n) -> int:
    """--turntable N: a whole number of frames, at least 1."""
    try:
        value = int(n)
    except (TypeError, ValueError):
        value = 0
    if value < 1 or str(n).strip() != str(value):
        raise SceneError(f"expected a number of frames >= 1, got {n!r}", key="--turntable")
    return value


def is_complete(path) -> bool:
    """Whether ``path`` is an image that reads back whole (outputs are written through a
    temporary and renamed, so one that exists is complete unless it was damaged since)."""
    from subtrace.errors import SubtraceError
    from subtrace.io.exr import read_exr

    if not os.path.isfile(path):
        return False
    try:
        read_exr(path)
    except SubtraceError:
        return False
    return True


def frame_scenes(scene, turntable=None, frames=None, output=None, png=None):
    """The frames of ``scene``: [(number, scene of the frame, output, preview)] and the
    cages read for them (None where each frame reads its own: free-form surfaces). Without
    ``turntable``, the one image (number None)."""
    from subtrace.io.scene import apply_overrides
    from subtrace.nurbs.scene import has_surfaces, load_nurbs
    from subtrace.render import load_objects, scene_bounds

    out = output or scene.output or "render.exr"
    loaded = cages = load_objects(scene)  # once for every frame
    if any(has_surfaces(o.mesh) for o in scene.objects):
        cages = None  # (a render given cages leaves free-form surfaces out: each frame reads)
    picked = frame_numbers(scene, turntable, frames)
    if picked is None:
        return [(None, scene, out, png)], cages
    if turntable is None:  # a USD stage's time codes
        from subtrace.io.usd import is_animated

        if any(map(is_animated, usd_stages(scene))):
            cages = None  # each frame reads its meshes
        return [(t, scene_at_time(scene, t), frame_path(out, t), png and frame_path(png, t))
                for t in picked], cages
    n = check_turntable(turntable)
    camera = scene.make_camera(*scene_bounds(loaded, load_nurbs(scene)),
                               outside=[c.points_box for c in loaded])
    return [(k, apply_overrides(scene, target=tuple(camera.target), up=tuple(camera.up),
                                fov=camera.fov_deg,
                                eye=turntable_eye(camera.eye, camera.target, camera.up, k, n)),
             frame_path(out, k), png and frame_path(png, k)) for k in picked], cages


def render_frames(scene, output=None, *, turntable=None, frames=None, crop=None, tile=None,
                  dask=False, resume=False, png=None, bits=8, threads=None, accel=None,
                  progress=None, report=None, wait=True):
    """Render the frames of ``scene`` (a :class:`subtrace.io.scene.Scene`, or the path of a
    TOML scene or an OBJ cage) to ``output`` (default: the scene's, else ``render.exr``):

    * ``turntable`` N: N frames orbiting the target (numbered outputs, :func:`frame_path`),
      ``frames`` "A:B[:STEP]" of them; without it, ``frames`` picks time codes of the
      scene's USD stages (:func:`stage_frames`), and without either, the one image;
    * ``crop`` (x0, y0, x1, y1): only that tile of each frame (an EXR's data window);
      ``tile`` N: each frame rendered as tiles of at most N x N pixels, put together;
    * ``dask``: False (here, the cages read once for every frame), None (a LocalCluster of
      a worker process per core), a scheduler's address or a ``distributed.Client``: each
      frame, or each tile, is a task (``cluster.py``);
    * ``resume``: leave out the frames whose files are already there and complete;
    * ``png``: a preview's path (numbered as the output); ``bits``: of a picture output.

    Returns a :class:`FrameResult` per frame, in frame order (those left out included, with
    ``skipped``); ``report(FrameResult)`` is also called as each finishes. With a Client
    and ``wait=False``: the Dask futures of the frames (each gives (out, png, stats)) and
    nothing is reported; the frames left out are not among them."""
    from subtrace.io.formats import picture_format
    from subtrace.jobs import FrameResult, render_tiled, result_files, write_frame

    if isinstance(scene, (str, os.PathLike)):
        from subtrace.io.scene import load_scene, scene_for_meshes

        path = os.fspath(scene)
        scene = load_scene(path) if path.lower().endswith(".toml") else scene_for_meshes([path])
    out = output or scene.output or "render.exr"
    picture = picture_format(out)
    if crop is not None:
        from subtrace.tiles import check_crop

        crop = check_crop(crop, scene.camera.width, scene.camera.height)
    if tile is not None:
        from subtrace.tiles import check_tile

        tile = check_tile(tile)
        if crop is not None:
            raise SceneError("--crop renders one tile: leave out --tile", key="--tile")
    if resume and turntable is None and frames is None:
        raise SceneError("it leaves out frames already rendered: give --turntable N (or "
                         "--frames of a USD stage)", key="--resume")
    jobs, cages = frame_scenes(scene, turntable, frames, out, png)
    results = {}
    if resume:
        for k, _, out_k, png_k in jobs:
            if is_complete(out_k) and (not png_k or is_complete(png_k)):
                results[k] = FrameResult(k, out_k, png_k, skipped=True)
        jobs = [j for j in jobs if j[0] not in results]
    if dask is not False:
        from subtrace.cluster import run_jobs

        if not wait and not _is_client(dask):
            raise ValueError("wait=False needs dask=<a distributed.Client> to hold the futures")
        futures = run_jobs(dask, jobs, crop, tile, picture, bits, accel,
                           report=None if not wait else
                           lambda f: _done(results, f, report), wait=wait)
        if not wait:
            return futures
    else:
        from subtrace.render import render_scene

        for k, scene_k, out_k, png_k in jobs:
            if tile is not None:
                result = render_tiled(scene_k, tile, cages=cages, threads=threads,
                                      accel=accel, progress=progress)
            else:
                result = render_scene(scene_k, cages=cages, threads=threads, accel=accel,
                                      progress=progress, crop=crop)
            took = write_frame(out_k, png_k, picture, bits, result.channels,
                               result_files(result, scene_k), scene_k.render.transparent)
            _done(results, FrameResult(k, out_k, png_k, dataclasses.asdict(result.stats),
                                       result=result, time_write=took), report)
    return [results[k] for k in sorted(results, key=lambda k: -1 if k is None else k)]


def _done(results, frame: FrameResult, report) -> None:
    results[frame.frame] = frame
    if report is not None:
        report(frame)


def _is_client(dask) -> bool:
    try:
        from distributed import Client
    except ImportError:
        return False
    return isinstance(dask, Client)


__all__ = ["parse_frames", "frame_path", "turntable_eye", "check_turntable", "render_frames",
           "is_complete", "frame_numbers", "stage_frames", "scene_at_time", "usd_stages"]
