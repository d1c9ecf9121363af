"""Shadows (trace/rays.py through shade.shadow_visibility and the ground): the ground
shadow's outline is the projection of the limit surface along the light, checked against
the line / surface intersection module (an independent code path); a convex closed
surface never shadows itself (no speckle); shadow rays build the patches no primary ray
reached; the image does not depend on the thread count; and ``shade.visibility_at``, the
shadow rays from any points (the reflected rays' hits too), answers as the geometry of an
analytic ball does, and is what the pixels' shadows are."""

from __future__ import annotations

import numpy as np
import pytest

from subtrace.io.scene import scene_from_dict
from subtrace.mesh.cage import load_cage
from subtrace.render import render_scene

CUBE = ("v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\n"
        "v -1 1 1\nf 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n")
LIGHT = np.array([0.5, -1.0, 0.3]) / np.linalg.norm([0.5, -1.0, 0.3])  # travels along it
GROUND = -1.5
BACKGROUND = 0.5


@pytest.fixture
def cube(tmp_path):
    path = tmp_path / "cube.obj"
    path.write_text(CUBE)
    return path


def _scene(cube, tmp_path, shadows=True, ground=True, width=96, height=72,
           eye=(3.0, 6.0, 7.0), target=(0.8, -1.0, 0.4)):
    d = {"object": [{"mesh": str(cube)}],
         "camera": {"eye": list(eye), "target": list(target), "width": width,
                    "height": height},
         "render": {"headlight": False, "shadows": shadows, "samples": 1,
                    "background": [BACKGROUND] * 3},
         "light": [{"direction": LIGHT.tolist()}]}
    d["ground"] = {"height": GROUND} if ground else False
    return scene_from_dict(d, base_dir=tmp_path)


def _near_edge(mask):
    """Pixels within one pixel (8-neighbourhood) of a change in ``mask``."""
    edge = np.zeros_like(mask)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            shifted = np.roll(np.roll(mask, dr, axis=0), dc, axis=1)
            edge |= shifted != mask
    return edge


def test_ground_shadow_is_the_projection_of_the_limit_surface(cube, tmp_path):
    """A ground pixel is in shadow exactly where the line from its ground point towards
    the light meets the limit surface (intersect_lines, not the renderer's kernels);
    disagreements only within a pixel of the outline."""
    from subtrace.lines.api import intersect_lines

    result = render_scene(_scene(cube, tmp_path))
    ch = result.channels
    cam = result.camera
    d = cam.ray_directions().reshape(-1, 3)
    eye = np.asarray(cam.eye)
    t = (GROUND - eye[1]) / d[:, 1]
    ground = (ch["Z"].ravel() == np.inf) & (t > 0)
    points = eye + t[:, None] * d
    hits = intersect_lines(load_cage(str(cube)), points[ground],
                           np.repeat(-LIGHT[None], ground.sum(), axis=0), 1e-6,
                           t_range=(0.0, np.inf), mode="first")
    expected = np.zeros(d.shape[0], bool)
    expected[np.nonzero(ground)[0][np.unique(hits.line)]] = True
    # the catcher: the background (black) where the light is held back, else the flat
    # background lit fraction (1: the background itself)
    shadow = ch["R"].ravel() < 0.5 * BACKGROUND
    assert expected.sum() > 200  # the shadow is in the picture
    wrong = (shadow != expected) & ground
    edge = _near_edge(expected.reshape(ch["A"].shape)).ravel()
    assert not np.any(wrong & ~edge), np.argwhere((wrong & ~edge).reshape(ch["A"].shape))
    assert wrong.sum() <= 0.1 * edge[ground].sum()
    # a single light: the catcher is fully dark or untouched; its alpha says "no hit"
    assert set(np.unique(ch["R"].ravel()[ground])) <= {0.0, np.float32(BACKGROUND)}
    assert not ch["A"].ravel()[ground].any()


def test_no_self_shadow_speckle_on_a_convex_surface(cube, tmp_path):
    """The limit surface of a cube is convex: no point of it can shadow another, so with
    shadows every pixel's colour is exactly that without them (every lit-facing pixel lit),
    while many pixels face the light and many do not."""
    view = {"ground": False, "width": 120, "height": 90, "eye": (-4.0, 1.0, 3.0),
            "target": (0.0, 0.0, 0.0)}  # the terminator in view
    lit = render_scene(_scene(cube, tmp_path, **view)).channels
    off = render_scene(_scene(cube, tmp_path, shadows=False, **view)).channels
    hit = lit["A"] > 0
    n = np.stack([lit[c] for c in ("N.X", "N.Y", "N.Z")], axis=-1)
    facing = (n @ -LIGHT) > 0
    assert (hit & facing).sum() > 1000 and (hit & ~facing).sum() > 100
    for c in "RGB":
        assert np.array_equal(lit[c], off[c]), c
    assert np.all(lit["R"][hit & facing] > 0)


def test_shadow_rays_build_what_primary_rays_left(cube, tmp_path):
    """Seen from above, the cube's underside is built only for the shadow rays that leave
    the ground towards the light; they are counted."""
    result = render_scene(_scene(cube, tmp_path))
    st = result.stats
    assert st.shadow_rays > 0 and st.secondary_patches_refined > 0
    assert st.secondary_micro_triangles > 0
    no = render_scene(_scene(cube, tmp_path, shadows=False)).stats
    assert no.shadow_rays == 0 and no.secondary_patches_refined == 0
    # the primary counts are the primary rays' alone
    assert (st.patches_refined, st.micro_triangles) == (no.patches_refined, no.micro_triangles)


def test_shadows_do_not_depend_on_the_threads(cube, tmp_path):
    scene = _scene(cube, tmp_path)
    one = render_scene(scene, threads=1).channels
    two = render_scene(scene, threads=2).channels
    for c in one:
        assert one[c].tobytes() == two[c].tobytes(), c


def test_secondary_rays_refine_no_deeper_than_the_footprint(cube, tmp_path):
    """Shadow rays reach the cube's underside (built for them alone) at the depth the
    angular criterion asks from the eye, never deeper: their deepest grid is reported
    (``secondary_max_depth``, header and summary), it is at most the deepest depth any
    patch of the table asks for from the eye (patches.criterion.wanted_depths, computed
    here apart from the render), and at most the primary rays' deepest grid (the underside
    is farther from the eye than the top the pixels see). A shadow ray's cone (the pixel's
    spread from the eye, width t times the tolerance at its hit) is wider at every point of
    the ray than the eye's footprint there (triangle inequality), so the eye's depth is
    never coarser than the cone needs; with AO rays (longer cones) it stays the same."""
    from subtrace.io.scene import apply_overrides
    from subtrace.patches.criterion import wanted_depths
    from subtrace.patches.table import build_patch_table
    from subtrace.render import result_attributes

    scene = _scene(cube, tmp_path)
    result = render_scene(scene)
    st = result.stats
    assert st.secondary_patches_refined > 0 and st.secondary_max_depth >= 0
    table = build_patch_table([load_cage(str(cube))])
    want = wanted_depths(table, np.asarray(result.camera.eye), result.tolerance_rad)
    assert st.secondary_max_depth <= want[np.isfinite(want)].max()
    assert st.secondary_max_depth <= st.max_depth
    assert result_attributes(result, scene)["subtrace:secondary_max_depth"] == \
        st.secondary_max_depth
    with_ao = render_scene(apply_overrides(scene, ao=4)).stats
    assert with_ao.secondary_max_depth <= want[np.isfinite(want)].max()
    none = render_scene(_scene(cube, tmp_path, shadows=False, ground=False)).stats
    assert none.secondary_max_depth == -1


def test_a_cage_with_no_patch_renders_its_ground_without_hanging(tmp_path):
    """Two boundary faces under boundary interpolation "none" make no patch: the shadow rays
    of the automatic lights' ground see an empty pool and miss (they once walked an empty
    BVH for ever). In a process of its own, with a time limit, so a hang fails."""
    import subprocess
    import sys

    from subtrace.io.exr import read_exr

    obj = tmp_path / "holes.obj"
    obj.write_text("t interpolateboundary 1/0/0 0\n"
                   + "".join(f"v {x} 0 {z}\n" for z in (0, 1, 2) for x in (0, 1, 2))
                   + "f 1 2 5 4\nf 2 3 6\n")
    out = tmp_path / "out.exr"
    proc = subprocess.run([sys.executable, "-m", "subtrace.cli", "render", str(obj), "-o",
                           str(out), "--width", "32", "--height", "24", "--quiet"],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    channels, attrs = read_exr(out)
    assert attrs["subtrace:patches"] == 0
    assert not (channels["A"] > 0).any()


# -- shade.visibility_at: shadow rays from arbitrary points ----------------------------

BALL, BALL_R = np.array([0.2, 1.0, -0.3]), 0.7  # an analytic occluder: a ball


def _ball_blocks(origins, dirs, tmax):
    """Any-hit rays against the ball: blocked (n,) uint8 (the segment [0, tmax] meets it)."""
    v = origins - BALL
    b = (v * dirs).sum(axis=1)
    c = (v * v).sum(axis=1) - BALL_R ** 2
    disc = b * b - c
    root = np.sqrt(np.maximum(disc, 0.0))
    near, far = -b - root, -b + root
    return ((disc > 0.0) & (far > 0.0) & (near < tmax)).astype(np.uint8)


def _ball_points(rng, n):
    """``n`` points around the ball, most below it, none within 0.05 of its surface, unit
    normals."""
    p = rng.uniform((-1.5, -3.5, -1.5), (1.5, 1.5, 1.5), size=(n, 3)) + BALL
    p = p[np.abs(np.linalg.norm(p - BALL, axis=1) - BALL_R) > 0.05]
    normals = rng.normal(size=p.shape)
    return p, normals / np.linalg.norm(normals, axis=1)[:, None]


def _segment_clear(p, to, dist):
    """Whether the segment p + s to, 0 <= s <= dist, misses the ball, and by what margin
    (the distance of its nearest point from the ball's surface)."""
    v = BALL - p
    s = np.clip((v * to).sum(axis=1), 0.0, dist)
    gap = np.linalg.norm(p + s[:, None] * to - BALL, axis=1) - BALL_R
    return gap > 0.0, np.abs(gap)


@pytest.mark.parametrize("threads", [1, 2])
def test_shadow_rays_from_points_see_past_a_ball_as_geometry_says(threads):
    """``shade.visibility_at`` from points scattered around a ball (not pixels' hits), a
    directional and a point light, the ball the only occluder: a point whose normal faces
    a light sees it exactly where the segment to it misses the ball (0 or 1; the points
    that graze the ball's outline are left out), one that faces away sees it (1: its
    lighting is 0 anyway); the rays leave each point along its normal by its error bound
    and end that much short of the point light."""
    from subtrace.lights import Light, light_array
    from subtrace.runtime import threads as tasks
    from subtrace.shade import visibility_at

    rng = np.random.default_rng(11)
    p, normals = _ball_points(rng, 3000)
    err = rng.uniform(0.0, 0.01, len(p))
    lamp = np.array([0.5, 4.0, 0.8])
    travel = np.array([0.3, -1.0, 0.2]) / np.linalg.norm([0.3, -1.0, 0.2])
    lights = light_array([Light(direction=tuple(travel)), Light(position=tuple(lamp))])
    seen = []

    def trace(origins, dirs, tmax):
        seen.append((origins.copy(), dirs.copy(), tmax.copy()))
        return _ball_blocks(origins, dirs, tmax)

    tasks.set_threads(threads)
    try:
        vis = visibility_at(trace, p, normals, err, lights)
    finally:
        tasks.set_threads(None)
    assert vis.shape == (2, len(p)) and vis.dtype == np.float32
    to_lamp = lamp - p
    dist = np.linalg.norm(to_lamp, axis=1)
    to_lamp /= dist[:, None]
    (origins, dirs, tmax), = seen
    j = 0
    for k, (to, far) in enumerate(((np.repeat(-travel[None], len(p), axis=0),
                                     np.full(len(p), 1e9)), (to_lamp, dist))):
        facing = (normals * to).sum(axis=1) > 0.0
        clear, margin = _segment_clear(p, to, far)
        sure = margin > 0.02
        assert np.all(vis[k][~facing] == 1.0)
        want = clear.astype(np.float32)
        assert np.array_equal(vis[k][facing & sure], want[facing & sure])
        assert 100 < np.count_nonzero(facing & sure & ~clear) < np.count_nonzero(facing) - 100
        # the rays of the facing points, in point order: from p + err n towards the light
        f = np.nonzero(facing)[0]
        part = slice(j, j + len(f))
        np.testing.assert_allclose(origins[part], p[f] + err[f, None] * normals[f],
                                   rtol=0, atol=1e-12)
        np.testing.assert_allclose(dirs[part], to[f], rtol=0, atol=1e-12)
        if k == 1:
            np.testing.assert_allclose(tmax[part], dist[f] - err[f], rtol=1e-12)
        else:
            assert np.all(tmax[part] == np.inf)
        j += len(f)
    assert j == len(tmax)


def test_a_surface_point_does_not_shadow_itself_past_its_error_bound():
    """Points on the ball's surface (normals outward) under a light from straight above:
    the rays leave along the normal by the error bound, so every point whose normal faces
    the light is lit (nothing else lies between); with no offset at all the rounding of the points lets the ball's own
    surface hold back some of them (the speckle the offset prevents)."""
    from subtrace.lights import Light, light_array
    from subtrace.shade import visibility_at

    rng = np.random.default_rng(5)
    n = rng.normal(size=(2000, 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    p = BALL + BALL_R * n
    travel = np.array([0.0, -1.0, 0.0])
    lights = light_array([Light(direction=tuple(travel))])
    facing = n[:, 1] > 0.05  # (well within the lit half: nothing else in the way)
    vis = visibility_at(_ball_blocks, p, n, np.full(len(p), 1e-6), lights)[0]
    assert facing.sum() > 500 and np.all(vis[facing] == 1.0)
    assert np.all(vis[n[:, 1] <= 0.0] == 1.0)  # facing away: 1 (unlit anyway)
    speckle = visibility_at(_ball_blocks, p, n, np.zeros(len(p)), lights)[0]
    assert np.count_nonzero(speckle[facing] == 0.0) > 10


def test_the_pixels_shadows_are_the_points_shadows_of_their_hits():
    """``shade.shadow_visibility`` (the pixels' hits: a window of an image, the centre
    rays' or given directions) is ``visibility_at`` of ``hit_points``: the same rays bit
    for bit, the same visibility at the hit pixels, 1 at the others; with lights of
    several rays per point (a sphere light, a soft sun, an environment) and their keys."""
    from subtrace.camera import Camera, CameraWindow
    from subtrace.lights import Light, light_array, ray_keys
    from subtrace.shade import hit_points, shadow_visibility, visibility_at

    rng = np.random.default_rng(8)
    camera = Camera(eye=(0.3, 1.5, 4.0), target=(0.0, 0.2, 0.0), up=(0.0, 1.0, 0.0),
                    fov_deg=40.0, width=41, height=29)
    lights = light_array([Light(position=(1.0, 3.0, 1.0), radius=0.5, samples=8),
                          Light(direction=(0.2, -1.0, 0.1), angle=10.0, samples=3),
                          Light(kind_key="environment", samples=5),
                          Light(direction=(-0.6, -0.2, -0.7))])
    for view in (camera, CameraWindow(camera, 4, 6, 30, 15)):
        frame, width = view.frame(), view.width
        n = view.width * view.height
        for dirs in (None, rng.normal(size=(n, 3))):
            if dirs is not None:
                dirs /= np.linalg.norm(dirs, axis=1)[:, None]
            t = rng.uniform(2.0, 6.0, n)
            normals = rng.normal(size=(n, 3))
            normals /= np.linalg.norm(normals, axis=1)[:, None]
            pix_patch = np.where(rng.random(n) < 0.6, 3, -1).astype(np.int32)
            keys = ray_keys(np.arange(n, dtype=np.int64))
            rays = []

            def trace(origins, to, tmax):
                rays.append((origins.copy(), to.copy(), tmax.copy()))
                return _ball_blocks(origins, to, tmax)

            pixels = shadow_visibility(trace, frame, width, t, normals, pix_patch, lights,
                                       1e-3, dirs, keys)
            hit = np.nonzero(pix_patch >= 0)[0]
            points, err = hit_points(frame, width, t, hit, 1e-3, dirs)
            at = visibility_at(trace, points, normals[hit], err, lights, keys[hit])
            assert np.array_equal(pixels[:, hit], at)
            assert np.all(np.delete(pixels, hit, axis=1) == 1.0)
            assert 0.0 < at.mean() < 1.0 and len(np.unique(at)) > 3  # (shadows, penumbrae)
            (o1, d1, m1), (o2, d2, m2) = rays
            assert o1.tobytes() == o2.tobytes() and d1.tobytes() == d2.tobytes()
            assert m1.tobytes() == m2.tobytes()
            # the hit points are the pixels' rays' (shade.pixel_rays, or dirs) at t
            from subtrace.shade import pixel_rays
            d = pixel_rays(frame, width, hit) if dirs is None else dirs[hit]
            np.testing.assert_array_equal(points, frame[0] + t[hit, None] * d)
