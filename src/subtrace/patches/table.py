"""The patch table: every face of the patch level L0 of every object, with its bounding shell.

A patch is a face of level ``L0`` (Catmull-Clark: level 1, where all faces are quads; Loop:
the cage). The renderer intersects regular patches through their Bezier nets, splits
irregular Catmull-Clark patches into pieces (:mod:`subtrace.patches.isolate`) and refines
Loop patches into grids of exact limit points (:mod:`subtrace.patches.grids`), on demand. Per patch, flat arrays (P = number of patches):

* ``object_id``, ``face`` (face of the object's L0 level), ``ptex`` with ``ptex_uv0`` (P,2)
  and ``ptex_scale``: patch parameter ``(s, t)`` is ptex ``uv0 + scale * (s, t)``;
* ``shell_min``/``shell_max`` (P,3): the axis-aligned box of the control points of the faces
  sharing a vertex with the patch. The limit surface over a face depends only on those
  points, with non-negative weights, so it lies in their convex hull and in this box
  (design invariant 2; Chaikin creases of sharpness in (1, 4/3) are the known exception and
  get ``config.SHELL_CHAIKIN_MARGIN``);
* ``edge_bound`` (P,): a bound on the length of the patch's iso-curves from its own and its
  neighbours' control edges (see ``_shells``), and ``rate`` (P,): how much
  control edges shrink per level near the patch's corners (1/2 for regular vertices, the
  subdominant eigenvalue near extraordinary ones); together they bound the size of a grid
  cell at depth n by ``edge_bound * rate^n`` (the refinement criterion);
* ``regular`` (P,) bool and ``nets`` (R,4,4,3): the Bezier nets of the regular bicubic
  patches (:mod:`subtrace.patches.bspline`), in patch order. For those, the shell is the
  net's box, ``edge_bound`` the exact bound on the derivatives and ``rate`` 1/2;
* ``edges`` (P,4) int64 (-1 pads triangles): global id of the L0 edge on each side (side k joins corners k, k+1),
  used to give both patches of an edge the same sampling.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from subtrace.runtime.jit import nb
import numpy as np

from subtrace import config
from subtrace.runtime.threads import run_tasks
from subtrace.patches.evaluate import ptex_layout
from subtrace.subdiv import catmark, loop
from subtrace.patches.bspline import _TO_BEZIER, _net_summary, _to_bezier, control_grids, regular_mask
from subtrace.patches.isolate import box_distance, isolated_depths

# ptex offset of the child at corner j of a regular face (quads keep the parent's orientation)
_QUAD_CHILD_UV0 = np.array([[0.0, 0.0], [0.5, 0.0], [0.5, 0.5], [0.0, 0.5]])


@dataclass(frozen=True, eq=False)
class ObjectPatches:
    """An object's patch level: topology, points, options (what grids are built from)."""

    cage: object
    level0: int
    level: object  # mesh.topology.Level of L0
    points: np.ndarray  # (V,3) float64 L0 points
    patch_faces: np.ndarray  # (p,) int64 faces of L0 that are patches (holes excluded)
    first_patch: int  # global id of this object's first patch
    first_edge: int  # global id of this object's first L0 edge


@dataclass(frozen=True, eq=False)
class PatchTable:
    objects: tuple  # ObjectPatches per object
    object_id: np.ndarray  # (P,) int32
    face: np.ndarray  # (P,) int64 face in the object's L0
    ptex: np.ndarray  # (P,) int32
    ptex_uv0: np.ndarray  # (P,2) float64
    ptex_scale: np.ndarray  # (P,) float64
    shell_min: np.ndarray  # (P,3) float64
    shell_max: np.ndarray  # (P,3) float64
    edge_bound: np.ndarray  # (P,) float64
    rate: np.ndarray  # (P,) float64
    regular: np.ndarray  # (P,) bool: a regular bicubic patch
    nets: np.ndarray  # (R,4,4,3) float64 Bezier nets of the regular patches, in patch order
    edges: np.ndarray  # (P,4) int64 global L0 edge ids (-1 pads a triangle's 4th side)
    is_quad: np.ndarray  # (P,) bool: Catmull-Clark quad (else Loop triangle)
    n_edges: int
    level0: np.ndarray  # (P,) int8: L0 of the patch's object
    material: np.ndarray  # (P,) int32 material of the base face (-1 none)

    @property
    def n_patches(self) -> int:
        return len(self.face)


def patch_level(cage) -> int:
    """L0: the first level where every face has the scheme's regular size."""
    return 1 if cage.scheme == "catmark" else 0


def build_patch_table(cages) -> PatchTable:
    """Patch table of several objects (Catmull-Clark and Loop cages may be mixed)."""
    objs, parts = [], []
    first_patch = first_edge = 0
    for oid, cage in enumerate(cages):
        L0 = patch_level(cage)
        lev = cage.level_topology(L0)
        pts = cage.refine(L0).points
        faces = np.nonzero(~lev.face_hole)[0].astype(np.int64)
        objs.append(ObjectPatches(cage, L0, lev, pts, faces, first_patch, first_edge))
        quad = cage.scheme == "catmark"
        parts.append(_object_arrays(cage, L0, lev, pts, faces, oid, first_edge, quad))
        first_patch += len(faces)
        first_edge += lev.n_edges
    if len(parts) == 1:
        cat = parts[0]  # already contiguous: no copy of the nets
    else:
        cat = {k: np.ascontiguousarray(np.concatenate([p[k] for p in parts])) for k in parts[0]}
    return PatchTable(objects=tuple(objs), n_edges=first_edge, **cat)


# regular patches converted to Bezier nets per call of _regular_shells' inner kernels: their
# B-spline points stay in cache
_NET_CHUNK = 64


def _object_arrays(cage, L0, lev, pts, faces, oid, first_edge, quad):
    k = 4 if quad else 3
    n = len(faces)
    # ptex mapping of each patch
    base, sub, first = ptex_layout(cage)
    if L0 == 1:
        # level-1 face c is the child of base face F at corner j, numbered by base corner
        fo = cage.base.face_offsets
        sizes = np.diff(fo)
        F = np.repeat(np.arange(len(sizes)), sizes)[faces]
        j = faces - fo[F]
        regular = sizes[F] == 4
        ptex = np.where(regular, first[F], first[F] + j).astype(np.int32)
        uv0 = _QUAD_CHILD_UV0.take(j % 4, axis=0)
        uv0[~regular] = 0.0
        scale = np.where(regular, 0.5, 1.0)
    else:
        F = faces
        ptex = first[faces].astype(np.int32)
        uv0 = np.zeros((n, 2))
        scale = np.ones(n)
    material = (
        np.full(n, -1, np.int32)
        if cage.face_material is None
        else np.asarray(cage.face_material, dtype=np.int32)[F]
    )
    smin = np.empty((n, 3))
    smax = np.empty((n, 3))
    ebound = np.empty(n)
    rate = np.empty(n)
    # regular quads: bicubic patches with a tight hull and an exact derivative bound
    regular = regular_mask(lev, cage.options, faces)
    rows = np.nonzero(regular)[0]
    nets = np.empty((len(rows), 4, 4, 3))
    run_tasks(_regular_shells, control_grids(lev, faces[rows]), pts, _TO_BEZIER, rows,
              _NET_CHUNK, nets, smin, smax, ebound)
    rate[rows] = 0.5
    # the others: boxes of their one-ring control points
    rows = np.nonzero(~regular)[0]
    lo, hi, bound, valence = one_ring_shells(lev, faces[rows], pts)
    if cage.options.chaikin and np.any(lev.edge_sharpness > 1.0):
        margin = config.SHELL_CHAIKIN_MARGIN * (hi - lo).max(axis=1, keepdims=True)
        lo -= margin
        hi += margin
    smin[rows], smax[rows], ebound[rows] = lo, hi, bound
    rate[rows] = _subdominant(valence, quad)
    # global ids of the sides' edges, a column at a time (-1 pads a triangle's 4th side)
    edges = np.empty((n, 4), dtype=np.int64)
    starts = lev.face_offsets[faces]
    for side in range(4):
        if side < k:
            np.add(lev.face_edges.take(starts + side), first_edge, out=edges[:, side])
        else:
            edges[:, side] = -1
    return dict(
        object_id=np.full(n, oid, np.int32),
        face=faces,
        ptex=ptex,
        ptex_uv0=uv0,
        ptex_scale=scale,
        shell_min=smin,
        shell_max=smax,
        edge_bound=ebound,
        rate=rate,
        regular=regular,
        nets=nets,
        edges=edges,
        is_quad=np.full(n, quad, dtype=bool),
        level0=np.full(n, L0, np.int8),
        material=material,
    )


@nb.njit(cache=True, nogil=True)
def _regular_shells(task, n_tasks, grids, pts, to_bezier, rows, chunk, nets, smin, smax,
                    ebound):
    """Bezier nets (R,4,4,3) of the regular patches from their control grids (R,4,4) of
    point ids, and each net's box and derivative bound written to patch rows ``rows``.

    The conversion and the bounds are bspline's own kernels, called on ``chunk`` patches at
    a time so that neither the B-spline points nor the nets make a pass through memory;
    task ``task`` of ``n_tasks`` (tasks.run_tasks) takes chunks task, task + n_tasks, ...
    """
    cv = np.empty((chunk, 4, 4, 3))
    lo = np.empty((chunk, 3))
    hi = np.empty((chunk, 3))
    bound = np.empty(chunk)
    for a in range(task * chunk, len(grids), n_tasks * chunk):
        m = min(chunk, len(grids) - a)
        # the chunk's B-spline control points
        for i in range(m):
            for u in range(4):
                for v in range(4):
                    p = grids[a + i, u, v]
                    cv[i, u, v, 0] = pts[p, 0]
                    cv[i, u, v, 1] = pts[p, 1]
                    cv[i, u, v, 2] = pts[p, 2]
        _to_bezier(cv[:m], to_bezier, nets[a : a + m])
        _net_summary(nets[a : a + m], lo[:m], hi[:m], bound[:m])
        # scattered to the patches' rows
        for i in range(m):
            r = rows[a + i]
            smin[r, 0], smin[r, 1], smin[r, 2] = lo[i, 0], lo[i, 1], lo[i, 2]
            smax[r, 0], smax[r, 1], smax[r, 2] = hi[i, 0], hi[i, 1], hi[i, 2]
            ebound[r] = bound[i]


def one_ring_shells(level, faces, pts):
    """(box min (n,3), box max (n,3), length bound (n,), largest corner valence (n,)) of the
    one-ring control points of ``faces`` of ``level`` at ``pts`` (see :func:`_shells`)."""
    lo = np.empty((len(faces), 3))
    hi = np.empty((len(faces), 3))
    bound = np.empty(len(faces))
    valence = np.empty(len(faces), dtype=np.int64)
    _shells(faces, level.face_offsets, level.face_verts, level.vert_face_offsets,
            level.vert_faces, pts, lo, hi, bound, valence)
    return lo, hi, bound, valence


@nb.njit(cache=True)
def _shells(faces, face_offsets, face_verts, vert_face_offsets, vert_faces, pts, smin, smax,
            ebound, valence):
    """Box of the one-ring faces' points, longest edge among them, largest corner valence."""
    for i in range(len(faces)):
        f = faces[i]
        lo0, lo1, lo2 = np.inf, np.inf, np.inf
        hi0, hi1, hi2 = -np.inf, -np.inf, -np.inf
        emax = 0.0
        vmax = 0
        # the patch's own edges
        own = 0.0
        n0 = face_offsets[f + 1] - face_offsets[f]
        for b in range(n0):
            p = face_verts[face_offsets[f] + b]
            q = face_verts[face_offsets[f] + (b + 1) % n0]
            dx, dy, dz = pts[q, 0] - pts[p, 0], pts[q, 1] - pts[p, 1], pts[q, 2] - pts[p, 2]
            own = max(own, math.sqrt(dx * dx + dy * dy + dz * dz))
        for c in range(face_offsets[f], face_offsets[f + 1]):
            v = face_verts[c]
            vmax = max(vmax, vert_face_offsets[v + 1] - vert_face_offsets[v])
            for a in range(vert_face_offsets[v], vert_face_offsets[v + 1]):
                g = vert_faces[a]
                g0 = face_offsets[g]
                ng = face_offsets[g + 1] - g0
                for b in range(ng):
                    p = face_verts[g0 + b]
                    q = face_verts[g0 + (b + 1) % ng]
                    x, y, z = pts[p, 0], pts[p, 1], pts[p, 2]
                    lo0, lo1, lo2 = min(lo0, x), min(lo1, y), min(lo2, z)
                    hi0, hi1, hi2 = max(hi0, x), max(hi1, y), max(hi2, z)
                    dx, dy, dz = pts[q, 0] - x, pts[q, 1] - y, pts[q, 2] - z
                    emax = max(emax, math.sqrt(dx * dx + dy * dy + dz * dz))
        smin[i, 0], smin[i, 1], smin[i, 2] = lo0, lo1, lo2
        smax[i, 0], smax[i, 1], smax[i, 2] = hi0, hi1, hi2
        # an iso-curve over the patch is a cubic B-spline whose control polygon blends the
        # patch's rows with weights >= 2/3 on its own two rows, and a B-spline span is no
        # longer than e0/6 + 2 e1/3 + e2/6 of its control edges: hence this length bound
        ebound[i] = (4.0 * own + 5.0 * emax) / 9.0
        valence[i] = vmax


def _subdominant(valence: np.ndarray, quad: bool) -> np.ndarray:
    """Per-level contraction of control edges at a vertex of this valence (at least 1/2)."""
    scheme = catmark if quad else loop
    return np.maximum(scheme.subdominant_eigenvalue(np.maximum(valence, 3)), 0.5)


def choose_depths(table: PatchTable, eye: np.ndarray, tol_rad: float, max_depth: int,
                  record=None, shells=None):
    """Grid depth of every patch: the smallest n with ``edge_bound * rate^n`` at most
    ``tol_rad`` times the distance from the eye to the patch's shell (capped); irregular
    quads needing more than depth 0 are then isolated (:mod:`subtrace.patches.isolate`).
    With a dict ``record``, ``record[object id]`` keeps what the isolation made (see
    :func:`~subtrace.patches.isolate.isolated_depths`). ``shells`` = (lo, hi), each (P,3),
    the shells to tighten: an isolated patch's shell becomes the box of what its isolation
    ended in (intersected with its own shell); the others' are left as they are."""
    d = box_distance(table.shell_min, table.shell_max, eye)
    allowed = d * tol_rad
    with np.errstate(divide="ignore", invalid="ignore"):
        n = np.log(allowed / table.edge_bound) / np.log(table.rate)
    n = np.where(allowed >= table.edge_bound, 0.0, np.ceil(n - 1e-9))
    n = np.where(np.isfinite(n), n, max_depth)
    depths = np.clip(n, 0, max_depth).astype(np.int32)
    for oid, o in enumerate(table.objects):
        if o.cage.scheme != "catmark":
            continue
        sel = np.nonzero((table.object_id == oid) & ~table.regular)[0]
        if record is None:
            sel = sel[depths[sel] > 0]
        if len(sel) and depths[sel].max() > 0:
            rec = record.setdefault(oid, {}) if record is not None else None
            boxes = None
            if shells is not None:
                boxes = (np.full((len(sel), 3), np.inf), np.full((len(sel), 3), -np.inf))
            depths[sel] = isolated_depths(o, table.face[sel], depths[sel], eye, tol_rad, rec,
                                          int(depths[sel].max()), boxes)
            if shells is not None:
                done = np.isfinite(boxes[0]).all(axis=1)
                at = sel[done]
                shells[0][at] = np.maximum(shells[0][at], boxes[0][done])
                shells[1][at] = np.minimum(shells[1][at], boxes[1][done])
    return depths


def memory_estimate(table, depths, n_pixels: int) -> int:
    """A conservative estimate (bytes) of a render's memory with grid depths ``depths``:
    the image's per-pixel buffers, the patch table, every Loop patch built as a grid at its
    depth and every irregular Catmull-Clark patch isolated to its depth, as if rays reached
    them all (the per-thread memos of split nets are kept within what is left:
    ``render._Memos``). The constants are ``config.MEMORY_*``."""
    loop = ~table.is_quad
    N = (1 << depths[loop].astype(np.int64)) if loop.any() else np.zeros(0, np.int64)
    grid_points = int(((N + 1) * (N + 2) // 2).sum())
    iso = table.is_quad & ~table.regular
    iso_levels = int((depths[iso].astype(np.int64) + 1).sum())
    return (config.MEMORY_BYTES_PER_PIXEL * int(n_pixels)
            + config.MEMORY_BYTES_PER_PATCH * table.n_patches
            + config.MEMORY_BYTES_PER_GRID_POINT * grid_points
            + config.MEMORY_BYTES_PER_ISOLATED_LEVEL * iso_levels)


def depth_cap(table, depths, n_pixels: int, budget: int):
    """The deepest grid depth ``cap`` at which ``np.minimum(depths, cap)`` fits ``budget``
    bytes (:func:`memory_estimate`), or None when ``depths`` fit as they are; -1 when
    nothing fits (not even depth 0)."""
    if memory_estimate(table, depths, n_pixels) <= budget:
        return None
    for cap in range(int(depths.max(initial=0)) - 1, -1, -1):
        if memory_estimate(table, np.minimum(depths, cap), n_pixels) <= budget:
            return cap
    return -1


def edge_sampling(table, depths):
    """Make both sides of every edge sample it alike (design invariant 4); raises ``depths``
    in place and returns ``(edge_depth, reg_side)``.

    * An irregular Catmull-Clark patch (built into pieces, ``patches/isolate.py``) is raised
      to the depth of every neighbour, repeatedly, so it is never coarser than a neighbour
      and equal to its irregular neighbours: its sides need no extra samples.
    * A regular patch (intersected directly) samples a side shared with a finer neighbour at
      the neighbour's depth (``reg_side`` (R,4)), fanning its cells there.
    * Loop grids snap a side to the coarsest depth on its edge (``edge_depth``, per edge).
    """
    n_e = max(table.n_edges, 1)
    iso = table.is_quad & ~table.regular
    nb_max = np.empty(table.edges.shape, dtype=np.int64)
    edge_depth = np.empty(n_e, dtype=np.int64)
    _sample_edges(table.edges, depths, iso, nb_max, edge_depth)
    reg_side = np.maximum(depths[table.regular][:, None], nb_max[table.regular])
    return edge_depth, np.ascontiguousarray(reg_side, dtype=np.int64)


@nb.njit(cache=True)
def _sample_edges(edges, depths, iso, nb_max, edge_depth):
    """Raise the ``iso`` patches to their neighbours' depths until none changes (in place);
    fill the deepest patch on each side's edge (``nb_max``) and the shallowest per edge."""
    best = np.full(len(edge_depth), -1, np.int64)
    for p in range(len(depths)):
        for k in range(4):
            e = edges[p, k]
            if e >= 0:
                best[e] = max(best[e], depths[p])
    changed = True
    while changed:
        changed = False
        for p in range(len(depths)):
            if not iso[p]:
                continue
            m = depths[p]
            for k in range(4):
                e = edges[p, k]
                if e >= 0:
                    m = max(m, best[e])
            if m > depths[p]:
                depths[p] = m
                changed = True
                for k in range(4):
                    e = edges[p, k]
                    if e >= 0:
                        best[e] = max(best[e], m)
    edge_depth[:] = np.iinfo(np.int32).max
    for p in range(len(depths)):
        for k in range(4):
            e = edges[p, k]
            nb_max[p, k] = best[e] if e >= 0 else -1
            if e >= 0:
                edge_depth[e] = min(edge_depth[e], depths[p])
