"""Catmull-Clark patches as the renderer intersects them (trace.pools.Pieces,
patches.isolate): regular patches as Bezier nets, irregular ones as feature-adaptive
pieces and cells, at depths within the tolerance."""

from __future__ import annotations

import numpy as np
import pytest
from shared_data import MODELS, SHAPES, load_shape

import subtrace
from subtrace.patches.grids import build_grids
from subtrace.patches.table import build_patch_table
from subtrace.subdiv.topology import INF_SHARP

PIECE_SHAPES = ["catmark_cube_creases1", "catmark_nonquads", "catmark_pole8",
                "catmark_edgecorner", "catmark_chaikin1", "catmark_hole_test2"]
# those with regular patches at level 1 (the semi-sharp creases of the cube and the Chaikin
# cage leave none there)
REGULAR_SHAPES = [n for n in PIECE_SHAPES if n not in ("catmark_cube_creases1", "catmark_chaikin1")]


# boundaries, sharp corners and infinitely sharp creases: regular patches with phantom points
SHARP_SHAPES = ["catmark_edgeonly", "catmark_edgecorner", "catmark_inf_crease0", "catmark_fan",
                "catmark_flap", "catmark_xord_boundary", "catmark_tent_creases0",
                "catmark_quadstrips", "catmark_single_crease", "catmark_nonman_edges",
                "catmark_val2_interior", "catmark_hole_test3", "catmark_gregory_test2"]
# closed cages whose sharp corners and creases have regular quads from level 2 on
# (the semi-sharp cubes and pyramids have none yet at level 2)
SHARP_LEVEL2 = ["catmark_cubes_infsharp", "catmark_edgeonly", "catmark_fan"]


@pytest.mark.parametrize("name", SHARP_SHAPES)
def test_sharp_sides_make_more_patches_regular(name):
    """Quads at a boundary, a sharp corner or an infinitely sharp crease whose corners are
    regular there are regular patches: more than the smooth ones alone."""
    from subtrace.patches import bspline

    cage = load_shape(name)
    lev = cage.level_topology(1)
    faces = np.nonzero(~lev.face_hole)[0]
    reg = faces[bspline.regular_mask(lev, cage.options, faces)]
    smooth = bspline.smooth_mask(lev, reg)
    assert (~smooth).sum() > 0


@pytest.mark.parametrize("name", REGULAR_SHAPES + SHARP_SHAPES)
def test_bicubic_grids_match_refinement(name):
    """A regular patch evaluated the way the renderer does (its Bezier net: points and
    derivatives) gives the limit points and normals of uniform refinement (to rounding),
    and the net's box contains them."""
    _check_nets(load_shape(name), 1)


@pytest.mark.parametrize("name", SHARP_LEVEL2)
def test_sharp_sided_nets_match_refinement_at_level_2(name):
    """The same at level 2, where the quads beside sharp corners and creases of closed
    cages (and of boundaries at their extraordinary vertices) become regular."""
    _check_nets(load_shape(name), 2, sharp_only=True)


def _check_nets(cage, level, sharp_only=False):
    from subtrace.patches import basis, bspline
    from subtrace.patches.basis import bez_derivatives, bez_point as _bez_point

    lev = cage.level_topology(level)
    pts = cage.refine(level).points
    faces = np.nonzero(~lev.face_hole)[0]
    reg = faces[bspline.regular_mask(lev, cage.options, faces)]
    if sharp_only:
        reg = reg[~bspline.smooth_mask(lev, reg)]
    assert len(reg) > 0
    nets = basis.bezier_nets(bspline.control_points(lev, reg, pts))
    lo, hi, _ = basis.net_bounds(nets)
    scale = float(np.abs(pts).max())
    # sides on an infinitely sharp edge (0: v = 0, 1: u = 1, 2: v = 1, 3: u = 0): the
    # reference normal there is one side's of a crease, so only points are compared
    sharp = lev.edge_sharpness[lev.face_edges[lev.face_offsets[reg][:, None] + np.arange(4)]] >= INF_SHARP
    for depth in (0, 3):
        n = (1 << depth) + 1
        ref, nref = build_grids(lev, pts, cage.options, reg, depth)
        for m, net in enumerate(nets):
            for g in range(n * n):
                j, i = divmod(g, n)
                u, v = i / (n - 1), j / (n - 1)
                p = np.array(_bez_point(nets, m, u, v))
                assert np.abs(p - ref[m, g]).max() <= 1e-13 * scale
                assert np.all(p >= lo[m] - 1e-12 * scale) and np.all(p <= hi[m] + 1e-12 * scale)
                on = sharp[m] & (np.array([v, 1 - u, 1 - v, u]) == 0)
                if on.any():
                    continue
                du, dv = bez_derivatives(net, u, v)
                nrm = np.cross(du, dv)
                assert np.abs(nrm / np.linalg.norm(nrm) - nref[m, g]).max() <= 1e-9


@pytest.mark.parametrize("name", PIECE_SHAPES)
def test_isolated_pieces_tile_the_grid(name):
    """The pieces of an irregular patch cover every cell of its grid exactly once, and their
    points are the grid's exact limit points (uniform refinement), to rounding."""
    from subtrace.patches.isolate import build_isolated
    from subtrace.patches.basis import bez_point as _bez_point

    cage = load_shape(name)
    table = build_patch_table([cage])
    o = table.objects[0]
    irr = np.nonzero(~table.regular)[0][:12]
    scale = float(np.abs(o.points).max())
    for depth in (0, 1, 3):
        (sr, sl, si, sj, nets, *_), (cr, ci, cj, cp, _) = build_isolated(o, table.face[irr], depth)
        G = build_grids(o.level, o.points, cage.options, table.face[irr], depth)[0]
        n = (1 << depth) + 1
        G = G.reshape(len(irr), n, n, 3)
        covered = np.zeros((len(irr), n - 1, n - 1), dtype=int)
        for k, (r, lev_, i, j) in enumerate(zip(sr, sl, si, sj)):
            m = 1 << (depth - lev_)
            for a in range(m + 1):
                for b in range(m + 1):
                    p = np.array(_bez_point(nets, k, a / m, b / m))
                    assert np.abs(p - G[r, j * m + b, i * m + a]).max() <= 1e-13 * scale
            covered[r, j * m:(j + 1) * m, i * m:(i + 1) * m] += 1
        for r, i, j, q in zip(cr, ci, cj, cp):
            want = [G[r, j, i], G[r, j, i + 1], G[r, j + 1, i + 1], G[r, j + 1, i]]
            assert np.abs(q - np.array(want)).max() <= 1e-13 * scale
            covered[r, j, i] += 1
        assert np.all(covered == 1)


def _walk(first, count, kind, ref, lo, hi, enters):
    """The items a ray reaches in rows ``first .. first + count - 1``, walked as
    ``bezier.intersect_patch`` does: a group whose box it misses is skipped whole."""
    from subtrace.geometry.kinds import GROUP

    seen, it = [], first
    while it < first + count:
        inside = enters(lo[it], hi[it])
        if kind[it] == GROUP:
            it += 1 if inside else int(ref[it])
            continue
        if inside:
            seen.append(it)
        it += 1
    return seen


@pytest.mark.parametrize("scheme", ["catmark", "loop"])
def test_item_groups_skip_only_items_the_ray_misses(scheme):
    """Isolated patches' items with their group rows (patches/groups.py): every item once;
    each group's box holds the boxes of the rows it spans, its span within its parent's;
    and a ray walking the rows with skips reaches exactly the items whose boxes it enters
    (random rays through the patches, against testing every item's box)."""
    from subtrace.geometry.kinds import GROUP
    from subtrace.patches.isolate import build_isolated
    from subtrace.patches.isolate_loop import build_loop_isolated
    from subtrace.trace.pools import Pieces

    if scheme == "catmark":
        cage = subtrace.load_cage(MODELS / "spot_control_mesh.obj")
    else:
        cage = subtrace.load_cage(SHAPES / "loop_icos_semisharp.obj")
    table = build_patch_table([cage])
    irr = np.nonzero(~table.regular)[0][:40]
    depth = np.full(len(irr), 5)
    iso = Pieces(table.n_patches)
    if scheme == "catmark":
        subs, cells = build_isolated(table.objects[0], table.face[irr], depth)
        iso.append(irr, depth, np.repeat(depth, 4), subs, cells, 0)
        n_items = len(subs[0]) + len(cells[0])
    else:
        subs, cells = build_loop_isolated(table.objects[0], table.face[irr], depth)
        iso.append_loop(irr, depth, np.full((len(irr), 3), -1), subs, cells, 0)
        n_items = len(subs[0]) + len(cells[0])
    a = iso.a
    kind, ref, lo, hi = a["kind"], a["ref"], a["lo"], a["hi"]
    groups = np.nonzero(kind == GROUP)[0]
    assert len(groups) > 0 and np.count_nonzero(kind != GROUP) == n_items
    rng = np.random.default_rng(7)
    for f, c in zip(a["first"], a["count"]):
        end = f + c
        assert kind[f] == GROUP and f + ref[f] == end  # the whole patch first
        for g in range(f, end):
            if kind[g] != GROUP:
                continue
            span = slice(g, g + int(ref[g]))
            assert g + ref[g] <= end
            assert np.all(lo[span] >= lo[g]) and np.all(hi[span] <= hi[g])
        # rays from random points towards random points of the patch's box
        box_lo, box_hi = lo[f], hi[f]
        size = float(np.max(box_hi - box_lo))
        for _ in range(40):
            target = box_lo + rng.random(3) * (box_hi - box_lo)
            origin = target + rng.normal(size=3) * 4 * size
            d = target - origin

            def enters(b_lo, b_hi, o=origin, d=d):
                with np.errstate(divide="ignore", invalid="ignore"):
                    t0, t1 = (b_lo - o) / d, (b_hi - o) / d
                tn = np.nanmax(np.minimum(t0, t1))
                tf = np.nanmin(np.maximum(t0, t1))
                return tn <= tf and tf >= 0

            want = [it for it in range(f, end) if kind[it] != GROUP and enters(lo[it], hi[it])]
            assert _walk(f, c, kind, ref, lo, hi, enters) == want


def test_cells_subtend_at_most_the_tolerance():
    """Invariant 3 on real grids: with the chosen depths, every cell side of every patch of
    Spot (regular and isolated, and each piece of an isolated patch at its own depth)
    subtends at most the tolerance at the eye (the bound is conservative) - and not far
    below it for most patches (the bound is tight)."""
    from subtrace.patches.criterion import choose_depths

    cage = subtrace.load_cage(MODELS / "spot_control_mesh.obj")
    table = build_patch_table([cage])
    o = table.objects[0]
    eye = np.array([2.393, 1.306, -3.637])
    tol = np.radians(0.05)
    depths = choose_depths(table, eye, tol, 8)
    worst = []
    for d in np.unique(depths):
        ids = np.nonzero(depths == d)[0]
        P = build_grids(o.level, o.points, cage.options, table.face[ids], int(d))[0]
        n = (1 << d) + 1
        G = P.reshape(len(ids), n, n, 3)
        dist = np.linalg.norm(G - eye, axis=-1)
        su = np.linalg.norm(np.diff(G, axis=2), axis=-1) / np.minimum(dist[:, :, 1:], dist[:, :, :-1])
        sv = np.linalg.norm(np.diff(G, axis=1), axis=-1) / np.minimum(dist[:, 1:], dist[:, :-1])
        worst.append(np.maximum(su.reshape(len(ids), -1).max(1), sv.reshape(len(ids), -1).max(1)))
    # the pieces of isolated patches, each refined to its own depth
    from subtrace.patches.isolate import build_isolated

    irr = np.nonzero(~table.regular & (depths > 0))[0]
    for d in np.unique(depths[irr]):
        ids = irr[depths[irr] == d]
        (_, lev, _, _, nets, own, *_), _ = build_isolated(o, table.face[ids], int(d), eye, tol)
        assert np.all((own >= lev) & (own <= d))
        for pd in np.unique(own - lev):
            sel = own - lev == pd
            t = np.linspace(0.0, 1.0, (1 << pd) + 1)
            B = np.stack([(1 - t) ** 3, 3 * t * (1 - t) ** 2, 3 * t * t * (1 - t), t ** 3], 1)
            G = np.einsum("ia,jb,nabk->njik", B, B, nets[sel])  # (n, v, u, 3)
            dist = np.linalg.norm(G - eye, axis=-1)
            su = (np.linalg.norm(np.diff(G, axis=2), axis=-1)
                  / np.minimum(dist[:, :, 1:], dist[:, :, :-1]))
            sv = (np.linalg.norm(np.diff(G, axis=1), axis=-1)
                  / np.minimum(dist[:, 1:], dist[:, :-1]))
            worst.append(np.maximum(su.reshape(sel.sum(), -1).max(1),
                                    sv.reshape(sel.sum(), -1).max(1)))
    worst = np.concatenate(worst) / tol
    assert worst.max() <= 1.0 + 1e-9
    assert np.median(worst) > 0.4


@pytest.mark.parametrize("record_depth", [0, 6])
def test_isolation_taken_from_the_depth_choice_equals_a_fresh_one(record_depth, monkeypatch):
    """``build_isolated`` with the record of ``isolated_depths`` gives the same pieces and
    cells as refining the requested patches afresh, also where a patch's depth was raised
    beyond what the record reaches (it then refines further itself); recording deeper
    (``record_depth``) does not change the depths chosen. (Every patch by local topology,
    which the record serves: the maps of patches/stencil.py need none, test_stencil.py.)"""
    from subtrace import config
    from subtrace.patches.isolate import build_isolated, isolated_depths

    monkeypatch.setattr(config, "STENCIL_ISOLATION", False)

    cage = subtrace.load_cage(MODELS / "spot_control_mesh.obj")
    table = build_patch_table([cage])
    o = table.objects[0]
    irr = np.nonzero(~table.regular)[0]
    eye = np.array([0.3, 0.6, 2.2])
    tol = 2e-3
    record = {}
    depths = isolated_depths(o, table.face[irr], np.full(len(irr), 6), eye, tol, record,
                             record_depth)
    assert np.array_equal(depths, isolated_depths(o, table.face[irr], np.full(len(irr), 6),
                                                  eye, tol))
    assert len(record["levels"]) >= (2 if record_depth == 0 else record_depth)
    pick = np.arange(0, len(irr), 3)
    dep = np.minimum(depths[pick] + (pick % 2), 6)  # some raised, as neighbours raise them
    a = build_isolated(o, table.face[irr[pick]], dep, eye, tol, record)
    b = build_isolated(o, table.face[irr[pick]], dep, eye, tol)
    scale = float(np.abs(o.points).max())

    def by_piece(arrays, n_keys):
        order = np.lexsort(arrays[:n_keys][::-1])
        return [x[order] for x in arrays]

    (ar, al, ai, aj, an, ad, *_), (br, bl, bi, bj, bn, bd, *_) = by_piece(a[0], 4), by_piece(b[0], 4)
    for x, y in ((ar, br), (al, bl), (ai, bi), (aj, bj), (ad, bd)):
        assert np.array_equal(x, y)
    # each piece's box travels with it (taken from the record, or made with its net): the
    # box of its net's control points, bit for bit
    from subtrace.patches.basis import net_bounds

    for subs in (a[0], b[0]):
        lo, hi, _ = net_bounds(subs[4])
        assert np.array_equal(subs[6], lo) and np.array_equal(subs[7], hi)
    assert np.abs(an - bn).max() <= 1e-13 * scale
    (cr, ci, cj, cp, _), (dr, di, dj, dp, _) = by_piece(a[1], 3), by_piece(b[1], 3)
    for x, y in ((cr, dr), (ci, di), (cj, dj)):
        assert np.array_equal(x, y)
    assert np.abs(cp - dp).max() <= 1e-13 * scale


def test_regular_patches_appended_directly_equal_the_general_append():
    """``Pieces.append_regular`` lays out regular patches as ``append`` does (one piece
    each, sides as given, the net's box for both boxes)."""
    from subtrace.trace.pools import Pieces

    table = build_patch_table([subtrace.load_cage(MODELS / "spot_control_mesh.obj")])
    reg = np.nonzero(table.regular)[0]
    rng = np.random.default_rng(1)
    depth = rng.integers(0, 6, len(reg))
    side = depth[:, None] + rng.integers(0, 2, (len(reg), 4))
    z = np.zeros(len(reg), np.int64)
    none = np.zeros(0, np.int64)
    a, b = Pieces(table.n_patches), Pieces(table.n_patches)
    from subtrace.patches.basis import net_bounds

    lo, hi, _ = net_bounds(table.nets)
    a.append(reg, depth, side, (np.arange(len(reg)), z, z, z, table.nets, depth, lo, hi),
             (none, none, none, np.zeros((0, 4, 3)), np.zeros((0, 4, 3))), -1)
    b.append_regular(reg, depth, side, table.nets, table.shell_min[reg], table.shell_max[reg])
    assert np.array_equal(a.patch_iso, b.patch_iso)
    for name in a.a:
        assert np.array_equal(a.a[name], b.a[name]), name


def test_valence_two_corners_follow_the_boundary_interpolation():
    """A boundary vertex of one face is a sharp corner (regular) under edge-and-corner
    interpolation or with an infinite ``t corner`` tag, but a smooth crease (irregular, as
    OpenSubdiv takes it) under edge only untagged; a semi-sharp corner tag is irregular."""
    from subtrace.subdiv.topology import BOUNDARY_EDGE_AND_CORNER, BOUNDARY_EDGE_ONLY
    from subtrace.patches import bspline

    path = SHAPES / "catmark_edgeonly.obj"  # corners 16, 19, 36, 37 tagged 10, 38, 39 tagged 2
    found = {}
    for mode in (BOUNDARY_EDGE_ONLY, BOUNDARY_EDGE_AND_CORNER):
        cage = subtrace.load_cage(path, boundary=mode)
        lev = cage.level_topology(1)
        one_face = np.nonzero(np.diff(lev.vert_face_offsets) == 1)[0]
        # the face at each one-face vertex, and that vertex's corner sharpness
        face = lev.vert_faces[lev.vert_face_offsets[one_face]]
        found[mode] = (bspline.regular_mask(lev, cage.options, face),
                       lev.vert_sharpness[one_face])
    reg, sharp = found[BOUNDARY_EDGE_ONLY]
    assert (sharp == 0).sum() > 0 and (sharp >= INF_SHARP).sum() == 4
    assert not reg[sharp == 0].any()
    assert reg[sharp >= INF_SHARP].all()
    assert not reg[(sharp > 0) & (sharp < INF_SHARP)].any()
    reg, sharp = found[BOUNDARY_EDGE_AND_CORNER]
    assert reg[sharp >= INF_SHARP].all() and (sharp >= INF_SHARP).sum() > 4


def _cube_cage(extra_points=()):
    """The unit cube (8 vertices, 6 quads), with ``extra_points`` after its vertices that no
    face uses."""
    from subtrace.mesh.cage import make_cage

    pts = [[x, y, z] for z in (0.5, -0.5) for y in (-0.5, 0.5) for x in (-0.5, 0.5)]
    quads = [[0, 1, 3, 2], [2, 3, 7, 6], [6, 7, 5, 4], [4, 5, 1, 0], [1, 5, 7, 3],
             [4, 0, 2, 6]]
    return make_cage(np.array(pts + list(extra_points), float), np.full(6, 4),
                     np.array(quads).ravel(), "catmark")


def test_a_record_of_the_maps_alone_serves_shallower_builds():
    """When every patch the depth choice isolates goes by the maps (patches/stencil.py,
    caps of ``MIN_LEVELS`` and more), the record holds no levels of its own; a patch
    built later below ``MIN_LEVELS`` (by local topology) refines afresh, as without a
    record (a cube seen small: every patch's cap 4, some depths 1 or 2; this raised
    ``KeyError: 'levels'``)."""
    from subtrace.patches.isolate import build_isolated, isolated_depths
    from subtrace.patches.stencil import MIN_LEVELS

    table = build_patch_table([_cube_cage()])
    o = table.objects[0]
    faces = table.face[~table.regular]
    assert len(faces) == 24
    eye, tol = np.array([9.0, 1.0, -7.5]), 0.02
    cap = np.full(len(faces), MIN_LEVELS + 1)
    record = {}
    depths = isolated_depths(o, faces, cap, eye, tol, record)
    shallow = depths < MIN_LEVELS
    assert shallow.any() and depths.max() > 0
    a = build_isolated(o, faces[shallow], depths[shallow], eye, tol, record)
    b = build_isolated(o, faces[shallow], depths[shallow], eye, tol)
    for x, y in zip(a[0] + a[1], b[0] + b[1]):
        assert np.array_equal(x, y)
