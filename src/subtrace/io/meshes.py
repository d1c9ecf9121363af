"""Triangle and polygon mesh formats that scanners and other tools write, read as cages
through trimesh (``pip install subtrace[meshes]``): ``.ply``, ``.stl``, ``.off``, ``.glb`` /
``.gltf``.

These formats carry no subdivision tags, so a cage read from them is all smooth, with
OpenSubdiv's default boundary rule; an all-triangle mesh (what scanners give, and every STL)
is a Loop cage, as the "triangulated surfaces" of the subdivision literature are, unless
``scheme`` says otherwise. trimesh triangulates polygons when it loads PLY and OFF files:
where the file held polygons, one warning says that the cage is the triangulated one.
STL stores each triangle with its own three corners: corners at the same position are
merged into one vertex (a cage needs its faces to share vertices). A glTF scene's meshes are
placed by their node transforms and joined into one cage. A file with no faces (a point
cloud, an empty scene) is refused with one line naming it and what is read.
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import warnings

import numpy as np

from subtrace.errors import SubtraceError, SubtraceWarning

MESH_EXTENSIONS = {".ply": "PLY", ".stl": "STL", ".off": "OFF", ".glb": "glTF",
                   ".gltf": "glTF"}


def is_mesh_file(path) -> bool:
    """Whether ``path`` is in one of :data:`MESH_EXTENSIONS` (by its extension)."""
    return os.path.splitext(os.fspath(path))[1].lower() in MESH_EXTENSIONS


def read_mesh(path):
    """(points (n,3) float64, face sizes (f,) int32, face vertices (sum,) int32) of the mesh
    file ``path``, with the warnings the module comment lists."""
    path = os.fsdecode(os.fspath(path))
    kind = MESH_EXTENSIONS[os.path.splitext(path)[1].lower()]
    try:
        import trimesh
    except ImportError:
        raise SubtraceError(f"{path}: reading {kind} files needs trimesh: pip install "
                            "'subtrace[meshes]' (or pip install trimesh)") from None
    if not os.path.exists(path):
        raise SubtraceError(f"{path}: no such file")
    if os.path.isdir(path):
        raise SubtraceError(f"{path}: is a directory, expected a {kind} file")
    try:
        with warnings.catch_warnings(), _quiet_log("trimesh"):
            warnings.simplefilter("ignore")
            loaded = trimesh.load(path, process=False, force=None)
    except Exception as exc:  # noqa: BLE001 - trimesh raises many kinds
        text = " ".join(str(exc).split()) or type(exc).__name__
        raise SubtraceError(f"{path}: not a readable {kind} file: {text[:200]}") from None
    if isinstance(loaded, trimesh.Scene):
        geoms = [g for g in loaded.dump() if isinstance(g, trimesh.Trimesh)]
        loaded = trimesh.util.concatenate(geoms) if geoms else None
    faces = getattr(loaded, "faces", None)
    if loaded is None or faces is None or not len(faces):
        what = "a point cloud" if isinstance(loaded, trimesh.PointCloud) else "no faces"
        raise SubtraceError(f"{path}: {what}: subtrace renders meshes (OBJ, USD, PLY, STL, "
                            "OFF and glTF with faces)")
    points = np.asarray(loaded.vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if kind == "STL":
        points, faces = _merge_corners(points, faces)
    declared = _declared_faces(path, kind)
    if declared is not None and declared < len(faces):
        warnings.warn(SubtraceWarning(
            f"{path}: its {declared} faces include polygons, which trimesh triangulated on "
            f"load: the cage is the {len(faces)} triangles (use OBJ to keep the polygons)"),
            stacklevel=3)
    sizes = np.full(len(faces), faces.shape[1], np.int32)
    return points, sizes, faces.ravel().astype(np.int32)


@contextlib.contextmanager
def _quiet_log(name):
    """The logger ``name`` silenced for the block: trimesh logs the tracebacks of the
    readers it tries before the one that works (a damaged binary STL read as text, say)
    to stderr, which must hold only subtrace's one line."""
    log = logging.getLogger(name)  # (its modules' loggers inherit its level)
    was = log.level
    log.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        log.setLevel(was)


def _merge_corners(points, faces):
    """One vertex per distinct position (STL repeats a vertex in every triangle)."""
    uniq, inverse = np.unique(points, axis=0, return_inverse=True)
    return uniq, inverse.reshape(-1)[faces]


def _declared_faces(path, kind):
    """The face count a PLY or OFF file's header declares (None for other formats or a
    header that cannot be read)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096)
    except OSError:
        return None
    if kind == "PLY":
        m = re.search(rb"element\s+face\s+(\d+)", head)
        return int(m.group(1)) if m else None
    if kind == "OFF":
        lines = [ln.split(b"#")[0].strip() for ln in head.splitlines()]
        lines = [ln for ln in lines if ln]
        if lines and lines[0].startswith(b"OFF"):
            rest = lines[0][3:].split() or (lines[1].split() if len(lines) > 1 else [])
            try:
                return int(rest[1])
            except (IndexError, ValueError):
                return None
    return None


__all__ = ["read_mesh", "is_mesh_file", "MESH_EXTENSIONS"]
