"""Face-varying data (UVs) refined with OpenSubdiv's rules (Vtr's FVarLevel / FVarRefinement,
Far's PrimvarRefiner::InterpolateFaceVarying and LimitFaceVarying).

A channel gives each face corner a value index. Its own topology is a :class:`Channel`: a
:class:`~subtrace.subdiv.topology.Level` over the channel's *values* -- one per distinct
(vertex, value index) of the corners, OpenSubdiv's "vertex values" and their siblings --
with the cage level's faces, in the same order and with the same sizes. So its child faces
are numbered as the cage's at every level, and a value index shared by two vertices gives
each its own value, as in OpenSubdiv. Where a vertex's faces use one value, the channel's
topology around it is the cage's; where they use several, or an edge joins different values
on its two faces (a seam), the channel has a boundary there. OpenSubdiv's rules for the data
then come to the cage's own subdivision rules applied on that topology, with:

* sharpness from the cage level: each channel edge has its cage edge's (and the halves its
  children), a boundary of the channel is infinitely sharp, each value has its vertex's
  sharpness. A seam value is so a crease along the seam (OpenSubdiv's "crease" values:
  3/4, 1/8, 1/8 of its two neighbours along the seam; limit 2/3, 1/6, 1/6), a value whose
  faces hold an inner semi-sharp edge (or whose vertex is semi-sharp) a corner until that
  sharpness has decayed, then a crease with the fractional weight (``semiSharp``); values
  of the same vertex with one topology keep the vertex's rules (``valueTopologyMatches``);
* ``pinned`` values: made infinitely sharp by the linear-interpolation mode (Sdc's
  FVarLinearInterpolation, numbered as Sdc and OpenSubdiv's OBJ tag number them), decided
  once on the cage's own level as ``FVarLevel::completeTopologyFromFaceValues`` decides, and
  inherited by the values' children: every mode but NONE pins a value on one face (a corner,
  and a cage corner that the boundary mode leaves smooth); CORNERS_PLUS1 also the values of
  a vertex with three or more, and both of a vertex with two where either has an inner
  infinitely sharp edge or is split; CORNERS_PLUS2 also a single value on a seam ending
  inside (a dart) and both values of two where one is a corner; BOUNDARIES every value on a
  boundary of the channel, at every level; values whose faces do not form one fan, those of
  a non-manifold or infinitely sharp vertex, and those with an inner infinitely sharp edge
  always;
* ``partner``: CORNERS_PLUS1 / PLUS2 sharpen both values of a two-valued vertex when one is
  semi-sharp: the other follows its sharpness (``depSharp``) -- a corner while it is one,
  then a crease with its fractional weight, or a level later where the vertex keeps another
  semi-sharp edge (OpenSubdiv's ``reclassifySemisharpValues``);
* ALL: linear everywhere (every value pinned, every edge sharp: bilinear refinement).

Values are refined in step with the cage: :func:`refine_channel` takes the cage level's
:class:`~subtrace.subdiv.refine.Refinement` of the same faces (the sharpness of its edges
and vertices, Chaikin's included, comes from there).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from subtrace.subdiv.refine import Refinement, refine_level, refine_points
from subtrace.subdiv.topology import (
    BOUNDARY_EDGE_AND_CORNER, INF_SHARP, Level, Options, base_edges, build_level,
)

# Sdc::Options::FVarLinearInterpolation, in its order (= OpenSubdiv's OBJ tag values)
FVAR_NONE = 0
FVAR_CORNERS_ONLY = 1
FVAR_CORNERS_PLUS1 = 2
FVAR_CORNERS_PLUS2 = 3
FVAR_BOUNDARIES = 4
FVAR_ALL = 5
FVAR_NAMES = ("none", "corners only", "corners plus1", "corners plus2", "boundaries", "all")

_F0 = np.float32(0.0)


@dataclass(frozen=True, eq=False)
class Channel:
    """A face-varying channel's topology at one level (module comment).

    ``level``: its Level (faces as the cage level's, vertices its values, sharpness from the
    cage level); ``vert_of`` (n,) int64: the cage vertex of each value; ``pinned`` (n,) bool;
    ``partner`` (n,) int64: -1, or the value whose sharpness this one follows."""

    level: Level
    vert_of: np.ndarray
    pinned: np.ndarray
    partner: np.ndarray
    mode: int


def base_channel(cage_level: Level, face_values: np.ndarray, mode: int, options: Options):
    """The channel of a cage's tagged level ``cage_level`` whose face corners have the value
    indices ``face_values`` (C,), and the value index of each of its values (n,) int64."""
    fv = cage_level.face_verts.astype(np.int64)
    vals = np.asarray(face_values, dtype=np.int64)
    n_index = int(vals.max()) + 1 if len(vals) else 1
    uniq, corner_value = np.unique(fv * n_index + vals, return_inverse=True)
    vert_of, value_index = uniq // n_index, uniq % n_index
    n = len(uniq)
    corner_value = corner_value.astype(np.int32)
    ev, fe, fwd = base_edges(cage_level.face_offsets, corner_value, n)
    level = build_level(n, cage_level.face_offsets, corner_value, ev, fe, fwd,
                        np.zeros(len(ev), np.float32), np.zeros(n, np.float32),
                        cage_level.face_hole)
    edge_sharp = _edge_sharpness(level, cage_level)
    pinned, partner = _mode_tags(cage_level, level, vert_of, edge_sharp, mode, options)
    ch = Channel(level, vert_of, pinned, partner, mode)
    return _with_sharpness(ch, cage_level), value_index


def cut_channel(ch: Channel, faces: np.ndarray, cage_vmap: np.ndarray):
    """The channel of the faces ``faces`` alone, as ``subdiv.limit.extract`` cut its cage's
    level (``cage_vmap``: that cut's map from the level's vertices to its own, -1 outside),
    and the values it keeps (indices into ``ch``'s)."""
    from subtrace.subdiv.limit import cut_level

    sub, old_v, vmap, _ = cut_level(ch.level, faces)
    partner = ch.partner[old_v]
    partner = np.where(partner >= 0, vmap[np.maximum(partner, 0)], -1)
    return Channel(sub, cage_vmap[ch.vert_of[old_v]], ch.pinned[old_v], partner, ch.mode), old_v


def refine_channel(ch: Channel, cage_ref: Refinement, points: np.ndarray):
    """One level of refinement: the child channel and the values of its values (n', d)
    from those of ``ch``'s (n, d). ``cage_ref`` refines the cage level ``ch`` belongs to."""
    p = ch.level
    cage_p = cage_ref.parent
    split = refine_level(p, cage_ref.options).child  # (its sharpness is replaced below)
    V, F = p.n_verts, p.n_faces
    cage_V, cage_F = cage_p.n_verts, cage_p.n_faces
    # the cage vertex of each child value: vertex children keep their index, face children
    # follow (Catmull-Clark), then edge children
    edge_of = np.empty(p.n_edges, dtype=np.int64)
    edge_of[p.face_edges] = cage_p.face_edges
    loop = cage_ref.options.scheme == "loop"
    parts = [ch.vert_of] + ([] if loop else [cage_V + np.arange(cage_F)])
    parts.append(cage_V + (0 if loop else cage_F) + edge_of)
    vert_of = np.concatenate(parts)
    n_child = split.n_verts
    pinned = np.zeros(n_child, dtype=bool)
    pinned[:V] = ch.pinned
    partner = np.full(n_child, -1, dtype=np.int64)
    if ch.mode == FVAR_BOUNDARIES:
        pinned |= split.vert_boundary()
    child = Channel(split, vert_of, pinned, partner, ch.mode)
    child = _with_sharpness(child, cage_ref.child)
    # the halves of each edge: the cage edge's, turned where the channel's edge runs the other
    # way; boundaries of the channel (and everything, linear) infinitely sharp
    same = p.face_edge_forward == cage_p.face_edge_forward
    edge_child = np.empty((p.n_edges, 2), dtype=np.float32)
    halves = cage_ref.edge_child_sharpness[cage_p.face_edges]
    edge_child[p.face_edges] = np.where(same[:, None], halves, halves[:, ::-1])
    vert_child = cage_ref.vert_child_sharpness[ch.vert_of].astype(np.float32)
    if ch.mode == FVAR_ALL:
        edge_child[:] = INF_SHARP
        vert_child[:] = INF_SHARP
    else:
        edge_child[np.diff(p.edge_face_offsets) == 1] = INF_SHARP
        vert_child[ch.pinned] = INF_SHARP
    ref = Refinement(p, child.level, cage_ref.options, edge_child, vert_child)
    out = refine_points(ref, points)
    deps = np.nonzero(ch.partner >= 0)[0]
    if len(deps):
        _follow_partners(ch, child, ref, cage_ref, deps, points, out)
    return child, out


def channel_levels(cage_level: Level, face_values, values, mode, options, level: int):
    """Uniform refinement of a cage's channel to ``level``: (Channel, values (n, d)) of each
    level 0..level, in step with the cage's own refinement of ``cage_level``."""
    ch, index = base_channel(cage_level, face_values, mode, options)
    pts = np.asarray(values, dtype=np.float64)[index]
    out = [(ch, pts)]
    cage = cage_level
    for _ in range(level):
        ref = refine_level(cage, options)
        ch, pts = refine_channel(ch, ref, pts)
        cage = ref.child
        out.append((ch, pts))
    return out


# --------------------------------------------------------------------------------------


def _edge_sharpness(level: Level, cage_level: Level) -> np.ndarray:
    """(E,) float32: each channel edge's cage edge's sharpness, its boundaries infinite."""
    es = np.empty(level.n_edges, dtype=np.float32)
    es[level.face_edges] = cage_level.edge_sharpness[cage_level.face_edges]
    es[np.diff(level.edge_face_offsets) == 1] = INF_SHARP
    return es


def _with_sharpness(ch: Channel, cage_level: Level) -> Channel:
    """``ch`` with its level's sharpness taken from ``cage_level`` (the cage's level of the
    same faces): edges as :func:`_edge_sharpness`, values their vertex's, pinned ones (and
    all, linear) infinitely sharp."""
    es = _edge_sharpness(ch.level, cage_level)
    vs = cage_level.vert_sharpness[ch.vert_of].astype(np.float32)
    if ch.mode == FVAR_ALL:
        es[:] = INF_SHARP
        vs[:] = INF_SHARP
    vs[ch.pinned] = INF_SHARP
    return replace(ch, level=replace(ch.level, edge_sharpness=es, vert_sharpness=vs))


def _ring_counts(level: Level, edge_sharp: np.ndarray):
    """Per value: its faces, and the inner (two-face) edges of its faces that are infinitely
    sharp and semi-sharp (OpenSubdiv's ValueSpan)."""
    n_faces = np.diff(level.vert_face_offsets)
    counts = np.repeat(np.arange(level.n_verts), np.diff(level.vert_edge_offsets))
    e = level.vert_edges
    inner = np.diff(level.edge_face_offsets)[e] == 2
    s = edge_sharp[e]
    inf = np.bincount(counts, inner & (s >= INF_SHARP), minlength=level.n_verts)
    semi = np.bincount(counts, inner & (s > 0) & (s < INF_SHARP), minlength=level.n_verts)
    return n_faces, inf.astype(np.int64), semi.astype(np.int64)


def _mode_tags(cage: Level, level: Level, vert_of, edge_sharp, mode: int, options: Options):
    """(pinned (n,) bool, partner (n,) int64) of the base channel (module comment;
    ``FVarLevel::completeTopologyFromFaceValues``)."""
    n = level.n_verts
    pinned = np.zeros(n, dtype=bool)
    partner = np.full(n, -1, dtype=np.int64)
    if mode == FVAR_ALL:
        return ~pinned, partner
    linear_boundaries = mode == FVAR_BOUNDARIES
    dependent = mode in (FVAR_CORNERS_PLUS1, FVAR_CORNERS_PLUS2)
    corners_sharp = mode != FVAR_NONE
    smooth_corners_sharp = corners_sharp and options.boundary != BOUNDARY_EDGE_AND_CORNER
    both_if_one_corner = mode == FVAR_CORNERS_PLUS2
    darts = both_if_one_corner or linear_boundaries
    V = cage.n_verts
    # a cage edge is split (OpenSubdiv's discontinuous edge) where its faces' uses of it are
    # different channel edges; both its ends then differ from the cage's topology
    lo = np.full(cage.n_edges, np.iinfo(np.int64).max)
    hi = np.full(cage.n_edges, -1)
    np.minimum.at(lo, cage.face_edges, level.face_edges)
    np.maximum.at(hi, cage.face_edges, level.face_edges)
    split = (hi >= 0) & (lo != hi)
    mismatch = np.zeros(V, dtype=bool)
    mismatch[cage.edge_verts[split].ravel()] = True
    n_faces = np.diff(cage.vert_face_offsets)
    boundary = cage.vert_boundary()
    n_values = np.bincount(vert_of, minlength=V)
    nonmanifold = ~cage.vert_manifold & (n_faces > 0)
    mismatch |= boundary & (n_faces > 0) & linear_boundaries
    mismatch |= boundary & (n_faces == 1) & smooth_corners_sharp
    mismatch |= nonmanifold & (n_values > 1)
    size, inf_edges, semi_edges = _ring_counts(level, edge_sharp)
    apart = ~level.vert_manifold  # the value's faces are not one fan (its span is split)
    vs = cage.vert_sharpness
    first = np.searchsorted(vert_of, np.arange(V + 1))  # values sorted by vertex
    for v in np.nonzero(mismatch)[0]:
        vals = np.arange(first[v], first[v + 1])
        all_sharp = (linear_boundaries or vs[v] >= INF_SHARP or nonmanifold[v]
                     or (dependent and len(vals) > 2)
                     or (darts and len(vals) == 1 and not boundary[v]))
        follow = False
        if not all_sharp and dependent and len(vals) == 2:
            a, b = vals
            all_sharp = bool(inf_edges[a] or inf_edges[b] or apart[a] or apart[b]
                             or (both_if_one_corner and (size[a] == 1 or size[b] == 1)))
            follow = (semi_edges[a] > 0) != (semi_edges[b] > 0)
        for u in vals:
            sharp = (apart[u] or all_sharp or inf_edges[u] > 0
                     or (size[u] == 1 and corners_sharp))
            if sharp:
                pinned[u] = True
            elif semi_edges[u] == 0 and not (0 < vs[v] < INF_SHARP) and follow:
                partner[u] = vals[0] if u == vals[1] else vals[1]
    return pinned, partner


def _follow_partners(ch: Channel, child: Channel, ref: Refinement, cage_ref: Refinement,
                     deps, points, out):
    """The children of values that follow a partner's sharpness (module comment), in place
    in ``out``; their children's ``partner`` set where they still follow it."""
    p, c = ch.level, child.level
    cage_c = cage_ref.child
    for j in deps:
        k = ch.partner[j]
        v = ch.vert_of[j]
        # the vertex (which keeps its index in the child) has no semi-sharp edge left
        es = cage_c.edge_sharpness[cage_c.vert_edges[cage_c.vert_edge_offsets[v]:
                                                     cage_c.vert_edge_offsets[v + 1]]]
        vsc = cage_c.vert_sharpness[v]
        none_left = not (((es > 0) & (es < INF_SHARP)).any() or 0 < vsc < INF_SHARP)
        ke = c.vert_edges[c.vert_edge_offsets[k]:c.vert_edge_offsets[k + 1]]
        inner = np.diff(c.edge_face_offsets)[ke] == 2
        ks = c.edge_sharpness[ke][inner]
        partner_semi = bool(((ks > 0) & (ks < INF_SHARP)).any())
        if none_left:
            # a crease now, by the partner's fractional weight (crease ends: the far ends
            # of its two boundary edges, first and last of its ring)
            pe = p.vert_edges[p.vert_edge_offsets[k]:p.vert_edge_offsets[k + 1]]
            ends = np.where(p.edge_verts[pe, 0] == k, 0, 1)
            w = _fractional_weight(cage_ref.parent.vert_sharpness[v], vsc,
                                   p.edge_sharpness[pe], ref.edge_child_sharpness[pe, ends])
            je = p.vert_edges[p.vert_edge_offsets[j]:p.vert_edge_offsets[j + 1]]
            a = _far(p, je[0], j)
            b = _far(p, je[-1], j)
            crease, corner = 1.0 - w, w
            out[j] = ((crease * 0.125) * points[a] + (crease * 0.125) * points[b]
                      + (crease * 0.75 + corner) * points[j])
        else:
            out[j] = points[j]  # still a corner
            if partner_semi:
                child.partner[j] = k


def _far(level: Level, e, v):
    a, b = level.edge_verts[e]
    return b if a == v else a


def _fractional_weight(p_vert, c_vert, p_edges, c_edges) -> float:
    """Sdc's ComputeFractionalWeightAtVertex given the children's sharpness (float32): the
    mean of the parent sharpness of the vertex and edges whose children are smooth, at
    most 1 (both crease methods: their child sharpness says which decayed)."""
    total = _F0
    count = 0
    if p_vert > 0 and c_vert <= 0:
        count, total = 1, np.float32(p_vert)
    for ps, cs in zip(p_edges, c_edges):
        if ps > 0 and cs <= 0:
            total = np.float32(total + ps)
            count += 1
    if count == 0:
        return 0.0
    return float(min(np.float32(total / np.float32(count)), np.float32(1.0)))
