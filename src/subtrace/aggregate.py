"""The scene aggregate: everything a secondary ray can meet, the cages and the free-form
(NURBS) surfaces together, behind two questions that every secondary ray of the picture
asks (shadow rays, ambient occlusion, the extra anti-aliasing rays, reflected rays):

* :meth:`SceneAggregate.occluded`: any-hit rays, blocked or not before their ends; the
  cages first (the BVH of the shells, ``trace.rays.trace_rays``, which builds what the
  rays reach by the narrowest cone that can reach it), then, for the rays no cage blocks,
  the free-form surfaces (``nurbs.scene.blocked``), each ray with its cone: its width at
  its origin ``|origin - eye| * tol_rad``, the footprint of the hit it leaves;
* :meth:`SceneAggregate.closest`: the closest hits, shaded: the cages' (their normals,
  patches and image textures: ``shade.shade``, ``textures.texture_hits``), then the
  free-form surfaces' where nearer (``nurbs.scene.shade_rays``). Rays from the eye (the
  extra anti-aliasing rays, with every channel of the shading) or from any points (the
  reflected rays, whose cones widen along their paths from the eye).

Both answer ray by ray in the order given, whatever the threads.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from subtrace.nurbs.scene import blocked as nurbs_blocked
from subtrace.nurbs.scene import shade_rays
from subtrace.runtime.threads import thread_count
from subtrace.shade import CHANNELS, shade
from subtrace.textures import texture_hits
from subtrace.geometry.bezier import table_loop_flag
from subtrace.trace.rays import trace_rays


class Closest(NamedTuple):
    """The closest hits of n rays (:meth:`SceneAggregate.closest`)."""

    t: np.ndarray  # (n,) float64 the distance along the ray, inf: none
    normals: np.ndarray  # (n,3) float64 unit, towards the ray's origin (bump and normal maps)
    patch: np.ndarray  # (n,) int32 the row of the patch shading (-1: none)
    planes: np.ndarray | None  # (len(CHANNELS), n) float32 but the colour; None: not from the eye
    texel: np.ndarray | None  # the image textures' colours (textures.texture_hits), or None


class SceneAggregate:
    """The cages (``pools``: the picture's ``trace.rays.Pools``, None: none) and the free-form
    surfaces (``nurbs``: ``nurbs.scene.NurbsScene``, None: none) of a picture seen through
    ``frame`` (``camera.frame()``) at the angular tolerance ``tol_rad``; ``patches``: the
    patch shading (``shade.PatchShading``), the free-form surfaces' rows from ``offset``;
    ``miss``: what a ray that hits nothing holds (``shade.miss_values``); ``textures``: the
    patches' image textures (``textures.texture_sets``; None: none), looked up over the
    rays' cones (``pixel_angle``: a pixel's angle)."""

    def __init__(self, pools, nurbs, frame, tol_rad, patches=None, offset=0, miss=None,
                 textures=None, pixel_angle=0.0):
        self.pools, self.nurbs, self.frame = pools, nurbs, frame
        self.tol_rad, self.patches, self.offset = float(tol_rad), patches, offset
        self.miss = np.zeros(len(CHANNELS), np.float32) if miss is None else miss
        self.textures, self.pixel_angle = textures, float(pixel_angle)
        self.bounds = _bounds(pools, nurbs)

    def occluded(self, origins, dirs, tmax) -> np.ndarray:
        """(n,) uint8: whether the ray ``origins + s dirs`` (unit ``dirs``) meets a cage or a
        free-form surface for some 0 < s < ``tmax`` (see the module comment)."""
        out = np.zeros(len(tmax), np.uint8)
        if self.pools is not None:
            out = trace_rays(self.pools, origins, dirs, tmax, any_hit=True)[0]
        if self.nurbs is not None:
            rest = np.nonzero(out == 0)[0]
            if len(rest):
                o = np.asarray(origins)[rest]
                cone = np.sqrt(((o - self.frame[0]) ** 2).sum(axis=1)) * self.tol_rad
                out[rest] = nurbs_blocked(self.nurbs, o, np.asarray(dirs)[rest],
                                          np.asarray(tmax)[rest], cone, self.tol_rad)
        return out

    def closest(self, dirs, origins=None, length=None) -> Closest:
        """The closest hits of the rays along the unit ``dirs`` (n,3): from the eye
        (``origins`` None: the shading's every channel but the colour in ``planes``, as the
        centre rays' pass writes them) or from ``origins`` (n,3), each ``length`` (n,) from
        the eye along its path (the width of its cone at its origin is ``length *
        tol_rad``; ``planes`` None)."""
        n = len(dirs)
        from_eye = origins is None
        if from_eye:
            origins = np.repeat(self.frame[0][None], n, axis=0)
        planes = np.empty((len(CHANNELS), n), np.float32)
        normals = np.zeros((n, 3))
        patch = np.full(n, -1, np.int32)
        t = np.full(n, np.inf)
        texel = None
        if self.pools is None or not n:
            planes[:] = self.miss[:, None]
        else:
            pools = self.pools
            _, hits = trace_rays(pools, origins, dirs, np.full(n, np.inf), any_hit=False)
            covered = np.zeros(thread_count(), np.int64)
            shade(self.frame, 1, hits, pools.iso.view(), self.patches, self.miss, planes,
                  normals, patch, covered, dirs, table_loop_flag(pools.table),
                  table=pools.table)
            # (the cone at a hit: as wide as the path from the eye makes it)
            seen = hits if from_eye else hits._replace(t=hits.t + length)
            texel = texture_hits(self.textures, pools.table, seen, pools.iso.view(),
                                 self.patches, self.frame, 1, dirs, self.pixel_angle, normals,
                                 planes)
            t = hits.t.copy()
        if self.nurbs is not None and n:
            shade_rays(self.nurbs, self.frame, dirs, self.tol_rad, self.offset, t, normals,
                       patch, planes if from_eye else None, origins,
                       None if from_eye else length * self.tol_rad)
            if texel is not None:  # (a free-form surface's hits take no texture)
                texel[patch >= self.offset] = -1.0
        return Closest(t, normals, patch, planes if from_eye else None, texel)


def _bounds(pools, nurbs):
    """(lo, hi) of a box that holds everything an any-hit ray can meet: the roots of the
    shells' BVH and of the free-form surfaces' BVH, grown by a relative 1e-9 (a ray whose
    segment misses it is unblocked, and need not be traced); None where there is nothing
    to hit (then nothing is left out: there is nothing to trace either)."""
    roots = [b for b in ((None if pools is None else pools.bvh),
                         (None if nurbs is None else nurbs.bvh))
             if b is not None and len(b.node_count)]
    if not roots:
        return None
    lo = np.min([b.node_min[0] for b in roots], axis=0)
    hi = np.max([b.node_max[0] for b in roots], axis=0)
    pad = 1e-9 * (float(np.max(hi - lo)) + float(np.max(np.abs(np.concatenate([lo, hi])))))
    return lo - pad, hi + pad
