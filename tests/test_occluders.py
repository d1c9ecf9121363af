"""Any-hit rays and the picture's passes around them: an occluder certainly met ends a
shadow ray's descent (``geometry.bezier._covers``), parallel rays find their shells in a grid
along their direction (``accel/parallel.py``), and the answers stay those of the closest
hit through the BVH; the shadow rays made by kernels are those numpy made
(``naive.shadow_rays``); the anti-aliasing's edge marks on every thread are numpy's
(``naive.edge_marks``)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import naive
from shared_data import MODELS
from subtrace import config
from subtrace.io.scene import scene_from_dict
from subtrace.runtime import threads as tasks


def _bezier_grid(net, n):
    """(n+1, n+1, 3): the bicubic Bezier patch ``net`` (4,4,3) at u = i/n, v = j/n."""
    s = np.linspace(0.0, 1.0, n + 1)
    b = np.stack([(1 - s) ** 3, 3 * s * (1 - s) ** 2, 3 * s * s * (1 - s), s ** 3], axis=1)
    return np.einsum("ia,jc,ack->ijk", b, b, net)


def _cells_triangles(grid):
    """The triangles (0,1,2), (0,2,3) of every cell of ``grid``: (A, B, C) each (m,3)."""
    p00, p10 = grid[:-1, :-1].reshape(-1, 3), grid[1:, :-1].reshape(-1, 3)
    p11, p01 = grid[1:, 1:].reshape(-1, 3), grid[:-1, 1:].reshape(-1, 3)
    return (np.concatenate([p00, p00]), np.concatenate([p10, p11]),
            np.concatenate([p11, p01]))


@st.composite
def nets_and_rays(draw):
    """A bicubic net over a unit square, bent and twisted, moved anywhere, and a ray
    aimed from either side at a point of its patch or near it (parameters -0.2 .. 1.2),
    from near or far."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    g = np.linspace(0.0, 1.0, 4)
    net = np.zeros((4, 4, 3))
    net[..., 0], net[..., 1] = np.meshgrid(g, g, indexing="ij")
    net[..., 2] = rng.normal(0.0, draw(st.sampled_from([0.01, 0.1, 0.4])), (4, 4))
    net[..., :2] += rng.normal(0.0, 0.05, (4, 4, 2))
    net = net @ _rotation(rng) + rng.normal(0.0, 2.0, 3)
    aim = _bezier_point(net, *rng.uniform(-0.2, 1.2, 2))
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    return net, aim - rng.uniform(0.05, 5.0) * d, d


def _bezier_point(net, u, v):
    bu = np.array([(1 - u) ** 3, 3 * u * (1 - u) ** 2, 3 * u * u * (1 - u), u ** 3])
    bv = np.array([(1 - v) ** 3, 3 * v * (1 - v) ** 2, 3 * v * v * (1 - v), v ** 3])
    return np.einsum("a,c,ack->k", bu, bv, net)


def _rotation(rng):
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 300))
def test_a_grid_lists_every_box_a_parallel_ray_enters(seed, n_boxes):
    """Every box a ray of the grid's direction enters (``accel.bvh.slab_range``, from
    anywhere, both ways along the line) is listed in the ray's cell; a ray outside every
    box's shadow has no cell or one whose boxes it misses."""
    from subtrace.accel.bvh import slab_range
    from subtrace.accel.parallel import grid_cell, parallel_grid

    rng = np.random.default_rng(seed)
    lo = rng.normal(0.0, 3.0, (n_boxes, 3)) * 10.0 ** rng.uniform(-2, 2)
    hi = lo + rng.exponential(0.5, (n_boxes, 3)) * rng.uniform(0.01, 3.0)
    d = _unit(rng.normal(size=(1, 3)))[0]
    if seed % 4 == 0:  # along an axis: the slab test's infinities
        d = np.eye(3)[seed % 3] * (1 if seed % 8 else -1)
    grid = parallel_grid(lo, hi, d)
    # rays aimed at the boxes' corners, centres and beyond, from their sides
    aim = np.concatenate([lo, hi, (lo + hi) / 2, rng.normal(0.0, 5.0, (100, 3))])
    origins = aim - rng.uniform(-20.0, 20.0, (len(aim), 1)) * d
    with np.errstate(divide="ignore"):
        inv = 1.0 / d
        for o in origins:
            c = grid_cell(grid, *o)
            listed = set() if c < 0 else set(grid.items[grid.start[c]:grid.start[c + 1]])
            for p in range(n_boxes):
                if slab_range(*o, *inv, *lo[p], *hi[p], -np.inf, np.inf)[0] < np.inf:
                    assert p in listed, (p, o)


def _covers(net, origin, d, thi):
    """geometry.bezier._covers for the whole patch of ``net`` (its corners, its bound and its
    box, as a piece's root node gives them to an any-hit ray)."""
    from subtrace.patches.basis import net_box
    from subtrace.geometry.bezier import LOCATE_PAD, _covers as covers, _interpolation_bound
    from subtrace.geometry.prims import shear

    nets = np.ascontiguousarray(net[None])
    kx, ky, kz, sx, sy, sz = shear(*d)
    o = (origin[0], origin[1], origin[2])
    corners = [tuple(float(x) for x in net[a, c]) for a, c in ((0, 0), (3, 0), (0, 3), (3, 3))]
    box = net_box(nets, 0)
    dlt = _interpolation_bound(nets, 0, 1.0) + LOCATE_PAD * float(np.abs(origin).max())
    return covers(o[kx], o[ky], o[kz], kx, ky, kz, sx, sy, sz, *corners, dlt, box[kz],
                  box[3 + kz], thi)


@settings(max_examples=300, deadline=None)
@given(nets_and_rays(), st.sampled_from([4, 16, 64]), st.booleans())
def test_a_node_covers_the_ray_only_where_its_triangles_meet_it(case, n, reach):
    """Where ``_covers`` says a ray certainly meets a patch before ``thi``, the
    triangles of any dyadic grid of its limit points do (Moller-Trumbore, an independent
    ray / triangle test), at a distance no nearer than the one it returns and before
    ``thi``."""
    net, origin, d = case
    thi = np.inf if reach else float(np.linalg.norm(net.mean(axis=(0, 1)) - origin))
    t0 = _covers(net, origin, d, thi)
    if t0 == np.inf:
        return
    t, _ = naive.ray_triangle_hits(origin, d, *_cells_triangles(_bezier_grid(net, n)))
    t = t[(t > 0.0) & (t < thi)]
    assert len(t), (origin, d)
    assert t0 <= t.min() * (1 + 1e-12)


def test_a_node_covers_most_rays_through_its_middle():
    """Not vacuous: rays aimed at the middle half of a gently curved patch from a distance
    are certified; rays aimed beside it, or at a patch behind their origin, never."""
    rng = np.random.default_rng(7)
    g = np.linspace(0.0, 1.0, 4)
    net = np.zeros((4, 4, 3))
    net[..., 0], net[..., 1] = np.meshgrid(g, g, indexing="ij")
    net[..., 2] = rng.normal(0.0, 0.02, (4, 4))
    certified = 0
    for _ in range(200):
        aim = np.array([*rng.uniform(0.25, 0.75, 2), 0.0])
        d = np.array([*rng.normal(0.0, 0.3, 2), -1.0])
        d /= np.linalg.norm(d)
        certified += _covers(net, aim - 3.0 * d, d, np.inf) < np.inf
        assert _covers(net, aim + 3.0 * d, d, np.inf) == np.inf  # the patch behind it
        assert _covers(net, aim - 3.0 * d, d, 1.0) == np.inf  # the patch beyond its end
        beside = np.array([1.3, 0.5, 0.0])
        assert _covers(net, beside - 3.0 * d, d, np.inf) == np.inf
    assert certified >= 190


def _scene(samples=4):
    light = {"direction": [-1.2, -1.8, -0.15]}
    point = {"position": [1.5, 2.0, -1.0], "intensity": 2.0}
    return scene_from_dict({
        "object": [{"mesh": str(MODELS / "spot_control_mesh.obj")}],
        "camera": {"eye": [2.55, 1.31, -2.85], "target": [0.0, 0.04, 0.16], "fov": 30,
                   "width": 320, "height": 180},
        "render": {"samples": samples, "ao": 2},
        "light": [light, {"direction": [0.25, -2.5, 1.1], "intensity": 0.2}, point],
        "ground": {}})


def test_any_hit_rays_answer_as_closest_hits(monkeypatch):
    """Every any-hit ray of a picture (shadow rays from the surface and the ground, of the
    extra anti-aliasing rays, ambient occlusion; directional and point lights) is blocked
    exactly where the same ray traced for its closest hit (through the BVH, to its
    nearest triangle) meets a surface before its end; and the shortcuts are taken: the
    directional lights' rays walked grids, and most blocked rays report a distance nearer
    than the closest hit's (a covering node's box), which no triangle of theirs could."""
    from subtrace import aggregate
    from subtrace.render import render_scene
    from subtrace.trace import rays

    calls = []
    trace = rays.trace_rays

    def recording(pools, origins, dirs, tmax, any_hit):
        blocked, hits = trace(pools, origins, dirs, tmax, any_hit)
        if any_hit:
            calls.append((pools, np.array(origins), np.array(dirs), np.array(tmax),
                          blocked.copy(), hits.t.copy()))
        return blocked, hits

    monkeypatch.setattr(aggregate, "trace_rays", recording)
    render_scene(_scene(), threads=2)
    monkeypatch.undo()
    tasks.set_threads(2)
    n = n_blocked = nearer = 0
    for pools, origins, dirs, tmax, blocked, t_any in calls:
        _, hits = trace(pools, origins, dirs, tmax, False)
        assert np.array_equal(blocked, (hits.t < tmax).astype(np.uint8))
        n += len(tmax)
        n_blocked += int(blocked.sum())
        nearer += int(np.count_nonzero(t_any < hits.t))
    tasks.set_threads(None)
    assert n > 50_000 and n_blocked > 5_000
    assert nearer > 0.5 * n_blocked, (nearer, n_blocked)
    assert len(calls[0][0].grids) == 2  # (the two directional lights')


def test_shadow_rays_are_those_numpy_made():
    """``shade.shadow_visibility``'s kernels make the rays ``naive.shadow_rays`` makes, bit
    for bit, light by light in pixel order (directional and point lights, a window of an
    image, the extra rays' own directions), and mark shadow where they were blocked."""
    from subtrace.camera import Camera, CameraWindow
    from subtrace.shade import POINT_ROUNDING, shadow_visibility

    rng = np.random.default_rng(3)
    camera = Camera(eye=(0.3, 1.5, 4.0), target=(0.0, 0.2, 0.0), up=(0.0, 1.0, 0.0),
                    fov_deg=40.0, width=37, height=23)
    from subtrace.lights import Light, light_array

    lights = light_array([Light(direction=(-0.3, -0.9, -0.3)), Light(position=(2.0, 3.0, 1.0)),
                          Light(direction=(0.6, 0.0, -0.8))])
    for view in (camera, CameraWindow(camera, 5, 7, 25, 12)):
        frame = view.frame()
        n = view.width * view.height
        for dirs in (None, _unit(rng.normal(size=(n, 3)))):
            t = rng.uniform(1.0, 6.0, n)
            normals = _unit(rng.normal(size=(n, 3)))
            pix_patch = np.where(rng.random(n) < 0.7, 0, -1).astype(np.int32)
            seen = []

            def trace(origins, to_light, tmax):
                blocked = (rng.random(len(tmax)) < 0.5).astype(np.uint8)
                seen.append((origins.copy(), to_light.copy(), tmax.copy(), blocked))
                return blocked

            for threads in (1, 2):
                tasks.set_threads(threads)
                seen.clear()
                visible = shadow_visibility(trace, frame, view.width, t, normals, pix_patch,
                                            lights, 1e-3, dirs)
                want = naive.shadow_rays(frame, view.width, t, normals, pix_patch, lights,
                                         1e-3, POINT_ROUNDING, dirs)
                (origins, to_light, tmax, blocked), = seen
                k0 = 0
                for k, (pix, o, d, tm) in enumerate(want):
                    part = slice(k0, k0 + len(pix))
                    assert np.array_equal(origins[part], o) and np.array_equal(tmax[part], tm)
                    assert np.array_equal(to_light[part], d)
                    k0 += len(pix)
                    lit = np.ones(n, np.float32)
                    lit[pix] = 1.0 - blocked[part]
                    assert np.array_equal(visible[k], lit)
                assert k0 == len(tmax) and k0 > 100
    tasks.set_threads(None)


def _unit(v):
    return v / np.linalg.norm(v, axis=1)[:, None]


def test_edge_marks_on_every_thread_are_numpys():
    """``shade.edge_pixels`` (three passes by rows, on every thread) marks the pixels
    ``naive.edge_marks`` marks, on a rendered picture's planes and on planes of random
    values (coverage, objects, depths and normals changing anywhere)."""
    from subtrace.render import render_scene
    from subtrace.shade import C_A, C_N, C_OBJECT, C_R, C_Z, CHANNELS, edge_pixels

    result = render_scene(_scene(samples=1), threads=2)
    W, H = result.camera.width, result.camera.height
    rendered = np.stack([result.channels[c].ravel() for c in CHANNELS])
    rng = np.random.default_rng(5)
    w, h = 31, 17
    noise = np.zeros((len(CHANNELS), w * h), np.float32)  # mostly flat, changing here and there
    some = lambda p: rng.random(w * h) < p  # noqa: E731
    noise[C_R:C_R + 3] = np.where(some(0.1), rng.random(w * h), 0.5)
    noise[C_A] = ~some(0.1)
    noise[C_OBJECT] = some(0.05)
    noise[C_Z] = np.where(some(0.1), rng.uniform(1.0, 2.0, w * h), 1.0)
    noise[C_N + 2] = 1.0
    turned = some(0.1)
    noise[C_N:C_N + 3, turned] = _unit(rng.normal(size=(int(turned.sum()), 3))).T
    cos_jump = math.cos(math.radians(config.AA_NORMAL_DEG))
    for planes, width, height in ((rendered, W, H), (noise, w, h)):
        want = naive.edge_marks(planes, width, height, config.AA_DEPTH_STEP, cos_jump,
                                config.AA_CONTRAST, (C_R, C_A, C_Z, C_N, C_OBJECT))
        assert 0 < want.sum() < want.size
        for threads in (1, 2):
            tasks.set_threads(threads)
            assert np.array_equal(edge_pixels(planes, width, height), want)
    tasks.set_threads(None)
