"""Bounding shells of patches from their one-ring control points, and distances to boxes.

A face's limit surface depends only on the control points of the faces sharing a vertex
with it (its one-ring), with non-negative weights, so it lies in their convex hull and in
their axis-aligned box (design invariant 2). Per face, flat arrays: box min / max (n,3)
float64, a length bound on its iso-curves (n,) and its largest corner valence (n,) int64.
:func:`face_ring_boxes` makes the boxes alone for every face of a level at once (the view
cull of cage faces, ``patches/table.py``). :func:`sight_distance` is the distance the
refinement criterion takes the tolerance at, from the eye or a :class:`Sight`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from subtrace.runtime.jit import nb
from subtrace.runtime.threads import run_tasks, thread_count


def box_distance(bmin, bmax, p):
    """(n,) distance from point ``p`` (3,) to each box ``[bmin, bmax]`` (n,3) (0 inside)."""
    q = np.maximum(np.maximum(bmin - p, 0.0), p - bmax)
    return np.sqrt((q * q).sum(axis=1))


def box_extent(axes, lo, hi):
    """(lo (N,k), hi (N,k)): each box ``[lo, hi]`` (N,3)'s least and greatest coordinate
    along each of ``axes`` (k,3) (a linear function's extremes over a box are at its
    corners: per coordinate, the smaller or larger of its two ends: the low end where the
    axis grows with the coordinate, else the high one). Two products of (N,3) by (3,k): the
    (N,3,3) products and their sums took 0.11 s on the sword refined twice's 358,048 faces."""
    return box_least(axes, lo, hi), box_least(axes, hi, lo)


def box_least(axes, lo, hi):
    """(N,k): each box's least coordinate along each of ``axes`` (k,3) (:func:`box_extent`;
    with ``lo`` and ``hi`` swapped, the greatest)."""
    return lo @ np.maximum(axes, 0.0).T + hi @ np.minimum(axes, 0.0).T


@dataclass(frozen=True, eq=False)
class Sight:
    """Where the rays that refine the patches come from, for the angular criterion
    (design invariants 3 and 8): rays from the eye ``eye`` (3,), and secondary rays (shadow,
    ambient occlusion) leaving the points their hits see. Those points lie in the box
    ``[seen_min, seen_max]`` (either may be infinite) and at least ``near`` from the eye.

    A secondary ray leaving such a point ``x`` carries the pixel's cone: at a point ``q``
    a distance ``s`` along it, its width is the tolerance times ``|x - eye| + s``, and
    ``s >= |q - x|``. So every ray reaching a box has a cone there at least as wide as the
    tolerance times :func:`sight_distance`: the larger of the box's distance from the eye
    (the triangle inequality, and a primary ray's own length) and ``near`` plus its gap
    to the box of the points in view. A patch refined by that distance is refined as
    finely as the narrowest cone that can reach it asks, and no finer, within the bound:
    a caster out of view, nearer the eye than anything in view, is not refined as if a
    pixel looked at it from there."""

    eye: np.ndarray
    near: float
    seen_min: np.ndarray
    seen_max: np.ndarray


def sight_distance(bmin, bmax, eye):
    """(n,) the distance the tolerance is taken at for each box ``[bmin, bmax]`` (n,3)
    seen from ``eye``: a point (3,), its :func:`box_distance`, or a :class:`Sight`, the
    least length of the cone of a ray that can reach the box (see there)."""
    if not isinstance(eye, Sight):
        return box_distance(bmin, bmax, eye)
    d = box_distance(bmin, bmax, eye.eye)
    gap = np.maximum(np.maximum(bmin - eye.seen_max, eye.seen_min - bmax), 0.0)
    return np.maximum(d, eye.near + np.sqrt((gap * gap).sum(axis=1)))


def eye_point(eye) -> np.ndarray:
    """The eye's position (3,) of ``eye``: a point, or a :class:`Sight`."""
    return eye.eye if isinstance(eye, Sight) else eye


_SHELLS_PER_THREAD = 4096  # (fewer faces: one thread, not worth starting the others)


def one_ring_shells(level, faces, pts):
    """(box min (n,3), box max (n,3), length bound (n,), largest corner valence (n,)) of the
    one-ring control points of ``faces`` of ``level`` at ``pts`` (see :func:`_shells`)."""
    lo = np.empty((len(faces), 3))
    hi = np.empty((len(faces), 3))
    bound = np.empty(len(faces))
    valence = np.empty(len(faces), dtype=np.int64)
    run_tasks(_shells, np.ascontiguousarray(faces, dtype=np.int64), level.face_offsets,
              level.face_verts, level.vert_face_offsets, level.vert_faces, pts, lo, hi, bound,
              valence, n=thread_count() if len(faces) >= _SHELLS_PER_THREAD else 1)
    return lo, hi, bound, valence


def face_ring_boxes(level, pts):
    """(box min (F,3), box max (F,3)): per face of ``level``, the box of its one-ring's
    control points at ``pts`` (the box :func:`one_ring_shells` makes), for every face at
    once: the union of its corners' vertex-ring boxes, each made once."""
    vlo = np.empty((level.n_verts, 3))
    vhi = np.empty((level.n_verts, 3))
    lo = np.empty((level.n_faces, 3))
    hi = np.empty((level.n_faces, 3))
    for step in (0, 1):  # (the vertices' boxes, then the faces')
        run_tasks(_ring_boxes, step, level.vert_face_offsets, level.vert_faces,
                  level.face_offsets, level.face_verts, pts, vlo, vhi, lo, hi)
    return lo, hi


def face_star_boxes(face_offsets, face_verts, pts):
    """:func:`face_ring_boxes` from the face lists alone (``face_offsets`` (F+1,) int64,
    ``face_verts`` int32), without the topology: each vertex's box is the union of the
    boxes of the faces that list it, the same points as its ring's, so the same boxes."""
    n_faces = len(face_offsets) - 1
    vlo = np.full((len(pts), 3), np.inf)
    vhi = np.full((len(pts), 3), -np.inf)
    lo = np.empty((n_faces, 3))
    hi = np.empty((n_faces, 3))
    fo = np.ascontiguousarray(face_offsets, dtype=np.int64)
    fv = np.ascontiguousarray(face_verts, dtype=np.int32)
    _ring_boxes(0, 1, 2, fo, fv, fo, fv, pts, vlo, vhi, lo, hi)  # (the vertices' boxes)
    _face_step(fo, fv, vlo, vhi, lo, hi)
    return lo, hi


def split_ring_boxes(level, child_pts):
    """(box min (F,3), box max (F,3)): per face of ``level`` (a Loop level), the box of the
    points of the next level that its four children's one-rings hold, ``child_pts`` being
    that level's points (vertex points first, then edge points: ``subdiv/refine.py``). A
    child's one-ring is the next level's faces around its corners (the vertex points of the
    face's corners and the edge points of its edges), which reach the vertex points of the
    face's corners and the edge points of every edge at them, no further: so the box is the
    union of its corners' boxes of those points."""
    vlo = np.empty((level.n_verts, 3))
    vhi = np.empty((level.n_verts, 3))
    lo = np.empty((level.n_faces, 3))
    hi = np.empty((level.n_faces, 3))
    run_tasks(_vertex_split_boxes, level.vert_edge_offsets, level.vert_edges, child_pts,
              vlo, vhi)
    _face_step(level.face_offsets, level.face_verts, vlo, vhi, lo, hi)
    return lo, hi


def _face_step(face_offsets, face_verts, vlo, vhi, lo, hi):
    """Per face, the union ``lo, hi`` of its corners' boxes ``vlo, vhi``: step 1 of
    :func:`_ring_boxes` (whose vertex arrays and points it does not read: the face lists
    and ``vlo`` stand in for them, of the same types)."""
    fo = np.ascontiguousarray(face_offsets, dtype=np.int64)
    fv = np.ascontiguousarray(face_verts, dtype=np.int32)
    run_tasks(_ring_boxes, 1, fo, fv, fo, fv, vlo, vlo, vhi, lo, hi)


@nb.njit(cache=True, nogil=True)
def _vertex_split_boxes(task, n_tasks, vert_edge_offsets, vert_edges, child_pts, vlo, vhi):
    """Per vertex v, the box of its vertex point and the edge points of its edges in the
    next level's points (``run_tasks`` shares the vertices out as below)."""
    n = len(vlo)
    nv = n
    for v in range(task * n // n_tasks, (task + 1) * n // n_tasks):
        lo0, lo1, lo2 = child_pts[v, 0], child_pts[v, 1], child_pts[v, 2]
        hi0, hi1, hi2 = lo0, lo1, lo2
        for a in range(vert_edge_offsets[v], vert_edge_offsets[v + 1]):
            p = nv + vert_edges[a]
            x, y, z = child_pts[p, 0], child_pts[p, 1], child_pts[p, 2]
            lo0, lo1, lo2 = min(lo0, x), min(lo1, y), min(lo2, z)
            hi0, hi1, hi2 = max(hi0, x), max(hi1, y), max(hi2, z)
        vlo[v, 0], vlo[v, 1], vlo[v, 2] = lo0, lo1, lo2
        vhi[v, 0], vhi[v, 1], vhi[v, 2] = hi0, hi1, hi2


@nb.njit(cache=True, nogil=True)
def _ring_boxes(task, n_tasks, step, vert_face_offsets, vert_faces, face_offsets, face_verts,
                pts, vlo, vhi, lo, hi):
    """Step 0: per vertex, the box ``vlo, vhi`` of the points of the faces around it; step
    1: per face, the union ``lo, hi`` of its corners' boxes (:func:`face_ring_boxes`); step
    2 (one task, no topology: :func:`face_star_boxes`): per vertex, the box of the points
    of the faces that list it (``vlo``, ``vhi`` start at +inf / -inf), each face's box
    widened into its corners' boxes. One kernel for the three steps: one load in a render,
    not three. ``run_tasks``: task ``task`` of ``n_tasks`` takes a contiguous share of the
    vertices, or of the faces."""
    if step == 2:
        for f in range(len(face_offsets) - 1):
            lo0, lo1, lo2 = np.inf, np.inf, np.inf
            hi0, hi1, hi2 = -np.inf, -np.inf, -np.inf
            for c in range(face_offsets[f], face_offsets[f + 1]):
                p = face_verts[c]
                x, y, z = pts[p, 0], pts[p, 1], pts[p, 2]
                lo0, lo1, lo2 = min(lo0, x), min(lo1, y), min(lo2, z)
                hi0, hi1, hi2 = max(hi0, x), max(hi1, y), max(hi2, z)
            for c in range(face_offsets[f], face_offsets[f + 1]):
                v = face_verts[c]
                vlo[v, 0], vhi[v, 0] = min(vlo[v, 0], lo0), max(vhi[v, 0], hi0)
                vlo[v, 1], vhi[v, 1] = min(vlo[v, 1], lo1), max(vhi[v, 1], hi1)
                vlo[v, 2], vhi[v, 2] = min(vlo[v, 2], lo2), max(vhi[v, 2], hi2)
        return
    if step == 1:
        n = len(lo)
        for f in range(task * n // n_tasks, (task + 1) * n // n_tasks):
            for k in range(3):
                lo[f, k], hi[f, k] = np.inf, -np.inf
            for c in range(face_offsets[f], face_offsets[f + 1]):
                v = face_verts[c]
                for k in range(3):
                    lo[f, k] = min(lo[f, k], vlo[v, k])
                    hi[f, k] = max(hi[f, k], vhi[v, k])
        return
    n = len(vlo)
    for v in range(task * n // n_tasks, (task + 1) * n // n_tasks):
        lo0, lo1, lo2 = np.inf, np.inf, np.inf
        hi0, hi1, hi2 = -np.inf, -np.inf, -np.inf
        for a in range(vert_face_offsets[v], vert_face_offsets[v + 1]):
            g = vert_faces[a]
            for c in range(face_offsets[g], face_offsets[g + 1]):
                p = face_verts[c]
                x, y, z = pts[p, 0], pts[p, 1], pts[p, 2]
                lo0, lo1, lo2 = min(lo0, x), min(lo1, y), min(lo2, z)
                hi0, hi1, hi2 = max(hi0, x), max(hi1, y), max(hi2, z)
        vlo[v, 0], vlo[v, 1], vlo[v, 2] = lo0, lo1, lo2
        vhi[v, 0], vhi[v, 1], vhi[v, 2] = hi0, hi1, hi2


@nb.njit(cache=True, nogil=True)
def _shells(task, n_tasks, faces, face_offsets, face_verts, vert_face_offsets, vert_faces, pts,
            smin, smax, ebound, valence):
    """Box of the one-ring faces' points, longest edge among them, largest corner valence
    (task ``task`` of ``n_tasks`` takes a contiguous share of the faces)."""
    n = len(faces)
    for i in range(task * n // n_tasks, (task + 1) * n // n_tasks):
        f = faces[i]
        lo0, lo1, lo2 = np.inf, np.inf, np.inf
        hi0, hi1, hi2 = -np.inf, -np.inf, -np.inf
        emax = 0.0
        vmax = 0
        # the patch's own edges
        own = 0.0
        n0 = face_offsets[f + 1] - face_offsets[f]
        for b in range(n0):
            p = face_verts[face_offsets[f] + b]
            q = face_verts[face_offsets[f] + (b + 1) % n0]
            dx, dy, dz = pts[q, 0] - pts[p, 0], pts[q, 1] - pts[p, 1], pts[q, 2] - pts[p, 2]
            own = max(own, math.sqrt(dx * dx + dy * dy + dz * dz))
        for c in range(face_offsets[f], face_offsets[f + 1]):
            v = face_verts[c]
            vmax = max(vmax, vert_face_offsets[v + 1] - vert_face_offsets[v])
            for a in range(vert_face_offsets[v], vert_face_offsets[v + 1]):
                g = vert_faces[a]
                g0 = face_offsets[g]
                ng = face_offsets[g + 1] - g0
                for b in range(ng):
                    p = face_verts[g0 + b]
                    q = face_verts[g0 + (b + 1) % ng]
                    x, y, z = pts[p, 0], pts[p, 1], pts[p, 2]
                    lo0, lo1, lo2 = min(lo0, x), min(lo1, y), min(lo2, z)
                    hi0, hi1, hi2 = max(hi0, x), max(hi1, y), max(hi2, z)
                    dx, dy, dz = pts[q, 0] - x, pts[q, 1] - y, pts[q, 2] - z
                    emax = max(emax, math.sqrt(dx * dx + dy * dy + dz * dz))
        smin[i, 0], smin[i, 1], smin[i, 2] = lo0, lo1, lo2
        smax[i, 0], smax[i, 1], smax[i, 2] = hi0, hi1, hi2
        # an iso-curve over the patch is a cubic B-spline whose control polygon blends the
        # patch's rows with weights >= 2/3 on its own two rows, and a B-spline span is no
        # longer than e0/6 + 2 e1/3 + e2/6 of its control edges: hence this length bound
        ebound[i] = (4.0 * own + 5.0 * emax) / 9.0
        valence[i] = vmax
