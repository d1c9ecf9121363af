"""subtrace.lights: the room of the light kinds. Everything a kind is lives here: its
record (:class:`Light`), its scene keys and how they are checked (:func:`parse_light`, which
``io/scene.py`` asks for every ``[[light]]`` table), its row of the array the kernels take
(:func:`light_array`), how it lights a point and where its shadow rays go (the jitted
helpers :func:`incoming`, :func:`irradiance_at`, :func:`shadow_samples` and
:func:`shadow_target`, which ``shade.py``'s kernels inline), and what bounds its shadow
rays for the cull to the view (:func:`shadow_cast`, which ``accel/cull.py`` asks). A new kind is its entry in each.

The kinds:

* **directional** (``direction``: the unit direction the light travels): irradiance 1, one
  shadow ray along ``-direction``, unbounded;
* **point** (``position``): irradiance 1 / distance^2, one shadow ray to the position;

Array layout (:func:`light_array`): (L, ROW) float64, one row per light: ``KIND``, then
x, y, z (``AT``: a directional light's unit travel, else its position), the colour times
the intensity (``RGB``), the shadow rays it takes per shading point (``SAMPLES``; 1 for a
directional or point light) and one number of the kind's own (``PARAM``, 0 for those).

A light of several shadow rays per shading point samples them per pixel: each ray that
is shaded carries a key (:func:`ray_keys`: its image pixel times ``KEY_STRIDE`` plus its
anti-aliasing sample, 0 for the centre ray) from which the kind chooses its rays, so that
nothing depends on the thread count or on how the image is cut into tiles or bands.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from subtrace.camera import check_vector
from subtrace.errors import SceneError, show_value
from subtrace.runtime.jit import leaf_njit, llvm_inline_njit, nb

# kinds (column KIND of light_array)
DIRECTIONAL, POINT = 0, 1
KIND, AT, RGB, SAMPLES, PARAM = 0, 1, 4, 7, 8  # columns of a row
ROW = 9  # columns of a row

DEFAULT_LIGHT_COLOR = (1.0, 1.0, 1.0)
# a ray's key: its image pixel times KEY_STRIDE plus its anti-aliasing sample (below
# io.scene.MAX_SAMPLES)
KEY_STRIDE = 64


@dataclass(frozen=True)
class Light:
    """A light: directional (unit ``direction`` the light travels, ``position`` None) or
    point (``position``), with its colour and intensity."""

    direction: tuple[float, float, float] | None = None
    color: tuple[float, float, float] = DEFAULT_LIGHT_COLOR
    intensity: float = 1.0
    position: tuple[float, float, float] | None = None

    @property
    def kind(self) -> int:
        """DIRECTIONAL or POINT."""
        return DIRECTIONAL if self.position is None else POINT


# --------------------------------------------------------------------------------------
# the scene keys
# --------------------------------------------------------------------------------------

# every key of a [[light]] table (io.scene.SCENE_KEYS["light"]); per kind, in the order
# they are told apart (the first whose marking keys a table has), its name, the keys that
# mark it and its own keys (a table may add the common ones)
LIGHT_KEYS = ("direction", "position", "color", "intensity")
_COMMON = ("color", "intensity")
_KINDS = (
    ("point light", ("position",), ("position",)),
    ("directional light", ("direction",), ("direction",)),
)
_NEEDS = ("every [[light]] needs direction = [x, y, z] (the direction the light travels) "
          "or position = [x, y, z] (a point light)")


def parse_light(table: dict, value, error) -> Light:
    """The :class:`Light` of one ``[[light]]`` table (its keys checked against LIGHT_KEYS
    already). ``value(key, check, *args)``: ``check(table[key], *args)`` with a SceneError
    it raises put at the key's line; ``error(key, problem)``: a SceneError at the key's
    line (None: the table's)."""
    if "direction" in table and "position" in table:
        raise error("position", "give a light either a direction (directional) or a "
                    "position (point light), not both")
    kind = next((k for k in _KINDS if all(x in table for x in k[1])), None)
    if kind is None:
        raise error(None, f"missing key direction: {_NEEDS}")
    name, _, keys = kind
    for key in table:
        if key not in keys and key not in _COMMON:
            raise error(key, f"{key} is not a key of a {name} ({', '.join(keys + _COMMON)})")
    values = {}
    if "direction" in table:
        direction = value("direction", check_vector, table["direction"], "")
        norm = math.sqrt(sum(c * c for c in direction))
        if norm == 0.0:
            raise error("direction", "the direction is zero; give a non-zero vector")
        values["direction"] = tuple(c / norm for c in direction)
    else:
        values["position"] = value("position", check_vector, table["position"], "")
    if "color" in table:
        values["color"] = value("color", _color, table["color"])
    if "intensity" in table:
        values["intensity"] = value("intensity", _non_negative, table["intensity"])
    return Light(**values)


def _number(value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f"expected a number, got {show_value(value)}")
    value = float(value)
    if not math.isfinite(value):
        raise SceneError(f"expected a finite number, got {value}")
    return value


def _non_negative(value) -> float:
    value = _number(value)
    if value < 0.0:
        raise SceneError(f"must be 0 or more, got {value:g}")
    return value


def _color(value) -> tuple[float, float, float]:
    rgb = check_vector(value, "color")
    if not all(0.0 <= c <= 1.0 for c in rgb):
        raise SceneError(
            f"color components must be between 0 and 1 (linear RGB), got {show_value(value)}")
    return rgb


# --------------------------------------------------------------------------------------
# the kernels' rows, the rays' keys, the cull's bounds
# --------------------------------------------------------------------------------------


def light_array(lights) -> np.ndarray:
    """(L, ROW) float64 rows of :class:`Light` s (the module comment's layout)."""
    rows = []
    for light in lights:
        kind = light.kind
        at = light.direction if kind == DIRECTIONAL else light.position
        rows.append([kind, *at, *(np.asarray(light.color) * light.intensity), 1, 0.0])
    return np.array(rows, dtype=np.float64).reshape(-1, ROW)


def directional_rows(lights) -> np.ndarray:
    """(D, 6) float64: the directional lights' unit travel and colour times intensity."""
    return np.array([[*l.direction, *(np.asarray(l.color) * l.intensity)]
                     for l in lights if l.kind == DIRECTIONAL],
                    dtype=np.float64).reshape(-1, 6)


def sampled(rows) -> bool:
    """Whether any light of ``rows`` (:func:`light_array`) sends more than one shadow ray
    per shading point: then the shaded rays need their keys (:func:`ray_keys`)."""
    return bool(len(rows)) and bool(np.any(np.asarray(rows)[:, SAMPLES] > 1))


def ray_keys(pixels, samples=None) -> np.ndarray:
    """(n,) int64 keys of shaded rays: ``pixels`` (n,) their image pixels (row * image
    width + column), ``samples`` (n,) their anti-aliasing sample (None: 0, centre rays)."""
    keys = np.asarray(pixels, np.int64) * KEY_STRIDE
    return keys if samples is None else keys + np.asarray(samples, np.int64)


def shadow_cast(light: Light):
    """How the cull to the view (``accel/cull.py``) bounds the light's shadow rays:
    ``("parallel", unit travel)`` (rays along one direction), ``("point", position)`` (rays
    to one point), or None (not bounded: the scene is not culled)."""
    kind = light.kind
    if kind == DIRECTIONAL:
        return "parallel", np.asarray(light.direction, np.float64)
    if kind == POINT:
        return "point", np.asarray(light.position, np.float64)
    return None


# --------------------------------------------------------------------------------------
# the kernels' helpers (inlined into shade.py's kernels)
# --------------------------------------------------------------------------------------


@leaf_njit
def incoming(lights, k, frame, t, dx, dy, dz):
    """Light ``k`` at the hit ``eye + t d``: the unit direction it travels there and its
    irradiance factor (1 for a directional light, 1 / distance^2 from a point light)."""
    if lights[k, KIND] == DIRECTIONAL:
        return lights[k, 1], lights[k, 2], lights[k, 3], 1.0
    lx = frame[0, 0] + t * dx - lights[k, 1]
    ly = frame[0, 1] + t * dy - lights[k, 2]
    lz = frame[0, 2] + t * dz - lights[k, 3]
    d2 = lx * lx + ly * ly + lz * lz
    if not d2 > 0.0:
        return 0.0, 0.0, 0.0, 0.0
    inv = 1.0 / math.sqrt(d2)
    return lx * inv, ly * inv, lz * inv, 1.0 / d2


@llvm_inline_njit
def irradiance_at(lights, k, x, y, z):
    """Light ``k`` at the point (x, y, z): the unit direction towards it, its distance (inf:
    directional) and its irradiance factor (1 for a directional light, 1 / distance^2 from
    a point light, 0 at it)."""
    if lights[k, KIND] == DIRECTIONAL:
        return -lights[k, 1], -lights[k, 2], -lights[k, 3], np.inf, 1.0
    lx, ly, lz = lights[k, 1] - x, lights[k, 2] - y, lights[k, 3] - z
    d2 = lx * lx + ly * ly + lz * lz
    d = np.sqrt(d2)
    return lx / d, ly / d, lz / d, d, (1.0 / d2 if d2 > 0.0 else 0.0)


@leaf_njit
def shadow_samples(lights, k):
    """The shadow rays light ``k`` takes per shading point."""
    return np.int64(lights[k, SAMPLES])


@llvm_inline_njit
def shadow_target(lights, k, s, key, px, py, pz):
    """Shadow ray ``s`` of the point (px, py, pz) towards light ``k``, for the shaded ray of
    ``key`` (:func:`ray_keys`; read only where the light takes several rays): its unit
    direction x, y, z and the distance to where it meets the light (inf: directional)."""
    kind = lights[k, KIND]
    if kind == DIRECTIONAL:
        return -lights[k, 1], -lights[k, 2], -lights[k, 3], np.inf
    vx, vy, vz = lights[k, 1] - px, lights[k, 2] - py, lights[k, 3] - pz
    dist = np.sqrt(vx * vx + vy * vy + vz * vz)
    return vx / dist, vy / dist, vz / dist, dist
