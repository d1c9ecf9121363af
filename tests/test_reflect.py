"""Reflections (subtrace/reflect.py): a mirror floor shows an object exactly where the
mirror law puts it (the object mirrored through the floor, seen without the floor, covers
the same pixels); a mirror blob under a constant environment or background shows that
radiance times Schlick's Fresnel term at each pixel's angle (metal and dielectric); a
glossy floor tends to the mirror as the roughness goes to 0; a glossy metal in a white
furnace returns the GGX lobe's directional albedo (a quadrature of the closed-form lobe,
not its sampling); the same image on 1 and 2 threads and in a tile; materials without
reflection render as before; bad values are one clear line naming the file and line,
exit code 2."""

from __future__ import annotations

import math

import numpy as np
import pytest

from subtrace.cli import main
from subtrace.io.obj import read_obj
from subtrace.io.scene import load_scene, scene_from_dict
from subtrace.render import render_scene
from subtrace.shade import material_of

CUBE = ("v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\n"
        "v -1 1 1\nf 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n")
EYE = [0.5, 4.0, 7.0]
BLUE = [0.1, 0.2, 0.9]


def _plane(n=4, half=5.0) -> str:
    """A flat grid of n x n quads on y = 0 (its limit surface: the plane itself)."""
    lines = [f"v {-half + 2 * half * i / n} 0 {-half + 2 * half * j / n}"
             for j in range(n + 1) for i in range(n + 1)]
    lines.append("t interpolateboundary 1/0/0 1")
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i + 1
            lines.append(f"f {a} {a + n + 1} {a + n + 2} {a + 1}")
    return "\n".join(lines) + "\n"


def _files(tmp_path):
    (tmp_path / "cube.obj").write_text(CUBE)
    (tmp_path / "plane.obj").write_text(_plane())


def _floor_scene(tmp_path, roughness=0.0, mirrored_only=False, width=96, height=72,
                 samples=1, extra=None):
    """A red blob (a cube's limit surface, 1.4 over y = 0) above a white metal floor at
    y = 0 under a blue background; ``mirrored_only``: the blob mirrored through the
    floor's plane and no floor."""
    _files(tmp_path)
    blob = {"mesh": str(tmp_path / "cube.obj"), "color": [1.0, 0.0, 0.0],
            "scale": 0.8, "translate": [0.0, 1.4, 0.0]}
    if mirrored_only:
        blob = dict(blob, scale=[0.8, -0.8, 0.8], translate=[0.0, -1.4, 0.0])
    floor = {"mesh": str(tmp_path / "plane.obj"), "color": [1.0, 1.0, 1.0],
             "metallic": 1.0, "roughness": roughness}
    objects = [blob] if mirrored_only else [blob, floor]
    return scene_from_dict({
        "object": objects,
        "camera": {"eye": EYE, "target": [0.0, 0.2, 0.0], "width": width, "height": height},
        "render": dict({"headlight_intensity": 0.5, "samples": samples, "background": BLUE},
                       **(extra or {})),
        "light": [{"direction": [-0.3, -1.0, -0.4], "intensity": 0.8}],
        "ground": False}, base_dir=tmp_path)


def _grow(mask):
    """The mask and its 8 neighbours."""
    out = mask.copy()
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            out |= np.roll(np.roll(mask, dy, axis=0), dx, axis=1)
    return out


def test_a_mirror_floor_shows_the_object_where_the_mirror_law_puts_it(tmp_path):
    """Every floor pixel shows the blob's colour (no blue) exactly where the blob mirrored
    through the floor's plane, rendered alone, covers the pixel (but on that mirrored
    silhouette's one-pixel border), and the background (blue) elsewhere."""
    a = render_scene(_floor_scene(tmp_path)).channels
    b = render_scene(_floor_scene(tmp_path, mirrored_only=True)).channels
    floor = a["object_id"] == 1
    shows_blob = floor & (a["B"] < 0.45)
    seen = b["A"] > 0.0
    border = _grow(seen) & _grow(~seen)  # (pixels within one of the mirrored silhouette)
    check = floor & ~border & ~_grow(a["object_id"] == 0)
    assert np.count_nonzero(seen & check) > 200  # (the reflection is there, and large)
    assert np.array_equal(shows_blob[check], seen[check])
    # the floor shows the background's blue, times Fresnel 1 (a white metal), elsewhere
    rest = check & ~seen
    assert np.allclose(a["B"][rest], BLUE[2], atol=1e-6)
    assert np.allclose(a["R"][rest], BLUE[0], atol=1e-6)


def _blob_scene(tmp_path, color, metallic, roughness=0.0, env=None, background=None,
                samples=8, width=80, height=60):
    _files(tmp_path)
    lights = [] if env is None else [{"kind": "environment", "color": env}]
    return scene_from_dict({
        "object": [{"mesh": str(tmp_path / "cube.obj"), "color": color,
                    "metallic": metallic, "roughness": roughness}],
        "camera": {"eye": [2.5, 1.8, 4.0], "target": [0.0, 0.0, 0.0], "width": width,
                   "height": height},
        "render": {"headlight": False, "samples": 1, "reflection_samples": samples,
                   "background": background or [0.0, 0.0, 0.0]},
        "light": lights, "ground": False}, base_dir=tmp_path)


def _cosines(ch, eye):
    """Per covered pixel: the cosine of its normal (N, turned to the eye) with the view."""
    hit = ch["A"] > 0.0
    p = np.stack([ch["P.X"], ch["P.Y"], ch["P.Z"]], axis=-1)[hit].astype(np.float64)
    n = np.stack([ch["N.X"], ch["N.Y"], ch["N.Z"]], axis=-1)[hit].astype(np.float64)
    v = np.asarray(eye) - p
    v /= np.linalg.norm(v, axis=1)[:, None]
    n /= np.linalg.norm(n, axis=1)[:, None]
    return hit, np.abs((n * v).sum(axis=1))


def _schlick(f0, c):
    return f0 + (1.0 - f0) * (1.0 - c)[:, None] ** 5


@pytest.mark.parametrize("metallic", [1.0, 0.0])
def test_a_mirror_under_a_constant_sky_shows_it_times_fresnel(tmp_path, metallic):
    """A blob (convex: its reflected rays escape) of roughness 0 under a constant
    environment of radiance L shows F pi L + (1 - F) (1 - metallic) colour pi L, F
    Schlick's term of its reflectance ((1 - m) 0.04 + m colour) at the pixel's angle;
    within 2e-5 (float32 channels, the normal's rounding)."""
    color, sky = np.array([0.9, 0.6, 0.3]), 0.5
    ch = render_scene(_blob_scene(tmp_path, list(color), metallic, env=[sky] * 3)).channels
    hit, c = _cosines(ch, [2.5, 1.8, 4.0])
    f0 = (1.0 - metallic) * 0.04 + metallic * color
    f = _schlick(f0, c)
    want = f * math.pi * sky + (1.0 - f) * (1.0 - metallic) * color * math.pi * sky
    got = np.stack([ch["R"], ch["G"], ch["B"]], axis=-1)[hit]
    assert np.count_nonzero(hit) > 800
    assert np.abs(got - want).max() < 2e-5


def test_a_mirror_without_an_environment_shows_the_background_times_fresnel(tmp_path):
    """No lights, one background colour b: a metal mirror shows F b, a dielectric one F b
    (its diffuse part unlit)."""
    back = np.array([0.2, 0.4, 0.6])
    for metallic in (1.0, 0.0):
        ch = render_scene(_blob_scene(tmp_path, [0.9, 0.6, 0.3], metallic,
                                      background=list(back))).channels
        hit, c = _cosines(ch, [2.5, 1.8, 4.0])
        f0 = (1.0 - metallic) * 0.04 + metallic * np.array([0.9, 0.6, 0.3])
        got = np.stack([ch["R"], ch["G"], ch["B"]], axis=-1)[hit]
        assert np.abs(got - _schlick(f0, c) * back).max() < 2e-5


def _ggx_albedo(mu, alpha, n_theta=600, n_phi=600):
    """The directional albedo of GGX (Fresnel 1, Smith's height-correlated masking) for
    the view at cosine ``mu``: the integral over the hemisphere of D G2 / (4 mu), by the
    midpoint rule in (cos theta, phi) of the light's direction."""
    a2 = alpha * alpha
    v = np.array([math.sqrt(max(0.0, 1.0 - mu * mu)), 0.0, mu])
    ct = (np.arange(n_theta) + 0.5) / n_theta
    ph = (np.arange(n_phi) + 0.5) / n_phi * 2.0 * math.pi
    ct, ph = np.meshgrid(ct, ph, indexing="ij")
    st = np.sqrt(1.0 - ct * ct)
    lx, ly, lz = st * np.cos(ph), st * np.sin(ph), ct
    hx, hy, hz = lx + v[0], ly + v[1], lz + v[2]
    hn = np.sqrt(hx * hx + hy * hy + hz * hz)
    ch = hz / hn
    d = a2 / (math.pi * (ch * ch * (a2 - 1.0) + 1.0) ** 2)

    def lam(c):
        return 0.5 * (np.sqrt(1.0 + a2 * (1.0 - c * c) / (c * c)) - 1.0)

    g2 = 1.0 / (1.0 + lam(mu) + lam(lz))
    f = d * g2 / (4.0 * mu)
    return float(f.sum() * (1.0 / n_theta) * (2.0 * math.pi / n_phi))


def test_a_glossy_metal_in_a_white_furnace_returns_the_lobes_albedo(tmp_path):
    """A white metal of roughness 0.5 under a constant sky of radiance 1: each pixel's
    mean of 32 sampled rays against pi times the lobe's directional albedo at its angle
    (a quadrature of the lobe: energy lost to masking only). Over ~900 pixels the mean
    difference is within 0.005 (the samples' noise averaged; the quadrature's error is
    below 1e-4) and each pixel within 0.35 (32 rays of weights from 0 to 1: one pixel's
    noise, about 10% of its value at the most)."""
    alpha = 0.25
    ch = render_scene(_blob_scene(tmp_path, [1.0, 1.0, 1.0], 1.0, roughness=0.5,
                                  env=[1.0, 1.0, 1.0], samples=32)).channels
    hit, c = _cosines(ch, [2.5, 1.8, 4.0])
    keep = c > 0.05  # (grazing pixels: their normal's rounding matters)
    table_mu = np.linspace(0.05, 1.0, 40)
    table = np.array([_ggx_albedo(m, alpha) for m in table_mu])
    # (the lobe loses energy: rays below the horizon, masking)
    assert 0.8 < table.min() and table.max() < 0.95
    want = math.pi * np.interp(c[keep], table_mu, table)
    got = ch["G"][hit][keep].astype(np.float64)
    assert np.count_nonzero(keep) > 800
    assert abs((got - want).mean()) < 0.005
    assert np.abs(got - want).max() < 0.35


def test_a_glossy_floor_tends_to_the_mirror(tmp_path):
    """The floor's pixels for roughness 0.3, 0.1, 0.02 against the mirror's (roughness
    0): the mean difference falls with the roughness and is below 0.01 at 0.02."""
    mirror = render_scene(_floor_scene(tmp_path, 0.0)).channels
    floor = mirror["object_id"] == 1
    errors = []
    for roughness in (0.3, 0.1, 0.02):
        ch = render_scene(_floor_scene(tmp_path, roughness)).channels
        assert np.array_equal(ch["object_id"], mirror["object_id"])
        errors.append(float(np.mean([np.abs(ch[k][floor] - mirror[k][floor]).mean()
                                     for k in "RGB"])))
    assert errors[0] > errors[1] > errors[2], errors
    assert errors[2] < 0.01, errors


def test_reflections_do_not_depend_on_threads_or_tiles(tmp_path):
    """A glossy floor with adaptive anti-aliasing and a reflection of a reflection: the
    same image on 1 and 2 threads, and a tile of it alone is its pixels bit for bit."""
    scene = _floor_scene(tmp_path, 0.2, samples=4, extra={"reflection_depth": 2})
    one = render_scene(scene, threads=1)
    two = render_scene(scene, threads=2).channels
    assert one.stats.reflection_rays > 0
    for c in one.channels:
        assert one.channels[c].tobytes() == two[c].tobytes(), c
    tile = render_scene(scene, threads=2, crop=(24, 16, 72, 56)).channels
    for c in one.channels:
        assert tile[c].tobytes() == np.ascontiguousarray(
            one.channels[c][16:56, 24:72]).tobytes(), c


def test_materials_without_reflection_send_no_reflected_rays(tmp_path):
    """A floor whose material gives neither metallic nor roughness: no reflected ray; and
    the blob, which does not reflect, has the same colour bit for bit over a mirror floor
    as over that one (its lighting alone)."""
    scene = _floor_scene(tmp_path)
    plain = scene_from_dict({
        "object": [dict(o) for o in [
            {"mesh": str(tmp_path / "cube.obj"), "color": [1.0, 0.0, 0.0], "scale": 0.8,
             "translate": [0.0, 1.4, 0.0]},
            {"mesh": str(tmp_path / "plane.obj"), "color": [1.0, 1.0, 1.0]}]],
        "camera": {"eye": EYE, "target": [0.0, 0.2, 0.0], "width": 96, "height": 72},
        "render": {"headlight_intensity": 0.5, "samples": 1, "background": BLUE},
        "light": [{"direction": [-0.3, -1.0, -0.4], "intensity": 0.8}],
        "ground": False}, base_dir=tmp_path)
    a = render_scene(plain)
    b = render_scene(scene).channels
    assert a.stats.reflection_rays == 0
    blob = a.channels["object_id"] == 0
    for k in "RGB":
        assert a.channels[k][blob].tobytes() == b[k][blob].tobytes()


# --------------------------------------------------------------------------------------
# materials and bad values
# --------------------------------------------------------------------------------------


def test_mtl_reflection_statements(tmp_path):
    """MTL's Pm / Pr set metallic and roughness (either alone: the other 0), illum 3 a
    reflection of colour Ks with the gloss of Ns (its Blinn-Phong lobe then the
    reflection's), illum 2 none."""
    (tmp_path / "m.mtl").write_text(
        "newmtl metal\nKd 0.8 0.5 0.2\nPm 1\nPr 0.25\n"
        "newmtl varnish\nKd 0.5 0.5 0.5\nPr 0.1\n"
        "newmtl classic\nKd 0.3 0.3 0.3\nKs 0.5 0.5 0.5\nNs 98\nillum 3\n"
        "newmtl plastic\nKd 0.3 0.3 0.3\nKs 0.5 0.5 0.5\nNs 98\nillum 2\n")
    (tmp_path / "a.obj").write_text("mtllib m.mtl\n" + CUBE.replace(
        "f 1 4", "usemtl metal\nf 1 4"))
    mats = {m.name: m for m in read_obj(tmp_path / "a.obj").materials}
    assert (mats["metal"].metallic, mats["metal"].roughness) == (1.0, 0.25)
    assert (mats["varnish"].metallic, mats["varnish"].roughness) == (0.0, 0.1)
    assert mats["classic"].metallic is None
    assert mats["classic"].roughness == pytest.approx((2.0 / 100.0) ** 0.25)
    assert (mats["plastic"].metallic, mats["plastic"].roughness) == (None, None)
    color, spec, _, f0, rough = material_of(mats["metal"])
    assert np.allclose(color, 0.0) and np.allclose(f0, [0.8, 0.5, 0.2]) and rough == 0.25
    color, _, _, f0, _ = material_of(mats["varnish"])
    assert np.allclose(color, 0.5) and np.allclose(f0, 0.04)
    color, spec, _, f0, _ = material_of(mats["classic"])
    assert np.allclose(f0, 0.5) and np.allclose(spec, 0.0) and np.allclose(color, 0.3)
    assert np.allclose(material_of(mats["plastic"])[3], 0.0)


def _run(capsys, argv):
    code = main([str(a) for a in argv])
    return code, capsys.readouterr()[1]


@pytest.mark.parametrize("key, value, words", [
    ("roughness", "-0.1", "roughness, a number from 0 to 1"),
    ("metallic", "1.5", "metallic, a number from 0 to 1"),
    ("metallic", '"shiny"', "metallic, a number from 0 to 1"),
])
def test_bad_scene_values_are_one_clear_error(tmp_path, capsys, key, value, words):
    """A scene's bad metallic / roughness: exit code 2, one line naming the file, line and
    key."""
    (tmp_path / "cube.obj").write_text(CUBE)
    text = f'[[object]]\nmesh = "cube.obj"\n{key} = {value}\n'
    path = tmp_path / "scene.toml"
    path.write_text(text)
    code, err = _run(capsys, ["render", path, "-o", tmp_path / "o.exr", "--quiet"])
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert f"{path}:3" in lines[0] and key in lines[0] and words in lines[0], err


@pytest.mark.parametrize("key, value, words", [
    ("reflection_depth", "9", "from 0 to 8"),
    ("reflection_samples", "0", "from 1 to 256"),
    ("reflection_depth", "1.5", "from 0 to 8"),
])
def test_bad_render_values_are_one_clear_error(tmp_path, key, value, words):
    (tmp_path / "cube.obj").write_text(CUBE)
    path = tmp_path / "scene.toml"
    path.write_text(f'[[object]]\nmesh = "cube.obj"\n\n[render]\n{key} = {value}\n')
    with pytest.raises(Exception) as err:
        load_scene(path)
    assert f"{path}:5" in str(err.value) and words in str(err.value), str(err.value)


@pytest.mark.parametrize("line, words", [
    ("Pr -0.2", "Pr needs one number between 0 and 1"),
    ("Pm 2", "Pm needs one number between 0 and 1"),
    ("Pm metal", "Pm needs one number between 0 and 1"),
    ("illum 3.5", "illum needs one whole number 0..10"),
])
def test_bad_mtl_values_are_one_clear_error(tmp_path, capsys, line, words):
    """An MTL's bad Pm / Pr / illum: exit code 2, one line naming the MTL file and line."""
    (tmp_path / "m.mtl").write_text(f"newmtl a\nKd 0.5 0.5 0.5\n{line}\n")
    (tmp_path / "a.obj").write_text("mtllib m.mtl\nusemtl a\n" + CUBE)
    code, err = _run(capsys, ["render", tmp_path / "a.obj", "-o", tmp_path / "o.exr",
                              "--quiet", "--width", "16", "--height", "12"])
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert f"{tmp_path / 'm.mtl'}:3" in lines[0] and words in lines[0], err


def test_a_mirror_shows_the_objects_image_texture(tmp_path):
    """A blob with a checker image texture (one UV square per cage face) over the mirror
    floor: where the floor shows it, the reflection has the texture's two colours where
    the blob mirrored through the floor, rendered alone, has them (the hue of each pixel,
    its blue over its red, on the same side of 1 at 80 % of the pixels well inside a
    square of the lone blob's, at 96x72: the reflection's lighting and cone blur the
    squares' edges there)."""
    import OpenImageIO as oiio

    n, k = 64, 4
    y, x = np.mgrid[0:n, 0:n]
    c = ((x // (n // k) + y // (n // k)) % 2).astype(np.float32)
    img = np.stack([0.1 + 0.8 * c, 0.1 + 0.1 * c, 0.9 - 0.8 * c], axis=2)
    assert oiio.ImageBuf(np.ascontiguousarray(img)).write(str(tmp_path / "chk.png"), "uint8")
    scenes = []
    for mirrored in (False, True):
        scene = _floor_scene(tmp_path, mirrored_only=mirrored)
        faces = CUBE.splitlines()[8:]
        vt = "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
        (tmp_path / "cube.obj").write_text(
            "\n".join(CUBE.splitlines()[:8]) + "\n" + vt + "".join(
                "f " + " ".join(f"{v}/{j + 1}" for j, v in enumerate(f.split()[1:])) + "\n"
                for f in faces))
        obj = scene.objects[0]
        from dataclasses import replace

        from subtrace.io.obj import TextureMap

        tex = TextureMap("diffuse", str(tmp_path / "chk.png"), "test")
        scenes.append(replace(scene, objects=(replace(obj, color=None, textures=(tex,)),
                                              *scene.objects[1:])))
    a = render_scene(scenes[0]).channels
    b = render_scene(scenes[1]).channels
    floor = a["object_id"] == 1
    seen = b["A"] > 0.0
    inside = floor & seen & ~_grow(_grow(~seen)) & ~_grow(a["object_id"] == 0)
    assert np.count_nonzero(inside) > 150
    ra, ba, rb, bb = (ch[k][inside].astype(np.float64) for ch in (a, b) for k in ("R", "B"))
    # (the pixels well inside a square of the checker in the lone blob's picture: the
    # reflection, lit from another side and looked up over a wider cone, blurs its edges)
    sure = np.abs(bb - rb) > 0.5 * (bb + rb)
    assert sure.sum() > 80 and 0.2 < (bb > rb)[sure].mean() < 0.8  # (both colours)
    assert 0.2 < (ba > ra)[sure].mean() < 0.8  # (the reflection has both too)
    # (the blob's constant colour in the mirror would agree at about half of them)
    assert ((ba > ra) == (bb > rb))[sure].mean() >= 0.8
