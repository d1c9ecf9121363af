"""The sample project's golden tests. ``render`` stands in for the project's renderer (a
sphere ray cast in numpy, with subtrace's channels); each test hands its picture to the
``golden`` fixture of subtrace's plugin.

goldens/sphere.exr is this render; goldens/sphere_lit.exr was made with the light from the
other side, so test_sphere_lit fails until ``pytest --update-goldens`` rewrites it."""

import numpy as np

WIDTH, HEIGHT = 40, 30


def render(light=(0.5, 0.5, -1.0), radius=0.8) -> dict:
    """An orthographic view along +z of a sphere centred at z = 3, lit from the direction
    ``light`` (towards the light): subtrace's channels."""
    x = (np.arange(WIDTH) + 0.5) / WIDTH * 2.0 - 1.0
    y = 1.0 - (np.arange(HEIGHT) + 0.5) / HEIGHT * 1.5
    px, py = np.meshgrid(x * 4 / 3, y * 4 / 3)
    r2 = px * px + py * py
    hit = r2 < radius * radius
    pz = -np.sqrt(np.where(hit, radius * radius - r2, 0.0))
    normal = np.stack([px, py, pz], axis=-1) / radius
    direction = np.asarray(light) / np.linalg.norm(light)
    shade = np.clip(normal @ direction, 0.0, 1.0)
    f32 = lambda a: np.asarray(a, dtype=np.float32)  # noqa: E731
    ch = {c: f32(np.where(hit, 0.05 + k * shade, 0.0)) for c, k in zip("RGB", (0.8, 0.5, 0.3))}
    ch["A"] = f32(hit)
    ch["Z"] = f32(np.where(hit, 3.0 + pz, np.inf))
    for k, c in enumerate(("N.X", "N.Y", "N.Z")):
        ch[c] = f32(np.where(hit, normal[..., k], 0.0))
    patch = (px > 0).astype(int) + 2 * (py > 0)
    ch["level"] = f32(np.where(hit, 2, -1))
    ch["patch_id"] = f32(np.where(hit, patch, -1))
    ch["object_id"] = f32(np.where(hit, 0, -1))
    return ch


def test_sphere(golden):
    golden(render(), "sphere")


def test_sphere_lit(golden):
    golden(render(light=(0.5, 0.5, -1.0)), "sphere_lit")
