"""Image textures (subtrace.textures): filtering over the ray cones' footprints (a
checkerboard plane at a grazing angle far away averages to its mean, with 1 or 16 rays a
pixel alike, and stays sharp near), the hits' UVs against the cage's exact face-varying
evaluation, bump and normal maps against their analytic normals, a missing or unreadable
texture (one warning, the constant colour), and bad texture keys in a scene (one line,
exit code 2)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import subtrace
from subtrace.cli import main
from subtrace.errors import SubtraceWarning
from subtrace.io.scene import scene_from_dict
from subtrace.render import render_scene

# the plane: y = 0, x and z in [-HALF, HALF], its texture repeated REPEAT times across
HALF, REPEAT, CHECKS = 100.0, 50, 8


def _image(path, pixels):
    """Write ``pixels`` (h, w, c) float32 to ``path`` with OpenImageIO (a PNG as 8 bits)."""
    import OpenImageIO as oiio

    h, w, c = pixels.shape
    fmt = oiio.UINT8 if str(path).endswith(".png") else oiio.FLOAT
    buf = oiio.ImageBuf(oiio.ImageSpec(w, h, c, fmt))
    buf.set_pixels(oiio.ROI(), np.ascontiguousarray(pixels, np.float32))
    assert buf.write(str(path)), oiio.geterror()
    return path


def _checker(path, size=256):
    """A black and white checkerboard of CHECKS x CHECKS squares (its mean: 0.5 linear)."""
    i = np.arange(size) * CHECKS // size
    board = ((i[:, None] + i[None, :]) % 2).astype(np.float32)
    return _image(path, np.repeat(board[:, :, None], 3, axis=2))


def _plane(path, repeat=REPEAT, n=4):
    """An n x n quad grid on y = 0 (normal +y, corners kept: edge-and-corner), vt from 0 to
    ``repeat`` across: the limit surface is the plane and its UV (linear mode) is
    ((x + HALF) / (2 HALF), (z + HALF) / (2 HALF)) times ``repeat``."""
    xs = np.linspace(-HALF, HALF, n + 1)
    lines = ["t interpolateboundary 1/0/0 1"]
    lines += [f"v {x} 0 {z}" for z in xs for x in xs]
    lines += [f"vt {repeat * (x + HALF) / (2 * HALF)} {repeat * (z + HALF) / (2 * HALF)}"
              for z in xs for x in xs]
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i + 1
            c = (a, a + n + 1, a + n + 2, a + 1)  # (counter-clockwise seen from +y)
            lines.append("f " + " ".join(f"{k}/{k}" for k in c))
    path.write_text("\n".join(lines) + "\n")
    return path


def _scene(tmp_path, mesh, eye, target, size=(160, 120), samples=1, light=None, **obj):
    """The plane lit by one light straight down (intensity 1, no headlight, no shadows):
    a pixel's colour is its albedo (Lambert, n.l = 1)."""
    return scene_from_dict({
        "object": [{"mesh": str(mesh), **obj}],
        "camera": {"eye": list(eye), "target": list(target), "width": size[0],
                   "height": size[1], "fov": 30.0},
        "render": {"headlight": False, "shadows": False, "samples": samples,
                   "background": [0.0, 0.0, 0.0]},
        "light": [light or {"direction": [0.0, -1.0, 0.0], "intensity": 1.0}],
        "ground": False,
    }, base_dir=tmp_path)


def _grey(result):
    ch = result.channels
    return np.stack([ch["R"], ch["G"], ch["B"]]).mean(axis=0)


@pytest.fixture(scope="module")
def grazing(tmp_path_factory):
    """The checkerboard plane seen from 1 unit above it, along it: renders with 1 and 16
    rays a pixel."""
    d = tmp_path_factory.mktemp("grazing")
    _checker(d / "check.png")
    mesh = _plane(d / "plane.obj")
    out = {}
    for samples in (1, 16):
        scene = _scene(d, mesh, (0.0, 1.0, 95.0), (0.0, 0.0, 0.0), samples=samples,
                       diffuse_texture="check.png")
        out[samples] = render_scene(scene)
    return out


def test_far_checkerboard_averages_to_its_mean(grazing):
    """Far away at a grazing angle (40 to 150 units, incidence 84-89.6 degrees: hundreds of
    checks a pixel) every pixel is the board's mean, 0.5, within 0.05 (the MIP levels'
    box averages are 0.5 exactly; what is left is the anisotropic filter's edge and the
    tilt of the footprint across rows): no shimmer; point sampling would give 0 or 1."""
    res = grazing[1]
    z = res.channels["Z"]
    far = (z > 40.0) & (z < 150.0)
    assert far.sum() > 300
    grey = _grey(res)[far]
    assert abs(grey.mean() - 0.5) < 0.02, grey.mean()
    assert np.abs(grey - 0.5).max() < 0.1, np.abs(grey - 0.5).max()
    assert grey.std() < 0.03, grey.std()


def test_near_checkerboard_stays_sharp(grazing):
    """Near (under 6 units: about 0.013 units a pixel, a check is 0.5) the checks keep their
    black and white."""
    res = grazing[1]
    z = res.channels["Z"]
    near = (z > 0.0) & (z < 6.0)
    assert near.sum() > 500
    grey = _grey(res)[near]
    assert np.quantile(grey, 0.2) < 0.05 and np.quantile(grey, 0.8) > 0.95


def test_one_and_sixteen_rays_agree_far_away(grazing):
    """The far region with 16 rays a pixel (where anti-aliasing adds them) is the image of
    1 ray within noise: the filter did the averaging already."""
    z = grazing[1].channels["Z"]
    far = (z > 40.0) & (z < 150.0)
    one, many = _grey(grazing[1])[far], _grey(grazing[16])[far]
    assert abs(one.mean() - many.mean()) < 0.01
    assert np.abs(one - many).max() < 0.08


def _uv_ramp(path, size=512):
    """A float image whose R, G are its own (u, v) (OBJ's v up), B 0: a linear function,
    which bilinear lookups and the MIP levels' box averages keep exactly."""
    s = (np.arange(size) + 0.5) / size
    img = np.zeros((size, size, 3), np.float32)
    img[:, :, 0] = s[None, :]
    img[:, :, 1] = 1.0 - s[:, None]  # (row 0: the top, v = 1)
    return _image(path, img)


def test_hit_uvs_are_the_cages_exact_uvs(tmp_path):
    """Spot with a UV ramp texture: each covered pixel's colour over that of the same
    render in white (the lighting is linear in the albedo) is the limit UV at its ptex
    point (the EXR's patch_id, u, v) as ``Cage.evaluate_uv`` gives it (OpenSubdiv's rules,
    tests/test_facevarying.py): within 1e-5 (the float32 channels; a linear ramp's filtered
    value is its value at the footprint's centre), away from the texture's border (its
    lookups wrap around) and from grazing views (incidence over 75 degrees: footprints
    long enough to wrap)."""
    from subtrace.data import sample_cage_path

    _uv_ramp(tmp_path / "ramp.exr")
    kw = dict(eye=(2.55, 1.31, -2.85), target=(0.0, 0.04, 0.16), size=(200, 150),
              light={"direction": [0.3, -1.0, 0.6], "intensity": 1.0})
    white = render_scene(_scene(tmp_path, sample_cage_path(), color=[1.0, 1.0, 1.0], **kw))
    ramp = render_scene(_scene(tmp_path, sample_cage_path(), diffuse_texture="ramp.exr",
                               **kw))
    ch, w = ramp.channels, white.channels
    P = np.stack([ch["P.X"], ch["P.Y"], ch["P.Z"]], -1) - np.array(kw["eye"])
    N = np.stack([ch["N.X"], ch["N.Y"], ch["N.Z"]], -1)
    cos = np.abs((P * N).sum(-1)) / np.maximum(np.linalg.norm(P, axis=-1), 1e-30)
    lit = (ch["patch_id"] >= 0) & (w["R"] > 0.1) & (cos > 0.25)
    assert lit.sum() > 3000
    cage = subtrace.load_cage(sample_cage_path())
    face = ch["patch_id"][lit].astype(np.int64)
    uv = np.clip(np.stack([ch["u"][lit], ch["v"][lit]], 1).astype(np.float64), 0, 1)
    ref = cage.evaluate_uv(face, uv)
    got = np.stack([ch["R"][lit] / w["R"][lit], ch["G"][lit] / w["G"][lit]], 1)
    inside = ((ref > 0.01) & (ref < 0.99)).all(axis=1)
    err = np.abs(got - ref)[inside]
    assert np.quantile(err, 0.99) < 2e-3 and err.max() < 1e-2, (np.quantile(err, 0.99),
                                                                 err.max())


def test_cage_uvs_match_evaluate_uv():
    """``textures.cage_uvs``'s closed form for the linear mode: the UVs of
    ``Cage.evaluate_uv`` and its Jacobian, a central difference of it (Spot: quads,
    pentagons' sub-faces, triangles)."""
    from subtrace.data import sample_cage_path
    from subtrace.patches.evaluate import ptex_starts
    from subtrace.textures import cage_uvs

    cage = subtrace.load_cage(sample_cage_path())
    rng = np.random.default_rng(7)
    m = 4000
    face = rng.integers(0, int(ptex_starts(cage)[-1]), m)
    x = rng.uniform(0.01, 0.99, (m, 2))
    st, jac = cage_uvs(cage, face, x)
    np.testing.assert_allclose(st, cage.evaluate_uv(face, x), atol=1e-12)
    h = 1e-6
    for k, step in enumerate(([h, 0.0], [0.0, h])):
        diff = (cage.evaluate_uv(face, x + step) - cage.evaluate_uv(face, x - step)) / (2 * h)
        np.testing.assert_allclose(jac[:, :, k], diff, atol=1e-7)


def _flat(path, rgb, size=16):
    return _image(path, np.tile(np.asarray(rgb, np.float32), (size, size, 1)))


def test_flat_normal_map_and_bump_map_leave_the_shading(tmp_path):
    """A normal map of (0.5, 0.5, 1) (the unperturbed normal) and a constant bump map
    render as no map (to the normal map's 8-bit rounding: 1/255 of a radian at most)."""
    mesh = _plane(tmp_path / "plane.obj", repeat=1)
    _image(tmp_path / "flat.exr", np.tile(np.float32([0.5, 0.5, 1.0]), (8, 8, 1)))
    _flat(tmp_path / "height.exr", [0.7, 0.7, 0.7])
    light = {"direction": [0.6, -1.0, 0.3], "intensity": 1.0}
    kw = dict(eye=(0.0, 60.0, 80.0), target=(0.0, 0.0, 0.0), light=light)
    plain = _grey(render_scene(_scene(tmp_path, mesh, **kw)))
    normal = _grey(render_scene(_scene(tmp_path, mesh, normal_texture="flat.exr", **kw)))
    bump = _grey(render_scene(_scene(tmp_path, mesh, bump_texture="height.exr",
                                     bump_scale=3.0, **kw)))
    hit = plain > 0
    assert hit.sum() > 5000
    np.testing.assert_allclose(normal[hit], plain[hit], atol=1e-5)
    np.testing.assert_allclose(bump[hit], plain[hit], atol=1e-5)


def test_tilted_normal_map_and_ramp_bump_turn_the_normal_as_analytic(tmp_path):
    """On the plane (tangent +x along u, +z along v, normal +y): a normal map of constant
    tangent-space (sin a, 0, cos a) turns the normal to (sin a, cos a, 0); a bump map of
    height u (a ramp across the plane's 2 HALF units), times bump_scale k, turns it to
    (-g, 1, 0) / |.| with g = k / (2 HALF). Lit by a light straight down (colour = the
    normal's y), the renders are those cosines (within the 8-bit ramp's steps and the
    filter's)."""
    mesh = _plane(tmp_path / "plane.obj", repeat=1)
    a = 0.5
    tilt = np.float32([np.sin(a), 0.0, np.cos(a)]) * 0.5 + 0.5
    _image(tmp_path / "tilt.exr", np.tile(tilt, (8, 8, 1)))
    _uv_ramp(tmp_path / "ramp.exr", 256)  # (R: u)
    kw = dict(eye=(0.0, 60.0, 80.0), target=(0.0, 0.0, 0.0), color=[1.0, 1.0, 1.0])
    got = _grey(render_scene(_scene(tmp_path, mesh, normal_texture="tilt.exr", **kw)))
    hit = got > 0
    assert hit.sum() > 5000
    np.testing.assert_allclose(got[hit], np.cos(a), atol=2e-3)
    k = 150.0
    res = render_scene(_scene(tmp_path, mesh, bump_texture="ramp.exr", bump_scale=k, **kw))
    g = k / (2 * HALF)
    grey = _grey(res)
    x = res.channels["P.X"]
    inside = hit & (np.abs(x) < 0.9 * HALF)  # (the ramp wraps at the border)
    np.testing.assert_allclose(grey[inside], 1.0 / np.sqrt(1 + g * g), atol=5e-3)
    # and lit from the side, the sign: the normal leans towards -x
    side = {"direction": [1.0, 0.0, 0.0], "intensity": 1.0}
    res = render_scene(_scene(tmp_path, mesh, bump_texture="ramp.exr", bump_scale=k,
                              light=side, **kw))
    np.testing.assert_allclose(_grey(res)[inside], g / np.sqrt(1 + g * g), atol=5e-3)


def test_missing_texture_warns_once_and_renders_the_constant_colour(tmp_path):
    mesh = _plane(tmp_path / "plane.obj")
    kw = dict(eye=(0.0, 60.0, 80.0), target=(0.0, 0.0, 0.0))
    plain = render_scene(_scene(tmp_path, mesh, color=[0.3, 0.5, 0.7], **kw))
    with pytest.warns(SubtraceWarning) as caught:
        res = render_scene(_scene(tmp_path, mesh, color=[0.3, 0.5, 0.7],
                                  diffuse_texture="nowhere.png", **kw))
    mine = [str(w.message) for w in caught if "nowhere.png" in str(w.message)]
    assert len(mine) == 1, mine
    assert "object[0].diffuse_texture" in mine[0] and "no such file" in mine[0]
    assert "constant colour" in mine[0]
    for c in ("R", "G", "B"):
        np.testing.assert_array_equal(res.channels[c], plain.channels[c])


def test_unreadable_mtl_texture_warns_naming_the_mtl_line(tmp_path):
    """An MTL map_Kd whose file is there but is no image: one warning naming the file and
    the MTL line; the material's Kd is rendered."""
    (tmp_path / "bad.png").write_bytes(b"not an image at all")
    (tmp_path / "m.mtl").write_text("newmtl skin\nKd 0.2 0.4 0.6\nmap_Kd bad.png\n")
    mesh = _plane(tmp_path / "plane.obj")
    text = mesh.read_text()
    mesh.write_text("mtllib m.mtl\nusemtl skin\n" + text)
    kw = dict(eye=(0.0, 60.0, 80.0), target=(0.0, 0.0, 0.0))
    with pytest.warns(SubtraceWarning) as caught:
        res = render_scene(_scene(tmp_path, mesh, **kw))
    mine = [str(w.message) for w in caught if "bad.png" in str(w.message)]
    assert len(mine) == 1, mine
    assert "m.mtl:3" in mine[0] and "not read" in mine[0]
    hit = res.channels["A"] > 0
    np.testing.assert_allclose(res.channels["B"][hit] / res.channels["R"][hit], 3.0,
                               rtol=1e-5)


def test_mtl_map_kd_multiplies_kd(tmp_path):
    """An MTL map_Kd is multiplied by the material's Kd (the MTL format's rule): a white
    texture renders as Kd."""
    _flat(tmp_path / "white.png", [1.0, 1.0, 1.0])
    (tmp_path / "m.mtl").write_text("newmtl skin\nKd 0.2 0.4 0.6\nmap_Kd white.png\n")
    mesh = _plane(tmp_path / "plane.obj")
    mesh.write_text("mtllib m.mtl\nusemtl skin\n" + mesh.read_text())
    res = render_scene(_scene(tmp_path, mesh, eye=(0.0, 60.0, 80.0), target=(0.0, 0.0, 0.0)))
    hit = res.channels["A"] > 0
    for c, kd in zip("RGB", (0.2, 0.4, 0.6)):
        np.testing.assert_allclose(res.channels[c][hit], kd, rtol=1e-5)


@pytest.mark.parametrize("line, words", [
    ('diffuse_texture = 3', "expected an image file name"),
    ('bump_scale = "big"', "expected a number"),
    ('normal_texture = ""', "expected an image file name")])
def test_bad_texture_key_is_one_line_exit_2(tmp_path, capsys, line, words):
    mesh = _plane(tmp_path / "plane.obj")
    extra = 'bump_texture = "h.png"\n' if line.startswith("bump_scale") else ""
    scene = tmp_path / "s.toml"
    scene.write_text(f'[[object]]\nmesh = "{mesh.name}"\n{extra}{line}\n')
    code = main(["render", str(scene), "-o", str(tmp_path / "o.exr"), "--width", "16",
                 "--height", "12", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    row = 4 if extra else 3
    assert f"s.toml:{row}:" in lines[0] and words in lines[0], err
    assert not (tmp_path / "o.exr").exists()


def test_bump_scale_scales_the_mtl_bump_map_too(tmp_path):
    """A scene's bump_scale without a bump_texture scales the materials' bump maps (their
    -bm replaced): a ramp bump of the MTL turns the normal as the scene's own would."""
    _uv_ramp(tmp_path / "ramp.exr", 256)
    (tmp_path / "m.mtl").write_text("newmtl skin\nKd 1 1 1\nbump -bm 7 ramp.exr\n")
    mesh = _plane(tmp_path / "plane.obj", repeat=1)
    mesh.write_text("mtllib m.mtl\nusemtl skin\n" + mesh.read_text())
    kw = dict(eye=(0.0, 60.0, 80.0), target=(0.0, 0.0, 0.0))
    a = render_scene(_scene(tmp_path, mesh, bump_scale=150.0, **kw))
    b = render_scene(_scene(tmp_path, mesh, bump_texture="ramp.exr", bump_scale=150.0,
                            color=[1.0, 1.0, 1.0], **kw))
    np.testing.assert_array_equal(_grey(a), _grey(b))


def test_textures_are_made_once_into_the_cache(tmp_path, monkeypatch):
    """The tiled MIP-mapped file lies in the kernel cache's base folder under textures/,
    is made on first use and found again; a newer file (another mtime or size) makes a
    new one."""
    from subtrace.io.obj import TextureMap
    from subtrace.textures import prepare, texture_folder

    monkeypatch.setenv("SUBTRACE_CACHE_DIR", str(tmp_path / "cache"))
    src = _checker(tmp_path / "c.png", 64)
    tmap = TextureMap("diffuse", str(src), "here")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        a = prepare(tmap)
        b = prepare(tmap)
    assert a.file == b.file and a.file.startswith(str(tmp_path / "cache" / "textures"))
    assert texture_folder() == tmp_path / "cache" / "textures"
    assert (a.width, a.height) == (64, 64)
    _checker(src, 128)
    c = prepare(tmap)
    assert c.file != a.file and (c.width, c.height) == (128, 128)


# --------------------------------------------------------------------------------------
# the MIP-map filter against OpenImageIO's TextureSystem
# --------------------------------------------------------------------------------------


def _texture_system_lookup(ts, prep, st, major, minor, channels):
    """The lookups of ``textures.lookup`` made one by one through OpenImageIO's
    TextureSystem ``ts`` (its default MIP mode, bilinear, the map's wrap, -s / -o and
    channel, ``gray_to_rgb`` on): the reference the Numba filter follows."""
    import OpenImageIO as oiio

    from subtrace.textures import ANISOTROPY

    tmap = prep.map
    sc = np.asarray(tmap.scale)
    s = st[:, 0] * sc[0] + tmap.offset[0]
    t = 1.0 - (st[:, 1] * sc[1] + tmap.offset[1])  # (OpenImageIO's t: down from the top)
    a, b = major * sc, minor * sc
    opt = oiio.TextureOpt()
    opt.swrap = opt.twrap = oiio.Wrap.Clamp if tmap.clamp else oiio.Wrap.Periodic
    opt.anisotropic = ANISOTROPY
    opt.interpmode = oiio.InterpMode.Bilinear
    opt.firstchannel = tmap.channel if tmap.slot == "bump" else 0
    rows = zip(s.tolist(), t.tolist(), a[:, 0].tolist(), a[:, 1].tolist(), b[:, 0].tolist(),
               b[:, 1].tolist())
    return np.array([ts.texture(prep.file, opt, s0, t0, a0, -a1, b0, -b1, channels)
                     for s0, t0, a0, a1, b0, b1 in rows], np.float32).reshape(len(st), channels)


def _random_footprints(rng, m):
    """``m`` UVs in [-0.5, 1.5]^2 (both wraps at work) and footprints of any orientation, a
    minor axis from 1e-5 (far under a texel: near) to 2 (past the whole texture: far),
    an aspect from 1 to 316 (past ANISOTROPY) and axes up to 27 degrees off orthogonal."""
    st = rng.uniform(-0.5, 1.5, (m, 2))
    ang = rng.uniform(0.0, np.pi, m)
    size = 10.0 ** rng.uniform(-5.0, 0.3, m)
    aspect = 10.0 ** rng.uniform(0.0, 2.5, m)
    skew = rng.uniform(-0.5, 0.5, m)
    d = np.stack([np.cos(ang), np.sin(ang)], 1)
    major = d * (size * aspect)[:, None]
    minor = (np.stack([-d[:, 1], d[:, 0]], 1) + skew[:, None] * d) * size[:, None]
    return st, major, minor


@pytest.mark.parametrize("case", ["checker", "checker-clamp", "spot", "bump-channel", "grey"])
def test_lookup_matches_the_texture_system(tmp_path, case):
    """``textures.lookup`` (the Numba MIP-map filter) against OpenImageIO's TextureSystem
    on the same tiled file over 20,000 random UVs and footprints (near and far, isotropic
    to 316:1, both wraps, -s / -o, a bump map's channel, a grey map's one channel spread
    over R, G, B): the mean absolute difference under 1e-4 of the texture's range (0..1)
    and the largest under 1 % of it (measured: means 0.3-1.1e-6, largest 0.6-3e-4; what
    is left is the TextureSystem's float32 arithmetic and its fast exp and atan2)."""
    import OpenImageIO as oiio

    from subtrace.data import sample_cage_path
    from subtrace.io.obj import TextureMap
    from subtrace.textures import lookup, prepare

    rng = np.random.default_rng(11)
    check = str(_checker(tmp_path / "check.png"))
    tmap, channels = {
        "checker": (TextureMap("diffuse", check, "t", scale=(1.5, 0.75), offset=(0.1, -0.3)),
                    3),
        "checker-clamp": (TextureMap("diffuse", check, "t", clamp=True), 3),
        "spot": (TextureMap("diffuse", str(sample_cage_path().parent / "spot_texture.png"),
                            "t"), 3),
        "bump-channel": (TextureMap("bump", str(_image(
            tmp_path / "rgb.exr", rng.uniform(0, 1, (64, 48, 3)).astype(np.float32))), "t",
            channel=1), 1),
        "grey": (TextureMap("diffuse", str(_image(
            tmp_path / "grey.png", rng.uniform(0, 1, (40, 40, 1)).astype(np.float32))), "t"),
            3),
    }[case]
    prep = prepare(tmap)
    st, major, minor = _random_footprints(rng, 20000)
    got = lookup(prep, st, major, minor, channels)
    ts = oiio.TextureSystem(shared=False)
    ts.attribute("gray_to_rgb", 1)
    want = _texture_system_lookup(ts, prep, st, major, minor, channels)
    err = np.abs(got.astype(np.float64) - want)
    assert err.mean() < 1e-4 and err.max() < 1e-2, (err.mean(), err.max())
    if case == "grey":
        np.testing.assert_array_equal(got[:, 1], got[:, 0])
        np.testing.assert_array_equal(got[:, 2], got[:, 0])


def test_lookups_are_the_same_on_any_thread_count():
    """The filter runs on the render's threads, each ray's texel from its own inputs: the
    textured default scene renders the same bit for bit with 1 and 2 threads."""
    from subtrace.data import default_scene_path
    from subtrace.io.scene import apply_overrides, load_scene

    scene = apply_overrides(load_scene(default_scene_path()), width=160, height=90)
    one, two = (render_scene(scene, threads=n).channels for n in (1, 2))
    for c in one:
        np.testing.assert_array_equal(one[c], two[c], err_msg=c)
