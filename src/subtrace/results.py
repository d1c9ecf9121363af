"""What a render returns: its counts and timings (:class:`RenderStats`), its channels and
camera (:class:`RenderResult`), and the EXR header attributes of both
(:func:`result_attributes`). ``render.py`` fills them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


@dataclass
class RenderStats:
    time_load: float = 0.0
    time_preprocess: float = 0.0
    time_refine: float = 0.0
    time_trace: float = 0.0
    time_shade: float = 0.0
    time_total: float = 0.0
    patches: int = 0  # patches built into the table (those in view, of cage faces in view)
    faces_culled: int = 0  # cage faces outside the view, whose patches were never built
    patches_refined: int = 0
    # built: 2 per cell a thread tested first (its corners evaluated and kept, or a fan
    # counted once) or isolated
    # (threads take bands as they are free, so with several threads the count may differ
    # slightly between runs)
    micro_triangles: int = 0
    pieces: int = 0  # regular sub-patches and cells of the isolated irregular patches
    memo_nodes: int = 0  # quadtree nodes of Bezier pieces split and kept by the threads
    memo_full: int = 0  # times a thread's memo ran out during a round (rays split on the spot)
    memo_bytes: int = 0  # the most bytes the memos' stores held at once (summed over threads)
    rounds: int = 0
    max_depth: int = 0  # the deepest grid built (in its patch's units)
    max_level: int = -1  # the deepest level hit: the level channel's maximum (-1: none)
    # the deepest grid depth a cap held a patch to, below what its tolerance asked (-1: no
    # cap), and why: "memory" (the budget), "precision" (what doubles resolve, config:
    # PRECISION_BITS), "size" (Loop patches: LOOP_MAX_ISOLATED_DEPTH, LOOP_MAX_INSIDE_DEPTH),
    # "depth" (an explicit maximum depth), comma-separated, or "none"
    depth_cap: int = -1
    depth_cap_reason: str = "none"
    # 1: the projection's tile lists did not fit the memory budget, so rays walked the BVH
    accel_fallback: int = 0
    pixels_covered: int = 0
    rays: int = 0
    shadow_rays: int = 0  # shadow rays traced (towards every light from lit-facing hits;
    # the ground's only where they may meet an object: shade.ground_pixels)
    time_shadows: float = 0.0  # of time_shade: tracing shadow rays (building included)
    aa_pixels: int = 0  # pixels that got more than their centre ray (--samples)
    aa_rays: int = 0  # the extra rays they got
    time_aa: float = 0.0  # of time_shade: tracing and shading the extra rays
    ao_rays: int = 0  # ambient occlusion rays traced ([render] ao per hit, extra rays too)
    time_ao: float = 0.0  # of time_shade: tracing them (building included)
    reflection_rays: int = 0  # reflected rays traced (every bounce; subtrace.reflect)
    time_reflections: float = 0.0  # of time_shade: tracing and shading them
    # built for secondary rays (shadow and anti-aliasing rays: patches no primary ray had
    # reached, micro-triangles they evaluated), not counted in the primary counts above
    secondary_patches_refined: int = 0
    secondary_micro_triangles: int = 0
    # the deepest grid (in its patch's units, as max_depth) secondary rays reached: where
    # they found their hits or occluders, and what they built (-1: no secondary ray hit)
    secondary_max_depth: int = -1

    def as_attributes(self) -> dict:
        return {f"subtrace:{k}": v for k, v in self.__dict__.items()}


@dataclass
class RenderResult:
    channels: dict  # name -> (H,W) float32
    stats: RenderStats
    camera: object
    tolerance_rad: float
    schemes: tuple
    refined_objects: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    accel: str = "projection"  # how rays found the shells they enter
    # object id of every refined patch (what was built, for tests and reports)
    # crop: (x0, y0, x1, y1), the pixels of ``camera``'s image the channels hold; None: all
    crop: tuple | None = None


# the colour channels are linear Rec.709 / sRGB primaries with a D65 white point
REC709_CHROMATICITIES = (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290)


def result_attributes(result: RenderResult, scene) -> dict:
    """EXR header attributes of a render: camera (``worldToCamera``, ``worldToNDC``),
    ``chromaticities``, what ``Z`` holds, tolerance, schemes, the meshes' file names,
    timings and counts."""
    attrs = dict(result.camera.header_attributes())
    attrs["subtrace:tolerance_rad"] = float(result.tolerance_rad)
    attrs["subtrace:tolerance_px"] = float(result.tolerance_rad / result.camera.pixel_angle())
    attrs["subtrace:scheme"] = ",".join(result.schemes)
    # file names only: a header travels with the image, the user's folders need not
    attrs["subtrace:meshes"] = ";".join(Path(o.mesh).name for o in scene.objects)
    attrs["chromaticities"] = REC709_CHROMATICITIES
    attrs["subtrace:Z"] = ("distance from the eye along the pixel's ray (not camera-space z): "
                           "its centre ray, or where that missed, its nearest "
                           "anti-aliasing ray that hit")
    attrs["subtrace:P"] = ("world-space hit point of that ray, eye + Z * its unit "
                           "direction; NaN where no ray of the pixel hit (Z = +inf)")
    attrs["subtrace:accel"] = result.accel
    attrs["subtrace:samples"] = int(scene.render.samples or 1)  # rays per edge pixel at most
    attrs["subtrace:shadows"] = int(bool(scene.render.shadows and scene.lights))
    attrs["subtrace:ao"] = int(scene.render.ao)  # ambient occlusion rays per hit (0: none)
    if result.crop is not None:  # (the file's data window, in its display window)
        attrs["subtrace:crop"] = " ".join(map(str, result.crop))
    for k, v in result.stats.__dict__.items():
        attrs[f"subtrace:{k}"] = (v if isinstance(v, str) else float(v) if isinstance(v, float)
                                  else int(v))
    return attrs
