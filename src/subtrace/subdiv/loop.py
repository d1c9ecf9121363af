"""Loop masks (OpenSubdiv Sdc::Scheme<LOOP>): weights only, no topology.

Edge masks weight the two endpoints and the vertex opposite the edge in each incident
triangle; vertex masks weight the vertex and the far ends of its incident edges. Catmull-
Clark's module has the same names.
"""

from __future__ import annotations

import math

import numpy as np

from subtrace.runtime.jit import callee_njit, nb

REGULAR_VALENCE = 6


@callee_njit
def _beta(valence):
    # OpenSubdiv evaluates this cosine in single precision (cosf)
    inv = 1.0 / valence
    c = math.cos(math.pi * 2.0 * inv)
    return 0.25 * c + 0.375


def subdominant_eigenvalue(valence):
    """Subdominant eigenvalue of the smooth Loop rule at a vertex of this valence (scalar
    or array; 1/2 for valence 6): how fast the one-ring shrinks per level."""
    return 3.0 / 8.0 + np.cos(2.0 * np.pi / np.asarray(valence, dtype=np.float64)) / 4.0


@callee_njit
def smooth_edge_weights(n_faces, tri0, tri1, smooth_triangles):
    """(endpoint weight, weight of each opposite vertex) of a smooth edge point."""
    if n_faces == 2:
        return 0.375, 0.125
    return 0.375, 0.125 * 2.0 / n_faces


@callee_njit
def smooth_vertex_weights(valence):
    """(vertex, each edge end, face point = 0) weights of the smooth vertex rule."""
    if valence == 6:
        return 0.625, 0.0625, 0.0
    b = _beta(valence)
    ew = (0.625 - b * b) / valence
    return 1.0 - ew * valence, ew, 0.0


@callee_njit
def smooth_limit_weights(valence):
    """(vertex, each edge end, 0) weights of the smooth limit position."""
    if valence == 6:
        return 0.5, 1.0 / 12.0, 0.0
    b = _beta(valence)
    b = (0.625 - b * b) / valence
    ew = 1.0 / (valence + 3.0 / (8.0 * b))
    return 1.0 - ew * valence, ew, 0.0


def smooth_tangent_weights(valence: int):
    """Weights of the first limit tangent over the ordered ring of edge ends: (edge (n,), None)."""
    n = valence
    i = np.arange(n)
    return np.cos(2.0 * math.pi * i / n), None
