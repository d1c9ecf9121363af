"""The lazy patch table (``render.table_in_view``, ``patches.table.build_patch_table``
with ``keep`` and ``in_view``): only the patches a primary ray may reach are built, they
are exactly the whole cage's patches, and the image does not change. A large cage seen in
part builds its topology only around those (``patches.table.restrict``,
``Cage.restricted``), with the same patches and image."""

from __future__ import annotations

import numpy as np
import pytest
from shared_data import MODELS, SHAPES, small_scene

import subtrace
from subtrace import config
from subtrace.camera import camera_frame
from subtrace.mesh.cage import RESTRICT_RINGS, face_rings, lowest_limit
from subtrace.patches.shells import face_ring_boxes, face_star_boxes, one_ring_shells
from subtrace.patches.table import build_patch_table, cage_face_shells
from subtrace.patches.evaluate import ptex_starts
from subtrace.patches.table import restrict
from subtrace.render import faces_in_view, render_scene, table_in_view

SWORD = MODELS / "sword_quad_dominant.obj"
# looking at the sword's tip: about a tenth of its cage faces reach the image
TIP_EYE, TIP_TARGET, TIP_FOV = (1.543, 0.6184, 0.4523), (0.0, 0.0, -0.4), 2.6


def _rows_in(full, table):
    """Each patch of ``table`` as its row in ``full`` (patches keyed by ptex face and
    origin)."""
    row = {k: i for i, k in enumerate(zip(full.ptex.tolist(), map(tuple, full.ptex_uv0)))}
    return np.array([row[k] for k in zip(table.ptex.tolist(), map(tuple, table.ptex_uv0))])


def _in_view_naive(lo, hi, camera):
    """(N,) bool: whether a box reaches the image, in plain numpy: any of its corners is
    not in front of the eye plane (then it may reach every pixel), or the rectangle of its
    corners' projections meets the image widened by 1.5 pixels (the cull keeps a pixel of
    rounding margin around each box's rectangle)."""
    frame = camera_frame(camera)
    bits = [np.array([(k >> a) & 1 for a in range(3)], bool) for k in range(8)]
    corners = np.stack([np.where(b, hi, lo) for b in bits], axis=1) - frame[0]
    basis = np.stack([frame[3], frame[1], frame[2]], axis=1)
    a = corners @ np.linalg.inv(basis).T  # (N, 8, 3): depth, column * depth, row * depth
    front = (a[..., 0] > 0).all(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        col, row = a[..., 1] / a[..., 0], a[..., 2] / a[..., 0]
    meets = ((col.min(axis=1) <= camera.width - 0.5 + 1.5) & (col.max(axis=1) >= -0.5 - 1.5)
             & (row.min(axis=1) <= camera.height - 0.5 + 1.5)
             & (row.max(axis=1) >= -0.5 - 1.5))
    return ~front | meets


def _tip_scene(width=96, height=54):
    return small_scene([SWORD], TIP_EYE, TIP_TARGET, width=width, height=height, fov=TIP_FOV)


_BOX_CAGES = ("sword_quad_dominant", "hole_capsule", "catmark_edgecorner",
              "catmark_nonman_edges", "loop_triangle_edgeonly")


def _shared_cage(name):
    path = MODELS / f"{name}.obj"
    return subtrace.load_cage(path if path.exists() else SHAPES / f"{name}.obj")


@pytest.mark.parametrize("name", _BOX_CAGES)
def test_face_ring_boxes_are_the_one_ring_shells(name):
    """The per-vertex construction of the cage faces' boxes gives the one-ring boxes, and
    so does the one from the face lists alone (no topology: what a large cage seen in part
    culls by), on manifold, holed, non-manifold and Loop cages."""
    cage = _shared_cage(name)
    offsets = np.r_[0, np.cumsum(cage.face_sizes)].astype(np.int64)
    lo0, hi0 = face_star_boxes(offsets, cage.face_verts, cage.points)
    assert not cage.has_topology
    lo, hi = face_ring_boxes(cage.base, cage.points)
    lo2, hi2, _, _ = one_ring_shells(cage.base, np.arange(cage.n_faces), cage.points)
    assert np.array_equal(lo, lo2) and np.array_equal(hi, hi2)
    assert np.array_equal(lo0, lo) and np.array_equal(hi0, hi)


def _rings_naive(cage, faces, rings):
    """Faces within ``rings`` rings of ``faces``, one face and vertex at a time."""
    sizes = cage.face_sizes.tolist()
    starts = np.r_[0, np.cumsum(sizes)]
    verts = [set(cage.face_verts[a:b].tolist()) for a, b in zip(starts[:-1], starts[1:])]
    sel = set(np.nonzero(faces)[0].tolist())
    for _ in range(rings):
        mark = set().union(*(verts[f] for f in sel)) if sel else set()
        sel = {f for f in range(len(sizes)) if verts[f] & mark}
    out = np.zeros(len(sizes), bool)
    out[list(sel)] = True
    return out


@pytest.mark.parametrize("name", _BOX_CAGES[1:])
def test_face_rings_are_the_faces_around(name):
    """``face_rings`` (from the face lists) against a plain set construction."""
    cage = _shared_cage(name)
    rng = np.random.default_rng(len(name))
    for rings in (0, 1, RESTRICT_RINGS):
        faces = rng.random(cage.n_faces) < 0.05
        assert np.array_equal(face_rings(cage, faces, rings), _rings_naive(cage, faces, rings))


def _restricting(monkeypatch):
    """Restrict every cage seen in part, whatever its size and share in view."""
    monkeypatch.setattr(config, "LAZY_TOPOLOGY_FACES", 0)
    monkeypatch.setattr(config, "LAZY_TOPOLOGY_SHARE", 1.0)


@pytest.mark.parametrize("tris,ngons,boundary", [(False, False, 1), (False, True, 0),
                                                 (False, True, 2), (True, False, 2),
                                                 (True, False, 1)],
                         ids=["catmark", "ngons-none", "ngons-edgeonly", "loop", "loop-corner"])
def test_a_restricted_cage_has_the_whole_cages_patches(tmp_path, monkeypatch, tris, ngons,
                                                      boundary):
    """A cage cut to the faces on one side of a plane and ``RESTRICT_RINGS`` rings around
    them: the table of those faces is the whole cage's (same ptex ids, shells, length
    bounds, rates, nets, materials), and the cage's own topology is never built. Grids with
    boundaries, semi-sharp and infinitely sharp creases, a corner, a hole, n-gons and
    extraordinary vertices, in each boundary mode, Catmull-Clark and Loop."""
    _restricting(monkeypatch)
    path = _feature_grid(tmp_path / "grid.obj", 40, tris, False, ngons, boundary)
    full = build_patch_table([subtrace.load_cage(path)])
    cage = subtrace.load_cage(path)
    assert (cage.face_sizes > 4).any() == ngons
    starts = np.r_[0, np.cumsum(cage.face_sizes)[:-1]]
    centre = np.array([cage.points[cage.face_verts[a:a + n]].mean(axis=0)
                       for a, n in zip(starts, cage.face_sizes)])
    rng = np.random.default_rng(7)
    for _ in range(3):
        d = centre @ rng.standard_normal(3)
        keep = d < np.quantile(d, rng.uniform(0.1, 0.4))
        sub, sub_keep = restrict(cage, keep)
        assert sub.n_faces == np.count_nonzero(face_rings(cage, keep, RESTRICT_RINGS))
        assert sub.n_faces < cage.n_faces and np.count_nonzero(sub_keep) == keep.sum()
        table = build_patch_table([sub], [sub_keep])
        assert table.n_patches > 0
        rows = _rows_in(full, table)
        for field in ("shell_min", "shell_max", "edge_bound", "rate", "regular", "is_quad",
                      "material", "ptex_scale"):
            assert np.array_equal(getattr(table, field), getattr(full, field)[rows]), field
        reg_rank = np.cumsum(full.regular) - 1
        assert np.array_equal(table.nets, full.nets[reg_rank[rows[table.regular]]])
        # every patch of the kept faces (and no other): the whole table's of those faces
        full_face = np.repeat(np.arange(cage.n_faces), np.diff(
            ptex_starts(cage)))[full.ptex]
        assert np.array_equal(np.sort(rows), np.nonzero(keep[full_face])[0])
    assert not cage.has_topology


def test_cage_face_boxes_hold_their_patches_shells():
    """A cage face's box holds the one-ring boxes of its level-1 patches (their points are
    convex combinations of its one-ring's), so culling by it never drops a visible patch."""
    cage = subtrace.load_cage(SWORD)
    lo, hi = cage_face_shells(cage)
    table = build_patch_table([cage])
    lev = cage.level_topology(1)
    l1, h1, _, _ = one_ring_shells(lev, table.face, cage.refine(1).points)
    parent = np.repeat(np.arange(cage.n_faces), np.diff(cage.base.face_offsets))[table.face]
    # (the level-1 points are convex combinations rounded once per operation: a few ulps
    # of the coordinates may stick out)
    scale = np.abs(cage.points).max()
    assert np.all(l1 >= lo[parent] - 1e-15 * scale)
    assert np.all(h1 <= hi[parent] + 1e-15 * scale)


def test_only_patches_in_view_are_built():
    """Looking at the sword's tip: the table holds every patch whose shell reaches the
    image (a plain-numpy projection of the whole cage's shells), few more, the same shells
    and nets as the whole cage's table, and the image is the one without the cull."""
    cage = subtrace.load_cage(SWORD)
    full = build_patch_table([cage])
    scene = _tip_scene()
    cam = scene.make_camera()
    needed = _in_view_naive(full.shell_min, full.shell_max, cam)
    assert 0.02 < needed.mean() < 0.2  # the frame shows a small part of the sword
    res = render_scene(scene, cages=[cage])
    st = res.stats
    assert st.faces_culled > 0.8 * cage.n_faces
    assert st.patches < 0.25 * full.n_patches
    assert np.count_nonzero(needed) <= st.patches <= 1.5 * np.count_nonzero(needed)
    # the culled table: a subset of the whole table holding the needed patches, each with
    # the same shell and net
    lazy, _ = table_in_view([cage], cam)
    assert lazy.n_patches == st.patches
    rows = _rows_in(full, lazy)
    assert set(np.nonzero(needed)[0]) <= set(rows.tolist())
    for name in ("shell_min", "shell_max", "edge_bound", "rate", "regular", "material"):
        assert np.array_equal(getattr(lazy, name), getattr(full, name)[rows]), name
    reg_rank = np.cumsum(full.regular) - 1
    assert np.array_equal(lazy.nets, full.nets[reg_rank[rows[lazy.regular]]])
    _same_image_without_cull(scene, [cage], res)


def _same_image_without_cull(scene, cages, res):
    """The image of ``scene`` rendered with every patch built equals ``res``'s."""
    saved = config.CULL_TO_VIEW
    config.CULL_TO_VIEW = False
    try:
        ref = render_scene(scene, cages=cages)
    finally:
        config.CULL_TO_VIEW = saved
    assert ref.stats.faces_culled == 0
    for name, plane in ref.channels.items():
        np.testing.assert_array_equal(res.channels[name], plane, err_msg=name)


def _feature_grid(path, n, tris, chaikin, ngons=False, boundary=1):
    """An n x n bumpy grid (quads, or each split into two triangles) with boundaries, a
    semi-sharp crease line across it (sharpness 2.5, Chaikin or uniform decay), an
    infinitely sharp one, a sharp corner and a hole, as an OBJ with OpenSubdiv tags.
    ``ngons``: every fifth pair of quads in a row merged into a hexagon (two vertices of
    valence 3 each); ``boundary``: the interpolateboundary mode."""
    rng = np.random.default_rng(n)
    lines = []
    idx = lambda i, j: i * (n + 1) + j  # noqa: E731
    for i in range(n + 1):
        for j in range(n + 1):
            lines.append(f"v {j / n} {i / n} {0.05 * rng.standard_normal()}")
    faces = []
    for i in range(n):
        for j in range(n):
            a, b, c, d = idx(i, j), idx(i, j + 1), idx(i + 1, j + 1), idx(i + 1, j)
            if ngons and j % 5 == 1 and j + 1 < n:
                faces.append((a, b, idx(i, j + 2), idx(i + 1, j + 2), c, d))
            elif ngons and j % 5 == 2 and j > 0:
                continue
            else:
                faces += [(a, b, c), (a, c, d)] if tris else [(a, b, c, d)]
    lines += ["f " + " ".join(str(v + 1) for v in f) for f in faces]
    row = n // 3
    lines += [f"t crease 2/1/0 {idx(row, j)} {idx(row, j + 1)} 2.5" for j in range(n)]
    lines += [f"t crease 2/1/0 {idx(i, row)} {idx(i + 1, row)} 10" for i in range(n)]
    lines += [f"t corner 1/1/0 {idx(n // 2, n // 2)} 3", f"t hole 1/0/0 {len(faces) // 2 + 3}",
              f"t interpolateboundary 1/0/0 {boundary}"]
    if chaikin:
        lines.append("t creasemethod 0/0/1 chaikin")
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("tris", [False, True], ids=["catmark", "loop"])
@pytest.mark.parametrize("chaikin", [False, True], ids=["uniform", "chaikin"])
@pytest.mark.parametrize("target", [(0.33, 0.33), (0.5, 0.5), (0.0, 0.0), (0.95, 0.6)])
@pytest.mark.parametrize("restricted", [False, True], ids=["whole", "restricted"])
def test_partial_views_of_feature_cages_are_unchanged(tmp_path, monkeypatch, tris, chaikin,
                                                      target, restricted):
    """Creases (semi-sharp, Chaikin or not, and infinitely sharp), a corner, boundaries and
    a hole, in Catmull-Clark and Loop cages seen in part: some faces are culled and the
    image is the one of the whole table, with the cage's topology built whole or only
    around the faces in view (``restricted``; a Chaikin cage is never restricted: its
    cull's margin needs its edges' sharpness)."""
    if restricted:
        _restricting(monkeypatch)
    mesh = _feature_grid(tmp_path / "grid.obj", 24, tris, chaikin)
    cage = subtrace.load_cage(mesh)
    assert cage.scheme == ("loop" if tris else "catmark")
    eye = (target[0] + 0.3, target[1] - 0.4, 1.2)
    scene = small_scene([mesh], eye, (*target, 0.0), fov=20.0)
    res = render_scene(scene, cages=[cage])
    assert 0 < res.stats.faces_culled < cage.n_faces
    assert res.stats.pixels_covered > 0
    assert cage.has_topology == (chaikin or not restricted)
    _same_image_without_cull(scene, [subtrace.load_cage(mesh)], res)


def test_object_out_of_view_builds_nothing(tmp_path):
    """Invariant 5: a second sword beside the view, or behind the eye, adds no patch."""
    cage = subtrace.load_cage(SWORD)
    scene = _tip_scene(48, 27)
    alone = render_scene(scene, cages=[cage]).stats
    for shift in ((0.0, 1.0, 0.0), (3.0, 1.2, 0.9)):  # (beside; behind the eye)
        other = subtrace.make_cage(cage.points + shift, cage.face_sizes, cage.face_verts)
        both = small_scene([SWORD, SWORD], TIP_EYE, TIP_TARGET, width=48, height=27,
                           fov=TIP_FOV)
        res = render_scene(both, cages=[cage, other])
        assert res.stats.patches == alone.patches
        assert res.stats.faces_culled == alone.faces_culled + other.n_faces
        assert np.all(res.refined_objects == 0)


def test_nothing_in_view_renders_the_background(tmp_path):
    """A cage wholly behind the eye: no patch, every pixel a miss."""
    cage = subtrace.make_cage([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [4], [0, 1, 2, 3])
    obj = tmp_path / "quad.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
    scene = small_scene([obj], (2.0, 0.5, 0.0), (5.0, 0.5, 0.0), width=16, height=12)
    res = render_scene(scene, cages=[cage])
    assert res.stats.patches == 0 and res.stats.faces_culled == 1
    assert np.all(res.channels["object_id"] < 0) or np.all(res.channels["A"] == 0)


def test_level_one_patches_out_of_view_are_left_out():
    """On a coarse cage seen close, a kept face's level-1 quads whose own one-ring box
    misses the image are not built either; the image is unchanged."""
    mesh = MODELS / "spot_control_mesh.obj"
    cage = subtrace.load_cage(mesh)
    scene = small_scene([mesh], (0.3, 0.45, 1.0), (0.0, 0.3, 0.2), fov=12.0)
    res = render_scene(scene, cages=[cage])
    kept = cage.n_faces - res.stats.faces_culled
    quads_kept = int(np.sum(np.diff(cage.base.face_offsets)[
        faces_in_view([cage], scene.make_camera())[0]]))
    assert 0 < kept < cage.n_faces
    assert 0 < res.stats.patches < quads_kept  # (a kept face has one patch per corner)
    _same_image_without_cull(scene, [cage], res)


@pytest.mark.parametrize("tris,ngons,boundary", [(False, True, 1), (False, False, 0),
                                                 (True, False, 2)],
                         ids=["catmark", "catmark-none", "loop"])
def test_the_lowest_limit_point_is_found_around_the_lowest_faces(tmp_path, monkeypatch, tris,
                                                                  ngons, boundary):
    """``lowest_limit`` (the automatic ground's height) is the least of the level-1 limit
    points along ``up``, bit for bit, made from a cut of the cage around its lowest faces;
    for several directions on grids with creases, a corner, a hole, n-gons, boundaries."""
    _restricting(monkeypatch)
    path = _feature_grid(tmp_path / "grid.obj", 30, tris, False, ngons, boundary)
    whole = subtrace.load_cage(path).limit(1)[0]
    rng = np.random.default_rng(3)
    for up in [(0.0, 0.0, 1.0), (0.0, 0.0, -1.0), (1.0, 0.0, 0.0), *rng.standard_normal((4, 3))]:
        up = np.asarray(up) / np.linalg.norm(up)
        cage = subtrace.load_cage(path)
        assert lowest_limit(cage, up) == float((whole @ up).min())
        assert not cage.has_topology  # (the cut's, not the cage's)


def test_a_ground_under_a_partial_view_builds_no_whole_topology():
    """The sword seen at its tip above an automatic ground: the ground's height comes from
    a cut around the sword's lowest faces, the cage's own topology is never built (before,
    the whole cage was refined once for it), and the image is the full table's."""
    from dataclasses import replace

    from subtrace.io.scene import Ground

    cage = subtrace.load_cage(SWORD)
    scene = replace(small_scene([SWORD], TIP_EYE, TIP_TARGET, width=64, height=36,
                                fov=TIP_FOV), ground=Ground(height=None, color=(0.6, 0.6, 0.6)))
    res = render_scene(scene, cages=[cage])
    assert res.stats.faces_culled > 0.8 * cage.n_faces
    assert not cage.has_topology
    _same_image_without_cull(scene, [subtrace.load_cage(SWORD)], res)


def test_the_ground_and_the_cull_share_one_computation_of_the_face_boxes(monkeypatch):
    """The sword's tip under a sun over an automatic ground: the ground's height (its
    lowest faces) and the cull (the faces in view) both need every face's star box; they
    are made once per render, read-only, and not kept after the render's set-up."""
    from dataclasses import replace

    import subtrace.mesh.cage as cage_module
    from subtrace.io.scene import Ground, Light

    made = []

    def counted(*args):
        made.append(1)
        return face_star_boxes(*args)

    monkeypatch.setattr(cage_module, "face_star_boxes", counted)
    cage = subtrace.load_cage(SWORD)
    scene = replace(small_scene([SWORD], TIP_EYE, TIP_TARGET, width=64, height=36,
                                fov=TIP_FOV), ground=Ground(height=None, color=(0.6, 0.6, 0.6)),
                    lights=(Light(direction=(-0.4, -1.0, -0.5), intensity=0.5),))
    res = render_scene(scene, cages=[cage])
    assert res.stats.faces_culled > 0.8 * cage.n_faces and res.stats.shadow_rays > 0
    assert len(made) == 1
    assert "star_boxes" not in cage._cache and "sharing" not in cage._cache
    with cage.sharing_star_boxes():
        lo, hi = cage.star_boxes
        assert cage.star_boxes[0] is lo and not lo.flags.writeable
        with pytest.raises(ValueError):
            hi[0, 0] = 0.0
    assert cage.star_boxes[0] is not lo  # (made again: not kept)
    assert np.array_equal(cage.star_boxes[0], lo)


@pytest.mark.parametrize("n", [1, 1000, 60_000])
def test_the_points_box_is_numpys_min_and_max(n):
    """``Cage.points_box`` (one pass of a kernel on a large cage) equals NumPy's reductions,
    NaN where a coordinate is NaN."""
    from subtrace.mesh.cage import _points_box

    rng = np.random.default_rng(n)
    pts = rng.standard_normal((n, 3)) * 10.0 ** rng.integers(-3, 4, (n, 1))
    for p in (pts, np.asfortranarray(pts)):
        lo, hi = _points_box(p)
        assert np.array_equal(lo, p.min(axis=0)) and np.array_equal(hi, p.max(axis=0))
    pts[n // 2, 1] = np.nan
    lo, hi = _points_box(pts)
    assert np.array_equal(lo, pts.min(axis=0), equal_nan=True) and np.isnan(hi[1])
    assert not np.isnan(lo[0]) and not np.isnan(hi[2])


def test_the_lowest_limit_point_is_not_taken_at_the_lowest_control_point(monkeypatch):
    """A flat grid with one control point pulled far down (its limit surface dips to
    about 4/9 of it) and, far from it, a broad valley half as deep (its limit surface
    reaches the valley's floor): the lowest limit point is the valley's, found although
    the faces around the pulled point have the lowest boxes."""
    _restricting(monkeypatch)
    n = 40
    xs, ys = np.meshgrid(np.arange(n + 1) / n, np.arange(n + 1) / n, indexing="ij")
    z = np.zeros((n + 1, n + 1))
    z[5, 5] = -1.0
    z[26:34, 26:34] = -0.5
    points = np.c_[xs.ravel(), ys.ravel(), z.ravel()]
    quads = [(i * (n + 1) + j, i * (n + 1) + j + 1, (i + 1) * (n + 1) + j + 1,
              (i + 1) * (n + 1) + j) for i in range(n) for j in range(n)]
    cage = subtrace.make_cage(points, [4] * len(quads), np.ravel(quads))
    up = np.array([0.0, 0.0, 1.0])
    low = lowest_limit(cage, up)
    assert low == float((subtrace.make_cage(points, [4] * len(quads),
                                            np.ravel(quads)).limit(1)[0] @ up).min())
    assert abs(low + 0.5) < 1e-12  # the valley's floor (the pulled point dips to -0.44)


@pytest.mark.parametrize("name", ["pawn", "rook", "car", "helmet"])
def test_the_lowest_limit_of_a_creased_cage_skips_no_lower_vertex(name, monkeypatch):
    """On OpenSubdiv's hard-surface cages (semi-sharp creases of sharpness 6-8, whose
    vertices' limits take repeated refinement), ``lowest_limit`` is the least of all level-1
    limit points bit for bit in several directions, though it refines only the creased
    vertices whose faces reach lower than the others' least (a flat bottom: none)."""
    from subtrace.subdiv import limit

    path = MODELS / "opensubdiv" / f"catmark_{name}.obj"
    whole = subtrace.load_cage(path).limit(1)[0]
    refined = []
    real = limit._hard_limits
    monkeypatch.setattr(limit, "_hard_limits",
                        lambda lev, pts, opts, hard, *a, **k: (refined.append(len(hard)),
                                                               real(lev, pts, opts, hard, *a,
                                                                    **k)))
    rng = np.random.default_rng(5)
    for up in [(0.0, 1.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, 1.0), *rng.standard_normal((4, 3))]:
        up = np.asarray(up) / np.linalg.norm(up)
        assert lowest_limit(subtrace.load_cage(path), up) == float((whole @ up).min())
    n_hard = int((limit.classify(subtrace.load_cage(path).level_topology(1),
                                 subtrace.load_cage(path).options) < 0).sum())
    assert n_hard > 0 and sum(refined) < 7 * n_hard / 4
