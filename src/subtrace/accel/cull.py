"""What the cull to the view keeps: the boxes a primary ray may enter, and those a secondary
ray leaving a point in view may meet (``render.faces_in_view``; design invariant 5).

A box is kept when its pixel rectangle meets the image (``projection.boxes_in_view``, the
test the tile lists make) or when a secondary ray from a point in view may reach it:

* **ambient occlusion** rays travel at most ``distance`` (``config.AO_DISTANCE`` times the
  scene's diagonal): a box that blocks one lies within that distance of a point in view, so
  the box grown by it reaches the view;
* **shadow rays** towards a directional light leave a point ``q`` in view along the light's
  reverse travel ``-d``. A box that blocks one holds a point ``q - s d`` (``0 < s``), so

  - swept along ``d`` as far as a shadow can fall (twice the scene's diagonal between
    objects; with a ground plane, as far as the scene box's corners travel along ``d`` to
    it, which a low sun makes long), it reaches the view (the box of the sweep is
    tested); and
  - seen along ``d`` it overlaps the points in view, and does not lie wholly beyond them
    from the light. Those are the objects' (in the part of the scene's box ``B`` inside
    the camera's pyramid: a polytope, whose corners are found by clipping ``B``'s faces by
    the pyramid's planes) and a ground plane's (the part of it in view that lies in
    ``B``'s shadow along ``d``: ``B``'s corners carried along ``d`` onto the plane, their
    hull clipped by the pyramid). In a frame ``(e1, e2, d)`` the box's extent along ``e1``
    and ``e2`` must meet theirs, and its least ``d`` must not exceed their greatest.

* **shadow rays** towards a point light at ``L`` leave ``q`` towards ``L``: a box that
  blocks one holds a point of the segment, which the light sees in the same direction as
  ``q`` and nearer. The light's view of the points in view is the central projection of
  their corners (when they lie wholly in front of the light along an axis): the
  polytope's, and under a ground plane those of the part of the ground in view that ``B``
  can shadow (``B``'s corners carried from ``L`` onto the plane, their hull clipped by the
  pyramid; ``L`` must stand above ``B``, else that shadow runs to the horizon). A box is
  kept when it projects into that view (``projection.boxes_in_view`` with the light as the
  eye; a box reaching the light's plane is kept) and is not wholly deeper than those
  corners.

A point light among the points in view (in front of it along no axis tried), or under a
ground plane one not above the scene's box, is not bounded so: such scenes are not culled
(:func:`secondary_reach` gives None). Neither is a ground plane along which a directional
light runs (its sweep alone decides then). Which of the two bounds a light's shadow rays
take (rays along one direction, or rays to one point), or none (then no cull), is its
kind's (``lights.shadow_cast``).

Where the secondary rays start bounds their cones too (:func:`secondary_origins`, for the
refinement's ``patches.shells.Sight``): a box around the points in view, and their least
distance from the eye.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from subtrace import config
from subtrace.accel.projection import boxes_in_view
from subtrace.camera import camera_frame
from subtrace.lights import shadow_cast
from subtrace.patches.shells import box_distance, box_extent, box_least

# pixels of margin around the image for the pyramid's sides (the tile lists widen a box's
# rectangle by one pixel for rounding; half a pixel more reaches the pixels' outer edges)
_PYRAMID_MARGIN = 2.0


@dataclass
class Reach:
    """How far secondary rays from the points in view may go (module comment): ``grow``
    the ambient occlusion distance (0: none); per directional light, ``sweeps`` (3,) its
    travel as far as a shadow can fall and ``light_frames`` (None: the sweeps alone decide)
    ``(axes (3,3): rows e1, e2, d; lo (3,), hi (3,))``, the extent of the points in view
    along e1, e2 and d; per point light, ``point_views``
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
    boxes = [c.points_box for c in cages]
    if nurbs is not None:
        boxes.append(nurbs.bounds())
    return np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)


def secondary_reach(scene, bounds, camera, ground=None) -> Reach | None:
    """The :class:`Reach` of ``scene``'s shadow and ambient occlusion rays seen by
    ``camera``; ``bounds`` (lo, hi): the box of everything that casts or receives (the
    cages' control points, the free-form surfaces' patches); ``ground``: the scene's ground
    plane as (unit up, height), or None (none, or not known: then a directional light's
    sweep alone decides). None: what a light's shadow rays may meet is not bounded (a point
    light above a ground plane, or among the points in view): no cull."""
    lo, hi = (np.asarray(b, np.float64) for b in bounds)
    diagonal = float(np.linalg.norm(hi - lo))
    reach = Reach()
    if scene.render.ao > 0:
        reach.grow = config.AO_DISTANCE * diagonal
    if not (scene.lights and scene.render.shadows):
        return reach
    # (how each light's shadow rays are bounded is the light kind's: lights.shadow_cast)
    casts = [shadow_cast(light) for light in scene.lights]
    if any(c is None for c in casts):
        return None  # (a light whose shadow rays are not bounded)
    points = [at for how, at in casts if how == "point"]
    if points and scene.ground is not None and ground is None:
        return None  # (a ground whose height is not given: its shadows are not bounded)
    seen = _seen_in_box(camera, lo, hi)  # (the objects' points in view lie in its hull)
    for position in points:
        where = seen
        if ground is not None:
            shadow = _ground_under_point(camera, lo, hi, position, *ground)
            if shadow is None:
                return None
            where = np.concatenate([seen, shadow])
        view = _point_view(position, where, lo, hi)
        if view is None:
            return None
        reach.point_views.append(view)
    dirs = [at / np.linalg.norm(at) for how, at in casts if how == "parallel"]
    reach.sweeps = [2.0 * diagonal * d for d in dirs]
    if ground is not None:
        # (a low sun carries a shadow on the ground further than the scene's diagonal: as
        # far as the box's corners travel along the light to the plane)
        box = _box_corners(lo, hi)
        up, height = np.asarray(ground[0], np.float64), float(ground[1])
        for k, d in enumerate(dirs):
            across = abs(float(d @ up))
            if across < 1e-9:
                return None  # (the light runs along the ground: no bound)
            travel = float(np.abs(box @ up - height).max()) / across
            reach.sweeps[k] = max(2.0 * diagonal, 1.01 * travel) * d
    elif scene.ground is not None:
        return None  # (a ground whose height is not given: its shadows are not bounded)
    if scene.ground is None:
        reach.light_frames = [_light_extent(d, seen) for d in dirs]
    elif ground is not None:
        grounds = [_ground_in_view(camera, lo, hi, d, *ground) for d in dirs]
        if all(g is not None for g in grounds):
            reach.light_frames = [_light_extent(d, np.concatenate([seen, g]))
                                  for d, g in zip(dirs, grounds)]
    return reach


def secondary_origins(camera, lo, hi, ground=None, extra=None):
    """Where the secondary rays of ``camera``'s picture may start, for the refinement's
    :class:`~subtrace.patches.shells.Sight`: (near, seen_min (3,), seen_max (3,)), a
    box holding every such point and their least distance from the eye; None when no
    point is in view. They are the hits of rays through the image: on the surfaces of
    patches whose boxes (``lo``, ``hi``: (n,3), holding what the rays test) project into
    it (``projection.boxes_in_view``, as the tile lists; an anti-aliasing ray passes
    within a pixel's rectangle), on free-form surfaces within the box ``extra`` = (lo,
    hi), and on the ground plane ``ground`` = (unit up, height) where it is in view
    (:func:`_plane_in_view`)."""
    eye = np.asarray(camera.eye, np.float64)
    inside = boxes_in_view(lo, hi, camera_frame(camera), camera.width, camera.height)
    boxes = [(lo[inside], hi[inside])]
    if extra is not None:
        boxes.append(tuple(np.asarray(b, np.float64).reshape(1, 3) for b in extra))
    near = np.inf
    seen_min, seen_max = np.full(3, np.inf), np.full(3, -np.inf)
    for a, b in boxes:
        if len(a):
            near = min(near, float(box_distance(a, b, eye).min()))
            seen_min = np.minimum(seen_min, a.min(axis=0))
            seen_max = np.maximum(seen_max, b.max(axis=0))
    # (the magnitude of every coordinate that matters: the eye's, the boxes')
    extent = max(float(np.abs(eye).max()), float(np.abs(lo).max(initial=0.0)),
                 float(np.abs(hi).max(initial=0.0)))
    on_ground = None if ground is None else _plane_in_view(camera, *ground, extent)
    if on_ground is not None:
        ground_near, part = on_ground
        near = min(near, ground_near)
        seen_min, seen_max = np.minimum(seen_min, part[0]), np.maximum(seen_max, part[1])
    if not np.isfinite(near):
        return None
    return near, seen_min, seen_max


def _plane_in_view(camera, up, height, extent):
    """(the least distance from the eye to the part of the plane ``up`` . x = ``height``
    in the camera's pyramid (:func:`_pyramid_planes`), (lo (3,), hi (3,)) a box holding
    the points of that part that matter), or None when no part is in view.

    The part is taken within a square of the plane around the eye's foot, of half-side
    ``r`` a million times the coordinates' magnitude ``extent`` (the eye's and every box
    a secondary ray may reach), clipped by the pyramid. A ground point X beyond it is at
    least ``r`` from the eye; with P the part's nearest point, a box point Y is reached
    from X by a cone no shorter than from the points between P and X (the cone's length
    from X, |X - eye| + |Y - X|, is convex along that segment), the last of which in the
    square counts, when P's cone is no longer than X's: |P - eye| + |Y - P| <= 2 |P - eye|
    + |Y - eye| <= 2 |P - eye| + 4 extent <= r <= |X - eye|. Where that holds the square's
    part is the box; otherwise the plane's box (the plane along an axis it faces, else
    everything)."""
    up = np.asarray(up, np.float64) / np.linalg.norm(up)
    eye = np.asarray(camera.eye, np.float64)
    above = float(up @ eye) - float(height)
    foot = eye - above * up
    e1, e2 = _perpendicular(up)
    r = 1e6 * max(1.0, abs(above), extent)
    poly = np.array([foot + a * e1 + b * e2 for a, b in ((-r, -r), (r, -r), (r, r), (-r, r))])
    for point, normal in _pyramid_planes(camera):
        poly = _clip(poly, point, normal)
    if not len(poly):
        return None
    # the nearest point: the foot where the part holds it, else on one of its sides
    rel = poly - foot
    turns = [float(np.cross(rel[k], rel[(k + 1) % len(poly)]) @ up) for k in range(len(poly))]
    if len(poly) >= 3 and (min(turns) >= 0.0 or max(turns) <= 0.0):
        best = abs(above)
    else:
        best = np.inf
        for k in range(len(poly)):
            a, b = poly[k], poly[(k + 1) % len(poly)]
            ab = b - a
            f = (0.0 if not ab @ ab > 0.0
                 else min(max(float((eye - a) @ ab / (ab @ ab)), 0.0), 1.0))
            best = min(best, float(np.linalg.norm(eye - (a + f * ab))))
    if 2.0 * best + 4.0 * max(extent, 1.0) <= r:
        return best, (poly.min(axis=0), poly.max(axis=0))
    lo, hi = np.full(3, -np.inf), np.full(3, np.inf)
    axis = np.nonzero(up != 0.0)[0]
    if len(axis) == 1:  # (a plane facing an axis: one coordinate, the others any)
        lo[axis[0]] = hi[axis[0]] = height / up[axis[0]]
    return best, (lo, hi)


def _box_corners(lo, hi):
    """(8,3): the corners of the box [lo, hi]."""
    return np.array([[(hi if (k >> a) & 1 else lo)[a] for a in range(3)] for k in range(8)])


def _pyramid_planes(camera):
    """The camera's pyramid (its image widened by ``_PYRAMID_MARGIN`` pixels) as planes
    (point (3,), normal (3,)) whose normals face its inside: its four sides, through the
    eye, and the eye's own plane (what is in view lies in front of the eye)."""
    eye, dx, dy, p00 = camera_frame(camera)
    m = _PYRAMID_MARGIN
    c0, c1 = -0.5 - m, camera.width - 0.5 + m
    r0, r1 = -0.5 - m, camera.height - 0.5 + m
    rays = [p00 + c * dx + r * dy for c, r in ((c0, r0), (c1, r0), (c1, r1), (c0, r1))]
    forward = camera.basis()[2]
    planes = []
    for k in range(4):
        normal = np.cross(rays[k], rays[(k + 1) % 4])
        planes.append((eye, normal if normal @ forward > 0.0 else -normal))
    return planes + [(eye, forward)]


def _seen_in_box(camera, lo, hi):
    """(k,3): the corners of the part of the box [lo, hi] in the camera's pyramid (each of
    the box's faces clipped by the pyramid: the part's corners lie on them, but for the eye
    when the box holds it); (0,3) when none is."""
    planes = _pyramid_planes(camera)
    box = _box_corners(lo, hi)
    corners = []
    for axis in range(3):
        for side in (0, 1):
            # the face at lo or hi along this axis, its corners in order around it
            a, b = (axis + 1) % 3, (axis + 2) % 3
            face = []
            for u, v in ((0, 0), (1, 0), (1, 1), (0, 1)):
                k = (side << axis) | (u << a) | (v << b)
                face.append(box[k])
            poly = np.array(face)
            for point, normal in planes:
                poly = _clip(poly, point, normal)
            corners.append(poly)
    eye = np.asarray(camera.eye, np.float64)
    if (eye >= lo).all() and (eye <= hi).all():
        corners.append(eye[None])
    return np.concatenate(corners).reshape(-1, 3)


def _perpendicular(d):
    """(e1, e2): unit vectors with (e1, e2, d) orthonormal (``d`` unit)."""
    e1 = np.cross(d, [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(d, e1)


# the side, in pixels, of a point light's view of the points in view (boxes_in_view widens a
# box's rectangle by a pixel: finer pixels cull closer)
_POINT_VIEW_PIXELS = 64


def _point_view(light, seen, lo, hi):
    """The ``point_views`` entry of a point light at ``light`` (module comment): seen from
    the light, the points in view lie in the central projection of the corners ``seen``
    (:func:`_seen_in_box`) when those lie wholly in front of it along its axis (towards the
    box [lo, hi]'s nearest point, which puts the whole box in front of a light outside it,
    or else towards their middle), and no deeper than they are. None when neither axis
    puts them in front (the light is among the points in view); an empty view when there
    are none."""
    n = _POINT_VIEW_PIXELS
    if not len(seen):  # nothing in view: a view no box meets
        return np.array([light, [1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]]), n, np.ones(3), -np.inf
    for target in (np.clip(light, lo, hi), seen.mean(axis=0)):
        axis = target - light
        if not np.linalg.norm(axis) > 0.0:
            continue
        axis = axis / np.linalg.norm(axis)
        rel = seen - light
        z = rel @ axis
        if (z > 0.0).all():
            break
    else:
        return None
    e1, e2 = _perpendicular(axis)
    u, v = (rel @ e1) / z, (rel @ e2) / z
    su = max((u.max() - u.min()) / n, 1e-300)
    sv = max((v.max() - v.min()) / n, 1e-300)
    p00 = axis + (u.min() + 0.5 * su) * e1 + (v.min() + 0.5 * sv) * e2
    return np.array([light, su * e1, sv * e2, p00]), n, axis, float(z.max())


def _light_extent(d, points):
    """(rows e1, e2, d; lo, hi) of :class:`Reach`'s ``light_frames`` for the light
    travelling along ``d`` (unit): the extent of the points in view, whose hull's corners
    are ``points`` (k,3) (the objects' and the ground's); an empty one when there are none."""
    axes = np.array([*_perpendicular(d), d])
    if not len(points):
        return axes, np.full(3, np.inf), np.full(3, -np.inf)
    along = points @ axes.T
    return axes, along.min(axis=0), along.max(axis=0)


def _ground_in_view(camera, lo, hi, d, up, height):
    """(k,3): the corners of the part of the ground plane (``up`` . x = ``height``) that
    lies in the box [lo, hi]'s shadow along ``d`` (the box's corners carried along ``d``
    onto the plane: what the box holds can shadow no ground point outside their hull) and
    in the camera's pyramid (:func:`_pyramid_planes`); (0,3) when none does. None when the
    light runs along the plane (its shadows there are unbounded)."""
    up = np.asarray(up, np.float64)
    across = float(d @ up)
    if abs(across) < 1e-9:
        return None
    box = _box_corners(lo, hi)
    return _in_view_on_plane(camera, box - ((box @ up - height) / across)[:, None] * d, up)


def _ground_under_point(camera, lo, hi, light, up, height):
    """(k,3): the corners of the part of the ground plane (``up`` . x = ``height``) that
    lies in the box [lo, hi]'s shadow from a point light at ``light`` (the box's corners
    carried from the light onto the plane: a ray from a ground point to the light meets
    the box only inside their hull) and in the camera's pyramid; (0,3) when none does.
    None when the box reaches the light's height above the plane (its shadow there runs
    to the horizon) or the light is not above the plane."""
    up = np.asarray(up, np.float64)
    box = _box_corners(lo, hi)
    level = float(light @ up)
    if not (level > height and (box @ up).max() < level):
        return None
    s = (height - level) / (box @ up - level)
    return _in_view_on_plane(camera, light + s[:, None] * (box - light), up)


def _in_view_on_plane(camera, on_plane, up):
    """(k,3): the corners of the hull of ``on_plane`` (n,3), points of a plane facing
    ``up``, clipped by the camera's pyramid (:func:`_pyramid_planes`)."""
    poly = _hull_on_plane(on_plane, up)
    for point, normal in _pyramid_planes(camera):
        poly = _clip(poly, point, normal)
    return poly


def _hull_on_plane(points, up):
    """``points`` (n,3), all on a plane facing ``up``, reduced to their convex hull's
    corners, in order around it."""
    b1, b2 = _perpendicular(up / np.linalg.norm(up))
    xy = np.stack([points @ b1, points @ b2], axis=1)
    order = sorted(range(len(points)), key=lambda i: (xy[i, 0], xy[i, 1]))

    def turn(o, a, b):  # > 0: o, a, b turn counter-clockwise
        (ax, ay), (bx, by) = xy[a] - xy[o], xy[b] - xy[o]
        return ax * by - ay * bx

    def half(seq):  # Andrew's monotone chain
        chain = []
        for i in seq:
            while len(chain) >= 2 and turn(chain[-2], chain[-1], i) <= 0.0:
                chain.pop()
            chain.append(i)
        return chain[:-1]

    corners = half(order) + half(order[::-1])
    return points[corners] if corners else points[:1]


def _clip(poly, point, normal):
    """The part of the convex polygon ``poly`` (k,3), corners in order, on the side of the
    plane through ``point`` that ``normal`` faces (Sutherland and Hodgman's step)."""
    if not len(poly):
        return poly
    side = (poly - point) @ normal
    out = []
    for k in range(len(poly)):
        a, b = poly[k], poly[(k + 1) % len(poly)]
        sa, sb = side[k], side[(k + 1) % len(poly)]
        if sa >= 0.0:
            out.append(a)
        if (sa >= 0.0) != (sb >= 0.0):
            out.append(a + (sa / (sa - sb)) * (b - a))
    return np.array(out).reshape(-1, 3)


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
                blo, bhi = box_extent(axes, lo[rest], hi[rest])
                near = ((blo[:, 0] <= ehi[0]) & (bhi[:, 0] >= elo[0])
                        & (blo[:, 1] <= ehi[1]) & (bhi[:, 1] >= elo[1]) & (blo[:, 2] <= ehi[2]))
                rest[rest] = near
            idx = np.nonzero(rest)[0]
            if len(idx):
                a, b = lo[idx], hi[idx]
                seen[idx] = boxes_in_view(np.minimum(a, a + v), np.maximum(b, b + v), frame,
                                          camera.width, camera.height)
        for light_frame, n, axis, depth in reach.point_views:
            # the boxes not kept yet whose least depth along the light's axis is no deeper
            # than the points'
            least = box_least(axis[None], lo, hi)[:, 0]
            idx = np.nonzero(~seen & (least <= depth + float(light_frame[0] @ axis)))[0]
            if len(idx):
                seen[idx] = boxes_in_view(lo[idx], hi[idx], light_frame, n, n)
        return seen

    return in_view
