"""The control cage: positions, faces, tags and options, and its subdivision queries.

A :class:`Cage` is immutable. ``refine(level)`` gives a uniformly refined :class:`Mesh`,
``limit(level)`` the exact limit positions and tangents of the level's vertices, and
``evaluate(ptex_face, uv)`` the exact limit surface at parametric points (OpenSubdiv's ptex
numbering and orientation). Refined levels are cached per cage. A cage may carry UVs
(:class:`FaceVarying`: an OBJ's ``vt``, a USD mesh's ``primvars:st``), refined and evaluated
with OpenSubdiv's face-varying rules (``refine_uv``, ``evaluate_uv``); None without.

The topology of the cage itself (``base``, a :class:`~subtrace.subdiv.topology.Level` with
its tags) is built when first asked for, not when the cage is read: a render that sees part
of a large cage builds it only for :meth:`Cage.restricted`, the faces around those in view
(``render.table_in_view``), so its memory and time follow what is seen. The limit surface
over a face depends on the faces that share a vertex with it and on their tags alone, so
a restriction that keeps enough rings of faces around the faces it is for
(:func:`face_rings`) gives them exactly the whole cage's surface.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from subtrace import config
from subtrace.errors import TopologyError
from subtrace.io.obj import read_obj
from subtrace.patches.evaluate import evaluate, evaluate_uv, ptex_starts
from subtrace.patches.shells import box_extent, face_star_boxes
from subtrace.runtime.jit import nb
from subtrace.subdiv.facevarying import FVAR_ALL, FVAR_NAMES, channel_levels
from subtrace.subdiv.limit import least_limit_height, limit_points
from subtrace.subdiv.refine import refine_level, refine_points
# (the restricted cages' rings, which callers take from here too)
from subtrace.subdiv.topology import (  # noqa: F401
    BOUNDARY_EDGE_ONLY,
    RESTRICT_RINGS,
    Level,
    Options,
    cage_level,
    face_rings,
)

SCHEME_ALIASES = {
    "catmark": "catmark",
    "catmull-clark": "catmark",
    "catmullclark": "catmark",
    "catmull_clark": "catmark",
    "cc": "catmark",
    "loop": "loop",
}


@dataclass(frozen=True, eq=False)
class Mesh:
    """A uniformly refined mesh: points (n,3) float64, faces as sizes + flat 0-based indices."""

    points: np.ndarray
    face_sizes: np.ndarray
    face_verts: np.ndarray
    face_hole: np.ndarray
    level: int

    @property
    def n_faces(self) -> int:
        return len(self.face_sizes)


@dataclass(frozen=True, eq=False)
class Tags:
    """A cage's tags as given (OpenSubdiv's OBJ tags): creases as vertex pairs (k,2) int64
    with their sharpness (k,) float32, corners (m,) int64 with theirs (m,) float32, and the
    hole faces (h,) int64. :func:`~subtrace.subdiv.topology.tag_base_level` applies them."""

    crease_edges: np.ndarray
    crease_sharpness: np.ndarray
    corner_verts: np.ndarray
    corner_sharpness: np.ndarray
    hole_faces: np.ndarray

    @classmethod
    def of(cls, crease_edges=(), crease_sharpness=(), corner_verts=(), corner_sharpness=(),
           hole_faces=()):
        return cls(np.asarray(crease_edges, dtype=np.int64).reshape(-1, 2),
                   np.asarray(crease_sharpness, dtype=np.float32).ravel(),
                   np.asarray(corner_verts, dtype=np.int64).ravel(),
                   np.asarray(corner_sharpness, dtype=np.float32).ravel(),
                   np.asarray(hole_faces, dtype=np.int64).ravel())


@dataclass(frozen=True, eq=False)
class FaceVarying:
    """A cage's UVs: ``values`` (T,2) float64, the value index of each face corner
    ``face_values`` (sum of face sizes,) int32 (aligned with the cage's ``face_verts``), and
    OpenSubdiv's face-varying linear-interpolation mode ``mode`` (``subdiv.facevarying``:
    0 none, 1 corners only, 2 corners plus1, 3 corners plus2, 4 boundaries, 5 all; the
    default is Sdc::Options' and OpenSubdiv's OBJ loaders', all)."""

    values: np.ndarray
    face_values: np.ndarray
    mode: int = FVAR_ALL

    @property
    def mode_name(self) -> str:
        return FVAR_NAMES[self.mode]


@dataclass(frozen=True, eq=False)
class Cage:
    """A control cage ready for subdivision (build it with :func:`subtrace.load_cage`).

    ``ptex_first``: None, or for a :meth:`restricted` cage the ptex id each of its faces has
    in the cage it was cut from (so its patches keep the whole cage's ids). ``uv``: its
    :class:`FaceVarying` UVs, or None."""

    points: np.ndarray  # (n,3) float64
    face_sizes: np.ndarray  # (F,) int32
    face_verts: np.ndarray  # (sum,) int32
    options: Options
    tags: Tags
    path: str | None = None
    face_material: np.ndarray | None = None
    materials: tuple = ()
    ptex_first: np.ndarray | None = None
    uv: FaceVarying | None = None
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def scheme(self) -> str:
        return self.options.scheme

    @property
    def base(self) -> Level:
        """The cage's own topology and tags, built on first use (module comment)."""
        level = self._cache.get("base")
        if level is None:
            level = self._cache["base"] = _base_level(self)
        return level

    @property
    def face_offsets(self) -> np.ndarray:
        """(F+1,) int64: where each face's corners start in ``face_verts`` (the face lists'
        offsets, as the topology's; made once, without it)."""
        offsets = self._cache.get("face_offsets")
        if offsets is None:
            offsets = self._cache["face_offsets"] = np.zeros(self.n_faces + 1, np.int64)
            np.cumsum(self.face_sizes, out=offsets[1:])
        return offsets

    @property
    def points_box(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo (3,), hi (3,)): the box of the control points (which holds the limit
        surface), made once (the cull and the coordinate check ask for it on every render;
        two reductions of the sword refined twice's points took 13 ms)."""
        box = self._cache.get("points_box")
        if box is None:
            box = self._cache["points_box"] = _points_box(self.points)
        return box

    @property
    def star_boxes(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo (F,3), hi (F,3)), read-only: per face, the box of the points of the faces
        around its corners (its one-ring's points: a box that holds its limit surface), from
        the face lists alone (``patches.shells.face_star_boxes``). Within
        :meth:`sharing_star_boxes` they are made once (the cull and the ground's height
        both ask on a large cage: 13 ms each on the sword refined twice)."""
        boxes = self._cache.get("star_boxes")
        if boxes is None:
            boxes = face_star_boxes(self.face_offsets, self.face_verts, self.points)
            for b in boxes:
                b.flags.writeable = False  # (shared: a caller widening them must copy)
            if "sharing" in self._cache:
                self._cache["star_boxes"] = boxes
        return boxes

    @contextlib.contextmanager
    def sharing_star_boxes(self):
        """Keep :attr:`star_boxes` once made, until the block ends (48 bytes a face)."""
        self._cache["sharing"] = True
        try:
            yield self
        finally:
            self._cache.pop("sharing", None)
            self._cache.pop("star_boxes", None)

    @property
    def has_topology(self) -> bool:
        """Whether :attr:`base` has been built."""
        return "base" in self._cache

    def restricted(self, faces: np.ndarray) -> Cage:
        """The cage of the faces ``faces`` ((F,) bool) alone, in their order, with the
        vertices they use (renumbered in order), the tags among those, their materials and
        their ptex ids in this cage (``ptex_first``, which the patch table reads; its own
        :meth:`evaluate` numbers its ptex faces afresh). Its faces that keep every face
        around their vertices (:func:`face_rings`) have this cage's limit surface."""
        faces = np.asarray(faces, dtype=bool)
        corners = np.repeat(faces, self.face_sizes)
        used = np.zeros(len(self.points), bool)
        used[self.face_verts[corners]] = True
        new_vert = np.cumsum(used, dtype=np.int64) - 1
        t = self.tags
        # (a crease naming a vertex the cage does not have names no edge: ignored, as
        # tag_base_level ignores it)
        ce = t.crease_edges
        both = ((ce >= 0) & (ce < len(used))).all(axis=1)
        both[both] = used[ce[both]].all(axis=1)
        corner_kept = used[t.corner_verts]
        new_face = np.cumsum(faces, dtype=np.int64) - 1
        hole_kept = faces[t.hole_faces]
        first = ptex_starts(self)[:-1] if self.ptex_first is None else self.ptex_first
        return Cage(
            points=self.points[used],
            face_sizes=self.face_sizes[faces],
            face_verts=new_vert[self.face_verts[corners]].astype(np.int32),
            options=self.options,
            tags=Tags(new_vert[t.crease_edges[both]], t.crease_sharpness[both],
                      new_vert[t.corner_verts[corner_kept]], t.corner_sharpness[corner_kept],
                      new_face[t.hole_faces[hole_kept]]),
            path=self.path,
            face_material=None if self.face_material is None else
            np.asarray(self.face_material)[faces],
            materials=self.materials,
            ptex_first=first[faces],
            uv=None if self.uv is None else replace(self.uv,
                                                    face_values=self.uv.face_values[corners]),
        )

    @property
    def n_faces(self) -> int:
        return len(self.face_sizes)

    @property
    def face_hole(self) -> np.ndarray:
        return self.base.face_hole

    # ----------------------------------------------------------------------------------
    # uniform refinement
    # ----------------------------------------------------------------------------------

    def _levels(self, level: int):
        """[(Level, points)] for levels 0..level, computed once and cached."""
        levels = self._cache.setdefault("levels", [(self.base, self.points, None)])
        while len(levels) <= level:
            lev, pts, _ = levels[-1]
            ref = refine_level(lev, self.options)
            levels.append((ref.child, refine_points(ref, pts), ref))
        return levels

    def refine(self, level: int) -> Mesh:
        """Uniform refinement to ``level`` (0 is the cage itself)."""
        level = _check_level(level)
        lev, pts, _ = self._levels(level)[level]
        return Mesh(
            points=pts,
            face_sizes=lev.face_sizes,
            face_verts=lev.face_verts,
            face_hole=lev.face_hole,
            level=level,
        )

    def level_topology(self, level: int) -> Level:
        return self._levels(_check_level(level))[level][0]

    # ----------------------------------------------------------------------------------
    # limit surface
    # ----------------------------------------------------------------------------------

    def limit(self, level: int = 0):
        """Exact limit positions and tangents of the level-``level`` vertices.

        Returns ``(P, du, dv)``, each (n,3) float64 in the order of ``refine(level).points``.
        Tangents follow OpenSubdiv's limit-mask convention (du along the first edge of the
        vertex's counter-clockwise ring; ``du x dv`` is the outward normal); only their
        directions are meaningful at extraordinary vertices.
        """
        level = _check_level(level)
        lev, pts, _ = self._levels(level)[level]
        return limit_points(lev, pts, self.options)

    def evaluate(self, ptex_face, uv):
        """Limit position and first derivatives at parametric points.

        ``ptex_face`` (m,) int, ``uv`` (m,2) float in OpenSubdiv's ptex convention. Returns
        ``(P, dPdu, dPdv)`` each (m,3) float64, derivatives with respect to the ptex (u,v).
        """
        return evaluate(self, ptex_face, uv)

    def evaluate_uv(self, ptex_face, uv):
        """Limit UVs at parametric points: ``ptex_face`` (m,) int, ``uv`` (m,2) float as for
        :meth:`evaluate`. Returns (m,2) float64 (NaN on holes), with OpenSubdiv's
        face-varying rules for the cage's mode (``uv.mode``); ValueError without UVs."""
        return evaluate_uv(self, ptex_face, uv)

    def refine_uv(self, level: int):
        """UVs of uniform refinement to ``level``: ``(values (n,2) float64, face_values
        (corners of the level,) int64)``, the value of each face corner of
        ``refine(level)`` (OpenSubdiv's InterpolateFaceVarying); ValueError without UVs."""
        level = _check_level(level)
        if self.uv is None:
            raise ValueError("refine_uv: the cage has no UVs (an OBJ file's vt on every "
                             "face corner, a USD mesh's primvars:st)")
        ch, values = channel_levels(self.base, self.uv.face_values, self.uv.values,
                                    self.uv.mode, self.options, level)[level]
        return values, ch.level.face_verts.astype(np.int64)

    # ----------------------------------------------------------------------------------

    def bounds(self):
        """Axis-aligned bounds of the limit surface (the cage's hull bounds it too)."""
        P, _, _ = self.limit(1 if self.n_faces < 200000 else 0)
        return P.min(axis=0), P.max(axis=0)


def _check_level(level) -> int:
    if isinstance(level, bool) or not isinstance(level, (int, np.integer)) or level < 0:
        raise ValueError(f"level must be a non-negative integer, got {level!r}")
    return int(level)


def make_cage(
    points,
    face_sizes,
    face_verts,
    scheme: str | None = None,
    *,
    boundary: int | None = None,
    chaikin: bool = False,
    smooth_triangles: bool = False,
    crease_edges=(),
    crease_sharpness=(),
    corner_verts=(),
    corner_sharpness=(),
    hole_faces=(),
    path=None,
    face_material=None,
    materials=(),
    uvs=None,
    face_uvs=None,
    uv_mode: int | None = None,
) -> Cage:
    """Build a :class:`Cage` from arrays (what :func:`subtrace.load_cage` does after parsing).

    ``uvs`` (T,2) and ``face_uvs`` (one index into ``uvs`` per corner, aligned with
    ``face_verts``) give the cage UVs (:class:`FaceVarying`), ``uv_mode`` their
    face-varying interpolation (default all, as :class:`FaceVarying`'s)."""
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    face_sizes = np.ascontiguousarray(face_sizes, dtype=np.int32)
    face_verts = np.ascontiguousarray(face_verts, dtype=np.int32)
    where = f"{path}: " if path else ""
    if len(face_sizes) == 0:
        raise TopologyError("empty", f"{where}the cage has no faces")
    if np.any(face_sizes < 3):
        raise TopologyError("face", f"{where}a face has fewer than 3 vertices")
    if face_sizes.sum() != len(face_verts):
        raise TopologyError("face", f"{where}face sizes do not match the face index list")
    if len(face_verts) and (face_verts.min() < 0 or face_verts.max() >= len(points)):
        raise TopologyError("index", f"{where}a face index is out of range")
    if not np.all(np.isfinite(points)):
        raise TopologyError("points", f"{where}a vertex coordinate is not finite")
    all_tris = bool(np.all(face_sizes == 3))
    if scheme is None:
        scheme = "loop" if all_tris else "catmark"
    key = str(scheme).strip().lower()
    if key not in SCHEME_ALIASES:
        raise TopologyError(
            "scheme", f"{where}unknown scheme {scheme!r}: use 'catmark' (Catmull-Clark) or 'loop'"
        )
    scheme = SCHEME_ALIASES[key]
    if scheme == "loop" and not all_tris:
        bad = int(np.nonzero(face_sizes != 3)[0][0])
        raise TopologyError(
            "scheme",
            f"{where}the Loop scheme needs an all-triangle cage, but face {bad} has "
            f"{int(face_sizes[bad])} vertices (use scheme 'catmark')",
        )
    uv = _face_varying(uvs, face_uvs, uv_mode, len(face_verts), where)
    options = Options(
        scheme=scheme,
        boundary=BOUNDARY_EDGE_ONLY if boundary is None else int(boundary),
        chaikin=bool(chaikin),
        smooth_triangles=bool(smooth_triangles),
    )
    return Cage(
        points=points,
        face_sizes=face_sizes,
        face_verts=face_verts,
        options=options,
        tags=Tags.of(crease_edges, crease_sharpness, corner_verts, corner_sharpness,
                     hole_faces),
        path=None if path is None else str(path),
        face_material=face_material,
        materials=tuple(materials),
        uv=uv,
    )


def _face_varying(uvs, face_uvs, mode, n_corners, where) -> FaceVarying | None:
    """The :class:`FaceVarying` of :func:`make_cage`'s arguments (None without ``uvs``)."""
    if uvs is None and face_uvs is None:
        return None
    if uvs is None or face_uvs is None:
        raise TopologyError("uv", f"{where}UVs need both the values and a value per corner")
    values = np.ascontiguousarray(uvs, dtype=np.float64)
    if values.ndim != 2 or values.shape[1] != 2:
        raise TopologyError("uv", f"{where}UVs must be (T, 2) values, got shape {values.shape}")
    index = np.ascontiguousarray(face_uvs, dtype=np.int64)
    if index.shape != (n_corners,):
        raise TopologyError("uv", f"{where}{len(index)} UV indices for {n_corners} face "
                                  "corners: give one per corner")
    if len(index) and (index.min() < 0 or index.max() >= len(values)):
        bad = int(index[(index < 0) | (index >= len(values))][0])
        raise TopologyError("uv", f"{where}UV index {bad} is out of range: there are "
                                  f"{len(values)} UVs")
    if not np.all(np.isfinite(values)):
        raise TopologyError("uv", f"{where}a UV coordinate is not finite")
    mode = FVAR_ALL if mode is None else mode
    if isinstance(mode, bool) or not isinstance(mode, (int, np.integer)) or not 0 <= mode <= 5:
        raise TopologyError("uv", f"{where}unknown face-varying interpolation {mode!r}: use 0 "
                                  "(none) .. 5 (all)")
    return FaceVarying(values, index.astype(np.int32), int(mode))


def _base_level(cage: Cage) -> Level:
    """The topology of ``cage``'s faces with its tags applied."""
    t = cage.tags
    return cage_level(len(cage.points), cage.face_offsets, cage.face_verts, cage.options,
                      (t.crease_edges, t.crease_sharpness, t.corner_verts, t.corner_sharpness,
                       t.hole_faces))


# points from which the box is one pass of a kernel: NumPy's reductions along the first
# axis of an (n, 3) array take 7 ms each on 400,000 points
BOX_KERNEL_POINTS = 50_000


def _points_box(points) -> tuple[np.ndarray, np.ndarray]:
    """(lo (3,), hi (3,)) of ``points`` (n,3), as ``points.min(axis=0)``, ``.max(axis=0)``
    (NaN where a coordinate is; zeros for no points)."""
    if not len(points):
        return np.zeros(3), np.zeros(3)
    if len(points) < BOX_KERNEL_POINTS:
        return points.min(axis=0), points.max(axis=0)
    lo, hi = np.empty(3), np.empty(3)
    if _box_kernel(np.ascontiguousarray(points, dtype=np.float64), lo, hi):
        return points.min(axis=0), points.max(axis=0)  # (a NaN: NumPy's answer)
    return lo, hi


@nb.njit(cache=True, nogil=True)
def _box_kernel(points, lo, hi):
    """The box of ``points`` into ``lo``, ``hi``; True when a coordinate is NaN."""
    lo[:] = np.inf
    hi[:] = -np.inf
    nan = False
    for i in range(points.shape[0]):
        for k in range(3):
            x = points[i, k]
            lo[k] = min(lo[k], x)
            hi[k] = max(hi[k], x)
            nan |= x != x
    return nan


def lowest_limit(cage: Cage, up) -> float:
    """The least ``P . up`` over the limit points of ``cage``'s level-1 vertices:
    ``(cage.limit(1)[0] @ up).min()`` to rounding, made from the faces that can hold it
    alone on a large cage (at least ``config.LAZY_TOPOLOGY_FACES`` faces), and the limits
    that take repeated refinement only of the vertices that can lie lower than the others
    (``subdiv.limit.least_limit_height``: chess's flat-bottomed pieces, 0.13 -> 0.01 s).

    Every level-1 vertex lies on a face whose one-ring box holds its limit point (a convex
    combination of that ring's points), and each face's surface reaches no higher than the
    top of its box, so the least point is on a face whose box's bottom is below the lowest
    box top. Those faces, with ``RESTRICT_RINGS`` rings around them, are cut out
    (:meth:`Cage.restricted`) and refined: their own level-1 limit points are the whole
    cage's, and the cut's other points, whatever the cut's boundary makes of them, are
    still combinations of points above that lowest top. Chaikin creases (which may leave
    the box) and the smooth triangle rule take the whole cage."""
    up = np.asarray(up, np.float64)
    key = ("lowest", up.tobytes())  # (the cull and the picture both ask)
    if key not in cage._cache:
        cage._cache[key] = _lowest_limit(cage, up)
    return cage._cache[key]


def _lowest_limit(cage: Cage, up: np.ndarray) -> float:
    if cage.options.chaikin or cage.options.smooth_triangles:
        return float((cage.limit(1)[0] @ up).min())
    if cage.n_faces < config.LAZY_TOPOLOGY_FACES:
        return _least_level1_height(cage, up)
    # each face's range of heights from its star box (exact for an axis as ``up``, else
    # wider, which only keeps more faces)
    bottom, top = box_extent(up[None], *cage.star_boxes)
    bottom, top = bottom[:, 0], top[:, 0].min()
    # (a margin for the rounding of the limit masks' sums: far above it, far below a cell)
    top += 1e-9 * (np.abs(cage.points @ up).max() + 1.0)
    near = face_rings(cage, bottom <= top, RESTRICT_RINGS)
    return _least_level1_height(cage.restricted(near), up)


def _least_level1_height(cage: Cage, up: np.ndarray) -> float:
    """``subdiv.limit.least_limit_height`` of ``cage``'s level-1 vertices."""
    lev, pts, _ = cage._levels(1)[1]
    return least_limit_height(lev, pts, cage.options, up)


def without_unused_vertices(cage: Cage) -> Cage:
    """``cage`` without the vertices no face uses (``v`` lines of an OBJ file that no face
    names): :meth:`Cage.restricted` to all its faces, so the surface, the tags on used
    vertices and the ptex ids are the same; ``cage`` itself when every vertex is used. An
    unused vertex is no part of the limit surface, but its level-1 point is among the
    limit points that frame the automatic camera and set the ground's height."""
    used = np.zeros(len(cage.points), bool)
    used[cage.face_verts] = True
    if used.all():
        return cage
    return cage.restricted(np.ones(cage.n_faces, bool))


def placed(cage: Cage, matrix, shared: bool = False) -> Cage:
    """``cage`` with its points mapped by the 4x4 affine ``matrix`` (``io.placement``; None:
    ``cage`` itself): the same faces, tags and materials, so its limit surface is the
    cage's own, mapped (subdivision commutes with affine maps). Its topology, built or
    not, is shared. ``shared``: ``cage`` is placed more than once (copies of one file in a
    scene): its topology is built now, once, for every copy (a cage of
    ``config.LAZY_TOPOLOGY_FACES`` faces or more keeps it unbuilt: the render cuts such a
    cage to the faces in view first), and a copy without a matrix is a cage of its own
    (its caches its own) over the same arrays."""
    if shared and cage.n_faces < config.LAZY_TOPOLOGY_FACES:
        cage.base  # noqa: B018 (built once, for every copy)
    if matrix is None:
        if not shared:
            return cage
        return replace(cage, _cache={k: v for k, v in cage._cache.items() if k == "base"})
    from subtrace.io.placement import place

    keep = {k: v for k, v in cage._cache.items() if k == "base"}
    return replace(cage, points=place(cage.points, matrix), _cache=keep)


def valence_bound(cage: Cage) -> np.ndarray:
    """(n,) int64: each vertex's valence (its edges) where the topology is built, else an
    upper bound from the face lists alone: two edges for each face at the vertex."""
    if cage.has_topology:
        return np.diff(cage.base.vert_edge_offsets)
    return 2 * np.bincount(cage.face_verts, minlength=len(cage.points))


def load_cage(path, scheme: str | None = None, boundary: int | None = None,
              prim: str | None = None, time: float | None = None) -> Cage:
    """Read an OBJ control cage (with OpenSubdiv ``t`` tags), a mesh of a USD stage
    (``subtrace.io.usd``: the mesh ``prim``, or all its meshes as one), or a PLY, STL, OFF or
    glTF mesh (``subtrace.io.meshes``), and prepare it for subdivision. ``boundary`` (0
    none, 1 edge-and-corner, 2 edge-only) overrides the file's ``interpolateboundary`` tag
    or attribute; ``time``: a USD stage's time code (None:
    its still)."""
    from subtrace.io.meshes import is_mesh_file
    from subtrace.io.usd import is_usd

    if is_mesh_file(path):
        from subtrace.io.meshes import read_mesh

        points, sizes, verts = read_mesh(path)
        return make_cage(points, sizes, verts, scheme, boundary=boundary, path=Path(path))
    if is_usd(path):
        from subtrace.io.usd import combined_mesh, read_stage

        arrays = combined_mesh(read_stage(path, time), prim).cage_arrays()
        if scheme is not None:
            arrays["scheme"] = scheme
        if boundary is not None:
            arrays["boundary"] = boundary
        return make_cage(path=Path(path), **arrays)
    return cage_from_obj(read_obj(path), scheme, boundary)


def cage_from_obj(data, scheme: str | None = None, boundary: int | None = None) -> Cage:
    """The :class:`Cage` of an OBJ file already read (:func:`subtrace.io.obj.read_obj`);
    ``scheme`` / ``boundary`` as :func:`load_cage` takes them. Its UVs are the ``vt`` of the
    corners where every corner names one (else it has none), their mode the
    ``facevaryinginterpolateboundary`` tag's (without one all, as OpenSubdiv's loaders)."""
    with_uvs = len(data.face_uvs) > 0 and bool((data.face_uvs >= 0).all())
    return make_cage(
        data.points,
        data.face_sizes,
        data.face_verts,
        scheme,
        boundary=data.boundary if boundary is None else boundary,
        chaikin=data.crease_method == "chaikin",
        smooth_triangles=data.smooth_triangles == "smooth",
        crease_edges=data.crease_edges,
        crease_sharpness=data.crease_sharpness,
        corner_verts=data.corner_verts,
        corner_sharpness=data.corner_sharpness,
        hole_faces=data.hole_faces,
        path=Path(data.path),
        face_material=data.face_material,
        materials=data.materials,
        uvs=data.uvs if with_uvs else None,
        face_uvs=data.face_uvs if with_uvs else None,
        uv_mode=data.fvar_interpolation,
    )
