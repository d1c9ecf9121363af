"""Shading: rebuild position, normal, ids and colour from the hits (pbrt habit: the
intersection kernels return only t, the micro-face and its barycentrics).

A hit on a Bezier piece or a Loop triangular net takes the exact normal of its net at the
hit's parameter. On a cell (of an irregular patch) the normal interpolates the exact unit
limit normals of the cell's corners (computed from the limit tangents of the subdivision
core) with the hit's barycentrics; where the limit tangents leave a corner's normal
undefined, the micro-triangle's own normal is used. Where a corner's normal lies more than
``config.CELL_NORMAL_SPREAD_DEG`` from that blend (a semi-sharp crease narrower than the
cell), the hit takes the exact limit normal at its parameter instead
(:func:`exact_cell_normals`): every shading normal is then within about that angle of the
limit normal (tests/test_cell_normals.py).
Lighting (:func:`light`) is two-sided Lambert plus the material's Blinn-Phong lobe (MTL's
``Ks (N.H)^Ns``) under a headlight at the eye and directional and point lights, each scaled
by its visibility (shadow rays: ``subtrace.picture``). Also here: the ground plane's colour
(:func:`ground_pixels`), the background gradient, and which pixels need more rays
(:func:`edge_pixels`).

The per-pixel kernels that allocate nothing are compiled without Numba's reference counting
(``_nrt=False``, as ``runtime.jit.leaf_njit``): the helpers they inline pass arrays around,
and where the branches defeat Numba's pruning of the counts each pass of an array costs an
atomic increment and decrement per pixel. The ground's first pass took 106 ns a pixel with
them and 23 without (one thread, 916k ground pixels); a render's shading 0.083 -> 0.033 s
(Spot, 1280x720, no shadows).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from subtrace import config
from subtrace.accel.bvh import slab_entry
from subtrace.camera import window_offset
from subtrace.geometry.bezier import cell_normal
from subtrace.geometry.kinds import BEZIER, CELL, LOOP_CELL, TRI
from subtrace.geometry.prims import ray_setup
from subtrace.geometry.tris import tri_cell_normal, tri_normal
from subtrace.io.obj import DEFAULT_DIFFUSE, Material
from subtrace.lights import (DIRECTIONAL, PARAM, R2_A1, R2_A2, RGB, ROW, environment_irradiance,
                             hash01, incoming, irradiance_at, is_environment, shadow_samples,
                             shadow_target, shadow_weight)
from subtrace.patches.basis import bez_normal
from subtrace.patches.crease import crease_normals
from subtrace.patches.evaluate import evaluate, ptex_starts
from subtrace.runtime.jit import callee_njit, inline_njit, leaf_njit, llvm_inline_njit, nb
from subtrace.runtime.threads import run_tasks, thread_count
from subtrace.trace.pools import Hits, PieceArrays


# the planes the shading fills, in this order, and what a pixel whose ray missed holds
# (R, G, B: the background colour). P.X, P.Y, P.Z: the world-space hit point of the
# ray, eye + Z d (OpenEXR's / Cycles' names), NaN where it missed (Z = +inf: no point);
# a pixel's ray is its centre ray, or where that missed its nearest anti-aliasing ray
# that hit (picture.py)
CHANNELS = ("R", "G", "B", "A", "Z", "N.X", "N.Y", "N.Z", "level", "patch_id", "object_id",
            "u", "v", "P.X", "P.Y", "P.Z")
C_R, C_A, C_Z, C_N, C_LEVEL, C_PATCH, C_OBJECT, C_U, C_P = 0, 3, 4, 5, 8, 9, 10, 11, 13
MISS = (0.0, 0.0, 0.0, 0.0, np.inf, 0.0, 0.0, 0.0, -1.0, -1.0, -1.0, 0.0, 0.0, np.nan,
        np.nan, np.nan)


def shade(frame, width, hits, iso, patches, miss, planes, normals, pix_patch, covered,
          dirs=None, loop=None, lit=None, table=None):
    """Fill ``planes`` (len(CHANNELS), n_pixels) float32 from ``hits``
    (:class:`~subtrace.trace.pools.Hits`) on every thread (blocks of pixels in turn): every
    channel but the colour, which :func:`light` adds, or with ``lit`` = (lights (L,7),
    headlight (1,)) the colour too, as :func:`light` gives it with every pixel lit and no
    ambient occlusion (a render without shadows or ambient occlusion: one pass over the
    pixels, and the lights' kernel neither loaded nor run; not for Loop cages, whose
    normals come after).

    ``iso``: the built patches' items (:class:`~subtrace.trace.pools.PieceArrays`);
    ``patches``: per patch, its ids and material (:class:`PatchShading`); ``miss``
    (:func:`miss_values`); ``normals`` (n_pixels,3) float64 receives each hit's unit normal
    turned towards the eye, ``pix_patch`` (n_pixels,) int32 its patch (-1: a miss);
    ``covered`` (threads,) int64 receives the hits each thread shaded. ``dirs``: None (ray
    r is pixel r's centre ray), or the (n,3) unit directions of rays from the eye (extra
    samples): then ``hits`` and the outputs are per ray. ``loop``: whether any cage is a
    Loop cage (``geometry.bezier.loop_flag``: True or None); the normals of hits on Loop items
    are a second pass of their own (:func:`_loop_normals_task`), which a render of
    Catmull-Clark cages neither runs nor compiles. ``table``: the patch table the items
    were built from; given, the hits on cells whose corner normals spread take the exact
    limit normal (:func:`exact_cell_normals`)."""
    dirs = _no_dirs() if dirs is None else dirs
    if lit is None:  # (the same types: one compiled kernel either way)
        lit = (np.zeros((0, ROW)), np.zeros(0))
    elif loop is not None:
        raise ValueError("Loop items' normals come after the shading pass: colour them "
                         "by light()")
    lights, headlight = lit
    # (the bundles as plain tuples, named again inside: see trace.kernels.trace_round)
    run_tasks(_shade_task, frame, width, tuple(hits), tuple(iso), tuple(patches), miss, planes,
              normals, pix_patch, covered, dirs, lights, headlight, _all_lit(len(lights)),
              _NO_OCCLUSION, _NO_TEXEL)
    if loop is not None:
        run_tasks(_loop_normals_task, frame, width, hits, iso, planes, normals, dirs)
    if table is not None:
        exact_cell_normals(table, frame, width, hits, iso, patches, planes, normals, dirs, lit)


def own_ptex(cage, ptex):
    """The ptex ids ``ptex`` of a cage's patches (the whole cage's numbering) in the cage's
    own: a :meth:`~subtrace.mesh.cage.Cage.restricted` cut of a large cage keeps the whole
    cage's ids (``ptex_first``, one per face, increasing)."""
    ptex = np.asarray(ptex, np.int64)
    if cage.ptex_first is None:
        return ptex
    first = np.asarray(cage.ptex_first, np.int64)
    face = np.searchsorted(first, ptex, side="right") - 1
    return ptex_starts(cage)[face] + (ptex - first[face])


def exact_cell_normals(table, frame, width, hits, iso, patches, planes, normals, dirs, lit):
    """The hits on cells (of irregular patches) whose exact corner normals spread by more
    than ``config.CELL_NORMAL_SPREAD_DEG`` from the blend at the hit take the exact limit
    normal at their parameter instead (``patches.crease.crease_normals`` on a patch along
    one crease of one sharpness, else ``patches.evaluate``; both OpenSubdiv-checked), in the
    N planes and ``normals`` (turned towards the eye), and are coloured again where the
    shading pass coloured them (``lit``). A cell is exact at its corners only: across a
    semi-sharp crease narrower than the cell (sharpness 6-8 at isolation depth 5) the
    blend turns the normal over the whole cell where the surface turns within the
    crease's fillet, and such pixels read as dots along the crease."""
    r = np.nonzero(hits.t < np.inf)[0]
    it = hits.item[r].astype(np.int64)
    on = iso.kind[it] == CELL
    r, it = r[on], it[on]
    if not len(r):
        return
    blend = planes[C_N:C_N + 3, r].T.astype(np.float64)
    corner = iso.cell_normals[iso.ref[it]]  # (m,4,3)
    lowest = np.einsum("mkd,md->mk", corner, blend).min(axis=1)
    far = lowest < math.cos(math.radians(config.CELL_NORMAL_SPREAD_DEG))
    r = r[far]
    if not len(r):
        return
    p = -hits.prim[r].astype(np.int64) - 2
    at = np.stack([hits.a[r], hits.b[r]], axis=1)  # (the patch's parameter)
    uv = np.clip(patches.uv0[p] + patches.scale[p][:, None] * at, 0.0, 1.0)
    n = np.full((len(r), 3), np.nan)
    oid = table.object_id[p]
    for o in sorted(set(oid.tolist())):  # (np.unique would import numpy.ma)
        sel = np.nonzero(oid == o)[0]
        obj = table.objects[o]
        # a patch along one crease of one sharpness in closed form (patches/crease.py),
        # any other by local refinement
        ok, n[sel] = crease_normals(obj.level, obj.points, obj.cage.options,
                                    table.face[p[sel]], np.clip(at[sel], 0.0, 1.0))
        rest = sel[~ok]
        if len(rest):
            _, du, dv = evaluate(obj.cage, own_ptex(obj.cage, patches.ptex[p[rest]]),
                                 uv[rest])
            n[rest] = np.cross(du, dv)
    length = np.sqrt((n * n).sum(axis=1))
    good = length > 0.0  # (NaN: a hole face; 0: an undefined normal)
    r, p, n = r[good], p[good], n[good] / length[good][:, None]
    if not len(r):
        return
    n *= np.where((n * blend[far][good]).sum(axis=1) < 0.0, -1.0, 1.0)[:, None]
    planes[C_N:C_N + 3, r] = n.T
    d = dirs[r] if len(dirs) else pixel_rays(frame, width, r)
    facing = n * np.where((n * d).sum(axis=1) > 0.0, -1.0, 1.0)[:, None]
    normals[r] = facing
    lights, headlight = lit
    if len(headlight):  # (the shading pass coloured them: again with the new normals)
        sub = planes[:, r]
        light(frame, width, hits.t[r], facing, p.astype(np.int32),
              patches, lights, headlight, _all_lit(len(lights)), sub, dirs=d)
        planes[C_R:C_R + 3, r] = sub[C_R:C_R + 3]


def _no_dirs():
    return np.zeros((0, 3))


def _all_lit(n_lights):
    """(n_lights, 0) float32: every pixel lit by every light (:func:`light`'s ``visible``
    without columns)."""
    return np.ones((n_lights, 0), np.float32)


_NO_OCCLUSION = np.zeros(0, np.float32)  # (light()'s ``occlusion``: none)
_NO_TEXEL = np.zeros((0, 6), np.float32)  # (light()'s ``texel``: no ray textured)


def light(frame, width, t, normals, pix_patch, patches, lights, headlight, visible, planes,
          dirs=None, occlusion=None, texel=None):
    """The colour (R, G, B of ``planes``) of every hit pixel: two-sided Lambert plus the
    material's Blinn-Phong lobe (``Ks (N.H)^Ns``, MTL's) under a headlight at the eye
    (``headlight`` (1,): its intensity) and ``lights`` (L, ROW) (``lights.light_array``), each
    scaled by ``visible`` (L, n_pixels) float32 (1 lit, 0 in shadow; (L, 0): all lit).
    ``t`` (n_pixels,) float64: the hits' distances; ``normals``, ``pix_patch``, ``dirs``:
    as for :func:`shade`. ``occlusion``: None, or (n_pixels,) float32 ambient occlusion
    (:func:`ambient_occlusion`: the share of the hemisphere open) scaling the diffuse
    (Lambert) part of every light; the specular lobe keeps its own visibility. ``texel``:
    None, or (n_pixels,6) float32 per ray diffuse and specular colours of its textures
    (``textures.texture_hits``), -1 where the patch's constant colours hold."""
    dirs = _no_dirs() if dirs is None else dirs
    occlusion = _NO_OCCLUSION if occlusion is None else occlusion
    texel = _NO_TEXEL if texel is None else texel
    run_tasks(_light_task, frame, width, t, normals, pix_patch, patches, lights, headlight,
              visible, planes, dirs, occlusion, texel)


class PatchShading(NamedTuple):
    """Per patch (P,): what the shading writes besides the geometry."""

    object_id: np.ndarray  # (P,) int32
    ptex: np.ndarray  # (P,) int32: ptex face
    uv0: np.ndarray  # (P,2) float64: the patch's origin in its ptex face
    scale: np.ndarray  # (P,) float64: the patch's size in its ptex face
    level0: np.ndarray  # (P,) int8: the patch level (0, or 1 for split n-gons)
    color: np.ndarray  # (P,3) float64: diffuse colour
    specular: np.ndarray  # (P,3) float64: specular colour (Ks; 0: none)
    shininess: np.ndarray  # (P,) float64: specular exponent (Ns)
    reflect: np.ndarray  # (P,3) float64: reflectance at normal incidence (0: none)
    roughness: np.ndarray  # (P,) float64: 0 a mirror .. 1 (GGX alpha = roughness^2)


def miss_values(background) -> np.ndarray:
    """(len(CHANNELS),) float32: each plane's value where the ray missed."""
    miss = np.array(MISS, dtype=np.float32)
    miss[C_R:C_R + 3] = background
    return miss


def deepest_level(planes) -> int:
    """The level channel's maximum over the pixels hit (the planes of :func:`shade`); -1
    when no ray hit."""
    level = planes[C_LEVEL]
    return int(level.max(initial=-1.0))


SHADE_BLOCK = 1024  # consecutive pixels shaded together


@nb.njit(cache=True, nogil=True, _nrt=False)
def _shade_task(task, n_tasks, frame, width, hits_t, iso_t, patches_t, miss, planes, normals,
                pix_patch, covered, dirs, lights, headlight, visible, occlusion, texel):
    """Shade the blocks of pixels ``task, task + n_tasks, ...`` into ``planes`` (see
    :func:`shade`): each block is first filled with ``miss`` (contiguous stores), then its
    hits are shaded over it, and coloured where ``headlight`` is not empty (its other
    arguments as :func:`light`'s; the hits, pieces and patch shading as plain tuples)."""
    hits, iso, patches = Hits(*hits_t), PieceArrays(*iso_t), PatchShading(*patches_t)
    n_pix = len(hits.t)
    n_blocks = (n_pix + SHADE_BLOCK - 1) // SHADE_BLOCK
    n_hit = 0
    for blk in range(task, n_blocks, n_tasks):
        b0 = blk * SHADE_BLOCK
        b1 = min(n_pix, b0 + SHADE_BLOCK)
        for k in range(planes.shape[0]):
            planes[k, b0:b1] = miss[k]
        pix_patch[b0:b1] = -1
        for r in range(b0, b1):
            t = hits.t[r]
            if not (t < np.inf):
                continue
            n_hit += 1
            planes[C_Z, r] = t
            dx, dy, dz = _direction(frame, width, dirs, r)
            planes[C_P, r] = frame[0, 0] + t * dx
            planes[C_P + 1, r] = frame[0, 1] + t * dy
            planes[C_P + 2, r] = frame[0, 2] + t * dz
            # the patch and item hit, (a, b) the patch parameter
            p = -np.int64(hits.prim[r]) - 2
            u = hits.a[r]
            v = hits.b[r]
            depth = np.int64(hits.leaf[r])  # (1 << depth: in 64 bits)
            it = np.int64(hits.item[r])
            c = iso.ref[it]
            if iso.kind[it] == TRI or iso.kind[it] == LOOP_CELL:
                nx = ny = nz = 0.0  # (a Loop item: its normal's pass, _loop_normals_task)
            elif iso.kind[it] == BEZIER:
                # a Bezier piece over a dyadic square of the patch (the whole of a regular one)
                sc = 1 << iso.level[it]
                nx, ny, nz = bez_normal(iso.nets[c], u * sc - iso.i0[it], v * sc - iso.j0[it])
            else:
                nx, ny, nz = cell_normal(iso.cells[4 * c:4 * c + 4], iso.cell_normals[c],
                                          u * (1 << depth) - iso.i0[it],
                                          v * (1 << depth) - iso.j0[it])
            planes[C_N, r] = nx
            planes[C_N + 1, r] = ny
            planes[C_N + 2, r] = nz
            planes[C_U, r] = patches.uv0[p, 0] + patches.scale[p] * u
            planes[C_U + 1, r] = patches.uv0[p, 1] + patches.scale[p] * v
            planes[C_LEVEL, r] = patches.level0[p] + depth
            planes[C_PATCH, r] = patches.ptex[p]
            planes[C_OBJECT, r] = patches.object_id[p]
            planes[C_A, r] = 1.0
            # two-sided: the normal turned towards the eye
            sgn = -1.0 if nx * dx + ny * dy + nz * dz > 0.0 else 1.0
            normals[r, 0] = sgn * nx
            normals[r, 1] = sgn * ny
            normals[r, 2] = sgn * nz
            pix_patch[r] = np.int32(p)
            if len(headlight):
                _colour_pixel(r, p, frame, width, t, normals, patches, lights, headlight,
                              visible, planes, dirs, occlusion, texel)
    covered[task] = n_hit


@nb.njit(cache=True, nogil=True, _nrt=False)
def _light_task(task, n_tasks, frame, width, t, normals, pix_patch, patches, lights, headlight,
                visible, planes, dirs, occlusion, texel):
    """The colour of the hit pixels of blocks ``task, task + n_tasks, ...`` (see
    :func:`light`)."""
    n_pix = len(pix_patch)
    n_blocks = (n_pix + SHADE_BLOCK - 1) // SHADE_BLOCK
    for blk in range(task, n_blocks, n_tasks):
        for r in range(blk * SHADE_BLOCK, min(n_pix, (blk + 1) * SHADE_BLOCK)):
            p = pix_patch[r]
            if p >= 0:
                _colour_pixel(r, np.int64(p), frame, width, t[r], normals, patches, lights,
                              headlight, visible, planes, dirs, occlusion, texel)


@inline_njit
def _colour_pixel(r, p, frame, width, t, normals, patches, lights, headlight, visible, planes,
                  dirs, occlusion, texel):
    """The colour (R, G, B of ``planes``) of hit pixel ``r`` on patch ``p`` at distance
    ``t``, its eye-facing normal in ``normals`` (:func:`light`: the lights, their
    visibility, ambient occlusion and the textures' colours)."""
    dx, dy, dz = _direction(frame, width, dirs, r)
    fx, fy, fz = normals[r, 0], normals[r, 1], normals[r, 2]
    kd0, kd1, kd2 = patches.color[p, 0], patches.color[p, 1], patches.color[p, 2]
    ks0, ks1, ks2 = patches.specular[p, 0], patches.specular[p, 1], patches.specular[p, 2]
    if len(texel) and texel[r, 0] >= 0.0:  # (a diffuse texture)
        kd0, kd1, kd2 = texel[r, 0], texel[r, 1], texel[r, 2]
    if len(texel) and texel[r, 3] >= 0.0:  # (a specular texture)
        ks0, ks1, ks2 = texel[r, 3], texel[r, 4], texel[r, 5]
    shiny = ks0 > 0.0 or ks1 > 0.0 or ks2 > 0.0
    lr = lg = lb = 0.0
    sr = sg = sb = 0.0
    if headlight[0] > 0.0:
        c = -(fx * dx + fy * dy + fz * dz) * headlight[0]
        lr += c
        lg += c
        lb += c
        if shiny:  # the headlight's half vector is the view direction
            h = (-(fx * dx + fy * dy + fz * dz)) ** patches.shininess[p] * headlight[0]
            sr += h
            sg += h
            sb += h
    for k in range(lights.shape[0]):
        if is_environment(lights, k):  # (its own irradiance of the normal; no lobe)
            v = visible[k, r] if visible.shape[1] else 1.0
            er, eg, eb = environment_irradiance(lights, k, fx, fy, fz)
            lr += er * v * lights[k, RGB]
            lg += eg * v * lights[k, RGB + 1]
            lb += eb * v * lights[k, RGB + 2]
            continue
        # (lx, ly, lz): the direction the light arrives along; e: its irradiance
        lx, ly, lz, e = incoming(lights, k, frame, t, dx, dy, dz)
        c = -(fx * lx + fy * ly + fz * lz) * e
        v = visible[k, r] if visible.shape[1] else 1.0  # (no columns: all lit)
        if c > 0.0 and v > 0.0:
            c *= v
            lr += c * lights[k, RGB]
            lg += c * lights[k, RGB + 1]
            lb += c * lights[k, RGB + 2]
            if shiny:
                h = _blinn(fx, fy, fz, lx, ly, lz, dx, dy, dz, patches.shininess[p])
                h *= e * v
                sr += h * lights[k, RGB]
                sg += h * lights[k, RGB + 1]
                sb += h * lights[k, RGB + 2]
    if len(occlusion):  # ambient occlusion darkens the diffuse light
        lr *= occlusion[r]
        lg *= occlusion[r]
        lb *= occlusion[r]
    planes[C_R, r] = kd0 * lr
    planes[C_R + 1, r] = kd1 * lg
    planes[C_R + 2, r] = kd2 * lb
    if shiny:
        planes[C_R, r] += ks0 * sr
        planes[C_R + 1, r] += ks1 * sg
        planes[C_R + 2, r] += ks2 * sb


@nb.njit(cache=True, nogil=True, _nrt=False)
def _loop_normals_task(task, n_tasks, frame, width, hits, iso, planes, normals, dirs):
    """The normals of the hits on Loop items in the blocks of :func:`_shade_task`'s task
    ``task``, which left them zero: the normal (N) channel and ``normals``, turned towards
    the eye."""
    n_pix = len(hits.t)
    n_blocks = (n_pix + SHADE_BLOCK - 1) // SHADE_BLOCK
    for blk in range(task, n_blocks, n_tasks):
        for r in range(blk * SHADE_BLOCK, min(n_pix, (blk + 1) * SHADE_BLOCK)):
            if not (hits.t[r] < np.inf):
                continue
            it = np.int64(hits.item[r])
            if iso.kind[it] != TRI and iso.kind[it] != LOOP_CELL:
                continue
            u = hits.a[r]
            v = hits.b[r]
            c = iso.ref[it]
            g = np.float64(iso.orient[it])
            if iso.kind[it] == TRI:
                # a Loop patch or piece: the normal of its triangular net at its own
                # (s, t) (geometry/tris.py: the patch's (u, v) = (A + g (s, t)) 2^-level)
                sc = 1 << iso.level[it]
                nx, ny, nz = tri_normal(iso.tri_nets, c,
                                        g * (u * sc - iso.i0[it]), g * (v * sc - iso.j0[it]))
            else:
                depth = np.int64(hits.leaf[r])  # (1 << depth: in 64 bits)
                nx, ny, nz = tri_cell_normal(iso.cells[4 * c:4 * c + 3],
                                              iso.cell_normals[c],
                                              g * (u * (1 << depth) - iso.i0[it]),
                                              g * (v * (1 << depth) - iso.j0[it]))
            planes[C_N, r] = nx
            planes[C_N + 1, r] = ny
            planes[C_N + 2, r] = nz
            dx, dy, dz = _direction(frame, width, dirs, r)
            sgn = -1.0 if nx * dx + ny * dy + nz * dz > 0.0 else 1.0
            normals[r, 0] = sgn * nx
            normals[r, 1] = sgn * ny
            normals[r, 2] = sgn * nz


@leaf_njit
def _direction(frame, width, dirs, r):
    """Ray r's unit direction: ``dirs[r]``, or with no ``dirs`` pixel r's centre ray."""
    if len(dirs):
        return dirs[r, 0], dirs[r, 1], dirs[r, 2]
    row = r // width
    col = r - row * width
    return ray_setup(frame, row, col)


@callee_njit
def _blinn(fx, fy, fz, lx, ly, lz, dx, dy, dz, shininess):
    """Blinn-Phong's (N.H)^Ns for light travelling along l seen along d (H: the unit half
    vector of -l and -d)."""
    hx, hy, hz = -lx - dx, -ly - dy, -lz - dz
    n = math.sqrt(hx * hx + hy * hy + hz * hz)
    if not n > 0.0:
        return 0.0
    c = (fx * hx + fy * hy + fz * hz) / n
    return c ** shininess if c > 0.0 else 0.0


def patch_shading(table, overrides) -> PatchShading:
    """Per patch of ``table``: its ids, ptex placement and material: its object's
    ``overrides[object id]`` (a :class:`subtrace.io.scene.SceneObject`, or None) where that
    gives a colour / specular colour / shininess / metallic / roughness, else its OBJ
    material's (:func:`material_of`)."""
    fields = [np.empty((table.n_patches, 3)), np.empty((table.n_patches, 3)),
              np.empty(table.n_patches), np.empty((table.n_patches, 3)),
              np.empty(table.n_patches)]
    for oid, o in enumerate(table.objects):
        sl = slice(o.first_patch, o.first_patch + o.n_patches)
        mats = list(o.cage.materials) + [Material("", DEFAULT_DIFFUSE)]
        mat = table.material[sl]
        pick = np.where(mat >= 0, mat, len(mats) - 1)
        rows = [material_of(m, overrides[oid]) for m in mats]
        for k, f in enumerate(fields):
            f[sl] = np.array([r[k] for r in rows], dtype=np.float64)[pick]
    return PatchShading(table.object_id, table.ptex, table.ptex_uv0, table.ptex_scale,
                        table.level0, *fields)


DIELECTRIC_REFLECTANCE = 0.04  # a dielectric's reflectance at normal incidence (n = 1.5)


def material_of(mat, over=None):
    """(diffuse (3,), specular (3,), shininess, reflectance (3,), roughness) of the OBJ
    material ``mat`` (:class:`subtrace.io.obj.Material`) under the scene object ``over``'s
    keys (None: none; its colour, specular, shininess, metallic, roughness replace the
    material's where given). How it reflects: with a ``metallic`` m (the scene's keys, MTL's
    ``Pm`` / ``Pr``) a reflectance of (1 - m) 0.04 + m colour and a diffuse colour of
    (1 - m) colour; with ``metallic`` None and a ``roughness`` (MTL's ``illum`` 3..7) its
    specular colour is the reflectance and its Blinn-Phong lobe the reflection's; with
    neither, no reflection (reflectance 0)."""
    def pick(key, own):
        return own if over is None or getattr(over, key) is None else getattr(over, key)

    color = pick("color", mat.diffuse)
    specular, shininess = pick("specular", mat.specular), pick("shininess", mat.shininess)
    metallic, roughness = mat.metallic, mat.roughness
    if over is not None and over.roughness is not None:  # (the scene gives both)
        metallic, roughness = over.metallic, over.roughness
    color = np.asarray(color, np.float64)
    none = np.zeros(3)
    if roughness is None:
        return color, specular, shininess, none, 0.0
    if metallic is None:  # (MTL's illum 3..7: Ks reflects)
        return color, none, shininess, np.asarray(specular, np.float64), roughness
    f0 = (1.0 - metallic) * DIELECTRIC_REFLECTANCE + metallic * color
    return (1.0 - metallic) * color, specular, shininess, f0, roughness


# --------------------------------------------------------------------------------------
# shadows, the ground and the background (after the geometry pass)
# --------------------------------------------------------------------------------------


def pixel_rays(frame, width, pixels) -> np.ndarray:
    """(n,3) float64 unit directions of the rays through the centres of ``pixels`` (flat
    indices), the arithmetic of ``geometry.prims.ray_setup``."""
    row, col = np.divmod(np.asarray(pixels, np.int64), width)
    col0, row0 = window_offset(frame)  # (a window's pixels: their image's rays)
    row, col = row + row0, col + col0
    d = frame[3] + col[:, None] * frame[1] + row[:, None] * frame[2]
    return d / np.sqrt((d * d).sum(axis=1))[:, None]


# relative rounding of a hit point eye + t d (a few operations on doubles, with room)
POINT_ROUNDING = 2.0 ** -40


def error_bound(points, length, tol_rad) -> np.ndarray:
    """(n,) float64: how far the micro-surface may lie from the hit ``points`` (n,3) whose
    paths from the eye are ``length`` (n,) long: a cell subtends at most the angular
    tolerance ``tol_rad`` from the eye, so it lies within ``length * tol_rad`` of the hit,
    plus the rounding of the point itself. A ray that leaves a hit displaced along its
    normal by this much leaves the cell it hit (:func:`visibility_at`)."""
    return length * tol_rad + POINT_ROUNDING * np.abs(points).max(axis=1)


def hit_points(frame, width, t, pixels, tol_rad, dirs=None):
    """(points (n,3), err (n,)): the hits ``eye + t d`` of the rays of ``pixels`` (flat
    indices, int64; their centres' rays, :func:`pixel_rays`, or ``dirs[pixels]``) and their
    error bounds (:func:`error_bound` over the paths ``t``), on every thread
    (:func:`_hit_points_task`: numpy's arithmetic, operation for operation)."""
    pixels = np.ascontiguousarray(pixels, np.int64)
    points, err = np.empty((len(pixels), 3)), np.empty(len(pixels))
    run_tasks(_hit_points_task, frame, int(width), t, _no_dirs() if dirs is None else dirs,
              pixels, float(tol_rad), points, err)
    return points, err


@nb.njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _hit_points_task(task, n_tasks, frame, width, t, dirs, pixels, tol_rad, points, err):
    """:func:`hit_points` of thread ``task``'s share of ``pixels`` (:func:`_segment`): the
    arithmetic of :func:`pixel_rays` (a division by the length) and of :func:`error_bound`,
    so the points are those numpy makes."""
    a, b = _segment(task, n_tasks, len(pixels))
    for i in range(a, b):
        r = pixels[i]
        if len(dirs):
            dx, dy, dz = dirs[r, 0], dirs[r, 1], dirs[r, 2]
        else:
            row = r // width
            col = r - row * width
            if frame.shape[0] > 4:  # (a window's pixels: their image's rays)
                col += np.int64(frame[4, 0])
                row += np.int64(frame[4, 1])
            ax = frame[3, 0] + col * frame[1, 0] + row * frame[2, 0]
            ay = frame[3, 1] + col * frame[1, 1] + row * frame[2, 1]
            az = frame[3, 2] + col * frame[1, 2] + row * frame[2, 2]
            n = np.sqrt(ax * ax + ay * ay + az * az)
            dx, dy, dz = ax / n, ay / n, az / n
        th = t[r]
        px, py, pz = frame[0, 0] + th * dx, frame[0, 1] + th * dy, frame[0, 2] + th * dz
        points[i, 0], points[i, 1], points[i, 2] = px, py, pz
        err[i] = th * tol_rad + POINT_ROUNDING * max(max(abs(px), abs(py)), abs(pz))


def shadow_visibility(trace, frame, width, t, normals, pix_patch, lights, tol_rad, dirs=None,
                      keys=None):
    """(L, n_pixels) float32: :func:`visibility_at` of the hit pixels' points
    (:func:`hit_points`; ``dirs``: as for :func:`shade`), with their (eye-facing)
    ``normals`` and ``keys`` (None, or (n_pixels,) int64: ``lights.ray_keys``), read in
    place (``rows``); 1 where a pixel's ray missed."""
    visible = np.ones((len(lights), len(pix_patch)), np.float32)
    hit = np.nonzero(pix_patch >= 0)[0]
    if not len(lights) or not len(hit):
        return visible
    points, err = hit_points(frame, width, t, hit, tol_rad, dirs)
    visible[:, hit] = visibility_at(trace, points, normals, err, lights, keys, rows=hit)
    return visible


def visibility_at(trace, points, normals, err, lights, keys=None, rows=None):
    """(L, n) float32: the share of light k that point i of ``points`` (n,3) sees, 1 where
    all its shadow rays towards it arrive (or where its normal faces away from it: then its
    lighting is 0 anyway), 0 in shadow; an environment's rays weighted by their cosine with
    the normal (``lights.shadow_weight``). ``normals`` (n,3): unit, on the side the rays
    leave from (towards the viewer); ``err`` (n,): each point's error bound
    (:func:`error_bound`); ``trace(origins, dirs, tmax)``: an any-hit trace returning
    blocked (``trace.rays.trace_rays``); ``keys``: None, or (n,) int64 each point's ray key
    (``lights.ray_keys``), which the lights of several shadow rays per point need
    (``lights.sampled``); ``rows``: None, or (n,) int64: point i's normal and key are row
    ``rows[i]`` of ``normals`` and ``keys`` (arrays of more rows, read in place). The
    pixels' shadows (:func:`shadow_visibility`) and the reflected
    rays' (``reflect``) are this.

    A shadow ray leaves its point displaced along the normal by the error bound, so it
    leaves the cell it hit and never speckles a lit surface with its own shadow; it ends at
    the light less that much. The rays are made on every thread, in three passes (count,
    make, mark), light after light, each light's in point order (a point's rays towards one
    light in turn, as ``lights.shadow_target`` gives them), and traced in one call."""
    n_lights = len(lights)
    visible = np.ones((n_lights, len(points)), np.float32)
    if not n_lights or not len(points):
        return visible
    at = (np.ascontiguousarray(points, np.float64), np.ascontiguousarray(normals, np.float64),
          np.ascontiguousarray(err, np.float64), lights,
          _NO_KEYS if keys is None else np.ascontiguousarray(keys, np.int64),
          _NO_KEYS if rows is None else np.ascontiguousarray(rows, np.int64))
    n_tasks = thread_count()
    counts = np.zeros((n_tasks, n_lights), np.int64)  # per thread and light: its rays
    run_tasks(_shadow_count, *at, counts, n=n_tasks)
    n_rays = int(counts.sum())
    if not n_rays:
        return visible
    # thread task's rays towards light k from base[task, k]: light by light, in point order
    flat = counts.T.ravel()
    base = np.ascontiguousarray((np.cumsum(flat) - flat).reshape(n_lights, n_tasks).T)
    origins, to_light, tmax = np.empty((n_rays, 3)), np.empty((n_rays, 3)), np.empty(n_rays)
    run_tasks(_shadow_make, *at, base, origins, to_light, tmax, n=n_tasks)
    blocked = np.ascontiguousarray(trace(origins, to_light, tmax), np.uint8)
    run_tasks(_shadow_mark, *at, base, blocked, visible, n=n_tasks)
    return visible


_NO_KEYS = np.zeros(0, np.int64)  # (no ray keys: every light takes one ray per point)
# (and no rows: point i's normal and key are row i's)


@llvm_inline_njit
def _faces(points, normals, i, q, lights, k):
    """Whether point i's normal (row q of ``normals``) faces light k (an environment:
    always)."""
    lx, ly, lz = irradiance_at(lights, k, points[i, 0], points[i, 1], points[i, 2])[:3]
    return (normals[q, 0] * lx + normals[q, 1] * ly + normals[q, 2] * lz > 0.0
            or is_environment(lights, k))


@nb.njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _shadow_count(task, n_tasks, points, normals, err, lights, keys, rows, counts):
    """Pass 1 of :func:`visibility_at`: the shadow rays of thread ``task``'s points
    (:func:`_segment`), per light, into ``counts[task]``."""
    a, b = _segment(task, n_tasks, len(points))
    for k in range(lights.shape[0]):
        n = 0  # (counted here: threads adding to ``counts`` share a cache line)
        m = shadow_samples(lights, k)
        for i in range(a, b):
            if _faces(points, normals, i, rows[i] if len(rows) else i, lights, k):
                n += m
        counts[task, k] = n


@nb.njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _shadow_make(task, n_tasks, points, normals, err, lights, keys, rows, base, origins,
                 to_light, tmax):
    """Pass 2: the shadow rays of thread ``task``'s points, light k's from ``base[task, k]``:
    origin the point displaced along its normal by ``err``, unit direction, tmax."""
    a, b = _segment(task, n_tasks, len(points))
    for k in range(lights.shape[0]):
        j = base[task, k]
        m = shadow_samples(lights, k)
        for i in range(a, b):
            q = rows[i] if len(rows) else i
            if not _faces(points, normals, i, q, lights, k):
                continue
            key = keys[q] if len(keys) else np.int64(0)
            px, py, pz, e = points[i, 0], points[i, 1], points[i, 2], err[i]
            for s in range(m):
                lx, ly, lz, dist = shadow_target(lights, k, s, key, px, py, pz)
                origins[j, 0] = px + e * normals[q, 0]
                origins[j, 1] = py + e * normals[q, 1]
                origins[j, 2] = pz + e * normals[q, 2]
                to_light[j, 0], to_light[j, 1], to_light[j, 2] = lx, ly, lz
                tmax[j] = dist - e
                j += 1


@nb.njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _shadow_mark(task, n_tasks, points, normals, err, lights, keys, rows, base, blocked,
                 visible):
    """Pass 3: in ``visible``, the share of thread ``task``'s rays not ``blocked`` (0 or
    1 for a light of one ray)."""
    a, b = _segment(task, n_tasks, len(points))
    for k in range(lights.shape[0]):
        j = base[task, k]
        m = shadow_samples(lights, k)
        for i in range(a, b):
            q = rows[i] if len(rows) else i
            if not _faces(points, normals, i, q, lights, k):
                continue
            if is_environment(lights, k):
                visible[k, i] = _weighted_share(points, normals, i, q, lights, k, keys, m,
                                                blocked, j)
                j += m
            else:
                dark = 0
                for s in range(m):
                    if blocked[j]:
                        dark += 1
                    j += 1
                if dark:
                    visible[k, i] = np.float32(m - dark) / np.float32(m)


@llvm_inline_njit
def _weighted_share(points, normals, i, q, lights, k, keys, m, blocked, j):
    """The share of point i's ``m`` shadow rays towards light k (from ``blocked[j]`` on)
    that arrive, each weighted by ``lights.shadow_weight`` (an environment's: its cosine
    with the normal, row q of ``normals``); 1 where none has weight."""
    key = keys[q] if len(keys) else np.int64(0)
    px, py, pz = points[i, 0], points[i, 1], points[i, 2]
    total = dark = 0.0
    for s in range(m):
        lx, ly, lz, _ = shadow_target(lights, k, s, key, px, py, pz)
        w = shadow_weight(lights, k, lx, ly, lz, normals[q, 0], normals[q, 1], normals[q, 2])
        total += w
        if blocked[j + s]:
            dark += w
    return np.float32((total - dark) / total) if total > 0.0 else np.float32(1.0)


def ambient_occlusion(trace, frame, width, t, normals, pix_patch, samples, distance, tol_rad,
                      dirs=None, ids=None):
    """(n_pixels,) float32: the share of ``samples`` ambient occlusion rays per hit pixel
    that meet no surface within ``distance`` (1 where nothing was hit). ``trace(origins,
    dirs, tmax)``: an any-hit trace returning blocked, as for :func:`visibility_at`;
    ``dirs``: as for :func:`shade`.

    The rays are cosine-weighted over the hemisphere of the hit's eye-facing normal: points
    0..samples-1 of the R2 sequence (:func:`ao_directions`), the whole set turned by a hash
    of each ray's key (``ids`` (n,) int64: by default its index; a window passes its
    image's pixel indices and the extra anti-aliasing rays keys of their own), so
    neighbours see different patterns (noise, not bands) and the result depends on the
    pixel alone, never on the threads or the window. They leave the hit displaced along its
    normal by the hit's error bound (:func:`hit_points`), as shadow rays do
    (:func:`visibility_at`). Traced in chunks of config.AO_CHUNK_RAYS rays."""
    open_ = np.ones(len(pix_patch), np.float32)
    pix = np.nonzero(pix_patch >= 0)[0]
    if samples <= 0 or not len(pix):
        return open_
    per = max(1, config.AO_CHUNK_RAYS // samples)
    for a in range(0, len(pix), per):
        px = pix[a:a + per]
        points, err = hit_points(frame, width, t, px, tol_rad, dirs)
        f = np.ascontiguousarray(normals[px])
        origins = np.repeat(points + err[:, None] * f, samples, axis=0)
        rays = ao_directions(f, px if ids is None else ids[px], samples)
        blocked = trace(origins, rays, np.full(len(rays), float(distance)))
        hidden = blocked.reshape(len(px), samples).sum(axis=1, dtype=np.int64)
        open_[px] = (samples - hidden).astype(np.float32) / np.float32(samples)
    return open_


def ao_directions(normals, ids, samples) -> np.ndarray:
    """(n * samples, 3) float64 unit directions, ``samples`` per row of ``normals`` (n,3)
    (unit), cosine-weighted over its hemisphere (see :func:`ambient_occlusion`); ``ids``
    (n,) int64: what turns each row's set (a pixel or ray index)."""
    out = np.empty((len(normals) * samples, 3))
    _ao_directions(np.ascontiguousarray(normals, np.float64),
                   np.ascontiguousarray(ids, np.int64), samples, out)
    return out


def ground_points(frame, width, miss, up, height, dirs=None):
    """Where the missed rays ``miss`` (pixel or ray indices, as for :func:`ground_pixels`)
    meet the ground plane p . up = height going down: (t (n,) float64, their distances,
    inf where a ray meets no ground; points (n,3) float64, eye + t d, the eye where none)."""
    up = np.asarray(up, np.float64)
    d = pixel_rays(frame, width, miss) if dirs is None or not len(dirs) else dirs[miss]
    dn = d @ up
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (height - frame[0] @ up) / dn
    down = (dn < 0.0) & (t > 0.0) & (t < np.inf)
    points = frame[0] + np.where(down, t, 0.0)[:, None] * d
    return np.where(down, t, np.inf), points


def ground_occlusion(trace, t, points, up, samples, distance, keys, skip=None) -> np.ndarray:
    """(n,) float32: the ambient occlusion of the ground at ``points`` (n,3), where missed
    rays meet it at distances ``t`` (n,) (:func:`ground_points`; inf: no ground): the share
    of ``samples`` cosine-weighted rays over the hemisphere of ``up`` from the point that
    meet no surface within ``distance`` (``trace``: as for :func:`ambient_occlusion`). 1
    where there is no ground, and where the point lies farther than ``distance`` from
    ``trace.bounds`` (the box of everything ``trace`` can hit): nothing can occlude it
    there, and most of a ground's pixels are traced no ray. ``keys`` (n,) int64 turn each
    point's pattern, as :func:`ambient_occlusion`'s ids (the ray's pixel or id).
    ``skip``: None, or (n,) bool: points traced no ray (left 1; the smoothing fills them
    from their neighbours: :func:`smooth_occlusion`'s ``sampled``)."""
    open_ = np.ones(len(t), np.float32)
    bounds = getattr(trace, "bounds", None)
    if samples <= 0 or not len(t) or bounds is None:
        return open_
    up = np.asarray(up, np.float64)
    gap = np.maximum(np.maximum(bounds[0] - points, points - bounds[1]), 0.0)
    near = (t < np.inf) & ((gap * gap).sum(axis=1) < float(distance) ** 2)
    near = np.nonzero(near if skip is None else near & ~skip)[0]
    keys = np.asarray(keys, np.int64)
    per = max(1, config.AO_CHUNK_RAYS // samples)
    for a in range(0, len(near), per):
        m = near[a:a + per]
        origins = np.repeat(points[m], samples, axis=0)
        rays = ao_directions(np.repeat(up[None], len(m), axis=0), keys[m], samples)
        blocked = trace(origins, rays, np.full(len(rays), float(distance)))
        hidden = blocked.reshape(len(m), samples).sum(axis=1, dtype=np.int64)
        open_[m] = (samples - hidden).astype(np.float32) / np.float32(samples)
    return open_


def smooth_occlusion(frame, width, t, normals, group, values, pixel_rad, radius,
                     sampled=None) -> np.ndarray:
    """(n,) float32: ``values`` (n,) (ambient occlusion, one estimate per pixel of a
    ``width``-wide grid of rays from the eye) filtered by each pixel's neighbours within
    ``radius`` pixels that lie on the same smooth surface: a cross-bilateral filter guided
    by the geometry, which keeps contacts and creases and removes the grain of a few rays.

    A pixel of ``group`` g >= 0 (its object, or any other label of a surface: the ground)
    takes the neighbours of its group, weighted by a Gaussian of their distance in pixels
    (sigma radius / 2), by (n . n')^8 of the normals ``normals`` (n,3) and by how near the
    neighbour's point (eye + t' d') lies to the pixel's tangent plane: (1 - (h / reach)^2)^2
    for a distance h within two of the pixel's footprints (``reach = 2 t pixel_rad``), none
    beyond; pixels of group -1 keep their value. ``sampled``: None, or (n,) float32, 0 for
    the pixels that hold no estimate of their own (they take their neighbours' and give
    none), 1 for the others. Each pixel
    reads only its own neighbourhood, so a window of the image with ``radius`` pixels
    more on every side gives its pixels' values bit for bit."""
    out = np.asarray(values, np.float32).copy()
    if radius > 0 and len(out):
        t = np.ascontiguousarray(t, np.float64)
        group = np.ascontiguousarray(group, np.int64)
        points = np.empty((len(out), 3))
        run_tasks(_points_task, frame, int(width), t, group, _no_dirs(), points)
        spatial = np.arange(-radius, radius + 1, dtype=np.float64) ** 2
        spatial = np.exp(-(spatial[:, None] + spatial[None, :]) * 2.0 / (radius * radius))
        sampled = np.ones(len(out), np.float32) if sampled is None else sampled
        run_tasks(_smooth_task, int(width), points, np.ascontiguousarray(normals, np.float64),
                  group, np.ascontiguousarray(values, np.float32), t * (2.0 * pixel_rad),
                  int(radius), spatial, np.ascontiguousarray(sampled, np.float32), out)
    return out


@nb.njit(cache=True, nogil=True, _nrt=False)
def _points_task(task, n_tasks, frame, width, t, group, dirs, points):
    """The points eye + t d of the pixels of ``group`` >= 0, rows ``task, task + n_tasks,
    ...`` (:func:`smooth_occlusion`)."""
    height = len(t) // width
    for row in range(task, height, n_tasks):
        for r in range(row * width, (row + 1) * width):
            if group[r] >= 0:
                dx, dy, dz = _direction(frame, width, dirs, r)
                points[r, 0] = frame[0, 0] + t[r] * dx
                points[r, 1] = frame[0, 1] + t[r] * dy
                points[r, 2] = frame[0, 2] + t[r] * dz


@nb.njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _smooth_task(task, n_tasks, width, points, normals, group, values, reach, radius, spatial,
                 sampled, out):
    """Rows ``task, task + n_tasks, ...`` of :func:`smooth_occlusion` (``reach``: each
    pixel's two footprints; ``spatial``: the Gaussian over the (2 radius + 1)^2 offsets)."""
    height = len(values) // width
    for row in range(task, height, n_tasks):
        i0, i1 = max(row - radius, 0), min(row + radius + 1, height)
        for col in range(width):
            r = row * width + col
            g = group[r]
            if g < 0:
                continue
            px, py, pz = points[r, 0], points[r, 1], points[r, 2]
            nx, ny, nz = normals[r, 0], normals[r, 1], normals[r, 2]
            inv = 1.0 / reach[r]
            total = 0.0
            weight = 0.0
            for i in range(i0, i1):
                for j in range(max(col - radius, 0), min(col + radius + 1, width)):
                    q = i * width + j
                    if group[q] != g:
                        continue
                    c = nx * normals[q, 0] + ny * normals[q, 1] + nz * normals[q, 2]
                    if not c > 0.0:
                        continue
                    h = ((points[q, 0] - px) * nx + (points[q, 1] - py) * ny
                         + (points[q, 2] - pz) * nz) * inv
                    near = 1.0 - h * h  # (1 - h^2)^2: 1 on the plane, 0 from one reach off
                    if not near > 0.0:
                        continue
                    c2 = c * c
                    c4 = c2 * c2
                    w = (spatial[i - row + radius, j - col + radius] * near * near * c4 * c4
                         * sampled[q])
                    total += w * values[q]
                    weight += w
            if weight > 0.0:
                out[r] = np.float32(total / weight)


@nb.njit(cache=True, _nrt=False)
def _ao_directions(normals, ids, samples, out):
    """Fill ``out`` (see :func:`ao_directions`)."""
    for i in range(len(normals)):
        nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
        # an orthonormal basis (b1, b2, n) (Duff et al. 2017: continuous, no division by 0)
        sign = 1.0 if nz >= 0.0 else -1.0
        a = -1.0 / (sign + nz)
        b = nx * ny * a
        b1x, b1y, b1z = 1.0 + sign * nx * nx * a, sign * b, -sign * nx
        b2x, b2y, b2z = b, sign + ny * ny * a, -ny
        # the R2 points turned by this row's hash (Cranley-Patterson rotation)
        r1 = hash01(ids[i], 1)
        r2 = hash01(ids[i], 2)
        for k in range(samples):
            u1 = (0.5 + k * R2_A1 + r1) % 1.0
            u2 = (0.5 + k * R2_A2 + r2) % 1.0
            # cosine-weighted: uniform on the unit disc, lifted to the hemisphere
            rad = math.sqrt(u1)
            phi = 2.0 * math.pi * u2
            x, y = rad * math.cos(phi), rad * math.sin(phi)
            z = math.sqrt(max(0.0, 1.0 - u1))
            j = i * samples + k
            out[j, 0] = x * b1x + y * b2x + z * nx
            out[j, 1] = x * b1y + y * b2y + z * ny
            out[j, 2] = x * b1z + y * b2z + z * nz


def background_rows(top, bottom, height) -> np.ndarray:
    """(height, 3) float64: the background colour of each image row: ``top`` everywhere,
    or a linear blend from ``top`` (row 0) to ``bottom`` (the last row) at row centres."""
    top = np.asarray(top, np.float64)
    if bottom is None:
        return np.repeat(top[None], height, axis=0)
    w = (np.arange(height) + 0.5)[:, None] / height
    return (1.0 - w) * top + w * np.asarray(bottom, np.float64)


def background_pixels(miss, rows, width, planes, dirs=None) -> None:
    """The background colour (``rows``: per image row, or per ray with ``dirs``) into the
    colour of the missed pixels ``miss``, on every thread."""
    rows = np.ascontiguousarray(rows, np.float64)
    run_tasks(_background_task, miss, rows, int(width), dirs is not None, planes)


@nb.njit(cache=True, nogil=True, _nrt=False)
def _background_task(task, n_tasks, miss, rows, width, per_ray, planes):
    a, b = _segment(task, n_tasks, len(miss))
    for m in range(a, b):
        r = miss[m]
        row = r if per_ray else r // width
        planes[C_R, r] = rows[row, 0]
        planes[C_R + 1, r] = rows[row, 1]
        planes[C_R + 2, r] = rows[row, 2]


def ground_pixels(frame, width, pix_patch, up, height, trace, lights, headlight, color, rows,
                  planes, dirs=None, miss=None, occlusion=None, keys=None):
    """Where the primary ray missed every surface and meets the ground plane (points p with
    p . up = height, ``up`` a unit vector), write the ground's colour into ``planes``: an
    opaque Lambertian ``color`` under ``lights`` with shadows and the ``headlight`` (its
    intensity), or (``color`` None) a shadow catcher: the background ``rows`` darkened by
    the fraction of the light (the headlight's included: it casts no shadow) the objects
    hold back (``trace``: as for :func:`visibility_at`; None: no shadows). The ground
    is part of the background: alpha and the other channels keep
    saying "no hit" (the EXR's coverage is the surface's). Returns the number of ground
    pixels. ``dirs``: as for :func:`shade` (then ``rows`` (n,3): each ray's background);
    ``miss``: the missed pixels, if known (``pix_patch < 0``); ``occlusion``: None, or
    (len(miss),) float32 the ground's ambient occlusion there (:func:`ground_occlusion`),
    which scales its light (a shadow catcher: the share of the background it keeps) as
    the surfaces' occlusion scales their diffuse light. ``keys``: as for
    :func:`shadow_visibility` (a light of several rays lights a point by the share of them
    that arrive).

    On every thread, three passes over the missed pixels: the first shades each ground
    pixel none of whose shadow rays may meet an object (a ray whose segment towards its
    light misses ``trace.bounds``, the box of everything ``trace`` can hit: on a scene that
    is mostly ground, most of them) and counts the rays of the others; the second makes
    those rays, ``trace`` traces them, and the third shades their pixels."""
    miss = np.nonzero(pix_patch < 0)[0] if miss is None else miss
    dirs = _no_dirs() if dirs is None else dirs
    keys = _NO_KEYS if keys is None else keys
    up = np.asarray(up, np.float64)
    shadows = trace is not None
    bounds = getattr(trace, "bounds", None) if shadows else None
    cull = bounds is not None
    lo, hi = (np.asarray(bounds[0], np.float64), np.asarray(bounds[1], np.float64)) if cull \
        else (np.zeros(3), np.zeros(3))
    catcher = color is None
    color = np.zeros(3) if catcher else np.asarray(color, np.float64)
    rows = np.ascontiguousarray(rows, np.float64)
    n_tasks = thread_count()
    pending = np.empty(len(miss), np.int8)  # per missed pixel: whether it has rays to trace
    # per thread: its ground pixels, then its rays towards each light (rows of 16 at
    # least: a thread's counts on cache lines of their own)
    counts = np.zeros((n_tasks, max(16, 1 + len(lights))), np.int64)
    occlusion = np.zeros(0, np.float32) if occlusion is None else occlusion
    shading = (frame, width, miss, dirs, keys, up, float(height), _with_inverse(lights),
               float(headlight), color, catcher, rows, shadows, cull, lo, hi, planes, occlusion,
               pending)
    run_tasks(_ground_first, *shading, counts, n=n_tasks)
    n_rays = int(counts[:, 1:1 + len(lights)].sum())
    if n_rays:
        # thread task's rays towards light k from base[task, k]: light by light (a run of
        # one direction for each directional light: trace.rays), in pixel order
        flat = counts[:, 1:1 + len(lights)].T.ravel()
        base = np.ascontiguousarray((np.cumsum(flat) - flat).reshape(-1, n_tasks).T)
        origins, to_light, dist = np.empty((n_rays, 3)), np.empty((n_rays, 3)), np.empty(n_rays)
        run_tasks(_ground_rays, *shading, base.copy(), origins, to_light, dist, n=n_tasks)
        blocked = np.ascontiguousarray(trace(origins, to_light, dist), np.uint8)
        run_tasks(_ground_last, *shading, base, blocked, n=n_tasks)
    return int(counts[:, 0].sum())


def _with_inverse(lights) -> np.ndarray:
    """(L, C + 3) float64: the C columns of ``lights.light_array``'s rows and, for a
    directional light, the inverse of each component of the direction towards it (the ground's slab
    tests, made once instead of per pixel; the same IEEE quotients)."""
    lights = np.asarray(lights, np.float64)
    n, width = lights.shape
    out = np.zeros((n, width + 3))
    out[:, :width] = lights
    with np.errstate(divide="ignore"):
        inv = 1.0 / -lights[:, 1:4]
    out[:, width:] = np.where(out[:, :1] == DIRECTIONAL, inv, 0.0)
    return out


@llvm_inline_njit
def _ground_hit(frame, width, dirs, r, up, e_up, height):
    """Where ray r meets the ground plane going down: (hit, point x, y, z, d . up)."""
    dx, dy, dz = _direction(frame, width, dirs, r)
    dn = dx * up[0] + dy * up[1] + dz * up[2]
    if not dn < 0.0:
        return False, 0.0, 0.0, 0.0, dn
    t = (height - e_up) / dn
    if not (t > 0.0 and t < np.inf):
        return False, 0.0, 0.0, 0.0, dn
    return True, frame[0, 0] + t * dx, frame[0, 1] + t * dy, frame[0, 2] + t * dz, dn


@llvm_inline_njit
def _ground_irradiance(lights, k, x, y, z, up):
    """Light k's irradiance at the ground point (x, y, z): the cosine with ``up`` of the
    direction towards it times its irradiance factor (``lights.irradiance_at``; 0 facing
    away)."""
    if is_environment(lights, k):  # (its luminance: the rays' and the catcher's)
        er, eg, eb = environment_irradiance(lights, k, up[0], up[1], up[2])
        return 0.2126 * er + 0.7152 * eg + 0.0722 * eb
    lx, ly, lz, d, f = irradiance_at(lights, k, x, y, z)
    return max(lx * up[0] + ly * up[1] + lz * up[2], 0.0) * f


# (1 / 0: inf, as the ray kernels take it; inlined, it takes its callers' error model, so
# theirs is numpy's too)
@llvm_inline_njit
def _ground_ray(lights, k, s, key, x, y, z, cull, lo, hi):
    """Shadow ray ``s`` of the ground point (x, y, z) towards light k
    (``lights.shadow_target``): its unit direction, length and whether it is to be traced:
    (``cull``) its segment enters the box [lo, hi]. ``lights``: :func:`_with_inverse`'s."""
    lx, ly, lz, d = shadow_target(lights, k, s, key, x, y, z)
    ray = True
    if cull:
        if lights[k, 0] == DIRECTIONAL and not lights[k, PARAM] > 0.0:  # (a soft sun's vary)
            c = lights.shape[1] - 3  # (_with_inverse's columns)
            ix, iy, iz = lights[k, c], lights[k, c + 1], lights[k, c + 2]
        else:
            ix, iy, iz = 1.0 / lx, 1.0 / ly, 1.0 / lz
        ray = slab_entry(x, y, z, ix, iy, iz, lo[0], lo[1], lo[2], hi[0], hi[1], hi[2], 0.0,
                         d) < np.inf
    return lx, ly, lz, d, ray


@llvm_inline_njit
def _ground_rays_of(lights, k, key, x, y, z, up, shadows, cull, lo, hi):
    """Light k at the ground point: (its irradiance there, :func:`_ground_irradiance`; how
    many of its shadow rays are to be traced: none without shadows or facing away)."""
    ck = _ground_irradiance(lights, k, x, y, z, up)
    n = 0
    if shadows and ck > 0.0:
        for s in range(shadow_samples(lights, k)):
            if _ground_ray(lights, k, s, key, x, y, z, cull, lo, hi)[4]:
                n += 1
    return ck, n


@inline_njit
def _segment(task, n_tasks, n):
    """Thread ``task``'s share [a, b) of ``n`` items (contiguous: its rays keep pixel order)."""
    return n * task // n_tasks, n * (task + 1) // n_tasks


@llvm_inline_njit
def _shade_ground(r, x, y, z, dn, frame, width, dirs, keys, up, lights, headlight, color,
                  catcher, rows, shadows, cull, lo, hi, planes, occ, blocked, next_ray,
                  traced):
    """The colour of ground pixel r (point (x, y, z), ``dn`` its ray's d . up) into
    ``planes``: each light's irradiance times the share of its shadow rays not blocked
    (for the rays :func:`_ground_ray` traces, where ``traced``: the rays ``next_ray[k]``
    on of ``blocked``, which moves on), all scaled by the ambient occlusion ``occ``."""
    full = max(-dn, 0.0) * headlight
    lit = full
    cr = cg = cb = full
    key = keys[r] if len(keys) else np.int64(0)
    for k in range(len(lights)):
        ck = _ground_irradiance(lights, k, x, y, z, up)
        full += ck
        m = shadow_samples(lights, k)
        if is_environment(lights, k):
            share = _ground_share(lights, k, key, x, y, z, up, cull, lo, hi, blocked,
                                  next_ray, traced and shadows and ck > 0.0)
            er, eg, eb = environment_irradiance(lights, k, up[0], up[1], up[2])
            lit += ck * share
            cr += er * share * lights[k, RGB]
            cg += eg * share * lights[k, RGB + 1]
            cb += eb * share * lights[k, RGB + 2]
            continue
        dark = 0
        if traced and shadows and ck > 0.0:
            for s in range(m):
                if _ground_ray(lights, k, s, key, x, y, z, cull, lo, hi)[4]:
                    if blocked[next_ray[k]] != 0:
                        dark += 1
                    next_ray[k] += 1
        if dark == 0:
            lit += ck
            cr += ck * lights[k, RGB]
            cg += ck * lights[k, RGB + 1]
            cb += ck * lights[k, RGB + 2]
        elif dark < m:  # (a share of a light of several rays)
            c = ck * ((m - dark) / m)
            lit += c
            cr += c * lights[k, RGB]
            cg += c * lights[k, RGB + 1]
            cb += c * lights[k, RGB + 2]
    if catcher:
        row = r if len(dirs) else r // width
        keep = (lit / full if full > 0.0 else 1.0) * occ
        cr, cg, cb = rows[row, 0] * keep, rows[row, 1] * keep, rows[row, 2] * keep
    else:
        cr, cg, cb = cr * color[0] * occ, cg * color[1] * occ, cb * color[2] * occ
    planes[C_R, r] = cr
    planes[C_R + 1, r] = cg
    planes[C_R + 2, r] = cb


@llvm_inline_njit
def _ground_share(lights, k, key, x, y, z, up, cull, lo, hi, blocked, next_ray, traced):
    """The share of light k's shadow rays from the ground point that arrive, each weighted
    by ``lights.shadow_weight`` against ``up`` (for the rays :func:`_ground_ray` traces,
    where ``traced``: those from ``next_ray[k]`` on of ``blocked``, which moves on); 1
    where none is traced or none has weight."""
    if not traced:
        return 1.0
    total = dark = 0.0
    for s in range(shadow_samples(lights, k)):
        lx, ly, lz, _, ray = _ground_ray(lights, k, s, key, x, y, z, cull, lo, hi)
        w = shadow_weight(lights, k, lx, ly, lz, up[0], up[1], up[2])
        total += w
        if ray:
            if blocked[next_ray[k]] != 0:
                dark += w
            next_ray[k] += 1
    return (total - dark) / total if total > 0.0 else 1.0


@nb.njit(cache=True, nogil=True, error_model="numpy", _nrt=False)  # (see _ground_ray)
def _ground_first(task, n_tasks, frame, width, miss, dirs, keys, up, height, lights,
                  headlight, color, catcher, rows, shadows, cull, lo, hi, planes, occlusion,
                  pending, counts):
    """Pass 1 of :func:`ground_pixels` over thread ``task``'s missed pixels: shade the ground
    pixels with no shadow ray to trace, set ``pending`` (1 for the others, 0 for these)
    and count the ground pixels and each light's rays (``counts[task]``: the pixels, then
    the rays of light 0, 1, ...)."""
    e_up = frame[0, 0] * up[0] + frame[0, 1] * up[1] + frame[0, 2] * up[2]
    a, b = _segment(task, n_tasks, len(miss))
    n_ground = 0  # (counted here: threads adding to ``counts`` share a cache line)
    for m in range(a, b):
        r = miss[m]
        pending[m] = 0
        hit, x, y, z, dn = _ground_hit(frame, width, dirs, r, up, e_up, height)
        if not hit:
            continue
        n_ground += 1
        n = 0
        key = keys[r] if len(keys) else np.int64(0)
        for k in range(len(lights) if shadows else 0):
            rays = _ground_rays_of(lights, k, key, x, y, z, up, shadows, cull, lo, hi)[1]
            counts[task, 1 + k] += rays  # (a row of this thread's own)
            n += rays
        if n == 0:
            occ = occlusion[m] if len(occlusion) else 1.0
            _shade_ground(r, x, y, z, dn, frame, width, dirs, keys, up, lights, headlight,
                          color, catcher, rows, shadows, cull, lo, hi, planes, occ, pending,
                          counts[0], False)
        else:
            pending[m] = 1
    counts[task, 0] = n_ground


@nb.njit(cache=True, nogil=True, error_model="numpy", _nrt=False)  # (see _ground_ray)
def _ground_rays(task, n_tasks, frame, width, miss, dirs, keys, up, height, lights,
                 headlight, color, catcher, rows, shadows, cull, lo, hi, planes, occlusion,
                 pending, base, origins, to_light, dist):
    """Pass 2: the shadow rays of thread ``task``'s pending pixels, light k's from
    ``base[task, k]`` on (which this moves on), in pixel order."""
    e_up = frame[0, 0] * up[0] + frame[0, 1] * up[1] + frame[0, 2] * up[2]
    a, b = _segment(task, n_tasks, len(miss))
    for m in range(a, b):
        if pending[m] == 0:
            continue
        r = miss[m]
        x, y, z = _ground_hit(frame, width, dirs, r, up, e_up, height)[1:4]
        key = keys[r] if len(keys) else np.int64(0)
        for k in range(len(lights)):
            if not _ground_irradiance(lights, k, x, y, z, up) > 0.0:
                continue
            for s in range(shadow_samples(lights, k)):
                lx, ly, lz, d, ray = _ground_ray(lights, k, s, key, x, y, z, cull, lo, hi)
                if ray:
                    j = base[task, k]
                    origins[j, 0], origins[j, 1], origins[j, 2] = x, y, z
                    to_light[j, 0], to_light[j, 1], to_light[j, 2] = lx, ly, lz
                    dist[j] = d
                    base[task, k] = j + 1


@nb.njit(cache=True, nogil=True, error_model="numpy", _nrt=False)  # (see _ground_ray)
def _ground_last(task, n_tasks, frame, width, miss, dirs, keys, up, height, lights,
                 headlight, color, catcher, rows, shadows, cull, lo, hi, planes, occlusion,
                 pending, base, blocked):
    """Pass 3: shade thread ``task``'s pending pixels with their rays' ``blocked`` (light
    k's from ``base[task, k]``, which this moves on)."""
    e_up = frame[0, 0] * up[0] + frame[0, 1] * up[1] + frame[0, 2] * up[2]
    a, b = _segment(task, n_tasks, len(miss))
    for m in range(a, b):
        if pending[m] == 0:
            continue
        r = miss[m]
        hit, x, y, z, dn = _ground_hit(frame, width, dirs, r, up, e_up, height)
        occ = occlusion[m] if len(occlusion) else 1.0
        _shade_ground(r, x, y, z, dn, frame, width, dirs, keys, up, lights, headlight, color,
                      catcher, rows, shadows, cull, lo, hi, planes, occ, blocked, base[task],
                      True)


def edge_pixels(planes, width, height) -> np.ndarray:
    """(height, width) bool: pixels that differ from their right or lower neighbour (both
    of a pair are marked) in coverage or object id, by a depth step (more than
    ``config.AA_DEPTH_STEP`` of the nearer depth), a normal jump (more than
    ``config.AA_NORMAL_DEG``) or a contrast in displayed luminance (sRGB, more than
    ``config.AA_CONTRAST``): silhouettes, folds, creases, shadow edges. ``planes``: the
    (len(CHANNELS), width*height) float32 of :func:`shade` with the colour lit. On every
    thread, rows in turn: each pixel's luminance, then whether it differs from its right
    and lower neighbours, then each pixel's mark from the pairs it is in."""
    n = width * height
    lum = np.empty(n)
    pairs = np.zeros(n, np.uint8)  # bit 0: differs from its right neighbour, bit 1: lower
    flag = np.zeros(n, np.bool_)
    run_tasks(_luminance_rows, planes, width, height, lum)
    run_tasks(_pair_rows, planes, width, height, lum, config.AA_DEPTH_STEP,
              math.cos(math.radians(config.AA_NORMAL_DEG)), config.AA_CONTRAST, pairs)
    run_tasks(_flag_rows, width, height, pairs, flag)
    return flag.reshape(height, width)


@leaf_njit
def _display_luminance(planes, r):
    """The sRGB-encoded luminance of pixel r's colour, clipped to 0..1."""
    y = 0.2126 * planes[C_R, r] + 0.7152 * planes[C_R + 1, r] + 0.0722 * planes[C_R + 2, r]
    if y <= 0.0031308:
        return max(12.92 * y, 0.0)
    return min(1.055 * y ** (1.0 / 2.4) - 0.055, 1.0)


@leaf_njit
def _differ(planes, lum, a, b, depth_step, cos_jump, contrast):
    """Whether pixels a and b differ enough for more rays (see :func:`edge_pixels`);
    ``lum``: each pixel's displayed luminance."""
    if abs(lum[a] - lum[b]) > contrast:
        return True
    ha = planes[C_A, a] > 0.0
    hb = planes[C_A, b] > 0.0
    if ha != hb:
        return True
    if ha:
        if planes[C_OBJECT, a] != planes[C_OBJECT, b]:
            return True
        za, zb = planes[C_Z, a], planes[C_Z, b]
        if abs(za - zb) > depth_step * min(za, zb):
            return True
        dot = (planes[C_N, a] * planes[C_N, b] + planes[C_N + 1, a] * planes[C_N + 1, b]
               + planes[C_N + 2, a] * planes[C_N + 2, b])
        if dot < cos_jump:
            return True
    return False


@nb.njit(cache=True, nogil=True, _nrt=False)
def _luminance_rows(task, n_tasks, planes, width, height, lum):
    """Rows ``task, task + n_tasks, ...``: each pixel's displayed luminance into ``lum``
    (a pixel of its left neighbour's colour takes its value: a row of the background or
    of a lit ground is one colour, and a power per pixel was most of the pass)."""
    for row in range(task, height, n_tasks):
        last_r = last_g = last_b = np.float32(np.nan)
        y = 0.0
        for r in range(row * width, (row + 1) * width):
            cr, cg, cb = planes[C_R, r], planes[C_R + 1, r], planes[C_R + 2, r]
            if not (cr == last_r and cg == last_g and cb == last_b):
                y = _display_luminance(planes, r)
                last_r, last_g, last_b = cr, cg, cb
            lum[r] = y


@nb.njit(cache=True, nogil=True, _nrt=False)
def _pair_rows(task, n_tasks, planes, width, height, lum, depth_step, cos_jump, contrast,
               pairs):
    """Rows ``task, task + n_tasks, ...``: whether each pixel differs from its right (bit 0
    of ``pairs``) and lower (bit 1) neighbour."""
    for row in range(task, height, n_tasks):
        for col in range(width):
            r = row * width + col
            bits = 0
            if col + 1 < width and _differ(planes, lum, r, r + 1, depth_step, cos_jump,
                                           contrast):
                bits |= 1
            if row + 1 < height and _differ(planes, lum, r, r + width, depth_step, cos_jump,
                                            contrast):
                bits |= 2
            pairs[r] = bits


@nb.njit(cache=True, nogil=True, _nrt=False)
def _flag_rows(task, n_tasks, width, height, pairs, flag):
    """Rows ``task, task + n_tasks, ...``: a pixel is marked when a pair it is in differs
    (with its right or lower neighbour: its own bits; its left or upper: theirs)."""
    for row in range(task, height, n_tasks):
        for col in range(width):
            r = row * width + col
            flag[r] = ((pairs[r] != 0) or (col > 0 and (pairs[r - 1] & 1) != 0)
                       or (row > 0 and (pairs[r - width] & 2) != 0))
