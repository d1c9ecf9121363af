"""USD stages (``.usd``, ``.usda``, ``.usdc``, ``.usdz``) as subtrace cages, camera and lights.

Reads through Pixar's ``usd-core`` (``pip install subtrace[usd]``), imported only when a
stage is opened. What is read, at a time code ``time`` (:func:`read_stage`; None, for a still:
the start of the stage's authored time range, else its earliest time samples, where an
attribute has any, else the default values):

* every ``UsdGeomMesh`` that is visible and of purpose ``default`` or ``render``, its points
  in world space (the prim's local-to-world transform), faces (``faceVertexCounts`` /
  ``faceVertexIndices``; ``orientation = "leftHanded"`` faces are turned to the
  right-handed order OBJ and OpenSubdiv use), and its subdivision attributes:
  ``subdivisionScheme`` (``catmullClark``, ``loop``; ``bilinear`` and ``none`` as flat
  polygons: every edge and vertex infinitely sharp, so each planar face renders as itself),
  ``interpolateBoundary`` (``none``, ``edgeOnly``, ``edgeAndCorner``: USD's default is
  ``edgeAndCorner``, unlike OpenSubdiv's OBJ loaders' ``edgeOnly``),
  ``triangleSubdivisionRule`` (``catmullClark`` or ``smooth``), creases
  (``creaseIndices`` in chains of ``creaseLengths`` vertices, ``creaseSharpnesses`` one per
  chain or one per edge), corners (``cornerIndices`` / ``cornerSharpnesses``) and holes
  (``holeIndices``); a constant ``primvars:displayColor`` as the object's colour;
  the ``UsdPreviewSurface`` of its bound material as the cage's material (before its
  displayColor): its authored ``diffuseColor``, ``specularColor`` (with
  ``useSpecularWorkflow`` 1), ``metallic`` and ``roughness``, and ``UsdUVTexture`` images
  connected to the colours or ``normal`` (:func:`_material`);
  ``primvars:st`` as the cage's UVs (``mesh.cage.FaceVarying``): ``faceVarying`` values
  (with their indices where the primvar is indexed; unindexed, each corner is a value of its
  own, as OpenSubdiv then sees it) interpolated by the mesh's
  ``faceVaryingLinearInterpolation`` (``none``, ``cornersOnly``, ``cornersPlus1``, USD's
  default, ``cornersPlus2``, ``boundaries``, ``all``), ``vertex`` values as the points are
  (the face-varying rules of mode none on the vertices' own topology), ``varying``,
  ``uniform`` and ``constant`` ones linearly;
* ``UsdGeomCamera`` prims (focal length and vertical aperture as the vertical field of
  view, the transform as eye, target and up); :func:`read_stage` returns them by path;
* time: :func:`time_range` gives the frames (time codes) a stage animates, and
  :func:`is_animated` whether its meshes change between them (points, topology, tags,
  visibility or a transform above them), so frames of a still stage share one cage;
* ``UsdLuxDistantLight`` as a directional light (its -Z axis in world space, colour, and
  intensity times 2^exposure relative to the brightest: USD's units are physical, a sun's
  default is 50,000, subtrace's are relative, 1 for a full light; an authored
  ``inputs:angle`` above 0 makes it a soft sun of that angular diameter, ``lights.py``,
  its fallback of 0.53 degrees is not taken: a stage that says nothing gets hard shadows,
  as before); other lights are reported as ignored.

USD's sharpness scale is OpenSubdiv's (10 and above: infinitely sharp), as the OBJ tags'.
Every problem is a :class:`subtrace.errors.SubtraceError` naming the file (and prim).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np

from subtrace.config import SHARPNESS_INFINITE
from subtrace.errors import SubtraceError
from subtrace.io.obj import BOUNDARY_EDGE_AND_CORNER, BOUNDARY_EDGE_ONLY, BOUNDARY_NONE
from subtrace.lights import MAX_SUN_ANGLE

USD_EXTENSIONS = (".usd", ".usda", ".usdc", ".usdz")
BOUNDARY_TOKENS = {"none": BOUNDARY_NONE, "edgeOnly": BOUNDARY_EDGE_ONLY,
                   "edgeAndCorner": BOUNDARY_EDGE_AND_CORNER}
SCHEME_TOKENS = {"catmullClark": "catmark", "loop": "loop", "bilinear": None, "none": None}
# faceVaryingLinearInterpolation: Sdc's FVarLinearInterpolation, in its order
FVAR_TOKENS = {"none": 0, "cornersOnly": 1, "cornersPlus1": 2, "cornersPlus2": 3,
               "boundaries": 4, "all": 5}
FVAR_NONE, FVAR_ALL = 0, 5


def is_usd(path) -> bool:
    """Whether ``path`` names a USD stage (by its extension)."""
    return os.path.splitext(os.fspath(path))[1].lower() in USD_EXTENSIONS


@dataclass
class UsdMesh:
    """One mesh prim, ready for :func:`subtrace.mesh.cage.make_cage`."""

    prim: str
    points: np.ndarray
    face_sizes: np.ndarray
    face_verts: np.ndarray
    scheme: str | None  # "catmark" | "loop"; None: flat polygons (bilinear / none)
    boundary: int
    smooth_triangles: bool
    crease_edges: np.ndarray  # (e, 2) int32
    crease_sharpness: np.ndarray  # (e,) float32
    corner_verts: np.ndarray
    corner_sharpness: np.ndarray
    hole_faces: np.ndarray
    color: tuple[float, float, float] | None = None
    uvs: np.ndarray | None = None  # (T, 2) float64: primvars:st
    face_uvs: np.ndarray | None = None  # (corners,) int32 into uvs
    uv_mode: int | None = None  # FVAR_TOKENS' numbers
    # the bound material's UsdPreviewSurface (subtrace.io.obj.Material, _material), or None;
    # a combined mesh's: (face_material, materials) (_combined_materials)
    material: object = None

    def cage_arrays(self) -> dict:
        """Keyword arguments of ``make_cage`` (flat polygons as every edge and vertex
        infinitely sharp: a planar face's limit surface is the face)."""
        edges, sharp = self.crease_edges, self.crease_sharpness
        corners, corner_sharp = self.corner_verts, self.corner_sharpness
        if self.scheme is None:
            a = self.face_verts
            b = np.concatenate([np.roll(f, -1) for f in np.split(a, np.cumsum(self.face_sizes)[:-1])])
            edges = np.unique(np.sort(np.stack([a, b], axis=1), axis=1), axis=0).astype(np.int32)
            sharp = np.full(len(edges), SHARPNESS_INFINITE, np.float32)
            corners = np.arange(len(self.points), dtype=np.int32)
            corner_sharp = np.full(len(corners), SHARPNESS_INFINITE, np.float32)
        return dict(points=self.points, face_sizes=self.face_sizes, face_verts=self.face_verts,
                    scheme="catmark" if self.scheme is None else self.scheme,
                    boundary=self.boundary, smooth_triangles=self.smooth_triangles,
                    crease_edges=edges, crease_sharpness=sharp, corner_verts=corners,
                    corner_sharpness=corner_sharp, hole_faces=self.hole_faces,
                    uvs=self.uvs, face_uvs=self.face_uvs,
                    uv_mode=FVAR_ALL if self.scheme is None and self.uvs is not None
                    else self.uv_mode, **self._materials())

    def _materials(self) -> dict:
        """``make_cage``'s face_material and materials: the bound material on every face
        (a combined mesh's: each mesh's own, ``face_material`` set by
        :func:`combined_mesh`), none without one."""
        if isinstance(self.material, tuple):  # (combined: (face_material, materials))
            return dict(face_material=self.material[0], materials=self.material[1])
        if self.material is None:
            return {}
        return dict(face_material=np.zeros(len(self.face_sizes), np.int32),
                    materials=(self.material,))


@dataclass
class UsdCamera:
    prim: str
    eye: tuple
    target: tuple
    up: tuple
    fov_deg: float


@dataclass
class UsdStageContent:
    path: str
    meshes: list[UsdMesh] = field(default_factory=list)
    cameras: list[UsdCamera] = field(default_factory=list)
    # (direction, color, intensity, angle: an authored angular diameter in degrees or None)
    lights: list[tuple] = field(default_factory=list)
    ignored: list[str] = field(default_factory=list)  # prims read but not rendered, said why


def _pxr(path):
    try:
        from pxr import Usd, UsdGeom, UsdLux  # noqa: F401
    except ImportError:
        raise SubtraceError(f"{path}: reading USD needs Pixar's usd-core: "
                            "pip install 'subtrace[usd]' (or pip install usd-core)") from None
    import pxr

    return pxr


_OPENED: dict = {}  # the last stage opened: (path, size, mtime) -> its Usd.Stage


def open_stage(path):
    """The ``Usd.Stage`` of ``path``; SubtraceError naming the file when it cannot be read.
    The last stage opened is kept while its file is unchanged: frames read it at each time
    code, and their range and animation are asked of it first."""
    path = os.fsdecode(os.fspath(path))
    pxr = _pxr(path)
    if not os.path.exists(path):
        raise SubtraceError(f"{path}: no such file")
    if os.path.isdir(path):
        raise SubtraceError(f"{path}: is a directory, expected a USD stage")
    st = os.stat(path)
    key = (os.path.abspath(path), st.st_size, st.st_mtime_ns)
    if key in _OPENED:
        return _OPENED[key]
    _check_text(path)
    try:
        stage = pxr.Usd.Stage.Open(path)
    except Exception as exc:  # noqa: BLE001 - USD raises its own Tf errors
        raise SubtraceError(f"{path}: not a readable USD stage: {_describe(exc)}") from None
    if stage is None:
        raise SubtraceError(f"{path}: not a readable USD stage")
    _OPENED.clear()
    _OPENED[key] = stage
    return stage


def _check_text(path) -> None:
    """A text stage (``#usda`` first) must be UTF-8: a bad byte is named by its line, as in
    an OBJ file (USD's own parser reports it in a message that cannot be decoded)."""
    from subtrace.io.text import BadByte, utf8_text

    try:
        with open(path, "rb") as f:
            if f.read(5) != b"#usda":
                return
            data = b"#usda" + f.read()
    except OSError as err:
        raise SubtraceError(f"{path}: cannot read the file: {err.strerror or err}") from None
    try:
        utf8_text(data)
    except BadByte as err:
        raise SubtraceError(f"{path}:{err.line}: {err}; save the stage as UTF-8") from None


def _describe(exc) -> str:
    """One line (at most 300 characters) of a USD error: its text may hold bytes of the file
    that are not UTF-8, and then ``str`` of the exception itself fails."""
    try:
        text = str(exc)
    except Exception:  # noqa: BLE001 - (UnicodeDecodeError inside pxr.Tf)
        text = "USD's error message could not be decoded"
    return " ".join(text.split())[:300] or type(exc).__name__


_CACHE: dict = {}  # the last stage read: (path, size, mtime, time) -> its content


def read_stage(path, time=None) -> UsdStageContent:
    """Meshes, cameras and lights of the stage ``path`` (module comment). The last stage
    read is kept (a scene reads it for its objects, camera and lights, then per object)."""
    path = os.fsdecode(os.fspath(path))
    try:
        st = os.stat(path)
        key = (os.path.abspath(path), st.st_size, st.st_mtime_ns, time)
    except OSError:
        key = None
    if key is not None and key in _CACHE:
        return _CACHE[key]
    try:
        content = _read_stage(path, time)
    except SubtraceError:
        raise
    except Exception as exc:  # noqa: BLE001 - a Tf error from a prim or value USD rejects
        if type(exc).__module__.split(".")[0] != "pxr":
            raise
        raise SubtraceError(f"{path}: not a readable USD stage: {_describe(exc)}") from None
    _CACHE.clear()
    if key is not None:
        _CACHE[key] = content
    return content


def _read_stage(path, time) -> UsdStageContent:
    stage = open_stage(path)
    pxr = _pxr(path)
    Usd, UsdGeom, UsdLux = pxr.Usd, pxr.UsdGeom, pxr.UsdLux
    t = _time_code(stage, Usd, time)
    out = UsdStageContent(path)
    cache = UsdGeom.XformCache(t)
    for prim in stage.Traverse():
        where = f"{path}: {prim.GetPath()}"
        if prim.IsA(UsdGeom.Imageable):
            img = UsdGeom.Imageable(prim)
            if img.ComputeVisibility(t) == UsdGeom.Tokens.invisible:
                continue
            if img.ComputePurpose() not in (UsdGeom.Tokens.default_, UsdGeom.Tokens.render):
                continue
        matrix = np.array(cache.GetLocalToWorldTransform(prim), dtype=np.float64)
        if prim.IsA(UsdGeom.Mesh):
            out.meshes.append(_mesh(UsdGeom.Mesh(prim), matrix, t, where))
        elif prim.IsA(UsdGeom.Camera):
            out.cameras.append(_camera(UsdGeom.Camera(prim), matrix, t, where))
        elif prim.IsA(UsdLux.DistantLight):
            out.lights.append(_distant_light(UsdLux.DistantLight(prim), matrix, t))
        elif prim.HasAPI(UsdLux.LightAPI) or prim.GetTypeName().endswith("Light"):
            out.ignored.append(f"{prim.GetPath()} ({prim.GetTypeName()}: subtrace's lights "
                               "are directional)")
        elif prim.IsA(UsdGeom.Gprim):
            out.ignored.append(f"{prim.GetPath()} ({prim.GetTypeName()}: not a mesh)")
    if not out.meshes:
        raise SubtraceError(f"{path}: no visible UsdGeomMesh prims to render (subtrace renders "
                            "subdivision meshes)")
    top = max((i for _, _, i, _ in out.lights), default=0.0)
    if top > 1.0:
        out.lights = [(d, c, i / top, a) for d, c, i, a in out.lights]
    return out


def _time_code(stage, Usd, time):
    """``time`` as a UsdTimeCode; None: the start of the authored time range, else the
    earliest time (time samples where an attribute has them, else its default value)."""
    if time is not None:
        return Usd.TimeCode(float(time))
    if stage.HasAuthoredTimeCodeRange():
        return Usd.TimeCode(stage.GetStartTimeCode())
    return Usd.TimeCode.EarliestTime()


def _rendered_prims(stage, pxr):
    """The prims that the stage's picture depends on: meshes, cameras, lights, and every
    prim above them (their transforms)."""
    UsdGeom, UsdLux = pxr.UsdGeom, pxr.UsdLux
    seen = {}
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.Mesh) or prim.IsA(UsdGeom.Camera) or prim.HasAPI(UsdLux.LightAPI):
            p = prim
            while p and not p.IsPseudoRoot() and p.GetPath() not in seen:
                seen[p.GetPath()] = p
                p = p.GetParent()
    return list(seen.values())


def time_range(path) -> tuple[int, int] | None:
    """(first, last) frame (whole time codes) of the stage ``path``: its authored
    ``startTimeCode`` / ``endTimeCode``, else the span of the time samples of its meshes,
    cameras, lights and their transforms; None when nothing in it is animated."""
    path = os.fsdecode(os.fspath(path))
    stage = open_stage(path)
    if stage.HasAuthoredTimeCodeRange():
        a, b = stage.GetStartTimeCode(), stage.GetEndTimeCode()
    else:
        times = [t for prim in _rendered_prims(stage, _pxr(path))
                 for attr in prim.GetAttributes() for t in attr.GetTimeSamples()]
        if not times:
            return None
        a, b = min(times), max(times)
    if not (math.isfinite(a) and math.isfinite(b)) or b < a:
        raise SubtraceError(f"{path}: its time range {a:g}..{b:g} is not a range of frames")
    first, last = math.ceil(a), math.floor(b)
    if last < first:
        raise SubtraceError(f"{path}: its time range {a:g}..{b:g} holds no whole frame")
    return int(first), int(last)


def is_animated(path) -> bool:
    """Whether a mesh of the stage ``path`` may change between time codes: an attribute of
    the mesh prim (points, topology, tags, visibility) or a transform above it is
    time-varying."""
    path = os.fsdecode(os.fspath(path))
    stage = open_stage(path)
    pxr = _pxr(path)
    for prim in stage.Traverse():
        if not prim.IsA(pxr.UsdGeom.Mesh):
            continue
        p = prim
        while p and not p.IsPseudoRoot():
            if any(a.ValueMightBeTimeVarying() for a in p.GetAttributes()):
                return True
            p = p.GetParent()
    return False


def combined_mesh(content: UsdStageContent, prim: str | None) -> UsdMesh:
    """The mesh ``prim`` of the stage, or with None its only mesh, or all its meshes as one
    (their points and faces side by side) when they share scheme, boundary and rules."""
    where = content.path
    if prim is not None:
        for m in content.meshes:
            if m.prim == prim:
                return m
        names = ", ".join(m.prim for m in content.meshes[:8])
        raise SubtraceError(f"{where}: no visible mesh prim {prim}; its meshes: {names}")
    ms = content.meshes
    if len(ms) == 1:
        return ms[0]
    if len({(m.scheme, m.boundary, m.smooth_triangles) for m in ms}) > 1:
        raise SubtraceError(f"{where}: its {len(ms)} meshes differ in subdivision scheme or "
                            "rules; name one prim (a scene's object prim = \"/path\")")
    off = np.cumsum([0] + [len(m.points) for m in ms])[:-1]
    foff = np.cumsum([0] + [len(m.face_sizes) for m in ms])[:-1]
    cat = lambda f, shift=None: np.concatenate(  # noqa: E731
        [getattr(m, f) + (0 if shift is None else shift[k]) for k, m in enumerate(ms)])
    uvs = face_uvs = mode = None
    if all(m.uvs is not None for m in ms) and len({m.uv_mode for m in ms}) == 1:
        # (the meshes' UVs side by side where every mesh has them, in one mode)
        uoff = np.cumsum([0] + [len(m.uvs) for m in ms])[:-1]
        uvs, face_uvs, mode = cat("uvs"), cat("face_uvs", uoff), ms[0].uv_mode
    return UsdMesh("", cat("points"), cat("face_sizes"), cat("face_verts", off), ms[0].scheme,
                   ms[0].boundary, ms[0].smooth_triangles, cat("crease_edges", off),
                   cat("crease_sharpness"), cat("corner_verts", off), cat("corner_sharpness"),
                   cat("hole_faces", foff), ms[0].color, uvs, face_uvs, mode,
                   _combined_materials(ms))


def _combined_materials(ms):
    """The bound materials of meshes ``ms`` side by side: ``(face_material (F,) int32,
    materials)`` (-1 on the faces of a mesh without one), or None where none has one."""
    if all(m.material is None for m in ms):
        return None
    materials = tuple(m.material for m in ms if m.material is not None)
    face, k = [], 0
    for m in ms:
        face.append(np.full(len(m.face_sizes), -1 if m.material is None else k, np.int32))
        k += m.material is not None
    return np.concatenate(face), materials


def _get(attr, t, default=None):
    value = attr.Get(t) if attr and attr.HasAuthoredValue() else None
    return default if value is None else value


def _transform_points(points, matrix):
    """Points (n,3) through a USD matrix (row vectors: p' = [p 1] M)."""
    h = np.concatenate([points, np.ones((len(points), 1))], axis=1) @ matrix
    return h[:, :3] / h[:, 3:4]


def _mesh(mesh, matrix, t, where) -> UsdMesh:
    pts = np.asarray(_get(mesh.GetPointsAttr(), t, []), dtype=np.float64).reshape(-1, 3)
    counts = np.asarray(_get(mesh.GetFaceVertexCountsAttr(), t, []), dtype=np.int32)
    idx = np.asarray(_get(mesh.GetFaceVertexIndicesAttr(), t, []), dtype=np.int32)
    if not len(counts):
        raise SubtraceError(f"{where}: the mesh has no faces")
    if counts.min() < 3:
        raise SubtraceError(f"{where}: a face has {int(counts.min())} vertices; a face needs "
                            "at least 3")
    if counts.sum() != len(idx):
        raise SubtraceError(f"{where}: faceVertexCounts add up to {int(counts.sum())} but "
                            f"faceVertexIndices has {len(idx)} entries")
    if len(idx) and (idx.min() < 0 or idx.max() >= len(pts)):
        raise SubtraceError(f"{where}: a face vertex index is outside the {len(pts)} points")
    if not np.all(np.isfinite(pts)):
        raise SubtraceError(f"{where}: a point coordinate is not finite")
    uvs, face_uvs, uv_mode = _st(mesh, t, counts, idx, len(pts), where)
    if _get(mesh.GetOrientationAttr(), t, "rightHanded") == "leftHanded":
        starts = np.r_[0, np.cumsum(counts)[:-1]]
        idx = np.concatenate([idx[s:s + n][::-1] for s, n in zip(starts, counts)])
        if face_uvs is not None:  # (each corner keeps its UV)
            face_uvs = np.concatenate([face_uvs[s:s + n][::-1] for s, n in zip(starts, counts)])
    scheme_token = str(_get(mesh.GetSubdivisionSchemeAttr(), t, "catmullClark"))
    if scheme_token not in SCHEME_TOKENS:
        raise SubtraceError(f"{where}: subdivisionScheme {scheme_token!r}: subtrace renders "
                            "catmullClark, loop, bilinear and none")
    boundary_token = str(_get(mesh.GetInterpolateBoundaryAttr(), t, "edgeAndCorner"))
    if boundary_token not in BOUNDARY_TOKENS:
        raise SubtraceError(f"{where}: interpolateBoundary {boundary_token!r}: expected one of "
                            + ", ".join(BOUNDARY_TOKENS))
    rule = str(_get(mesh.GetTriangleSubdivisionRuleAttr(), t, "catmullClark"))
    edges, sharp = _creases(mesh, t, len(pts), where)
    corners = np.asarray(_get(mesh.GetCornerIndicesAttr(), t, []), dtype=np.int32)
    corner_sharp = np.asarray(_get(mesh.GetCornerSharpnessesAttr(), t, []), dtype=np.float32)
    if len(corners) != len(corner_sharp):
        raise SubtraceError(f"{where}: {len(corners)} cornerIndices but {len(corner_sharp)} "
                            "cornerSharpnesses")
    if len(corners) and (corners.min() < 0 or corners.max() >= len(pts)):
        raise SubtraceError(f"{where}: a corner index is outside the {len(pts)} points")
    holes = np.asarray(_get(mesh.GetHoleIndicesAttr(), t, []), dtype=np.int32)
    if len(holes) and (holes.min() < 0 or holes.max() >= len(counts)):
        raise SubtraceError(f"{where}: a hole index is outside the {len(counts)} faces")
    color = None
    colors = _get(mesh.GetDisplayColorAttr(), t)
    if colors is not None and len(colors) >= 1:
        color = tuple(float(min(max(c, 0.0), 1.0)) for c in colors[0])
    return UsdMesh(str(mesh.GetPath()), _transform_points(pts, matrix), counts, idx,
                   SCHEME_TOKENS[scheme_token], BOUNDARY_TOKENS[boundary_token],
                   rule == "smooth", edges, sharp, corners, corner_sharp, holes, color,
                   uvs, face_uvs, uv_mode, _material(mesh.GetPrim(), t, where))


# UsdPreviewSurface's fallbacks that matter here (its specification's)
SURFACE_DIFFUSE = (0.18, 0.18, 0.18)
# a UsdUVTexture connected to one of these inputs: the texture slot it fills
_SURFACE_TEXTURES = {"diffuseColor": "diffuse", "specularColor": "specular",
                     "normal": "normal"}


def _material(prim, t, where):
    """The :class:`subtrace.io.obj.Material` of the UsdPreviewSurface of the material bound
    to ``prim`` (its full render binding, ``UsdShadeMaterialBindingAPI``), from its authored
    inputs: ``diffuseColor`` (else the surface's fallback, 0.18 grey; white where a texture
    gives it), with ``useSpecularWorkflow`` 1 ``specularColor`` as the Blinn-Phong
    specular colour, ``metallic`` and ``roughness`` (0..1; either authored turns reflections
    on, ``subtrace.reflect``, the other 0: a fallback such as roughness 0.5 turns nothing
    on), and the image of a ``UsdUVTexture`` connected to ``diffuseColor``, ``specularColor``
    or ``normal`` as that slot's texture (``inputs:file`` as the stage resolves it; sampled
    at the mesh's ``primvars:st``). None without such a material."""
    from pxr import UsdShade

    from subtrace.io.obj import DEFAULT_SPECULAR, Material, TextureMap

    bound = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()[0]
    if not bound:
        return None
    shader = bound.ComputeSurfaceSource()[0]
    if not shader or shader.GetIdAttr().Get() != "UsdPreviewSurface":
        return None
    at = f"{where}: material {bound.GetPath()}"
    specular_flow = _input_value(shader, "useSpecularWorkflow", t) == 1
    maps = []
    for name, slot in _SURFACE_TEXTURES.items():
        put = shader.GetInput(name)
        file = _connected_texture(put, t, f"{at}: inputs:{name}") if put else None
        if file is not None and (name != "specularColor" or specular_flow):
            maps.append(TextureMap(slot, file, f"{at}: inputs:{name}"))
    colours = {}
    for name in ("diffuseColor", "specularColor"):
        value = _input_value(shader, name, t)
        if value is None:
            continue
        rgb = [float(x) for x in value]
        if len(rgb) != 3 or not all(math.isfinite(x) for x in rgb):
            raise SubtraceError(f"{at}: inputs:{name} is not a finite colour")
        colours[name] = tuple(min(max(x, 0.0), 1.0) for x in rgb)
    numbers = {}
    for name in ("metallic", "roughness"):
        value = _input_value(shader, name, t)
        if value is None:
            continue
        x = float(value)
        if not 0.0 <= x <= 1.0:
            raise SubtraceError(f"{at}: inputs:{name} is {x:g}; expected a number from 0 "
                                "to 1")
        numbers[name] = x
    textured = {m.slot for m in maps}
    diffuse = colours.get("diffuseColor",
                          (1.0, 1.0, 1.0) if "diffuse" in textured else SURFACE_DIFFUSE)
    specular = colours.get("specularColor", DEFAULT_SPECULAR) if specular_flow else \
        DEFAULT_SPECULAR
    reflect = (numbers.get("metallic", 0.0), numbers.get("roughness", 0.0)) if numbers else \
        (None, None)
    return Material(str(bound.GetPath()), diffuse, specular, maps=tuple(maps),
                    metallic=reflect[0], roughness=reflect[1])


def _input_value(shader, name, t):
    """The authored value of the shader's input ``name`` at ``t``, or None."""
    put = shader.GetInput(name)
    if not put:
        return None
    attr = put.GetAttr()
    return attr.Get(t) if attr.HasAuthoredValue() else None


def _connected_texture(put, t, where):
    """The image file (an absolute path) of the UsdUVTexture whose output the shader input
    ``put`` is connected to, or None where it is not connected to one."""
    from pxr import UsdShade

    if not put.HasConnectedSource():
        return None
    source = put.GetConnectedSources()[0][0].source
    texture = UsdShade.Shader(source.GetPrim())
    if not texture or texture.GetIdAttr().Get() != "UsdUVTexture":
        return None
    file = texture.GetInput("file")
    asset = file.GetAttr().Get(t) if file else None
    if asset is None:
        raise SubtraceError(f"{where}: its UsdUVTexture {texture.GetPath()} has no inputs:file")
    path = asset.resolvedPath or asset.path
    if not path:
        raise SubtraceError(f"{where}: its UsdUVTexture {texture.GetPath()} names no file")
    if not os.path.isabs(path):  # (not found by the resolver: relative to the layer)
        layer = file.GetAttr().GetStage().GetRootLayer().realPath
        path = os.path.join(os.path.dirname(layer), path)
    return path


def _st(mesh, t, counts, idx, n_points, where):
    """(uvs (T,2) float64, face_uvs (corners,) int32, mode) of the mesh's ``primvars:st``
    (module comment), or (None, None, None) without one."""
    from pxr import UsdGeom

    pv = UsdGeom.PrimvarsAPI(mesh.GetPrim()).GetPrimvar("st")
    if not pv or not pv.HasAuthoredValue():
        return None, None, None
    values = np.asarray(pv.Get(t), dtype=np.float64)
    if values.ndim != 2 or values.shape[1] != 2:
        raise SubtraceError(f"{where}: primvars:st must hold 2-D texture coordinates, got "
                            f"values of shape {values.shape}")
    if not np.all(np.isfinite(values)):
        raise SubtraceError(f"{where}: primvars:st has a value that is not finite")
    interp = str(pv.GetInterpolation())
    corners = len(idx)
    element = {  # the element each corner takes its value from, and how many there are
        "faceVarying": (np.arange(corners), corners),
        "vertex": (idx, n_points), "varying": (idx, n_points),
        "uniform": (np.repeat(np.arange(len(counts)), counts), len(counts)),
        "constant": (np.zeros(corners, np.int64), 1),
    }
    if interp not in element:
        raise SubtraceError(f"{where}: primvars:st has interpolation {interp!r}; expected "
                            "faceVarying, vertex, varying, uniform or constant")
    of, n_elements = element[interp]
    indices = pv.GetIndices(t) if pv.IsIndexed() else None
    if indices is not None:
        indices = np.asarray(indices, dtype=np.int64)
        what = f"{len(indices)} indices"
        if len(indices) and (indices.min() < 0 or indices.max() >= len(values)):
            raise SubtraceError(f"{where}: primvars:st has an index outside its "
                                f"{len(values)} values")
    else:
        indices, what = np.arange(len(values)), f"{len(values)} values"
    if len(indices) != n_elements:
        raise SubtraceError(f"{where}: primvars:st ({interp}) has {what} for "
                            f"{n_elements} {_ELEMENTS[interp]}")
    if interp == "faceVarying":
        token = str(_get(mesh.GetFaceVaryingLinearInterpolationAttr(), t, "cornersPlus1"))
        if token not in FVAR_TOKENS:
            raise SubtraceError(f"{where}: faceVaryingLinearInterpolation {token!r}: "
                                "expected one of " + ", ".join(FVAR_TOKENS))
        mode = FVAR_TOKENS[token]
    else:
        mode = FVAR_NONE if interp == "vertex" else FVAR_ALL
    return values, indices[of].astype(np.int32), mode


_ELEMENTS = {"faceVarying": "face corners", "vertex": "points", "varying": "points",
             "uniform": "faces", "constant": "value (constant)"}


def _creases(mesh, t, n_points, where):
    """Crease chains as edges (e,2) and a sharpness per edge: ``creaseSharpnesses`` holds one
    value per chain, or one per edge of the chains."""
    idx = np.asarray(_get(mesh.GetCreaseIndicesAttr(), t, []), dtype=np.int32)
    lengths = np.asarray(_get(mesh.GetCreaseLengthsAttr(), t, []), dtype=np.int64)
    sharp = np.asarray(_get(mesh.GetCreaseSharpnessesAttr(), t, []), dtype=np.float32)
    if not len(idx) and not len(lengths):
        return np.zeros((0, 2), np.int32), np.zeros(0, np.float32)
    if np.any(lengths < 2) or lengths.sum() != len(idx):
        raise SubtraceError(f"{where}: creaseLengths (each at least 2) must add up to the "
                            f"{len(idx)} creaseIndices")
    if idx.min() < 0 or idx.max() >= n_points:
        raise SubtraceError(f"{where}: a crease index is outside the {n_points} points")
    starts = np.r_[0, np.cumsum(lengths)[:-1]]
    edges = np.concatenate([np.stack([idx[s:s + n - 1], idx[s + 1:s + n]], axis=1)
                            for s, n in zip(starts, lengths)])
    if len(sharp) == len(lengths):
        per_edge = np.repeat(sharp, lengths - 1)
    elif len(sharp) == len(edges):
        per_edge = sharp
    else:
        raise SubtraceError(f"{where}: {len(sharp)} creaseSharpnesses for {len(lengths)} "
                            f"creases of {len(edges)} edges: give one per crease or one per "
                            "edge")
    return edges.astype(np.int32), per_edge.astype(np.float32)


def _camera(cam, matrix, t, where) -> UsdCamera:
    focal = float(_get(cam.GetFocalLengthAttr(), t, 50.0))
    aperture = float(_get(cam.GetVerticalApertureAttr(), t, 15.2908))
    if not (focal > 0 and aperture > 0):
        raise SubtraceError(f"{where}: focalLength and verticalAperture must be > 0")
    fov = math.degrees(2.0 * math.atan(0.5 * aperture / focal))
    eye = _transform_points(np.zeros((1, 3)), matrix)[0]
    ahead = _transform_points(np.array([[0.0, 0.0, -1.0]]), matrix)[0]
    up = np.array([0.0, 1.0, 0.0, 0.0]) @ matrix
    return UsdCamera(str(cam.GetPath()), tuple(float(x) for x in eye),
                     tuple(float(x) for x in ahead), tuple(float(x) for x in up[:3]), fov)


def _distant_light(light, matrix, t):
    direction = (np.array([0.0, 0.0, -1.0, 0.0]) @ matrix)[:3]
    intensity = float(_get(light.GetIntensityAttr(), t, 1.0))
    exposure = float(_get(light.GetExposureAttr(), t, 0.0))
    color = tuple(float(c) for c in _get(light.GetColorAttr(), t, (1.0, 1.0, 1.0)))
    attr = light.GetAngleAttr()
    angle = float(_get(attr, t, 0.0)) if attr and attr.HasAuthoredValue() else None
    return (tuple(direction / np.linalg.norm(direction)), color, intensity * 2.0 ** exposure,
            angle if angle is not None and angle > 0.0 else None)


def light_table(light) -> dict:
    """A ``[[light]]`` table of a stage's light ``(direction, color, intensity, angle)``."""
    d, col, i, angle = light
    table = {"direction": [float(x) for x in d],
             "color": [min(max(float(x), 0.0), 1.0) for x in col], "intensity": float(i)}
    if angle is not None:
        table["angle"] = min(float(angle), MAX_SUN_ANGLE)
    return table


__all__ = ["read_stage", "open_stage", "is_usd", "time_range", "is_animated", "combined_mesh", "UsdMesh", "UsdCamera", "UsdStageContent",
           "USD_EXTENSIONS"]


def usd_scene_table(objects: list[dict], camera: str | None, time=None) -> dict:
    """A scene table (as a TOML scene parses) for ``objects`` (``{"mesh": path}`` each)
    where the USD stages are replaced by one object per mesh prim (its displayColor as the
    object's colour) and the first stage's camera (``camera``: a prim path; default its
    first camera, if it has one) and distant lights are the scene's, all read at ``time``
    (:func:`read_stage`). The table's ``"usd"`` entry (taken out before the table is
    parsed) names the stage, the camera prim and whether the lights came from it."""
    out: list[dict] = []
    table: dict = {"object": out}
    first = True
    for obj in objects:
        if not is_usd(obj["mesh"]):
            out.append(obj)
            continue
        content = read_stage(obj["mesh"], time)
        for m in content.meshes:
            item = {"mesh": obj["mesh"], "prim": m.prim}
            if m.color is not None and m.material is None:  # (a bound material's first)
                item["color"] = list(m.color)
            out.append(item)
        if first:
            first = False
            cams = content.cameras
            if camera is not None:
                cams = [c for c in cams if c.prim == camera]
                if not cams:
                    names = ", ".join(c.prim for c in content.cameras) or "none"
                    raise SubtraceError(f"{content.path}: no camera prim {camera} (its "
                                        f"cameras: {names})")
            table["usd"] = {"stage": obj["mesh"], "camera": cams[0].prim if cams else None,
                            "lights": bool(content.lights)}
            if cams:
                c = cams[0]
                table["camera"] = {"eye": [float(x) for x in c.eye],
                                   "target": [float(x) for x in c.target],
                                   "up": [float(x) for x in c.up], "fov": float(c.fov_deg)}
            if content.lights:
                table["light"] = [light_table(light) for light in content.lights]
    return table
