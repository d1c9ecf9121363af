"""The patch table: the faces of the patch level L0 of every object, with their bounding shells.

Only the patches of the cage faces asked for are made (``build_patch_table(cages, keep)``:
the renderer keeps the faces whose one-ring box reaches the image, ``render.faces_in_view``):
only they and three rings of faces around them are refined to L0.

A patch is a face of level ``L0`` (Catmull-Clark: level 1, where all faces are quads; Loop:
the cage), or, on a Catmull-Clark cage, a regular quad of the cage itself
(:func:`regular_cage_quads`: one bicubic patch where level 1 would make four, as
OpenSubdiv's adaptive tables do; only the cage's other faces and the rings around them are
refined to level 1). The renderer intersects regular patches through their Bezier nets,
splits irregular Catmull-Clark patches into pieces (:mod:`subtrace.patches.isolate`) and
refines Loop patches into grids of exact limit points (:mod:`subtrace.patches.grids`), on
demand. Per patch, flat arrays (P = number of patches):

* ``object_id``, ``face`` (face of the object's L0 level, or of the cage for a cage quad),
  ``ptex`` with ``ptex_uv0`` (P,2) and ``ptex_scale``: patch parameter ``(s, t)`` is ptex
  ``uv0 + scale * (s, t)``;
* ``shell_min``/``shell_max`` (P,3): the axis-aligned box of the control points of the faces
  sharing a vertex with the patch. The limit surface over a face depends only on those
  points, with non-negative weights, so it lies in their convex hull and in this box
  (design invariant 2; Chaikin creases of sharpness in (1, 4/3) are the known exception and
  get ``config.SHELL_CHAIKIN_MARGIN``);
* ``ray_min``/``ray_max`` (P,3): the boxes the rays find the patches by (the image tiles'
  and the BVH's, :mod:`subtrace.trace.budget`): the shells, but for a Loop triangle the
  part of its shell in the union of its four children's one-ring boxes one level down
  (the triangle's surface is theirs, so it lies there too; the renderer also cuts a regular
  one's to its quartic net's box, ``trace.build.cut_to_loop_nets``). A Loop cage's patches are its
  own triangles, whose one-rings reach a whole ring of neighbours out: on a coarse cage
  (an icosahedron, a lathe's rings) a ray entered a dozen of them for the one it hits.
  The depths still take their distances from the shells (``patches/criterion.py``);
* ``edge_bound`` (P,): a bound on the length of the patch's iso-curves from its own and its
  neighbours' control edges (see :mod:`subtrace.patches.shells`), and ``rate`` (P,): how much
  control edges shrink per level near the patch's corners (1/2 for regular vertices, the
  subdominant eigenvalue near extraordinary ones); together they bound the size of a grid
  cell at depth n by ``edge_bound * rate^n`` (the refinement criterion);
* ``patch_type`` (P,) int8, one code per patch (:class:`Patch`: a regular
  bicubic quad, another Catmull-Clark quad, a Loop triangle; ``regular`` and ``is_quad``
  are its views), and ``nets`` (R,4,4,3): the Bezier nets of the regular bicubic
  patches, smooth or along boundaries and infinitely sharp creases (phantom points; see
  :mod:`subtrace.patches.bspline`, :mod:`subtrace.patches.basis`), in patch order. For
  those, the shell is the net's box, ``edge_bound`` the exact bound on the derivatives and
  ``rate`` 1/2. The nets are the first rows of a larger store (``nets.base``,
  :func:`net_room`) that the renderer's pieces take over instead of copying them
  (``trace.pools.Growable.adopt``);
* ``edges`` (P,4) int64 (-1 pads triangles): global id of the edge on each side (side k
  joins corners k, k+1), used to give both patches of an edge the same sampling: the
  patch level's edge, or the cage's edge for the sides of cage quad patches and for the
  level-1 sides that lie on one of their edges (``side_shift`` (P,4) int8 is then 1 for
  the level-1 side: it samples half of the cage edge, ``criterion.edge_sampling``).
"""

from __future__ import annotations

import enum
import hashlib
from dataclasses import dataclass, field

import numpy as np

from subtrace import config
from subtrace.patches.basis import NET_CHUNK, TO_BEZIER, bspline_nets
from subtrace.patches.bspline import phantom_grids, regular_mask
from subtrace.patches.criterion import subdominant
from subtrace.patches.evaluate import ptex_starts
from subtrace.patches.shells import face_ring_boxes, one_ring_shells, split_ring_boxes
from subtrace.runtime.jit import nb
from subtrace.runtime.threads import run_tasks
from subtrace.subdiv.limit import extract
from subtrace.subdiv.refine import refine_level, refine_points
from subtrace.subdiv.topology import (RESTRICT_RINGS, compact, face_rings, gather,
                                      gather_index)

# ptex offset of the child at corner j of a regular face (quads keep the parent's orientation)
_QUAD_CHILD_UV0 = np.array([[0.0, 0.0], [0.5, 0.0], [0.5, 0.5], [0.0, 0.5]])


class Patch(enum.IntEnum):
    """The patch types of the table's ``patch_type`` column (one code per patch; the item
    kinds a ray meets inside a patch are ``geometry.kinds.Item``):

    * ``CATMARK_REGULAR``: a regular bicubic Catmull-Clark patch (one Bezier net, the table's);
    * ``CATMARK_IRREGULAR``: any other Catmull-Clark quad of the patch level (isolated into
      pieces and cells when a ray first asks for it);
    * ``LOOP``: a Loop triangle (a regular one becomes one triangular net, the others are
      isolated, both when the trace starts or a ray asks: ``patches.boxspline.loop_regular``).
    """

    CATMARK_REGULAR = 0
    CATMARK_IRREGULAR = 1
    LOOP = 2


CATMARK_REGULAR = int(Patch.CATMARK_REGULAR)
CATMARK_IRREGULAR = int(Patch.CATMARK_IRREGULAR)
LOOP = int(Patch.LOOP)


def patch_types(quad: bool, regular) -> np.ndarray:
    """(n,) int8 patch types of an object's patches: Loop triangles, or Catmull-Clark quads
    regular where ``regular`` (n,) bool says."""
    regular = np.asarray(regular, dtype=bool)
    if not quad:
        return np.full(len(regular), LOOP, np.int8)
    return np.where(regular, CATMARK_REGULAR, CATMARK_IRREGULAR).astype(np.int8)


@dataclass(frozen=True, eq=False)
class ObjectPatches:
    """An object's patch level: topology, points, options (what grids are built from)."""

    cage: object
    level0: int
    level: object  # subdiv.topology.Level of L0
    points: np.ndarray  # (V,3) float64 L0 points
    patch_faces: np.ndarray  # (p,) int64 faces of L0 that are patches (holes excluded)
    first_patch: int  # global id of this object's first patch
    first_edge: int  # global id of this object's first L0 edge
    # (Catmull-Clark) the regular quads of the cage that are patches themselves
    # (:func:`regular_cage_quads`), after those of ``patch_faces``: ``level0`` 0, ``face``
    # a face of the cage
    cage_quads: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    @property
    def n_patches(self) -> int:
        return len(self.patch_faces) + len(self.cage_quads)

    def parts(self):
        """The object's patches by level: [(level, points, slice of the table's patches,
        their faces in that level)], the patch level's first, then the cage quads'."""
        n = len(self.patch_faces)
        out = [(self.level, self.points, slice(self.first_patch, self.first_patch + n),
                self.patch_faces)]
        if len(self.cage_quads):
            out.append((self.cage.base, self.cage.points,
                        slice(self.first_patch + n, self.first_patch + self.n_patches),
                        self.cage_quads))
        return out


@dataclass(frozen=True, eq=False)
class PatchTable:
    objects: tuple  # ObjectPatches per object
    object_id: np.ndarray  # (P,) int32
    face: np.ndarray  # (P,) int64 face in the object's L0 (a cage quad patch's: of the cage)
    ptex: np.ndarray  # (P,) int32
    ptex_uv0: np.ndarray  # (P,2) float64
    ptex_scale: np.ndarray  # (P,) float64
    shell_min: np.ndarray  # (P,3) float64
    shell_max: np.ndarray  # (P,3) float64
    ray_min: np.ndarray  # (P,3) float64: the shells the rays walk (see the module doc)
    ray_max: np.ndarray  # (P,3) float64
    edge_bound: np.ndarray  # (P,) float64
    rate: np.ndarray  # (P,) float64
    patch_type: np.ndarray  # (P,) int8: Patch (regular, irregular quad, Loop)
    nets: np.ndarray  # (R,4,4,3) float64 Bezier nets of the regular patches, in patch order
    edges: np.ndarray  # (P,4) int64 global edge ids (-1 pads a triangle's 4th side)
    side_shift: np.ndarray  # (P,4) int8: the patch's level less its side's edge's level
    n_edges: int
    level0: np.ndarray  # (P,) int8: L0 of the patch's object
    material: np.ndarray  # (P,) int32 material of the base face (-1 none)

    @property
    def n_patches(self) -> int:
        return len(self.face)

    @property
    def regular(self) -> np.ndarray:
        """(P,) bool: a regular bicubic patch (``patch_type`` CATMARK_REGULAR)."""
        return self.patch_type == CATMARK_REGULAR

    @property
    def is_quad(self) -> np.ndarray:
        """(P,) bool: a Catmull-Clark quad (else a Loop triangle)."""
        return self.patch_type != LOOP


def patch_level(cage) -> int:
    """L0: the first level where every face has the scheme's regular size."""
    return 1 if cage.scheme == "catmark" else 0


def build_patch_table(cages, keep=None, in_view=None) -> PatchTable:
    """Patch table of several objects (Catmull-Clark and Loop cages may be mixed).

    ``keep``: None (every patch), or per object None or a (F,) bool mask of its cage faces
    whose patches are wanted (e.g. those a ray may see: :func:`cage_face_shells`). The
    others' patches are never made: only the neighbourhood of the kept faces is refined to
    the patch level (:func:`_patch_level`), so the cost follows what is kept, and the kept
    patches are exactly those of the whole cage (their shells, nets and isolation read the
    same points). ``in_view``: None, or ``in_view(lo, hi)`` -> (n,) bool for boxes (n,3):
    then a patch of a Catmull-Clark cage's kept face is left out too when the box of its own
    one-ring is not in view (a face of level 1 is a quarter of a quad)."""
    objs, plans = [], []
    first_patch = first_edge = 0
    for oid, cage in enumerate(cages):
        L0 = patch_level(cage)
        kept = None if keep is None else keep[oid]
        quad = cage.scheme == "catmark"
        # Catmull-Clark: the regular quads of the cage are patches themselves (level 0,
        # as OpenSubdiv's adaptive patches); only the others are refined to level 1. (A
        # cage quad kept: its one-ring box is in view, as its face's.)
        faces0 = np.zeros(0, np.int64)
        if quad:
            quad_mask = regular_cage_quads(cage)
            if quad_mask.any():
                take = quad_mask & ~cage.base.face_hole
                faces0 = np.nonzero(take if kept is None else take & kept)[0]
                kept = ~quad_mask if kept is None else kept & ~quad_mask
        lev, pts, faces, base_face, corner, parent_edge = _patch_level(cage, L0, kept)
        if in_view is not None and L0 > 0 and len(faces):
            # (every face's at once: each vertex ring's box made once, about 4x faster
            # than a ring per face on the sword's 89,512 patches)
            lo, hi = face_ring_boxes(lev, pts)
            lo, hi = lo[faces], hi[faces]
            _chaikin_margin(lev, cage.options, lo, hi)
            seen = in_view(lo, hi)
            faces, base_face, corner = faces[seen], base_face[seen], corner[seen]
        plans.append(((cage, L0, lev, pts, faces, base_face, corner, oid, first_edge, quad),
                      regular_mask(lev, cage.options, faces), None))
        n_edges = lev.n_edges
        if len(faces0):  # (after the patch level's patches and edges)
            plans.append(((cage, 0, cage.base, cage.points, faces0, faces0,
                           np.full(len(faces0), -1, np.int64), oid, first_edge + n_edges, quad),
                          np.ones(len(faces0), bool),
                          (cage.base, faces0, lev, parent_edge, first_edge + n_edges)))
            n_edges += cage.base.n_edges
        objs.append(ObjectPatches(cage, L0, lev, pts, faces, first_patch, first_edge, faces0))
        first_patch += len(faces) + len(faces0)
        first_edge += n_edges
    # every object's nets written into one store, with the renderer's room after them
    # (np.empty: the room costs nothing until written): concatenating them took 0.29 s
    # and a second copy of them on the sword refined twice seen whole (366,532 patches)
    counts = [int(np.count_nonzero(regular)) for _, regular, _ in plans]
    n_nets = sum(counts)
    room = sum(net_room(np.full(len(regular), args[-1]), regular) for args, regular, _ in plans)
    store = np.empty((n_nets + room, 4, 4, 3))
    parts = []
    at = 0
    for (args, regular, share), r in zip(plans, counts):
        parts.append(_object_arrays(*args, regular=regular, nets=store[at:at + r]))
        at += r
        if share is not None:  # (the cage quads' part: its object's level-1 part before)
            base, faces0, lev, parent_edge, first_cage_edge = share
            _share_cage_edges(base, faces0, parts[-2], lev, parent_edge, first_cage_edge)
    if len(parts) == 1:
        cat = parts[0]
    else:
        cat = {k: np.ascontiguousarray(np.concatenate([p[k] for p in parts])) for k in parts[0]
               if k != "nets"}
        cat["nets"] = store[:n_nets]
    return PatchTable(objects=tuple(objs), n_edges=first_edge, **cat)


# rows of room the nets' storage keeps after them (np.empty: no memory until written) for
# what the renderer appends to the same store (trace.pools.Pieces adopts it): the pieces
# of each irregular quad, the net of each Loop triangle. A patch along a crease of
# sharpness s isolates into about 3 2^s pieces (patches/crease.py): the chess pieces'
# 2,823 irregular quads made 331,283, 117 each, and with 16 rows each the store was grown
# (copied) three times, 0.34-0.47 s of a 2 s refinement; with 128, not once.
NET_ROOM_PER_IRREGULAR = 128


def net_room(is_quad, regular) -> int:
    """Rows of room after the nets of a table with these patches (``NET_ROOM_PER_IRREGULAR``
    per irregular quad, one per Loop triangle)."""
    return int(NET_ROOM_PER_IRREGULAR * np.count_nonzero(is_quad & ~regular)
               + np.count_nonzero(~is_quad))


def cage_face_shells(cage):
    """(lo, hi), each (F,3) float64: per face of the cage, a box that holds the limit
    surface over it (the box of its one-ring's control points, widened for Chaikin creases
    as the patches' shells are). Cheap: no refinement. A cage of at least
    ``config.LAZY_TOPOLOGY_FACES`` faces whose topology is not built yet gets the same boxes
    from its face lists (:attr:`~subtrace.mesh.cage.Cage.star_boxes`, read-only; the
    Chaikin margin needs the edges' sharpness, so not for Chaikin cages)."""
    if (not cage.has_topology and not cage.options.chaikin
            and cage.n_faces >= config.LAZY_TOPOLOGY_FACES):
        return cage.star_boxes
    lo, hi = face_ring_boxes(cage.base, cage.points)
    _chaikin_margin(cage.base, cage.options, lo, hi)
    return lo, hi


def _ray_shells(cage, lev, pts, faces, smin, smax, quad):
    """The rays' boxes of the patches ``faces`` of ``lev`` (module doc): for Loop triangles
    their shells ``smin, smax`` cut to the union of their children's one-ring boxes in the
    level below (:func:`~subtrace.patches.shells.split_ring_boxes`), the others' their
    shells."""
    if quad or not len(faces):
        return smin, smax
    ref = refine_level(lev, cage.options)
    lo, hi = split_ring_boxes(lev, refine_points(ref, pts))
    lo, hi = lo[faces], hi[faces]
    _chaikin_margin(ref.child, cage.options, lo, hi)
    return np.maximum(smin, lo), np.minimum(smax, hi)


def _chaikin_margin(level, options, lo, hi):
    """Widen the one-ring boxes ``lo``, ``hi`` in place where Chaikin creases of sharpness
    above 1 may carry the limit surface out of them (``config.SHELL_CHAIKIN_MARGIN``)."""
    if options.chaikin and np.any(level.edge_sharpness > 1.0):
        margin = config.SHELL_CHAIKIN_MARGIN * (hi - lo).max(axis=1, keepdims=True)
        lo -= margin
        hi += margin


# cage rings cut around the kept faces: their children's neighbourhoods out to
# config.GRID_RINGS rings of the patch level (what isolation and grids cut) must be refined
# exactly, and a face is refined exactly when every face around its vertices is in the cut
# (config.GRID_RINGS + 1; a restricted cage, mesh/cage.py, keeps one ring more)
_CUT_RINGS = RESTRICT_RINGS - 1


def restrict(cage, keep):
    """``(cage, keep)`` to build the patches of ``cage``'s faces ``keep`` ((F,) bool) from:
    a cage of at least ``config.LAZY_TOPOLOGY_FACES`` faces whose topology is not built yet
    is cut to the kept faces and ``RESTRICT_RINGS`` rings around them
    (:meth:`~subtrace.mesh.cage.Cage.restricted`, face order and ptex ids kept) when those
    are at most ``config.LAZY_TOPOLOGY_SHARE`` of its faces; the kept faces' patches,
    shells and nets are the whole cage's. Otherwise ``cage`` and ``keep`` as they are."""
    if (cage.has_topology or cage.n_faces < config.LAZY_TOPOLOGY_FACES or keep is None
            or keep.all()):
        return cage, keep
    around = face_rings(cage, keep, RESTRICT_RINGS)
    if np.count_nonzero(around) > config.LAZY_TOPOLOGY_SHARE * cage.n_faces:
        return cage, keep
    return cage.restricted(around), keep[around]


def _patch_level(cage, L0, keep):
    """The patch level of ``cage`` where the faces ``keep`` (a (F,) bool mask of cage faces,
    or None for all) are: (level, points, patch faces in it, the cage face of each patch,
    its corner there (-1: the face itself is the patch), the cage edge of each edge of the
    level (-1 inside a cage face; None when L0 is 0)). With some faces left out, the
    level is that of a cut of the cage around the kept faces (``_CUT_RINGS`` rings, the
    faces' relative order kept), refined to L0."""
    base = cage.base
    if keep is None or np.all(keep):
        lev = cage.level_topology(L0)
        pts = cage.refine(L0).points
        cut_face = None
        kept = np.arange(base.n_faces, dtype=np.int64)
        sub_edge = np.arange(base.n_edges, dtype=np.int64)
        n_corners = len(base.face_verts)
    elif not np.any(keep):
        return base, cage.points, *(np.zeros(0, np.int64),) * 3, None
    else:
        kept = np.nonzero(keep)[0].astype(np.int64)
        lev, pts, sub_edge, n_corners, cut_face = _cut_level(cage, L0, kept)
        kept = np.searchsorted(cut_face, kept)  # in the cut
    parent_edge = None
    if L0 == 1:
        # (refine._split_quads: the halves of edge e of the level above are edges
        # corners + 2 e and corners + 2 e + 1, the edges before them lie inside faces)
        parent_edge = np.full(lev.n_edges, -1, np.int64)
        parent_edge[n_corners:] = np.repeat(sub_edge, 2)
    if L0 == 1:
        # the level-1 children of face c of the cut (or cage) are its corners, in order
        fo = (base.face_offsets if cut_face is None else
              np.r_[0, np.cumsum(np.diff(base.face_offsets)[cut_face])].astype(np.int64))
        sizes = np.diff(fo)[kept]
        parent = np.repeat(kept, sizes)
        corner = np.arange(len(parent), dtype=np.int64) - np.repeat(
            np.cumsum(sizes) - sizes, sizes)
        faces = fo[parent] + corner
    else:
        parent, corner, faces = kept, np.full(len(kept), -1, np.int64), kept
    base_face = parent if cut_face is None else cut_face[parent]
    live = ~lev.face_hole[faces]
    return lev, pts, faces[live], base_face[live], corner[live], parent_edge


def _cut_level(cage, L0, kept):
    """The cut of ``cage`` around its faces ``kept`` (``_CUT_RINGS`` rings) refined to
    ``L0``: (level, points, the cage edge of each edge of the cut before refinement, the
    cut's corners, the cage face of each face of the cut). The last cut made is kept on the
    cage (its cache, as its uniform levels are): the frames of a turntable that keep the
    same faces, as a whole cage in view with its regular quads left out does, make it once."""
    key = (L0, hashlib.blake2b(kept.tobytes(), digest_size=16).digest())
    last = cage._cache.get("cut")
    if last is not None and last[0] == key:
        return last[1]
    base = cage.base
    verts = compact(gather(base.face_offsets, base.face_verts, kept), base.n_verts)[0]
    lev, sub_to_base, _, cut_face = extract(base, verts, rings=_CUT_RINGS)
    # the cage edge of each edge of the cut (its faces' corners are the cage's, in order)
    sub_edge = np.empty(lev.n_edges, np.int64)
    sub_edge[lev.face_edges] = base.face_edges[gather_index(base.face_offsets, cut_face)]
    n_corners = len(lev.face_verts)
    pts = cage.points[sub_to_base]
    for _ in range(L0):
        ref = refine_level(lev, cage.options)
        pts = refine_points(ref, pts)
        lev = ref.child
    cage._cache["cut"] = (key, (lev, pts, sub_edge, n_corners, cut_face))
    return lev, pts, sub_edge, n_corners, cut_face


def regular_cage_quads(cage) -> np.ndarray:
    """(F,) bool: the faces of a Catmull-Clark cage that are regular bicubic patches as they
    are (:func:`~subtrace.patches.bspline.regular_mask` on the cage, each corner's faces all
    quads, as the 16-point grid needs). The limit surface over such a face is the B-spline
    patch of its 16 points (with phantom points beyond sharp sides), equal to its four
    level-1 children's: the table takes it as one patch of level 0. Made once per cage
    (kept in its cache; not to be written)."""
    if "cage_quads" not in cage._cache:
        cage._cache["cage_quads"] = _regular_cage_quads(cage)
    return cage._cache["cage_quads"]


def _regular_cage_quads(cage) -> np.ndarray:
    base = cage.base
    faces = np.arange(base.n_faces, dtype=np.int64)
    regular = regular_mask(base, cage.options, faces)
    if not regular.any():
        return regular
    quad_face = np.diff(base.face_offsets) == 4
    around = np.diff(base.vert_face_offsets)
    # vertices whose faces are all quads
    quads_around = np.bincount(np.repeat(np.arange(base.n_verts), around),
                               weights=quad_face[base.vert_faces], minlength=base.n_verts)
    all_quads = quads_around == around
    corners = base.face_verts[base.face_offsets[faces[regular]][:, None] + np.arange(4)]
    regular[regular] = all_quads[corners].all(axis=1)
    return regular


def _share_cage_edges(base, faces0, part, lev, parent_edge, first_cage_edge):
    """Sides of level-1 patches (``part``, patches of ``lev``) on a cage edge that is also a
    side of a cage quad patch (``faces0``): given that cage edge's id (``first_cage_edge`` +
    its index) and a ``side_shift`` of 1, so both sides sample the whole edge alike
    (``criterion.edge_sampling``; the halves of such an edge are sampled alike too)."""
    if not len(part["face"]) or parent_edge is None:
        return
    shared = np.zeros(base.n_edges, bool)
    shared[base.face_edges[gather_index(base.face_offsets, faces0)]] = True
    starts = lev.face_offsets[part["face"]]
    for side in range(4):
        cage_edge = parent_edge[lev.face_edges.take(starts + side)]
        on = cage_edge >= 0
        on[on] = shared[cage_edge[on]]
        part["edges"][on, side] = first_cage_edge + cage_edge[on]
        part["side_shift"][on, side] = 1


def _object_arrays(cage, L0, lev, pts, faces, F, j, oid, first_edge, quad, regular, nets):
    """The table's per-patch arrays of one object (its patches ``faces`` of level ``lev``,
    each the child at corner ``j`` of cage face ``F``; see :func:`_patch_level`).
    ``regular``: (n,) bool, the patches that are regular quads (:func:`regular_mask`);
    ``nets``: (count of those, 4, 4, 3), where their Bezier nets are written."""
    k = 4 if quad else 3
    n = len(faces)
    # ptex mapping of each patch (a restricted cage's faces keep their whole cage's ids)
    first = ptex_starts(cage) if cage.ptex_first is None else cage.ptex_first
    if L0 == 1:
        # level-1 face c is the child of base face F at corner j, numbered by base corner
        sizes = np.diff(cage.base.face_offsets)
        of_quad = sizes[F] == 4
        ptex = np.where(of_quad, first[F], first[F] + j).astype(np.int32)
        uv0 = _QUAD_CHILD_UV0.take(j % 4, axis=0)
        uv0[~of_quad] = 0.0
        scale = np.where(of_quad, 0.5, 1.0)
    else:
        ptex = first[F].astype(np.int32)
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
    rows = np.nonzero(regular)[0]
    grids, ext = phantom_grids(lev, faces[rows], pts)
    run_tasks(bspline_nets, grids, ext, TO_BEZIER, rows, NET_CHUNK, nets, smin, smax, ebound)
    rate[rows] = 0.5
    # the others: boxes of their one-ring control points
    rows = np.nonzero(~regular)[0]
    lo, hi, bound, valence = one_ring_shells(lev, faces[rows], pts)
    _chaikin_margin(lev, cage.options, lo, hi)
    smin[rows], smax[rows], ebound[rows] = lo, hi, bound
    rate[rows] = subdominant(valence, quad)
    ray_min, ray_max = _ray_shells(cage, lev, pts, faces, smin, smax, quad)
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
        ray_min=ray_min,
        ray_max=ray_max,
        edge_bound=ebound,
        rate=rate,
        patch_type=patch_types(quad, regular),
        nets=nets,
        edges=edges,
        side_shift=np.zeros((n, 4), np.int8),
        level0=np.full(n, L0, np.int8),
        material=material,
    )


