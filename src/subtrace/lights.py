"""subtrace.lights: the room of the light kinds. Everything a kind is lives here: its
record (:class:`Light`), its scene keys and how they are checked (:func:`parse_light`, which
``io/scene.py`` asks for every ``[[light]]`` table), its row of the array the kernels take
(:func:`light_array`), how it lights a point and where its shadow rays go (the jitted
helpers :func:`incoming`, :func:`irradiance_at`, :func:`shadow_samples` and
:func:`shadow_target`, which ``shade.py``'s kernels inline), and what bounds its shadow
rays for the cull to the view (:func:`shadow_cast`, which ``accel/cull.py`` asks). A new
kind is its entry in each.

The kinds:

* **directional** (``direction``: the unit direction the light travels): irradiance 1, one
  shadow ray along ``-direction``, unbounded; with ``angle`` > 0 (degrees: the angular
  diameter of the sun it stands for, as USD's DistantLight and Blender's sun take it, the
  real sun's 0.53) a disc of uniform radiance that far: ``samples`` shadow rays per
  shading point, uniform in the cone of that diameter around ``-direction``, the share
  that arrives unblocked the visibility (a penumbra as wide as the occluder's distance
  times the angle); its shadows are not bounded for the cull to the view either;
* **point** (``position``): irradiance 1 / distance^2, one shadow ray to the position;
* **sphere** (``position``, ``radius`` >= 0, ``samples`` shadow rays per shading point): a
  ball of uniform radiance. Unshadowed, such a ball above a point's horizon lights it as a
  point light of the same power at its centre does, so the lighting is the point light's
  (direction and 1 / distance^2 from the centre), scaled by the fraction of the ball's
  solid angle the point sees: its shadow rays go to points of the ball's near side,
  uniform in the cone of directions it subtends, and the share that arrives unblocked is
  the visibility (a penumbra). Radius 0 is a point light, ray for ray. The cull to the
  view does not bound its rays: a scene with a sphere light of radius > 0 is not culled;
* **quad** (``kind = "quad"``: ``position`` its centre, ``u`` and ``v`` its half edges,
  corners ``position`` ± u ± v) and **disk** (``kind = "disk"``: ``position``, unit
  ``normal``, ``radius`` > 0): one-sided Lambertian emitters of uniform radiance (on the
  side of u x v, or of the normal; nothing behind), of the power of a point light of the
  same intensity (4 pi intensity from one side: radiance 4 intensity / area). Their
  unshadowed light is the irradiance vector (:func:`_area_vector`: the integral of the
  direction towards the light over the solid angle it subtends, times the radiance),
  closed forms: Lambert's formula for the quad, the form factors of a differential area
  to a disk for the disk; a surface of normal n receives n . vector, exact where the
  light lies wholly above its horizon (where it straddles it the part below counts
  against the rest; the shading keeps it at 0 or more), and the vector's direction and
  length stand for a point light's direction and 1 / distance^2 in the shading (its
  specular lobe takes that direction). ``samples`` shadow rays per shading point go to
  points uniform over the area (the R2 points below, mapped to a quad's parameters or a
  disk's polar coordinates), and the share that arrives unblocked is the visibility. The
  cull to the view does not bound their rays: a scene with one is not culled.

* **environment** (``kind = "environment"``: ``file`` a lat-long image OpenImageIO reads,
  EXR or HDR (linear; an sRGB one is decoded), or none: a constant radiance; its
  ``color`` times ``intensity`` scales it): light from every direction at infinity. Row 0
  of the image looks up (+Y), the last row down (-Y), the middle column along -Z
  (forward) and three quarters across along +X (:func:`environment_tail`). Its
  unshadowed irradiance of a normal is the image's to the spherical harmonics of order
  2 (:func:`environment_irradiance`, Ramamoorthi and Hanrahan: exact for a constant sky
  and for one colour per hemisphere, within a few percent of the peak for others); its
  ``samples`` shadow rays per shading point go to infinity in directions drawn by the
  image's luminance (a 2-D piecewise-constant distribution over at most ENV_MAX_TABLE
  cells: the rows' shares of luminance times solid angle, then each row's columns'),
  and the share of them that arrives, each weighted by its cosine with the normal
  (:func:`shadow_weight`; those below the horizon weigh 0), is the visibility. It has
  no specular lobe, is not seen as the background, and is not bounded for the cull.

Array layout (:func:`light_array`): (L, ROW) float64, one row per light: ``KIND``, then
x, y, z (``AT``: a directional light's unit travel, else its position or centre), the
colour times the intensity (``RGB``), the shadow rays it takes per shading point
(``SAMPLES``; 1 for a directional or point light), one number of the kind's own
(``PARAM``: a sphere's or disk's radius, a directional light's half angle in radians, 1
for a quad; 0 for a point light) and two vectors (``EDGE_U``, ``EDGE_V``: a quad's u and
v, a disk's unit normal and 0; 0 for the others); an environment's row goes on (ENV)
and the others are padded with 0 to its width.

A light of several shadow rays per shading point samples them per pixel: each ray that
is shaded carries a key (:func:`ray_keys`: its image pixel times ``KEY_STRIDE`` plus its
anti-aliasing sample, 0 for the centre ray) from which the kind chooses its rays, so that
nothing depends on the thread count or on how the image is cut into tiles or bands. A
sphere's shadow ray ``s`` of sample ``a`` takes point ``a * samples + s`` of the R2
low-discrepancy sequence turned by a hash of the pixel (a Cranley-Patterson rotation): the
rays of a pixel's anti-aliasing samples together are the first ``rays * samples`` points of
one stratified sequence, and the more rays an edge pixel gets, the finer its penumbra. A
soft sun's rays take the same points (:func:`_cone_ray`, the cone of its angle).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from subtrace.camera import check_vector
from subtrace.errors import SceneError, show_value
from subtrace.runtime.jit import leaf_njit, llvm_inline_njit

# kinds (column KIND of light_array)
DIRECTIONAL, POINT, SPHERE, QUAD, DISK, ENVIRONMENT = 0, 1, 2, 3, 4, 5
KIND, AT, RGB, SAMPLES, PARAM, EDGE_U, EDGE_V = 0, 1, 4, 7, 8, 9, 12  # columns of a row
ROW = 15  # columns of a row
AREA_KINDS = ("quad", "disk", "environment")  # the values of a [[light]] table's kind key
ENV = ROW  # an environment's row goes on: its irradiance (27: per colour 9 coefficients of
# E(n) = k0 + k1 y + k2 z + k3 x + k4 x z + k5 z y + k6 (3 y^2 - 1) + k7 x y + k8 (x^2 - z^2)),
# then its sampling table's rows h and columns w, the rows' cos(theta) edges (h + 1), the
# columns' phi edges (w + 1), the rows' cumulative shares (h + 1), each row's columns'
# cumulative shares (h (w + 1))
ENV_MAX_TABLE = (256, 128)  # the sampling table's columns and rows at most

DEFAULT_LIGHT_COLOR = (1.0, 1.0, 1.0)
DEFAULT_SPHERE_SAMPLES = 8  # a sphere light's (or soft sun's) shadow rays per shading point
MAX_SPHERE_SAMPLES = 256
MAX_SUN_ANGLE = 90.0  # degrees: a soft sun's angular diameter, at most
# a ray's key: its image pixel times KEY_STRIDE plus its anti-aliasing sample (below
# io.scene.MAX_SAMPLES)
KEY_STRIDE = 64


@dataclass(frozen=True)
class Light:
    """A light: directional (unit ``direction`` the light travels, ``position`` None;
    ``angle`` its angular diameter in degrees, None or 0: a hard one), point (``position``)
    or sphere (``position`` its centre and ``radius``), or (``kind_key`` "quad" or "disk") an
    area light: ``position`` its centre and ``u``, ``v`` a quad's half-edge vectors or
    ``normal`` (unit) and ``radius`` a disk's; with its colour and intensity; ``samples``:
    a sphere's, soft sun's or area light's shadow rays per shading point (None:
    DEFAULT_SPHERE_SAMPLES)."""

    direction: tuple[float, float, float] | None = None
    color: tuple[float, float, float] = DEFAULT_LIGHT_COLOR
    intensity: float = 1.0
    position: tuple[float, float, float] | None = None
    radius: float | None = None
    samples: int | None = None
    angle: float | None = None
    kind_key: str | None = None  # the table's kind: "quad", "disk" or "environment"
    u: tuple[float, float, float] | None = None  # a quad's half-edge vectors
    v: tuple[float, float, float] | None = None
    normal: tuple[float, float, float] | None = None  # a disk's unit normal
    file: str | None = None  # an environment's lat-long image (None: its colour alone)

    @property
    def kind(self) -> int:
        """DIRECTIONAL, POINT, SPHERE, QUAD or DISK."""
        if self.kind_key is not None:
            return {"quad": QUAD, "disk": DISK}.get(self.kind_key, ENVIRONMENT)
        if self.position is None:
            return DIRECTIONAL
        return POINT if self.radius is None else SPHERE


# --------------------------------------------------------------------------------------
# the scene keys
# --------------------------------------------------------------------------------------

# every key of a [[light]] table (io.scene.SCENE_KEYS["light"]); per kind, in the order
# they are told apart (the first whose marking keys a table has), its name, the keys that
# mark it and its own keys (a table may add the common ones)
LIGHT_KEYS = ("kind", "direction", "angle", "position", "radius", "samples", "u", "v",
              "normal", "file", "color", "intensity")
_COMMON = ("color", "intensity")
# the area kinds (kind = "quad" or "disk"): their names and own keys (each one needed but
# samples)
_AREA = {"quad": ("quad light", ("position", "u", "v", "samples")),
         "disk": ("disk light", ("position", "normal", "radius", "samples")),
         "environment": ("environment light", ("samples",))}
_KINDS = (
    ("sphere light", ("radius",), ("position", "radius", "samples")),
    ("point light", ("position",), ("position",)),
    ("directional light", ("direction",), ("direction", "angle", "samples")),
)
_NEEDS = ("every [[light]] needs direction = [x, y, z] (the direction the light travels) "
          "or position = [x, y, z] (a point light, with radius = r a sphere light)")


def parse_light(table: dict, value, error, base_dir=None) -> Light:
    """The :class:`Light` of one ``[[light]]`` table (its keys checked against LIGHT_KEYS
    already). ``value(key, check, *args)``: ``check(table[key], *args)`` with a SceneError
    it raises put at the key's line; ``error(key, problem)``: a SceneError at the key's
    line (None: the table's); ``base_dir``: the folder an environment's ``file`` is relative
    to (None: the working directory)."""
    if table.get("kind") == "environment":
        return _parse_environment(table, value, error, base_dir)
    if "kind" in table:
        return _parse_area(table, value, error)
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
        if "position" not in table:
            raise error(None, "missing key position: a sphere light needs position = "
                        "[x, y, z] (its centre) besides its radius")
        values["position"] = value("position", check_vector, table["position"], "")
    if "radius" in table:
        values["radius"] = value("radius", _radius, table["radius"])
    if "angle" in table:
        values["angle"] = value("angle", _angle, table["angle"])
    if "samples" in table:
        values["samples"] = value("samples", _sphere_samples, table["samples"])
    if "color" in table:
        values["color"] = value("color", _color, table["color"])
    if "intensity" in table:
        values["intensity"] = value("intensity", _non_negative, table["intensity"])
    return Light(**values)


# --light KIND:KEY=VALUE,... (the render command's flag): each kind's name and what its
# table takes besides the flag's keys (a quad or disk: its kind key)
FLAG_KINDS = {"sun": {}, "directional": {}, "point": {}, "sphere": {},
              "quad": {"kind": "quad"}, "disk": {"kind": "disk"}}


def parse_light_flag(text: str) -> Light:
    """The :class:`Light` of one ``--light`` value, ``KIND:KEY=VALUE,...`` (KIND of
    FLAG_KINDS; the keys of a ``[[light]]`` table, a vector as 3 numbers: e.g.
    ``sphere:position=1,2,3,radius=0.5,intensity=4``); a bad one raises one SceneError
    naming the flag, its value and the key."""
    kind, sep, rest = str(text).partition(":")
    kind = kind.strip().lower()
    if not sep or kind not in FLAG_KINDS:
        raise SceneError(f"expected KIND:KEY=VALUE,... with KIND one of "
                         f"{', '.join(FLAG_KINDS)}, got {text!r}", key="--light")
    table = dict(FLAG_KINDS[kind])
    key = None
    for item in rest.split(","):
        name, eq, item = item.partition("=")
        if eq:
            key = name.strip()
            if not key or key in table or key not in LIGHT_KEYS or key == "kind":
                raise SceneError(f"{text!r}: {key!r} is not a key of a light or is given "
                                 f"twice (keys: {', '.join(LIGHT_KEYS[1:])})", key="--light")
            table[key] = []
        elif key is None:
            raise SceneError(f"{text!r}: expected KEY=VALUE after {kind}:", key="--light")
        else:
            item = name
        table[key].append(_flag_number(text, key, item))
    for k in table:
        if k != "kind" and len(table[k]) == 1:
            table[k] = table[k][0]  # (one number; else a vector)

    def value(key, check, *args):
        try:
            return check(*args)
        except SceneError as err:
            raise SceneError(f"{text!r}: {key}: {err.problem}", key="--light") from None

    def error(key, problem):
        return SceneError(f"{text!r}: {problem}" if key is None else
                          f"{text!r}: {key}: {problem}", key="--light")

    for need in _FLAG_NEEDS.get(kind, ()):
        if need not in table:
            raise error(None, f"missing key {need}: a {kind} light needs "
                        f"{', '.join(_FLAG_NEEDS[kind])}")
    if kind == "point" and "radius" in table:
        raise error("radius", "a point light has no radius (sphere:position=...,radius=R)")
    return parse_light(table, value, error)


_FLAG_NEEDS = {"sun": ("direction",), "directional": ("direction",), "point": ("position",),
               "sphere": ("position", "radius")}


def _flag_number(text: str, key: str, item: str):
    """One number of a ``--light`` value: an int where it reads as one, else a float."""
    item = item.strip()
    try:
        return int(item)
    except ValueError:
        pass
    try:
        return float(item)
    except ValueError:
        raise SceneError(f"{text!r}: {key}: expected a number, got {item!r}",
                         key="--light") from None


def _parse_area(table: dict, value, error) -> Light:
    """The :class:`Light` of a ``[[light]]`` table with a ``kind`` key (an area light)."""
    kind = table["kind"]
    if not isinstance(kind, str) or kind not in _AREA:
        raise error("kind", f"kind must be one of {', '.join(map(repr, AREA_KINDS))} (the "
                    f"other lights are told by their keys), got {show_value(kind)}")
    name, keys = _AREA[kind]
    for key in table:
        if key != "kind" and key not in keys and key not in _COMMON:
            raise error(key, f"{key} is not a key of a {name} ({', '.join(keys + _COMMON)})")
    for key in keys[:-1]:
        if key not in table:
            raise error(None, f"missing key {key}: a {name} needs {', '.join(keys[:-1])}")
    values = {"kind_key": kind, "position": value("position", check_vector, table["position"], "")}
    if kind == "quad":
        values["u"] = value("u", check_vector, table["u"], "")
        values["v"] = value("v", check_vector, table["v"], "")
        if not np.linalg.norm(np.cross(values["u"], values["v"])) > 0.0:
            raise error("v", "a quad light's u and v (its half edges) must be non-zero and "
                        "not parallel")
    else:
        normal = value("normal", check_vector, table["normal"], "")
        norm = math.sqrt(sum(c * c for c in normal))
        if not norm > 0.0:
            raise error("normal", "the normal is zero; give a non-zero vector")
        values["normal"] = tuple(c / norm for c in normal)
        values["radius"] = value("radius", _disk_radius, table["radius"])
    for key, check in (("samples", _sphere_samples), ("color", _color),
                       ("intensity", _non_negative)):
        if key in table:
            values[key] = value(key, check, table[key])
    return Light(**values)


def _parse_environment(table: dict, value, error, base_dir) -> Light:
    """The :class:`Light` of a ``kind = "environment"`` table: its image read (and kept,
    :func:`_environment_image`) here, so that a bad one is the table's error."""
    keys = ("file", "samples") + _COMMON
    for key in table:
        if key != "kind" and key not in keys:
            raise error(key, f"{key} is not a key of an environment light ({', '.join(keys)})")
    values = {"kind_key": "environment"}
    if "file" in table:
        if not isinstance(table["file"], str) or not table["file"]:
            raise error("file", f"expected the path of a lat-long image, got "
                        f"{show_value(table['file'])}")
        path = os.path.normpath(os.path.join(base_dir or os.getcwd(),
                                             os.path.expanduser(table["file"])))
        problem = _environment_image(path)[1]
        if problem:
            raise error("file", f"{path}: {problem}")
        values["file"] = path
    for key, check in (("samples", _sphere_samples), ("color", _color),
                       ("intensity", _non_negative)):
        if key in table:
            values[key] = value(key, check, table[key])
    return Light(**values)


_IMAGES: dict = {}  # path -> ((mtime, size), linear RGB (H, W, 3) float64)


def _environment_image(path: str):
    """(the image of ``path`` (H, W, 3) float64 linear RGB, None) or (None, the problem),
    read through OpenImageIO once per version of the file."""
    import OpenImageIO as oiio

    try:
        st = os.stat(path)
    except OSError:
        return None, "no such file"
    if os.path.isdir(path):
        return None, "is a directory, expected a lat-long image"
    stamp = (st.st_mtime_ns, st.st_size)
    if path in _IMAGES and _IMAGES[path][0] == stamp:
        return _IMAGES[path][1], None
    inp = oiio.ImageInput.open(path)
    if inp is None:
        return None, f"cannot read the image: {oiio.geterror().strip() or 'unknown format'}"
    try:
        spec = inp.spec()
        pixels = inp.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
    finally:
        inp.close()
    if pixels is None or spec.width < 1 or spec.height < 1:
        return None, "cannot read the pixels"
    pixels = np.asarray(pixels, np.float64).reshape(spec.height, spec.width, -1)
    rgb = pixels[..., :3] if pixels.shape[2] >= 3 else np.repeat(pixels[..., :1], 3, axis=2)
    if "srgb" in str(spec.getattribute("oiio:ColorSpace") or "").lower():
        rgb = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    rgb = np.ascontiguousarray(rgb)
    if not np.all(np.isfinite(rgb)) or rgb.min() < 0.0:
        return None, "its pixels must be finite and 0 or more (linear radiance)"
    _IMAGES[path] = (stamp, rgb)
    return rgb, None


def _disk_radius(value) -> float:
    value = _number(value)
    if not value > 0.0:
        raise SceneError(f"a disk light's radius must be more than 0, got {value:g}")
    return value


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


def _radius(value) -> float:
    value = _number(value)
    if value < 0.0:
        raise SceneError(f"a sphere light's radius must be 0 or more (0: a point light), "
                         f"got {value:g}")
    return value


def _angle(value) -> float:
    angle = _number(value)
    if not 0.0 <= angle <= MAX_SUN_ANGLE:
        raise SceneError(f"a sun's angle (its angular diameter, degrees) must be from 0 to "
                         f"{MAX_SUN_ANGLE:g}, got {show_value(value)}")
    return angle


def _sphere_samples(value) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not (
            1 <= value <= MAX_SPHERE_SAMPLES):
        raise SceneError(f"expected a whole number of shadow rays per shading point from 1 "
                         f"to {MAX_SPHERE_SAMPLES}, got {show_value(value)}")
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
    """(L, ROW) float64 rows of :class:`Light` s (the module comment's layout; wider where
    an environment's row goes on, the others' padded with 0)."""
    rows = []
    for light in lights:
        kind = light.kind
        at = light.direction if kind == DIRECTIONAL else light.position or (0.0, 0.0, 0.0)
        param = (light.radius if kind in (SPHERE, DISK) else
                 math.radians(light.angle or 0.0) / 2.0 if kind == DIRECTIONAL else
                 1.0 if kind in (QUAD, ENVIRONMENT) else 0.0)
        samples = 1 if not param > 0.0 else (
            DEFAULT_SPHERE_SAMPLES if light.samples is None else light.samples)
        edges = (*light.u, *light.v) if kind == QUAD else (
            (*light.normal, 0.0, 0.0, 0.0) if kind == DISK else (0.0,) * 6)
        row = [kind, *at, *(np.asarray(light.color) * light.intensity), samples, param,
               *edges]
        rows.append(np.concatenate([row, environment_tail(light)]) if kind == ENVIRONMENT
                    else np.asarray(row, np.float64))
    out = np.zeros((len(rows), max([ROW] + [len(r) for r in rows])))
    for k, row in enumerate(rows):
        out[k, :len(row)] = row
    return out


def environment_tail(light) -> np.ndarray:
    """The columns from ENV on of an environment's row (the layout at ENV): its image's
    (or, without one, a constant radiance 1's) irradiance coefficients and sampling
    table. The image is lat-long: row 0 looks up (+Y), the last row down, its middle
    column along -Z and its columns turn to +X at three quarters of the width
    (direction (sin t sin p, cos t, -sin t cos p), t = pi (row + 1/2) / height, p = 2 pi
    ((column + 1/2) / width - 1/2))."""
    image = np.ones((1, 1, 3)) if light.file is None else _environment_image(light.file)[0]
    if image is None:
        raise SceneError(f"{light.file}: {_environment_image(light.file)[1]}")
    height, width = image.shape[:2]
    mu = np.cos(np.pi * np.arange(height + 1) / height)  # (each row's edges: cos theta)
    phi = 2.0 * np.pi * (np.arange(width + 1) / width - 0.5)
    coeffs = _irradiance_coefficients(image, mu, phi)
    # the sampling table: cells of the image summed to at most ENV_MAX_TABLE
    w, h = min(width, ENV_MAX_TABLE[0]), min(height, ENV_MAX_TABLE[1])
    cols = np.round(np.arange(w + 1) * width / w).astype(np.int64)
    rows = np.round(np.arange(h + 1) * height / h).astype(np.int64)
    lum = image @ np.array([0.2126, 0.7152, 0.0722])
    solid = (mu[:-1] - mu[1:])[:, None] * np.diff(phi)[None, :] * lum  # (per pixel)
    cells = np.add.reduceat(np.add.reduceat(solid, rows[:-1], axis=0), cols[:-1], axis=1)
    if not cells.sum() > 0.0:  # (black: any directions, uniform)
        cells = (mu[rows[:-1]] - mu[rows[1:]])[:, None] * np.diff(phi[cols])[None, :]
    per_row = cells.sum(axis=1)
    marginal = np.concatenate([[0.0], np.cumsum(per_row)]) / per_row.sum()
    with np.errstate(invalid="ignore", divide="ignore"):
        cond = np.concatenate([np.zeros((h, 1)), np.cumsum(cells, axis=1)], axis=1) / \
            per_row[:, None]
    cond = np.where(per_row[:, None] > 0.0, cond, np.linspace(0.0, 1.0, w + 1)[None, :])
    return np.concatenate([coeffs.ravel(), [h, w], mu[rows], phi[cols], marginal,
                           cond.ravel()])


def environment_radiance(light) -> np.ndarray:
    """(H, W, 3) float64: environment ``light``'s radiance per direction, its lat-long
    image (the layout of :func:`environment_tail`; (1, 1, 3) without one) times its colour
    times its intensity (what a reflected ray that escapes sees of it: ``subtrace.reflect``)."""
    image = np.ones((1, 1, 3)) if light.file is None else _environment_image(light.file)[0]
    if image is None:
        raise SceneError(f"{light.file}: {_environment_image(light.file)[1]}")
    return image * (np.asarray(light.color, np.float64) * light.intensity)


def _irradiance_coefficients(image, mu, phi) -> np.ndarray:
    """(3, 9): per colour the coefficients k of the module comment's E(n) (at ENV): the
    irradiance of the piecewise-constant lat-long ``image`` (rows between the cos theta
    edges ``mu``, columns between the ``phi`` edges) to its spherical harmonics of order 2
    (Ramamoorthi and Hanrahan: exact for a radiance of those orders, as a constant or one
    colour per hemisphere; within a few percent of the peak for any other), each term the
    exact integral over each pixel."""
    m0, m1 = mu[:-1], mu[1:]  # (a row from m0 down to m1: its integral is from m1 to m0)

    def rows_of(f):  # the integral of f(mu) over each row
        return f(m0) - f(m1)

    sq = lambda m: np.sqrt(np.maximum(1.0 - m * m, 0.0))  # noqa: E731
    by_mu = {  # the antiderivatives of the polar parts in mu (s = sin theta)
        "1": lambda m: m, "mu": lambda m: m * m / 2.0, "s": lambda m: (m * sq(m) +
                                                                       np.arcsin(m)) / 2.0,
        "s2": lambda m: m - m ** 3 / 3.0, "smu": lambda m: -sq(m) ** 3 / 3.0,
        "3mu2-1": lambda m: m ** 3 - m}
    p0, p1 = phi[:-1], phi[1:]
    by_phi = {  # the integrals of the azimuthal parts over each column
        "1": p1 - p0, "sin": np.cos(p0) - np.cos(p1), "-cos": np.sin(p0) - np.sin(p1),
        "-sincos": (np.cos(2 * p1) - np.cos(2 * p0)) / 4.0,
        "-cos2": (np.sin(2 * p0) - np.sin(2 * p1)) / 2.0}
    # the basis of the module comment: (polar, azimuthal, A_l c_lm^2)
    c0, c1 = 1.0 / (4.0 * math.pi), 3.0 / (4.0 * math.pi)
    c2, c20, c22 = 15.0 / (4.0 * math.pi), 5.0 / (16.0 * math.pi), 15.0 / (16.0 * math.pi)
    a0, a1, a2 = math.pi, 2.0 * math.pi / 3.0, math.pi / 4.0
    basis = [("1", "1", a0 * c0), ("mu", "1", a1 * c1), ("s", "-cos", a1 * c1),
             ("s", "sin", a1 * c1), ("s2", "-sincos", a2 * c2), ("smu", "-cos", a2 * c2),
             ("3mu2-1", "1", a2 * c20), ("smu", "sin", a2 * c2), ("s2", "-cos2", a2 * c22)]
    out = np.empty((3, 9))
    for i, (polar, azimuth, scale) in enumerate(basis):
        weights = rows_of(by_mu[polar])[:, None] * by_phi[azimuth][None, :]
        out[:, i] = scale * np.einsum("hw,hwc->c", weights, image)
    return out


def sampled(rows) -> bool:
    """Whether any light of ``rows`` (:func:`light_array`) samples its shadow rays (a
    sphere of radius > 0, a soft sun or an area light (its PARAM > 0), even with one ray a point: each shaded ray, the
    anti-aliasing rays of an edge pixel too, takes its own): then the shaded rays need
    their keys (:func:`ray_keys`)."""
    return bool(len(rows)) and bool(np.any(np.asarray(rows)[:, PARAM] > 0.0))


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
    if kind == DIRECTIONAL and not (light.angle or 0.0) > 0.0:
        return "parallel", np.asarray(light.direction, np.float64)
    if kind == POINT or (kind == SPHERE and not light.radius > 0.0):
        return "point", np.asarray(light.position, np.float64)
    return None  # (a sphere's, soft sun's or area light's rays spread: no bound is made)


# --------------------------------------------------------------------------------------
# the kernels' helpers (inlined into shade.py's kernels)
# --------------------------------------------------------------------------------------


@leaf_njit
def incoming(lights, k, frame, t, dx, dy, dz):
    """Light ``k`` at the hit ``eye + t d``: the unit direction it travels there and its
    irradiance factor (1 for a directional light, 1 / distance^2 from a point light or a
    sphere's centre, an area light's irradiance vector's length: :func:`_area_vector`)."""
    if lights[k, KIND] == DIRECTIONAL:
        return lights[k, 1], lights[k, 2], lights[k, 3], 1.0
    if lights[k, KIND] == ENVIRONMENT:  # (lit by environment_irradiance)
        return 0.0, 0.0, 0.0, 0.0
    if lights[k, KIND] >= QUAD:  # (an area light: its irradiance vector, reversed)
        gx, gy, gz = _area_vector(lights, k, frame[0, 0] + t * dx, frame[0, 1] + t * dy,
                                  frame[0, 2] + t * dz)
        g = math.sqrt(gx * gx + gy * gy + gz * gz)
        if not g > 0.0:
            return 0.0, 0.0, 0.0, 0.0
        return -gx / g, -gy / g, -gz / g, g
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
    directional; an area light's centre) and its irradiance factor (1 for a directional
    light, 1 / distance^2 from a point light or a sphere's centre, 0 at it; an area
    light's: the direction and length of its irradiance vector, :func:`_area_vector`, so
    that the irradiance of a surface of unit normal n is n . direction times the factor)."""
    if lights[k, KIND] == DIRECTIONAL:
        return -lights[k, 1], -lights[k, 2], -lights[k, 3], np.inf, 1.0
    if lights[k, KIND] == ENVIRONMENT:  # (lit by environment_irradiance)
        return 0.0, 0.0, 0.0, np.inf, 0.0
    if lights[k, KIND] >= QUAD:  # (an area light: its irradiance vector)
        gx, gy, gz = _area_vector(lights, k, x, y, z)
        g = math.sqrt(gx * gx + gy * gy + gz * gz)
        lx, ly, lz = lights[k, 1] - x, lights[k, 2] - y, lights[k, 3] - z
        d = math.sqrt(lx * lx + ly * ly + lz * lz)
        if not g > 0.0:
            return 0.0, 0.0, 0.0, d, 0.0
        return gx / g, gy / g, gz / g, d, g
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
    direction x, y, z and the distance to where it meets the light (inf: directional; an
    area light's: to its point of the ray, :func:`_area_point`)."""
    kind = lights[k, KIND]
    if kind == DIRECTIONAL:
        wx, wy, wz = -lights[k, 1], -lights[k, 2], -lights[k, 3]
        m = np.int64(lights[k, SAMPLES])
        if not lights[k, PARAM] > 0.0:
            return wx, wy, wz, np.inf
        ox, oy, oz, _, _ = _cone_ray(wx, wy, wz, math.cos(lights[k, PARAM]), m, s, key)
        return ox, oy, oz, np.inf
    if kind == ENVIRONMENT:
        ox, oy, oz = _environment_ray(lights, k, np.int64(lights[k, SAMPLES]), s, key)
        return ox, oy, oz, np.inf
    if kind >= QUAD:
        qx, qy, qz = _area_point(lights, k, np.int64(lights[k, SAMPLES]), s, key)
        vx, vy, vz = qx - px, qy - py, qz - pz
        dist = math.sqrt(vx * vx + vy * vy + vz * vz)
        if not dist > 0.0:
            return 0.0, 0.0, 1.0, 0.0
        return vx / dist, vy / dist, vz / dist, dist
    vx, vy, vz = lights[k, 1] - px, lights[k, 2] - py, lights[k, 3] - pz
    dist = np.sqrt(vx * vx + vy * vy + vz * vz)
    wx, wy, wz = vx / dist, vy / dist, vz / dist
    m = np.int64(lights[k, SAMPLES])
    if kind != SPHERE or not lights[k, PARAM] > 0.0:
        return wx, wy, wz, dist
    return _sphere_point(wx, wy, wz, dist, lights[k, PARAM], m, s, key)


@llvm_inline_njit
def _sphere_point(wx, wy, wz, dist, radius, m, s, key):
    """Shadow ray ``s`` of ``m`` towards a ball of ``radius`` whose centre lies ``dist``
    along the unit (wx, wy, wz): uniform in the cone the ball subtends, at the R2 point of
    the module comment; its direction and the distance to the ball's near side."""
    sin_max = min(radius / dist, 1.0)  # (inside the ball: every direction)
    cos_max = math.sqrt(max(0.0, 1.0 - sin_max * sin_max))
    ox, oy, oz, c, sn = _cone_ray(wx, wy, wz, cos_max, m, s, key)
    # where the ray meets the ball first (the cone's rim: where it touches it)
    h = radius * radius - dist * dist * sn * sn
    return ox, oy, oz, max(dist * c - math.sqrt(max(h, 0.0)), 0.0)


@leaf_njit
def is_environment(lights, k):
    """Whether light ``k`` is an environment (lit by :func:`environment_irradiance`, its
    shadow rays weighted by :func:`shadow_weight`)."""
    return lights[k, KIND] == ENVIRONMENT


@llvm_inline_njit
def environment_irradiance(lights, k, nx, ny, nz):
    """Environment ``k``'s unshadowed irradiance R, G, B of a surface of unit normal n per
    unit of its colour times intensity (the coefficients at ENV; 0 or more)."""
    er = _sh_irradiance(lights, k, ENV, nx, ny, nz)
    eg = _sh_irradiance(lights, k, ENV + 9, nx, ny, nz)
    eb = _sh_irradiance(lights, k, ENV + 18, nx, ny, nz)
    return max(er, 0.0), max(eg, 0.0), max(eb, 0.0)


@llvm_inline_njit
def _sh_irradiance(lights, k, a, nx, ny, nz):
    """One colour's E(n) of the module comment from its 9 coefficients at column ``a``."""
    return (lights[k, a] + lights[k, a + 1] * ny + lights[k, a + 2] * nz
            + lights[k, a + 3] * nx + lights[k, a + 4] * nx * nz + lights[k, a + 5] * nz * ny
            + lights[k, a + 6] * (3.0 * ny * ny - 1.0) + lights[k, a + 7] * nx * ny
            + lights[k, a + 8] * (nx * nx - nz * nz))


@leaf_njit
def shadow_weight(lights, k, lx, ly, lz, nx, ny, nz):
    """The weight of a shadow ray along the unit (lx, ly, lz) from a point of unit normal n
    in the share of light ``k`` it sees: an environment's its cosine with n (0 below the
    horizon: its rays, drawn by the image's brightness over every direction, are weighted
    as the irradiance weighs them), 1 for the others."""
    if lights[k, KIND] != ENVIRONMENT:
        return 1.0
    return max(lx * nx + ly * ny + lz * nz, 0.0)


@llvm_inline_njit
def _environment_ray(lights, k, m, s, key):
    """Environment ``k``'s shadow ray ``s`` of ``m`` (the R2 point of the module comment):
    a row of its sampling table by the rows' shares, a column by that row's, the point
    uniform in cos theta and phi within the cell; its unit direction."""
    u1, u2 = _r2_point(m, s, key)
    h = np.int64(lights[k, ENV + 27])
    w = np.int64(lights[k, ENV + 28])
    mu0 = ENV + 29
    phi0 = mu0 + h + 1
    marg0 = phi0 + w + 1
    cond0 = marg0 + h + 1
    j, f1 = _cdf_pick(lights, k, marg0, h, u1)
    c, f2 = _cdf_pick(lights, k, cond0 + j * (w + 1), w, u2)
    mu = lights[k, mu0 + j] + f1 * (lights[k, mu0 + j + 1] - lights[k, mu0 + j])
    phi = lights[k, phi0 + c] + f2 * (lights[k, phi0 + c + 1] - lights[k, phi0 + c])
    sn = math.sqrt(max(0.0, 1.0 - mu * mu))
    return sn * math.sin(phi), mu, -sn * math.cos(phi)


@llvm_inline_njit
def _cdf_pick(lights, k, at, n, u):
    """The cell of ``u`` in [0, 1) in the ``n + 1`` cumulative shares from column ``at`` of
    row ``k`` (the last whose share starts at or below it, of a share above 0) and
    where in it u lies, 0..1."""
    lo, hi = 0, n - 1
    while lo < hi:  # (the last cell i with cdf[i] <= u)
        mid = (lo + hi + 1) // 2
        if lights[k, at + mid] <= u:
            lo = mid
        else:
            hi = mid - 1
    while lo > 0 and not lights[k, at + lo + 1] > lights[k, at + lo]:
        lo -= 1  # (an empty cell: the one below)
    a, b = lights[k, at + lo], lights[k, at + lo + 1]
    return lo, min(max((u - a) / (b - a), 0.0), 1.0) if b > a else 0.5


@llvm_inline_njit
def _area_vector(lights, k, x, y, z):
    """Area light ``k``'s irradiance vector at the point (x, y, z), per unit of its colour
    times intensity: the integral of the unit direction towards the light over the solid
    angle it subtends, times its radiance (4 / area: the power of a point light of the
    same intensity, 4 pi, from one side of a Lambertian emitter, pi radiance area); 0 on
    or behind the plane it faces away from. A surface of unit normal n there receives
    n . vector, exactly where the light lies wholly above its horizon (Lambert's formula
    for the quad, the form factors of a differential area to a disk for the disk)."""
    cx, cy, cz = lights[k, 1], lights[k, 2], lights[k, 3]
    wx, wy, wz = x - cx, y - cy, z - cz
    if lights[k, KIND] == QUAD:
        return _quad_vector(wx, wy, wz, lights[k, EDGE_U], lights[k, EDGE_U + 1],
                            lights[k, EDGE_U + 2], lights[k, EDGE_V], lights[k, EDGE_V + 1],
                            lights[k, EDGE_V + 2])
    nx, ny, nz = lights[k, EDGE_U], lights[k, EDGE_U + 1], lights[k, EDGE_U + 2]
    h = wx * nx + wy * ny + wz * nz  # (the height over the disk's plane)
    if not h > 0.0:
        return 0.0, 0.0, 0.0
    radius = lights[k, PARAM]
    rx, ry, rz = wx - h * nx, wy - h * ny, wz - h * nz  # (off the axis)
    r = math.sqrt(rx * rx + ry * ry + rz * rz)
    h2, rr = h * h, radius * radius
    a = h2 + r * r - rr
    # sqrt((h^2 + r^2 + R^2)^2 - 4 r^2 R^2), as a product (no cancellation)
    sq = math.sqrt((h2 + (r - radius) ** 2) * (h2 + (r + radius) ** 2))
    # the normal part: (1 - a / sq) / 2 of pi radiance (sq - a = 4 R^2 h^2 / (sq + a))
    normal = (4.0 * rr * h2 / (sq + a) if a >= 0.0 else sq - a) / sq
    # the radial part: h / (2 r) ((h^2 + r^2 + R^2) / sq - 1) of pi radiance
    radial = 4.0 * rr * h / (sq * (h2 + r * r + rr + sq))
    c = 2.0 / rr  # (pi radiance / 2: radiance 4 / (pi R^2))
    return (-c * (normal * nx + radial * rx), -c * (normal * ny + radial * ry),
            -c * (normal * nz + radial * rz))


@llvm_inline_njit
def _quad_vector(wx, wy, wz, ux, uy, uz, vx, vy, vz):
    """:func:`_area_vector` of the quad of half edges u, v at the offset w from its centre
    (Lambert: the sum over its edges of the angle each subtends times the unit normal of
    the plane through it and the point, halved, times the radiance)."""
    nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx  # (u x v)
    if not wx * nx + wy * ny + wz * nz > 0.0:
        return 0.0, 0.0, 0.0
    # the corners -u-v, +u-v, +u+v, -u+v (counter-clockwise about u x v) less w
    ax, ay, az = -ux - vx - wx, -uy - vy - wy, -uz - vz - wz
    bx, by, bz = ux - vx - wx, uy - vy - wy, uz - vz - wz
    cx, cy, cz = ux + vx - wx, uy + vy - wy, uz + vz - wz
    dx, dy, dz = -ux + vx - wx, -uy + vy - wy, -uz + vz - wz
    e1 = _edge_term(ax, ay, az, bx, by, bz)
    e2 = _edge_term(bx, by, bz, cx, cy, cz)
    e3 = _edge_term(cx, cy, cz, dx, dy, dz)
    e4 = _edge_term(dx, dy, dz, ax, ay, az)
    gx = e1[0] + e2[0] + e3[0] + e4[0]
    gy = e1[1] + e2[1] + e3[1] + e4[1]
    gz = e1[2] + e2[2] + e3[2] + e4[2]
    c = -0.5 / math.sqrt(nx * nx + ny * ny + nz * nz)  # (radiance 4 / (4 |u x v|), halved)
    return c * gx, c * gy, c * gz


@llvm_inline_njit
def _edge_term(ax, ay, az, bx, by, bz):
    """The angle between a and b times the unit normal of a x b (0 for parallel a, b)."""
    cx, cy, cz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    cn = math.sqrt(cx * cx + cy * cy + cz * cz)
    if not cn > 0.0:
        return 0.0, 0.0, 0.0
    angle = math.atan2(cn, ax * bx + ay * by + az * bz) / cn
    return angle * cx, angle * cy, angle * cz


@llvm_inline_njit
def _area_point(lights, k, m, s, key):
    """Area light ``k``'s point for shadow ray ``s`` of ``m`` (the R2 point of the module
    comment, mapped uniformly onto its area: a quad's parameters, a disk's polar
    coordinates (radius sqrt(u1) R))."""
    u1, u2 = _r2_point(m, s, key)
    cx, cy, cz = lights[k, 1], lights[k, 2], lights[k, 3]
    ex, ey, ez = lights[k, EDGE_U], lights[k, EDGE_U + 1], lights[k, EDGE_U + 2]
    if lights[k, KIND] == QUAD:
        a, b = 2.0 * u1 - 1.0, 2.0 * u2 - 1.0
        fx, fy, fz = lights[k, EDGE_V], lights[k, EDGE_V + 1], lights[k, EDGE_V + 2]
        return cx + a * ex + b * fx, cy + a * ey + b * fy, cz + a * ez + b * fz
    rad = lights[k, PARAM] * math.sqrt(u1)
    phi = 2.0 * math.pi * u2
    a, b = rad * math.cos(phi), rad * math.sin(phi)
    # an orthonormal basis of the disk's plane (as in _cone_ray)
    sign = 1.0 if ez >= 0.0 else -1.0
    f = -1.0 / (sign + ez)
    g = ex * ey * f
    return (cx + a * (1.0 + sign * ex * ex * f) + b * g,
            cy + a * (sign * g) + b * (sign + ey * ey * f),
            cz + a * (-sign * ex) + b * (-ey))


@llvm_inline_njit
def _r2_point(m, s, key):
    """Point ``s`` of ``m`` of the shaded ray of ``key`` in the unit square: the R2 point
    of the module comment (the pixel's anti-aliasing sample, then s), turned by the
    pixel's hash."""
    pixel = key // KEY_STRIDE
    i = (key - pixel * KEY_STRIDE) * m + s
    return (0.5 + i * R2_A1 + hash01(pixel, 3)) % 1.0, (0.5 + i * R2_A2 + hash01(pixel, 4)) % 1.0


@llvm_inline_njit
def _cone_ray(wx, wy, wz, cos_max, m, s, key):
    """Shadow ray ``s`` of ``m`` in the cone of directions within ``acos(cos_max)`` of the
    unit (wx, wy, wz), uniform in solid angle, at the R2 point of the module comment: its
    unit direction and the cosine and sine of its angle from the axis."""
    pixel = key // KEY_STRIDE
    i = (key - pixel * KEY_STRIDE) * m + s  # (the pixel's anti-aliasing sample, then s)
    u1 = (0.5 + i * R2_A1 + hash01(pixel, 3)) % 1.0
    u2 = (0.5 + i * R2_A2 + hash01(pixel, 4)) % 1.0
    c = 1.0 - u1 * (1.0 - cos_max)  # uniform in solid angle: cos theta in [cos_max, 1]
    sn = math.sqrt(max(0.0, 1.0 - c * c))
    phi = 2.0 * math.pi * u2
    a, b = sn * math.cos(phi), sn * math.sin(phi)
    # an orthonormal basis (b1, b2, w) (Duff et al. 2017: continuous, no division by 0)
    sign = 1.0 if wz >= 0.0 else -1.0
    f = -1.0 / (sign + wz)
    g = wx * wy * f
    ox = a * (1.0 + sign * wx * wx * f) + b * g + c * wx
    oy = a * (sign * g) + b * (sign + wy * wy * f) + c * wy
    oz = a * (-sign * wx) + b * (-wy) + c * wz
    return ox, oy, oz, c, sn


# the R2 sequence's steps (the plastic number's powers): every sampled ray's (the
# anti-aliasing offsets of picture.sample_offsets, AO directions, sphere-light points)
R2_A1 = 1.0 / 1.32471795724474602596
R2_A2 = 1.0 / (1.32471795724474602596 * 1.32471795724474602596)


@leaf_njit
def hash01(x, k):
    """A float in [0, 1) from the integer ``x`` and stream ``k`` (splitmix64's finaliser)."""
    z = np.uint64(x) * np.uint64(0x9E3779B97F4A7C15) + np.uint64(k) * np.uint64(
        0xD1B54A32D192ED03)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    return np.float64(z >> np.uint64(11)) * (1.0 / 9007199254740992.0)
