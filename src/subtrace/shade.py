"""Shading: rebuild position, normal, ids and colour from the hits (pbrt habit: the
intersection kernels return only t, the micro-face and its barycentrics).

A hit on a Bezier piece or a Loop triangular net takes the exact normal of its net at the
hit's parameter. On a cell (of an irregular patch) the normal interpolates the exact unit
limit normals of the cell's corners (computed from the limit tangents of the subdivision
core) with the hit's barycentrics, so it is within the tolerance's angle of the limit normal at that point; where the limit
tangents leave a corner's normal undefined, the micro-triangle's own normal is used.
Lighting is Lambertian, two-sided: a headlight at the eye plus directional lights.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from subtrace.io.obj import DEFAULT_DIFFUSE
from subtrace.patches.basis import bez_normal
from subtrace.runtime.jit import nb
from subtrace.runtime.threads import run_tasks
from subtrace.trace.prims import ray_setup
from subtrace.trace.tris import LOOP_CELL, TRI, tri_normal


# the planes the shading fills, in this order, and what a pixel whose ray missed holds
# (R, G, B: the background colour)
CHANNELS = ("R", "G", "B", "A", "Z", "N.X", "N.Y", "N.Z", "level", "patch_id", "object_id",
            "u", "v")
C_R, C_A, C_Z, C_N, C_LEVEL, C_PATCH, C_OBJECT, C_U = 0, 3, 4, 5, 8, 9, 10, 11
MISS = (0.0, 0.0, 0.0, 0.0, np.inf, 0.0, 0.0, 0.0, -1.0, -1.0, -1.0, 0.0, 0.0)


def shade(frame, width, hits, iso, patches, lights, headlight, miss, planes, covered):
    """Fill ``planes`` (len(CHANNELS), n_pixels) float32 from ``hits``
    (:class:`~subtrace.trace.pools.Hits`) on every thread (blocks of pixels in turn).

    ``iso``: the built patches' items (:class:`~subtrace.trace.pools.PieceArrays`);
    ``patches``: per patch, its ids and colour (:class:`PatchShading`); ``lights`` (L,6):
    direction the light travels (unit) and its colour times intensity; ``headlight`` (1,);
    ``miss`` (:func:`miss_values`); ``covered`` (threads,) int64 receives the hits each
    thread shaded."""
    run_tasks(_shade_task, frame, width, hits, iso, patches, lights, headlight, miss, planes,
              covered)


class PatchShading(NamedTuple):
    """Per patch (P,): what the shading writes besides the geometry."""

    object_id: np.ndarray  # (P,) int32
    ptex: np.ndarray  # (P,) int32: ptex face
    uv0: np.ndarray  # (P,2) float64: the patch's origin in its ptex face
    scale: np.ndarray  # (P,) float64: the patch's size in its ptex face
    level0: np.ndarray  # (P,) int8: the patch level (0, or 1 for split n-gons)
    color: np.ndarray  # (P,3) float64: diffuse colour


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


@nb.njit(cache=True, nogil=True)
def _shade_task(task, n_tasks, frame, width, hits, iso, patches, lights, headlight, miss, planes,
                covered):
    """Shade the blocks of pixels ``task, task + n_tasks, ...`` into ``planes`` (see
    :func:`shade`): each block is first filled with ``miss`` (contiguous stores), then its
    hits are shaded over it."""
    n_pix = len(hits.t)
    n_blocks = (n_pix + SHADE_BLOCK - 1) // SHADE_BLOCK
    n_hit = 0
    for blk in range(task, n_blocks, n_tasks):
        b0 = blk * SHADE_BLOCK
        b1 = min(n_pix, b0 + SHADE_BLOCK)
        for k in range(planes.shape[0]):
            planes[k, b0:b1] = miss[k]
        for r in range(b0, b1):
            t = hits.t[r]
            if not (t < np.inf):
                continue
            n_hit += 1
            planes[C_Z, r] = t
            row = r // width
            col = r - row * width
            dx, dy, dz = ray_setup(frame, row, col)
            # the patch and item hit, (a, b) the patch parameter
            p = -hits.prim[r] - 2
            u = hits.a[r]
            v = hits.b[r]
            depth = hits.leaf[r]
            it = hits.item[r]
            c = iso.ref[it]
            if iso.kind[it] == TRI:
                # a Loop patch or piece: the normal of its triangular net at its own
                # (s, t) (trace/tris.py: the patch's (u, v) = (A + g (s, t)) 2^-level)
                sc = 1 << iso.level[it]
                g = np.float64(iso.orient[it])
                nx, ny, nz = tri_normal(iso.nets.reshape((len(iso.nets), 16, 3)), c,
                                        g * (u * sc - iso.i0[it]), g * (v * sc - iso.j0[it]))
            elif iso.kind[it] == LOOP_CELL:
                g = np.float64(iso.orient[it])
                nx, ny, nz = _tri_cell_normal(iso.cells[4 * c:4 * c + 3],
                                              iso.cell_normals[c],
                                              g * (u * (1 << depth) - iso.i0[it]),
                                              g * (v * (1 << depth) - iso.j0[it]))
            elif iso.kind[it] == 0:
                # a Bezier piece over a dyadic square of the patch (the whole of a regular one)
                sc = 1 << iso.level[it]
                nx, ny, nz = bez_normal(iso.nets[c], u * sc - iso.i0[it], v * sc - iso.j0[it])
            else:
                nx, ny, nz = _cell_normal(iso.cells[4 * c:4 * c + 4], iso.cell_normals[c],
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
            # two-sided Lambert: headlight plus directional lights
            sgn = -1.0 if nx * dx + ny * dy + nz * dz > 0.0 else 1.0
            fx, fy, fz = sgn * nx, sgn * ny, sgn * nz
            lr = lg = lb = 0.0
            if headlight[0] > 0.0:
                c = -(fx * dx + fy * dy + fz * dz) * headlight[0]
                lr += c
                lg += c
                lb += c
            for k in range(lights.shape[0]):
                c = -(fx * lights[k, 0] + fy * lights[k, 1] + fz * lights[k, 2])
                if c > 0.0:
                    lr += c * lights[k, 3]
                    lg += c * lights[k, 4]
                    lb += c * lights[k, 5]
            planes[C_R, r] = patches.color[p, 0] * lr
            planes[C_R + 1, r] = patches.color[p, 1] * lg
            planes[C_R + 2, r] = patches.color[p, 2] * lb
            planes[C_A, r] = 1.0
    covered[task] = n_hit


@nb.njit(cache=True)
def _cell_normal(pts, nrm, a, b):
    """Bilinear blend of a cell's exact corner normals at (a, b) in [0,1]^2 (corner order
    (0,0), (1,0), (1,1), (0,1)); the cell's own normal where a corner's is undefined."""
    w0, w1, w2, w3 = (1 - a) * (1 - b), a * (1 - b), a * b, (1 - a) * b
    nx = w0 * nrm[0, 0] + w1 * nrm[1, 0] + w2 * nrm[2, 0] + w3 * nrm[3, 0]
    ny = w0 * nrm[0, 1] + w1 * nrm[1, 1] + w2 * nrm[2, 1] + w3 * nrm[3, 1]
    nz = w0 * nrm[0, 2] + w1 * nrm[1, 2] + w2 * nrm[2, 2] + w3 * nrm[3, 2]
    ln = math.sqrt(nx * nx + ny * ny + nz * nz)
    if not (ln > 0.0):
        # diagonals' cross product
        ax, ay, az = pts[2, 0] - pts[0, 0], pts[2, 1] - pts[0, 1], pts[2, 2] - pts[0, 2]
        bx, by, bz = pts[3, 0] - pts[1, 0], pts[3, 1] - pts[1, 1], pts[3, 2] - pts[1, 2]
        nx, ny, nz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
        ln = math.sqrt(nx * nx + ny * ny + nz * nz)
    if ln > 0.0:
        return nx / ln, ny / ln, nz / ln
    return 0.0, 0.0, 0.0


@nb.njit(cache=True)
def _tri_cell_normal(pts, nrm, b, c):
    """Blend of a Loop cell's exact corner normals at barycentrics (1 - b - c, b, c); the
    cell's own normal where a corner's is undefined."""
    a = 1.0 - b - c
    nx = a * nrm[0, 0] + b * nrm[1, 0] + c * nrm[2, 0]
    ny = a * nrm[0, 1] + b * nrm[1, 1] + c * nrm[2, 1]
    nz = a * nrm[0, 2] + b * nrm[1, 2] + c * nrm[2, 2]
    ln = math.sqrt(nx * nx + ny * ny + nz * nz)
    if not (ln > 0.0):
        ax, ay, az = pts[1, 0] - pts[0, 0], pts[1, 1] - pts[0, 1], pts[1, 2] - pts[0, 2]
        bx, by, bz = pts[2, 0] - pts[0, 0], pts[2, 1] - pts[0, 1], pts[2, 2] - pts[0, 2]
        nx, ny, nz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
        ln = math.sqrt(nx * nx + ny * ny + nz * nz)
    if ln > 0.0:
        return nx / ln, ny / ln, nz / ln
    return 0.0, 0.0, 0.0


def patch_shading(table, overrides) -> PatchShading:
    """Per patch of ``table``: its ids, ptex placement and colour: its object's colour
    ``overrides[object id]`` where that is not None, else its material's diffuse colour."""
    colors = np.empty((table.n_patches, 3))
    for oid, o in enumerate(table.objects):
        sl = slice(o.first_patch, o.first_patch + len(o.patch_faces))
        override = overrides[oid]
        if override is not None:
            colors[sl] = override
            continue
        mats = o.cage.materials
        table_rgb = np.array([m.diffuse for m in mats] + [DEFAULT_DIFFUSE], dtype=np.float64)
        mat = table.material[sl]
        colors[sl] = table_rgb[np.where(mat >= 0, mat, len(mats))]
    return PatchShading(table.object_id, table.ptex, table.ptex_uv0, table.ptex_scale,
                        table.level0, colors)
