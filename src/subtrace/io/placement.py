"""Where an ``[[object]]`` stands: its keys ``translate``, ``rotate``, ``orient``, ``scale``
and ``matrix`` checked and made into one affine 4x4 matrix (``p' = M [p, 1]``, translation
in the last column).

* ``translate = [x, y, z]``;
* ``rotate = [rx, ry, rz]``: degrees about the fixed X, then Y, then Z axis (right-handed:
  a positive angle turns Y towards Z about X); or ``orient = [w, x, y, z]``, a quaternion
  (real part first, as USD's ``xformOp:orient``; normalised here), not both;
* ``scale``: a number, or ``[sx, sy, sz]``, none of them 0 (a negative one mirrors);
* ``matrix``: 4 rows of 4 numbers, its last row ``[0, 0, 0, 1]``, its 3x3 part invertible;
  alone (not with the others).

The others compose as ``translate * rotate * scale`` (scaled first, then turned, then
moved: USD's usual op order). Subdivision commutes with affine maps (every rule is an
affine combination of points), so the placed cage's limit surface is the cage's own, placed.
"""

from __future__ import annotations

import math

import numpy as np

from subtrace.errors import SceneError, show_value

KEYS = ("translate", "rotate", "orient", "scale", "matrix")


def _numbers(value, n: int, what: str) -> list[float]:
    if (isinstance(value, (str, bytes, dict)) or not hasattr(value, "__len__")
            or len(value) != n or not all(isinstance(v, (int, float)) and
                                          not isinstance(v, bool) for v in value)):
        raise SceneError(f"expected {what}, got {show_value(value)}")
    out = [float(v) for v in value]
    if not all(math.isfinite(v) for v in out):
        raise SceneError(f"expected finite numbers, got {show_value(value)}")
    return out


def check_translate(value) -> np.ndarray:
    return np.array(_numbers(value, 3, "3 numbers [x, y, z]"))


def check_rotate(value) -> np.ndarray:
    """The rotation matrix of ``[rx, ry, rz]`` degrees (X, then Y, then Z)."""
    rx, ry, rz = (math.radians(a) for a in _numbers(value, 3, "3 angles in degrees "
                                                    "[about x, about y, about z]"))
    cx, sx, cy, sy, cz, sz = (math.cos(rx), math.sin(rx), math.cos(ry), math.sin(ry),
                              math.cos(rz), math.sin(rz))
    x = np.array([[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]])
    y = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
    z = np.array([[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]])
    return z @ y @ x


def check_orient(value) -> np.ndarray:
    """The rotation matrix of the quaternion ``[w, x, y, z]`` (normalised)."""
    q = np.array(_numbers(value, 4, "a quaternion [w, x, y, z]"))
    norm = float(np.linalg.norm(q))
    if not norm > 0.0:
        raise SceneError("the quaternion is zero; give [w, x, y, z] of a rotation "
                         "([1, 0, 0, 0]: none)")
    w, x, y, z = q / norm
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def check_scale(value) -> np.ndarray:
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        s = _numbers([value] * 3, 3, "a number or 3 numbers [sx, sy, sz]")
    else:
        s = _numbers(value, 3, "a number or 3 numbers [sx, sy, sz]")
    if any(v == 0.0 for v in s):
        raise SceneError(f"a scale of 0 flattens the object; got {show_value(value)}")
    return np.array(s)


def check_matrix(value) -> np.ndarray:
    if (isinstance(value, (str, bytes, dict)) or not hasattr(value, "__len__")
            or len(value) != 4):
        raise SceneError(f"expected 4 rows of 4 numbers, got {show_value(value)}")
    m = np.array([_numbers(row, 4, "4 rows of 4 numbers") for row in value])
    if not np.array_equal(m[3], [0.0, 0.0, 0.0, 1.0]):
        raise SceneError(f"the last row must be [0, 0, 0, 1] (an affine map: the "
                         f"translation is the last column), got {show_value(value[3])}")
    if not abs(float(np.linalg.det(m[:3, :3]))) > 0.0:
        raise SceneError("the matrix is singular (it flattens the object)")
    return m


def compose(translate=None, rotate=None, scale=None) -> np.ndarray:
    """The 4x4 matrix ``translate * rotate * scale`` of the checked parts (None: none)."""
    m = np.eye(4)
    if scale is not None:
        m[:3, :3] = np.diag(scale)
    if rotate is not None:
        m[:3, :3] = rotate @ m[:3, :3]
    if translate is not None:
        m[:3, 3] = translate
    return m


def as_tuple(m: np.ndarray) -> tuple:
    """A matrix as nested tuples (a frozen scene's field)."""
    return tuple(tuple(float(x) for x in row) for row in m)


def place(points: np.ndarray, matrix) -> np.ndarray:
    """(n,3) points mapped by the 4x4 affine ``matrix``."""
    m = np.asarray(matrix, dtype=np.float64)
    return np.asarray(points, dtype=np.float64) @ m[:3, :3].T + m[:3, 3]
