"""Rendering: orchestration only (the maths lives in patches/, accel/, trace/, lights.py,
shade.py).

``render_scene(scene)`` runs the stages in turn:

1. **prepare** (``prepare.py``): the cages loaded and checked, the camera framed, the patch
   table of the cage faces that can reach the image (primary or secondary rays: the cull
   to the view), the budget, where secondary rays start;
2. **trace** (``trace/rounds.py``): the depths, the shells' projection or BVH, then rounds
   of ``trace.kernels.trace_round``, building between rounds what rays asked for, until
   no ray asks; patches no ray reaches before a closer hit are never refined;
3. **shade** (``shade.py``): the hits into image channels; the free-form (trimmed NURBS)
   surfaces' pass (:func:`subtrace.nurbs.scene.nurbs_pass`) overwrites a pixel's channels
   where its hit is nearer;
4. **picture** (``picture.py``): shadows, ambient occlusion, lighting, the background and
   the ground, anti-aliasing;
5. **sink**: the channels handed over (or kept for the result).

There is one output pipeline (:func:`_paint_bands`): the image goes through it in bands of
rows when a ``sink`` streams it (``subtrace render`` of an EXR: ``io.exr.ExrBands``; its
channels are never held whole), else as one band (the whole image, or a crop's window).
Each band is shaded and painted as the window of ``prepare.crop_window`` around it (the
rows its anti-aliasing and smoothed occlusion read). The trace's set-up is the whole
image's, once; its rays are traced for the whole image, or, for a streamed image of more
than ``config.STREAM_TRACE_PIXELS`` or cages of ``config.STREAM_TRACE_FACES`` faces and
more, band by band, so that the hit records are a band's too.
"""

from __future__ import annotations

import time
from types import SimpleNamespace

import numpy as np

from subtrace import config
from subtrace.camera import whole_image
from subtrace.errors import SceneError
from subtrace.nurbs.scene import load_nurbs, nurbs_pass, picture_hits, with_surfaces
from subtrace.picture import ground_plane, lit_in_shading, paint
# (the first stage's names, which callers take from here too)
from subtrace.prepare import (apron, cage_objects, check_extent, crop_window,  # noqa: F401
                              faces_in_view, load_objects, prepare, scene_bounds,
                              table_in_view)
# (what a render returns, which callers take from here too)
from subtrace.results import RenderResult, RenderStats, result_attributes  # noqa: F401
from subtrace.runtime import threads as tasks
from subtrace.runtime.memory import let_go, one_block
from subtrace.shade import (C_OBJECT, C_R, CHANNELS, background_rows, deepest_level,
                            miss_values, patch_shading, shade)
from subtrace.startup import warmup
from subtrace.textures import texture_hits, texture_sets
from subtrace.tiles import check_crop
from subtrace.trace.pools import Hits, round_arrays
# (the trace's rounds, which callers take from here too)
from subtrace.trace.rounds import trace_hits, trace_setup, trace_window  # noqa: F401


def _threads_and_accel(threads, accel) -> str:
    """Set the render's threads up (``runtime.threads``); the acceleration ``accel``
    checked (SceneError naming --accel), its default filled in."""
    threads = tasks.usable_threads(threads)
    accel = config.PRIMARY_ACCEL if accel is None else accel
    if accel not in ("projection", "bvh"):
        raise SceneError(f"expected projection or bvh, got {accel!r}", key="--accel")
    tasks.set_threads(threads)
    return accel


def render_scene(scene, cages=None, threads=None, progress=None, accel=None,
                 crop=None, sink=None, band_rows=None, trace_bands=None) -> RenderResult:
    """Render a :class:`subtrace.io.scene.Scene`; returns the channels and statistics.
    ``accel``: how rays find the shells they enter (see :func:`trace_hits`). ``progress``:
    None, or called as ``progress(done, total, label)`` with the rays whose hits are final
    out of all (e.g. :class:`subtrace.runtime.progress.ProgressBar`); it reaches
    done == total. ``cages``: the scene's cages already loaded (its free-form surfaces are
    then not rendered); None: loaded here, with the free-form surfaces of its OBJ files.
    ``crop``: (x0, y0, x1, y1), a tile of the image (pixels, x1 and y1 excluded): only the
    rays of its :func:`crop_window` are traced and the channels are the tile's, equal bit
    for bit to those pixels of the whole render (the camera, tolerance, patch table, depths
    and projection lists are the whole image's; the per-pixel arrays are the window's, and
    the memory budget holds them: where the whole image's pixels would make the budget cap
    depths (a warning says so), its tiles, needing less, may be refined further).
    ``sink``: None (the result holds the channels), or ``sink(y0, y1, channels)``, told
    the image's rows [y0, y1) (name -> (y1 - y0, W) float32 views, valid during the call)
    band after band, top to bottom (:func:`render_bands`; ``band_rows``: their height;
    ``trace_bands``: whether the rays are traced band by band too, None: for an image of
    more than ``config.STREAM_TRACE_PIXELS`` or cages of at least
    ``config.STREAM_TRACE_FACES`` faces): the result's channels are then empty. Only
    a whole image of cages is rendered in bands (a crop, or free-form surfaces, go to the
    sink as one band)."""
    t_start = time.perf_counter()
    accel = _threads_and_accel(threads, accel)
    stats = RenderStats()
    compiling = warmup.start(tasks.thread_count())  # on a cold cache only
    try:
        owners = cage_objects(scene) if cages is None else list(range(len(cages)))
        nurbs = load_nurbs(scene) if cages is None else None  # free-form surfaces
        cages, table, camera, view, tol_rad, budget, seen = prepare(scene, cages, stats, nurbs,
                                                                    crop, compiling)
        if compiling is None and table is not None:  # the kernel for other schemes only
            compiling = warmup.start_for(tasks.thread_count(), [c.scheme for c in cages])
        if crop is not None:
            crop = check_crop(crop, camera.width, camera.height)
        if progress is not None:
            progress(0, stats.rays, "tracing")
        # streamed in bands: a whole image of cages; else one band
        banded = sink is not None and table is not None and nurbs is None and crop is None
        if trace_bands is None:
            trace_bands = (view.width * view.height > config.STREAM_TRACE_PIXELS
                           or sum(c.n_faces for c in cages) >= config.STREAM_TRACE_FACES)
        shared = None
        if table is None:
            warmup.stop(compiling)  # no cage: the subdivision kernels are not needed
        else:
            shared = trace_setup(table, view, tol_rad, stats, compiling=compiling, accel=accel,
                                 max_memory=budget, seen=seen, windows=banded and trace_bands)
        job = SimpleNamespace(scene=scene, cages=cages, owners=owners, nurbs=nurbs,
                              camera=camera, view=view, tol_rad=tol_rad, shared=shared,
                              stats=stats, sink=sink, compiling=compiling, progress=progress)
        bands = (_bands(camera, shared, scene, band_rows) if banded
                 else [(view, crop or (0, 0, camera.width, camera.height))])
        channels, built = _paint_bands(job, bands)
    except BaseException:
        warmup.stop(compiling)
        raise
    stats.time_total = time.perf_counter() - t_start - job.t_sink
    schemes = tuple(c.scheme for c in cages) + (("nurbs",) if nurbs is not None else ())
    used = "bvh" if stats.accel_fallback else accel
    refined = np.zeros(0, np.int32) if table is None else table.object_id[built]
    return RenderResult(channels, stats, camera, tol_rad, schemes, refined, used, crop)


def _bands(camera, shared, scene, band_rows):
    """The bands of a streamed image: (the window of ``prepare.crop_window`` each is traced,
    shaded and painted as, the pixels (x0, y0, x1, y1) of the image it hands over), in
    ``band_rows`` rows (default: about ``config.STREAM_BAND_PIXELS`` pixels,
    ``config.STREAM_TRACE_BAND_PIXELS`` when traced band by band; whole blocks of an EXR's
    lines, ``io.exr.LINES_PER_BLOCK``, and so of tiles' rows)."""
    W, H = camera.width, camera.height
    if band_rows is None:
        band_rows = (config.STREAM_TRACE_BAND_PIXELS if shared.windows
                     else config.STREAM_BAND_PIXELS) // W
    rows = int(band_rows)
    align = config.EXR_LINES_PER_BLOCK
    rows = max(align, rows - rows % align)
    margin = apron(scene)
    return [(crop_window(camera, (0, y0, W, min(H, y0 + rows)), margin),
             (0, y0, W, min(H, y0 + rows))) for y0 in range(0, H, rows)]


def _paint_bands(job, bands):
    """The one output pipeline: each band of ``bands`` (:func:`_bands`, or the image as
    one) traced (or cut from the whole image's hits), shaded, painted and handed to the
    sink; returns (the channels of a render without a sink, the patches refined). The
    bands share the depths, the projection's lists, the memos and what earlier bands built
    (``trace.rounds.SharedTrace``), so a patch is built once, and each band's pixels are
    those of a render of the whole image (the tile renders' argument: the same rays,
    depths and pieces; only the order in which a ray meets the patches built differs).
    One band's arrays serve every band."""
    scene, shared, stats, camera, nurbs = job.scene, job.shared, job.stats, job.camera, job.nurbs
    table = None if shared is None else shared.table
    patches = None if table is None else patch_shading(table, [scene.objects[k]
                                                                for k in job.owners])
    pixel_angle = whole_image(job.camera).pixel_angle()
    textures = None if table is None else texture_sets(table, [scene.objects[k]
                                                               for k in job.owners])
    lit = (None if table is None or textures is not None
           else lit_in_shading(scene, nurbs, shared.loop))
    miss = miss_values(scene.render.background)
    n_max = max(w.width * w.height for w, _ in bands)
    buffers = round_arrays(n_max) if shared is not None and shared.windows else None
    planes_store, normals_store, pix_store = one_block(
        ((len(CHANNELS) * n_max,), np.float32), ((3 * n_max,), np.float64), ((n_max,), np.int32))
    covered = np.zeros(tasks.thread_count(), np.int64)
    keep = {}  # what secondary rays need of the trace's pools
    whole = built = None
    if shared is not None and not shared.windows:  # the whole image's rays first
        whole = trace_window(shared, job.view.frame(), job.view.width, job.view.height,
                             job.progress, keep)
        built = shared.finish()
        shared.memos = None  # (secondary rays keep memos of their own)
    t0 = time.perf_counter()
    ground = ground_plane(scene, job.cages, camera, nurbs)
    t_shade, job.t_sink = time.perf_counter() - t0, 0.0
    channels, n_covered, max_level = {}, 0, -1
    for b, (window, (x0, y0, x1, y1)) in enumerate(bands):
        w, h = window.width, window.height
        n, frame = w * h, window.frame()
        hits = texel = None
        if whole is not None:  # (the band's rows of the whole image's hits)
            a = 0 if window is job.view else window.y0 * w
            hits = whole if len(bands) == 1 else Hits(*(f[a:a + n] for f in whole))
        elif shared is not None:
            hits = trace_window(shared, frame, w, h, _band_progress(job, y0, y1, h), keep,
                                buffers)
        t0 = time.perf_counter()
        planes = planes_store[:len(CHANNELS) * n].reshape(len(CHANNELS), n)
        normals, pix_patch = normals_store[:3 * n].reshape(n, 3), pix_store[:n]
        if hits is None:  # free-form surfaces only: the background, then the NURBS pass
            t = _background(scene, window, camera.height, miss, planes, pix_patch)
        else:
            _shade_hits(frame, w, hits, shared.iso, patches, miss, planes, normals, pix_patch,
                        covered, job.owners, shared.loop, lit, table)
            texel = texture_hits(textures, table, hits, shared.iso.view(), patches, frame, w,
                                 None, pixel_angle, normals, planes)
            # each pixel's hit distance for the picture (the NURBS pass writes its nearer
            # hits into a copy); one band: the rest of the hit records (one block with the
            # rounds' requests, 40 bytes a ray) is given back before the picture's arrays
            t = hits.t if nurbs is None else hits.t.copy()
            if hits is whole:
                let_go(hits[1:])
                hits = whole = None
        band_patches, offset = patches, 0
        if nurbs is not None:
            t_trace = stats.time_trace
            t, band_patches, offset = _nurbs_hits(scene, nurbs, frame, w, h, job.tol_rad,
                                                  table, t, normals, pix_patch, patches, planes,
                                                  stats)
            t0 += stats.time_trace - t_trace  # (the NURBS pass counts as trace)
            if job.progress is not None and table is None:
                job.progress(stats.rays, stats.rays, "NURBS")
        if b == 0:
            _picture_kernels(job.compiling, keep)
        paint(scene, job.cages, window, keep, t, normals, pix_patch, band_patches, planes,
              stats, nurbs, offset, ground=ground, lit=lit is not None, textures=textures,
              texel=texel)
        wx0, wy0 = getattr(window, "x0", 0), getattr(window, "y0", 0)
        band = planes.reshape(len(CHANNELS), h, w)[:, y0 - wy0:y1 - wy0, x0 - wx0:x1 - wx0]
        # (a pixel whose centre ray missed but an anti-aliasing ray hit is covered too)
        n_covered += int(np.count_nonzero(band[C_OBJECT] >= 0))
        max_level = max(max_level, deepest_level(band))
        channels = {name: np.ascontiguousarray(band[k]) for k, name in enumerate(CHANNELS)}
        t_shade += time.perf_counter() - t0
        if job.sink is not None:
            t0 = time.perf_counter()
            job.sink(y0, y1, channels)
            channels = {}
            job.t_sink += time.perf_counter() - t0
    stats.time_shade = t_shade
    stats.pixels_covered, stats.max_level = n_covered, max_level
    if shared is None:
        return channels, np.zeros(0, np.int64)
    return channels, shared.finish() if built is None else built


def _band_progress(job, y0, y1, h):
    """A band's rounds' progress, as the image's rays final (None without progress)."""
    if job.progress is None:
        return None
    W, H = job.camera.width, job.camera.height
    return lambda done, total, label: job.progress(W * y0 + done * (y1 - y0) // max(h, 1),
                                                   W * H, label)


def _shade_hits(frame, width, hits, iso, patches, miss, planes, normals, pix_patch, covered,
                owners, loop, lit=None, table=None):
    """``shade.shade`` the hits into ``planes`` (and ``normals``, ``pix_patch``,
    ``covered``; their colour too with ``lit``, ``picture.lit_in_shading``); the object ids
    made the scene's (``owners``: the scene index of each cage's object,
    :func:`cage_objects`)."""
    shade(frame, width, hits, iso.view(), patches, miss, planes, normals, pix_patch, covered,
          loop=loop, lit=lit, table=table)
    if owners != list(range(len(owners))):  # objects without a cage: scene indices
        hit = planes[C_OBJECT] >= 0
        index = planes[C_OBJECT][hit].astype(np.int64)
        planes[C_OBJECT][hit] = np.array(owners, np.float32)[index]


def _picture_kernels(compiling, keep) -> None:
    """Wait for the picture's kernels a helper compiled while the rays were traced (a cold
    cache: ``warmup.compile_picture``); the secondary rays' BVH build compiles here
    meanwhile."""
    if compiling is not None and compiling.procs and keep:
        warmup.compile_bvh()
    warmup.wait(compiling)


def _background(scene, view, image_height, miss, planes, pix_patch):
    """``planes`` of a render without cages before the NURBS pass: every ray missed (the
    background's rows of the image's gradient); returns their distances (inf)."""
    planes[:] = miss[:, None]
    y0 = getattr(view, "y0", 0)  # (a window's rows of the image's gradient)
    rows = background_rows(scene.render.background, scene.render.background_bottom,
                           image_height)[y0:y0 + view.height]
    for k in range(3):
        planes[C_R + k] = np.repeat(rows[:, k], view.width)
    pix_patch[:] = -1
    return np.full(view.width * view.height, np.inf)


def _nurbs_hits(scene, nurbs, frame, W, H, tol_rad, table, t, normals, pix_patch, patches,
                planes, stats):
    """The free-form surfaces' pass (``nurbs.scene.nurbs_pass``: every channel of the
    pixels where they are nearer than ``t``), handed to the picture as hits of their own
    rows of the patch shading (``nurbs.scene.picture_hits``): (t, patches, offset of the
    surfaces' rows)."""
    nh = nurbs_pass(nurbs, frame, W, H, tol_rad, None if table is None else t, planes, stats)
    patches, offset = with_surfaces(nurbs, patches)
    picture_hits(nurbs, nh, frame, W, offset, t, normals, pix_patch)
    return t, patches, offset
