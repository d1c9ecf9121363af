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
        scene = scene_for_meshes(inputs, scheme=args.scheme)
    else:
        raise SceneError("give one TOML scene, or OBJ cages, not both")
    vec = lambda v: None if v is None else " ".join(v)  # noqa: E731
    return apply_overrides(
        scene, width=args.width, height=args.height, fov=args.fov, eye=vec(args.eye),
        target=vec(args.target), up=vec(args.up), scheme=args.scheme,
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
                              samples=args.samples)
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
    check_writable(out)
    if png:
        check_writable(png)
    # imported once the inputs are checked: bad input fails before the renderer's kernels
    # and OpenImageIO load
    from subtrace.io.exr import write_exr, write_picture, write_png
    from subtrace.render import render_scene, result_attributes

    trim_numba(args)
    progress = ProgressBar() if sys.stderr.isatty() and not args.quiet else None
    result = render_scene(scene, threads=args.threads, accel=args.accel, progress=progress)
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
    return 0


def _summary(out, png, result, time_write: float) -> str:
    """The line ``subtrace render`` prints: size, tolerance, coverage, refinement, times."""
    st = result.stats
    cam = result.camera
    return (
        f"{out}: {cam.width}x{cam.height}, tolerance "
        f"{result.tolerance_rad / cam.pixel_angle():.3g} px, {st.pixels_covered} pixels "
        f"covered; {st.patches_refined} of {st.patches} patches refined, "
        f"{st.micro_triangles} micro-triangles, deepest level {st.max_level}; "
        f"total {st.time_total:.3f} s (load {st.time_load:.3f}, preprocess "
        f"{st.time_preprocess:.3f}, refine {st.time_refine:.3f}, trace {st.time_trace:.3f}, "
        f"shade {st.time_shade:.3f}, write {time_write:.3f})"
        + (f"; preview {png}" if png else "")
    )
