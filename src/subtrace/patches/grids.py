"""Grids of exact limit points over patches, by sparse local refinement.

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
from subtrace.mesh.topology import Level, Options, compact as _compact, gather as _gather
from subtrace.subdiv.limit import extract, limit_points
from subtrace.subdiv.refine import refine_level, refine_points


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


def grid_params(n: int, quad: bool) -> np.ndarray:
    """(G,2) float64 patch parameters of the grid points of a depth-``n`` patch."""
    N = 1 << n
    if quad:
        j, i = np.divmod(np.arange((N + 1) * (N + 1)), N + 1)
    else:
        i = np.concatenate([np.arange(N + 1 - jj) for jj in range(N + 1)])
        j = np.concatenate([np.full(N + 1 - jj, jj) for jj in range(N + 1)])
    return np.stack([i, j], axis=1).astype(np.float64) / N


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
    nrm = np.cross(du, dv)
    length = np.linalg.norm(nrm, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        nrm = np.where(length > 0, nrm / length, np.nan)
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


def cut_around(level: Level, points: np.ndarray, start: np.ndarray, m: int):
    """Cut the faces within ``config.GRID_RINGS`` rings of the blocks ``start[i] .. +m`` out
    of ``level``; return the cut level, its points and the blocks' new starts (the cut keeps
    the faces' relative order, so blocks stay contiguous)."""
    blocks = (start[:, None] + np.arange(m, dtype=np.int64)[None, :]).ravel()
    verts = _compact(_gather(level.face_offsets, level.face_verts, blocks), level.n_verts)[0]
    sub, sub_to_cur, _, sub_faces = extract(level, verts, rings=config.GRID_RINGS)
    return sub, points[sub_to_cur], np.searchsorted(sub_faces, start)


def side_indices(depth: int, quad: bool) -> np.ndarray:
    """(k, N+1) grid indices along each side, from corner k to corner k+1."""
    N = 1 << depth
    t = np.arange(N + 1)
    if quad:
        W = N + 1
        return np.stack([t, N + t * W, (N - t) + N * W, (N - t) * W])
    row = lambda j: j * (N + 1) - j * (j - 1) // 2  # noqa: E731
    return np.stack([t, row(t) + (N - t), row(N - t)])


def node_boxes(P: np.ndarray, depth: int, quad: bool):
    """Quadtree boxes (m, K, 3) of grids P (m, G, 3): leaves from their corners, then up
    (level ``l``'s 4^l boxes at ``(4^l - 1) / 3``)."""
    lc = leaf_corners(depth, quad)
    corners = P[:, lc]  # (m, 4^n, k, 3)
    lo = [corners.min(axis=2)]
    hi = [corners.max(axis=2)]
    while lo[0].shape[1] > 1:
        m, n = lo[0].shape[:2]
        lo.insert(0, lo[0].reshape(m, n // 4, 4, 3).min(axis=2))
        hi.insert(0, hi[0].reshape(m, n // 4, 4, 3).max(axis=2))
    return np.concatenate(lo, axis=1), np.concatenate(hi, axis=1)


def snap_sides(P: np.ndarray, depth: int, quad: bool, side_depth: np.ndarray):
    """Move boundary points of sides shared with a coarser patch (``side_depth`` (m, k): the
    depth each side is sampled at, -1 for none) onto the coarser patch's polyline (linear
    interpolation of the points it shares), in place."""
    sides = side_indices(depth, quad)
    N = 1 << depth
    for k in range(sides.shape[0]):
        for de in np.unique(side_depth[:, k]):
            if de >= depth or de < 0:
                continue
            rows = np.nonzero(side_depth[:, k] == de)[0]
            r = 1 << (depth - de)
            t = np.arange(N + 1)
            t0 = (t // r) * r
            t1 = np.minimum(t0 + r, N)
            w = ((t - t0) / r)[None, :, None]
            idx = sides[k]
            Q = P[rows][:, idx]
            P[rows[:, None], idx[None, :]] = (1.0 - w) * Q[:, t0] + w * Q[:, t1]
