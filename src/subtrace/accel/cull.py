"""What the cull to the view keeps: the boxes a primary ray may enter, and those a secondary
ray leaving a point in view may meet (``render.faces_in_view``; design invariant 5).

A box is kept when its pixel rectangle meets the image (``projection.boxes_in_view``, the
test the tile lists make) or when a secondary ray from a point in view may reach it:

* **ambient occlusion** rays travel at most ``distance`` (``config.AO_DISTANCE`` times the
  scene's diagonal): a box that blocks one lies within that distance of a point in view, so
  the box grown by it reaches the view;
* **shadow rays** towards a directional light leave a point ``q`` in view along the light's
  reverse travel ``-d``. A box that blocks one holds a point ``q - s d`` (``0 < s``), so

  - swept along ``d`` over twice the scene's diagonal (the longest way between an object and
    a point it shades), it reaches the view (the box of the sweep is tested); and
  - without a ground plane (the points in view are then surface points of the objects, in
    the box ``B`` of the scene), seen along ``d`` it overlaps the points in view: those lie
    in the camera's pyramid cut to the depths of ``B``'s corners, whose eight corners bound
    them, and in ``B``. In a frame ``(e1, e2, d)`` the box's extent along ``e1`` and
    ``e2`` must meet both the pyramid's and ``B``'s, and its least ``d`` must not exceed
    the pyramid's greatest (a shadow ray leaves towards the light, so what blocks it is
    nearer the light). A ground plane in view may reach the horizon: its points are not
    bounded so, and the sweep alone decides.

* **shadow rays** towards a point light at ``L`` leave ``q`` towards ``L``: a box that
  blocks one holds a point of the segment, which the light sees in the same direction as
  ``q`` and nearer. Without a ground plane, the light's view of the points in view is
  bounded by the central projections of the pyramid's and ``B``'s corners (of those lying
  wholly in front of the light, along its axis towards them): a box is kept when it
  projects into that view (``projection.boxes_in_view`` with the light as the eye; a box
  reaching the light's plane is kept) and is not wholly deeper than those corners.

A point light above a ground plane, or one among the points in view (neither projection
lies in front of it), is not bounded so: such scenes are not culled (:func:`secondary_reach`
gives None).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from subtrace import config
from subtrace.accel.projection import boxes_in_view
from subtrace.camera import camera_frame

# pixels of margin around the image for the pyramid's corners (the tile lists widen a box's
# rectangle by one pixel for rounding; half a pixel more reaches the pixels' outer edges)
_PYRAMID_MARGIN = 2.0


@dataclass
class Reach:
    """How far secondary rays from the points in view may go (module comment): ``grow``
    the ambient occlusion distance (0: none); per directional light, ``sweeps`` (3,) its
    travel over twice the scene's diagonal and ``light_frames`` (None: a ground plane)
    ``(axes (3,3): rows e1, e2, d; lo (3,), hi (3,))``, the extent of the points in view
    along e1 and e2 and the greatest along d; per point light, ``point_views``
    ``(frame (4,3), n, axis (3,), depth)``: the light's view of the points in view as an
    n x n image (``projection.boxes_in_view``'s frame) and their greatest depth along its
    axis."""

    grow: float = 0.0
    sweeps: list = field(default_factory=list)
    light_frames: list | None = None
    point_views: list = field(default_factory=list)


def casting_bounds(cages, nurbs=None):
    """(lo, hi): the box of the cages' control points (which holds their limit surfaces)
    and of the free-form surfaces ``nurbs``' patches: all that casts or receives."""
    boxes = [(c.points.min(axis=0), c.points.max(axis=0)) for c in cages]
    if nurbs is not None:
        boxes.append(nurbs.bounds())
    return np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)


def secondary_reach(scene, bounds, camera) -> Reach | None:
    """The :class:`Reach` of ``scene``'s shadow and ambient occlusion rays seen by
    ``camera``; ``bounds`` (lo, hi): the box of everything that casts or receives (the
    cages' control points, the free-form surfaces' patches). None: what a light's shadow
    rays may meet is not bounded (a point light above a ground plane, or among the points
    in view): no cull."""
    lo, hi = (np.asarray(b, np.float64) for b in bounds)
    diagonal = float(np.linalg.norm(hi - lo))
    reach = Reach()
    if scene.render.ao > 0:
        reach.grow = config.AO_DISTANCE * diagonal
    if not (scene.lights and scene.render.shadows):
        return reach
    points = [l for l in scene.lights if l.position is not None]
    if points and scene.ground is not None:
        return None
    corners = _pyramid_corners(camera, lo, hi)
    for light in points:
        view = _point_view(np.asarray(light.position, np.float64), corners, lo, hi)
        if view is None:
            return None
        reach.point_views.append(view)
    dirs = [np.asarray(l.direction, np.float64) for l in scene.lights if l.position is None]
    dirs = [d / np.linalg.norm(d) for d in dirs]
    reach.sweeps = [2.0 * diagonal * d for d in dirs]
    if scene.ground is None:
        reach.light_frames = [_light_extent(d, corners, lo, hi) for d in dirs]
    return reach


def _box_corners(lo, hi):
    """(8,3): the corners of the box [lo, hi]."""
    return np.array([[(hi if (k >> a) & 1 else lo)[a] for a in range(3)] for k in range(8)])


def _pyramid_corners(camera, lo, hi):
    """(8,3): the corners of the camera's pyramid (the image widened by
    ``_PYRAMID_MARGIN`` pixels) between the least and greatest depth of the box's corners
    (depth 0 at the eye when the box reaches behind it); None when the box is wholly
    behind the eye (nothing in view)."""
    frame = camera_frame(camera)
    eye, dx, dy, p00 = frame
    forward = camera.basis()[2]
    depth = (_box_corners(lo, hi) - eye) @ forward
    far = float(depth.max())
    if far <= 0.0:
        return None
    near = max(float(depth.min()), 0.0)
    m = _PYRAMID_MARGIN
    cols = (-0.5 - m, camera.width - 0.5 + m)
    rows = (-0.5 - m, camera.height - 0.5 + m)
    # p00 + c dx + r dy has unit depth (dx, dy are across the view): z times it is at depth z
    rays = np.array([p00 + c * dx + r * dy for c in cols for r in rows])
    return np.concatenate([eye + near * rays, eye + far * rays])


def _perpendicular(d):
    """(e1, e2): unit vectors with (e1, e2, d) orthonormal (``d`` unit)."""
    e1 = np.cross(d, [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(d, e1)


# the side, in pixels, of a point light's view of the points in view (boxes_in_view widens a
# box's rectangle by a pixel: finer pixels cull closer)
_POINT_VIEW_PIXELS = 64


def _point_view(light, corners, lo, hi):
    """The ``point_views`` entry of a point light at ``light`` (module comment): seen from
    the light, the points in view lie in the central projections of the pyramid
    ``corners`` and of the box [lo, hi] (of each that lies wholly in front of the light
    along its axis: the first of three for which one does), and no deeper than their
    corners. None when neither does for any (the light is in the box, among the points in
    view); an empty view when nothing is in view."""
    n = _POINT_VIEW_PIXELS
    box = _box_corners(lo, hi)
    if corners is None:  # nothing in view: a view no box meets
        return np.array([light, [1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]]), n, np.ones(3), -np.inf
    # axes to try: towards the box's nearest point (the whole box lies in front of the
    # light along it, when the light is outside), the middle of the two, the pyramid's
    mid = 0.5 * (np.maximum(corners.min(axis=0), lo) + np.minimum(corners.max(axis=0), hi))
    for target in (np.clip(light, lo, hi), mid, corners.mean(axis=0)):
        axis = target - light
        if not np.linalg.norm(axis) > 0.0:
            continue
        axis = axis / np.linalg.norm(axis)
        e1, e2 = _perpendicular(axis)
        rect = [-np.inf, np.inf, -np.inf, np.inf]
        depth, bounded = np.inf, False
        for pts in (corners, box):
            rel = pts - light
            z = rel @ axis
            if not (z > 0.0).all():
                continue
            u, v = (rel @ e1) / z, (rel @ e2) / z
            rect = [max(rect[0], u.min()), min(rect[1], u.max()),
                    max(rect[2], v.min()), min(rect[3], v.max())]
            depth, bounded = min(depth, float(z.max())), True
        if bounded:
            break
    else:
        return None
    if rect[0] > rect[1] or rect[2] > rect[3]:  # the two do not meet: nothing in view
        return np.array([light, e1, e2, axis]), n, axis, -np.inf
    su = max((rect[1] - rect[0]) / n, 1e-300)
    sv = max((rect[3] - rect[2]) / n, 1e-300)
    p00 = axis + (rect[0] + 0.5 * su) * e1 + (rect[2] + 0.5 * sv) * e2
    return np.array([light, su * e1, sv * e2, p00]), n, axis, depth


def _light_extent(d, corners, lo, hi):
    """(rows e1, e2, d; lo, hi) of :class:`Reach`'s ``light_frames`` for the light
    travelling along ``d`` (unit): the points in view lie in the pyramid ``corners`` (None:
    there are none, an empty extent) and in the box [lo, hi]."""
    axes = np.array([*_perpendicular(d), d])
    if corners is None:
        return axes, np.full(3, np.inf), np.full(3, -np.inf)
    along = corners @ axes.T  # (8,3)
    blo, bhi = _box_extent(axes, lo[None], hi[None])
    elo = np.maximum(along.min(axis=0), blo[0])
    ehi = np.minimum(along.max(axis=0), bhi[0])
    return axes, elo, ehi


def _box_extent(axes, lo, hi):
    """(lo (N,3), hi (N,3)): each box's least and greatest coordinate along each of
    ``axes`` (3,3) (a linear function's extremes over a box are at its corners: per
    coordinate, the smaller or larger of its two ends)."""
    a = axes.T[None]  # (1, 3 coords, 3 axes)
    p, q = lo[:, :, None] * a, hi[:, :, None] * a
    return np.minimum(p, q).sum(axis=1), np.maximum(p, q).sum(axis=1)


def view_test(camera, reach: Reach | None = None):
    """``in_view(lo, hi)`` -> (N,) bool: the boxes (N,3) that a primary ray of ``camera``
    may enter, or a secondary ray of ``reach`` may meet (module comment)."""
    frame = camera_frame(camera)
    reach = Reach() if reach is None else reach

    def in_view(lo, hi):
        if reach.grow > 0.0:
            lo, hi = lo - reach.grow, hi + reach.grow
        seen = boxes_in_view(lo, hi, frame, camera.width, camera.height)
        for k, v in enumerate(reach.sweeps):
            rest = ~seen
            if reach.light_frames is not None:
                axes, elo, ehi = reach.light_frames[k]
                blo, bhi = _box_extent(axes, lo[rest], hi[rest])
                near = ((blo[:, 0] <= ehi[0]) & (bhi[:, 0] >= elo[0])
                        & (blo[:, 1] <= ehi[1]) & (bhi[:, 1] >= elo[1]) & (blo[:, 2] <= ehi[2]))
                rest[rest] = near
            idx = np.nonzero(rest)[0]
            if len(idx):
                a, b = lo[idx], hi[idx]
                seen[idx] = boxes_in_view(np.minimum(a, a + v), np.maximum(b, b + v), frame,
                                          camera.width, camera.height)
        for light_frame, n, axis, depth in reach.point_views:
            idx = np.nonzero(~seen)[0]
            if len(idx):
                a, b = lo[idx], hi[idx]
                # (the box's least depth along the light's axis: no deeper than the points)
                light = light_frame[0]
                near = np.minimum((a - light) * axis, (b - light) * axis).sum(axis=1) <= depth
                seen[idx[near]] = boxes_in_view(a[near], b[near], light_frame, n, n)
        return seen

    return in_view
