"""The render's first stage: the scene's cages loaded and checked, the camera framed (around
the free-form surfaces too, and the directional lights' shadows on the ground), the cage
faces that can reach the image kept (the cull to the view, ``accel/cull.py``: primary rays
and the secondary rays that may leave a point in view), their patch table, the memory
budget checked against the pixels traced, and where secondary rays start
(:func:`prepare`); a crop's window (:func:`crop_window`). Orchestration: no maths here.
"""

from __future__ import annotations

import contextlib
import time
from collections import Counter

import numpy as np

from subtrace import config
from subtrace.accel.cull import casting_bounds, secondary_origins, secondary_reach, view_test
from subtrace.accel.projection import TILE
from subtrace.camera import CameraWindow
from subtrace.errors import SceneError
from subtrace.io.limits import check_coordinates, check_valences
from subtrace.mesh.cage import load_cage, placed, valence_bound, without_unused_vertices
from subtrace.nurbs.scene import has_faces, has_surfaces
from subtrace.patches.table import build_patch_table, cage_face_shells, restrict
from subtrace.picture import ground_plane, ground_shadow_points
from subtrace.reflect import scene_reflects
from subtrace.startup import warmup
from subtrace.tiles import check_crop
from subtrace.trace.budget import check_memory


def cage_objects(scene) -> list[int]:
    """Indices of the scene's objects that have a cage: all but OBJ files of free-form
    surfaces only (those render through ``nurbs/scene.py`` alone)."""
    return [k for k, o in enumerate(scene.objects)
            if not has_surfaces(o.mesh) or has_faces(o.mesh)]


def load_objects(scene):
    """Cages of the scene's objects (scheme / boundary overrides applied), in the order of
    :func:`cage_objects`, their coordinates checked and the vertices no face uses left out
    (``mesh.cage.without_unused_vertices``: checked first, so a message's vertex number
    is the file's). Objects that name one file with the same reading options (placed
    copies: ``[[object]]`` tables that differ in their placement alone) read it once, and
    their cages share its face lists, tags, materials and topology
    (``mesh.cage.placed``); each has its own points."""
    objects = [scene.objects[k] for k in cage_objects(scene)]
    keys = [_cage_key(o) for o in objects]
    uses = Counter(keys)
    loaded = {}
    cages = []
    for o, key in zip(objects, keys):
        if key not in loaded:
            loaded[key] = load_cage(o.mesh, scheme=o.scheme, boundary=o.boundary_code,
                                    prim=o.prim, time=o.time)
        c = placed(loaded[key], o.transform, shared=uses[key] > 1)
        check_coordinates(c.path, c.points, config.MAX_COORDINATE, c.points_box)
        cages.append(without_unused_vertices(c))
    return cages


def _cage_key(o):
    """What makes two objects' cages one cage as loaded (before their placements): the
    file and what its reading takes (scheme, boundary, a USD prim and time code)."""
    return (o.mesh, o.scheme, o.boundary_code, o.prim, o.time)


def scene_bounds(cages, nurbs=None):
    """(lo, hi) that the automatic camera frames: the bounds of the level-1 limit points of
    every object (the limit surface, not the cage), and of the free-form surfaces ``nurbs``
    (their patches' control points)."""
    bounds = [c.bounds() for c in cages]
    if nurbs is not None:
        bounds.append(nurbs.bounds())
    return np.min([b[0] for b in bounds], axis=0), np.max([b[1] for b in bounds], axis=0)


def check_extent(cages, lo, hi) -> None:
    """SceneError naming the cages when their limit surface's box [lo, hi] is a point
    (every vertex at one place): nothing an automatic camera could frame (its eye would
    be the point it looks at)."""
    scale = max(1.0, float(np.abs(lo).max()), float(np.abs(hi).max()))
    if float((hi - lo).max()) > 1e-12 * scale:
        return
    where = ", ".join(f"{v:.6g}" for v in lo)
    if len(cages) == 1:
        raise SceneError(f"the cage has no extent: its vertices all lie at one point "
                         f"({where}); nothing to frame", path=cages[0].path)
    names = ", ".join(str(c.path) for c in cages)
    raise SceneError(f"the cages {names} have no extent: their vertices all lie at one "
                     f"point ({where}); nothing to frame")


def faces_in_view(cages, camera, reach=None):
    """Per cage, a (F,) bool mask of the faces whose limit surface a primary ray may reach:
    the box that holds it (``patches.table.cage_face_shells``) projects into the image
    (``accel.projection.boxes_in_view``, the test the tile lists make). The patches of the
    other faces are never built (design invariant 5). ``reach``: None, or the
    :class:`~subtrace.accel.cull.Reach` of the scene's shadow and ambient occlusion rays
    (:func:`~subtrace.accel.cull.secondary_reach`): the faces those may meet from a point
    in view are kept too."""
    in_view = view_test(camera, reach)
    return [in_view(*cage_face_shells(c)) for c in cages]


def table_in_view(cages, camera, reach=None):
    """The patch table of what a ray of ``camera`` (or a secondary ray, with ``reach``) may
    reach: the patches of the cage faces in view (:func:`faces_in_view`) whose own
    one-ring box is in view too. Returns (table, the per-cage masks of the faces kept)."""
    keep = faces_in_view(cages, camera, reach)
    # (a large cage seen in part: its topology built around the faces kept alone)
    cut = [restrict(c, k) for c, k in zip(cages, keep)]
    return build_patch_table([c for c, _ in cut], [k for _, k in cut],
                             view_test(camera, reach)), keep


def _valences(cage):
    """Each vertex's valence for ``check_valences``: a bound from the face lists where it
    is within ``config.MAX_VALENCE`` (no topology built for it), else the exact ones."""
    bound = valence_bound(cage)
    return bound if bound.max(initial=0) <= config.MAX_VALENCE else np.diff(
        cage.base.vert_edge_offsets)


def prepare(scene, cages, stats, nurbs=None, crop=None, compiling=None):
    """Load and check the cages, frame the camera (around the free-form surfaces ``nurbs``
    too), build the patch table of the cage faces in view, check the budget against the
    pixels traced (the image's, or the window of its ``crop``: :func:`crop_window`):
    (cages, table (None without cages), camera, the camera or its window, tolerance in
    radians, budget in bytes, where secondary rays start: ``accel.cull.secondary_origins``,
    None without shadows or ambient occlusion). ``compiling``: the processes compiling the
    trace kernels (``warmup.start``), told the cages' schemes once they are loaded."""
    t_start = time.perf_counter()
    if cages is None:
        cages = load_objects(scene)
    warmup.tell(compiling, [c.scheme for c in cages])
    if not cages:
        lo, hi = nurbs.bounds()
        camera = scene.make_camera(lo, hi)
        view = camera if crop is None else crop_window(camera, crop, apron(scene))
        stats.rays = view.width * view.height
        stats.time_load = time.perf_counter() - t_start
        return cages, None, camera, view, scene.render.tolerance_rad(camera), None, None
    for c in cages:
        check_coordinates(c.path, c.points, config.MAX_COORDINATE, c.points_box)
        check_valences(c.path, c.face_sizes, _valences(c),
                       config.MAX_VALENCE, c.scheme == "catmark")
    stats.time_load = time.perf_counter() - t_start
    t0 = time.perf_counter()
    lo = hi = points = None
    if scene.camera.is_auto:
        # frame the limit surface: limit points of every object (level 2 on small cages,
        # whose level-1 points are too sparse to reach the silhouette), and the corners of
        # the box of the free-form surfaces' control points
        extra = []
        if nurbs is not None:
            b = nurbs.bounds()
            extra = [np.array([[b[i & 1][0], b[(i >> 1) & 1][1], b[i >> 2][2]]
                               for i in range(8)])]
        points = np.concatenate([c.limit(2 if c.n_faces < 20000 else 1 if c.n_faces < 200000
                                         else 0)[0] for c in cages] + extra)
        lo, hi = points.min(axis=0), points.max(axis=0)
        if scene.camera.eye is None and nurbs is None:
            check_extent(cages, lo, hi)
        # and the shadows on the ground; the eye outside every cage's box
        points = np.concatenate([points, ground_shadow_points(scene, cages, points, nurbs)])
        lo, hi = points.min(axis=0), points.max(axis=0)
    camera = scene.make_camera(lo, hi, points, [c.points_box for c in cages])
    # (shadow and ambient occlusion rays may meet what the camera does not see; the
    # ground's shadows are bounded by where the ground is)
    # (so may reflected rays, and from a point in view anything: no cull)
    mirror = scene_reflects(scene, cages, nurbs)
    secondary = bool(scene.lights and scene.render.shadows) or scene.render.ao > 0 or mirror
    with contextlib.ExitStack() as stack:  # (the ground's height and the cull share them)
        for c in cages:
            stack.enter_context(c.sharing_star_boxes())
        ground = ground_plane(scene, cages, camera, nurbs) if secondary else None
        reach = secondary_reach(scene, casting_bounds(cages, nurbs), camera,
                                ground if scene.lights and scene.render.shadows else None)
        if config.CULL_TO_VIEW and reach is not None and not mirror:
            table, keep = table_in_view(cages, camera, reach)
            stats.faces_culled = int(sum(np.count_nonzero(~k) for k in keep))
        else:
            table = build_patch_table(cages)
    budget = scene.render.max_memory
    budget = config.default_max_memory() if budget is None else budget
    view = camera if crop is None else crop_window(camera, crop, apron(scene))
    check_memory(table, view.width * view.height, budget, view.width, view.height)
    stats.patches = table.n_patches
    stats.rays = view.width * view.height
    # where shadow and ambient occlusion rays start: their cones refine what they reach
    # (patches.shells.Sight), from the whole image's camera (a crop's tiles alike)
    # (the shells: they hold the boxes the rays test, patches.table._ray_shells, so a
    # patch in view is no nearer the eye than ``near``, and keeps the eye's depth)
    seen = (secondary_origins(camera, table.shell_min, table.shell_max, ground,
                              None if nurbs is None else nurbs.bounds())
            if secondary else None)
    stats.time_preprocess = time.perf_counter() - t0
    return cages, table, camera, view, scene.render.tolerance_rad(camera), budget, seen


def crop_window(camera, crop, margin=1) -> CameraWindow:
    """The window of ``camera``'s image that :func:`render_scene` traces for ``crop`` =
    (x0, y0, x1, y1) (pixels, x1 and y1 excluded; checked: SceneError naming --crop): the
    crop and ``margin`` pixels around it (anti-aliasing compares each pixel with its right
    and lower neighbours: 1; smoothed ambient occlusion reads its neighbours within
    config.AO_SMOOTH_RADIUS more: :func:`apron`), widened to even bounds (the projection's
    tiles are 2x2 pixels of the image) and held within the image. Every pixel of the crop
    is then traced and shaded exactly as in the whole image."""
    x0, y0, x1, y1 = check_crop(crop, camera.width, camera.height)
    a = TILE
    wx0, wy0 = max(x0 - margin, 0) // a * a, max(y0 - margin, 0) // a * a
    wx1 = min(-(-(x1 + margin) // a) * a, camera.width)
    wy1 = min(-(-(y1 + margin) // a) * a, camera.height)
    return CameraWindow(camera, wx0, wy0, wx1 - wx0, wy1 - wy0)


def apron(scene) -> int:
    """The pixels a tile's window holds around the tile (:func:`crop_window`): none when a
    pixel's value is its own rays' alone (one ray a pixel, no ambient occlusion)."""
    if (scene.render.samples or 1) <= 1 and scene.render.ao <= 0:
        return 0
    return 1 + (config.AO_SMOOTH_RADIUS if scene.render.ao > 0 else 0)
