"""``subtrace render [SCENE.toml | CAGE.obj ...]``: render a scene to EXR (and PNG), and
the scene the render and sweep commands build from their inputs and options
(:func:`scene_from_inputs`).
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import replace

import numpy as np

from subtrace.cli.common import trim_numba
from subtrace.data import default_scene_path
from subtrace.errors import SceneError
from subtrace.frames import check_turntable, frame_path, parse_frames, turntable_eye
from subtrace.io.atomic import check_writable
from subtrace.io.formats import DEEP, picture_format
from subtrace.io.scene import DEFAULT_SAMPLES, apply_overrides, load_scene, scene_for_meshes
from subtrace.runtime.progress import ProgressBar


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
    frames = None
    if turntable is not None:
        n = check_turntable(turntable)
        frames = [(k, frame_path(out, k), png and frame_path(png, k))
                  for k in parse_frames(args.frames, n)]
    elif getattr(args, "frames", None) is not None:
        raise SceneError("--frames picks frames of a camera path: give --turntable N",
                         key="--frames")
    elif getattr(args, "dask", None) is not None:
        raise SceneError("--dask renders frames on a cluster: give --turntable N", key="--dask")
    for path in [out, png] if frames is None else [p for _, o, g in frames for p in (o, g)]:
        if path:
            check_writable(path)
    # imported once the inputs are checked: bad input fails before the renderer's kernels
    # and OpenImageIO load
    from subtrace.render import render_scene

    trim_numba(args)
    progress = ProgressBar() if sys.stderr.isatty() and not args.quiet else None
    if frames is None:
        result = render_scene(scene, threads=args.threads, accel=args.accel, progress=progress)
        _write(args, scene, result, out, png, picture, bits)
        return 0
    from subtrace.nurbs.scene import has_surfaces, load_nurbs
    from subtrace.render import load_objects, scene_bounds

    cages = load_objects(scene)  # once for every frame
    camera = scene.make_camera(*scene_bounds(cages, load_nurbs(scene)))
    if any(has_surfaces(o.mesh) for o in scene.objects):
        cages = None  # (a render given cages leaves free-form surfaces out: each frame reads)
    scenes = [apply_overrides(scene, target=tuple(camera.target), up=tuple(camera.up),
                              fov=camera.fov_deg, eye=turntable_eye(camera.eye, camera.target,
                                                                    camera.up, k, n))
              for k, _, _ in frames]
    if getattr(args, "dask", None) is not None:
        from subtrace.cluster import run_frames

        def report(out_k, png_k, stats):
            if not args.quiet:
                print(f"{out_k}: {stats['pixels_covered']} pixels covered, render "
                      f"{stats['time_total']:.3f} s" + (f"; preview {png_k}" if png_k else ""))

        run_frames(args.dask or None, [(sc, o, g, picture, bits)
                                       for sc, (_, o, g) in zip(scenes, frames)],
                   args.accel, report)
        return 0
    for scene_k, (_, out_k, png_k) in zip(scenes, frames):
        result = render_scene(scene_k, cages=cages, threads=args.threads, accel=args.accel,
                              progress=progress)
        _write(args, scene_k, result, out_k, png_k, picture, bits)
    return 0


def _write(args, scene, result, out, png, picture, bits) -> None:
    """Write one render's EXR (or picture) and preview; print its summary line."""
    from subtrace.io.exr import write_exr, write_picture, write_png
    from subtrace.render import result_attributes

    t0 = time.perf_counter()
    if picture is None:
        write_exr(out, result.channels, result_attributes(result, scene), png_path=png)
    else:
        ch = result.channels
        if not scene.render.transparent:  # opaque: the colour over the background
            ch = {c: ch[c] for c in "RGB"}
        write_picture(out, ch, bits)
        if png:
            ch = result.channels
            write_png(png, np.stack([ch["R"], ch["G"], ch["B"]], axis=-1))
    if not args.quiet:
        print(_summary(out, png, result, time.perf_counter() - t0))


def _summary(out, png, result, time_write: float) -> str:
    """The line ``subtrace render`` prints: size, tolerance, coverage, refinement, times.
    The render time is the header's ``subtrace:time_total`` (load to shade; the header is
    written before the write ends); the total adds the write."""
    st = result.stats
    cam = result.camera
    return (
        f"{out}: {cam.width}x{cam.height}, tolerance "
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
