"""Watertight and exact: renders from inside closed cages (and a creased box) leave no
pixel uncovered at 4, 1 and 0.25 px, and hits lie on the limit surface."""

from __future__ import annotations

import numpy as np
import pytest
from shared_data import MODELS, SHAPES, check_watertight, lathe_cage, small_scene

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
    check_watertight(mesh, eye, tolerance, monkeypatch)


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
    check_watertight(mesh, (0.5 * n, 0.45 * n, 0.55 * n), tolerance, monkeypatch)


@pytest.mark.parametrize("tolerance", [4.0, 1.0, 0.25])
def test_watertight_from_inside_a_hard_surface_cage(tmp_path, tolerance, monkeypatch):
    """The same inside a lathe cage with creases of sharpness 6 to 8
    (``shared_data.lathe_cage``): its patches go through every path of the isolation (the crease maps, the stencils at the
    poles, local topology at the crease ends, the junction and beside the poles' triangles),
    and their sides are sampled and snapped across all of them."""
    mesh = lathe_cage(tmp_path / "lathe.obj")
    cage = subtrace.load_cage(mesh)
    from subtrace.patches.crease import crease_faces

    table = build_patch_table([cage])
    o = table.objects[0]
    quads = np.nonzero(~table.regular[table.object_id == 0])[0]
    ok = crease_faces(o.level, cage.options, table.face[quads])[0]
    assert ok.any() and not ok.all()  # crease maps and other paths both
    check_watertight(mesh, (0.0, 1.0, 0.1), tolerance, monkeypatch)


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
