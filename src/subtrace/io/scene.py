"""subtrace.io.scene: TOML scene files -> :class:`Scene`, and command-line overrides.

Owns the scene format and its validation; no geometry is loaded here (mesh files are only
checked to exist). Every problem raises :class:`subtrace.errors.SceneError` naming the file,
the line (TOML syntax errors: tomllib's line; other errors: the line of the offending key,
found by scanning the text, else the line of its table, else none) and the key path
(``camera.fov``, ``object[0].mesh``, 0-based array index), then the problem and the fix.
Unknown keys are errors (they are usually typos); the message lists the allowed keys.

Schema (every table and key optional unless marked *required*)::

    output  = "renders/spot.exr"    # EXR to write; relative to this file's folder
    preview = "renders/spot.png"    # 8-bit sRGB PNG preview; relative to this file's folder

    [[object]]                      # *required*, one or more (a single [object] also works)
    mesh     = "spot.obj"           # *required*: OBJ cage or USD stage (.usd, .usda, .usdc,
                                    #   .usdz), relative to this file's folder
    prim     = "/World/Body"        # a USD stage's mesh prim; default: all its meshes
    scheme   = "catmark"            # "catmark" | "catmull-clark" | "loop";
                                    #   default: loop for all-triangle cages, else catmark
    boundary = "edge-only"          # "none" | "edge-only" | "edge-and-corner";
                                    #   default: the OBJ's interpolateboundary tag, else
                                    #   edge-only (OpenSubdiv's loaders)
    color    = [0.8, 0.6, 0.4]      # linear RGB in 0..1; overrides the OBJ's materials' Kd
    specular = [0.2, 0.2, 0.2]      # linear RGB in 0..1; overrides their Ks (default none)
    shininess = 40.0                # >= 0: Blinn-Phong exponent; overrides their Ns
    diffuse_texture = "skin.png"    # image textures (subtrace.textures), relative to this
    specular_texture = "spec.png"   #   file's folder; they replace the OBJ's maps of the
    bump_texture = "height.png"     #   same slot; a diffuse / specular texture is
    bump_scale = 0.01               #   multiplied by color / specular (default white);
    normal_texture = "normal.png"   #   bump_scale: height per unit of the bump map's value
    metallic = 1.0                  # 0..1: reflects as a metal (1) or a dielectric (0);
    roughness = 0.2                 #   0..1: a mirror (0) to a broad gloss; either one
                                    #   turns reflections on (the other default 0)

    [camera]                        # without eye and target: an automatic camera framing
    eye    = [3.0, 2.0, 5.0]        #   all objects (subtrace.camera.auto_camera); an eye
    target = [0.0, 0.5, 0.0]        #   without a target looks at the objects' centre
    up     = [0.0, 1.0, 0.0]        # default [0, 1, 0]; must not be along target - eye
                                    #   (the automatic camera uses it too)
    fov    = 30.0                   # vertical field of view, degrees, in (0, 180); default 30
    width  = 1280                   # pixels, 1..32768; default 1280
    height = 720                    # pixels, 1..32768; default 720

    [render]
    tolerance = 1.0                 # angular tolerance in pixels (> 0); default 1 ...
    # tolerance_deg = 0.05          # ... or in degrees (> 0); not both
    background = [0.0, 0.0, 0.0]    # linear RGB in 0..1, or [top, bottom]: a vertical
                                    #   gradient; default the gradient
                                    #   [[0.42, 0.47, 0.54], [0.09, 0.10, 0.12]]
    shadows = true                  # shadow rays towards every [[light]]; default true
    samples = 4                     # rays per pixel at most (adaptive anti-aliasing: edge
                                    #   pixels only), 1..64; default: one ray per pixel in
                                    #   the API, DEFAULT_SAMPLES on the command line
    reflection_depth = 1            # reflections of reflections, 0..8; default 1
    reflection_samples = 8          # glossy reflection rays per shaded ray, 1..256
    ao = 16                         # ambient occlusion rays per hit pixel, 0..1024 (0:
                                    #   none, the default): the diffuse lighting scaled by
                                    #   the share of cosine-weighted rays that escape
    transparent = false             # .png / .tif pictures: alpha where nothing was hit
                                    #   (default false: opaque over the background)
    headlight = true                # a directional light from the eye; default true
    headlight_intensity = 1.0       # >= 0; default 0.2
    max_memory = "4G"               # memory budget: a number of MiB or a size with a unit
                                    #   (K, M, G, T: powers of 1024); default half of the
                                    #   memory available when the render starts

    [[light]]                       # directional or point lights, any number; without
                                    #   any, a key and a fill light (DEFAULT_LIGHT_RAYS);
                                    #   light = [] for none
    direction = [-1.0, -1.0, -0.5]  # the direction a directional light travels (from the
                                    #   light into the scene), any non-zero length; or
    # position = [2.0, 4.0, 1.0]    #   a point light's position (1 / distance^2 falloff)
    color     = [1.0, 1.0, 1.0]     # linear RGB in 0..1; default white
    intensity = 1.0                 # >= 0; default 1

    [ground]                        # a ground plane facing the camera's up; without the
                                    #   table the default one (its defaults below);
                                    #   ground = false for none
    height = -0.7                   # along up; default: the objects' lowest point
    color = [0.6, 0.6, 0.6]         # an opaque lit ground; without it the ground is a
                                    #   shadow catcher (the background, darkened by shadows)

Paths in a :class:`Scene` are absolute (resolved against the scene file's folder, or
``base_dir``); command-line overrides of paths are relative to the working directory.
"""

from __future__ import annotations

import difflib
import math

import numpy as np
import os
import re
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path

from subtrace.errors import SceneError, show_value
from subtrace.io import placement
from subtrace.io.text import decode, read_bytes
from subtrace.io.obj import (BOUNDARY_EDGE_AND_CORNER, BOUNDARY_EDGE_ONLY, BOUNDARY_NONE,
                            TextureMap)
from subtrace.io.usd import is_usd, usd_scene_table
from subtrace.lights import LIGHT_KEYS, Light, parse_light
from subtrace.camera import (
    Camera,
    auto_camera,
    check_fov,
    check_resolution,
    check_vector,
    check_view,
)

# The picture defaults, the same for a TOML scene, OBJ cages or USD stages on the command
# line and a scene built in code: what a scene leaves out it gets from here, what it sets
# it keeps. 1280x720 through a 30 degree lens, a soft vertical gradient behind, a key and
# a fill light (the directions they travel, for +Y up and the automatic camera's view:
# a scene's [[light]] tables, or a USD stage's distant lights, replace them; light = []
# leaves none) with shadows, a weak headlight, and a shadow-catching ground at the
# objects' lowest point (ground = false leaves it out).
DEFAULT_WIDTH, DEFAULT_HEIGHT = 1280, 720
DEFAULT_FOV_DEG = 30.0
DEFAULT_UP = (0.0, 1.0, 0.0)
DEFAULT_TOLERANCE_PX = 1.0
DEFAULT_BACKGROUND = ((0.42, 0.47, 0.54), (0.09, 0.10, 0.12))  # (top, bottom)
DEFAULT_LIGHT_RAYS = (((0.45, -1.0, -0.5), 0.75), ((-0.8, -1.0, 0.1), 0.25))  # key, fill
# the fill is a small sun (its angular diameter, degrees, and shadow rays per point): a
# hard fill drew its shadow's edge as a jagged seam across the objects it fell on
DEFAULT_FILL_ANGLE, DEFAULT_FILL_SAMPLES = 6.0, 4
DEFAULT_HEADLIGHT_INTENSITY = 0.2
# rays per edge pixel at most where neither the scene nor --samples says: the command
# line's default (subtrace.picture; chosen in BENCHMARKS.md); the API renders one ray per
# pixel unless asked
DEFAULT_SAMPLES = 4
MAX_SAMPLES = 64
MAX_AO_SAMPLES = 1024
# reflections (subtrace.reflect): bounces after the first hit, and a glossy lobe's rays per
# shaded ray (stratified per pixel, continued by its anti-aliasing rays)
DEFAULT_REFLECTION_DEPTH, MAX_REFLECTION_DEPTH = 1, 8
DEFAULT_REFLECTION_SAMPLES, MAX_REFLECTION_SAMPLES = 8, 256

SCHEMES = {"catmark": "catmark", "catmull-clark": "catmark", "loop": "loop"}
BOUNDARIES = {
    "none": BOUNDARY_NONE,
    "edge-only": BOUNDARY_EDGE_ONLY,
    "edge-and-corner": BOUNDARY_EDGE_AND_CORNER,
}

_TOP_KEYS = ("object", "camera", "render", "light", "ground", "output", "preview")
# an object's image texture keys and the slot of each (subtrace.io.obj.TextureMap)
TEXTURE_KEYS = {"diffuse_texture": "diffuse", "specular_texture": "specular",
                "bump_texture": "bump", "normal_texture": "normal"}
_OBJECT_KEYS = ("mesh", "prim", "scheme", "boundary", "color", "specular", "shininess",
                *TEXTURE_KEYS, "bump_scale", "metallic", "roughness", *placement.KEYS)
_CAMERA_KEYS = ("eye", "target", "up", "fov", "width", "height")
_RENDER_KEYS = ("tolerance", "tolerance_deg", "background", "headlight", "headlight_intensity",
                "max_memory", "shadows", "transparent", "samples", "ao", "reflection_depth",
                "reflection_samples")
_LIGHT_KEYS = LIGHT_KEYS  # (the light kinds' keys: subtrace.lights)
_GROUND_KEYS = ("height", "color")
# Every key the parser accepts, by table ("": the top level); docs/guide/scene-format.md
# lists exactly these (tests/test_docs.py)
SCENE_KEYS = {"": _TOP_KEYS, "object": _OBJECT_KEYS, "camera": _CAMERA_KEYS,
              "render": _RENDER_KEYS, "light": _LIGHT_KEYS, "ground": _GROUND_KEYS}
# Camera field -> scene key / command-line option
_CAMERA_FIELD_KEY = {
    "eye": "eye",
    "target": "target",
    "up": "up",
    "fov_deg": "fov",
    "width": "width",
    "height": "height",
}


# --------------------------------------------------------------------------------------
# the scene
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SceneObject:
    """One cage to render: ``mesh`` absolute path; None fields fall back to the cage's own."""

    mesh: str
    scheme: str | None = None  # "catmark" | "loop"; None: by the cage's faces
    boundary: str | None = None  # "none" | "edge-only" | "edge-and-corner"; None: OBJ tag
    color: tuple[float, float, float] | None = None  # linear RGB 0..1; None: OBJ materials
    prim: str | None = None  # a USD stage's mesh prim ("/World/Body"); None: all its meshes
    specular: tuple[float, float, float] | None = None  # Ks; None: OBJ materials
    shininess: float | None = None  # Ns; None: OBJ materials
    # reflection (shade.reflection_of): either given, the other is 0; None: OBJ materials
    metallic: float | None = None
    roughness: float | None = None
    time: float | None = None  # a USD stage's time code; None: its still (io/usd.py)
    # image textures (subtrace.io.obj.TextureMap), replacing the cage's maps of their slots
    textures: tuple = ()
    bump_scale: float | None = None  # the bump maps' scale (a scene's or the MTL's -bm)
    # where it stands: a 4x4 affine matrix as rows (p' = M [p, 1]); None: as the file has it
    transform: tuple | None = None

    @property
    def boundary_code(self) -> int | None:
        """The boundary mode as OpenSubdiv's Sdc code (subtrace.io.obj.BOUNDARY_*), or None."""
        return None if self.boundary is None else BOUNDARIES[self.boundary]


DEFAULT_LIGHTS = tuple(
    Light(tuple(c / math.sqrt(sum(x * x for x in d)) for c in d), intensity=intensity,
          **({} if k == 0 else {"angle": DEFAULT_FILL_ANGLE, "samples": DEFAULT_FILL_SAMPLES}))
    for k, (d, intensity) in enumerate(DEFAULT_LIGHT_RAYS))


@dataclass(frozen=True)
class Ground:
    """The [ground] table: a plane facing the camera's up at ``height`` along it (None: the
    objects' lowest point), opaque in ``color`` or (None) a shadow catcher."""

    height: float | None = None
    color: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class CameraSettings:
    """The [camera] table: eye and target both given (explicit) or both None (automatic)."""

    eye: tuple[float, float, float] | None = None
    target: tuple[float, float, float] | None = None
    up: tuple[float, float, float] = DEFAULT_UP
    fov_deg: float = DEFAULT_FOV_DEG
    width: int = DEFAULT_WIDTH
    height: int = DEFAULT_HEIGHT

    @property
    def is_auto(self) -> bool:
        """True when the camera needs the scene's bounds: no target (an eye alone looks at
        their centre), or neither eye nor target (:func:`auto_camera`)."""
        return self.target is None

    def make_camera(self, bounds_min=None, bounds_max=None, points=None, outside=()) -> Camera:
        """The Camera: explicit, or :func:`auto_camera` framing the bounds (then required)
        and ``points`` of the surface where given, its eye outside the boxes ``outside``."""
        if not self.is_auto:
            return Camera(self.eye, self.target, self.up, self.fov_deg, self.width, self.height)
        if bounds_min is None or bounds_max is None:
            raise ValueError("an automatic camera needs the scene bounds")
        if self.eye is not None:
            centre = 0.5 * (np.asarray(bounds_min, np.float64) + np.asarray(bounds_max))
            target = tuple(float(c) for c in centre)
            try:
                check_view(self.eye, target, self.up)
            except SceneError as err:
                raise SceneError(f"{err.problem} (the target is the objects' centre)",
                                 key="eye") from None
            return Camera(self.eye, target, self.up, self.fov_deg, self.width, self.height)
        return auto_camera(
            bounds_min, bounds_max, self.width, self.height, self.fov_deg, self.up, points,
            outside,
        )


@dataclass(frozen=True)
class RenderSettings:
    """The [render] table. Exactly one of tolerance_px / tolerance_deg is set."""

    tolerance_px: float | None = DEFAULT_TOLERANCE_PX
    tolerance_deg: float | None = None
    background: tuple[float, float, float] = DEFAULT_BACKGROUND[0]  # (a gradient's top)
    # None: a flat background
    background_bottom: tuple[float, float, float] | None = DEFAULT_BACKGROUND[1]
    headlight: bool = True
    headlight_intensity: float = DEFAULT_HEADLIGHT_INTENSITY
    max_memory: int | None = None  # bytes; None: config.default_max_memory() at render time
    shadows: bool = True
    transparent: bool = False
    samples: int | None = None  # None: not given (one ray; the command line: DEFAULT_SAMPLES)
    ao: int = 0  # ambient occlusion rays per hit pixel (0: none)
    reflection_depth: int = DEFAULT_REFLECTION_DEPTH  # bounces of reflected rays at most
    reflection_samples: int = DEFAULT_REFLECTION_SAMPLES  # a glossy lobe's rays per ray

    def tolerance_rad(self, camera: Camera) -> float:
        """The angular tolerance in radians (pixels times the camera's pixel angle)."""
        if self.tolerance_deg is not None:
            return math.radians(self.tolerance_deg)
        return self.tolerance_px * camera.pixel_angle()


@dataclass(frozen=True)
class Scene:
    """A validated scene. ``path``: the scene file (None for a scene built in code)."""

    objects: tuple[SceneObject, ...]
    camera: CameraSettings = CameraSettings()
    render: RenderSettings = RenderSettings()
    lights: tuple[Light, ...] = DEFAULT_LIGHTS
    ground: Ground | None = Ground()  # None: no ground
    output: str | None = None
    preview: str | None = None
    path: str | None = None
    # a scene made from a USD stage: (its path, the camera prim the camera came from or
    # None, whether the lights came from it): read again at each frame's time code
    usd_source: tuple[str, str | None, bool] | None = None

    def make_camera(self, bounds_min=None, bounds_max=None, points=None, outside=()) -> Camera:
        """See :meth:`CameraSettings.make_camera`."""
        return self.camera.make_camera(bounds_min, bounds_max, points, outside)


# --------------------------------------------------------------------------------------
# loading
# --------------------------------------------------------------------------------------


def load_scene(path) -> Scene:
    """Read and validate a TOML scene file (UTF-8). Raises SceneError on any bad input."""
    path = os.fspath(path)
    if isinstance(path, bytes):
        path = os.fsdecode(path)
    text = _read_text(path)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise _syntax_error(path, text, err) from None
    return scene_from_dict(data, path=path, text=text)


def scene_from_dict(d: dict, path=None, base_dir=None, *, text: str | None = None) -> Scene:
    """Validate a parsed scene table (as tomllib gives it) into a :class:`Scene`.

    path: the scene file, named in errors; base_dir: the folder relative paths are resolved
    against (default: the folder of ``path``, else the working directory); text: the file's
    text, used to find the line of an offending key (read from ``path`` when omitted).
    """
    if path is not None:
        path = os.fsdecode(os.fspath(path))
    if base_dir is None:
        base_dir = os.path.dirname(os.path.abspath(path)) if path is not None else os.getcwd()
    base_dir = os.path.abspath(os.fsdecode(os.fspath(base_dir)))
    if text is None and path is not None:
        try:
            text = Path(path).read_text(encoding="utf-8-sig")
        except (OSError, UnicodeDecodeError):
            text = None
    ctx = _Context(path, _KeyLines(text) if text is not None else None)
    if not isinstance(d, dict):
        raise ctx.error((), "a scene must be a TOML table of keys and tables")
    ctx.check_keys((), d, _TOP_KEYS)

    objects = _objects(ctx, d, base_dir)
    camera = _camera(ctx, d.get("camera", {}))
    render = _render(ctx, d.get("render", {}))
    lights = _lights(ctx, d["light"], base_dir) if "light" in d else DEFAULT_LIGHTS
    ground = _ground(ctx, d["ground"]) if "ground" in d else Ground()
    output = _out_path(ctx, d, "output", base_dir)
    preview = _out_path(ctx, d, "preview", base_dir)
    return Scene(
        objects=objects,
        camera=camera,
        render=render,
        lights=lights,
        ground=ground,
        output=output,
        preview=preview,
        path=None if path is None else os.path.abspath(path),
    )


def scene_for_meshes(meshes, scheme: str | None = None, camera: str | None = None,
                     time: float | None = None) -> Scene:
    """The scene of cages named on the command line: the automatic camera and the picture
    defaults (``DEFAULT_*``: the same a TOML scene of these objects alone gets). A USD stage
    brings its meshes, its camera (``camera``: the prim path of one, default its first) and
    its distant lights (:func:`subtrace.io.usd.usd_scene_table`), which replace the default
    ones, all at the time code ``time`` (None: the stage's still,
    :func:`subtrace.io.usd.read_stage`).

    Relative paths are relative to the working directory.
    """
    objects = [{"mesh": os.fsdecode(os.fspath(m))} for m in meshes]
    for obj in objects:
        if os.path.isdir(obj["mesh"]):
            raise SceneError("is a directory, expected an OBJ file", path=obj["mesh"])
        if not os.path.isfile(obj["mesh"]):
            raise SceneError("no such mesh file", path=obj["mesh"])
    table = {"object": objects}
    usd = None
    if any(is_usd(o["mesh"]) for o in objects):
        table = usd_scene_table(objects, camera, time)
        usd = table.pop("usd", None)
    elif camera is not None:
        raise SceneError("--camera names a USD camera prim: give a USD stage",
                         key="--camera")
    if scheme is not None:
        for obj in table["object"]:
            obj["scheme"] = scheme
    try:
        scene = scene_from_dict(table)
    except SceneError as err:
        key = "--scheme" if err.key and err.key.endswith(".scheme") else None
        raise SceneError(err.problem, key=key) from None
    if time is not None:
        scene = replace(scene, objects=tuple(replace(o, time=float(time)) if is_usd(o.mesh)
                                             else o for o in scene.objects))
    if usd is not None:
        scene = replace(scene, usd_source=(os.path.abspath(usd["stage"]), usd["camera"],
                                           usd["lights"]))
    return scene


def _read_text(path: str) -> str:
    """The scene file's text; SceneError naming the file (and the line of a bad byte)."""

    def error(problem, line):
        return SceneError(problem, path=path, line=line)

    data = read_bytes(path, error, expected="a TOML scene file", noun="scene file")
    return decode(data, error, noun="scene file")


_AT_LINE = re.compile(r"\s*\(at line (\d+), column (\d+)\)\s*$")
_AT_END = re.compile(r"\s*\(at end of document\)\s*$")


def _syntax_error(path: str, text: str, err: Exception) -> SceneError:
    message = str(err)
    line = None
    m = _AT_LINE.search(message)
    if m:
        line = int(m.group(1))
        message = f"{message[: m.start()]} (column {m.group(2)})"
    elif _AT_END.search(message):
        line = text.count("\n") + (0 if text.endswith("\n") else 1)
        message = f"{message[: _AT_END.search(message).start()]} (at the end of the file)"
    return SceneError(
        f"TOML syntax error: {message}; see https://toml.io for the syntax", path=path, line=line
    )


# --------------------------------------------------------------------------------------
# tables
# --------------------------------------------------------------------------------------


def _objects(ctx, d: dict, base_dir: str) -> tuple[SceneObject, ...]:
    raw = d.get("object")
    if raw is None:
        raise ctx.error(
            ("object",),
            "the scene has no objects: add an [[object]] table with mesh = \"model.obj\"",
        )
    tables = ctx.array_tables(
        "object", raw, _OBJECT_KEYS, "mesh",
        "mesh = \"file.obj\" (a path relative to the scene file's folder)")
    if not tables:
        raise ctx.error(("object",), "the scene has no objects: add at least one [[object]]")
    objects = []
    for where, table in tables:
        mesh = _mesh_path(ctx, where + ("mesh",), table["mesh"], base_dir)
        scheme = boundary = color = prim = specular = shininess = metallic = roughness = None
        if "prim" in table:
            prim = ctx.call(where + ("prim",), _prim_path, table["prim"], "prim")
        if "specular" in table:
            specular = ctx.color(where + ("specular",), table["specular"])
        if "shininess" in table:
            shininess = ctx.call(where + ("shininess",), _non_negative, table["shininess"])
        if "metallic" in table or "roughness" in table:
            metallic, roughness = (
                ctx.call(where + (key,), _unit_number, table[key], key) if key in table
                else 0.0 for key in ("metallic", "roughness"))
        if "scheme" in table:
            scheme = _choice(ctx, where + ("scheme",), table["scheme"], SCHEMES)
        if "boundary" in table:
            boundary = _choice(ctx, where + ("boundary",), table["boundary"], BOUNDARIES)
        if "color" in table:
            color = ctx.color(where + ("color",), table["color"])
        objects.append(SceneObject(mesh=mesh, scheme=scheme, boundary=boundary, color=color,
                                   prim=prim, specular=specular, shininess=shininess,
                                   metallic=metallic, roughness=roughness,
                                   transform=_placement(ctx, where, table),
                                   textures=_textures(ctx, where, table, base_dir),
                                   bump_scale=(float(table["bump_scale"]) if "bump_scale"
                                               in table else None)))
    return tuple(objects)


def _textures(ctx, where, table, base_dir) -> tuple:
    """The object's image textures (``TEXTURE_KEYS``): a :class:`TextureMap` each, its path
    relative to the scene file's folder (a missing file is the render's warning, not an
    error: the constant colour is used)."""
    scale = 1.0
    if "bump_scale" in table:
        scale = ctx.call(where + ("bump_scale",), _number, table["bump_scale"], "bump_scale")
    out = []
    for key, slot in TEXTURE_KEYS.items():
        if key not in table:
            continue
        value = table[key]
        if not isinstance(value, str) or not value.strip():
            raise ctx.error(where + (key,), f"expected an image file name in quotes, got "
                                            f"{show_value(value)}")
        full = os.path.normpath(os.path.join(base_dir, os.path.expanduser(value)))
        if os.path.isdir(full):
            raise ctx.error(where + (key,), f"{full} is a directory, expected an image file")
        line = ctx.lines.find(tuple(where + (key,))) if ctx.lines is not None else None
        at = f"{ctx.path}:{line}" if line is not None else f"{ctx.path or 'scene'}"
        out.append(TextureMap(slot, full, f"{at}: {_format_key(where + (key,))}",
                              bump_scale=scale if slot == "bump" else 1.0))
    return tuple(out)


def _placement(ctx, where, table):
    """The object's 4x4 matrix of its placement keys (``io.placement``), as rows; None
    without any."""
    given = [k for k in placement.KEYS if k in table]
    if not given:
        return None
    if "matrix" in given and len(given) > 1:
        other = next(k for k in given if k != "matrix")
        raise ctx.error(where + (other,), f"give an object either a matrix or "
                        f"translate / rotate / orient / scale, not both ({other} and matrix)")
    if "rotate" in given and "orient" in given:
        raise ctx.error(where + ("orient",), "give an object either rotate (angles) or "
                        "orient (a quaternion), not both")
    checks = {"translate": placement.check_translate, "rotate": placement.check_rotate,
              "orient": placement.check_orient, "scale": placement.check_scale,
              "matrix": placement.check_matrix}
    parts = {k: ctx.call(where + (k,), checks[k], table[k]) for k in given}
    if "matrix" in parts:
        return placement.as_tuple(parts["matrix"])
    return placement.as_tuple(placement.compose(
        parts.get("translate"), parts.get("rotate", parts.get("orient")), parts.get("scale")))


def _prim_path(value, key):
    """A USD prim path: a string starting with '/'."""
    if not isinstance(value, str) or not value.startswith("/"):
        raise SceneError(f"expected a USD prim path such as \"/World/Body\", got "
                         f"{show_value(value)}")
    return value


def _camera(ctx, table) -> CameraSettings:
    where = ("camera",)
    table = ctx.table(where, table, "[camera]")
    ctx.check_keys(where, table, _CAMERA_KEYS)
    values = {}
    for field, key in _CAMERA_FIELD_KEY.items():
        if key in table:
            values[field] = ctx.call(where + (key,), _CHECKERS[field], table[key], key)
    has_eye, has_target = "eye" in values, "target" in values
    if has_target and not has_eye:
        raise ctx.error(
            where + ("target",),
            "target is given but eye is not: give an eye (alone it looks at the objects' "
            "centre), or neither for an automatic camera that frames all objects",
        )
    settings = CameraSettings(**values)
    if has_eye and has_target:
        try:
            check_view(settings.eye, settings.target, settings.up)
        except SceneError as err:
            key = err.key if err.key in table else "target"
            raise ctx.error(where + (key,), err.problem) from None
    return settings


def _render(ctx, table) -> RenderSettings:
    where = ("render",)
    table = ctx.table(where, table, "[render]")
    ctx.check_keys(where, table, _RENDER_KEYS)
    if "tolerance" in table and "tolerance_deg" in table:
        raise ctx.error(
            where + ("tolerance_deg",),
            "give either tolerance (pixels) or tolerance_deg (degrees), not both",
        )
    values = {}
    if "tolerance_deg" in table:
        values["tolerance_px"] = None
        values["tolerance_deg"] = ctx.call(
            where + ("tolerance_deg",), _positive, table["tolerance_deg"], "degrees"
        )
    if "tolerance" in table:
        values["tolerance_px"] = ctx.call(
            where + ("tolerance",), _positive, table["tolerance"], "pixels"
        )
    if "background" in table:
        values["background"], values["background_bottom"] = ctx.call(
            where + ("background",), _background, table["background"])
    for key in ("headlight", "shadows", "transparent"):
        if key in table:
            value = table[key]
            if not isinstance(value, bool):
                raise ctx.error(where + (key,), f"expected true or false, got {show_value(value)}")
            values[key] = value
    if "headlight_intensity" in table:
        values["headlight_intensity"] = ctx.call(
            where + ("headlight_intensity",), _non_negative, table["headlight_intensity"]
        )
    if "max_memory" in table:
        values["max_memory"] = ctx.call(where + ("max_memory",), parse_memory,
                                        table["max_memory"])
    if "samples" in table:
        values["samples"] = ctx.call(where + ("samples",), _samples, table["samples"])
    if "ao" in table:
        values["ao"] = ctx.call(where + ("ao",), _ao_samples, table["ao"])
    for key, most in (("reflection_depth", MAX_REFLECTION_DEPTH),
                      ("reflection_samples", MAX_REFLECTION_SAMPLES)):
        if key in table:
            values[key] = ctx.call(where + (key,), _whole, table[key], 0 if key ==
                                   "reflection_depth" else 1, most)
    return RenderSettings(**values)


def _lights(ctx, raw, base_dir: str) -> tuple[Light, ...]:
    """The [[light]] tables: each kind's keys and checks are the lights room's
    (:func:`subtrace.lights.parse_light`); errors name the key's line here."""
    lights = []
    for where, table in ctx.array_tables("light", raw, _LIGHT_KEYS, None, ""):
        def value(key, check, *args, where=where):
            return ctx.call(where + (key,), check, *args)

        def error(key, problem, where=where):
            return ctx.error(where if key is None else where + (key,), problem)

        lights.append(parse_light(table, value, error, base_dir))
    return tuple(lights)


def _ground(ctx, table) -> Ground | None:
    """The [ground] table, or ``ground = false`` (no ground) / ``true`` (the default one)."""
    where = ("ground",)
    if isinstance(table, bool):
        return Ground() if table else None
    table = ctx.table(where, table, "[ground]")
    ctx.check_keys(where, table, _GROUND_KEYS)
    values = {}
    if "height" in table:
        values["height"] = ctx.call(where + ("height",), _number, table["height"])
    if "color" in table:
        values["color"] = ctx.color(where + ("color",), table["color"])
    return Ground(**values)


def _mesh_path(ctx, keypath, value, base_dir: str) -> str:
    if not isinstance(value, str) or not value.strip():
        raise ctx.error(keypath, f"expected a file name in quotes, got {show_value(value)}")
    full = os.path.normpath(os.path.join(base_dir, os.path.expanduser(value)))
    if os.path.isdir(full):
        raise ctx.error(keypath, f"{full} is a directory, expected an OBJ file")
    if not os.path.isfile(full):
        raise ctx.error(
            keypath,
            f"mesh file {value!r} does not exist (looked for {full}; relative paths are "
            "resolved against the scene file's folder)",
        )
    return full


def _out_path(ctx, d: dict, key: str, base_dir: str) -> str | None:
    if key not in d:
        return None
    value = d[key]
    if not isinstance(value, str) or not value.strip():
        raise ctx.error((key,), f"expected a file name in quotes, got {show_value(value)}")
    if key == "preview" and not value.lower().endswith(".png"):
        raise ctx.error((key,), f"a preview is an 8-bit sRGB PNG: give a file name ending in "
                                f".png, not {show_value(value)}")
    return os.path.normpath(os.path.join(base_dir, os.path.expanduser(value)))


def _choice(ctx, keypath, value, choices: dict) -> str:
    """The canonical name of a choice: SCHEMES' value, or BOUNDARIES' key."""
    return ctx.call(keypath, _parse_choice, value, choices)


# --------------------------------------------------------------------------------------
# value checks (raise SceneError with the bare problem; _Context adds where)
# --------------------------------------------------------------------------------------


def _number(value, what: str = "") -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        unit = f" of {what}" if what else ""
        raise SceneError(f"expected a number{unit}, got {show_value(value)}")
    value = float(value)
    if not math.isfinite(value):
        raise SceneError(f"expected a finite number, got {value}")
    return value


def _positive(value, what: str = "") -> float:
    value = _number(value, what)
    if not value > 0.0:
        unit = f" {what}" if what else ""
        raise SceneError(f"must be greater than 0{unit}, got {value:g}")
    return value


def _non_negative(value, what: str = "") -> float:
    value = _number(value, what)
    if value < 0.0:
        raise SceneError(f"must be 0 or more, got {value:g}")
    return value


def _color(value) -> tuple[float, float, float]:
    rgb = check_vector(value, "color")
    if not all(0.0 <= c <= 1.0 for c in rgb):
        raise SceneError(
            f"color components must be between 0 and 1 (linear RGB), got {show_value(value)}"
        )
    return rgb


def _samples(value) -> int:
    """Rays per pixel at most: a whole number 1..MAX_SAMPLES."""
    if isinstance(value, str):
        try:
            value = int(value.strip())
        except ValueError:
            pass
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= MAX_SAMPLES:
        raise SceneError(f"expected a whole number of rays per pixel from 1 to {MAX_SAMPLES}, "
                         f"got {show_value(value)}")
    return value


def _unit_number(value, what) -> float:
    """A ``metallic`` or ``roughness``: a number 0..1."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
            0.0 <= value <= 1.0):
        raise SceneError(f"expected the {what}, a number from 0 to 1, got {show_value(value)}")
    return float(value)


def _whole(value, least, most) -> int:
    """A whole number ``least``..``most``."""
    if isinstance(value, bool) or not isinstance(value, int) or not least <= value <= most:
        raise SceneError(f"expected a whole number from {least} to {most}, got "
                         f"{show_value(value)}")
    return value


def _ao_samples(value) -> int:
    """Ambient occlusion rays per hit pixel: a whole number 0..MAX_AO_SAMPLES."""
    if isinstance(value, str):
        try:
            value = int(value.strip())
        except ValueError:
            pass
    if isinstance(value, bool) or not isinstance(value, int) or not (
            0 <= value <= MAX_AO_SAMPLES):
        raise SceneError(f"expected a whole number of ambient occlusion rays per pixel from 0 "
                         f"to {MAX_AO_SAMPLES}, got {show_value(value)}")
    return value


def _background(value):
    """(top, bottom or None) of a background: one colour, or [top, bottom]."""
    if isinstance(value, (list, tuple)) and len(value) == 2 and all(
            isinstance(v, (list, tuple)) for v in value):
        return _color(value[0]), _color(value[1])
    try:
        return _color(value), None
    except SceneError as err:
        raise SceneError(f"{err.problem}; a gradient is [[r, g, b], [r, g, b]] (top, "
                         "bottom)") from None


_CHECKERS = {
    "eye": check_vector,
    "target": check_vector,
    "up": check_vector,
    "fov_deg": check_fov,
    "width": check_resolution,
    "height": check_resolution,
}


# --------------------------------------------------------------------------------------
# error context: file, line of a key path
# --------------------------------------------------------------------------------------


def _format_key(keypath) -> str:
    out = ""
    for part in keypath:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + part
    return out


class _Context:
    def __init__(self, path, lines):
        self.path = path
        self.lines = lines

    def error(self, keypath, problem: str) -> SceneError:
        line = self.lines.find(tuple(keypath)) if self.lines is not None else None
        return SceneError(problem, path=self.path, line=line, key=_format_key(keypath) or None)

    def call(self, keypath, check, value, *args):
        """check(value, ...) with its SceneError re-raised at keypath."""
        try:
            return check(value, *args)
        except SceneError as err:
            raise self.error(keypath, err.problem) from None

    def color(self, keypath, value):
        return self.call(keypath, _color, value)

    def table(self, keypath, value, name: str) -> dict:
        if not isinstance(value, dict):
            raise self.error(keypath, f"expected a table {name}, got {show_value(value)}")
        return value

    def table_list(self, keypath, value, name: str) -> list:
        """An array of tables; a single table counts as a list of one."""
        if isinstance(value, dict):
            return [value]
        if not isinstance(value, list) or not all(isinstance(t, dict) for t in value):
            raise self.error(keypath, f"expected {name} tables, got {show_value(value)}")
        return value

    def array_tables(self, name: str, value, allowed, required: str, hint: str) -> list:
        """``(keypath, table)`` for each table of the array ``[[name]]``: unknown keys are
        refused and each must have ``required`` (``hint`` says what it holds; None: the
        caller checks)."""
        out = []
        for i, table in enumerate(self.table_list((name,), value, f"[[{name}]]")):
            where = (name, i) if isinstance(value, list) else (name,)
            self.check_keys(where, table, allowed)
            if required is not None and required not in table:
                raise self.error(
                    where, f"missing key {required}: every [[{name}]] needs {hint}")
            out.append((where, table))
        return out

    def check_keys(self, keypath, table: dict, allowed) -> None:
        for key in table:
            if key not in allowed:
                hint = difflib.get_close_matches(key, allowed, n=1)
                did = f"did you mean {hint[0]!r}? " if hint else ""
                where = f" in [{_format_key(keypath)}]" if keypath else ""
                raise self.error(
                    tuple(keypath) + (key,),
                    f"unknown key {key!r}{where}; {did}allowed keys: {', '.join(allowed)}",
                )


_SEG = r"""(?:[A-Za-z0-9_-]+|"(?:[^"\\]|\\.)*"|'[^']*')"""
_KEY = rf"{_SEG}(?:\s*\.\s*{_SEG})*"
_ARRAY_HEADER = re.compile(rf"^\s*\[\[\s*({_KEY})\s*\]\]")
_TABLE_HEADER = re.compile(rf"^\s*\[\s*({_KEY})\s*\]")
_KEY_LINE = re.compile(rf"^\s*({_KEY})\s*=")
_SEG_RE = re.compile(_SEG)


class _KeyLines:
    """Best-effort map from key paths to the 1-based line that defines them.

    Scans table headers and ``key =`` lines, skipping the insides of multi-line arrays,
    inline tables and multi-line strings. Array-of-tables entries get their 0-based index
    in the path: ("object", 1, "mesh"). Keys inside inline tables are not recorded; find()
    falls back to the nearest recorded parent.
    """

    def __init__(self, text: str):
        self.lines: dict[tuple, int] = {}
        counts: dict[tuple, int] = {}
        current: tuple = ()
        depth, quote = 0, None
        for number, line in enumerate(text.splitlines(), 1):
            if depth == 0 and quote is None:
                m = _ARRAY_HEADER.match(line)
                if m:
                    raw = _segments(m.group(1))
                    counts[raw] = counts.get(raw, -1) + 1
                    current = _indexed(raw, counts)
                    self.lines.setdefault(current, number)
                    continue
                m = _TABLE_HEADER.match(line)
                if m:
                    current = _indexed(_segments(m.group(1)), counts)
                    self.lines.setdefault(current, number)
                    continue
                m = _KEY_LINE.match(line)
                if not m:
                    continue
                self.lines.setdefault(current + _segments(m.group(1)), number)
                line = line[m.end():]
            depth, quote = _scan_value(line, depth, quote)

    def find(self, keypath: tuple) -> int | None:
        for k in range(len(keypath), 0, -1):
            line = self.lines.get(keypath[:k])
            if line is not None:
                return line
        return None


def _segments(key: str) -> tuple:
    out = []
    for seg in _SEG_RE.findall(key):
        if seg[:1] in "\"'":
            seg = seg[1:-1]
        out.append(seg)
    return tuple(out)


def _indexed(raw: tuple, counts: dict) -> tuple:
    out: list = []
    for k in range(1, len(raw) + 1):
        out.append(raw[k - 1])
        if raw[:k] in counts:
            out.append(counts[raw[:k]])
    return tuple(out)


def _scan_value(text: str, depth: int, quote):
    """Bracket depth and open string quote after scanning ``text`` (a value's characters)."""
    i, n = 0, len(text)
    while i < n:
        if quote is not None:
            if quote in ('"', '"""') and text[i] == "\\":
                i += 2
                continue
            if text.startswith(quote, i):
                i += len(quote)
                quote = None
                continue
            i += 1
            continue
        c = text[i]
        if c == "#":
            break
        if text.startswith('"""', i) or text.startswith("'''", i):
            quote = text[i : i + 3]
            i += 3
            continue
        if c in "\"'":
            quote = c
        elif c in "[{":
            depth += 1
        elif c in "]}":
            depth = max(0, depth - 1)
        i += 1
    if quote in ('"', "'"):  # single-line strings cannot continue past the line
        quote = None
    return depth, quote


# --------------------------------------------------------------------------------------
# command-line overrides
# --------------------------------------------------------------------------------------

_OPTION = {
    "width": "--width",
    "height": "--height",
    "fov": "--fov",
    "eye": "--eye",
    "target": "--target",
    "up": "--up",
    "tolerance": "--tolerance",
    "tolerance_deg": "--tolerance-deg",
    "scheme": "--scheme",
    "boundary": "--boundary",
    "output": "--output",
    "preview": "--preview",
    "max_memory": "--max-memory",
    "color": "--color",
    "background": "--background",
    "samples": "--samples",
    "ao": "--ao",
}


def apply_overrides(
    scene: Scene,
    *,
    width=None,
    height=None,
    fov=None,
    eye=None,
    target=None,
    up=None,
    tolerance=None,
    tolerance_deg=None,
    scheme=None,
    boundary=None,
    output=None,
    preview=None,
    max_memory=None,
    color=None,
    background=None,
    shadows=None,
    transparent=None,
    samples=None,
    ao=None,
) -> Scene:
    """A new Scene with command-line values replacing the file's; None means not given.

    Values may be typed or the option's text ("1,2,3" or "1 2 3" for vectors). Errors are
    SceneError whose key is the option (``--fov``). --tolerance and --tolerance-deg exclude
    each other and each replaces either setting of the file. Relative paths are relative to
    the working directory.
    """
    given = {"width": width, "height": height, "fov": fov, "eye": eye, "target": target}
    given["up"] = up
    cam = scene.camera
    cam_values = {}
    for name, field, parse, check in (
        ("width", "width", _parse_int, check_resolution),
        ("height", "height", _parse_int, check_resolution),
        ("fov", "fov_deg", _parse_float, check_fov),
        ("eye", "eye", _parse_vector, check_vector),
        ("target", "target", _parse_vector, check_vector),
        ("up", "up", _parse_vector, check_vector),
    ):
        if given[name] is not None:
            cam_values[field] = _option(name, check, parse(given[name], name), _OPTION[name])
    if cam_values:
        cam = replace(cam, **cam_values)
        if scene.usd_source is not None and cam_values.keys() - {"width", "height"}:
            # the camera is the command line's now, not the stage's at each frame
            scene = replace(scene, usd_source=(scene.usd_source[0], None,
                                               scene.usd_source[2]))
        if cam.eye is None and cam.target is not None:
            raise SceneError(
                "the scene has no camera eye: give --eye as well (alone it looks at the "
                "objects' centre), or neither, for an automatic camera that frames all "
                "objects", key="--target")
        if not cam.is_auto and {"eye", "target", "up"} & cam_values.keys():
            try:
                check_view(cam.eye, cam.target, cam.up)
            except SceneError as err:
                given = [f for f in ("eye", "target", "up") if f in cam_values]
                key = err.key if err.key in given else given[0]
                raise SceneError(err.problem, key=_OPTION[key]) from None

    render = scene.render
    if tolerance is not None and tolerance_deg is not None:
        raise SceneError(
            "give either --tolerance (pixels) or --tolerance-deg (degrees), not both",
            key="--tolerance-deg",
        )
    if tolerance is not None:
        value = _option("tolerance", _positive, _parse_float(tolerance, "tolerance"), "pixels")
        render = replace(render, tolerance_px=value, tolerance_deg=None)
    if tolerance_deg is not None:
        value = _parse_float(tolerance_deg, "tolerance_deg")
        value = _option("tolerance_deg", _positive, value, "degrees")
        render = replace(render, tolerance_px=None, tolerance_deg=value)
    if max_memory is not None:
        render = replace(render, max_memory=_option("max_memory", parse_memory, max_memory))
    if background is not None:
        colors = _option("background", parse_colors, background, 2)
        render = replace(render, background=colors[0],
                         background_bottom=colors[1] if len(colors) > 1 else None)
    if shadows is not None:
        render = replace(render, shadows=bool(shadows))
    if samples is not None:
        render = replace(render, samples=_option("samples", _samples, samples))
    if ao is not None:
        render = replace(render, ao=_option("ao", _ao_samples, ao))
    if transparent is not None:
        render = replace(render, transparent=bool(transparent))

    objects = scene.objects
    if scheme is not None:
        value = _option("scheme", _parse_choice, scheme, SCHEMES)
        objects = tuple(replace(o, scheme=value) for o in objects)
    if boundary is not None:
        value = _option("boundary", _parse_choice, boundary, BOUNDARIES)
        objects = tuple(replace(o, boundary=value) for o in objects)
    if color is not None:
        value = _option("color", parse_colors, color, 1)[0]
        objects = tuple(replace(o, color=value) for o in objects)

    paths = {}
    for name, value in (("output", output), ("preview", preview)):
        if value is not None:
            paths[name] = _option(name, _parse_path, value)
    return replace(scene, camera=cam, render=render, objects=objects, **paths)


def _option(name: str, check, value, *args):
    """check(value, *args) with its SceneError re-raised naming the option."""
    try:
        return check(value, *args)
    except SceneError as err:
        raise SceneError(err.problem, key=_OPTION[name]) from None


def _parse_float(value, name: str):
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            raise SceneError(f"expected a number, got {value!r}", key=_OPTION[name]) from None
    return value


def _parse_int(value, name: str):
    if isinstance(value, str):
        try:
            return int(value.strip())
        except ValueError:
            raise SceneError(
                f"expected a whole number of pixels, got {value!r}", key=_OPTION[name]
            ) from None
    return value


def _parse_vector(value, name: str):
    if isinstance(value, str):
        parts = [p for p in re.split(r"[,\s]+", value.strip().strip("[]()")) if p]
        try:
            return [float(p) for p in parts]
        except ValueError:
            raise SceneError(
                f"expected 3 numbers like 1,2,3, got {value!r}", key=_OPTION[name]
            ) from None
    return value


_MEMORY_UNITS = {"": 1 << 20, "k": 1 << 10, "m": 1 << 20, "g": 1 << 30, "t": 1 << 40}


def parse_memory(value) -> int:
    """A memory size in bytes from a number of MiB (``500``) or a number with a unit
    (``500M``, ``2G``, ``1.5GiB``, ``2048K``; powers of 1024). Raises SceneError unless it
    is a positive size of at least 1 MiB."""
    hint = "expected a size such as 500M or 2G (a bare number is MiB)"
    if isinstance(value, bool):
        raise SceneError(f"{hint}, got {show_value(value)}")
    if isinstance(value, (int, float)):
        number, unit = float(value), ""
    elif isinstance(value, str):
        m = re.fullmatch(r"\s*([-+]?[0-9.]+(?:e[-+]?[0-9]+)?)\s*([kmgt]?)(?:i?b)?\s*", value,
                         flags=re.IGNORECASE)
        if m is None:
            raise SceneError(f"{hint}, got {value!r}")
        try:
            number = float(m.group(1))
        except ValueError:
            raise SceneError(f"{hint}, got {value!r}") from None
        unit = m.group(2).lower()
    else:
        raise SceneError(f"{hint}, got {show_value(value)}")
    size = number * _MEMORY_UNITS[unit]
    if not (math.isfinite(size) and size >= 1 << 20):
        shown = repr(value) if isinstance(value, str) else show_value(value)
        raise SceneError(f"{hint}, at least 1M, got {shown}")
    if size > 1 << 60:
        raise SceneError(f"{hint}, at most 2^60 bytes, got {value!r}")
    return int(size)


def parse_colors(value, most: int) -> list:
    """Up to ``most`` linear RGB colours from an option's text: numbers in 0..1, three per
    colour (``0.8,0.6,0.4``), or sRGB hex codes (``#cc9966``), separated by commas or
    spaces; two colours are a gradient's top and bottom."""
    if not isinstance(value, str):
        return [_color(v) for v in value][:most]
    tokens = [t for t in re.split(r"[,\s]+", value.strip()) if t]
    hint = ("expected a colour as three numbers 0..1 (0.8,0.6,0.4) or #rrggbb"
            + (", or two (top,bottom)" if most > 1 else ""))
    colors = []
    try:
        if tokens and all(t.startswith("#") for t in tokens):
            for t in tokens:
                if not re.fullmatch(r"#[0-9a-fA-F]{6}", t):
                    raise ValueError(t)
                srgb = [int(t[k:k + 2], 16) / 255.0 for k in (1, 3, 5)]
                colors.append(tuple(c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4
                                    for c in srgb))
        else:
            numbers = [float(t) for t in tokens]
            if len(numbers) % 3:
                raise ValueError(value)
            colors = [_color(numbers[k:k + 3]) for k in range(0, len(numbers), 3)]
    except (ValueError, SceneError):
        raise SceneError(f"{hint}, got {value!r}") from None
    if not 1 <= len(colors) <= most:
        raise SceneError(f"{hint}, got {value!r}")
    return colors


def _parse_choice(value, choices: dict) -> str:
    """The canonical name: the mapping's value when it is a name, else the key."""
    names = ", ".join(repr(c) for c in choices)
    if not isinstance(value, str):
        raise SceneError(f"expected one of {names}, got {show_value(value)}")
    key = value.strip().lower().replace("_", "-")
    if key not in choices:
        raise SceneError(f"unknown value {value!r}: use one of {names}")
    canonical = choices[key]
    return canonical if isinstance(canonical, str) else key


def _parse_path(value) -> str:
    value = os.fsdecode(os.fspath(value))
    if not value.strip():
        raise SceneError("expected a file name, got an empty string")
    return os.path.abspath(os.path.expanduser(value))
