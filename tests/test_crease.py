"""Isolation of patches along semi-sharp creases by fixed linear maps (patches/crease.py),
checked against the topological isolation it replaces (patches/isolate.py with
``crease.ENABLED`` off: local refinement of the mesh, an independent code path) and against
OpenSubdiv's own limit surface (the oracle's exact samples): the same depths, shells,
pieces and cells to rounding, on fractional and integer sharpness and both crease methods,
at the root and below it (a crease's ends and junctions); which faces qualify, against a
plain walk of each face's corners; item_sides against the pairwise rule it replaced;
watertight from inside closed creased cages, and the same image on 1 and 2 threads."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from shared_data import SHAPES, assert_same_isolation, small_scene

import subtrace
from subtrace.patches import crease, gridmaps, isolate
from subtrace.patches.criterion import wanted_depths
from subtrace.patches.isolate import build_isolated, isolated_depths, item_sides
from subtrace.patches.table import build_patch_table
from subtrace.render import render_scene
from subtrace.subdiv.topology import INF_SHARP

REPO = Path(__file__).resolve().parents[1]
HARD = REPO / "models" / "opensubdiv"


# ------------------------------------------------------------------------------------------
# creased tori: closed, every vertex of valence 4
# ------------------------------------------------------------------------------------------

# (crease method, [(ring kind, ring index, first, last, sharpness)]): "u" rings run around
# the tube's axis at tube angle j (edges (i, j)-(i+1, j), i = first .. last - 1), "v" rings
# around the tube at i
TORI = {
    "rings": ("uniform", [("u", 0, 0, 12, 7.5), ("u", 4, 0, 12, 7.0)]),
    "chaikin": ("chaikin", [("u", 0, 0, 12, 6.5), ("u", 4, 0, 12, 7.0), ("u", 2, 0, 12, 6.3)]),
    # a ring that ends, a ring across it (junctions), a ring whose sharpness changes
    "ends": ("uniform", [("u", 2, 2, 8, 4.3), ("v", 5, 0, 8, 3.0), ("u", 6, 0, 6, 5.0),
                         ("u", 6, 6, 12, 6.0)]),
    "chaikin_ends": ("chaikin", [("u", 2, 2, 8, 4.5), ("v", 5, 0, 8, 3.0)]),
    # rings one quad apart: at the cage's level, quads creased on two opposite sides
    "pair": ("uniform", [("u", 2, 0, 12, 2.5), ("u", 3, 0, 12, 4.0)]),
    # a ring with a spur of another sharpness at one point: Chaikin's rule there gives the
    # ring's edge no sharpness one level down at that end (0.75 1.05 + 0.25 0.675 < 1), a
    # blend instead of the midpoint, so the quads whose grid line ends there are not the
    # maps' (at the cage's level: one level down the ring is uneven there)
    "spur": ("chaikin", [("u", 2, 0, 12, 1.05), ("v", 3, 1, 2, 0.3)]),
}


def torus_obj(path, name, nu=12, nv=8, big=2.0, small=0.8):
    """Write the creased torus ``TORI[name]`` (nu x nv quads, faces wound outwards)."""
    method, rings = TORI[name]
    vid = lambda i, j: (i % nu) * nv + (j % nv) + 1  # noqa: E731
    lines = []
    for i in range(nu):
        for j in range(nv):
            a, b = 2 * np.pi * i / nu, 2 * np.pi * j / nv
            w = big + small * np.cos(b)
            lines.append(f"v {w * np.cos(a):.17g} {w * np.sin(a):.17g} {small * np.sin(b):.17g}")
    for i in range(nu):
        for j in range(nv):
            lines.append(f"f {vid(i, j)} {vid(i + 1, j)} {vid(i + 1, j + 1)} {vid(i, j + 1)}")
    for kind, at, first, last, s in rings:
        for k in range(first, last):
            a, b = ((vid(k, at), vid(k + 1, at)) if kind == "u" else (vid(at, k), vid(at, k + 1)))
            lines.append(f"t crease 2/1/0 {a - 1} {b - 1} {s}")
    if method == "chaikin":
        lines.append("t creasemethod 0/0/1 chaikin")
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def tori(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tori")
    return {name: torus_obj(folder / f"{name}.obj", name) for name in TORI}


def _cage(name, tori):
    return subtrace.load_cage(tori[name] if name in TORI else HARD / name)


# ------------------------------------------------------------------------------------------
# the maps against topology
# ------------------------------------------------------------------------------------------


def _isolate(o, faces, cap, eye, tol, maps, monkeypatch):
    """Depths, boxes and pieces of ``faces`` with the crease maps on or off; the levels the
    maps started at. (The grid maps, patches/gridmaps.py, stay off: what the crease maps
    leave goes through topology, the reference, on both paths.)"""
    starts = []
    real = crease.crease_pieces

    def counted(*args, **kw):
        starts.append(args[11] if len(args) > 11 else kw.get("k0", 0))
        return real(*args, **kw)

    monkeypatch.setattr(crease, "ENABLED", maps)
    monkeypatch.setattr(gridmaps, "ENABLED", False)
    monkeypatch.setattr(isolate, "crease_pieces", counted)
    boxes = (np.full((len(faces), 3), np.inf), np.full((len(faces), 3), -np.inf))
    record = {}
    depths = isolated_depths(o, faces, cap, eye, tol, record, 0, boxes)
    out = build_isolated(o, faces, depths, eye, tol, record, ring=True)
    monkeypatch.setattr(crease, "ENABLED", True)
    return depths, boxes, out, starts


def _compare(o, faces, cap, eye, tol, monkeypatch):
    """Both paths on ``faces``: the same depths, boxes, pieces and cells to rounding (the
    maps sum the same weights in another order, a few levels deep; a crease's sharp side
    makes short tangents across it at its corners: unit normals to 1e-9); returns the
    levels the maps started at and the two paths' counts."""
    d0, b0, out0, none = _isolate(o, faces, cap, eye, tol, False, monkeypatch)
    d1, b1, out1, starts = _isolate(o, faces, cap, eye, tol, True, monkeypatch)
    assert not none
    pieces, cells = assert_same_isolation((d0, b0, out0), (d1, b1, out1),
                                          float(np.abs(o.points).max()))
    return starts, pieces, cells


# the cages whose creases end or meet: the maps take over below the root there
BELOW = {"catmark_helmet.obj", "catmark_cubes_semisharp.obj", "catmark_chaikin1.obj", "ends",
         "chaikin_ends"}
CAGES = ["catmark_pawn.obj", "catmark_helmet.obj", "catmark_cubes_semisharp.obj",
         "catmark_chaikin1.obj", *TORI]


@pytest.mark.parametrize("far", [1.5, 8.0], ids=["near", "far"])
@pytest.mark.parametrize("name", CAGES)
def test_maps_isolate_as_the_mesh_does(name, far, tori, monkeypatch):
    """From near (deep: every crease runs out) and far (shallow: cells left along the
    creases) the maps give what topology gives, at the root and below it."""
    cage = _cage(name, tori)
    table = build_patch_table([cage])
    o = table.objects[0]
    sel = np.nonzero(table.is_quad & ~table.regular)[0]
    lo, hi = table.shell_min.min(axis=0), table.shell_max.max(axis=0)
    eye = lo + far * (hi - lo) + np.array([0.1, 0.2, 0.3])
    tol = np.radians(30.0) / 720
    cap = np.clip(wanted_depths(table, eye, tol)[sel], 0, 9).astype(np.int64)
    starts, pieces, cells = _compare(o, table.face[sel], cap, eye, tol, monkeypatch)
    assert pieces > 0
    if far > 2 and name not in ("pair", "chaikin_ends", "spur"):  # (low sharpness: run out)
        assert cells > 0
    at_root = crease.crease_faces(o.level, cage.options, table.face[sel])[0]
    # the maps serve patches at the root where the creases run through, below it elsewhere
    assert (0 in starts) == bool(at_root.any())
    if name in BELOW:
        assert max(starts, default=0) > 0


@pytest.mark.parametrize("depth", [0, 1, 4])
@pytest.mark.parametrize("name", ["pair", "spur"])
def test_at_the_cages_level(name, depth, tori, monkeypatch):
    """The isolation of the cage's own quads (as if they were the patch level): between
    two rings one quad apart, quads creased on two opposite sides (2.5 and 4: the curve
    across has two semi-sharp points); beside a spur on a Chaikin ring, quads left to the
    topology."""
    from types import SimpleNamespace

    cage = _cage(name, tori)
    o = SimpleNamespace(cage=cage, level=cage.base, points=cage.points)
    faces = np.arange(cage.base.n_faces)
    ok, side, s_lo, s_hi = crease.crease_faces(cage.base, cage.options, faces)
    if name == "pair":
        both = ok & (s_lo > 0) & (s_hi > 0)
        assert both.sum() == 12 and sorted({float(s_lo[both][0]), float(s_hi[both][0])}) == [
            2.5, 4]
    else:  # the four quads whose ring's grid line ends at the spur are not the maps'
        assert ok.sum() == 2 * 12 - 4 - 4  # (and the four the spur itself creases)
    lo, hi = cage.points.min(axis=0), cage.points.max(axis=0)
    eye = lo + 1.5 * (hi - lo)
    _, pieces, cells = _compare(o, faces, np.full(len(faces), depth), eye,
                                np.radians(30.0) / 720, monkeypatch)
    assert (pieces > 0) == (depth > 0)
    assert cells > 0 or depth > 1


# ------------------------------------------------------------------------------------------
# which faces qualify
# ------------------------------------------------------------------------------------------


def _qualifies(level, options, f):
    """A plain walk: (ok, side, s_lo, s_hi) of face f (crease_faces' rule). Line k of the
    grid is the edge at corner k opposite side k, side k, and the edge at corner k + 1
    opposite it (a corner of four edges in order: two apart)."""
    fo, fv, veo = level.face_offsets, level.face_verts, level.vert_edge_offsets
    if fo[f + 1] - fo[f] != 4:
        return False, 0, 0.0, 0.0
    corners = [int(v) for v in fv[fo[f]:fo[f] + 4]]
    for v in corners:
        faces = level.vert_faces[level.vert_face_offsets[v]:level.vert_face_offsets[v + 1]]
        if (not level.vert_manifold[v] or len(faces) != 4 or veo[v + 1] - veo[v] != 4
                or level.vert_sharpness[v] != 0):
            return False, 0, 0.0, 0.0
        if any(fo[g + 1] - fo[g] != 4 or level.face_hole[g] for g in faces):
            return False, 0, 0.0, 0.0
    ring = {v: [int(e) for e in level.vert_edges[veo[v]:veo[v] + 4]] for v in corners}
    lines, ends = [], []
    for k in range(4):
        a, b = corners[k], corners[(k + 1) % 4]
        e = int(level.face_edges[fo[f] + k])
        before = ring[a][(ring[a].index(e) + 2) % 4]
        after = ring[b][(ring[b].index(e) + 2) % 4]
        lines.append([float(level.edge_sharpness[x]) for x in (before, e, after)])
        far = lambda x, v: int(sum(level.edge_verts[x]) - v)  # noqa: E731
        ends.append([(far(before, a), before), (far(after, b), after)])
    creased = [len(set(s)) == 1 and 0 < s[0] < INF_SHARP for s in lines]
    if not all(c or s == [0, 0, 0] for c, s in zip(creased, lines)) or not any(creased):
        return False, 0, 0.0, 0.0
    if any(creased[k] and creased[(k + 1) % 4] for k in range(4)):
        return False, 0, 0.0, 0.0
    if options.chaikin and not all(_chaikin_ok(level, lines[k][0], ends[k])
                                   for k in range(4) if creased[k]):
        return False, 0, 0.0, 0.0
    side = creased.index(True)
    return True, side, lines[side][0], lines[(side + 2) % 4][0] if creased[(side + 2) % 4] else 0.0


def _chaikin_ok(level, s, ends):
    """Chaikin's rule gives the line's edges ``s - 1`` at its ends: no other semi-sharp
    edge there but one of ``s``."""
    s32 = np.float32(s)
    veo = level.vert_edge_offsets
    for v, own in ends:
        others = [float(level.edge_sharpness[x]) for x in level.vert_edges[veo[v]:veo[v + 1]]
                  if x != own and 0 < level.edge_sharpness[x] < INF_SHARP]
        if len(others) > 1 or (others and others[0] != s32):
            return False
    return True


@pytest.mark.parametrize("name", ["catmark_helmet.obj", "catmark_chaikin1.obj", *TORI])
def test_the_faces_that_qualify(name, tori):
    cage = _cage(name, tori)
    table = build_patch_table([cage])
    found = 0
    for level in (cage.level_topology(0), table.objects[0].level, cage.level_topology(2),
                  cage.level_topology(3)):
        faces = np.arange(level.n_faces)
        got = crease.crease_faces(level, cage.options, faces)
        want = [_qualifies(level, cage.options, f) for f in faces]
        np.testing.assert_array_equal(got[0], [w[0] for w in want])
        ok = got[0]
        found += int(ok.sum())
        for k in (1, 2, 3):
            np.testing.assert_array_equal(got[k][ok], [w[k] for w in want if w[0]])
    assert found > 0


# ------------------------------------------------------------------------------------------
# against OpenSubdiv
# ------------------------------------------------------------------------------------------

ORACLE_SHAPES = ["catmark_single_crease", "catmark_torus_creases0", "catmark_tent_creases0",
                 "catmark_chaikin0", "catmark_chaikin1", "catmark_cube_creases1",
                 "catmark_cubes_semisharp", "catmark_pyramid_creases1"]


def _bernstein(t):
    return np.array([(1 - t) ** 3, 3 * t * (1 - t) ** 2, 3 * t * t * (1 - t), t ** 3])


@pytest.mark.parametrize("name", ORACLE_SHAPES)
def test_the_pieces_are_opensubdivs_limit_surface(name, monkeypatch):
    """The pieces of the isolation with the maps, evaluated at the oracle's exact samples
    on the patches they cover, give OpenSubdiv's limit points (fractional sharpness 5.7,
    2.8, 1.4, 0.8, 0.2 in catmark_single_crease, Chaikin in catmark_chaikin1)."""
    z = np.load(SHAPES.parent / f"{name}.npz")
    meta = json.loads(str(z["meta"]))
    cage = subtrace.load_cage(SHAPES / f"{name}.obj", scheme=meta["scheme"])
    table = build_patch_table([cage])
    o = table.objects[0]
    sel = np.nonzero(~table.regular)[0]
    starts = []
    real = crease.crease_pieces
    monkeypatch.setattr(isolate, "crease_pieces",
                        lambda *a, **k: starts.append(a[11]) or real(*a, **k))
    (root, level, i0, j0, nets, *_), _ = build_isolated(o, table.face[sel], 10)
    assert starts  # the maps took part
    checked, worst = oracle_distances(table, sel, root, level, i0, j0, nets, z)
    assert checked > 30
    # both exact: rounding in the levels of refinement (a sharp rule's weight off by 1e-3
    # moves points by 1e-4 of the diagonal)
    assert worst <= 1e-13 * meta["bbox_diag"]


@pytest.mark.parametrize("name", ["catmark_helmet.obj", "catmark_rook.obj", "rings"])
def test_the_kernels_chunks_and_threads_change_nothing(name, tori, monkeypatch):
    """The maps' kernel takes its squares in chunks on the thread pool: depths, boxes,
    pieces and cells are the same bit for bit in one call on one thread and in chunks of
    three squares on two."""
    same_in_chunks_and_threads(_cage(name, tori), crease, _isolate, monkeypatch)


def same_in_chunks_and_threads(cage, maps, isolate_with, monkeypatch):
    """The isolation of ``cage``'s irregular quads by ``isolate_with(o, faces, cap, eye,
    tol, True, monkeypatch)`` (depths, boxes, (pieces, cells), the levels the maps started
    at) the same bit for bit in one call on one thread and, with the map kernel of module
    ``maps`` in chunks of three squares, on two."""
    from subtrace.runtime import threads

    table = build_patch_table([cage])
    o = table.objects[0]
    sel = np.nonzero(table.is_quad & ~table.regular)[0]
    lo, hi = table.shell_min.min(axis=0), table.shell_max.max(axis=0)
    eye = lo + 1.5 * (hi - lo) + np.array([0.1, 0.2, 0.3])
    tol = np.radians(30.0) / 720
    cap = np.clip(wanted_depths(table, eye, tol)[sel], 0, 9).astype(np.int64)
    got = []
    for n, chunk in ((1, 10 ** 9), (2, 3)):
        monkeypatch.setattr(maps, "_SQUARES_PER_CHUNK", chunk)
        threads.set_threads(n)
        try:
            got.append(isolate_with(o, table.face[sel], cap, eye, tol, True, monkeypatch))
        finally:
            threads.set_threads(None)
    (d0, b0, (s0, c0), starts), (d1, b1, (s1, c1), _) = got
    assert starts and len(s0[0]) > 0
    np.testing.assert_array_equal(d0, d1)
    for a, b in zip((*b0, *s0, *c0), (*b1, *s1, *c1)):
        np.testing.assert_array_equal(a, b)


def oracle_distances(table, sel, root, level, i0, j0, nets, z):
    """(samples checked, the largest distance): the pieces (``build_isolated``'s of the
    patches ``sel``) evaluated at the oracle's exact samples (``z``, an oracle npz) on the
    patches they cover, against OpenSubdiv's limit points (samples in cells left at an
    extraordinary vertex are not checked)."""
    checked = 0
    worst = 0.0
    for q, uv, P in zip(*(z[k][z["sample_exact_P"] == 1] for k in
                          ("sample_ptex_face", "sample_uv", "sample_P"))):
        for r in np.nonzero(table.ptex[sel] == q)[0]:
            st = (uv - table.ptex_uv0[sel[r]]) / table.ptex_scale[sel[r]]
            if (st < 0).any() or (st > 1).any():
                continue
            mine = np.nonzero(root == r)[0]
            n = np.exp2(level[mine])
            inside = ((i0[mine] <= st[0] * n) & (st[0] * n <= i0[mine] + 1)
                      & (j0[mine] <= st[1] * n) & (st[1] * n <= j0[mine] + 1))
            if inside.any():  # (not in a cell left at an extraordinary vertex)
                a = mine[np.argmax(inside)]
                s, t = st * np.exp2(level[a]) - (i0[a], j0[a])
                X = np.einsum("i,j,ijk->k", _bernstein(s), _bernstein(t), nets[a])
                worst = max(worst, float(np.linalg.norm(X - P)))
                checked += 1
            break
    return checked, worst


# ------------------------------------------------------------------------------------------
# item_sides
# ------------------------------------------------------------------------------------------


def _pairwise_sides(first, count, level, i0, j0, depth, patch_side):
    """item_sides' rule as it was first written: a piece's side on a side of its patch is
    sampled as the patch samples it; inside, every pair of pieces sharing a stretch of a
    line takes the deeper sampling of the two, until nothing changes."""
    out = np.zeros((len(level), 4), np.int64)
    for p in range(len(first)):
        items = range(first[p], first[p] + count[p])
        top = max(level[a] for a in items)
        box = {a: (i0[a] << (top - level[a]), j0[a] << (top - level[a]),
                   1 << (top - level[a])) for a in items}
        for a in items:
            u0, v0, sc = box[a]
            out[a] = depth[a]
            for k, on in enumerate((v0 == 0, u0 + sc == 1 << top, v0 + sc == 1 << top, u0 == 0)):
                if on:  # (a patch side: as the patch samples it, finer or coarser)
                    out[a, k] = patch_side[p, k]
        changed = True
        while changed:
            changed = False
            for a in items:
                (au, av, sa) = box[a]
                for b in items:
                    (bu, bv, sb) = box[b]
                    for ka, kb, touch, lo, hi in (
                            (2, 0, av + sa == bv, max(au, bu), min(au + sa, bu + sb)),
                            (1, 3, au + sa == bu, max(av, bv), min(av + sa, bv + sb))):
                        if touch and lo < hi:
                            m = max(out[a, ka], out[b, kb])
                            if out[a, ka] != m or out[b, kb] != m:
                                out[a, ka] = out[b, kb] = m
                                changed = True
    return out


def _random_layout(rng, patches):
    """Random quadtrees (leaves: dyadic squares tiling each patch), their depths."""
    level, i0, j0, count = [], [], [], []
    for _ in range(patches):
        leaves = [(0, 0, 0)]
        for _ in range(rng.integers(0, 12)):
            k = int(rng.integers(len(leaves)))
            lv, i, j = leaves.pop(k)
            leaves += [(lv + 1, 2 * i + di, 2 * j + dj) for di in (0, 1) for dj in (0, 1)]
        rng.shuffle(leaves)
        count.append(len(leaves))
        level += [lv for lv, _, _ in leaves]
        i0 += [i for _, i, _ in leaves]
        j0 += [j for _, _, j in leaves]
    count = np.array(count, np.int64)
    level = np.array(level, np.int64)
    depth = level + rng.integers(0, 4, len(level))
    return (np.cumsum(count) - count, count, level, np.array(i0, np.int64),
            np.array(j0, np.int64), depth, rng.integers(0, 9, (patches, 4)))


@pytest.mark.parametrize("seed", range(4))
def test_item_sides_joins_the_stretches_the_pairs_join(seed):
    rng = np.random.default_rng(seed)
    layout = _random_layout(rng, 30)
    out = np.empty((len(layout[2]), 4), np.int64)
    item_sides(*layout, out)
    np.testing.assert_array_equal(out, _pairwise_sides(*layout))
    assert (out > layout[5][:, None]).any()  # something was raised


@pytest.mark.parametrize("name", ["rings", "pair", "ends"])
def test_cell_free_depths_count_the_levels_until_the_creases_run_out(name, tori):
    """A patch the maps serve has no cell from the depth at which the larger sharpness of
    its creased lines, one less a level (to 0 from 1 down), is 0; the others have cells at
    every depth."""
    cage = _cage(name, tori)
    table = build_patch_table([cage])
    o = table.objects[0]
    iso = np.nonzero(table.is_quad & ~table.regular)[0]
    free = crease.cell_free_depths(o.level, o.cage.options, table.face[iso])
    ok, _, s_lo, s_hi = crease.crease_faces(o.level, o.cage.options, table.face[iso])
    assert ok.any()
    np.testing.assert_array_equal(free[~ok], crease.CELLS_AT_ANY_DEPTH)
    s = np.maximum(s_lo, s_hi)[ok].astype(np.float64)
    np.testing.assert_array_equal(free[ok], np.ceil(s - 1e-6).astype(np.int64))


def test_a_patch_with_cells_keeps_its_depth_and_a_finer_neighbour_snaps(tori):
    """edge_sampling never raises a patch along a crease while its isolation leaves cells
    (below its cell-free depth): its finer neighbour samples their edge at its depth
    (snapped, ``geometry/snap.py``). Past its creases the patch fans: it keeps its depth
    (within FAN_LEVELS) and samples that side at the neighbour's."""
    from subtrace import config
    from subtrace.patches.criterion import edge_sampling

    table = build_patch_table([_cage("rings", tori)])
    o = table.objects[0]
    iso = np.nonzero(table.is_quad & ~table.regular)[0]
    free = crease.cell_free_depths(o.level, o.cage.options, table.face[iso])
    p = int(iso[np.argmax(free < crease.CELLS_AT_ANY_DEPTH)])
    L = int(free[iso == p][0])
    assert L >= 2
    k = int(np.nonzero(table.edges[p] >= 0)[0][0])
    share = (table.edges == table.edges[p, k])
    q = int(np.nonzero(share.any(axis=1) & (np.arange(table.n_patches) != p))[0][0])
    kq = int(np.nonzero(share[q])[0][0])
    assert table.side_shift[p, k] == table.side_shift[q, kq] == 0
    deep = L + config.FAN_LEVELS - 1
    # past its creases: it fans
    depths = np.zeros(table.n_patches, np.int32)
    depths[p], depths[q] = L, deep
    _, side = edge_sampling(table, depths)
    assert depths[p] == L and depths[q] == deep
    assert side[p, k] == side[q, kq] == deep
    # with cells: it keeps its depth, the neighbour snaps onto it
    for start in (L - 1, L - 2):
        depths = np.zeros(table.n_patches, np.int32)
        depths[p], depths[q] = start, deep
        _, side = edge_sampling(table, depths)
        assert depths[p] == start and depths[q] == deep
        assert side[p, k] == side[q, kq] == start


# ------------------------------------------------------------------------------------------
# the renderer
# ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("tolerance", [4.0, 1.0, 0.25])
@pytest.mark.parametrize("name", ["rings", "chaikin", "ends"])
def test_watertight_from_inside_creased_tori(name, tolerance, tori, monkeypatch):
    """From inside the tube of closed tori with creases of sharpness 3 to 7.5 (rings, their
    ends and crossings; both methods) every ray hits the surface."""
    from shared_data import check_watertight

    starts = []
    real = crease.crease_pieces
    monkeypatch.setattr(isolate, "crease_pieces",
                        lambda *a, **k: starts.append(a[11]) or real(*a, **k))
    check_watertight(tori[name], (2.0, 0.0, 0.0), tolerance, monkeypatch)
    assert starts


@pytest.mark.parametrize("name", ["ends", "catmark_pawn.obj"])
def test_the_same_image_on_one_and_two_threads(name, tori):
    mesh = tori[name] if name in TORI else HARD / name
    cage = subtrace.load_cage(mesh)
    lo, hi = cage.bounds()
    mid = 0.5 * (lo + hi)
    scene = small_scene([mesh], mid + 0.7 * (hi - lo), mid, width=96, height=72, tolerance=0.5)
    one = render_scene(scene, cages=[cage], threads=1)
    two = render_scene(scene, cages=[cage], threads=2)
    assert one.stats.pixels_covered > 1000
    for key, channel in one.channels.items():
        assert channel.tobytes() == two.channels[key].tobytes(), key


@pytest.mark.parametrize("name", ["catmark_rook.obj", "catmark_helmet.obj", "rings", "ends",
                                  "chaikin", "pair"])
def test_evaluate_takes_the_closed_form_along_creases(name, tori, monkeypatch):
    """``Cage.evaluate`` retires a sample on a quad the maps serve in closed form
    (``crease.crease_derivatives``) instead of refining it until the sharpness runs out:
    at random points, a third of them within 0.1 % of a side, the same points and
    derivatives as the descent through topology alone (``crease.ENABLED`` False, checked
    against OpenSubdiv in tests/test_oracle.py) to rounding, and the closed form served
    some of them."""
    from subtrace.patches import evaluate as ev
    from subtrace.patches.evaluate import ptex_starts

    cage = _cage(name, tori)
    rng = np.random.default_rng(11)
    m = 600
    ptex = rng.integers(0, ptex_starts(cage)[-1], m)
    uv = rng.random((m, 2))
    uv[: m // 3, 1] *= 1e-3
    served = []
    real = ev.crease_derivatives

    def counted(*args):
        out = real(*args)
        served.append(int(out[0].sum()))
        return out

    monkeypatch.setattr(ev, "crease_derivatives", counted)
    P1, du1, dv1 = cage.evaluate(ptex, uv)
    assert sum(served) > 0
    monkeypatch.setattr(crease, "ENABLED", False)
    P0, du0, dv0 = cage.evaluate(ptex, uv)
    live = ~np.isnan(P0[:, 0])
    assert live.sum() > m // 2
    scale = float(np.abs(cage.points).max())
    np.testing.assert_allclose(P1[live], P0[live], rtol=0, atol=1e-13 * scale)
    # (the descent's derivatives on creased faces at its last level are finite differences
    # of exact points, good to about 1e-10 of their length)
    for a, b in ((du1, du0), (dv1, dv0)):
        size = np.linalg.norm(b[live], axis=1)
        assert (np.linalg.norm(a[live] - b[live], axis=1) <= 1e-8 * size + 1e-12 * scale).all()
