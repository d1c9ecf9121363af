"""Benchmark: what ray cones would allow the shadow and ambient-occlusion rays of cages.

    python benchmarks/cones.py [SCENE.toml ...]   (default: the default scene and four more)

A secondary ray that leaves a hit at distance ``t0`` from the eye carries the pixel's cone:
its width a distance ``s`` along the ray is ``tol_rad (t0 + s)``. Patches are refined per
patch, not per ray: a patch's grid depth is the one at which its cells subtend the
tolerance from the eye at the nearest point of its shell (``patches/criterion.py``), and
every ray that meets it, primary or secondary, meets the same micro-surface
(``trace/rays.py``). By the triangle inequality the cone is never narrower there than the
eye's criterion, so that depth is the tightest one that serves every ray that may reach
the patch; a ray whose cone is wider could have used a coarser grid of its own.

This script renders each scene with its own lights, shadows and ambient occlusion and,
for every secondary ray that a cage occludes, compares the cone's width where it meets
the occluder with the width the patch's depth was chosen for (the eye's distance to the
patch's shell times ``tol_rad``), and the depth the cone alone would have chosen for that
patch (the criterion's own formula with the cone's width) with the patch's grid depth.
The table says how much coarser per-ray grids could be: the ratio's median, 99th
percentile and maximum, and the share of occluded rays whose cone would choose a grid
one level coarser, or two or more (the patch's depth can also stand above its own
criterion: edge sampling raises a patch towards its neighbours' depths, and isolation
rounds up).
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
from _common import REPO, import_subtrace

DEFAULT = ["src/subtrace/data/default_scene.toml", "scenes/spot_ao.toml",
           "scenes/creases.toml", "scenes/sword.toml", "scenes/torus_loop.toml"]


def measure(path: str) -> dict:
    """Render the scene at ``path``; the occluded secondary rays' cone figures."""
    import_subtrace()
    from subtrace import picture, render
    from subtrace.io.scene import load_scene
    from subtrace.patches.shells import box_distance

    ratios, coarser = [], []
    traced = picture.trace_rays

    def spy(pools, origins, dirs, tmax, any_hit):
        blocked, hits = traced(pools, origins, dirs, tmax, any_hit)
        occluded = (blocked > 0) & (hits.prim <= -2)  # (prim = -2 - the patch hit)
        if occluded.any():
            patch = -2 - hits.prim[occluded].astype(np.int64)
            o = np.asarray(origins).reshape(-1, 3)[occluded]
            width = (np.linalg.norm(o - pools.eye, axis=1) + hits.t[occluded]) * pools.tol_rad
            eye_width = pools.tol_rad * box_distance(pools.shell_min[patch],
                                                     pools.shell_max[patch], pools.eye)
            ratios.append(width / np.maximum(eye_width, 1e-300))
            bound, rate = pools.table.edge_bound[patch], pools.table.rate[patch]
            with np.errstate(divide="ignore", invalid="ignore"):
                cone = np.ceil(np.log(width / bound) / np.log(rate) - 1e-9)
            cone = np.where(width >= bound, 0.0, cone)
            coarser.append(pools.depths[patch] - cone)
        return blocked, hits

    picture.trace_rays = spy
    try:
        render.render_scene(load_scene(path), threads=2)
    finally:
        picture.trace_rays = traced
    if not ratios:
        return {"rays": 0}
    r, c = np.concatenate(ratios), np.concatenate(coarser)
    return {"rays": len(r), "median": float(np.median(r)), "p99": float(np.percentile(r, 99)),
            "max": float(r.max()), "one": float(np.mean(c == 1)), "more": float(np.mean(c >= 2))}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=[str(REPO / p) for p in DEFAULT])
    args = ap.parse_args(argv)
    print("| scene | occluded rays | cone / criterion width: median | p99 | max "
          "| cone's grid 1 level coarser | 2+ levels |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for path in args.scenes:
        m = measure(path)
        name = path.rsplit("/", 1)[-1]
        if not m["rays"]:
            print(f"| {name} | 0 | - | - | - | - | - |")
            continue
        print(f"| {name} | {m['rays']:,} | {m['median']:.3f} | {m['p99']:.3f} | {m['max']:.3f} "
              f"| {100 * m['one']:.1f} % | {100 * m['more']:.1f} % |")
        sys.stdout.flush()


if __name__ == "__main__":
    main()
