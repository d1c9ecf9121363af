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

The criterion now takes each patch's distance from where the rays that may reach it come
from (``patches.shells.Sight``): the eye's distance, or, when larger, the least distance
from the eye of a point in view plus the patch's gap to the box of those points. The
table's "criterion width" is that distance times ``tol_rad``.

    python benchmarks/cones.py --side-by-side [--rounds N]

renders the canopy scene (Spot on the ground under a sun, and the sword laid flat above
and behind the camera, out of the picture, its shadow thrown onto the ground in view;
written by the script) and the default scene, alternating the depths chosen with the
cones (as subtrace renders) and from the eye alone, in one process, N rounds (default
5) after a warm-up: medians of the shadow rays' time and the whole render's, what the
secondary rays built and how deep, and the pixels whose colour differs.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
from pathlib import Path

from _common import REPO, import_subtrace

MODELS = REPO / "models"
SWORD = MODELS / "sword_quad_dominant.obj"

DEFAULT = ["src/subtrace/data/default_scene.toml", "scenes/spot_ao.toml",
           "scenes/creases.toml", "scenes/sword.toml", "scenes/torus_loop.toml"]


def measure(path: str) -> dict:
    """Render the scene at ``path``; the occluded secondary rays' cone figures."""
    import_subtrace()
    from subtrace import picture, render
    from subtrace.io.scene import load_scene
    from subtrace.patches.shells import eye_point, sight_distance

    ratios, coarser = [], []
    traced = picture.trace_rays

    def spy(pools, origins, dirs, tmax, any_hit):
        blocked, hits = traced(pools, origins, dirs, tmax, any_hit)
        occluded = (blocked > 0) & (hits.prim <= -2)  # (prim = -2 - the patch hit)
        if occluded.any():
            patch = -2 - hits.prim[occluded].astype(np.int64)
            o = np.asarray(origins).reshape(-1, 3)[occluded]
            width = ((np.linalg.norm(o - eye_point(pools.eye), axis=1) + hits.t[occluded])
                     * pools.tol_rad)
            eye_width = pools.tol_rad * sight_distance(pools.shell_min[patch],
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


def write_canopy(folder) -> str:
    """Write the canopy scene into ``folder`` (module comment); returns its path. The
    sword (blade turned flat, twice its size) hangs 1.2 above and 0.8 behind the eye of
    Spot's scene; the sun shines from it onto the ground seen at the middle of the
    picture's lower fifth."""
    import_subtrace()
    from subtrace.io.scene import load_scene

    spot = load_scene(str(REPO / "scenes" / "spot.toml"))
    cam = spot.camera
    eye, target = np.asarray(cam.eye, float), np.asarray(cam.target, float)
    back = (eye - target) / np.linalg.norm(eye - target)
    centre = eye + 0.8 * back + [0.0, 1.2, 0.0]
    lines = []
    for ln in open(SWORD):
        if ln.startswith("v "):
            x, y, z = map(float, ln.split()[1:4])
            p = centre + 2.0 * np.array([-y, x, z])  # (the blade's side faces up)
            ln = f"v {p[0]:.9g} {p[1]:.9g} {p[2]:.9g}\n"
        lines.append(ln)
    folder = Path(folder)
    (folder / "sword_canopy.obj").write_text("".join(lines))
    # the ground point seen at (0.5, 0.8) of the picture (Spot's lowest limit point, 0.70
    # below its cage's centre, is the ground's height)
    right = np.cross(target - eye, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    fwd = (target - eye) / np.linalg.norm(target - eye)
    up = np.cross(right, fwd)
    half = np.tan(np.radians(cam.fov_deg) / 2.0)
    ray = fwd - 0.6 * half * up
    height = -0.7
    ground = eye + (height - eye[1]) / ray[1] * ray
    sun = ground - centre
    text = (Path(REPO / "scenes" / "spot.toml").read_text()
            .replace("../models/", str(MODELS) + "/")
            .replace("[camera]", "[[object]]\nmesh = \"sword_canopy.obj\"\n"
                     "color = [0.75, 0.75, 0.8]\n\n[camera]")
            .replace("direction = [-0.4, -1.0, -0.5]",
                     f"direction = [{sun[0]:.6g}, {sun[1]:.6g}, {sun[2]:.6g}]")
            .replace('output = "spot.exr"', 'output = "canopy.exr"'))
    path = folder / "canopy.toml"
    path.write_text(text)
    return str(path)


def side_by_side(paths, rounds: int) -> None:
    """The ``--side-by-side`` table (module comment)."""
    import statistics

    import_subtrace()
    from subtrace import render
    from subtrace.io.scene import load_scene

    from subtrace import picture

    with_cones, traced = render.secondary_origins, picture.trace_rays
    last = {}

    def spy(pools, *args, **kwargs):  # (the depths the render chose: the last object's)
        obj = pools.table.object_id == pools.table.object_id.max()
        last["depths"] = pools.depths[obj]
        return traced(pools, *args, **kwargs)

    def once(path, cones):
        render.secondary_origins = with_cones if cones else (lambda *a, **k: None)
        picture.trace_rays = spy
        try:
            res = render.render_scene(load_scene(path), threads=2)
        finally:
            render.secondary_origins, picture.trace_rays = with_cones, traced
        return res, last["depths"]

    print("| scene | depths | shadows s | render s | secondary micro-triangles "
          "| secondary deepest grid | last object's depths: mean / max | pixels differing |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for path in paths:
        runs = {True: [], False: []}
        for r in range(rounds + 1):
            for cones in ((True, False) if r % 2 else (False, True)):
                res = once(path, cones)
                if r:
                    runs[cones].append(res)
        rgb = [np.stack([runs[c][0][0].channels[k] for k in "RGB"]) for c in (True, False)]
        differ = int(np.count_nonzero((rgb[0] != rgb[1]).any(axis=0)))
        name = path.rsplit("/", 1)[-1]
        for cones in (True, False):
            st = [x[0].stats for x in runs[cones]]
            depths = runs[cones][0][1]
            print(f"| {name} | {'cones' if cones else 'eye'} "
                  f"| {statistics.median(s.time_shadows for s in st):.3f} "
                  f"| {statistics.median(s.time_total for s in st):.3f} "
                  f"| {st[0].secondary_micro_triangles:,} | {st[0].secondary_max_depth} "
                  f"| {depths.mean():.2f} / {depths.max()} | {differ:,} |")
        sys.stdout.flush()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=[str(REPO / p) for p in DEFAULT])
    ap.add_argument("--side-by-side", action="store_true")
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args(argv)
    if args.side_by_side:
        import tempfile

        with tempfile.TemporaryDirectory() as folder:
            paths = [write_canopy(folder), str(REPO / DEFAULT[0])]
            side_by_side(paths, args.rounds)
        return
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
