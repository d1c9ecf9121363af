"""Catmull-Clark masks (OpenSubdiv Sdc::Scheme<CATMARK>): weights only, no topology.

Vertex masks weight the vertex itself, the far ends of its incident edges and (for the
refinement masks) the new face points; limit masks weight the far ends of the edges and the
vertices diagonally opposite in each incident quad. Loop's module has the same names.
"""

from __future__ import annotations

import math

import numpy as np

from subtrace.runtime.jit import callee_njit, nb

REGULAR_VALENCE = 4
# OpenSubdiv's weight for edges next to triangles under "smoothtriangles smooth" (a float).
_TRI_EDGE_WEIGHT = 0.47


@callee_njit
def smooth_edge_weights(n_faces, tri0, tri1, smooth_triangles):
    """(endpoint weight, weight of each face point) of a smooth edge point."""
    if smooth_triangles and n_faces == 2 and (tri0 or tri1):
        f0 = _TRI_EDGE_WEIGHT if tri0 else 0.25
        f1 = _TRI_EDGE_WEIGHT if tri1 else 0.25
        fw = 0.5 * (f0 + f1)
        return 0.5 * (1.0 - 2.0 * fw), fw
    if n_faces == 2:
        return 0.25, 0.25
    return 0.25, 0.5 / n_faces


@callee_njit
def smooth_vertex_weights(valence):
    """(vertex, each edge end, each face point) weights of the smooth vertex rule."""
    n = float(valence)
    return (n - 2.0) / n, 1.0 / (n * n), 1.0 / (n * n)


@callee_njit
def smooth_limit_weights(valence):
    """(vertex, each edge end, each diagonal vertex) weights of the smooth limit position."""
    if valence == 4:
        return 4.0 / 9.0, 1.0 / 9.0, 1.0 / 36.0
    n = float(valence)
    fw = 1.0 / (n * (n + 5.0))
    ew = 4.0 * fw
    return 1.0 - n * (ew + fw), ew, fw


def subdominant_eigenvalue(valence):
    """Subdominant eigenvalue of the smooth Catmull-Clark rule at a vertex of this valence
    (scalar or array; 1/2 for valence 4): how fast the one-ring shrinks per level."""
    theta = 2.0 * np.pi / np.asarray(valence, dtype=np.float64)
    c = np.cos(theta)
    return 5.0 / 16.0 + (c + np.cos(theta / 2) * np.sqrt(2 * (9 + c))) / 16.0


def smooth_tangent_weights(valence: int):
    """Weights of the first limit tangent over the ordered ring: (edge (n,), diagonal (n,)).

    The second tangent is the same mask rotated by one position. Face i of the ring lies
    between edges i and i+1, its diagonal vertex between them.
    """
    n = valence
    if n == 4:
        return np.array([4.0, 0.0, -4.0, 0.0]), np.array([1.0, -1.0, -1.0, 1.0])
    theta = 2.0 * math.pi / n
    lam = float(subdominant_eigenvalue(n))
    fscale = 1.0 / (4.0 * lam - 1.0)
    i = np.arange(n)
    ew = 4.0 * np.cos(i * theta)
    fw = fscale * (np.cos(i * theta) + np.cos((i + 1) * theta))
    return ew, fw
