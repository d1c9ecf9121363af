"""Adaptive renderer: grids against uniform refinement, shells, watertightness, laziness,
accuracy against the exact evaluator, and the EXR written by ``subtrace render``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import subtrace
from subtrace import config
from subtrace.io.scene import scene_from_dict
from subtrace.patches.grids import build_grids, leaf_corners
from subtrace.patches.table import build_patch_table
from subtrace.render import render_scene

SHARED = Path(__file__).resolve().parents[2] / "shared"
MODELS = SHARED / "models"
SHAPES = SHARED / "oracle" / "shapes"

needs_shared = pytest.mark.skipif(not MODELS.is_dir(), reason="../shared/models not present")

GRID_SHAPES = [
    "catmark_cube_creases1", "catmark_cubes_semisharp", "catmark_chaikin1", "catmark_edgenone",
    "catmark_edgecorner", "catmark_hole_test2", "catmark_nonman_verts", "catmark_nonquads",
    "catmark_pole8", "catmark_val2_interior", "loop_cube_creases1", "loop_saddle_edgecorner",
    "loop_icosahedron", "loop_triangle_edgeonly",
]


def _load(name):
    path = SHAPES / f"{name}.obj"
    if not path.exists():
        pytest.skip(f"{path} not present")
    return subtrace.load_cage(path)


@needs_shared
@pytest.mark.parametrize("name", GRID_SHAPES)
def test_grids_equal_uniform_refinement(name):
    """Grids built by sparse local refinement are bit-identical to the limit points of a
    uniform refinement (same arithmetic in the same order), so two patches that share a
    vertex at the same depth share it exactly."""
    cage = _load(name)
    L0 = 1 if cage.scheme == "catmark" else 0
    lev = cage.level_topology(L0)
    faces = np.nonzero(~lev.face_hole)[0]
    faces = faces[:: max(1, len(faces) // 6)]
    quad = cage.scheme == "catmark"
    k = 4 if quad else 3
    for depth in (0, 2):
        P, _ = build_grids(lev, cage.refine(L0).points, cage.options, faces, depth)
        ref, _, _ = cage.limit(L0 + depth)
        fine = cage.level_topology(L0 + depth)
        m = 4**depth
        slot = leaf_corners(depth, quad)
        for a, f in enumerate(faces):
            leaves = f * m + np.arange(m)
            cv = fine.face_verts[fine.face_offsets[leaves][:, None] + np.arange(k)]
            np.testing.assert_array_equal(P[a][slot], ref[cv])


@needs_shared
@pytest.mark.parametrize("name", GRID_SHAPES)
def test_shells_contain_limit_grids(name):
    """Invariant 2: the shell of every patch contains the exact limit points of its grid."""
    cage = _load(name)
    table = build_patch_table([cage])
    o = table.objects[0]
    P, _ = build_grids(o.level, o.points, cage.options, table.face, 3)
    assert np.all(P >= table.shell_min[:, None, :] - 1e-12)
    assert np.all(P <= table.shell_max[:, None, :] + 1e-12)


def _perturbed(name, seed):
    """The oracle shape ``name`` with its points moved at random (any positions are valid)."""
    base = _load(name)
    rng = np.random.default_rng(seed)
    pts = base.points + rng.normal(scale=0.3, size=base.points.shape)
    return subtrace.make_cage(
        pts, base.face_sizes, base.face_verts, base.scheme, boundary=base.options.boundary,
        smooth_triangles=base.options.smooth_triangles,
    )


@needs_shared
@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), name=st.sampled_from(GRID_SHAPES))
def test_shells_contain_limit_of_perturbed_cages(seed, name):
    """Same, for random perturbations of the cage points (any positions are valid)."""
    cage = _perturbed(name, seed)
    table = build_patch_table([cage])
    o = table.objects[0]
    P, _ = build_grids(o.level, o.points, cage.options, table.face, 2)
    assert np.all(P >= table.shell_min[:, None, :] - 1e-12)
    assert np.all(P <= table.shell_max[:, None, :] + 1e-12)


def _isolated_shells(cage, tol_rad):
    """The patch table and the shells the depth choice tightens (eye on the +z side, three
    bounding-box diagonals away), with the patches it tightened."""
    from subtrace.patches.criterion import choose_depths

    table = build_patch_table([cage])
    lo, hi = table.shell_min.copy(), table.shell_max.copy()
    centre = 0.5 * (lo.min(axis=0) + hi.max(axis=0))
    eye = centre + np.array([0.0, 0.0, 3.0 * np.linalg.norm(hi.max(axis=0) - lo.min(axis=0))])
    choose_depths(table, eye, tol_rad, config.MAX_GRID_DEPTH, {}, (lo, hi))
    changed = np.any(lo != table.shell_min, axis=1) | np.any(hi != table.shell_max, axis=1)
    return table, lo, hi, changed


ISOLATED_SHAPES = [n for n in GRID_SHAPES if n.startswith("catmark")]


@needs_shared
@pytest.mark.parametrize("name", ISOLATED_SHAPES)
def test_isolated_shells_contain_limit_grids(name):
    """Invariant 2 for the shells tightened by the depth choice's isolation (the union of
    the Bezier boxes and one-ring boxes of what an irregular patch was refined into): the
    exact limit points of a depth-5 grid of every patch lie inside, and the tightened ones
    are much smaller than the patches' one-ring boxes (else the tightening does nothing)."""
    cage = _load(name)
    table, lo, hi, changed = _isolated_shells(cage, 1e-4)
    assert changed.any() == bool((~table.regular).any())
    o = table.objects[0]
    P, _ = build_grids(o.level, o.points, cage.options, table.face, 5)
    assert np.all(P >= lo[:, None, :] - 1e-12)
    assert np.all(P <= hi[:, None, :] + 1e-12)
    if changed.any():
        old = np.prod(table.shell_max[changed] - table.shell_min[changed], axis=1)
        new = np.prod(hi[changed] - lo[changed], axis=1)
        assert np.median(new / np.where(old > 0, old, 1.0)) < 0.5


@needs_shared
@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), name=st.sampled_from(ISOLATED_SHAPES),
       tol_exp=st.floats(-5.0, -1.0))
def test_isolated_shells_contain_limit_of_perturbed_cages(seed, name, tol_exp):
    """Same, for random perturbations of the cage points and tolerances (each tolerance
    stops the isolation at other levels, so other boxes end the union)."""
    cage = _perturbed(name, seed)
    table, lo, hi, _ = _isolated_shells(cage, 10.0**tol_exp)
    o = table.objects[0]
    P, _ = build_grids(o.level, o.points, cage.options, table.face, 4)
    assert np.all(P >= lo[:, None, :] - 1e-12)
    assert np.all(P <= hi[:, None, :] + 1e-12)


@needs_shared
def test_isolated_shells_contain_spot():
    """On Spot (many extraordinary vertices), at about a pixel of the default scene."""
    cage = subtrace.load_cage(MODELS / "spot_control_mesh.obj")
    table, lo, hi, changed = _isolated_shells(cage, 1e-3)
    assert changed.sum() > 100
    o = table.objects[0]
    P, _ = build_grids(o.level, o.points, cage.options, table.face, 4)
    assert np.all(P >= lo[:, None, :] - 1e-12)
    assert np.all(P <= hi[:, None, :] + 1e-12)


def _scene(meshes, eye, target, width=64, height=48, fov=60.0, tolerance=1.0, colors=None):
    objects = [{"mesh": str(m)} for m in meshes]
    for o, c in zip(objects, colors or []):
        o["color"] = c
    return scene_from_dict(
        {
            "object": objects,
            "camera": {"eye": list(eye), "target": list(target), "fov": fov, "width": width,
                       "height": height},
            "render": {"tolerance": tolerance},
        }
    )


WATERTIGHT = [
    (MODELS / "spot_control_mesh.obj", (0.0, 0.05, 0.2)),
    (MODELS / "blub_control_mesh.obj", None),
    (MODELS / "torus.obj", None),
    (SHAPES / "catmark_cube_creases1.obj", None),
]


@needs_shared
@pytest.mark.parametrize("tolerance", [4.0, 1.0, 0.25])
@pytest.mark.parametrize("mesh,eye", WATERTIGHT, ids=lambda x: getattr(x, "stem", ""))
def test_watertight_from_inside(mesh, eye, tolerance, monkeypatch):
    """Invariant 4: from inside a closed surface every ray hits it (zero misses), whatever
    the tolerance and however differently neighbouring patches are refined."""
    monkeypatch.setattr(config, "MAX_GRID_DEPTH", 5)  # the eye sits inside nearby shells
    cage = subtrace.load_cage(mesh)
    if eye is None:
        # a point inside: the middle of the limit surface along a ray through the centre
        eye = _inside_point(cage)
    scene = _scene([mesh], eye, np.asarray(eye) + [0.3, 0.1, 1.0], fov=120.0, width=48,
                   height=36, tolerance=tolerance)
    res = render_scene(scene, cages=[cage])
    A = res.channels["A"]
    assert np.count_nonzero(A == 0) == 0
    # and looking the other way
    scene = _scene([mesh], eye, np.asarray(eye) - [0.3, 0.1, 1.0], fov=120.0, width=48,
                   height=36, tolerance=tolerance)
    assert np.count_nonzero(render_scene(scene, cages=[cage]).channels["A"] == 0) == 0


def _first_hit(cage, eye, direction):
    eye = np.asarray(eye, dtype=np.float64)
    scene = _scene([cage.path], eye, eye + direction, width=1, height=1, fov=1.0)
    t = float(render_scene(scene, cages=[cage]).channels["Z"][0, 0])
    assert np.isfinite(t)
    return eye + t * direction / np.linalg.norm(direction)


def _inside_point(cage):
    """Midpoint between where a ray from outside enters the limit surface and where it
    leaves it again (found by a second ray starting just past the entry)."""
    lo, hi = cage.bounds()
    size = float(np.linalg.norm(hi - lo))
    # aim at a point on the surface: the centre of the bounds may lie in a hole (torus)
    d = np.array([0.0, 0.0, -1.0])
    P, _, _ = cage.limit(1)
    start = P[np.argmax(P[:, 2])] + np.array([0.0, 0.0, 2.0 * size])
    start = start + 1e-3 * size * np.array([1.0, 1.0, 0.0])
    p1 = _first_hit(cage, start, d)
    p2 = _first_hit(cage, p1 + 1e-6 * size * d, d)
    return tuple(0.5 * (p1 + p2))


def _write_plane(path, z, half):
    """A 4x4-quad square in the plane z, normal +z, as an OBJ."""
    n = 5
    xs = np.linspace(-half, half, n)
    lines = [f"v {x} {y} {z}" for y in xs for x in xs]
    for j in range(n - 1):
        for i in range(n - 1):
            a = j * n + i + 1
            lines.append(f"f {a} {a + 1} {a + n + 1} {a + n}")
    path.write_text("\n".join(lines) + "\n")


@needs_shared
def test_hidden_object_is_not_refined(tmp_path):
    """Invariant 5: an object fully hidden behind another is never refined."""
    plane = tmp_path / "plane.obj"
    _write_plane(plane, 0.0, 6.0)
    spot = MODELS / "spot_control_mesh.obj"
    # Spot sits behind the plane (z < 0); the camera looks at it through the plane
    scene = _scene([plane, spot], (0.0, 0.0, 3.0), (0.0, 0.0, -1.0), fov=40.0)
    cages = [subtrace.load_cage(plane), subtrace.load_cage(spot)]
    cages[1] = subtrace.make_cage(
        cages[1].points - [0.0, 0.0, 3.0], cages[1].face_sizes, cages[1].face_verts
    )
    res = render_scene(scene, cages=cages)
    assert np.all(res.channels["object_id"] == 0)
    assert res.refined_objects.size > 0
    assert np.count_nonzero(res.refined_objects == 1) == 0
    # without the plane, Spot is refined (the test would notice a broken renderer)
    res = render_scene(_scene([spot], (0.0, 0.0, 3.0), (0.0, 0.0, -1.0), fov=40.0),
                       cages=cages[1:])
    assert np.count_nonzero(res.refined_objects == 0) > 0


@needs_shared
def test_offscreen_patches_are_not_refined():
    spot = MODELS / "spot_control_mesh.obj"
    cage = subtrace.load_cage(spot)
    # a narrow view of Spot's head only
    full = render_scene(_scene([spot], (0.0, 0.6, 3.0), (0.0, 0.2, 0.0), fov=50.0),
                        cages=[cage])
    part = render_scene(_scene([spot], (0.0, 0.6, 3.0), (0.0, 0.6, 0.9), fov=4.0),
                        cages=[cage])
    n_all = build_patch_table([cage]).n_patches
    # the full view refines what faces the camera, not the far side
    assert len(full.refined_objects) < 0.8 * n_all
    # a narrow view of part of the head refines a small part of that
    assert 0 < len(part.refined_objects) < 0.25 * len(full.refined_objects)


def _closest_distance(cage, ptex, uv, X, iters=12):
    """Distance from X to the limit patch near (ptex, uv): Gauss-Newton on the exact
    evaluator, parameters clamped to the ptex face (an upper bound on the true distance)."""
    uv = uv.copy()
    loop = cage.scheme == "loop"
    for _ in range(iters):
        P, du, dv = cage.evaluate(ptex, uv)
        J = np.stack([du, dv], axis=2)  # (m,3,2)
        r = X - P
        JtJ = np.einsum("mki,mkj->mij", J, J)
        Jtr = np.einsum("mki,mk->mi", J, r)
        delta = np.linalg.solve(JtJ + 1e-30 * np.eye(2), Jtr[..., None])[..., 0]
        uv = np.clip(uv + delta, 0.0, 1.0)
        if loop:
            s = uv.sum(axis=1)
            over = s > 1
            uv[over] /= s[over][:, None]
    P, _, _ = cage.evaluate(ptex, uv)
    return np.linalg.norm(P - X, axis=1)


@needs_shared
@pytest.mark.parametrize(
    "mesh,eye,target",
    [
        (MODELS / "spot_control_mesh.obj", (2.0, 0.8, 2.4), (0.0, 0.1, 0.2)),
        (SHAPES / "catmark_cube_creases1.obj", (2.0, 1.5, 2.5), (0.0, 0.0, 0.0)),
        (MODELS / "spot_low_resolution.obj", (2.0, 0.8, 2.4), (0.0, 0.1, 0.2)),
    ],
    ids=["spot", "creases", "loop"],
)
def test_hits_lie_on_the_limit_surface(mesh, eye, target):
    """Accuracy: each hit is within one pixel's footprint (the tolerance's distance at its
    depth) of the exact limit surface, found by Newton iteration on the exact evaluator
    from the hit's ptex coordinates."""
    cage = subtrace.load_cage(mesh)
    res = render_scene(_scene([mesh], eye, target, width=80, height=60, fov=40.0),
                       cages=[cage])
    ch = res.channels
    hit = np.nonzero(ch["A"].ravel() > 0)[0]
    assert len(hit) > 200
    rng = np.random.default_rng(1)
    pick = rng.choice(hit, size=min(150, len(hit)), replace=False)
    from subtrace.camera import camera_frame

    frame = camera_frame(res.camera)
    row, col = np.divmod(pick, res.camera.width)
    d = frame[3] + col[:, None] * frame[1] + row[:, None] * frame[2]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t = ch["Z"].ravel()[pick].astype(np.float64)
    X = frame[0] + t[:, None] * d
    ptex = ch["patch_id"].ravel()[pick].astype(np.int64)
    uv = np.stack([ch["u"].ravel()[pick], ch["v"].ravel()[pick]], axis=1).astype(np.float64)
    dist = _closest_distance(cage, ptex, uv, X)
    allowed = t * res.tolerance_rad
    # Z is stored as float32: its rounding (t * 6e-8) is far below the allowance
    assert np.all(dist <= allowed), (dist / allowed).max()
    # normals: the shading normal is within a few degrees of the exact normal there
    _, du, dv = cage.evaluate(ptex, uv)
    n_exact = np.cross(du, dv)
    n_exact /= np.linalg.norm(n_exact, axis=1, keepdims=True)
    n = np.stack([ch["N.X"], ch["N.Y"], ch["N.Z"]], axis=-1).reshape(-1, 3)[pick]
    cos = np.abs(np.sum(n * n_exact, axis=1))
    assert np.median(cos) > np.cos(np.radians(2.0))


@needs_shared
def test_render_cli_writes_exr(tmp_path):
    from subtrace.cli import main
    from subtrace.io.exr import read_exr

    out = tmp_path / "spot.exr"
    rc = main(["render", str(MODELS / "spot_control_mesh.obj"), "-o", str(out), "--width",
               "64", "--height", "48", "--png", "--quiet"])
    assert rc == 0
    ch, attrs = read_exr(out)
    for name in ["R", "G", "B", "A", "Z", "N.X", "N.Y", "N.Z", "level", "patch_id",
                 "object_id"]:
        assert name in ch
    assert (tmp_path / "spot.png").exists()
    miss = ch["A"] == 0
    assert np.all(np.isinf(ch["Z"][miss])) and np.all(np.isfinite(ch["Z"][~miss]))
    assert np.all(ch["object_id"][~miss] == 0)
    for key in ["subtrace:time_total", "subtrace:time_refine", "subtrace:time_trace",
                "subtrace:time_load", "subtrace:scheme", "subtrace:camera",
                "subtrace:patches_refined", "subtrace:micro_triangles"]:
        assert key in attrs, key
    assert attrs["subtrace:scheme"] == "catmark"


def test_render_cli_accel_chooses_the_traversal(tmp_path, capsys):
    """``--accel bvh`` renders the same image as the default projection and says so in the
    header; an unknown method is a usage error (exit 2, nothing written)."""
    from subtrace.cli import main
    from subtrace.io.exr import read_exr

    args = ["render", str(MODELS / "spot_control_mesh.obj"), "--width", "40", "--height", "30",
            "--quiet"]
    assert main(args + ["-o", str(tmp_path / "p.exr")]) == 0
    assert main(args + ["-o", str(tmp_path / "b.exr"), "--accel", "bvh"]) == 0
    (p, pa), (b, ba) = read_exr(tmp_path / "p.exr"), read_exr(tmp_path / "b.exr")
    assert (pa["subtrace:accel"], ba["subtrace:accel"]) == ("projection", "bvh")
    assert all(np.array_equal(p[k], b[k], equal_nan=True) for k in p)
    assert main(args + ["-o", str(tmp_path / "x.exr"), "--accel", "kd"]) == 2
    assert "invalid choice" in capsys.readouterr().err
    assert not (tmp_path / "x.exr").exists()


@needs_shared
def test_render_reports_progress_up_to_every_ray():
    """``render_scene(progress=...)`` is told the rays whose hits are final, never fewer than
    before, ending at all of them; a ProgressBar draws that on one line."""
    import io

    from subtrace.runtime.progress import ProgressBar

    calls = []
    scene = _scene([MODELS / "spot_control_mesh.obj"], (1.2, 0.6, 2.2), (0.0, 0.3, 0.0),
                   width=48, height=36)
    render_scene(scene, progress=lambda d, t, label: calls.append((d, t, label)))
    done = [d for d, _, _ in calls]
    assert len(calls) >= 3 and all(t == 48 * 36 for _, t, _ in calls)
    assert done[0] == 0 and done[-1] == 48 * 36 and np.all(np.diff(done) >= 0)
    out = io.StringIO()
    bar = ProgressBar(out)
    for d, t, label in calls:
        bar(d, t, label)
    text = out.getvalue()
    assert text.count("\n") == 1 and text.endswith("\n") and "round" in text


def test_render_cli_shows_no_progress_bar_off_a_terminal(tmp_path, capsys):
    from subtrace.cli import main

    assert main(["render", "-o", str(tmp_path / "x.exr"), "--width", "16", "--height",
                 "12"]) == 0
    err = capsys.readouterr().err
    assert "\r[" not in err and "#" not in err


def test_render_cli_bad_output_folder(tmp_path, capsys):
    from subtrace.cli import main

    out = tmp_path / "missing" / "x.exr"
    rc = main(["render", "-o", str(out), "--width", "16", "--height", "8", "--quiet"])
    assert rc == 2
    assert "Traceback" not in capsys.readouterr().err
    assert not out.exists()


def test_render_cli_default_scene_writes_to_working_directory(tmp_path, monkeypatch):
    from subtrace.cli import main
    from subtrace.io.exr import read_exr

    monkeypatch.chdir(tmp_path)
    assert main(["render", "--width", "24", "--height", "16", "--quiet"]) == 0
    ch, attrs = read_exr(tmp_path / "render.exr")
    assert ch["A"].shape == (16, 24) and np.count_nonzero(ch["A"]) > 0
    assert "spot_control_mesh.obj" in attrs["subtrace:meshes"]


@pytest.mark.parametrize("threads", ["0", "9999"])
def test_render_cli_bad_thread_count(tmp_path, capsys, threads):
    from subtrace.cli import main

    out = tmp_path / "x.exr"
    rc = main(["render", "-o", str(out), "--width", "8", "--height", "8", "--threads", threads])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.count("\n") == 1 and "--threads" in err and "Traceback" not in err
    assert not out.exists() and list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------------------
# regular patches as Bezier nets, irregular patches as feature-adaptive pieces
# --------------------------------------------------------------------------------------

PIECE_SHAPES = ["catmark_cube_creases1", "catmark_nonquads", "catmark_pole8",
                "catmark_edgecorner", "catmark_chaikin1", "catmark_hole_test2"]


@needs_shared
@pytest.mark.parametrize("name", PIECE_SHAPES)
def test_bicubic_grids_match_refinement(name):
    """A regular patch evaluated the way the renderer does (its Bezier net: points and
    derivatives) gives the limit points and normals of uniform refinement (to rounding),
    and the net's box contains them."""
    from subtrace.patches import bspline
    from subtrace.patches.basis import bez_derivatives, bez_point as _bez_point

    cage = _load(name)
    lev = cage.level_topology(1)
    pts = cage.refine(1).points
    faces = np.nonzero(~lev.face_hole)[0]
    reg = faces[bspline.regular_mask(lev, cage.options, faces)]
    if len(reg) == 0:
        pytest.skip("no regular patch")
    nets = bspline.bezier_nets(pts[bspline.control_grids(lev, reg)])
    lo, hi, _ = bspline.net_bounds(nets)
    scale = float(np.abs(pts).max())
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
                du, dv = bez_derivatives(net, u, v)
                nrm = np.cross(du, dv)
                assert np.abs(nrm / np.linalg.norm(nrm) - nref[m, g]).max() <= 1e-9


@needs_shared
@pytest.mark.parametrize("name", PIECE_SHAPES)
def test_isolated_pieces_tile_the_grid(name):
    """The pieces of an irregular patch cover every cell of its grid exactly once, and their
    points are the grid's exact limit points (uniform refinement), to rounding."""
    from subtrace.patches.isolate import build_isolated
    from subtrace.patches.basis import bez_point as _bez_point

    cage = _load(name)
    table = build_patch_table([cage])
    o = table.objects[0]
    irr = np.nonzero(~table.regular)[0][:12]
    scale = float(np.abs(o.points).max())
    for depth in (0, 1, 3):
        (sr, sl, si, sj, nets, _), (cr, ci, cj, cp, _) = build_isolated(o, table.face[irr], depth)
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


@needs_shared
def test_rest_boxes_contain_the_later_items():
    """The box a ray tests before a level's pieces contains every later piece of the patch
    (a miss skips them all) and is no larger than their union."""
    from subtrace.patches.isolate import build_isolated
    from subtrace.render import _Pieces

    cage = subtrace.load_cage(MODELS / "spot_control_mesh.obj")
    table = build_patch_table([cage])
    irr = np.nonzero(~table.regular)[0][:40]
    depth = np.full(len(irr), 4)
    subs, cells = build_isolated(table.objects[0], table.face[irr], depth)
    iso = _Pieces(table.n_patches)
    iso.append(irr, depth, np.repeat(depth, 4), subs, cells, 0)
    a = iso.a
    assert np.all(a["count"] > 1)
    for f, c in zip(a["first"], a["count"]):
        for it in range(f, f + c):
            lo = a["lo"][it:f + c].min(axis=0)
            hi = a["hi"][it:f + c].max(axis=0)
            assert np.array_equal(a["rest_lo"][it], lo)
            assert np.array_equal(a["rest_hi"][it], hi)


@needs_shared
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
        (_, lev, _, _, nets, own), _ = build_isolated(o, table.face[ids], int(d), eye, tol)
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


@needs_shared
def test_memo_and_threads_do_not_change_the_image(monkeypatch):
    """Rays share their Bezier splits through a per-thread memo; a memo that runs out makes
    the rays split on the spot instead. Neither the memo's size nor the thread count may
    change a single bit of the image (the same cells, boxes and order either way)."""
    from subtrace import render
    from subtrace.runtime import threads as tasks

    mesh = MODELS / "spot_control_mesh.obj"
    scene = _scene([mesh], (1.2, 0.6, 2.2), (0.0, 0.3, 0.0), width=96, height=72,
                   tolerance=0.5)
    cage = subtrace.load_cage(mesh)
    base = render_scene(scene, cages=[cage], threads=1)
    assert base.stats.pixels_covered > 1000
    two = render_scene(scene, cages=[cage], threads=min(2, tasks.max_threads()))
    monkeypatch.setattr(render._Memos, "START", {"child": 64, "nets": 8, "cells": 16})
    small = render_scene(scene, cages=[cage], threads=1)
    assert small.stats.rounds > base.stats.rounds or small.stats.memo_full > 0
    for name, ch in base.channels.items():
        assert np.array_equal(ch, two.channels[name], equal_nan=True), name
        assert np.array_equal(ch, small.channels[name], equal_nan=True), name


@needs_shared
def test_warmup_compiles_the_kernels_a_render_uses():
    """On a cold cache a second process compiles the trace and shade kernels from empty
    inputs (``subtrace.runtime.warmup``); that only helps if it does compile (or load) them, with
    exactly the types of a render: in a fresh process, the warm-up alone gives each kernel
    one specialisation, and a render after it adds none."""
    import subprocess
    import sys

    from subtrace.runtime import threads as tasks, warmup

    code = f"""
from subtrace import shade
from subtrace.runtime import threads as tasks, warmup
from subtrace.trace import kernels
from subtrace.io.scene import scene_from_dict
from subtrace.render import render_scene
warmup.compile_kernels({tasks.max_threads()})
sigs = lambda: (len(kernels._trace_task.signatures), len(shade._shade_task.signatures))
before = sigs()
scene = scene_from_dict({{"object": [{{"mesh": {str(MODELS / "spot_control_mesh.obj")!r}}}],
    "camera": {{"eye": [1.2, 0.6, 2.2], "target": [0.0, 0.3, 0.0], "width": 32,
                "height": 24}}}})
assert render_scene(scene).stats.pixels_covered > 20
print(before, sigs())
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()
    assert "".join(out) == "(1,1)(1,1)", out
    assert warmup.start(tasks.max_threads()) is None  # cached now: no second process


@needs_shared
@pytest.mark.parametrize("accel", ["projection", "bvh"])
def test_patches_are_built_only_for_rays_that_reach_them_first(accel):
    """'Only what is needed', checked from the outside: every patch built on request (an
    irregular one) has its shell entered by some ray before that ray's final hit. A ray asks
    for the nearest unbuilt shell it enters; asking for a farther one (a wrong order of the
    shells a ray remembers between rounds) builds patches that a nearer surface hides."""
    from subtrace.render import RenderStats, trace_hits
    from subtrace.camera import camera_frame
    from subtrace.trace.prims import H_T

    mesh = MODELS / "spot_control_mesh.obj"
    scene = _scene([mesh], (1.2, 0.6, 2.2), (0.0, 0.3, 0.0), width=96, height=72)
    table = build_patch_table([subtrace.load_cage(mesh)])
    camera = scene.make_camera(table.shell_min.min(0), table.shell_max.max(0))
    hits, _, iso, _, _ = trace_hits(table, camera, scene.render.tolerance_rad(camera),
                                    RenderStats(), accel=accel)
    asked = iso.a["patch"][iso.a["round"] >= 0]
    assert len(asked) > 20
    frame = camera_frame(camera)
    rows, cols = np.divmod(np.arange(camera.width * camera.height), camera.width)
    d = frame[3] + cols[:, None] * frame[1] + rows[:, None] * frame[2]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        t0 = (table.shell_min[asked][:, None, :] - frame[0]) * inv
        t1 = (table.shell_max[asked][:, None, :] - frame[0]) * inv
    near = np.maximum(np.nanmax(np.minimum(t0, t1), axis=2), 0.0)
    far = np.nanmin(np.maximum(t0, t1), axis=2)
    t_hit = hits[H_T]
    reached_first = (near <= far * (1 + 1e-9)) & (near < t_hit * (1 + 1e-9))
    assert np.all(reached_first.any(axis=1))


@needs_shared
@pytest.mark.parametrize("record_depth", [0, 6])
def test_isolation_taken_from_the_depth_choice_equals_a_fresh_one(record_depth):
    """``build_isolated`` with the record of ``isolated_depths`` gives the same pieces and
    cells as refining the requested patches afresh, also where a patch's depth was raised
    beyond what the record reaches (it then refines further itself); recording deeper
    (``record_depth``) does not change the depths chosen."""
    from subtrace.patches.isolate import build_isolated, isolated_depths

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

    (ar, al, ai, aj, an, ad), (br, bl, bi, bj, bn, bd) = by_piece(a[0], 4), by_piece(b[0], 4)
    for x, y in ((ar, br), (al, bl), (ai, bi), (aj, bj), (ad, bd)):
        assert np.array_equal(x, y)
    assert np.abs(an - bn).max() <= 1e-13 * scale
    (cr, ci, cj, cp, _), (dr, di, dj, dp, _) = by_piece(a[1], 3), by_piece(b[1], 3)
    for x, y in ((cr, dr), (ci, di), (cj, dj)):
        assert np.array_equal(x, y)
    assert np.abs(cp - dp).max() <= 1e-13 * scale


@needs_shared
def test_regular_patches_appended_directly_equal_the_general_append():
    """``_Pieces.append_regular`` lays out regular patches as ``append`` does (one piece
    each, sides as given, the net's box for both boxes)."""
    from subtrace.render import _Pieces

    table = build_patch_table([subtrace.load_cage(MODELS / "spot_control_mesh.obj")])
    reg = np.nonzero(table.regular)[0]
    rng = np.random.default_rng(1)
    depth = rng.integers(0, 6, len(reg))
    side = depth[:, None] + rng.integers(0, 2, (len(reg), 4))
    z = np.zeros(len(reg), np.int64)
    none = np.zeros(0, np.int64)
    a, b = _Pieces(table.n_patches), _Pieces(table.n_patches)
    a.append(reg, depth, side, (np.arange(len(reg)), z, z, z, table.nets, depth),
             (none, none, none, np.zeros((0, 4, 3)), np.zeros((0, 4, 3))), -1)
    b.append_regular(reg, depth, side, table.nets, table.shell_min[reg], table.shell_max[reg])
    assert np.array_equal(a.patch_iso, b.patch_iso)
    for name in a.a:
        assert np.array_equal(a.a[name], b.a[name]), name


@needs_shared
def test_catmark_micro_triangles_grow_with_the_tolerance_until_the_pixels_bound_them():
    """Coarse tolerances: each halving multiplies the micro-triangles built by 1.5-4.5 (cells
    a quarter the area, 4x, where whole cells are met; less where a ray meets only part of
    a cell), and fans count once, not once per ray. Fine tolerances: cells are below a
    pixel, each ray builds the few it meets, and the count stops growing."""
    counts = {}
    for tol in (16.0, 8.0, 4.0, 1.0, 0.5):
        scene = _scene([MODELS / "spot_control_mesh.obj"], (1.2, 0.6, 2.2), (0.0, 0.3, 0.0),
                       width=160, height=120, tolerance=tol)
        st = render_scene(scene).stats
        counts[tol] = st.micro_triangles
        assert st.micro_triangles <= 8 * st.pixels_covered
    for coarse, fine in ((16.0, 8.0), (8.0, 4.0)):
        assert 1.5 <= counts[fine] / counts[coarse] <= 4.5, counts
    assert counts[0.5] <= 1.3 * counts[1.0], counts
