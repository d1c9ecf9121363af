"""``subtrace render`` on the command line: outputs, options, progress, bad options."""

from __future__ import annotations

import numpy as np
import pytest
from shared_data import MODELS


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
    assert np.all(np.isinf(ch["Z"][miss])) and np.all(np.isfinite(ch["Z"][ch["A"] == 1]))
    # anti-aliased edges: partial alpha; the centre ray alone writes Z and the ids
    hit = np.isfinite(ch["Z"])
    assert np.all(ch["A"][hit] > 0) and np.any((ch["A"] > 0) & (ch["A"] < 1))
    assert np.all(ch["object_id"][hit] == 0)
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


def test_render_cli_bad_thread_count(tmp_path, capsys):
    from subtrace.cli import main

    out = tmp_path / "x.exr"
    rc = main(["render", "-o", str(out), "--width", "8", "--height", "8", "--threads", "0"])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.count("\n") == 1 and "--threads" in err and "Traceback" not in err
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_render_cli_more_threads_than_cores(tmp_path, capsys):
    """A thread count above the machine's cores (a script from a larger machine) renders on
    every core, with one warning that says so; the image is the one of --threads at most."""
    from subtrace.cli import main
    from subtrace.io.exr import read_exr
    from subtrace.runtime.threads import max_threads

    n = max_threads()
    out = tmp_path / "x.exr"
    rc = main(["render", "-o", str(out), "--width", "24", "--height", "16", "--quiet",
               "--threads", str(64 * n)])
    err = capsys.readouterr().err
    assert rc == 0, err
    assert err.count("\n") == 1 and "warning" in err and f"using {n}" in err, err
    same = tmp_path / "y.exr"
    assert main(["render", "-o", str(same), "--width", "24", "--height", "16", "--quiet",
                 "--threads", str(n)]) == 0
    a, _ = read_exr(out)
    b, _ = read_exr(same)
    assert all(np.array_equal(a[k], b[k], equal_nan=True) for k in a)


CUBE_SCENE_ARGS = ["--width", "40", "--height", "30", "--quiet"]


def _cube(tmp_path):
    """A cube cage in ``tmp_path`` (the renders below need no shared data)."""
    path = tmp_path / "cube.obj"
    path.write_text("v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\n"
                    "v 1 1 1\nv -1 1 1\nf 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\n"
                    "f 3 4 8 7\nf 4 1 5 8\n")
    return path


@pytest.mark.parametrize("name,fmt,bits,channels", [
    ("pic.png", "PNG", 8, "RGBA"), ("pic16.png", "PNG", 16, "RGBA"),
    ("pic.jpg", "JPEG", 8, "RGB"), ("pic.tif", "TIFF", 16, "RGBA"),
])
def test_render_cli_output_format_follows_the_extension(tmp_path, name, fmt, bits, channels):
    """``-o x.png`` (.jpg, .tif) writes that format, readable by another library (Pillow
    for the 8-bit ones), with alpha where the format has it (``--transparent``), sRGB-encoded:
    the same pixels as the EXR's colour after the sRGB transfer function; ``--png`` never
    writes over it."""
    import OpenImageIO as oiio
    from PIL import Image

    from subtrace.cli import main
    from subtrace.io.exr import read_exr, srgb_encode

    cage = _cube(tmp_path)
    out = tmp_path / name
    args = ["render", str(cage), *CUBE_SCENE_ARGS, "--eye", "3", "2.5", "4", "--target", "0", "0",
            "0"]
    assert main([*args, "-o", str(out), "--bit-depth", str(bits), "--png", "--transparent"]) == 0
    assert main([*args, "-o", str(tmp_path / "ref.exr")]) == 0
    spec = oiio.ImageInput.open(str(out)).spec()
    assert spec.nchannels == len(channels) and spec.format.size() * 8 == bits
    assert oiio.ImageInput.open(str(out)).format_name() == {"PNG": "png", "JPEG": "jpeg",
                                                          "TIFF": "tiff"}[fmt]
    if bits == 8:
        img = Image.open(out)
        assert img.format == fmt and img.mode == channels and img.size == (40, 30)
    ref, _ = read_exr(tmp_path / "ref.exr")
    got = oiio.ImageBuf(str(out)).get_pixels(oiio.FLOAT)
    want = np.stack([srgb_encode(ref[c]) for c in "RGB"], axis=-1)
    err = np.abs(got[..., :3] - want)
    if "A" in channels:  # (readers may premultiply by alpha: compare where it is 1)
        err = err[ref["A"] == 1.0]
    # quantisation (half a code) plus the reference's own rounding (the EXR stores colour as
    # half floats: 2^-11 relative, up to 12.92x that after the sRGB curve's steepest part),
    # and JPEG's lossy coding for the jpg
    assert err.max() <= (0.5 / (2**bits - 1) + 12.92 * 2.0**-11 if fmt != "JPEG" else 0.25)
    if "A" in channels:
        np.testing.assert_allclose(got[..., 3], ref["A"], atol=0.5 / (2**bits - 1) + 1e-6)
        assert 0 < ref["A"].sum() < ref["A"].size  # the cube covers part of the image


def test_render_cli_pictures_are_opaque_over_the_background(tmp_path):
    """Without --transparent a .png is RGB: the colour over the background (a gradient
    from --background top,bottom), as a picture viewer should show it."""
    import OpenImageIO as oiio

    from subtrace.cli import main

    out = tmp_path / "pic.png"
    args = ["render", str(_cube(tmp_path)), *CUBE_SCENE_ARGS, "--background",
            "1,0,0 0,0,1", "--color", "#00ff00", "-o", str(out)]
    assert main(args) == 0
    got = oiio.ImageBuf(str(out)).get_pixels(oiio.FLOAT)
    assert got.shape == (30, 40, 3)
    assert got[0, 0, 0] > 0.9 and got[-1, 0, 2] > 0.9  # red at the top, blue at the bottom
    centre = got[15, 20]
    assert centre[1] > 0.3 and centre[0] < 0.05 and centre[2] < 0.05  # the green object


def test_render_cli_sixteen_bits_only_where_the_format_has_them(tmp_path, capsys):
    from subtrace.cli import main

    out = tmp_path / "pic.jpg"
    code = main(["render", str(_cube(tmp_path)), *CUBE_SCENE_ARGS, "-o", str(out),
                 "--bit-depth", "16"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "--bit-depth" in err and not out.exists()


def test_render_header_names_files_only_and_the_colour_space(tmp_path):
    """The header records the meshes by file name (no folders of the user's), Rec.709
    chromaticities, what Z holds, and worldToCamera / worldToNDC in OpenEXR's conventions."""
    from subtrace.cli import main
    from subtrace.io.exr import read_exr

    out = tmp_path / "r.exr"
    assert main(["render", str(_cube(tmp_path)), *CUBE_SCENE_ARGS, "-o", str(out)]) == 0
    _, attrs = read_exr(out)
    assert attrs["subtrace:meshes"] == "cube.obj"
    assert str(tmp_path) not in " ".join(str(v) for v in attrs.values())
    np.testing.assert_allclose(attrs["chromaticities"],
                               (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290), atol=1e-7)
    assert "along the pixel's ray" in attrs["subtrace:Z"]
    assert len(attrs["worldToNDC"]) == 16 and len(attrs["worldToCamera"]) == 16


def test_boundary_option_single_quad(tmp_path, capsys):
    """A single quad is a rounded blob with OpenSubdiv's OBJ default (edge-only: corners
    smooth) and the whole square with ``--boundary edge-and-corner``; ``info`` and
    ``intersect`` take the same option. Independent check: the square's limit with sharp
    corners is the bilinear quad itself, so a line through a point near its corner hits."""
    from subtrace.cli import main
    from subtrace.io.exr import read_exr

    quad = tmp_path / "quad.obj"
    quad.write_text("v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nf 1 2 3 4\n")
    view = ["--eye", "0", "0", "5", "--target", "0", "0", "0", "--fov", "30", "--width", "64",
            "--height", "64", "--quiet"]
    covered = {}
    for mode in (None, "edge-only", "edge-and-corner"):
        out = tmp_path / f"q_{mode}.exr"
        extra = [] if mode is None else ["--boundary", mode]
        assert main(["render", str(quad), "-o", str(out), *view, *extra]) == 0
        covered[mode] = int(np.count_nonzero(read_exr(out)[0]["A"] > 0))
    assert covered[None] == covered["edge-only"]
    # the square at distance 5 with a 30 degree fov: 2 / (2 * 5 * tan 15deg) of 64 pixels a side
    side = 64 * 2.0 / (2 * 5 * np.tan(np.radians(15.0)))
    assert abs(covered["edge-and-corner"] - side * side) < 4 * side
    assert covered["edge-only"] < 0.9 * covered["edge-and-corner"]
    lines = tmp_path / "lines.csv"
    lines.write_text("ox,oy,oz,dx,dy,dz\n0.95,0.95,1,0,0,-1\n")
    hits = {}
    for mode in ("edge-only", "edge-and-corner"):
        out = tmp_path / f"hits_{mode}.csv"
        assert main(["intersect", str(quad), "--lines", str(lines), "--precision", "1e-6",
                     "-o", str(out), "--boundary", mode]) == 0
        hits[mode] = len(out.read_text().strip().splitlines()) - 1
    assert hits == {"edge-only": 0, "edge-and-corner": 1}
    capsys.readouterr()
    assert main(["info", str(quad), "--boundary", "edge-and-corner"]) == 0
    assert "edge-and-corner" in capsys.readouterr().out
    assert main(["render", str(quad), "--boundary", "corners", "-o", str(tmp_path / "x.exr")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--boundary" in err


def test_summary_total_includes_the_write(tmp_path, capsys):
    """The summary's total is the render time plus the write it lists."""
    import re

    from subtrace.cli import main

    out = tmp_path / "s.exr"
    assert main(["render", "-o", str(out), "--width", "32", "--height", "24"]) == 0
    line = capsys.readouterr().out
    render, write, total = (float(x) for x in re.search(
        r"render ([\d.]+) s \(.*\) \+ write ([\d.]+) s = total ([\d.]+) s", line).groups())
    assert abs(render + write - total) <= 0.0015 and write > 0


def test_render_cli_ao_option(tmp_path, capsys):
    """--ao N renders ambient occlusion (the header's subtrace:ao and ao_rays, the summary's
    secondary rays' deepest grid), and writes P.X, P.Y, P.Z; a bad count is one error line
    naming the option, exit code 2, no output."""
    from subtrace.cli import main
    from subtrace.io.exr import read_exr

    out = tmp_path / "ao.exr"
    assert main(["render", str(_cube(tmp_path)), "--width", "40", "--height", "30", "--ao",
                 "4", "-o", str(out)]) == 0
    assert "secondary rays' deepest grid" in capsys.readouterr().out
    ch, attrs = read_exr(out)
    assert attrs["subtrace:ao"] == 4 and attrs["subtrace:ao_rays"] > 0
    assert {"P.X", "P.Y", "P.Z"} <= set(ch)
    bad = tmp_path / "bad.exr"
    for value in ("-1", "x", "2000"):
        rc = main(["render", str(_cube(tmp_path)), *CUBE_SCENE_ARGS, "--ao", value, "-o",
                   str(bad)])
        err = capsys.readouterr().err
        assert rc == 2 and err.count("\n") == 1 and "--ao" in err and "Traceback" not in err
        assert not bad.exists()


# the magic bytes that open each format's files (the formats' own specifications)
MAGIC = {".bmp": (0, b"BM"), ".webp": (8, b"WEBP"), ".hdr": (0, b"#?"), ".tga": None,
         ".ppm": (0, b"P6"), ".gif": (0, b"GIF8")}


@pytest.mark.parametrize("ext", sorted(MAGIC))
def test_render_cli_writes_the_picture_format_its_extension_names(tmp_path, ext):
    """``-o x.bmp`` (.webp, .hdr, .tga, ...: any OpenImageIO writer) writes that format,
    not an EXR under that name: the file opens with the format's magic bytes, OpenImageIO
    reads it as that format, 40x30, its colour the EXR's (sRGB-encoded; linear in a
    Radiance .hdr)."""
    import OpenImageIO as oiio

    from subtrace.cli import main
    from subtrace.io.exr import read_exr, srgb_encode

    out = tmp_path / f"pic{ext}"
    args = ["render", str(_cube(tmp_path)), *CUBE_SCENE_ARGS]
    assert main([*args, "-o", str(out)]) == 0
    assert main([*args, "-o", str(tmp_path / "ref.exr")]) == 0
    data = out.read_bytes()
    assert not data.startswith(b"\x76\x2f\x31\x01")  # (OpenEXR's magic number)
    if MAGIC[ext] is not None:
        at, magic = MAGIC[ext]
        assert data[at:at + len(magic)] == magic
    inp = oiio.ImageInput.open(str(out))
    assert inp.format_name() == {".bmp": "bmp", ".webp": "webp", ".hdr": "hdr",
                                 ".tga": "targa", ".ppm": "pnm", ".gif": "gif"}[ext]
    assert (inp.spec().width, inp.spec().height) == (40, 30)
    inp.close()
    ref, _ = read_exr(tmp_path / "ref.exr")
    got = oiio.ImageBuf(str(out)).get_pixels(oiio.FLOAT)[..., :3]
    if ext == ".hdr":
        want = np.stack([ref[c] for c in "RGB"], axis=-1).astype(np.float64)
        # RGBE keeps 8 bits of mantissa under a shared exponent: 2^-8 of the largest
        # component; the EXR's half floats 2^-11
        assert np.all(np.abs(got - want) <= (2.0**-7 + 2.0**-11) * want.max(axis=-1,
                                                                              keepdims=True))
    elif ext != ".gif":  # (GIF's palette of 256 colours is not the picture's pixels)
        want = np.stack([srgb_encode(ref[c]) for c in "RGB"], axis=-1)
        tol = 0.5 / 255 + 12.92 * 2.0**-11 if ext != ".webp" else 0.1  # (lossy WebP)
        assert np.abs(got - want).max() <= tol


@pytest.mark.parametrize("name", ["out.txt", "out", "out.docx", "out.jp2"])
def test_render_cli_an_output_no_writer_takes_is_an_error(tmp_path, capsys, name):
    """An output whose extension names no format subtrace writes (or that has none) is one
    line that lists the formats, exit 2, and nothing is written (it was an EXR under that
    name, exit 0)."""
    from subtrace.cli import main

    cage = _cube(tmp_path)
    code = main(["render", str(cage), *CUBE_SCENE_ARGS, "-o", str(tmp_path / name)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert name in err and all(e in err for e in (".exr", ".png", ".jpg", ".webp", ".hdr"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cube.obj"]


def test_a_bare_toml_scene_renders_as_its_cage_on_the_command_line(tmp_path):
    """``[[object]] mesh = ...`` alone renders the picture the same cage gets on the command
    line, channel for channel (it was black, lit by a headlight alone, without shadows or
    ground, at 640x480); both at the default 1280x720 without --width / --height."""
    from subtrace.cli import main
    from subtrace.io.exr import read_exr

    cage = _cube(tmp_path)
    scene = tmp_path / "bare.toml"
    scene.write_text('[[object]]\nmesh = "cube.obj"\n')
    size = ["--width", "64", "--height", "36", "--quiet"]
    assert main(["render", str(scene), "-o", str(tmp_path / "toml.exr"), *size]) == 0
    assert main(["render", str(cage), "-o", str(tmp_path / "obj.exr"), *size]) == 0
    a, head = read_exr(tmp_path / "toml.exr")
    b, _ = read_exr(tmp_path / "obj.exr")
    assert set(a) == set(b)
    for name in a:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    assert head["subtrace:shadows"] == 1
    miss = a["A"] == 0
    assert a["R"][0][miss[0]].mean() > a["R"][-1][miss[-1]].mean()  # the gradient
    from subtrace.io.scene import load_scene, scene_for_meshes

    for s in (load_scene(scene), scene_for_meshes([str(cage)])):
        assert (s.camera.width, s.camera.height) == (1280, 720)
