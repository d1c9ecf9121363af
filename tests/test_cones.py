"""Ray cones of shadow and ambient occlusion rays (design invariant 8): with secondary rays,
each patch is refined for the narrowest cone that can reach it (``patches.shells.Sight``,
``accel.cull.secondary_origins``), so a caster out of view near the eye is not refined as
if a pixel looked at it from there, and never coarser than a cone that reaches it asks."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from shared_data import MODELS

from subtrace import prepare, render
from subtrace.accel.cull import secondary_origins
from subtrace.camera import Camera, camera_frame
from subtrace.io.scene import scene_from_dict
from subtrace.patches.shells import Sight, box_distance, sight_distance


def _pixel_rays(camera, rng, n):
    """(n,3) unit directions through random points of random pixels of ``camera``."""
    eye, dx, dy, p00 = camera_frame(camera)
    col = rng.uniform(-0.5, camera.width - 0.5, n)
    row = rng.uniform(-0.5, camera.height - 0.5, n)
    d = p00 + col[:, None] * dx + row[:, None] * dy
    return d / np.linalg.norm(d, axis=1)[:, None]


def _in_image(camera, x):
    """(n,) bool: the points ``x`` (n,3) lie in front of ``camera`` within its image."""
    eye, dx, dy, p00 = camera_frame(camera)
    a = (x - eye) @ np.linalg.inv(np.stack([p00, dx, dy], axis=1)).T
    ok = a[:, 0] > 0.0
    col, row = a[:, 1] / np.where(ok, a[:, 0], 1.0), a[:, 2] / np.where(ok, a[:, 0], 1.0)
    return ok & (col >= -0.5) & (col <= camera.width - 0.5) & (row >= -0.5) & (
        row <= camera.height - 0.5)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), ground=st.booleans())
def test_the_sight_distance_is_no_longer_than_any_cone(seed, ground):
    """Every point a secondary ray may leave (inside a box in view and the image, or on the
    ground in the image), and every point of any box: the ray's cone length there (its
    origin's distance from the eye plus its distance from the origin) is at least the
    box's sight distance, which is at least its distance from the eye."""
    rng = np.random.default_rng(seed)
    eye = rng.uniform(-4.0, 4.0, 3) + [0.0, 4.5, 0.0]
    camera = Camera(tuple(eye), tuple(rng.uniform(-1.0, 1.0, 3)), (0.0, 1.0, 0.0),
                    float(rng.uniform(20.0, 70.0)), 40, 30)
    centre = rng.uniform(-4.0, 4.0, (16, 3)) + [0.0, 2.0, 0.0]
    half = rng.uniform(0.05, 0.8, (16, 3))
    lo, hi = centre - half, centre + half
    plane = ((0.0, 1.0, 0.0), float(rng.uniform(-1.0, 0.5))) if ground else None
    seen = secondary_origins(camera, lo, hi, plane)
    # the points secondary rays leave: in the boxes, seen through the image
    x = [lo[k] + rng.uniform(0.0, 1.0, (200, 3)) * (hi[k] - lo[k]) for k in range(16)]
    x = np.concatenate(x)
    x = x[_in_image(camera, x)]
    if plane is not None:  # and on the ground, where pixels see it
        d = _pixel_rays(camera, rng, 400)
        down = d[:, 1] < 0.0
        t = (plane[1] - eye[1]) / d[down, 1]
        x = np.concatenate([x, eye + t[t > 0.0, None] * d[down][t > 0.0]])
    if seen is None:
        assert not len(x)
        return
    sight = Sight(eye, *seen)
    # boxes anywhere: near the eye, behind it, in view, far away
    qc = np.concatenate([eye + rng.normal(0.0, 1.0, (20, 3)), rng.uniform(-8.0, 8.0, (20, 3))])
    qh = rng.uniform(0.01, 0.5, (40, 3))
    qlo, qhi = qc - qh, qc + qh
    dist = sight_distance(qlo, qhi, sight)
    assert np.all(dist >= box_distance(qlo, qhi, eye))
    if not len(x):
        return
    for k in range(40):
        y = qlo[k] + rng.uniform(0.0, 1.0, (50, 3)) * (qhi[k] - qlo[k])
        cone = (np.linalg.norm(x - eye, axis=1)[:, None]
                + np.linalg.norm(y[None] - x[:, None], axis=2))
        assert cone.min() >= dist[k] * (1.0 - 1e-12)


def _torus(cx, cy, cz, n=10, m=6, major=0.6, minor=0.25):
    """An OBJ text: a torus cage of n x m quads (every vertex of valence 4: regular
    patches), centred at (cx, cy, cz), its axis along y."""
    lines = []
    for i in range(n):
        a = 2.0 * np.pi * i / n
        for j in range(m):
            b = 2.0 * np.pi * j / m
            r = major + minor * np.cos(b)
            lines.append(f"v {cx + r * np.cos(a)} {cy + minor * np.sin(b)} {cz + r * np.sin(a)}")
    for i in range(n):
        for j in range(m):
            v = [1 + ((i + di) % n) * m + (j + dj) % m for di, dj in ((0, 0), (1, 0), (1, 1),
                                                                       (0, 1))]
            lines.append("f " + " ".join(map(str, v)))
    return "\n".join(lines) + "\n"


def _caster_scene(tmp_path, **render_options):
    """The ground seen from 1.5 above it; a torus above and behind the eye, out of the
    picture, whose shadow a sun throws onto the ground in view."""
    path = tmp_path / "torus.obj"
    path.write_text(_torus(0.0, 2.7, 6.9))
    return scene_from_dict({
        "object": [{"mesh": str(path)}],
        "camera": {"eye": [0.0, 1.5, 6.0], "target": [0.0, 0.0, 0.0], "fov": 30.0,
                   "width": 96, "height": 64},
        "render": {"samples": 1, "headlight_intensity": 0.0, **render_options},
        "light": [{"direction": [0.0, -1.0, -1.6]}],
        "ground": {"height": 0.0, "color": [0.7, 0.7, 0.7]},
    })


def _by_the_eye(monkeypatch):
    """Make renders choose every depth from the eye alone (no cones)."""
    monkeypatch.setattr(prepare, "secondary_origins", lambda *args, **kwargs: None)


def _depths(scene, seen_too=True):
    """(patch table, each patch's depth, where secondary rays start) of ``scene``'s
    trace, as the render chooses them."""
    stats = render.RenderStats()
    cages, table, camera, view, tol_rad, budget, seen = prepare.prepare(scene, None, stats)
    keep = {}
    render.trace_hits(table, view, tol_rad, stats, keep=keep,
                      seen=seen if seen_too else None)
    return table, keep["depths"], camera, tol_rad, seen


def test_a_caster_near_the_eye_is_refined_for_the_cones_that_reach_it(tmp_path, monkeypatch):
    """The torus out of view, 1 to 2 from the eye, shadows ground 3 or more from it: its
    shadow rays' cones there are over four times a pixel's footprint at its distance. Its
    patches get shallower grids than the eye alone would give them (a lower
    ``secondary_max_depth``), yet none coarser than the narrowest cone of a ray
    leaving the ground in view asks (computed here from the pixels' ground points), and
    the shadow differs only along its outline."""
    scene = _caster_scene(tmp_path)
    cones = render.render_scene(scene)
    assert np.all(cones.channels["object_id"] < 0)  # the torus is out of the picture
    table, depths, camera, tol_rad, seen = _depths(scene)
    _, eye_depths, _, _, _ = _depths(scene, seen_too=False)
    assert seen is not None and np.all(depths <= eye_depths) and depths.sum() < eye_depths.sum()
    # the ground points the pixels see, and the narrowest cone from them at each patch
    eye = np.asarray(camera.eye)
    d = camera.ray_directions().reshape(-1, 3)
    t = -eye[1] / d[d[:, 1] < 0.0, 1]
    x = eye + t[:, None] * d[d[:, 1] < 0.0]
    cone = np.array([(np.linalg.norm(x - eye, axis=1)
                      + box_distance(np.repeat(table.shell_min[p:p + 1], len(x), 0),
                                     np.repeat(table.shell_max[p:p + 1], len(x), 0), x)).min()
                     for p in range(table.n_patches)])
    assert np.all(table.regular) and np.all(table.rate == 0.5)
    need = np.maximum(np.ceil(np.log2(table.edge_bound / (tol_rad * cone)) - 1e-9), 0)
    assert np.all(depths >= need)
    assert np.all(cone > 4.0 * box_distance(table.shell_min, table.shell_max, eye))
    # the render: a shallower deepest grid for the shadow rays (the micro-triangles they
    # test are a few per ray at either depth: geometry/bezier.py places a ray among a
    # block's cells)
    _by_the_eye(monkeypatch)
    eyes = render.render_scene(scene)
    assert cones.stats.secondary_max_depth <= eyes.stats.secondary_max_depth - 2
    # the same shadow, but for pixels on its outline (a 3 x 3 neighbourhood in which
    # either image has both shadowed and lit ground)
    lit = render.render_scene(_caster_scene(tmp_path, shadows=False)).channels["R"]
    masks = [r.channels["R"] < lit - 1e-3 for r in (cones, eyes)]
    assert masks[0].sum() > 100
    edge = np.zeros_like(masks[0])
    for m in masks:
        p = np.pad(m, 1, mode="edge")
        win = np.stack([p[i:i + m.shape[0], j:j + m.shape[1]] for i in range(3)
                        for j in range(3)])
        edge |= win.any(axis=0) & ~win.all(axis=0)
    assert np.all(~(masks[0] ^ masks[1]) | edge)
    assert np.count_nonzero(masks[0] ^ masks[1]) < 0.1 * masks[0].sum()


def test_patches_in_view_keep_the_eyes_depths(monkeypatch):
    """A patch a pixel may see is refined as the eye asks, cones or not: the Spot scene
    (a ground plane, a sun, shadows, ambient occlusion) renders bit for bit as with the
    eye's depths."""
    scene = scene_from_dict({
        "object": [{"mesh": str(MODELS / "spot_control_mesh.obj")}],
        "camera": {"eye": [2.393, 1.306, -3.637], "target": [0, 0.1091, 0.1916],
                   "width": 120, "height": 80},
        "render": {"samples": 1, "ao": 4},
        "light": [{"direction": [-0.4, -1.0, -0.5]}],
        "ground": {},
    })
    cones = render.render_scene(scene)
    _by_the_eye(monkeypatch)
    eyes = render.render_scene(scene)
    for name, plane in cones.channels.items():
        assert plane.tobytes() == eyes.channels[name].tobytes(), name
