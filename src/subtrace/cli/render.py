"""``subtrace render [SCENE.toml | CAGE.obj ...]``: render a scene to EXR (and PNG), and
the scene the render and sweep commands build from their inputs and options
(:func:`scene_from_inputs`).
"""

from __future__ import annotations

import contextlib
import os
import sys
from dataclasses import replace

from subtrace.cli.common import set_up_numba
from subtrace.data import default_scene_path
from subtrace.errors import SceneError
from subtrace.frames import frame_numbers, frame_path
from subtrace.io.formats import DEEP, picture_format
from subtrace.io.scene import DEFAULT_SAMPLES, apply_overrides, load_scene, scene_for_meshes
from subtrace.lights import parse_light_flag
from subtrace.runtime.atomic import check_writable
from subtrace.runtime.progress import ProgressBar
from subtrace.tiles import check_crop, check_tile


def scene_from_inputs(inputs, args, **overrides):
    """The scene of ``inputs`` (one TOML scene, or OBJ cages; none: the built-in default
    scene) with the camera / resolution / scheme flags of ``args`` and ``overrides``
    (further :func:`subtrace.io.scene.apply_overrides` keywords) applied."""
    if not inputs:
        scene = load_scene(default_scene_path())
    elif len(inputs) == 1 and inputs[0].lower().endswith(".toml"):
        scene = load_scene(inputs[0])
    elif all(not p.lower().endswith(".toml") for p in inputs):
        scene = scene_for_meshes(inputs, scheme=args.scheme,
                                 camera=getattr(args, "camera", None))
    else:
        raise SceneError("give one TOML scene, or OBJ cages, not both")
    vec = lambda v: None if v is None else " ".join(v)
    return apply_overrides(
        scene, width=args.width, height=args.height, fov=args.fov, eye=vec(args.eye),
        target=vec(args.target), up=vec(args.up), scheme=args.scheme,
        boundary=getattr(args, "boundary", None),
        max_memory=getattr(args, "max_memory", None), **overrides,
    )


def execute(args) -> int:
    """Render, write the EXR (and preview) and print a one-line summary."""
    inputs = list(args.inputs)
    # the default scene lives in the package: write into the working directory
    if not inputs and args.output is None:
        args.output = "render.exr"
    scene = scene_from_inputs(inputs, args, tolerance=args.tolerance,
                              tolerance_deg=args.tolerance_deg, output=args.output,
                              color=args.color, background=args.background,
                              shadows=args.shadows, transparent=args.transparent,
                              samples=args.samples, ao=getattr(args, "ao", None))
    if getattr(args, "light", None):  # (--light: these lights instead of the scene's)
        scene = replace(scene, lights=tuple(parse_light_flag(t) for t in args.light))
    if scene.render.samples is None:  # neither the scene nor --samples: the default
        scene = replace(scene, render=replace(scene.render, samples=DEFAULT_SAMPLES))
    out = scene.output or "render.exr"
    picture = picture_format(out)
    bits = int(getattr(args, "bit_depth", "8"))
    if bits == 16 and picture not in DEEP:
        raise SceneError(f"{out}: 16 bits per channel are for .png and .tif outputs",
                         key="--bit-depth")
    png = os.path.splitext(out)[0] + ".png" if args.png else scene.preview
    if png and os.path.abspath(png) == os.path.abspath(out):
        png = None  # the output is that picture already: --png never writes over it
    turntable = getattr(args, "turntable", None)
    crop = getattr(args, "crop", None)
    if crop is not None:
        crop = check_crop(crop, scene.camera.width, scene.camera.height)
    tile = getattr(args, "tile", None)
    dask = getattr(args, "dask", None)
    resume = getattr(args, "resume", False)
    if tile is not None:
        tile = check_tile(tile)
        if crop is not None:
            raise SceneError("--crop renders one tile: leave out --tile", key="--tile")
    numbers = frame_numbers(scene, turntable, getattr(args, "frames", None))
    if numbers is not None:
        paths = [p for k in numbers for p in (frame_path(out, k), png and frame_path(png, k))]
    elif resume:
        raise SceneError("it leaves out frames already rendered: give --turntable N (or "
                         "--frames of a USD stage)", key="--resume")
    elif dask is not None and tile is None:
        raise SceneError("its tasks are frames or tiles: give --turntable N, --frames of a "
                         "USD stage, or --tile N", key="--dask")
    else:
        paths = [out, png]
    for path in paths:
        if path:
            check_writable(path)
    # imported once the inputs are checked: bad input fails before the renderer's kernels
    # and OpenImageIO load (Numba set up first: its runtime starts while the renderer's
    # modules import)
    set_up_numba(args)
    import subtrace.render  # noqa: F401  (the modules whose kernels a render loads)

    # (a process of its own: the kernels the last render of this kind loaded, loaded ahead
    # from the moment the render starts)
    ahead = contextlib.nullcontext
    if getattr(args, "own_process", False):
        from subtrace.startup import preload

        key = preload.render_key(scene, args.accel, picture, crop is not None,
                                 numbers is not None, tile is not None, dask is not None)
        ahead = lambda: preload.loading(key)  # noqa: E731
    _render(args, scene, out, png, picture, bits, crop, tile, dask, resume, numbers,
            turntable, ahead)
    return 0


def _render(args, scene, out, png, picture, bits, crop, tile, dask, resume, numbers,
            turntable, ahead) -> None:
    """The render(s) of :func:`execute`, their files written and summaries printed;
    ``ahead()``: the context the renders run in (:func:`subtrace.startup.preload.loading`,
    or none)."""
    from subtrace.render import render_scene

    progress = ProgressBar() if sys.stderr.isatty() and not args.quiet else None
    if numbers is None and tile is None and dask is None:
        if picture is None and crop is None:  # an EXR of the whole image: streamed
            _render_streamed(args, scene, out, png, progress, ahead)
            return
        with ahead():
            result = render_scene(scene, threads=args.threads, accel=args.accel,
                                  progress=progress, crop=crop)
        _write(args, scene, result, out, png, picture, bits)
        return
    from subtrace.frames import render_frames

    def report(frame):
        if args.quiet:
            return
        if frame.result is not None:
            print(_summary(frame.path, frame.preview, frame.result, frame.time_write))
        else:
            print(f"{frame.path}: {frame.stats['pixels_covered']} pixels covered, render "
                  f"{frame.stats['time_total']:.3f} s"
                  + (f"; preview {frame.preview}" if frame.preview else ""))

    with ahead():
        done = render_frames(scene, out, turntable=turntable, frames=args.frames, crop=crop,
                             tile=tile, dask=False if dask is None else (dask or None),
                             resume=resume, png=png, bits=bits, threads=args.threads,
                             accel=args.accel, progress=progress, report=report)
    skipped = sum(f.skipped for f in done)
    if resume and not args.quiet:
        print(f"--resume: {skipped} of {len(done)} frames already there, left out")


def _write(args, scene, result, out, png, picture, bits) -> None:
    """Write one render's EXR (or picture; a tile's as its data window) and preview; print
    its summary line."""
    from subtrace.jobs import result_files, write_frame

    took = write_frame(out, png, picture, bits, result.channels, result_files(result, scene),
                       scene.render.transparent)
    if not args.quiet:
        print(_summary(out, png, result, took))


def _render_streamed(args, scene, out, png, progress, ahead) -> None:
    """Render the whole image in bands (``render.render_scene(sink=...)``), each encoded
    into the EXR as it is done (``io.exr.ExrBands``), so that neither the image's per-pixel
    arrays nor its channels are held at once; write the file and print its summary line.
    The write time is the bands' encoding and the file's writing."""
    from subtrace.io.exr import ExrBands
    from subtrace.jobs import result_files
    from subtrace.render import render_scene

    exr = ExrBands(out, scene.camera.width, scene.camera.height, png)
    with ahead():
        result = render_scene(scene, threads=args.threads, accel=args.accel,
                              progress=progress, sink=exr.write)
    exr.finish(result_files(result, scene))
    if not args.quiet:
        print(_summary(out, png, result, exr.seconds))


def _summary(out, png, result, time_write: float) -> str:
    """The line ``subtrace render`` prints: size, tolerance, coverage, refinement, times.
    The render time is the header's ``subtrace:time_total`` (load to shade; the header is
    written before the write ends); the total adds the write."""
    st = result.stats
    cam = result.camera
    size = f"{cam.width}x{cam.height}"
    if result.crop is not None:
        x0, y0, x1, y1 = result.crop
        size = f"columns {x0}..{x1 - 1}, rows {y0}..{y1 - 1} of {size}"
    return (
        f"{out}: {size}, tolerance "
        f"{result.tolerance_rad / cam.pixel_angle():.3g} px, {st.pixels_covered} pixels "
        f"covered; {st.patches_refined} of {st.patches} patches refined, "
        f"{st.micro_triangles} micro-triangles, deepest level {st.max_level}"
        + (f" (secondary rays' deepest grid {st.secondary_max_depth})"
           if st.secondary_max_depth >= 0 else "") + "; "
        f"render {st.time_total:.3f} s (load {st.time_load:.3f}, preprocess "
        f"{st.time_preprocess:.3f}, refine {st.time_refine:.3f}, trace {st.time_trace:.3f}, "
        f"shade {st.time_shade:.3f}) + write {time_write:.3f} s = total "
        f"{st.time_total + time_write:.3f} s"
        + (f"; preview {png}" if png else "")
    )
