"""Small procedural cages for tests, benchmarks and examples (no file needed).

Each function returns a :class:`subtrace.mesh.cage.Cage` (positions (n,3) float64, quads).
"""

from __future__ import annotations

import numpy as np

from subtrace.mesh.cage import make_cage


def torus_cage(n_major: int = 14, n_minor: int = 14, R: float = 1.0, r: float = 0.35):
    """A closed torus cage of ``n_major x n_minor`` quads (every vertex of valence 4, so
    every patch is a regular bicubic), centred at the origin around the z axis. 14 x 14 gives
    the 196 patches of the paper's second experiment."""
    i, j = np.meshgrid(np.arange(n_major), np.arange(n_minor), indexing="ij")
    a = 2 * np.pi * i / n_major
    b = 2 * np.pi * j / n_minor
    pts = np.stack([(R + r * np.cos(b)) * np.cos(a), (R + r * np.cos(b)) * np.sin(a),
                    r * np.sin(b)], axis=-1).reshape(-1, 3)
    vid = lambda p, q: (p % n_major) * n_minor + (q % n_minor)  # noqa: E731
    faces = np.stack([vid(i, j), vid(i + 1, j), vid(i + 1, j + 1), vid(i, j + 1)],
                     axis=-1).reshape(-1, 4)
    return make_cage(pts, np.full(len(faces), 4), faces.ravel(), scheme="catmark")
