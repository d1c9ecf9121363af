"""The trimmed NURBS surfaces of a scene, rendered beside its subdivision cages.

:func:`load_nurbs` reads the free-form surfaces of every scene object whose OBJ file has
``surf`` statements into one :class:`NurbsScene`: one :class:`~subtrace.nurbs.model.NurbsModel`
over all of them (surface index = the ``patch_id`` channel, in object then file order), the
BVH over its patches' shells, and per surface its scene object and colour (the object's
colour, else its material's diffuse colour). An object's polygon faces, if its file has any,
are its subdivision cage as before (:func:`has_faces`).

:func:`nurbs_pass` traces the surfaces (:mod:`subtrace.nurbs.trace`) and writes the
pixels whose NURBS hit is nearer than what the subdivision pass found into the same channel
planes (:data:`subtrace.shade.CHANNELS`), every one but the colour.
:func:`picture_hits` then hands those pixels to the picture (``subtrace.picture``) as hits
of extra patches (:func:`with_surfaces`: one per surface, past the cages' patches), so the
picture lights them with ``shade.light`` (shadows, ambient occlusion, point lights) and
anti-aliases their edges like the cages'; :func:`shade_rays` does the same for the extra
anti-aliasing rays, and :func:`blocked` answers the secondary rays (shadow, AO) with their
ray cones (``trace.trace_rays``'s ``cone``).
"""

from __future__ import annotations

import functools
import os
import re
import time
import warnings
from dataclasses import dataclass, replace

import numpy as np

from subtrace import config
from subtrace.errors import SubtraceWarning
from subtrace.io.limits import check_coordinates
from subtrace.io.meshes import is_mesh_file
from subtrace.io.placement import place
from subtrace.io.obj import DEFAULT_DIFFUSE, Material, read_obj, read_obj_bytes
from subtrace.io.usd import is_usd
from subtrace.nurbs.freeform import freeform_of
from subtrace.nurbs.model import NurbsModel, build_model
from subtrace.nurbs.trace import (
    NurbsHits,
    hit_geometry,
    patch_boxes,
    patch_bvh,
    trace_nurbs,
    trace_rays,
)
from subtrace.runtime.jit import nb
from subtrace.runtime.threads import run_tasks
from subtrace.shade import (C_A, C_LEVEL, C_N, C_OBJECT, C_P, C_PATCH, C_U, C_Z,
                            PatchShading, material_of, pixel_rays)
from subtrace.subdiv.topology import compact
from subtrace.geometry.prims import ray_setup

_LINE_START = re.compile(rb"[ \t]*")  # what may precede a statement's keyword on its line


def _has_statement(raw: bytes, keyword: bytes) -> bool:
    """Whether a line of ``raw`` starts (after blanks) with ``keyword`` then a blank: the
    keyword's occurrences found with ``bytes.find``, each checked in place (a regular
    expression anchored at line starts walked the sword's 1.2 MB cage in 4-7 ms looking
    for a ``surf`` it lacks; ``find`` takes 0.6 ms)."""
    at = raw.find(keyword)
    while at >= 0:
        start = raw.rfind(b"\n", 0, at) + 1
        after = raw[at + len(keyword):at + len(keyword) + 1]
        if after in (b" ", b"\t") and _LINE_START.fullmatch(raw, start, at):
            return True
        at = raw.find(keyword, at + 1)
    return False


def _is_obj(path) -> bool:
    """Whether ``path`` is read as OBJ (not a USD stage or a PLY / STL / OFF / glTF mesh)."""
    return not (is_usd(path) or is_mesh_file(path))


@functools.lru_cache(maxsize=64)
def _scan(path: str, mtime_ns: int, size: int) -> tuple[bool, bool]:
    """(has a ``surf`` statement, has an ``f`` statement) of the OBJ file (one read per
    version of the file: a render asks several times)."""
    raw = read_obj_bytes(path)
    return _has_statement(raw, b"surf"), _has_statement(raw, b"f")


def _kinds(path) -> tuple[bool, bool]:
    path = str(path)
    try:
        st = os.stat(path)
    except OSError:
        read_obj_bytes(path)  # the reader's one-line error for a missing file
        raise
    return _scan(path, st.st_mtime_ns, st.st_size)


def has_surfaces(path) -> bool:
    """The OBJ file has a ``surf`` statement (a quick scan of its bytes)."""
    return _is_obj(path) and _kinds(path)[0]


def has_faces(path) -> bool:
    """The OBJ file has an ``f`` statement: a subdivision cage (a quick scan); meshes of
    other formats always are cages."""
    return not _is_obj(path) or _kinds(path)[1]


@dataclass(frozen=True, eq=False)
class NurbsScene:
    """A scene's free-form surfaces (S surfaces; see the module comment)."""

    model: NurbsModel
    bvh: object  # subtrace.accel.bvh.BVH over the patches' shells
    surface_object: np.ndarray  # (S,) int32 scene object index
    surface_color: np.ndarray  # (S, 3) float64 diffuse colour
    surface_specular: np.ndarray  # (S, 3) float64 specular colour (Ks; 0: none)
    surface_shininess: np.ndarray  # (S,) float64 specular exponent (Ns)
    surface_reflect: np.ndarray  # (S, 3) float64 reflectance at normal incidence (0: none)
    surface_roughness: np.ndarray  # (S,) float64 (shade.material_of)

    def bounds(self):
        """(lo (3,), hi (3,)): the box of every patch's projected control points."""
        lo, hi = patch_boxes(self.model.nets, self.model.patch_degree)
        return lo.min(axis=0), hi.max(axis=0)


def load_nurbs(scene, quiet: bool = False) -> NurbsScene | None:
    """The free-form surfaces of ``scene``'s objects (None when no object has any).
    ``quiet``: the file's reading warnings are not repeated (the cage load gives them)."""
    surfaces, owner, rows = [], [], []
    for k, obj in enumerate(scene.objects):
        if not has_surfaces(obj.mesh):
            continue
        with warnings.catch_warnings():
            if quiet or has_faces(obj.mesh):  # the cage's load warns once already
                warnings.simplefilter("ignore", SubtraceWarning)
            data = read_obj(obj.mesh)
        if obj.transform is not None:  # (the weights are apart from the points: affine)
            data = replace(data, points=place(data.points, obj.transform))
        freeform = freeform_of(data)
        if freeform is None:
            continue
        check_coordinates(obj.mesh, data.points, config.MAX_COORDINATE)
        # the surface's usemtl material (the last row: none), the scene's keys over it
        table = [*data.materials, Material("", DEFAULT_DIFFUSE)]
        for surface in freeform.surfaces:
            surfaces.append(surface)
            owner.append(k)
            rows.append(material_of(table[surface.material], obj))
    if not surfaces:
        return None
    model = build_model(surfaces)
    fields = [np.array([r[k] for r in rows], dtype=np.float64) for k in range(5)]
    return NurbsScene(model, patch_bvh(model), np.array(owner, dtype=np.int32), *fields)


def nurbs_pass(nurbs: NurbsScene, frame, width, height, tol_rad, other_t, planes,
               stats) -> NurbsHits:
    """The render's NURBS pass: trace ``nurbs`` for every pixel and write every channel but
    the colour of the hits nearer than ``other_t`` (n,) (the subdivision hits' distances;
    None: none) into ``planes`` (len(CHANNELS), n) float32 (the picture colours them with
    the cages' hits, ``subtrace.picture``). Counts go into ``stats``
    (:class:`subtrace.render.RenderStats`): patches, the deepest split, the patches hit; a
    leaf held at NURBS_MAX_LEVEL above the tolerance is warned of and recorded as the
    ``precision`` cap. Returns the hits (those not shaded get patch -1)."""
    t0 = time.perf_counter()
    if other_t is None:
        other_t = np.full(width * height, np.inf)
    hits = _shade_nearer(nurbs, frame, width, height, tol_rad, other_t, planes)
    stats.patches += nurbs.model.n_patches
    stats.max_depth = max(stats.max_depth, int(hits.level.max(initial=0)))
    # (per ray; np.unique would import numpy.ma)
    stats.patches_refined += len(compact(hits.patch[hits.patch >= 0], nurbs.model.n_patches)[0])
    if hits.capped:
        warnings.warn(f"{hits.capped} NURBS sub-patches held at {config.NURBS_MAX_LEVEL} "
                      "halvings above the tolerance", SubtraceWarning, stacklevel=3)
        stats.depth_cap = max(stats.depth_cap, config.NURBS_MAX_LEVEL)
        stats.depth_cap_reason = ("precision" if stats.depth_cap_reason == "none"
                                  else stats.depth_cap_reason + ",precision")
    stats.time_trace += time.perf_counter() - t0
    return hits


def _shade_nearer(nurbs, frame, width, height, tol_rad, other_t, planes):
    """Trace and shade (see :func:`nurbs_pass`)."""
    hits = trace_nurbs(nurbs.model, nurbs.bvh, frame, width, height, tol_rad)
    near = np.nonzero(hits.t < other_t)[0]
    keep = np.zeros(len(hits.t), dtype=np.bool_)
    keep[near] = True
    hits.patch[~keep] = -1
    hits.level[~keep] = -1
    if not len(near):
        return hits
    _, normals, uv = hit_geometry(nurbs.model, hits.patch[near], hits.st[near])
    surface = nurbs.model.patch_surface[hits.patch[near]]
    run_tasks(_shade_hits, frame, int(width), near, hits.t, hits.level, surface, normals, uv,
              nurbs.surface_object, planes)
    return hits


def with_surfaces(nurbs: NurbsScene, patches: PatchShading | None):
    """(the cages' ``patches`` (None: none) followed by one row per free-form surface, the
    row of surface 0): the surfaces' materials for ``shade.light`` (diffuse colour and
    Blinn-Phong lobe, from the object's keys or the surface's MTL material, as the cages')."""
    s = len(nurbs.surface_color)
    rows = PatchShading(nurbs.surface_object.astype(np.int32), np.arange(s, dtype=np.int32),
                        np.zeros((s, 2)), np.ones(s), np.zeros(s, np.int8),
                        nurbs.surface_color.astype(np.float64),
                        nurbs.surface_specular.astype(np.float64),
                        nurbs.surface_shininess.astype(np.float64),
                        nurbs.surface_reflect.astype(np.float64),
                        nurbs.surface_roughness.astype(np.float64))
    if patches is None:
        return rows, 0
    return PatchShading(*(np.concatenate([a, b]) for a, b in zip(patches, rows))), len(
        patches.object_id)


def picture_hits(nurbs: NurbsScene, hits, frame, width, offset, t, normals, pix_patch,
                 dirs=None) -> np.ndarray:
    """Hand the rays whose ``hits`` (:class:`~subtrace.nurbs.trace.NurbsHits`) have a patch
    to the picture: their distance into ``t``, their exact unit normal turned towards the
    eye into ``normals`` and their surface's row of :func:`with_surfaces` (``offset`` +
    surface) into ``pix_patch``. Rays: pixel centres, or ``dirs`` (n,3) from the eye.
    Returns the rays (indices)."""
    near = np.nonzero(hits.patch >= 0)[0]
    if not len(near):
        return near
    _, n, _ = hit_geometry(nurbs.model, hits.patch[near], hits.st[near])
    d = pixel_rays(frame, width, near) if dirs is None else dirs[near]
    n = np.where(((n * d).sum(axis=1) > 0.0)[:, None], -n, n)
    t[near] = hits.t[near]
    normals[near] = n
    pix_patch[near] = offset + nurbs.model.patch_surface[hits.patch[near]]
    return near


def shade_rays(nurbs: NurbsScene, frame, dirs, tol_rad, offset, t, normals, pix_patch,
               planes, origins=None, cone=None) -> None:
    """Rays along ``dirs`` (n,3) from the eye (extra anti-aliasing rays; ``origins`` None) or
    from ``origins`` (n,3) (reflected rays; ``cone``: None, or (n,) each ray's width at its
    origin, ``trace.trace_rays``) whose NURBS hit is nearer than ``t`` (n,) (their
    subdivision hits): ``t``, ``normals``, ``pix_patch`` as :func:`picture_hits` writes
    them, and in ``planes`` (len(CHANNELS), n; None: none) every channel but the colour, as
    the pixels' pass writes them (A, Z, N, level, patch_id (the surface), object_id, u, v,
    P: a pixel whose centre ray missed takes them from its nearest extra ray that hit,
    ``picture._nearest_hit``)."""
    if origins is None:
        origins = np.repeat(frame[0][None], len(dirs), axis=0)
    hits = trace_rays(nurbs.model, nurbs.bvh, origins, dirs, tol_rad, cone=cone)
    hits.patch[~(hits.t < t)] = -1
    near = picture_hits(nurbs, hits, frame, 0, offset, t, normals, pix_patch, dirs)
    if planes is None:
        return
    planes[C_A, near] = 1.0
    planes[C_Z, near] = t[near]
    for k in range(3):
        planes[C_N + k, near] = normals[near, k]
        planes[C_P + k, near] = origins[near, k] + t[near] * dirs[near, k]
    surface = pix_patch[near] - offset
    planes[C_OBJECT, near] = nurbs.surface_object[surface]
    planes[C_PATCH, near] = surface
    planes[C_LEVEL, near] = hits.level[near]
    if len(near):
        planes[C_U:C_U + 2, near] = hit_geometry(nurbs.model, hits.patch[near],
                                                 hits.st[near])[2].T


def blocked(nurbs: NurbsScene, origins, dirs, tmax, cone, tol_rad) -> np.ndarray:
    """(n,) bool: whether a free-form surface lies on each ray ``origins + s dirs`` before
    ``tmax``; ``cone`` (n,): each ray's width at its origin (its ray cone)."""
    hits = trace_rays(nurbs.model, nurbs.bvh, origins, dirs, tol_rad, cone=cone)
    return hits.t < tmax


@nb.njit(cache=True, nogil=True)
def _shade_hits(task, n_tasks, frame, width, pixels, t, level, surface, normals, uv,
                surface_object, planes):
    """Every channel but the colour of every n_tasks-th of ``pixels`` (hit k at pixel
    ``pixels[k]``) into ``planes``."""
    for k in range(task, len(pixels), n_tasks):
        r = pixels[k]
        row = r // width
        col = r - row * width
        dx, dy, dz = ray_setup(frame, row, col)
        nx, ny, nz = normals[k, 0], normals[k, 1], normals[k, 2]
        s = surface[k]
        planes[C_Z, r] = t[r]
        planes[C_P, r] = frame[0, 0] + t[r] * dx
        planes[C_P + 1, r] = frame[0, 1] + t[r] * dy
        planes[C_P + 2, r] = frame[0, 2] + t[r] * dz
        planes[C_N, r] = nx
        planes[C_N + 1, r] = ny
        planes[C_N + 2, r] = nz
        planes[C_U, r] = uv[k, 0]
        planes[C_U + 1, r] = uv[k, 1]
        planes[C_LEVEL, r] = level[r]
        planes[C_PATCH, r] = s
        planes[C_OBJECT, r] = surface_object[s]
        planes[C_A, r] = 1.0
