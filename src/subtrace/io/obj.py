"""Wavefront OBJ cages with OpenSubdiv `t` tags -> ObjData.

Owns the text format only; topology checks beyond index ranges live in mesh/, the range
checks a render applies (coordinates, valences) in :mod:`subtrace.io.limits`. Layout of
ObjData, every array C-contiguous:
  points (V,3) f8 from `v`; uvs (T,2) f8 from `vt`; normals (N,3) f8 from `vn`.
  Faces as written, never triangulated: face_sizes (F,) i4 and face_verts (sum,) i4,
  0-based, in file order and winding. face_uvs / face_normals (sum,) i4 are aligned with
  face_verts and hold -1 where a corner names no vt / vn.
  face_material / face_group / face_object (F,) i4 index the name tuples (-1: no material).
  Tags: crease_edges (k,2) i4 + crease_sharpness (k,) f4, corner_verts (c,) i4 +
  corner_sharpness (c,) f4, hole_faces (h,) i4, all 0-based; sharpness >= 10 is infinite;
  fvar_interpolation, the face-varying (UV) mode of `t facevaryinginterpolateboundary`.
Tags follow OpenSubdiv's regression reader (regression/common/shape_utils.cpp parses
`t name nI/nF/nS ints floats strings`, far_utils.h interprets it); see ObjReader._tag.
Speed: a jitted byte scanner (:mod:`subtrace.io.obj_scan`) reads the v / vt / vn / f lines
and lists the other statements for Python; anything it cannot read exactly as the statement
reader does (continuation lines, malformed or out-of-range values) sends the file to the
statement reader (ObjReader.read), which is also the tests' oracle. Files with free-form
geometry (:mod:`subtrace.io.freeform`: ``surf``, ``curv2``, ``vp`` ...) are read by the
statement reader too: it keeps the weights of ``v x y z w`` lines for rational surfaces. That reader splits
statements in one Python pass keeping number tokens as strings; numpy converts each block in
bulk, and only a failed conversion walks the rows again to name the first bad line.
"""

from __future__ import annotations

import bisect
import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from subtrace.errors import ObjError, SubtraceWarning
from subtrace.io.freeform import STATEMENTS as FREEFORM_STATEMENTS
from subtrace.io.freeform import FreeFormReader, FreeFormRecords
from subtrace.io.obj_scan import MAX_INDEX, scan
from subtrace.io.text import check_text, decode, read_bytes

DEFAULT_NAME = "default"  # group / object of faces before any `g` / `o`
DEFAULT_DIFFUSE = (0.8, 0.8, 0.8)  # Kd of a material with no (readable) definition
DEFAULT_SPECULAR = (0.0, 0.0, 0.0)  # Ks of a material that gives none (MTL's default)
DEFAULT_SHININESS = 32.0  # Ns of a material that gives Ks but no Ns

BOUNDARY_NONE = 0  # Sdc VTX_BOUNDARY_NONE
BOUNDARY_EDGE_AND_CORNER = 1  # Sdc VTX_BOUNDARY_EDGE_AND_CORNER
BOUNDARY_EDGE_ONLY = 2  # Sdc VTX_BOUNDARY_EDGE_ONLY (OpenSubdiv's default)

_CREASE_METHODS = {"normal": "uniform", "chaikin": "chaikin"}
_SMOOTH_TRIANGLES = ("catmark", "smooth")
_TAGS = frozenset(
    ("crease", "corner", "hole", "interpolateboundary", "creasemethod", "smoothtriangles",
     "facevaryinginterpolateboundary")
)
# `t facevaryinginterpolateboundary 1/0/0 k`: Sdc's FVarLinearInterpolation k, as
# OpenSubdiv's regression/common/far_utils.h maps it (not RenderMan's numbering)
FVAR_MODES = ("none", "corners only", "corners plus1", "corners plus2", "boundaries", "all")
# Free-form statements: those read and ignored are warned about as such (the rest are
# read by subtrace.io.freeform).
_FREEFORM = frozenset(
    "cstype deg bmat step curv curv2 surf parm trim hole scrv sp end con vp".split()
)


@dataclass(frozen=True)
class TextureMap:
    """An image texture of a material (``subtrace.textures`` applies it): the ``slot`` it
    fills (``diffuse``: MTL's `map_Kd`, ``specular``: `map_Ks`, ``bump``: `map_Bump` /
    `bump`, a height map, ``normal``: `norm`, a tangent-space normal map), the image's
    absolute ``path``, and ``where`` it was given ("file:line", for messages)."""

    slot: str
    path: str
    where: str
    bump_scale: float = 1.0  # -bm: a bump map's height per unit of its value, scene units
    offset: tuple[float, float] = (0.0, 0.0)  # -o u v: added to the texture coordinates
    scale: tuple[float, float] = (1.0, 1.0)  # -s u v: multiplies them (before -o)
    clamp: bool = False  # -clamp on: coordinates clamped to [0, 1] (default: repeated)
    channel: int = 0  # -imfchan r|g|b|m|l: a bump map's channel (m, l: the first)


@dataclass(frozen=True)
class Material:
    """A material named by `usemtl`: its name, `Kd` diffuse and `Ks` specular colours
    (linear RGB, 0..1) and `Ns` specular exponent (MTL's Blinn-Phong lobe), its image
    textures (``maps``: :class:`TextureMap`, at most one per slot, MTL's last), and how it
    reflects (``shade.reflection_of``): ``metallic`` and ``roughness`` 0..1 from the PBR
    statements `Pm` / `Pr` (either given: both, the other 0), or ``metallic`` None and
    ``roughness`` from `Ns` for `illum` 3..7 (ray-traced reflection of colour `Ks`); both
    None: no reflection."""

    name: str
    diffuse: tuple[float, float, float]
    specular: tuple[float, float, float] = DEFAULT_SPECULAR
    shininess: float = DEFAULT_SHININESS
    maps: tuple = ()
    metallic: float | None = None
    roughness: float | None = None


@dataclass(frozen=True, eq=False)
class ObjData:
    """Everything read from one OBJ file (see the module comment for the array layout)."""

    path: str
    points: np.ndarray  # (V,3) float64
    face_sizes: np.ndarray  # (F,) int32
    face_verts: np.ndarray  # (sum,) int32, 0-based
    uvs: np.ndarray  # (T,2) float64
    face_uvs: np.ndarray  # (sum,) int32, -1 where absent
    normals: np.ndarray  # (N,3) float64
    face_normals: np.ndarray  # (sum,) int32, -1 where absent
    face_material: np.ndarray  # (F,) int32 into materials, -1 where none
    materials: tuple[Material, ...]
    face_group: np.ndarray  # (F,) int32 into groups
    groups: tuple[str, ...]
    face_object: np.ndarray  # (F,) int32 into objects
    objects: tuple[str, ...]
    crease_edges: np.ndarray  # (k,2) int32 vertex pairs
    crease_sharpness: np.ndarray  # (k,) float32
    corner_verts: np.ndarray  # (c,) int32
    corner_sharpness: np.ndarray  # (c,) float32
    hole_faces: np.ndarray  # (h,) int32
    boundary: int | None  # BOUNDARY_*; None without an interpolateboundary tag
    crease_method: str | None  # "uniform" | "chaikin"; None without a creasemethod tag
    smooth_triangles: str | None  # "catmark" | "smooth"; None without a smoothtriangles tag
    warnings: tuple[str, ...]  # each "path:line: message"
    # 0..5 (FVAR_MODES); None without a facevaryinginterpolateboundary tag
    fvar_interpolation: int | None = None
    # the free-form elements as read (subtrace.io.freeform), which subtrace.nurbs makes into
    # trimmed NURBS surfaces (subtrace.nurbs.freeform.freeform_of)
    freeform: FreeFormRecords | None = None


def read_obj(path) -> ObjData:
    """Read an OBJ file (UTF-8) with its MTL libraries and OpenSubdiv tags.

    Raises ObjError naming the file, the 1-based line and the problem for anything malformed.
    Ignored statements and missing MTL files become warnings: returned in `warnings` and
    emitted as SubtraceWarning.
    """
    path = os.fspath(path)
    if isinstance(path, bytes):
        path = os.fsdecode(path)
    raw = read_obj_bytes(path)
    foreign = foreign_format(path, raw)
    if foreign is not None:
        ext = os.path.splitext(path)[1].lower()
        if foreign in READ_ELSEWHERE and FOREIGN_EXTENSIONS.get(ext) != foreign:
            raise ObjError(path, None, f"a {foreign} file, not OBJ: give it the "
                                       f"{READ_ELSEWHERE[foreign]} extension to read it as "
                                       f"{foreign}")
        raise ObjError(path, None, f"{foreign} files are not read: subtrace reads {READABLE}")
    check_text(raw, _error(path))  # (a PNG or a gzip named .obj, say)
    # ASCII is valid UTF-8 without a byte-order mark: only other files need checking first
    text = None if raw.isascii() else decode_obj(path, raw)
    source = [raw]
    del raw  # (the fast reader lets the bytes go once it has what it needs of them)
    data = ObjReader(path).read_fast(source)
    if data is None:  # (the bytes again when the fast reader had let them go)
        raw = source[0] if source else read_obj_bytes(path)
        data = ObjReader(path).read(decode_obj(path, raw) if text is None else text)
    for message in data.warnings:
        warnings.warn(message, SubtraceWarning, stacklevel=2)
    return data


# mesh and scene formats subtrace does not read, by extension, and the magic bytes of those
# whose files are also met under other names
FOREIGN_EXTENSIONS = {
    ".ply": "PLY", ".stl": "STL", ".off": "OFF", ".gltf": "glTF", ".glb": "glTF (binary)",
    ".fbx": "FBX", ".abc": "Alembic", ".usd": "USD", ".usda": "USD", ".usdc": "USD",
    ".usdz": "USD", ".dae": "COLLADA", ".3ds": "3DS", ".blend": "Blender", ".x3d": "X3D",
    ".wrl": "VRML", ".vtk": "VTK", ".xyz": "point cloud (XYZ)", ".pts": "point cloud (PTS)",
    ".las": "point cloud (LAS)", ".e57": "point cloud (E57)", ".step": "STEP",
    ".stp": "STEP", ".iges": "IGES", ".igs": "IGES", ".3dm": "Rhino",
}
FOREIGN_MAGIC = (
    (b"ply\n", "PLY"), (b"ply\r\n", "PLY"), (b"glTF", "glTF (binary)"), (b"OFF\n", "OFF"),
    (b"solid ", "STL"), (b"PXR-USDC", "USD"), (b"#usda", "USD"), (b"BLENDER", "Blender"),
    (b"Ogawa", "Alembic"), (b"ISO-10303-21", "STEP"),
)


# formats read by other modules (io/meshes.py, io/usd.py), by extension
READ_ELSEWHERE = {"PLY": ".ply", "STL": ".stl", "STL (binary)": ".stl", "OFF": ".off",
                  "glTF": ".gltf", "glTF (binary)": ".glb", "USD": ".usda"}
READABLE = ("Wavefront OBJ cages (.obj, with OpenSubdiv tags and free-form surfaces), USD "
            "stages (.usd, .usda, .usdc, .usdz) and PLY, STL, OFF and glTF meshes")


def foreign_format(path: str, raw: bytes) -> str | None:
    """The name of the other format ``path`` is in (by its extension, or by its first bytes
    whatever its name), or None for a file to read as OBJ."""
    name = FOREIGN_EXTENSIONS.get(os.path.splitext(path)[1].lower())
    if name is not None:
        return name
    for magic, name in FOREIGN_MAGIC:
        if raw.startswith(magic):
            return name
    if raw[:80].count(b"\0") and raw[80:84] and len(raw) == 84 + 50 * int.from_bytes(
            raw[80:84], "little"):
        return "STL (binary)"
    return None


def _error(path: str):
    """The ``error(problem, line)`` of :mod:`subtrace.io.text` for the OBJ file ``path``."""
    return lambda problem, line: ObjError(path, line, problem)


def read_obj_bytes(path: str) -> bytes:
    """The bytes of the OBJ file ``path``; ObjError naming it when it cannot be read."""
    return read_bytes(path, _error(path), expected="an OBJ file")


def decode_obj(path: str, data: bytes) -> str:
    """UTF-8 text without a byte-order mark; a bad byte is an ObjError naming its line."""
    return decode(data, _error(path))


def _logical_lines(text: str):
    """Statements with `\\` continuations joined, and the first physical line of each."""
    if "\r" in text:
        text = text.replace("\r\n", "\n").replace("\r", "\n")
    lines = text.split("\n")
    if "\\" not in text:
        return lines, range(1, len(lines) + 1)
    joined, numbers = [], []
    pending, start = None, 0
    for number, line in enumerate(lines, 1):
        if pending is None:
            start = number
        stripped = line.rstrip()
        # A comment line never continues; any other line ending in `\` does.
        if stripped.endswith("\\") and not (pending is None and stripped.lstrip()[:1] == "#"):
            piece = stripped[:-1]
            pending = piece if pending is None else f"{pending} {piece}"
            continue
        joined.append(line if pending is None else f"{pending} {line}")
        numbers.append(start)
        pending = None
    if pending is not None:
        joined.append(pending)
        numbers.append(start)
    return joined, numbers


def _runs_to_array(runs: list, num_faces: int, ids: dict) -> np.ndarray:
    """Per-face int32 ids from (first face, key) runs; keys get ids in order of first use."""
    out = np.empty(num_faces, dtype=np.int32)
    for k, (first, key) in enumerate(runs):
        last = runs[k + 1][0] if k + 1 < len(runs) else num_faces
        if last > first:
            out[first:last] = -1 if key is None else ids.setdefault(key, len(ids))
    return out


# numbers converted per pass of :func:`slow_numbers` (its byte matrix and index stay small),
# and the longest converted so (longer ones, rare, one by one)
_SLOW_CHUNK = 1 << 15
_SLOW_WIDTH = 64


def slow_numbers(data: bytes, spans: np.ndarray):
    """(n,) float64: the decimal numbers ``data[a:b]`` for the rows (a, b, ...) of ``spans``
    (n, >=2), each rounded correctly (NumPy converts byte strings as Python's float() does,
    tests/test_obj.py), or None where one is not a number. In chunks, without a Python
    object per number: a file of a million such numbers (repr()-written coordinates)
    converts in a fraction of a second and a few MB, where a list of them took 0.2 GB."""
    buf = np.frombuffer(data, dtype=np.uint8)
    out = np.empty(len(spans))
    try:
        # (chunk by chunk: no temporary as long as the numbers, only their values)
        for s in range(0, len(spans), _SLOW_CHUNK):
            a, b = spans[s:s + _SLOW_CHUNK, 0], spans[s:s + _SLOW_CHUNK, 1]
            long = b - a > _SLOW_WIDTH
            for k in np.nonzero(long)[0].tolist():
                out[s + k] = float(data[a[k]:b[k]])
            rows = np.nonzero(~long)[0]
            if not len(rows):
                continue
            a, b = a[rows], b[rows]
            width = int((b - a).max())
            cols = np.arange(width)
            chars = buf[np.minimum(a[:, None] + cols, len(buf) - 1)]
            chars[cols >= (b - a)[:, None]] = 0  # (a byte string ends at its first NUL)
            out[s + rows] = chars.view(f"S{width}").ravel().astype(np.float64)
    except ValueError:
        return None
    return out


class ObjReader:
    """One pass over the statements, then bulk conversion and validation (:meth:`read`), or
    the byte scanner's result completed (:meth:`read_fast`). One reader per file read."""

    def __init__(self, path: str):
        self.path = path
        self.folder = Path(path).parent
        self.warnings: list[tuple[int, str]] = []  # (OBJ line for ordering, message)
        # Number tokens, kept as strings until the bulk conversion, and their lines.
        self.point_tokens: list[str] = []
        self.point_lines: list[int] = []
        self.uv_tokens: list[str] = []
        self.uv_lines: list[int] = []
        self.normal_tokens: list[str] = []
        self.normal_lines: list[int] = []
        # Face corners: vertex / vt / vn index tokens, "" where absent.
        self.corner_v: list[str] = []
        self.corner_t: list[str] = []
        self.corner_n: list[str] = []
        self.face_sizes: list[int] = []
        self.face_lines: list[int] = []
        # (first face, key) runs of the active group / object / material name.
        self.group_runs: list = [(0, DEFAULT_NAME)]
        self.object_runs: list = [(0, DEFAULT_NAME)]
        self.material_runs: list = [(0, None)]
        self.material_first_use: dict[str, int] = {}  # usemtl name -> line of first use
        self.mtl_diffuse: dict[str, tuple] = {}  # materials defined by MTL files, in order
        self.mtl_specular: dict[str, tuple] = {}  # their Ks, where given
        self.mtl_shininess: dict[str, float] = {}  # their Ns, where given
        self.mtl_maps: dict[str, dict] = {}  # their texture maps: slot -> TextureMap
        self.mtl_pbr: dict[str, dict] = {}  # their Pm / Pr / illum ("Pm" -> value), given
        self.unknown: dict[str, list] = {}  # keyword -> [first line, count]
        # Tags, already validated except for index ranges.
        self.creases: list = []  # (line, pairs (k,2), sharpness (k,))
        self.corners: list = []  # (line, verts (c,), sharpness (c,))
        self.holes: list = []  # (line, faces (h,))
        self.boundary = None
        self.crease_method = None
        self.smooth_triangles = None
        self.fvar_interpolation = None
        # Free-form geometry (subtrace.io.freeform), and the w of v lines that have one
        # (v index -> token; the rational surfaces' weights).
        self.freeform = FreeFormReader(self.fail, self._ignored)
        self.point_w: dict[int, str] = {}

    def fail(self, line, problem):
        raise ObjError(self.path, line, problem)

    def warn(self, line, message):
        self.warnings.append((line, f"{self.path}:{line}: {message}"))

    # -- the pass over statements --------------------------------------------------------

    def read_fast(self, source: list) -> ObjData | None:
        """What `read` returns, from the byte scanner; None where only `read` can tell.

        The scanner (:func:`subtrace.io.obj_scan.scan`) reads v / vt / vn / f lines and lists
        the other statements for _statement. Continuation lines, anything malformed or out of range, and errors of
        other statements go to `read` (on a fresh ObjReader), which reports them.
        ``source``: [the file's bytes], emptied once they are no longer needed (before the
        arrays are cut to size: a large file's bytes and both copies of its arrays are not
        held at once); a None returned after that leaves it empty.
        """
        data = source[0]
        if b"\\" in data:
            return None
        scanned = scan(data)
        if scanned is None:
            return None
        points, uvs, normals, face_sizes, corners, other, slow, counts = scanned
        del scanned
        nv, nt, nn, nf, nc, no, ns = counts.tolist()
        if nf == 0:
            return None
        # numbers the scanner cannot convert exactly (more digits than an int64 holds, as
        # a file written with repr() has): rounded correctly, as float() does
        if ns:
            slow = slow[:ns]
            values = slow_numbers(data, slow)
            if values is None or not np.isfinite(values).all():
                return None
            for k in range(0, ns, _SLOW_CHUNK):
                rows, vals = slow[k:k + _SLOW_CHUNK], values[k:k + _SLOW_CHUNK]
                for block, out in enumerate((points, uvs, normals)):
                    at = rows[:, 2] == block
                    out[rows[at, 3]] = vals[at]
        try:
            for a, b, number, num_faces in other[:no].tolist():
                line = data[a:b].decode("utf-8")
                parts = line.split()
                if not parts:
                    continue
                if parts[0] in ("v", "vt", "vn", "f"):
                    return None  # split at a non-ASCII space the scanner does not know
                if parts[0] in FREEFORM_STATEMENTS:
                    return None  # free-form geometry: weights of v lines are needed
                self._statement(number, line, parts, num_faces)
            source.clear()
            del data
            # each array cut to size, its scanner's buffer (sized for the worst case)
            # dropped before the next is cut
            points = points[: 3 * nv].reshape(-1, 3).copy()
            uvs = uvs[: 2 * nt].reshape(-1, 2).copy()
            normals = normals[: 3 * nn].reshape(-1, 3).copy()
            face_sizes = face_sizes[:nf].copy()
            verts = corners[0, :nc].copy()
            corner_uvs = corners[1, :nc].copy()
            corner_normals = corners[2, :nc].copy()
            del corners, other, slow
            return self._finish(points, uvs, normals, face_sizes, verts, corner_uvs,
                                corner_normals)
        except ObjError:
            return None

    def read(self, text: str) -> ObjData:
        lines, numbers = _logical_lines(text)
        try:
            self._scan(lines, numbers)
        except ObjError:
            # Bad numbers in earlier v / f lines are only found by the bulk conversion:
            # report those first so the error is always the earliest line.
            self._convert(check_forward=False)
            raise
        points, uvs, normals, face_verts, face_uvs, face_normals = self._convert(
            check_forward=True)
        if not self.face_sizes and not self.freeform.has_surfaces:
            empty = not any(line.split() for line in lines)
            self.fail(None, "empty file: no faces" if empty else "no faces (no `f` statements)")
        return self._finish(points, uvs, normals, self.face_sizes, face_verts, face_uvs,
                            face_normals)

    def _scan(self, lines, numbers):
        point_tokens, point_lines = self.point_tokens, self.point_lines
        corner_v, corner_t, corner_n = self.corner_v, self.corner_t, self.corner_n
        face_sizes, face_lines = self.face_sizes, self.face_lines
        for number, line in zip(numbers, lines):
            if "#" in line:
                line = line[: line.index("#")]
            parts = line.split()
            if not parts:
                continue
            keyword = parts[0]
            if keyword == "v":
                # x y z, then an optional w or r g b that are ignored.
                if len(parts) < 4:
                    self.fail(number, f"v needs 3 coordinates x y z, got {len(parts) - 1}")
                if len(parts) == 5:  # x y z w: the weight of a rational surface's point
                    self.point_w[len(point_lines)] = parts[4]
                point_tokens += parts[1:4]
                point_lines.append(number)
            elif keyword == "f":
                size = len(parts) - 1
                if size < 3:
                    self.fail(number, f"face has {size} vertices; a face needs at least 3")
                if "/" in line:
                    # Split every corner before storing any, so a bad face leaves no trace.
                    fields = [corner.split("/") for corner in parts[1:]]
                    for corner, field in zip(parts[1:], fields):
                        if len(field) > 3:
                            self.fail(
                                number,
                                f"face corner '{corner}' has too many '/': "
                                "expected v, v/vt, v//vn or v/vt/vn",
                            )
                    corner_v += [field[0] for field in fields]
                    corner_t += [field[1] if len(field) > 1 else "" for field in fields]
                    corner_n += [field[2] if len(field) > 2 else "" for field in fields]
                else:
                    corner_v += parts[1:]
                    absent = [""] * size
                    corner_t += absent
                    corner_n += absent
                face_sizes.append(size)
                face_lines.append(number)
            elif keyword == "vt":
                # u [v [w]]: v defaults to 0, w is ignored.
                if len(parts) < 2:
                    self.fail(number, "vt needs texture coordinates u [v [w]], got none")
                self.uv_tokens += (parts[1], parts[2] if len(parts) > 2 else "0")
                self.uv_lines.append(number)
            elif keyword == "vn":
                if len(parts) < 4:
                    self.fail(number, f"vn needs 3 coordinates x y z, got {len(parts) - 1}")
                self.normal_tokens += parts[1:4]
                self.normal_lines.append(number)
            else:
                self._statement(number, line, parts, len(face_sizes))

    def _statement(self, number, line, parts, num_faces):
        """A statement other than v / vt / vn / f, after `num_faces` faces."""
        keyword = parts[0]
        if keyword == "t":
            self._tag(number, parts)
        elif keyword == "g":
            self.group_runs.append((num_faces, " ".join(parts[1:]) or DEFAULT_NAME))
        elif keyword == "o":
            self.object_runs.append((num_faces, " ".join(parts[1:]) or DEFAULT_NAME))
        elif keyword == "usemtl":
            # `usemtl` without a name ends the active material.
            name = " ".join(parts[1:]) or None
            if name is not None:
                self.material_first_use.setdefault(name, number)
            self.material_runs.append((num_faces, name))
        elif keyword == "mtllib":
            self._mtllib(number, line.split(None, 1)[1].strip() if len(parts) > 1 else "")
        elif keyword == "s":
            pass  # smoothing groups do not affect subdivision surfaces
        elif keyword in FREEFORM_STATEMENTS:
            self.freeform.statement(number, parts, len(self.point_lines),
                                    self.material_runs[-1][1])
        else:
            self._ignored(keyword, number)

    def _ignored(self, keyword, number):
        """Record a statement that is read and ignored (one warning per keyword)."""
        seen = self.unknown.setdefault(keyword, [number, 0])
        seen[1] += 1

    # -- OpenSubdiv tags -----------------------------------------------------------------

    def _tag(self, number, parts):
        """Validate one `t name nI/nF/nS ints floats strings` line and record it.

        Semantics as OpenSubdiv's far_utils.h applies shape_utils.cpp's tags; unlike
        OpenSubdiv, which skips or misreads malformed tags silently, every problem is an error.
        """
        if len(parts) < 2:
            self.fail(number, "t needs a tag name: t <name> <nInts>/<nFloats>/<nStrings> ...")
        name = parts[1]
        if name == "facevaryingpropagatecorners":
            self.warn(number, f"tag '{name}' ignored: OpenSubdiv does not support it either "
                              "(facevaryinginterpolateboundary 3 propagates corners)")
            return
        if name not in _TAGS:
            self.warn(number, f"unknown tag '{name}' ignored (known: {', '.join(sorted(_TAGS))})")
            return
        ints, floats, strings = self._tag_values(number, name, parts)
        if name in ("crease", "corner"):
            self._tag_sharpness(number, name, ints, floats, strings)
        elif name == "hole":
            if floats or strings:
                self.fail(number, f"tag 'hole' takes face indices only (n/0/0), got {parts[2]}")
            self.holes.append((number, np.array(ints, dtype=np.int64)))
        else:
            self._tag_option(number, name, parts[2], ints, floats, strings)

    def _tag_values(self, number, name, parts) -> tuple[list, list, list]:
        """The ints, floats and strings of a tag line, as its count header announces them."""
        header = parts[2].split("/") if len(parts) > 2 else []
        if len(header) != 3 or not all(h.isascii() and h.isdigit() for h in header):
            got = f"'{parts[2]}'" if len(parts) > 2 else "nothing"
            self.fail(
                number,
                f"tag '{name}': count header must be nInts/nFloats/nStrings (e.g. 2/1/0), "
                f"got {got}",
            )
        n_ints, n_floats, n_strings = (int(h) for h in header)
        values = parts[3:]
        if len(values) != n_ints + n_floats + n_strings:
            self.fail(
                number,
                f"tag '{name}': count header {parts[2]} announces "
                f"{n_ints + n_floats + n_strings} values but the line has {len(values)}",
            )
        ints = []
        for token in values[:n_ints]:
            try:
                ints.append(int(token))
            except ValueError:
                self.fail(number, f"tag '{name}': '{token}' is not an integer")
            if abs(ints[-1]) > MAX_INDEX:
                self.fail(number, f"tag '{name}': index {token} out of range")
        floats = []
        for token in values[n_ints : n_ints + n_floats]:
            try:
                value = float(token)
            except ValueError:
                value = math.nan
            if math.isnan(value):
                self.fail(number, f"tag '{name}': '{token}' is not a number")
            floats.append(value)
        return ints, floats, values[n_ints + n_floats :]

    def _tag_sharpness(self, number, name, ints, floats, strings):
        """A `crease` or `corner` tag: vertex pairs / vertices and their sharpness.

        far_utils.h reads crease ints pairwise, (v0 v1) (v2 v3) ..., not as a chain, and
        drops an odd last one; here an odd count is an error. Both tags take one sharpness for
        all or one per edge / vertex (OpenSubdiv indexes a crease's floats by int position,
        floatargs[2k] for edge k, which only works with one float). OpenSubdiv clamps negative
        sharpness to 0; here it is an error.
        """
        n_ints, n_floats, n_strings = len(ints), len(floats), len(strings)
        items = n_ints // 2 if name == "crease" else n_ints
        if name == "crease" and (n_ints < 2 or n_ints % 2):
            self.fail(
                number,
                "tag 'crease' needs pairs of vertex indices v0 v1 [v2 v3 ...] "
                f"(one pair per edge), got {n_ints} integers",
            )
        if name == "corner" and n_ints < 1:
            self.fail(number, "tag 'corner' needs at least one vertex index")
        if n_floats not in (1, items) or n_strings:
            per = "edge" if name == "crease" else "vertex"
            self.fail(
                number,
                f"tag '{name}' needs 1 sharpness value or one per {per} ({items}) and "
                f"no strings, got {n_floats} floats and {n_strings} strings",
            )
        for value in floats:
            if value < 0.0:
                self.fail(number, f"tag '{name}': negative sharpness {value:g}")
        with np.errstate(over="ignore"):  # beyond float32 is infinitely sharp anyway
            sharpness = np.array(floats * items if n_floats == 1 else floats, dtype=np.float32)
        if name == "crease":
            pairs = np.array(ints, dtype=np.int64).reshape(-1, 2)
            loops = pairs[pairs[:, 0] == pairs[:, 1]]
            if len(loops):
                self.fail(number, f"tag 'crease': edge {loops[0][0]} {loops[0][1]} "
                          "joins a vertex to itself")
            self.creases.append((number, pairs, sharpness))
        else:
            self.corners.append((number, np.array(ints, dtype=np.int64), sharpness))

    def _tag_option(self, number, name, header, ints, floats, strings):
        """An `interpolateboundary`, `creasemethod` or `smoothtriangles` tag (count header
        ``header`` as written)."""
        counts = (len(ints), len(floats), len(strings))
        if name == "interpolateboundary":
            if counts != (1, 0, 0):
                self.fail(
                    number,
                    "tag 'interpolateboundary' expects 1/0/0 and one integer: 0 (none), "
                    f"1 (edge and corner) or 2 (edge only); got {header}",
                )
            if ints[0] not in (BOUNDARY_NONE, BOUNDARY_EDGE_AND_CORNER, BOUNDARY_EDGE_ONLY):
                self.fail(
                    number,
                    f"tag 'interpolateboundary': unknown value {ints[0]}, expected 0 (none), "
                    "1 (edge and corner) or 2 (edge only)",
                )
            self.boundary = ints[0]
        elif name == "facevaryinginterpolateboundary":
            choices = ", ".join(f"{k} ({m})" for k, m in enumerate(FVAR_MODES))
            if counts != (1, 0, 0):
                self.fail(number, "tag 'facevaryinginterpolateboundary' expects 1/0/0 and one "
                                  f"integer: {choices}; got {header}")
            if not 0 <= ints[0] < len(FVAR_MODES):
                self.fail(number, "tag 'facevaryinginterpolateboundary': unknown value "
                                  f"{ints[0]}, expected {choices}")
            self.fvar_interpolation = ints[0]
        elif name == "creasemethod":
            got = self._tag_string(number, name, counts, strings, header, _CREASE_METHODS,
                                   "'normal' or 'chaikin'")
            self.crease_method = _CREASE_METHODS[got]
        else:  # smoothtriangles
            self.smooth_triangles = self._tag_string(number, name, counts, strings, header,
                                                     _SMOOTH_TRIANGLES, "'catmark' or 'smooth'")

    def _tag_string(self, number, name, counts, strings, header, choices, expected):
        """The one string of an option tag (0/0/1) that must be one of ``choices``."""
        if counts != (0, 0, 1) or strings[0] not in choices:
            got = strings[0] if counts == (0, 0, 1) else header
            self.fail(number, f"tag '{name}' expects 0/0/1 and the string {expected}, got "
                              f"unknown '{got}'")
        return strings[0]

    # -- material libraries --------------------------------------------------------------

    def _mtllib(self, number, names: str):
        if not names:
            self.warn(number, "mtllib without a file name ignored")
            return
        # A name containing spaces is taken whole when such a file exists.
        try:
            whole = (self.folder / names).is_file()
        except (OSError, ValueError):
            whole = False
        files = [names] if whole else names.split()
        for name in files:
            mtl_path = self.folder / name
            try:
                data = mtl_path.read_bytes()
            except (OSError, ValueError) as err:
                reason = ("no such file" if isinstance(err, FileNotFoundError)
                          else getattr(err, "strerror", None) or str(err))
                self.warn(number, f"material library '{name}' not read ({reason}); "
                          f"its materials get diffuse {DEFAULT_DIFFUSE}")
                continue
            try:
                text = data.decode("utf-8-sig")
            except UnicodeDecodeError:
                self.warn(number, f"material library '{name}' is not valid UTF-8; "
                          "undecodable bytes replaced")
                text = data.decode("utf-8", errors="replace")
            self._parse_mtl(number, str(mtl_path), text)

    def _parse_mtl(self, obj_line, mtl_path: str, text: str):
        """Read `newmtl`, `Kd`, `Ks` and `Ns` statements and the texture maps subtrace
        applies (`map_Kd`, `map_Ks`, `map_Bump` / `bump`, `norm`: :data:`MAP_SLOTS`); a
        missing map file is one warning naming it, the material keeping its constant
        colours, as is any other map (`map_d`, `map_Ka`, `disp`, ...: not applied); other
        MTL statements do not matter here."""
        current = None
        # (a CRLF line ending is one line end: the lines keep their numbers)
        lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
        for number, line in enumerate(lines, 1):
            if "#" in line:
                line = line[: line.index("#")]
            parts = line.split()
            if not parts:
                continue
            if parts[0] == "newmtl":
                current = " ".join(parts[1:])
                if not current:
                    raise ObjError(mtl_path, number, "newmtl needs a material name")
                self.mtl_diffuse[current] = DEFAULT_DIFFUSE
            elif parts[0] in ("Kd", "Ks", "Ns", *REFLECTION_KEYS) and current is None:
                self.warnings.append(
                    (obj_line, f"{mtl_path}:{number}: {parts[0]} before any newmtl ignored"))
            elif parts[0] == "Ns":
                self.mtl_shininess[current] = _mtl_exponent(mtl_path, number, parts[1:])
            elif parts[0].lower() in MAP_SLOTS and current is not None:
                found = _texture_map(mtl_path, number, parts)
                if isinstance(found, str):
                    self.warnings.append((obj_line, found + f"; material '{current}' keeps "
                                                  "its constant colours"))
                else:
                    self.mtl_maps.setdefault(current, {})[found.slot] = found
            elif parts[0] in REFLECTION_KEYS:
                self.mtl_pbr.setdefault(current, {})[parts[0]] = _mtl_reflection(
                    mtl_path, number, parts[0], parts[1:])
            elif parts[0].lower() in TEXTURE_MAPS:
                self.warnings.append((obj_line, _texture_map_warning(
                    mtl_path, number, parts, current)))
            elif parts[0] in ("Kd", "Ks"):
                store = self.mtl_diffuse if parts[0] == "Kd" else self.mtl_specular
                if parts[1:2] in (["spectral"], ["xyz"]):
                    what = "diffuse" if parts[0] == "Kd" else "specular"
                    was = DEFAULT_DIFFUSE if parts[0] == "Kd" else DEFAULT_SPECULAR
                    self.warnings.append(
                        (obj_line, f"{mtl_path}:{number}: {parts[0]} {parts[1]} is not "
                                   f"supported; {what} of '{current}' stays {was}"))
                else:
                    store[current] = _mtl_rgb(mtl_path, number, parts[0], parts[1:])

    # -- bulk conversion -----------------------------------------------------------------

    def _convert(self, check_forward: bool):
        """Number blocks -> arrays; raises the earliest bad line over all blocks.

        check_forward: also check positive indices against the final element counts (off
        while reporting errors of a partial scan, where later lines may define them).
        """
        sizes = np.array(self.face_sizes, dtype=np.int64)
        face_lines = np.array(self.face_lines, dtype=np.int64)
        steps = [
            lambda: self._floats(self.point_tokens, self.point_lines, 3, "v"),
            lambda: self._floats(self.uv_tokens, self.uv_lines, 2, "vt"),
            lambda: self._floats(self.normal_tokens, self.normal_lines, 3, "vn"),
            lambda: self._indices(self.corner_v, self.point_lines, sizes, face_lines,
                                  "vertex", "v", check_forward),
            lambda: self._indices(self.corner_t, self.uv_lines, sizes, face_lines,
                                  "texture coordinate", "vt", check_forward),
            lambda: self._indices(self.corner_n, self.normal_lines, sizes, face_lines,
                                  "normal", "vn", check_forward),
        ]
        results, errors = [], []
        for step in steps:
            try:
                results.append(step())
            except ObjError as err:
                errors.append(err)
        if errors:
            raise min(errors, key=lambda err: err.line or 0)
        return results

    def _floats(self, tokens, lines, width, keyword) -> np.ndarray:
        """(n, width) float64 from n rows of `width` tokens, all finite."""
        try:
            values = np.array(tokens, dtype=np.float64)
            good = bool(np.isfinite(values).all())
        except (ValueError, OverflowError):
            good = False
        if good:
            return values.reshape(-1, width)
        for row, number in enumerate(lines):
            for token in tokens[row * width : (row + 1) * width]:
                try:
                    value = float(token)
                except ValueError:
                    self.fail(number, f"{keyword}: '{token}' is not a number")
                if not math.isfinite(value):
                    self.fail(number, f"{keyword}: '{token}' is not a finite number "
                              "(nan, inf or too large for a double)")
        self.fail(lines[0] if lines else None, f"cannot convert the {keyword} values")

    def _indices(self, tokens, element_lines, sizes, face_lines, what, keyword,
                 check_forward) -> np.ndarray:
        """0-based int32 corner indices; "" tokens become -1 (absent vt / vn)."""
        total = len(element_lines)
        if keyword != "v" and not any(tokens):
            return np.full(len(tokens), -1, dtype=np.int32)
        try:
            raw_tokens = np.array(tokens, dtype=str)
            present = raw_tokens != ""
            raw = np.zeros(len(tokens), dtype=np.int64)
            raw[present] = raw_tokens[present].astype(np.int64)
        except (ValueError, OverflowError):
            self._bad_index(tokens, element_lines, sizes, face_lines, what, keyword,
                            check_forward)
        # Negative indices count back from the elements read before the face's line.
        before = np.searchsorted(np.array(element_lines, dtype=np.int64), face_lines)
        resolved = np.where(raw < 0, raw + np.repeat(before, sizes), raw - 1)
        bad = (present & (raw == 0)) | (present & (resolved < 0))
        if keyword == "v":
            bad |= ~present
        if check_forward:
            bad |= present & (resolved >= total)
        if bad.any():
            self._bad_index(tokens, element_lines, sizes, face_lines, what, keyword,
                            check_forward)
        resolved[~present] = -1
        return resolved.astype(np.int32)

    def _bad_index(self, tokens, element_lines, sizes, face_lines, what, keyword,
                   check_forward):
        """Walk the corners in file order and raise the first bad index."""
        total = len(element_lines)
        start = 0
        for size, number in zip(sizes.tolist(), face_lines.tolist()):
            for token in tokens[start : start + size]:
                if token == "":
                    if keyword == "v":
                        self.fail(number, "face corner without a vertex index")
                    continue
                try:
                    index = int(token)
                except ValueError:
                    self.fail(number, f"{what} index '{token}' is not an integer")
                if index == 0:
                    self.fail(number, f"{what} index 0 is invalid: OBJ indices start at 1 "
                              f"(negative ones count back from the last {keyword})")
                if index < 0:
                    before = bisect.bisect_left(element_lines, number)
                    if index + before < 0:
                        self.fail(number, f"relative {what} index {index} out of range: "
                                  f"only {before} {keyword} lines before this face")
                elif (check_forward and index > total) or index > MAX_INDEX:
                    self.fail(number, f"{what} index {index} out of range: the file has "
                              f"{total} {keyword} lines")
            start += size
        self.fail(face_lines[0] if len(face_lines) else None,
                  f"cannot convert the {what} indices")

    # -- assembly ------------------------------------------------------------------------

    def _finish(self, points, uvs, normals, face_sizes, face_verts, face_uvs,
                face_normals) -> ObjData:
        num_faces = len(face_sizes)
        num_points = len(points)

        crease_edges = (np.concatenate([p for _, p, _ in self.creases])
                        if self.creases else np.zeros((0, 2), np.int64))
        corner_verts = (np.concatenate([v for _, v, _ in self.corners])
                        if self.corners else np.zeros(0, np.int64))
        hole_faces = (np.concatenate([f for _, f in self.holes])
                      if self.holes else np.zeros(0, np.int64))
        # Tag indices are 0-based; they can only be checked once the whole file is read.
        checks = ([(n, "crease", p.ravel(), "vertex", num_points) for n, p, _ in self.creases]
                  + [(n, "corner", v, "vertex", num_points) for n, v, _ in self.corners]
                  + [(n, "hole", f, "face", num_faces) for n, f in self.holes])
        for number, name, indices, what, count in sorted(checks, key=lambda c: c[0]):
            bad = indices[(indices < 0) | (indices >= count)]
            if len(bad):
                self.fail(number, f"tag '{name}': {what} index {bad[0]} out of range: the "
                          f"file has {count} {'vertices' if what == 'vertex' else 'faces'} (tag indices "
                          "are 0-based: the first is 0)")

        # Materials: every MTL definition in order, then names used but never defined.
        local_ids: dict = {}
        face_material = _runs_to_array(self.material_runs, num_faces, local_ids)
        diffuse = dict(self.mtl_diffuse)
        for name, number in self.material_first_use.items():
            if name not in diffuse:
                diffuse[name] = DEFAULT_DIFFUSE
                self.warn(number, f"material '{name}' is not defined in any material "
                          f"library; using diffuse {DEFAULT_DIFFUSE}")
        materials = tuple(
            Material(name, tuple(float(c) for c in rgb),
                     self.mtl_specular.get(name, DEFAULT_SPECULAR),
                     self.mtl_shininess.get(name, DEFAULT_SHININESS),
                     tuple(self.mtl_maps.get(name, {}).values()),
                     *_reflection(self.mtl_pbr.get(name, {}),
                                  self.mtl_shininess.get(name, DEFAULT_SHININESS)))
            for name, rgb in diffuse.items())
        material_ids = {name: k for k, name in enumerate(diffuse)}
        freeform = self.freeform.finish(self.path, points, self.point_lines, self.point_w,
                                        material_ids)
        if local_ids:
            remap = np.array([material_ids[name] for name in local_ids], dtype=np.int32)
            face_material = np.where(face_material >= 0, remap[face_material], -1)

        group_ids: dict = {}
        face_group = _runs_to_array(self.group_runs, num_faces, group_ids)
        object_ids: dict = {}
        face_object = _runs_to_array(self.object_runs, num_faces, object_ids)

        for keyword, (number, count) in self.unknown.items():
            kind = ("free-form geometry statement" if keyword in _FREEFORM
                    else "unsupported statement")
            more = f" ({count} lines)" if count > 1 else ""
            self.warn(number, f"{kind} '{keyword}' ignored{more}")
        self.warnings.sort(key=lambda w: w[0])

        def i32(a):
            return np.ascontiguousarray(a, dtype=np.int32)

        crease_sharpness = (np.concatenate([s for _, _, s in self.creases])
                            if self.creases else np.zeros(0, np.float32))
        corner_sharpness = (np.concatenate([s for _, _, s in self.corners])
                            if self.corners else np.zeros(0, np.float32))
        return ObjData(
            path=self.path,
            points=np.ascontiguousarray(points, dtype=np.float64),
            face_sizes=i32(face_sizes),
            face_verts=i32(face_verts),
            uvs=np.ascontiguousarray(uvs, dtype=np.float64),
            face_uvs=i32(face_uvs),
            normals=np.ascontiguousarray(normals, dtype=np.float64),
            face_normals=i32(face_normals),
            face_material=i32(face_material),
            materials=materials,
            face_group=i32(face_group),
            groups=tuple(group_ids),
            face_object=i32(face_object),
            objects=tuple(object_ids),
            crease_edges=i32(crease_edges).reshape(-1, 2),
            crease_sharpness=np.ascontiguousarray(crease_sharpness, dtype=np.float32),
            corner_verts=i32(corner_verts),
            corner_sharpness=np.ascontiguousarray(corner_sharpness, dtype=np.float32),
            hole_faces=i32(hole_faces),
            boundary=self.boundary,
            crease_method=self.crease_method,
            smooth_triangles=self.smooth_triangles,
            warnings=tuple(message for _, message in self.warnings),
            fvar_interpolation=self.fvar_interpolation,
            freeform=freeform,
        )


def statement_line(path, keyword: str, index: int) -> int | None:
    """The 1-based line of the ``index``-th (0-based) ``keyword`` statement of the OBJ file
    ``path`` (e.g. the line of vertex ``index`` for ``"v"``), or None where it cannot be
    found. For messages about a file that was read without error."""
    try:
        raw = read_obj_bytes(os.fspath(path))
        text = raw.decode("utf-8", errors="replace")
    except (ObjError, OSError, TypeError):
        return None
    lines, numbers = _logical_lines(text)
    seen = 0
    for line, number in zip(lines, numbers):
        parts = line.split(None, 1)
        if parts and parts[0] == keyword:
            if seen == index:
                return number
            seen += 1
    return None


def _mtl_rgb(mtl_path: str, number: int, key: str, tokens) -> tuple:
    """An MTL colour statement's ``r g b`` (or one grey value); ObjError otherwise."""
    try:
        rgb = [float(token) for token in tokens]
    except ValueError:
        rgb = []
    if len(rgb) not in (1, 3) or not all(math.isfinite(c) for c in rgb):
        raise ObjError(mtl_path, number,
                       f"{key} needs 3 numbers r g b (or 1 for grey), got '{' '.join(tokens)}'")
    return tuple(rgb * 3 if len(rgb) == 1 else rgb)


def _mtl_exponent(mtl_path: str, number: int, tokens) -> float:
    """An MTL ``Ns`` statement's exponent (a number >= 0); ObjError otherwise."""
    try:
        value = float(tokens[0]) if len(tokens) == 1 else -1.0
    except ValueError:
        value = -1.0
    if not (math.isfinite(value) and value >= 0.0):
        raise ObjError(mtl_path, number,
                       f"Ns needs one number >= 0 (the specular exponent), got "
                       f"'{' '.join(tokens)}'")
    return value


# MTL's statements of reflection: the PBR extension's metallic and roughness, and the
# illumination model (3..7: ray-traced reflection, of colour Ks)
REFLECTION_KEYS = ("Pm", "Pr", "illum")
REFLECTING_ILLUM = range(3, 8)


def _mtl_reflection(mtl_path: str, number: int, key: str, tokens) -> float:
    """An MTL ``Pm`` / ``Pr`` value (one number 0..1) or ``illum`` model (a whole number
    0..10); ObjError otherwise."""
    try:
        value = float(tokens[0]) if len(tokens) == 1 else math.nan
    except ValueError:
        value = math.nan
    if key == "illum":
        if not (value in range(0, 11)):
            raise ObjError(mtl_path, number, f"illum needs one whole number 0..10 (the "
                           f"illumination model), got '{' '.join(tokens)}'")
        return value
    if not 0.0 <= value <= 1.0:
        what = "metallic" if key == "Pm" else "roughness"
        raise ObjError(mtl_path, number, f"{key} needs one number between 0 and 1 (the "
                       f"{what}), got '{' '.join(tokens)}'")
    return value


def _reflection(given: dict, shininess: float) -> tuple:
    """(metallic, roughness) of a material whose MTL gave ``given`` (:data:`REFLECTION_KEYS`
    -> value) and exponent ``shininess`` (see :class:`Material`)."""
    if "Pm" in given or "Pr" in given:
        return given.get("Pm", 0.0), given.get("Pr", 0.0)
    if given.get("illum") in REFLECTING_ILLUM:
        return None, roughness_of_exponent(shininess)
    return None, None


def roughness_of_exponent(shininess: float) -> float:
    """The roughness (GGX alpha = roughness^2) of a Blinn-Phong exponent ``Ns``: the
    lobe of the same width, alpha^2 = 2 / (Ns + 2) (Walter et al. 2007: Beckmann's, which
    GGX's alpha matches near the peak)."""
    return (2.0 / (shininess + 2.0)) ** 0.25


# MTL's texture map statements (lower case: their keywords are matched so)
TEXTURE_MAPS = ("map_kd", "map_ks", "map_ka", "map_ns", "map_d", "map_bump", "bump", "norm",
                "disp", "decal", "refl", "map_pr", "map_pm", "map_ke")


# the texture maps subtrace applies (lower case) and the slot each fills
MAP_SLOTS = {"map_kd": "diffuse", "map_ks": "specular", "map_bump": "bump", "bump": "bump",
             "norm": "normal"}
# a map statement's options and how many values each takes (MTL's; those of
# _MAP_READ are applied, the others read and ignored)
_MAP_OPTIONS = {"-blendu": 1, "-blendv": 1, "-boost": 1, "-cc": 1, "-clamp": 1,
                "-imfchan": 1, "-mm": 2, "-o": 3, "-s": 3, "-t": 3, "-texres": 1, "-bm": 1,
                "-type": 1}
_CHANNELS = {"r": 0, "g": 1, "b": 2, "m": 0, "l": 0, "z": 0}


def _texture_map(mtl_path: str, number: int, parts):
    """A :class:`TextureMap` of an applied map statement ``parts`` (options, then the file:
    the last token, relative to the MTL file's folder), or the warning's text where its file
    is missing; ObjError for a bad option."""
    where = f"{mtl_path}:{number}"
    if len(parts) < 2:
        return f"{where}: {parts[0]} names no file; ignored"
    name = parts[-1]
    file = Path(mtl_path).parent / name
    if not file.is_file():
        return f"{where}: {parts[0]} texture '{name}' not found ({file})"
    values = {"bump_scale": 1.0, "offset": (0.0, 0.0), "scale": (1.0, 1.0), "clamp": False,
              "channel": 0}
    args, k = parts[1:-1], 0
    while k < len(args):
        option = args[k].lower()
        if option not in _MAP_OPTIONS:
            raise ObjError(mtl_path, number, f"{parts[0]}: unknown option '{args[k]}' (known: "
                                             f"{' '.join(_MAP_OPTIONS)}), before the file name")
        most = _MAP_OPTIONS[option]
        # (-o, -s, -t take 1 to 3 numbers, -mm 2; the others one word or number)
        given = args[k + 1:k + 2]
        if most > 1:
            while (len(given) < most and k + 1 + len(given) < len(args)
                   and _is_number(args[k + 1 + len(given)])):
                given.append(args[k + 1 + len(given)])
        if not given:
            raise ObjError(mtl_path, number, f"{parts[0]}: option {option} needs a value")
        k += 1 + len(given)
        if option == "-bm":
            values["bump_scale"] = _map_number(mtl_path, number, parts[0], option, given[0])
        elif option in ("-o", "-s"):
            uv = [_map_number(mtl_path, number, parts[0], option, g) for g in given[:2]]
            uv = uv + [0.0 if option == "-o" else 1.0] * (2 - len(uv))
            values["offset" if option == "-o" else "scale"] = (uv[0], uv[1])
        elif option == "-clamp":
            if given[0].lower() not in ("on", "off"):
                raise ObjError(mtl_path, number, f"{parts[0]}: -clamp takes on or off, got "
                                                 f"'{given[0]}'")
            values["clamp"] = given[0].lower() == "on"
        elif option == "-imfchan":
            if given[0].lower() not in _CHANNELS:
                raise ObjError(mtl_path, number, f"{parts[0]}: -imfchan takes r, g, b, m, l "
                                                 f"or z, got '{given[0]}'")
            values["channel"] = _CHANNELS[given[0].lower()]
    return TextureMap(MAP_SLOTS[parts[0].lower()], str(file.resolve()), where, **values)


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def _map_number(mtl_path, number, keyword, option, token) -> float:
    try:
        value = float(token)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise ObjError(mtl_path, number, f"{keyword}: option {option} needs a number, got "
                                         f"'{token}'")
    return value


def _texture_map_warning(mtl_path: str, number: int, parts, material) -> str:
    """The one warning of a texture map statement ``parts`` (its options, then the file:
    the last token, relative to the MTL file's folder)."""
    where = f"{mtl_path}:{number}: {parts[0]}"
    whose = f"material '{material}'" if material is not None else "no material (before newmtl)"
    if len(parts) < 2:
        return f"{where} names no file; ignored"
    name = parts[-1]
    file = Path(mtl_path).parent / name
    if not file.is_file():
        return (f"{where} texture '{name}' not found ({file}); {whose} keeps its constant "
                "colours")
    return (f"{where} texture '{name}' not applied (subtrace applies map_Kd, map_Ks, "
            f"map_Bump / bump and norm); {whose} keeps its constant colours")
