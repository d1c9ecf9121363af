"""The scene aggregate (subtrace/aggregate.py): its closest hits and its any-hit answers
on the rational torus of models/nurbs against the torus's quartic (rays from the eye and
from arbitrary points); on cages and free-form surfaces together, a ray is occluded
exactly where its closest hit lies before its end; and every kind of secondary ray of a
picture (shadow, ambient occlusion, extra anti-aliasing, reflected rays) asks the one
aggregate."""

from __future__ import annotations

import numpy as np

from shared_data import MODELS
from subtrace.io.scene import scene_from_dict
from subtrace.render import render_scene

TORUS = MODELS / "nurbs" / "torus_patches.obj"  # radii 1 and 0.35 about +Z, at the origin
R_MAJOR, R_MINOR = 1.0, 0.35
LOOP_TORUS = MODELS / "torus.obj"


def _scene(objects, **render):
    return scene_from_dict({
        "object": objects,
        "camera": {"eye": [3.4, -4.35, 2.75], "target": [0.0, 0.0, 0.0], "up": [0, 0, 1],
                   "fov": 30.0, "width": 48, "height": 32},
        "render": {"samples": 1, **render},
        "light": [{"direction": [-0.4, -0.5, -1.0]}], "ground": False})


def _aggregate_of(scene, monkeypatch):
    """The render's aggregate (``picture.SceneAggregate``), and every call made of it."""
    from subtrace import aggregate, picture

    made, calls = [], []

    class Recording(aggregate.SceneAggregate):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            made.append(self)

        def occluded(self, origins, dirs, tmax):
            calls.append(("occluded", len(tmax)))
            return super().occluded(origins, dirs, tmax)

        def closest(self, dirs, origins=None, length=None):
            calls.append(("closest from the eye" if origins is None else "closest", len(dirs)))
            return super().closest(dirs, origins, length)

    monkeypatch.setattr(picture, "SceneAggregate", Recording)
    render_scene(scene, threads=2)
    monkeypatch.undo()
    (world,) = made
    return world, calls


def _torus_roots(o, d):
    """The smallest positive root of |p|^2 + R^2 - r^2)^2 = 4 R^2 (x^2 + y^2) along each
    ray ``o + t d`` (unit d; inf: none), and whether the ray crosses there at a slant
    (|cos| of the normal and the ray above 0.2: the root is a simple one)."""
    a = (o * d).sum(axis=1)
    b = (o * o).sum(axis=1) + R_MAJOR ** 2 - R_MINOR ** 2
    e = (d[:, :2] ** 2).sum(axis=1)
    f = (o[:, :2] * d[:, :2]).sum(axis=1)
    g = (o[:, :2] ** 2).sum(axis=1)
    k = 4.0 * R_MAJOR ** 2
    out = np.full(len(o), np.inf)
    for i in range(len(o)):
        roots = np.roots([1.0, 4.0 * a[i], 4.0 * a[i] ** 2 + 2.0 * b[i] - k * e[i],
                          4.0 * a[i] * b[i] - 2.0 * k * f[i], b[i] ** 2 - k * g[i]])
        real = roots.real[(np.abs(roots.imag) < 1e-7) & (roots.real > 1e-9)]
        if len(real):
            out[i] = real.min()
    p = o + np.where(np.isfinite(out), out, 0.0)[:, None] * d
    normal = _torus_normal(p)
    slant = np.isfinite(out) & (np.abs((normal * d).sum(axis=1)) > 0.2)
    return out, slant


def _torus_normal(p):
    ring = np.concatenate([p[:, :2], np.zeros((len(p), 1))], axis=1)
    ring *= R_MAJOR / np.maximum(np.linalg.norm(ring, axis=1), 1e-300)[:, None]
    n = p - ring
    return n / np.maximum(np.linalg.norm(n, axis=1), 1e-300)[:, None]


def _clear_of_torus(o, d, reach=12.0, steps=4000):
    """Whether each ray stays more than 0.02 from the torus over [0, reach]."""
    s = np.linspace(0.0, reach, steps)
    gap = np.full(len(o), np.inf)
    for part in np.array_split(s, 40):
        p = o[:, None, :] + part[None, :, None] * d[:, None, :]
        ring = np.sqrt(p[..., 0] ** 2 + p[..., 1] ** 2) - R_MAJOR
        gap = np.minimum(gap, (np.sqrt(ring ** 2 + p[..., 2] ** 2) - R_MINOR).min(axis=1))
    return gap > 0.02


def _points_outside(rng, n):
    o = rng.uniform((-2.0, -2.0, -1.2), (2.0, 2.0, 1.2), size=(n, 3))
    ring = np.sqrt(o[:, 0] ** 2 + o[:, 1] ** 2) - R_MAJOR
    return o[np.sqrt(ring ** 2 + o[:, 2] ** 2) > R_MINOR + 0.05]


def _near_torus(rng, n):
    """``n`` points within 0.3 of the torus (about its tube's circles)."""
    u, v = rng.uniform(0.0, 2.0 * np.pi, (2, n))
    p = np.stack([(R_MAJOR + R_MINOR * np.cos(v)) * np.cos(u),
                  (R_MAJOR + R_MINOR * np.cos(v)) * np.sin(u), R_MINOR * np.sin(v)], axis=1)
    return p + rng.uniform(-0.3, 0.3, size=p.shape)


def _unit(v):
    return v / np.linalg.norm(v, axis=1)[:, None]


def test_closest_and_occluded_meet_the_rational_torus_where_its_quartic_says(monkeypatch):
    """Rays from arbitrary points around the free-form torus (and from the eye): where a
    ray crosses the torus at a slant, its closest hit is the quartic's smallest positive
    root within 1e-6 and its normal the torus's, turned towards the ray's origin; a ray
    that passes well clear of it hits nothing; and ``occluded`` says blocked exactly where
    that root lies before the ray's end."""
    world, _ = _aggregate_of(_scene([{"mesh": str(TORUS)}]), monkeypatch)
    assert world.pools is None and world.nurbs is not None  # (free-form surfaces alone)
    rng = np.random.default_rng(2)
    o = _points_outside(rng, 2000)
    d = _unit(rng.normal(size=o.shape))
    aim = rng.random(len(o)) < 0.6  # (most rays towards points near the torus)
    d[aim] = _unit(_near_torus(rng, int(aim.sum())) - o[aim])
    eye = world.frame[0]
    hit = world.closest(d, o, np.linalg.norm(o - eye, axis=1))
    assert hit.planes is None
    root, slant = _torus_roots(o, d)
    assert slant.sum() > 300
    np.testing.assert_allclose(hit.t[slant], root[slant], rtol=0, atol=1e-6)
    p = o[slant] + hit.t[slant, None] * d[slant]
    want = _torus_normal(p)
    want *= -np.sign((want * d[slant]).sum(axis=1))[:, None]  # (towards the origin)
    np.testing.assert_allclose(hit.normals[slant], want, rtol=0, atol=1e-5)
    assert np.all(hit.patch[slant] >= world.offset)
    clear = _clear_of_torus(o, d)
    assert clear.sum() > 300 and np.all(hit.t[clear] == np.inf)
    assert np.all(hit.patch[clear] == -1)
    # any-hit: blocked where the root lies before tmax (tmax 0.05 either side of it)
    for shift, blocked in ((0.05, 1), (-0.05, 0)):
        tmax = np.where(slant, root + shift, np.inf)[slant]
        got = world.occluded(o[slant], d[slant], tmax)
        assert got.dtype == np.uint8 and np.all(got == blocked), shift
    assert not world.occluded(o[clear], d[clear], np.full(int(clear.sum()), 1e3)).any()
    # from the eye: the same hits, and the shading's planes (depth, normal, position)
    toward = _unit(rng.uniform(-0.9, 0.9, size=(800, 3)) - eye)
    seen = world.closest(toward)
    root, slant = _torus_roots(np.repeat(eye[None], len(toward), axis=0), toward)
    assert slant.sum() > 100
    np.testing.assert_allclose(seen.t[slant], root[slant], rtol=0, atol=1e-6)
    from subtrace.shade import C_A, C_P, C_Z
    assert np.all(seen.planes[C_A, slant] == 1.0)
    np.testing.assert_allclose(seen.planes[C_Z, slant], root[slant], rtol=1e-6)
    np.testing.assert_allclose(seen.planes[C_P:C_P + 3, slant].T,
                               eye + root[slant, None] * toward[slant], rtol=0, atol=1e-5)


def test_a_ray_is_occluded_exactly_where_its_closest_hit_lies_before_its_end(monkeypatch):
    """The free-form torus linked through a Loop cage's torus: rays from arbitrary points
    (every cone as the shadow rays carry it: ``|origin - eye|`` times the tolerance) are
    ``occluded`` exactly where ``closest`` finds a cage or a free-form surface before their
    end, and both kinds of surface do the blocking."""
    world, _ = _aggregate_of(_scene([{"mesh": str(TORUS)}, {"mesh": str(LOOP_TORUS)}]),
                             monkeypatch)
    assert world.pools is not None and world.nurbs is not None
    rng = np.random.default_rng(4)
    o = rng.uniform((-2.0, -2.0, -1.2), (2.0, 2.0, 1.2), size=(3000, 3))
    d = _unit(rng.normal(size=o.shape))
    length = np.sqrt(((o - world.frame[0]) ** 2).sum(axis=1))
    hit = world.closest(d, o, length)
    tmax = rng.uniform(0.0, 3.0, len(o))
    blocked = world.occluded(o, d, tmax)
    assert np.array_equal(blocked, (hit.t < tmax).astype(np.uint8))
    near = hit.t < tmax
    free_form = near & (hit.patch >= world.offset)
    cage = near & (hit.patch >= 0) & (hit.patch < world.offset)
    assert free_form.sum() > 100 and cage.sum() > 100 and (~near).sum() > 100


def test_every_secondary_ray_asks_the_one_aggregate(monkeypatch, tmp_path):
    """A picture with shadows, ambient occlusion, anti-aliasing and a reflective material
    makes one aggregate, and its shadow and AO rays ask ``occluded``, its extra
    anti-aliasing rays ``closest`` from the eye and its reflected rays ``closest`` from
    their hits."""
    scene = _scene([{"mesh": str(TORUS)},
                    {"mesh": str(LOOP_TORUS), "metallic": 1.0, "roughness": 0.0}],
                   samples=4, ao=2)
    _, calls = _aggregate_of(scene, monkeypatch)
    kinds = {kind for kind, n in calls if n}
    assert kinds == {"occluded", "closest from the eye", "closest"}, calls
    assert sum(n for kind, n in calls if kind == "occluded") > 48 * 32  # (shadows and AO)


def test_the_aggregates_answers_do_not_depend_on_the_threads(monkeypatch):
    """The same rays give the same closest hits and any-hit answers on 1 and 2 threads."""
    from subtrace.runtime import threads as tasks

    world, _ = _aggregate_of(_scene([{"mesh": str(TORUS)}, {"mesh": str(LOOP_TORUS)}]),
                             monkeypatch)
    rng = np.random.default_rng(6)
    o = rng.uniform(-1.5, 1.5, size=(500, 3))
    d = _unit(rng.normal(size=o.shape))
    length = np.linalg.norm(o - world.frame[0], axis=1)
    answers = []
    for n in (2, 1):
        tasks.set_threads(n)
        try:
            hit = world.closest(d, o, length)
            answers.append((hit.t, hit.normals, hit.patch, world.occluded(o, d, hit.t + 1e-3)))
        finally:
            tasks.set_threads(None)
    for a, b in zip(*answers):
        assert a.tobytes() == b.tobytes()
