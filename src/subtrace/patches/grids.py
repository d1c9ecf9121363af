"""Grids of exact limit points over patches, by sparse local refinement: the exact reference
of what the renderer's per-ray refinement samples (tests compare against it; nothing in the
render path builds whole grids), and the cut-and-refine step the isolations share
(:func:`cut_around`).

A *patch* is one face of the patch level ``L0`` (Catmull-Clark: level 1, where every face is a
quad; Loop: the cage itself). Its *grid at depth n* holds the exact limit points (and limit
normals) of the vertices of its descendants ``n`` levels further down: for a quad,
``(N+1)^2`` points with ``N = 2^n``, vertex ``(i, j)`` at patch parameter ``(i/N, j/N)``
stored at ``i + j*(N+1)``; for a triangle the ``(N+1)(N+2)/2`` points with ``i + j <= N``
at ``(i/N, j/N)``, stored row by row (``j`` major).

Grids are computed by the subdivision core itself, so every OpenSubdiv rule (creases,
corners, boundaries, non-manifold vertices, extraordinary vertices) is honoured: the faces
within ``config.GRID_RINGS`` face rings of the requested patches are cut out of ``L0`` and
refined one level at a time, cutting the rings around the descendants out again after every
level so the work stays proportional to the grids' size. Descendants of a face keep
OpenSubdiv's child order (child ``j`` at parent corner ``j``; Loop's middle child last), so
the ``4^n`` descendants of a patch are a contiguous block in *quadtree order*, which
:func:`leaf_corners` decodes into grid coordinates.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from subtrace import config
from subtrace.patches.bspline import regular_mask
from subtrace.runtime.jit import nb
from subtrace.subdiv.limit import extract, limit_points
from subtrace.subdiv.refine import refine_level, refine_points
from subtrace.subdiv.topology import Level, Options, compact as _compact, gather as _gather


def grid_size(n: int, quad: bool) -> int:
    """Number of grid points of a patch at depth ``n``."""
    N = 1 << n
    return (N + 1) * (N + 1) if quad else (N + 1) * (N + 2) // 2


@lru_cache(maxsize=None)
def leaf_corners(n: int, quad: bool) -> np.ndarray:
    """(4^n, 4 or 3) int32 grid-vertex indices of the leaves of a depth-``n`` patch, in
    quadtree order (the order of OpenSubdiv's descendants), corners in face order."""
    N = 1 << n
    k = 4 if quad else 3
    # corner coordinates (i, j) of every node, refined level by level in child order
    c = np.zeros((1, k, 2), dtype=np.int64)
    if quad:
        c[0] = [[0, 0], [N, 0], [N, N], [0, N]]
    else:
        c[0] = [[0, 0], [N, 0], [0, N]]
    for _ in range(n):
        c = _split_corners(c, quad)
    i, j = c[..., 0], c[..., 1]
    if quad:
        idx = i + j * (N + 1)
    else:
        idx = j * (N + 1) - j * (j - 1) // 2 + i
    return np.ascontiguousarray(idx, dtype=np.int32)


def _split_corners(c: np.ndarray, quad: bool) -> np.ndarray:
    """Children of nodes given by their corner coordinates, in OpenSubdiv's child order."""
    if quad:
        a, b, cc, d = (c[:, m] for m in range(4))
        ab, bc, cd, da = (a + b) // 2, (b + cc) // 2, (cc + d) // 2, (d + a) // 2
        mid = (a + cc) // 2
        kids = [
            (a, ab, mid, da),
            (ab, b, bc, mid),
            (mid, bc, cc, cd),
            (da, mid, cd, d),
        ]
    else:
        a, b, cc = (c[:, m] for m in range(3))
        ab, bc, ca = (a + b) // 2, (b + cc) // 2, (cc + a) // 2
        kids = [(a, ab, ca), (ab, b, bc), (ca, bc, cc), (bc, ca, ab)]
    out = np.stack([np.stack(kid, axis=1) for kid in kids], axis=1)
    return out.reshape(-1, c.shape[1], 2)


def build_grids(level: Level, points: np.ndarray, options: Options, faces, depth: int):
    """Exact limit points and unit limit normals on the depth-``depth`` grids of ``faces``.

    ``level``/``points``: the patch level L0 (all faces of the scheme's regular size).
    Returns ``(P, N)``, each (len(faces), G, 3) float64 with ``G = grid_size(depth, quad)``.
    A normal that the limit tangents leave undefined (a degenerate vertex) is NaN.
    """
    quad = options.scheme == "catmark"
    faces = np.asarray(faces, dtype=np.int64)
    k = 4 if quad else 3
    n_leaf = 1 << (2 * depth)
    if len(faces) == 0:
        G = grid_size(depth, quad)
        return np.zeros((0, G, 3)), np.zeros((0, G, 3))
    cur, cur_pts = level, points
    start, m = faces.copy(), 1  # descendants of patch i: faces start[i] .. start[i]+m-1
    for _ in range(depth + 1):
        cur, cur_pts, start = cut_around(cur, cur_pts, start, m)
        if m == n_leaf:
            break
        ref = refine_level(cur, options)
        cur_pts = refine_points(ref, cur_pts)
        cur = ref.child
        # children of face s are 4s .. 4s+3, so each block of descendants stays contiguous
        start, m = 4 * start, 4 * m
    # leaves of every patch, corners in face order
    m = 1 << (2 * depth)
    leaf = start[:, None] + np.arange(m, dtype=np.int64)[None, :]  # (F, 4^n)
    corners = cur.face_verts[(cur.face_offsets[leaf][..., None] + np.arange(k)).reshape(-1)]
    corners = corners.reshape(len(faces), m, k)
    verts, rank = _compact(corners.ravel(), cur.n_verts)
    inverse = rank[corners]
    P, du, dv = limit_points(cur, cur_pts, options, which=verts)
    nrm = unit_normals(du, dv)
    G = grid_size(depth, quad)
    slot = leaf_corners(depth, quad)  # (4^n, k) grid index of each leaf corner
    gi = np.broadcast_to(slot[None], corners.shape)
    inv = inverse.reshape(corners.shape)
    outP = np.empty((len(faces), G, 3))
    outN = np.empty((len(faces), G, 3))
    rows = np.broadcast_to(np.arange(len(faces))[:, None, None], corners.shape)
    outP[rows, gi] = P[inv]
    outN[rows, gi] = nrm[inv]
    return outP, outN


def unit_normals(du, dv):
    """The unit normals ``du x dv`` (..., 3) of limit tangents, NaN where undefined: the
    products, the norm and the division of ``np.cross`` and ``np.linalg.norm``, in their
    order (so the same bits), in one kernel instead of a NumPy pass each."""
    du = np.ascontiguousarray(du, dtype=np.float64)
    dv = np.ascontiguousarray(np.broadcast_to(dv, du.shape), dtype=np.float64)
    out = np.empty(du.shape)
    _unit_normals(du.reshape(-1, 3), dv.reshape(-1, 3), out.reshape(-1, 3))
    return out


@nb.njit(cache=True, nogil=True)
def _unit_normals(du, dv, out):
    for r in range(len(du)):
        x = du[r, 1] * dv[r, 2] - du[r, 2] * dv[r, 1]
        y = du[r, 2] * dv[r, 0] - du[r, 0] * dv[r, 2]
        z = du[r, 0] * dv[r, 1] - du[r, 1] * dv[r, 0]
        length = np.sqrt(x * x + y * y + z * z)
        if length > 0:
            out[r, 0], out[r, 1], out[r, 2] = x / length, y / length, z / length
        else:
            out[r, 0] = out[r, 1] = out[r, 2] = np.nan


def cut_around(level: Level, points: np.ndarray, start: np.ndarray, m: int):
    """Cut the faces within ``config.GRID_RINGS`` rings of the blocks ``start[i] .. +m`` out
    of ``level``; return the cut level, its points and the blocks' new starts (the cut keeps
    the faces' relative order, so blocks stay contiguous)."""
    blocks = (start[:, None] + np.arange(m, dtype=np.int64)[None, :]).ravel()
    verts = _compact(_gather(level.face_offsets, level.face_verts, blocks), level.n_verts)[0]
    sub, sub_to_cur, _, sub_faces = extract(level, verts, rings=config.GRID_RINGS)
    return sub, points[sub_to_cur], np.searchsorted(sub_faces, start)


def levels_needed(bound, dist, tol_rad):
    """Smallest n >= 0 with ``bound * 2^-n <= tol_rad * dist`` (elementwise)."""
    allowed = tol_rad * dist
    with np.errstate(divide="ignore", invalid="ignore"):
        n = np.ceil(np.log2(bound / allowed) - 1e-9)
    n = np.where(bound <= allowed, 0.0, n)
    return np.where(np.isfinite(n), n, 1e9)


def refine_children(level, points, faces, options):
    """Cut the neighbourhood of ``faces`` out of ``level``, refine it once; return the refined
    cut, its points, the faces' four children each (in the cut) and which of those are
    regular bicubic patches."""
    cur, cur_pts, start = cut_around(level, points, faces, 1)
    ref = refine_level(cur, options)
    cur_pts = refine_points(ref, cur_pts)
    kids = (4 * start[:, None] + np.arange(4)).ravel()
    return ref.child, cur_pts, kids, regular_mask(ref.child, options, kids)
