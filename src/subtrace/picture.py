"""The picture: the colour of every pixel once the primary hits are shaded (orchestration
over ``shade.py`` and ``aggregate.py``; no kernels here).

Every secondary ray (shadow, ambient occlusion, extra anti-aliasing and reflected rays)
meets the scene through one aggregate of the cages and the free-form surfaces
(``aggregate.SceneAggregate``: ``occluded`` for any-hit rays, ``closest`` for the others).
``paint`` adds to the planes of ``shade.shade`` (which hold every channel but the colour):

* shadow rays from every hit towards each light (``[render] shadows``, on by default;
  ``shade.shadow_visibility``), as any-hit rays (the aggregate's ``occluded``) through the
  BVH of the shells (``trace/rays.py``) and then, for those no cage blocks, through the
  free-form surfaces' (``nurbs.scene.blocked``, with the ray's cone: its pixel's footprint
  at the hit it leaves);
* ambient occlusion (``[render] ao`` / ``--ao N``, off by default): N cosine-weighted
  any-hit rays from every hit (``shade.ambient_occlusion``) reaching ``config.AO_DISTANCE``
  of the diagonal of the scene's control points; the share that escapes scales the
  diffuse lighting, and the ground's (``shade.ground_occlusion``: rays over the up
  hemisphere from its points near the objects);
* the lighting (``shade.light``: Lambert plus the materials' Blinn-Phong lobe);
* the background (a colour or a vertical gradient) and the ground (``[ground]``);
* adaptive anti-aliasing (``[render] samples`` / ``--samples N``; the API's default is one
  ray per pixel, the command line's ``io.scene.DEFAULT_SAMPLES``): every pixel keeps its
  centre ray, which writes depth, normal, ids, level, (u, v) and position wherever it hit,
  so regression comparisons stay exact; a pixel that differs from a neighbour (coverage, object, a depth
  step, a normal jump, a contrast in the displayed colour: :func:`edge_pixels`) gets N - 1
  more rays at fixed stratified positions in its square (:func:`sample_offsets`), traced
  like any secondary ray (refined by the same angular criterion, at the depths chosen for
  the camera: an extra ray's footprint is the pixel's), shaded, shadowed and lit like
  centre rays. Its colour and alpha are the box-filtered mean of its N rays. Where the
  centre ray missed but others hit, the other channels are those of the nearest extra ray
  that hit (:func:`_nearest_hit`): a pixel of alpha above 0 has a depth and ids.

The free-form (NURBS) surfaces' pixels take part in every step as the cages' do: they are
hits of their own rows of the patch shading (``nurbs.scene.with_surfaces``), and the extra
anti-aliasing rays trace them too (the aggregate's ``closest``: ``nurbs.scene.shade_rays``).

Every step writes disjoint pixels or rays in a fixed order, so the picture does not depend
on the thread count.
"""

from __future__ import annotations

import time
from types import SimpleNamespace

import numpy as np

from subtrace.accel.bvh import build_bvh
from subtrace.accel.cull import casting_bounds
from subtrace.aggregate import SceneAggregate
from subtrace.camera import whole_image, window_offset
from subtrace.mesh.cage import lowest_limit
from subtrace.reflect import mirror_pass, reflects
from subtrace.runtime import threads as tasks
from subtrace import config
from subtrace.lights import DIRECTIONAL, R2_A1, R2_A2, light_array, ray_keys, sampled
from subtrace.shade import (C_A, C_R, C_Z, ambient_occlusion, background_pixels,
                            background_rows, edge_pixels, ground_occlusion, ground_pixels,
                            ground_points, light, miss_values, shadow_visibility,
                            smooth_occlusion)
from subtrace.trace.pools import Memos
from subtrace.trace.rays import Pools

# the R2 sequence's steps (the plastic number's powers): well-spread points in a square
_R2 = (R2_A1, R2_A2)


def sample_offsets(samples: int) -> np.ndarray:
    """(samples - 1, 2) float64: the extra rays' (row, col) offsets from a pixel's centre,
    in (-0.5, 0.5): points 1.. of the R2 low-discrepancy sequence started at the centre
    (point 0), so every prefix is spread evenly over the pixel and the centre ray is one of
    the samples. Fixed: the same for every pixel and run."""
    k = np.arange(1, samples, dtype=np.float64)[:, None]
    return np.mod(0.5 + k * np.asarray(_R2), 1.0) - 0.5


def _pools(keep, stats) -> Pools:
    """The primary trace's pools for secondary rays (the BVH of the shells built here when
    primary rays used the projection). What secondary rays build is counted apart
    (:func:`_count_secondary`), so the primary counts mean what they meant."""
    t0 = time.perf_counter()
    if not len(keep["bvh"].node_first):
        keep["bvh"] = build_bvh(keep["shell_min"], keep["shell_max"])
    if "memos" not in keep:  # (one set for every band of the image: trace.rays.Pools)
        keep["memos"] = Memos(tasks.thread_count(), keep["memo_bytes"])
        keep["grids"] = {}  # (the parallel rays' grids, made once: the shells are the image's)
    stats.time_preprocess += time.perf_counter() - t0
    side = SimpleNamespace(pieces=0, micro_triangles=0, grid_points=0, patches_refined=0,
                           max_depth=-1)
    return Pools(**dict(keep, stats=side))


def _count_secondary(pools, stats) -> None:
    """The patches and micro-triangles secondary rays built, into ``stats``."""
    if pools is not None:  # (added up over the bands of an image: render._paint_bands)
        stats.secondary_patches_refined += pools.stats.patches_refined
        stats.secondary_micro_triangles += pools.stats.micro_triangles
        stats.secondary_max_depth = max(stats.secondary_max_depth, pools.stats.max_depth)


def paint(scene, cages, camera, keep, t, normals, pix_patch, patches, planes, stats,
          nurbs=None, offset=0, ground=False, lit=False, textures=None, texel=None):
    """Fill the colour (R, G, B) and, with anti-aliasing, filter colour and alpha of
    ``planes`` (len(CHANNELS), W*H) float32, whose other channels :func:`shade.shade` (and
    the NURBS pass) wrote; ``t`` (W*H,) float64 each pixel's hit distance (inf: none);
    ``normals``, ``pix_patch``: its eye-facing normals and patches (the free-form surfaces'
    rows of ``patches`` from ``offset``: ``nurbs.scene.with_surfaces``); ``patches``: the
    :class:`shade.PatchShading`; ``keep``: what ``trace.rounds.trace_hits`` kept for secondary
    rays (empty: no cage); ``nurbs``: the free-form surfaces (None: none), which cast
    shadows, occlude and take extra rays too. ``lit``: the shading pass coloured the hits
    already (:func:`lit_in_shading`). ``textures``: the patches' textures
    (``textures.texture_sets``; None: none) and ``texel`` the centre rays' colours of them
    (``textures.texture_hits``). Counts and times go to ``stats``."""
    W, H = camera.width, camera.height
    frame = camera.frame()
    samples = scene.render.samples or 1
    lights = light_array(scene.lights)
    shadows = bool(len(lights)) and scene.render.shadows
    tol_rad = keep["tol_rad"] if keep else scene.render.tolerance_rad(whole_image(camera))
    mirror = reflects(patches)  # (a material reflects: subtrace.reflect)
    pools = (_pools(keep, stats) if keep and (shadows or samples > 1 or scene.render.ao > 0
                                              or mirror) else None)
    image = whole_image(camera)  # (a window's pixels are its image's: rows, AO patterns)
    world = SceneAggregate(pools, nurbs, frame, tol_rad, patches, offset,
                           miss_values(scene.render.background), textures,
                           image.pixel_angle())

    def trace_shadows(origins, dirs, tmax):
        """Any-hit shadow rays: blocked (n,) uint8 (none without shadows)."""
        if not shadows:
            return np.zeros(len(tmax), np.uint8)
        t0 = time.perf_counter()
        blocked = world.occluded(origins, dirs, tmax)
        stats.time_shadows += time.perf_counter() - t0
        stats.shadow_rays += len(tmax)
        return blocked

    trace_shadows.bounds = world.bounds  # (for the ground: :func:`shade.ground_pixels`)

    def trace_ao(origins, dirs, tmax):
        """Any-hit ambient occlusion rays: blocked (n,) uint8."""
        t0 = time.perf_counter()
        blocked = world.occluded(origins, dirs, tmax)
        stats.time_ao += time.perf_counter() - t0
        stats.ao_rays += len(tmax)
        return blocked

    trace_ao.bounds = world.bounds  # (for the ground: :func:`shade.ground_occlusion`)

    lo, hi = casting_bounds(cages, nurbs)
    ao = ids = keys = None
    if scene.render.ao > 0 or (shadows and sampled(lights)) or mirror:
        col0, row0 = window_offset(frame)
        row, col = np.divmod(np.arange(W * H, dtype=np.int64), W)
        ids = (row + row0) * image.width + col + col0
        # (the lights of several shadow rays per point sample them per pixel: lights.py;
        # a glossy reflection's rays too)
        keys = ray_keys(ids) if (shadows and sampled(lights)) or mirror else None
    if scene.render.ao > 0:
        ao = (trace_ao, scene.render.ao, config.AO_DISTANCE * float(np.linalg.norm(hi - lo)),
              image.width, config.AO_SMOOTH_RADIUS, image.pixel_angle())
    else:
        ids = None
    if ground is False:
        ground = ground_plane(scene, cages, camera, nurbs)
    y0 = getattr(camera, "y0", 0)
    rows = background_rows(scene.render.background, scene.render.background_bottom,
                           image.height)[y0:y0 + H]
    if texel is not None and offset:  # (the free-form surfaces' hits take no texture)
        texel[pix_patch >= offset] = -1.0
    if mirror:
        mirror = mirror_pass(scene, image, frame, W, lights, headlight_of(scene)[0], world,
                             patches, tol_rad, ground, trace_shadows, stats)
    _colour(scene, frame, W, t, normals, pix_patch, patches, planes, lights, rows,
            ground, trace_shadows, tol_rad, None, ao, ids, lit, keys, texel, mirror or None)
    if samples > 1:
        t0 = time.perf_counter()
        _antialias(scene, frame, W, image.height, world.closest, patches, planes, lights,
                   ground, trace_shadows, samples, stats, tol_rad, ao, image.width,
                   keys is not None, mirror or None)
        stats.time_aa += time.perf_counter() - t0
    _count_secondary(pools, stats)


def headlight_of(scene) -> np.ndarray:
    """(1,) float64: the headlight's intensity (0: none), as the lighting takes it."""
    r = scene.render
    return np.array([r.headlight_intensity if r.headlight else 0.0])


def lit_in_shading(scene, nurbs=None, loop=None):
    """``(lights, headlight)`` for :func:`shade.shade` to colour the hits in its own pass,
    where the colour needs nothing the shading pass lacks: no shadow rays (no lights, or
    shadows off), no ambient occlusion, no free-form surfaces (their hits come after the
    shading and are coloured with the cages'), no Loop cage (``loop``: its items' normals
    come after); else None, and :func:`paint` colours the hits."""
    if ((scene.lights and scene.render.shadows) or scene.render.ao > 0 or nurbs is not None
            or loop is not None):
        return None
    return light_array(scene.lights), headlight_of(scene)


def ground_plane(scene, cages, camera, nurbs=None):
    """(unit up, height) of the scene's ground plane, or None."""
    if scene.ground is None:
        return None
    up = np.asarray(camera.up, np.float64) / np.linalg.norm(camera.up)
    height = scene.ground.height
    if height is None:  # the objects' lowest limit point along up
        lows = [lowest_limit(c, up) for c in cages]
        if nurbs is not None:  # (the lowest corner of the box of the surfaces' patches)
            lo, hi = nurbs.bounds()
            lows.append(float(np.minimum(lo * up, hi * up).sum()))
        height = min(lows)
    return up, height


# the automatic camera frames the ground shadows of the directional lights at least this
# high above the horizon (sin of 20 degrees); a lower light's shadow reaches far, and
# framing it would leave the objects small
SHADOW_FRAMING_MIN_SIN = 0.34


def ground_shadow_points(scene, cages, points, nurbs=None) -> np.ndarray:
    """(n,3): ``points`` (of the objects' surface) projected along each directional light
    of ``scene`` that casts shadows onto its ground (:func:`ground_plane`, with the
    scene's up), where the automatic camera frames their shadows too; (0,3) without a
    ground, shadows or such lights."""
    if scene.ground is None or not scene.render.shadows or not len(points):
        return np.zeros((0, 3))
    up, height = ground_plane(scene, cages, scene.camera, nurbs)
    out = []
    for lamp in scene.lights:
        if lamp.kind != DIRECTIONAL:
            continue
        d = np.asarray(lamp.direction, np.float64)
        down = -float(d @ up) / float(np.linalg.norm(d))
        if down < SHADOW_FRAMING_MIN_SIN:
            continue
        # p + s d meets the plane x . up = height at s = (height - p . up) / (d . up)
        s = (height - points @ up) / float(d @ up)
        out.append(points + np.maximum(s, 0.0)[:, None] * d)
    return np.concatenate(out) if out else np.zeros((0, 3))


def _colour(scene, frame, width, t, normals, pix_patch, patches, planes, lights, rows,
            ground, trace_shadows, tol_rad, dirs, ao=None, ids=None, lit=False, keys=None,
            texel=None, mirror=None):
    """The colour of rays from the eye (pixel centres, or ``dirs``): shadows, ambient
    occlusion (``ao``: None, or (trace, rays per hit, distance, the image's width); ``ids``:
    each ray's key for its AO pattern, :func:`shade.ambient_occlusion`), lighting (unless
    ``lit``: the shading pass coloured the hits), the background (``rows``: per image row,
    or per ray with ``dirs``) and the ground. ``keys``: None, or each ray's key for the
    lights that sample their shadow rays (``lights.ray_keys``); ``texel``: the rays' texture
    colours (``textures.texture_hits``; None: none). ``mirror``: None, or the reflections
    (``reflect.mirror_pass``) added to the lit colour."""
    visible = np.ones((len(lights), 0), np.float32)  # (no columns: every pixel lit)
    if len(lights) and scene.render.shadows:
        visible = shadow_visibility(trace_shadows, frame, width, t, normals, pix_patch, lights,
                                    tol_rad, dirs, keys)
    occlusion = ground_ao = None
    miss = None
    if ao is not None:
        occlusion = ambient_occlusion(ao[0], frame, width, t, normals, pix_patch, ao[1], ao[2],
                                      tol_rad, dirs, ids)
        smoothed = dirs is None and ao[4] > 0  # a grid of pixels
        skip = t_ground = None
        if ground is not None:  # the ground darkens where objects stand on it or come near
            miss = np.nonzero(pix_patch < 0)[0]
            t_ground, points = ground_points(frame, width, miss, ground[0], ground[1], dirs)
            if smoothed:  # every other ground pixel, as a checkerboard of the image's
                row, col = np.divmod(miss, width)
                col0, row0 = window_offset(frame)
                skip = ((row + row0 + col + col0) & 1) == 1
            ground_ao = ground_occlusion(ao[0], t_ground, points, ground[0], ao[1], ao[2],
                                         miss if ids is None else ids[miss], skip)
        if smoothed:
            occlusion, ground_ao = _smooth(frame, width, t, normals, pix_patch, patches,
                                           occlusion, miss, ground, t_ground, ground_ao,
                                           skip, ao)
    r = scene.render
    headlight = headlight_of(scene)
    if not lit:
        light(frame, width, t, normals, pix_patch, patches, lights, headlight, visible, planes,
              dirs, occlusion, texel)
    if mirror is not None:
        mirror(t, normals, pix_patch, planes, dirs, keys, visible)
    if r.background_bottom is not None or dirs is not None:
        miss = np.nonzero(pix_patch < 0)[0] if miss is None else miss
        background_pixels(miss, rows, width, planes, dirs)
    # (a shadow catcher with no shadows and no occlusion to catch keeps the background)
    if ground is not None and not (scene.ground.color is None and ground_ao is None
                                   and not (len(lights) and r.shadows)):
        ground_pixels(frame, width, pix_patch, ground[0], ground[1],
                      trace_shadows if len(lights) and r.shadows else None, lights,
                      float(headlight[0]), scene.ground.color, rows, planes, dirs, miss,
                      ground_ao, keys)


def _smooth(frame, width, t, normals, pix_patch, patches, occlusion, miss, ground, t_ground,
            ground_ao, skip, ao):
    """The ambient occlusion of the surfaces' pixels (``occlusion``) and of the ground's
    (``ground_ao``, per missed pixel of ``miss``, whose rays meet the ground at ``t_ground``,
    :func:`shade.ground_points`; None: no ground) smoothed over the
    pixel grid (:func:`shade.smooth_occlusion`, radius ``ao[4]``, the pixel's angle
    ``ao[5]``): each surface pixel with its object's neighbours, each ground pixel with the
    ground's; the ground pixels ``skip`` traced no ray (every other one: the ground's
    occlusion varies slowly, and near the objects it can hold as many pixels as they do)
    and take their neighbours' estimates alone."""
    hit = pix_patch >= 0
    group = np.full(len(pix_patch), -1, np.int64)
    group[hit] = patches.object_id[pix_patch[hit]]
    depth = np.where(hit, t, np.inf)
    values = occlusion
    guide = normals
    ground_at = sampled = None
    if ground_ao is not None:
        on = t_ground < np.inf
        ground_at = miss[on]
        group[ground_at] = group.max(initial=-1) + 1  # (a label of its own)
        depth[ground_at] = t_ground[on]
        values = occlusion.copy()
        values[ground_at] = ground_ao[on]
        guide = normals.copy()
        guide[ground_at] = ground[0]
        if skip is not None:
            sampled = np.ones(len(pix_patch), np.float32)
            sampled[miss[on & skip]] = 0.0
    smooth = smooth_occlusion(frame, width, depth, guide, group, values, ao[5], ao[4],
                              sampled)
    occlusion = np.where(hit, smooth, occlusion).astype(np.float32)
    if ground_at is not None:
        ground_ao = ground_ao.copy()
        ground_ao[np.nonzero(on)[0]] = smooth[ground_at]
    return occlusion, ground_ao


def _antialias(scene, frame, W, H, closest, patches, planes, lights, ground, trace_shadows,
               samples, stats, tol_rad, ao=None, image_width=None, keyed=False, mirror=None):
    """More rays for the pixels :func:`edge_pixels` marks (see the module comment); their
    colour and alpha become the mean of all their rays. ``W``: the width of ``planes``;
    ``H``: the height of the image (a window's rows are offset in it: ``frame``);
    ``image_width`` its width. ``keyed``: the extra rays carry their keys for the lights
    that sample their shadow rays (``lights.ray_keys``: the pixel's samples 1, 2, ...)."""
    pix = np.nonzero(edge_pixels(planes, W, planes.shape[1] // W).ravel())[0]
    offsets = sample_offsets(samples)
    m = len(offsets)
    if not len(pix):
        return
    # the extra rays, pixel by pixel: (row + dr, col + dc) through the camera's frame
    row, col = np.divmod(pix, W)
    col0, row0 = window_offset(frame)  # (a window's pixels: their image's rays)
    row, col = row + row0, col + col0
    rr = (row[:, None] + offsets[None, :, 0]).ravel()
    cc = (col[:, None] + offsets[None, :, 1]).ravel()
    d = frame[3] + cc[:, None] * frame[1] + rr[:, None] * frame[2]
    dirs = np.ascontiguousarray(d / np.sqrt((d * d).sum(axis=1))[:, None])
    n = len(dirs)
    t, normals, pix_patch, sub, texel = closest(dirs)
    # the background at each ray's own height (a gradient's blend at row rr)
    top = np.asarray(scene.render.background, np.float64)
    bottom = scene.render.background_bottom
    w = np.clip((rr + 0.5) / H, 0.0, 1.0)[:, None]
    back = np.repeat(top[None], n, axis=0) if bottom is None else (
        (1.0 - w) * top + w * np.asarray(bottom, np.float64))
    ids = keys = None
    if ao is not None:  # each extra ray's AO pattern: its image pixel and sample, apart
        ids = ((row * ao[3] + col)[:, None] * m + np.arange(m)).ravel() + (np.int64(1) << 40)
    if keyed:
        keys = ray_keys(np.repeat(row * image_width + col, m), np.tile(np.arange(1, m + 1),
                                                                        len(pix)))
    _colour(scene, frame, W, t, normals, pix_patch, patches, sub, lights, back, ground,
            trace_shadows, tol_rad, dirs, ao, ids, False, keys, texel, mirror)
    # box filter: the centre ray and the extra ones, equally weighted
    for k in (C_R, C_R + 1, C_R + 2, C_A):
        extra = sub[k].astype(np.float64).reshape(len(pix), m).sum(axis=1)
        planes[k, pix] = ((planes[k, pix].astype(np.float64) + extra) / samples).astype(
            np.float32)
    _nearest_hit(planes, pix, sub, m)
    stats.aa_pixels += len(pix)
    stats.aa_rays += n


def _nearest_hit(planes, pix, sub, m) -> None:
    """The pixels ``pix`` whose centre ray missed (Z = +inf) but an extra ray hit take the
    channels after the colour and alpha (depth, normal, level, ids, (u, v), position) of
    their nearest extra ray that hit: ``sub`` (len(CHANNELS), len(pix) * m), each pixel's
    ``m`` extra rays in turn. A covered pixel then has a depth, as compositors expect."""
    z = sub[C_Z].reshape(len(pix), m)
    k = np.argmin(z, axis=1)
    rows = np.arange(len(pix))
    take = np.isinf(planes[C_Z, pix]) & np.isfinite(z[rows, k])
    planes[C_Z:, pix[take]] = sub[C_Z:, rows[take] * m + k[take]]
