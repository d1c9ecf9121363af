"""The renderer (render.render_scene, trace.kernels): watertight, only what is needed,
hits on the limit surface, images independent of memos and threads, the warm-up."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from shared_data import COMPILE_LISTENER, MODELS, SHAPES, run_fresh, small_scene

import subtrace
from subtrace.patches.table import build_patch_table
from subtrace.render import render_scene

WATERTIGHT = [
    (MODELS / "spot_control_mesh.obj", (0.0, 0.05, 0.2)),
    (MODELS / "blub_control_mesh.obj", None),
    (MODELS / "torus.obj", None),
    (MODELS / "spot_low_resolution.obj", None),
    (SHAPES / "catmark_cube_creases1.obj", None),
]


@pytest.mark.parametrize("tolerance", [4.0, 1.0, 0.25])
@pytest.mark.parametrize("mesh,eye", WATERTIGHT, ids=lambda x: getattr(x, "stem", ""))
def test_watertight_from_inside(mesh, eye, tolerance, monkeypatch):
    """Invariant 4: from inside a closed surface every ray hits it (zero misses), whatever
    the tolerance and however differently neighbouring patches are refined."""
    _check_watertight(mesh, eye, tolerance, monkeypatch)


@pytest.mark.parametrize("tolerance", [4.0, 1.0, 0.25])
def test_watertight_from_inside_creased_box(tmp_path, tolerance, monkeypatch):
    """The same inside a box of 3x3 quads a side whose twelve edges are infinitely sharp
    creases: regular crease patches (phantom points) beside irregular corner patches."""
    mesh = tmp_path / "creased_box.obj"
    n = 3
    ids, lines = {}, []
    for p in np.ndindex(n + 1, n + 1, n + 1):
        if min(p) == 0 or max(p) == n:
            ids[p] = len(ids)
            lines.append("v {} {} {}".format(*p))
    for a in range(3):
        b, c = (a + 1) % 3, (a + 2) % 3
        for side in (0, n):
            for i in range(n):
                for j in range(n):
                    quad = []
                    for di, dj in ((0, 0), (1, 0), (1, 1), (0, 1)):
                        q = [0, 0, 0]
                        q[a], q[b], q[c] = side, i + di, j + dj
                        quad.append(ids[tuple(q)] + 1)
                    if side == 0:
                        quad.reverse()
                    lines.append("f " + " ".join(map(str, quad)))
    for p, k in ids.items():
        for a in range(3):
            q = list(p)
            q[a] += 1
            on_edge = sum(x in (0, n) for x in p) >= 2 and sum(x in (0, n) for x in q) >= 2
            if tuple(q) in ids and on_edge and p[a] + 1 <= n:
                others = [x for i, x in enumerate(p) if i != a]
                if all(x in (0, n) for x in others):
                    lines.append(f"t crease 2/1/0 {k} {ids[tuple(q)]} 10.0")
    mesh.write_text("\n".join(lines) + "\n")
    cage = subtrace.load_cage(mesh)
    # the crease patches are regular (not only the smooth ones in the middle of the sides)
    from subtrace.patches.bspline import smooth_mask

    table = build_patch_table([cage])
    o = table.objects[0]
    assert not all(smooth_mask(level, faces[table.regular[rows]]).all()
                   for level, _, rows, faces in o.parts())
    # the middle quads of the sides and those along the creases are patches of the cage
    # (level 0) beside the corners' level-1 patches: their shared cage edges are sampled
    # alike from both levels (``criterion.edge_sampling``)
    assert len(o.cage_quads) == 6 * 5 and (table.side_shift == 1).any()
    assert not smooth_mask(cage.base, o.cage_quads).all()
    _check_watertight(mesh, (0.5 * n, 0.45 * n, 0.55 * n), tolerance, monkeypatch)


def _check_watertight(mesh, eye, tolerance, monkeypatch):
    cage = subtrace.load_cage(mesh)
    if eye is None:
        # a point inside: the middle of the limit surface along a ray through the centre
        eye = _inside_point(cage)
    scene = small_scene([mesh], eye, np.asarray(eye) + [0.3, 0.1, 1.0], fov=120.0, width=48,
                   height=36, tolerance=tolerance)
    res = render_scene(scene, cages=[cage])
    A = res.channels["A"]
    assert np.count_nonzero(A == 0) == 0
    # and looking the other way
    scene = small_scene([mesh], eye, np.asarray(eye) - [0.3, 0.1, 1.0], fov=120.0, width=48,
                   height=36, tolerance=tolerance)
    assert np.count_nonzero(render_scene(scene, cages=[cage]).channels["A"] == 0) == 0


def _first_hit(cage, eye, direction):
    eye = np.asarray(eye, dtype=np.float64)
    scene = small_scene([cage.path], eye, eye + direction, width=1, height=1, fov=1.0)
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


def test_hidden_object_is_not_refined(tmp_path):
    """Invariant 5: an object fully hidden behind another is never refined."""
    plane = tmp_path / "plane.obj"
    _write_plane(plane, 0.0, 6.0)
    spot = MODELS / "spot_control_mesh.obj"
    # Spot sits behind the plane (z < 0); the camera looks at it through the plane
    scene = small_scene([plane, spot], (0.0, 0.0, 3.0), (0.0, 0.0, -1.0), fov=40.0)
    cages = [subtrace.load_cage(plane), subtrace.load_cage(spot)]
    cages[1] = subtrace.make_cage(
        cages[1].points - [0.0, 0.0, 3.0], cages[1].face_sizes, cages[1].face_verts
    )
    # (Spot's patches include quads of the cage itself, level 0, beside level-1 ones)
    assert len(build_patch_table([cages[1]]).objects[0].cage_quads) > 0
    res = render_scene(scene, cages=cages)
    assert np.all(res.channels["object_id"] == 0)
    assert res.refined_objects.size > 0
    assert np.count_nonzero(res.refined_objects == 1) == 0
    # without the plane, Spot is refined (the test would notice a broken renderer)
    res = render_scene(small_scene([spot], (0.0, 0.0, 3.0), (0.0, 0.0, -1.0), fov=40.0),
                       cages=cages[1:])
    assert np.count_nonzero(res.refined_objects == 0) > 0


SEMI_SHARP = ("catmark_cube_creases0", "catmark_chaikin0")


@pytest.mark.parametrize("name", ["catmark_edgecorner", "catmark_single_crease", *SEMI_SHARP])
def test_hidden_sharp_patches_are_not_refined(tmp_path, name):
    """Invariant 5 for regular boundary and crease patches (phantom points) and for
    irregular patches at semi-sharp (and Chaikin) creases: a cage with boundaries or creases
    hidden behind a plane is never refined."""
    plane = tmp_path / "plane.obj"
    _write_plane(plane, 0.0, 6.0)
    # the shape fitted in a unit box behind the plane (its tags kept: the OBJ's other lines)
    text = (SHAPES / f"{name}.obj").read_text().splitlines()
    v = np.array([[float(x) for x in ln.split()[1:4]] for ln in text if ln.startswith("v ")])
    lo, hi = v.min(axis=0), v.max(axis=0)
    v = (v - 0.5 * (lo + hi)) / float((hi - lo).max()) - [0.0, 0.0, 2.0]
    it = iter(v)
    moved = tmp_path / f"{name}.obj"
    moved.write_text("\n".join(
        "v {} {} {}".format(*next(it)) if ln.startswith("v ") else ln for ln in text) + "\n")
    hidden = subtrace.load_cage(moved)
    # it has the patches the test is about: regular ones with a sharp side, or irregular
    # ones at semi-sharp creases (built by isolation when a ray asks for them)
    table = build_patch_table([hidden])
    if name in SEMI_SHARP:
        assert (~table.regular).sum() > 0
    else:
        assert table.regular.sum() > 0
    scene = small_scene([plane, moved], (0.0, 0.0, 3.0), (0.0, 0.0, -1.0), fov=40.0)
    res = render_scene(scene, cages=[subtrace.load_cage(plane), hidden])
    assert np.all(res.channels["object_id"] == 0)
    assert res.refined_objects.size > 0
    assert np.count_nonzero(res.refined_objects == 1) == 0
    # without the plane, the cage is refined
    res = render_scene(small_scene([moved], (0.0, 0.0, 3.0), (0.0, 0.0, -1.0), fov=40.0),
                       cages=[hidden])
    assert np.count_nonzero(res.refined_objects == 0) > 0


def test_offscreen_patches_are_not_refined():
    spot = MODELS / "spot_control_mesh.obj"
    cage = subtrace.load_cage(spot)
    # a narrow view of Spot's head only
    full = render_scene(small_scene([spot], (0.0, 0.6, 3.0), (0.0, 0.2, 0.0), fov=50.0),
                        cages=[cage])
    part = render_scene(small_scene([spot], (0.0, 0.6, 3.0), (0.0, 0.6, 0.9), fov=4.0),
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
    res = render_scene(small_scene([mesh], eye, target, width=80, height=60, fov=40.0),
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


def test_render_reports_progress_up_to_every_ray():
    """``render_scene(progress=...)`` is told the rays whose hits are final, never fewer than
    before, ending at all of them; a ProgressBar draws that on one line."""
    import io

    from subtrace.runtime.progress import ProgressBar

    calls = []
    scene = small_scene([MODELS / "spot_control_mesh.obj"], (1.2, 0.6, 2.2), (0.0, 0.3, 0.0),
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


@pytest.mark.parametrize("mesh", ["spot_control_mesh.obj", "spot_low_resolution.obj"])
def test_memo_and_threads_do_not_change_the_image(mesh, monkeypatch):
    """Rays share their Bezier splits (quads, and Loop triangles' nets) through a per-thread
    memo; a memo that runs out makes the rays split on the spot instead. Neither the memo's
    size nor the thread count may change a single bit of the image (the same cells, boxes
    and order either way)."""
    from subtrace.runtime import threads as tasks
    from subtrace.trace import pools

    mesh = MODELS / mesh
    scene = small_scene([mesh], (1.2, 0.6, 2.2), (0.0, 0.3, 0.0), width=96, height=72,
                   tolerance=0.5)
    cage = subtrace.load_cage(mesh)
    base = render_scene(scene, cages=[cage], threads=1)
    assert base.stats.pixels_covered > 1000
    two = render_scene(scene, cages=[cage], threads=min(2, tasks.max_threads()))
    monkeypatch.setattr(pools.Memos, "START", {"child": 64, "nets": 8, "cells": 16})
    small = render_scene(scene, cages=[cage], threads=1)
    assert small.stats.rounds > base.stats.rounds or small.stats.memo_full > 0
    for name, ch in base.channels.items():
        assert np.array_equal(ch, two.channels[name], equal_nan=True), name
        assert np.array_equal(ch, small.channels[name], equal_nan=True), name


def test_warmup_compiles_the_kernels_a_render_uses():
    """On a cold cache a second process compiles the trace and shade kernels from empty
    inputs (``subtrace.startup.warmup``); that only helps if it does compile (or load) them, with
    exactly the types of a render: in a fresh process, the warm-up alone gives each kernel
    one specialisation, and a render after it adds none."""
    import subprocess
    import sys

    from subtrace.runtime import threads as tasks
    from subtrace.startup import warmup

    code = f"""
from subtrace import shade
from subtrace.runtime import threads as tasks
from subtrace.startup import warmup
from subtrace.trace import kernels
from subtrace.io.scene import scene_from_dict
from subtrace.render import render_scene
warmup.compile_kernels({tasks.max_threads()}, ["catmark"])
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


def test_the_secondary_ray_kernels_compile_with_the_types_of_a_render():
    """On a cold cache the secondary-ray kernel compiles while the trace kernels compile
    elsewhere (``trace.rays.compile_kernel`` on empty pools); that only helps if the types
    are those of a render: in a fresh process on two threads, it gives the kernel one
    specialisation and a render with shadows and anti-aliasing rays adds none."""
    import subprocess
    import sys

    code = f"""
from subtrace.runtime import threads as tasks
from subtrace.trace import rays
from subtrace.io.scene import scene_from_dict
from subtrace.render import render_scene
tasks.set_threads(2)
rays.compile_kernel()
tasks.set_threads(None)
sigs = lambda: len(rays._rays_task.signatures)
before = sigs()
scene = scene_from_dict({{"object": [{{"mesh": {str(MODELS / "spot_control_mesh.obj")!r}}}],
    "camera": {{"eye": [1.2, 0.6, 2.2], "target": [0.0, 0.3, 0.0], "width": 32,
                "height": 24}}, "render": {{"samples": 4}},
    "light": [{{"direction": [-1.0, -2.0, -0.5]}}]}})
stats = render_scene(scene, threads=2).stats
assert stats.pixels_covered > 20 and stats.shadow_rays > 0, stats
print(before, sigs())
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()
    assert out == ["1", "1"], out


def test_warmup_compiles_the_picture_kernels_a_render_uses():
    """The helper compiles the picture's kernels (lights, background, ground with shadow rays,
    anti-aliasing flags: ``warmup.compile_picture``) from a few pixels; that only helps if
    their types are a render's: in a fresh process, a render with a light, shadows, a
    shadow-catching ground and anti-aliasing adds no signature to any of them."""
    import subprocess
    import sys

    code = f"""
from subtrace import shade
from subtrace.startup import warmup
from subtrace.io.scene import scene_from_dict
from subtrace.render import render_scene
warmup.compile_picture(2)
kernels = (shade._light_task, shade._background_task, shade._ground_first, shade._ground_rays,
           shade._ground_last, shade._shadow_count, shade._shadow_make, shade._shadow_mark,
           shade._luminance_rows, shade._pair_rows, shade._flag_rows)
sigs = lambda: [len(k.signatures) for k in kernels]
before = sigs()
scene = scene_from_dict({{"object": [{{"mesh": {str(MODELS / "spot_control_mesh.obj")!r}}}],
    "camera": {{"eye": [1.2, 0.6, 2.2], "target": [0.0, 0.3, 0.0], "width": 48,
                "height": 36}},
    "render": {{"samples": 4, "background": [[0.4, 0.4, 0.5], [0.1, 0.1, 0.1]]}},
    "light": [{{"direction": [-0.4, -1.0, -0.5]}}], "ground": {{}}}})
stats = render_scene(scene, threads=2).stats
assert stats.shadow_rays > 0 and stats.aa_pixels > 0, stats
print(before, sigs())
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == " ".join([str([1] * 11)] * 2), out


def test_a_render_of_other_schemes_compiles_their_trace_kernel_in_a_helper(monkeypatch):
    """The trace kernel has a variant without the Loop descents (``bezier.loop_flag``): a
    render whose cages' variant the cache lacks starts a helper for it (told the schemes at
    once), one whose variant is cached starts none; the cache's index is read for it."""
    from subtrace.runtime import threads as tasks
    from subtrace.startup import warmup

    warmup.compile_kernels(tasks.max_threads(), ["catmark"])  # (loaded if cached)
    assert warmup._trace_variant_cached(None)
    monkeypatch.setattr(warmup, "_trace_variant_cached", lambda loop: loop is None)
    assert warmup.start_for(tasks.max_threads(), ["catmark", "catmark"]) is None
    helpers = warmup.start_for(tasks.max_threads(), ["catmark", "loop"])
    assert helpers is not None and len(helpers.procs) >= 1
    warmup.wait(helpers)
    assert all(proc.returncode == 0 for proc in helpers.procs)
    monkeypatch.undo()
    assert warmup._trace_variant_cached(True)  # what the helper compiled (or found)


def test_the_picture_kernels_compile_here_only_while_the_trace_kernel_is_not_ready(monkeypatch):
    """warmup.traced tells, without reading it, whether a helper has said "traced" (or
    ended); warmup.picture_while_tracing compiles the picture's groups other than the
    ground's one at a time until then, and none once it is."""
    import select
    import subprocess
    import sys

    from subtrace.startup import warmup

    said = "import sys, time; time.sleep({}); print('traced', flush=True); sys.stdin.read()"
    compiled = []
    monkeypatch.setattr(warmup, "compile_picture",
                        lambda threads, parts: compiled.append(parts))
    slow = subprocess.Popen([sys.executable, "-c", said.format(60)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE)
    try:
        helpers = warmup.Helpers([slow], False)
        assert not warmup.traced(helpers)
        warmup.picture_while_tracing(helpers, 2)
        assert compiled == [(part,) for part in warmup.PICTURE if part != "ground"]
    finally:
        slow.kill()
        slow.wait()
    quick = subprocess.Popen([sys.executable, "-c", said.format(0)], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE)
    helpers = warmup.Helpers([quick], False)
    assert select.select([quick.stdout], [], [], 60)[0]  # (it has said it)
    assert warmup.traced(helpers) and warmup.traced(helpers)  # (nothing read)
    compiled.clear()
    warmup.picture_while_tracing(helpers, 2)
    assert compiled == []
    warmup.wait_traced(helpers)
    warmup.wait(helpers)
    assert quick.returncode == 0 and warmup.traced(warmup.Helpers([], False))


@pytest.mark.parametrize("accel", ["projection", "bvh"])
def test_patches_are_built_only_for_rays_that_reach_them_first(accel):
    """'Only what is needed', checked from the outside: every patch built on request (an
    irregular one) has its shell entered by some ray before that ray's final hit. A ray asks
    for the nearest unbuilt shell it enters; asking for a farther one (a wrong order of the
    shells a ray remembers between rounds) builds patches that a nearer surface hides."""
    from subtrace.camera import camera_frame
    from subtrace.render import RenderStats, trace_hits

    mesh = MODELS / "spot_control_mesh.obj"
    scene = small_scene([mesh], (1.2, 0.6, 2.2), (0.0, 0.3, 0.0), width=96, height=72)
    table = build_patch_table([subtrace.load_cage(mesh)])
    camera = scene.make_camera(table.shell_min.min(0), table.shell_max.max(0))
    hits, iso, _ = trace_hits(table, camera, scene.render.tolerance_rad(camera), RenderStats(),
                              accel=accel)
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
    t_hit = hits.t
    reached_first = (near <= far * (1 + 1e-9)) & (near < t_hit * (1 + 1e-9))
    assert np.all(reached_first.any(axis=1))


def test_catmark_micro_triangles_grow_with_the_tolerance_until_the_pixels_bound_them():
    """Coarse tolerances: each halving multiplies the micro-triangles built by 1.3-4.5 (cells
    a quarter the area, 4x, where whole cells are met; less where a ray meets only part of
    a cell, or where a coarse patch's cells of exact limit points keep their depth and its
    finer neighbours snap onto them: 1.42 from 16 to 8 px, 2.64 from 8 to 4), and fans
    count once, not once per ray. Fine tolerances: cells are below a
    pixel, each ray tests the few cells it may hit (placed among a block's four by its
    frame: measured 5.4 and 4.0 per covered pixel at 1 and 0.5 px on this small image,
    whose coarse patches' frames place rays less sharply), and the count stops growing."""
    counts = {}
    for tol in (16.0, 8.0, 4.0, 1.0, 0.5):
        scene = small_scene([MODELS / "spot_control_mesh.obj"], (1.2, 0.6, 2.2), (0.0, 0.3, 0.0),
                       width=160, height=120, tolerance=tol)
        st = render_scene(scene).stats
        counts[tol] = st.micro_triangles
        assert st.micro_triangles <= 24 * st.pixels_covered
    for coarse, fine in ((16.0, 8.0), (8.0, 4.0)):
        assert 1.3 <= counts[fine] / counts[coarse] <= 4.5, counts
    assert counts[0.5] <= 1.3 * counts[1.0], counts


@pytest.mark.parametrize("name", ["spot", "creases", "torus_loop"])
def test_a_few_micro_triangles_per_covered_pixel_at_every_tolerance(name):
    """At 4, 1 and 0.25 px, at most 4 micro-triangles per covered pixel, Catmull-Clark (Spot:
    n-gons and extraordinary vertices; creases: semi-sharp creases and corners) and Loop
    alike: a ray builds the few cells it may hit, however fine the grid. (Measured at
    640x360: Spot 1.7 / 3.3 / 2.6, creases 0.7 / 2.3 / 2.1, the Loop torus 1.1 / 2.4 / 2.4;
    at 1280x720 every scene of the benchmark is at most 3.)"""
    from subtrace.io.scene import apply_overrides, load_scene

    path = Path(__file__).resolve().parents[1] / "scenes" / f"{name}.toml"
    for tol in ("4", "1", "0.25"):
        scene = apply_overrides(load_scene(path), width=640, height=360, tolerance=tol,
                                samples="1", shadows=False, ao="0")
        st = render_scene(scene).stats
        assert st.pixels_covered > 10_000
        assert st.micro_triangles <= 4 * st.pixels_covered, (tol, st.micro_triangles,
                                                               st.pixels_covered)


_SHADING_PROBE = COMPILE_LISTENER + """
import json, sys
from subtrace.startup import warmup
warmup.compile_shading(1, None if sys.argv[1] == "catmark" else True)
print(json.dumps(compiled))
"""


@pytest.mark.parametrize("scheme", ["catmark", "loop"])
def test_the_shading_of_catmull_clark_cages_compiles_no_loop_normals(tmp_path, scheme):
    """shade.shade: the normals of hits on Loop items are a pass of their own, so the
    shading of Catmull-Clark cages (``loop`` None), in a fresh process on an empty cache,
    compiles neither that pass nor the Loop nets' normal; with Loop cages it compiles both
    (the golden Loop scenes check their numbers)."""
    import json

    compiled = json.loads(run_fresh(_SHADING_PROBE, scheme, cache=tmp_path / "cache"))
    names = {c.rpartition(".")[2] for c in compiled}
    assert "_shade_task" in names, compiled
    loop = {"_loop_normals_task", "tri_normal"} & names
    assert loop == (set() if scheme == "catmark" else {"_loop_normals_task", "tri_normal"})


CUBE = """v -0.5 -0.5 0.5
v 0.5 -0.5 0.5
v -0.5 0.5 0.5
v 0.5 0.5 0.5
v -0.5 0.5 -0.5
v 0.5 0.5 -0.5
v -0.5 -0.5 -0.5
v 0.5 -0.5 -0.5
f 1 2 4 3
f 3 4 6 5
f 5 6 8 7
f 7 8 2 1
f 2 8 6 4
f 7 1 3 5
"""


def _unused_cube(tmp_path, before, after):
    """The cube with a vertex ``before`` its eight and one ``after``, which no face uses."""
    lines = CUBE.splitlines()
    renumber = lambda s: " ".join(str(int(i) + 1) for i in s.split())
    text = "\n".join([f"v {before}"] + lines[:8] + [f"f {renumber(f[2:])}" for f in lines[8:]]
                     + [f"v {after}"]) + "\n"
    path = tmp_path / "cube_unused.obj"
    path.write_text(text)
    return path


@pytest.mark.parametrize("before,after", [("9 9 9", "7 7 7"), ("0 -40 0", "0.1 0.2 0.3")])
def test_unused_vertices_leave_the_picture_as_it_is(tmp_path, before, after):
    """Vertices that no face uses (common in OBJ files) are no part of the limit surface:
    the default picture of a cube with two of them (the automatic camera, which they used
    to push away until the cube was a few pixels wide, the lights and the ground, which
    they could move far below it) is the cube's alone, channel for channel."""
    from subtrace.io.scene import apply_overrides, scene_for_meshes

    plain = tmp_path / "cube.obj"
    plain.write_text(CUBE)
    images = []
    for path in (plain, _unused_cube(tmp_path, before, after)):
        scene = apply_overrides(scene_for_meshes([str(path)]), width=96, height=64)
        images.append(render_scene(scene).channels)
    assert set(images[0]) == set(images[1])
    assert np.count_nonzero(images[0]["A"]) > 0.1 * images[0]["A"].size
    for name in images[0]:
        assert np.array_equal(images[0][name], images[1][name], equal_nan=True), name


def test_the_automatic_camera_stays_out_of_the_shells_and_frames_the_shadow(tmp_path):
    """A four-face Loop tetrahedron, whose limit surface is far smaller than its cage,
    with the default picture: the eye lies outside the cage's box (it was inside the
    patches' shells: depth 14, 828k micro-triangles and a warning about the eye inside
    them), nothing warns, and the ground's shadow lies whole in the image (no pixel on the
    border darker than the background there)."""
    import warnings

    from subtrace.io.scene import apply_overrides, scene_for_meshes

    path = tmp_path / "tetrahedron.obj"
    path.write_text("v 1 1 1\nv -1 -1 1\nv -1 1 -1\nv 1 -1 -1\n"
                    "f 1 2 3\nf 1 4 2\nf 1 3 4\nf 2 4 3\n")
    scene = apply_overrides(scene_for_meshes([str(path)]), width=160, height=90)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        result = render_scene(scene)
    eye = np.asarray(result.camera.eye)
    assert np.any(np.abs(eye) > 1.0)  # (the cage's box is [-1, 1]^3)
    ch = result.channels
    top, bottom = (np.asarray(c) for c in (scene.render.background,
                                           scene.render.background_bottom))
    w = (np.arange(90) + 0.5) / 90
    back = (1 - w) * top[0] + w * bottom[0]  # the gradient's red, row by row
    shadow = (ch["A"] == 0) & (ch["R"] < 0.8 * back[:, None])
    assert shadow.sum() > 100  # (the key light's shadow, beside the object)
    assert not (shadow[0].any() or shadow[-1].any() or shadow[:, 0].any()
                or shadow[:, -1].any())
