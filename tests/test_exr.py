"""Tests of subtrace.io.exr: channel round trips, formats, header, atomic writes, sRGB PNG."""

from __future__ import annotations

import os
import sys

import numpy as np
import OpenImageIO as oiio
import pytest
from shared_data import error_without_root_powers

import subtrace
from subtrace.errors import SubtraceError
from subtrace.io import exr
from subtrace.io.exr import CHANNEL_ORDER, read_exr, srgb8, write_exr, write_png
from subtrace.runtime.atomic import atomic_paths, write_bytes, write_text

H, W = 7, 9
is_root = hasattr(os, "geteuid") and os.geteuid() == 0


def film(seed: int = 0) -> dict[str, np.ndarray]:
    """Every channel the renderer writes, with awkward values."""
    rng = np.random.default_rng(seed)
    ch = {c: rng.uniform(-2.0, 2.0, (H, W)).astype(np.float32) for c in ("N.X", "N.Y", "N.Z")}
    for c in "RGBA":
        ch[c] = rng.uniform(0.0, 1.5, (H, W)).astype(np.float32)
    ch["R"][0, :3] = [0.0, 65504.0, 1e-7]  # zero, largest half, a half subnormal
    z = rng.uniform(0.0, 1e6, (H, W)).astype(np.float32)
    z[0, 0], z[1, 1], z[2, 2] = np.inf, np.float32(1e-30), np.float32(3.4e38)
    ch["Z"] = z
    ch["level"] = rng.integers(0, 30, (H, W)).astype(np.int32)
    ch["patch_id"] = rng.integers(-1, 2**24 + 1, (H, W)).astype(np.int64)
    ch["patch_id"][0, :3] = [-1, 2**24, 2**24 - 1]
    ch["object_id"] = rng.integers(-1, 5, (H, W)).astype(np.float32)
    return ch


def listing(folder) -> list[str]:
    return sorted(os.listdir(folder))


# --------------------------------------------------------------------------------------
# round trip
# --------------------------------------------------------------------------------------


def test_round_trip_every_channel(tmp_path):
    ch = film()
    path = tmp_path / "film.exr"
    write_exr(path, ch, {})
    got, _ = read_exr(path)
    assert list(got) == list(CHANNEL_ORDER)
    for name in CHANNEL_ORDER:
        assert got[name].shape == (H, W) and got[name].dtype == np.float32
        if name in "RGBA":
            # half: the value rounded to nearest-even half precision, exactly
            expect = np.asarray(ch[name], np.float32).astype(np.float16).astype(np.float32)
        else:
            expect = np.asarray(ch[name]).astype(np.float32)  # exact, ids included
        np.testing.assert_array_equal(got[name], expect, err_msg=name)
    assert got["Z"][0, 0] == np.inf
    assert got["patch_id"][0, 1] == 2**24 and got["patch_id"][0, 0] == -1
    # half precision really is half: the rounding error is visible but within 2^-11
    assert not np.array_equal(got["G"], ch["G"])
    np.testing.assert_allclose(got["G"], ch["G"], rtol=2.0**-11)


def test_channel_names_formats_and_compression(tmp_path):
    path = tmp_path / "film.exr"
    write_exr(path, film(), {})
    inp = oiio.ImageInput.open(str(path))
    try:
        spec = inp.spec()
        formats = dict(zip(spec.channelnames, (str(f) for f in spec.get_channelformats())))
        assert sorted(spec.channelnames) == sorted(CHANNEL_ORDER)
        assert formats == {c: ("half" if c in "RGBA" else "float") for c in CHANNEL_ORDER}
        assert spec.get_string_attribute("compression") == "zip"
        assert spec.channelnames[spec.alpha_channel] == "A"
        assert spec.channelnames[spec.z_channel] == "Z"
        assert (spec.width, spec.height) == (W, H)
    finally:
        inp.close()


def test_subset_and_extra_channels(tmp_path):
    path = tmp_path / "few.exr"
    depth = np.arange(H * W, dtype=np.float32).reshape(H, W)
    write_exr(path, {"extra": depth * 2, "Z": depth}, {})
    got, _ = read_exr(path)
    assert list(got) == ["Z", "extra"]  # known channels first, in CHANNEL_ORDER
    np.testing.assert_array_equal(got["extra"], depth * 2)


def test_header_attributes_round_trip(tmp_path):
    path = tmp_path / "film.exr"
    matrix = tuple(float(i) for i in range(16))
    attrs = {
        "scheme": "catmark",
        "tolerance": 0.25,
        "subtrace:time_load": 1.5,
        "time_total": 3.125,
        "rays": 123456,
        "micro_triangles": 2**40,  # above int32: kept exact as text
        "watertight": True,
        "subtrace:eye": (1.0, 2.0, 3.0),
        "worldToCamera": matrix,
        "studio:note": "kept as given",
        "camera": "eye [0, 0, 5] target [0, 0, 0]",
    }
    write_exr(path, film(), attrs)
    _, got = read_exr(path)
    assert got["subtrace:scheme"] == "catmark"
    assert got["subtrace:tolerance"] == 0.25
    assert got["subtrace:time_load"] == 1.5
    assert got["subtrace:time_total"] == 3.125
    assert got["subtrace:rays"] == 123456
    assert got["subtrace:micro_triangles"] == str(2**40)
    assert got["subtrace:watertight"] == 1
    assert got["subtrace:eye"] == (1.0, 2.0, 3.0)
    assert got["worldToCamera"] == matrix
    assert got["studio:note"] == "kept as given"
    assert got["subtrace:camera"] == "eye [0, 0, 5] target [0, 0, 0]"
    assert got["subtrace:version"] == subtrace.__version__
    assert got["Software"] == f"subtrace {subtrace.__version__}"
    assert got["compression"] == "zip"
    # floats are stored as 32-bit
    write_exr(path, film(), {"tolerance": 0.1})
    assert read_exr(path)[1]["subtrace:tolerance"] == pytest.approx(0.1, rel=1e-7)


def test_camera_header_attributes(tmp_path):
    from subtrace.camera import Camera

    cam = Camera((0, 0, 5), (0, 0, 0), (0, 1, 0), 40, W, H)
    path = tmp_path / "film.exr"
    write_exr(path, film(), cam.header_attributes())
    _, got = read_exr(path)
    assert got["subtrace:camera"] == cam.header_attributes()["subtrace:camera"]
    np.testing.assert_allclose(np.reshape(got["worldToCamera"], (4, 4)).T, cam.world_to_camera())


def test_bad_arrays_and_attributes(tmp_path):
    path = tmp_path / "x.exr"
    with pytest.raises(ValueError, match="at least one"):
        write_exr(path, {}, {})
    with pytest.raises(ValueError, match="shape"):
        write_exr(path, {"R": np.zeros((2, 3)), "G": np.zeros((3, 2))}, {})
    with pytest.raises(ValueError, match=r"\(H,W\)"):
        write_exr(path, {"R": np.zeros((2, 3, 1))}, {})
    with pytest.raises(ValueError, match="2\\^24"):
        write_exr(path, {"patch_id": np.full((2, 2), 2**24 + 1)}, {})
    with pytest.raises(ValueError, match="whole numbers"):
        write_exr(path, {"level": np.full((2, 2), 0.5)}, {})
    with pytest.raises(TypeError, match="unsupported"):
        write_exr(path, {"R": np.zeros((2, 2))}, {"thing": {"a": 1}})
    with pytest.raises(ValueError, match="preview needs"):
        write_exr(path, {"Z": np.zeros((2, 2))}, {}, png_path=tmp_path / "x.png")
    assert listing(tmp_path) == []


# --------------------------------------------------------------------------------------
# temporary file, then rename
# --------------------------------------------------------------------------------------


def test_check_writable(tmp_path):
    exr.check_writable(tmp_path / "film.exr")
    assert listing(tmp_path) == []
    with pytest.raises(SubtraceError, match="does not exist"):
        exr.check_writable(tmp_path / "no" / "film.exr")
    with pytest.raises(SubtraceError, match="is a directory"):
        exr.check_writable(tmp_path)


def test_missing_folder(tmp_path):
    path = tmp_path / "no" / "such" / "film.exr"
    with pytest.raises(SubtraceError) as info:
        write_exr(path, film(), {})
    assert str(path) in str(info.value) and "does not exist" in str(info.value)
    assert listing(tmp_path) == []


def _write_error(path) -> str:
    """The error of writing a film to ``path``: in this process, or as root in one without
    root's power to write anywhere."""
    if not is_root:
        with pytest.raises(SubtraceError) as info:
            write_exr(path, film(), {})
        return str(info.value)
    return error_without_root_powers(f"""
import numpy as np
from subtrace.errors import SubtraceError
from subtrace.io.exr import write_exr
try:
    write_exr({str(path)!r}, {{"R": np.zeros((2, 3), np.float32)}}, {{}})
except SubtraceError as exc:
    print(exc)
""")


@pytest.mark.skipif(sys.platform == "win32", reason="Windows ignores a folder's read-only mode")
def test_read_only_folder(tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        message = _write_error(folder / "film.exr")
        assert "permission denied" in message and str(folder / "film.exr") in message
        assert listing(folder) == []
    finally:
        folder.chmod(0o755)


def test_round_trip_in_several_row_blocks(tmp_path):
    # taller than OpenEXR's 16-line ZIP blocks and not a multiple of them: a short last one
    rows = 2 * 16 + 5
    rng = np.random.default_rng(1)
    ch = {c: rng.uniform(-1e3, 1e3, (rows, 3)).astype(np.float32) for c in ("Z", "N.X", "u")}
    ch["R"] = rng.uniform(0.0, 1.0, (rows, 3)).astype(np.float32)
    ch["patch_id"] = np.arange(rows * 3).reshape(rows, 3)
    path = tmp_path / "tall.exr"
    write_exr(path, ch, {})
    got, _ = read_exr(path)
    np.testing.assert_array_equal(got["R"], ch["R"].astype(np.float16).astype(np.float32))
    for name in ("Z", "N.X", "u", "patch_id"):
        np.testing.assert_array_equal(got[name], ch[name].astype(np.float32), err_msg=name)


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs Linux /proc")
def test_unwritable_folder_even_for_root():
    with pytest.raises(SubtraceError, match="/proc/film.exr"):
        write_exr("/proc/film.exr", film(), {})


def test_target_is_a_directory(tmp_path):
    (tmp_path / "film.exr").mkdir()
    with pytest.raises(SubtraceError, match="is a directory"):
        write_exr(tmp_path / "film.exr", film(), {})
    assert listing(tmp_path) == ["film.exr"]


def test_failure_while_writing_leaves_existing_file_intact(tmp_path, monkeypatch):
    path = tmp_path / "film.exr"
    path.write_bytes(b"previous render")
    real = exr._write_image

    def write_then_fail(path_str, temp, fmt, spec, pixels):
        real(path_str, temp, fmt, spec, pixels)  # the temporary is complete...
        assert os.path.getsize(temp) > 0
        raise SubtraceError(f"{path_str}: disk full (simulated)")  # ...but then it fails

    monkeypatch.setattr(exr, "_write_image", write_then_fail)
    with pytest.raises(SubtraceError, match="simulated"):
        write_exr(path, film(), {})
    assert path.read_bytes() == b"previous render"
    assert listing(tmp_path) == ["film.exr"]


def test_failed_preview_leaves_no_file(tmp_path, monkeypatch):
    # the preview is written on a thread of its own beside the EXR: its failure still
    # leaves neither file nor temporary, and the existing EXR untouched
    path = tmp_path / "film.exr"
    path.write_bytes(b"previous render")
    real = exr._write_image

    def fail_png(path_str, temp, fmt, spec, pixels):
        if fmt == "png":
            raise SubtraceError(f"{path_str}: disk full (simulated)")
        real(path_str, temp, fmt, spec, pixels)

    monkeypatch.setattr(exr, "_write_image", fail_png)
    with pytest.raises(SubtraceError, match="film.png: disk full"):
        write_exr(path, film(), {}, png_path=tmp_path / "film.png")
    assert path.read_bytes() == b"previous render"
    assert listing(tmp_path) == ["film.exr"]


def test_failed_rename_leaves_existing_file_intact(tmp_path, monkeypatch):
    path = tmp_path / "film.exr"
    path.write_bytes(b"previous render")

    def refuse(src, dst):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(exr.os, "replace", refuse)
    with pytest.raises(SubtraceError, match="permission denied") as info:
        write_exr(path, film(), {})
    assert str(path) in str(info.value)
    assert path.read_bytes() == b"previous render"
    assert listing(tmp_path) == ["film.exr"]


def test_interrupt_while_writing_leaves_existing_file_intact(tmp_path):
    # runtime/atomic is the one writer of EXRs, PNGs, sweep tables and intersect hits: an
    # interrupt (any BaseException) removes the temporary and keeps the old file
    path = tmp_path / "hits.csv"
    path.write_text("old\n")
    with pytest.raises(KeyboardInterrupt):
        with atomic_paths([path]) as (temp,):
            with open(temp, "w") as fh:
                fh.write("half")
            raise KeyboardInterrupt
    assert path.read_text() == "old\n"
    assert listing(tmp_path) == ["hits.csv"]
    write_text(path, "new\n")
    assert path.read_text() == "new\n"
    assert listing(tmp_path) == ["hits.csv"]


def test_bytes_writer_replaces_whole_files(tmp_path):
    """write_bytes (the kernel cache's stored runtime and stencil maps) writes the bytes as
    given through a temporary, replaces an existing file, and leaves no temporary; a
    missing folder is named."""
    path = tmp_path / "maps.npy"
    write_bytes(path, b"\x00first\xff")
    assert path.read_bytes() == b"\x00first\xff"
    write_bytes(path, b"second")
    assert path.read_bytes() == b"second"
    assert listing(tmp_path) == ["maps.npy"]
    with pytest.raises(SubtraceError, match="does not exist"):
        write_bytes(tmp_path / "no" / "maps.npy", b"x")
    assert listing(tmp_path) == ["maps.npy"]


def test_stencil_maps_stored_whole_and_read_back(tmp_path, monkeypatch):
    """The maps of a valence are stored in the kernel cache's folder through the atomic
    writer (one file, no temporary left) and read back as derived."""
    from subtrace.patches import stencil
    from subtrace.runtime import jit

    monkeypatch.setattr(jit, "KERNEL_DIR", tmp_path)
    stencil.stencil.cache_clear()
    try:
        derived = stencil.stencil(7)
        assert listing(tmp_path / "stencils") == ["valence-7.npy"]
        stencil.stencil.cache_clear()
        read = stencil.stencil(7)
    finally:
        stencil.stencil.cache_clear()
    for name in stencil._STORED:
        assert np.array_equal(getattr(read, name), getattr(derived, name)), name


def test_text_writer_names_a_missing_folder(tmp_path):
    with pytest.raises(SubtraceError, match="does not exist"):
        write_text(tmp_path / "no" / "sweep.csv", "x\n")
    assert listing(tmp_path) == []


def test_exr_not_written_when_preview_folder_is_missing(tmp_path):
    with pytest.raises(SubtraceError, match="does not exist"):
        write_exr(tmp_path / "film.exr", film(), {}, png_path=tmp_path / "no" / "film.png")
    assert listing(tmp_path) == []


def test_overwrites_and_keeps_normal_permissions(tmp_path):
    path = tmp_path / "film.exr"
    path.write_bytes(b"old")
    write_exr(path, film(), {})
    assert read_exr(path)[0]["Z"][0, 0] == np.inf
    assert listing(tmp_path) == ["film.exr"]
    umask = os.umask(0)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask


# --------------------------------------------------------------------------------------
# PNG preview
# --------------------------------------------------------------------------------------


def read_png(path) -> np.ndarray:
    inp = oiio.ImageInput.open(str(path))
    try:
        assert inp.format_name() == "png"
        return inp.read_image(oiio.UINT8)
    finally:
        inp.close()


# sRGB codes: 255 * (1.055 x^(1/2.4) - 0.055), or 255 * 12.92 x at or below 0.0031308,
# rounded to nearest (0.5 -> 187.52, 0.18 -> 117.6, 0.001 -> 3.29, 0.0031308 -> 10.3, 0.9 -> 243.4)
KNOWN = [(0.5, 188), (0.0, 0), (1.0, 255), (0.18, 118), (0.001, 3), (0.0031308, 10), (0.9, 243)]


def test_png_srgb_curve(tmp_path):
    values = [v for v, _ in KNOWN] + [2.0, -1.0, np.nan, np.inf]
    codes = [c for _, c in KNOWN] + [255, 0, 0, 255]
    rgb = np.zeros((2, len(values), 3), np.float32)
    rgb[0, :, 0] = values  # red varies, green constant 0.5, blue 0
    rgb[0, :, 1] = 0.5
    rgb[1] = rgb[0, :, ::-1]
    path = tmp_path / "p.png"
    write_png(path, rgb)
    png = read_png(path)
    assert png.shape == (2, len(values), 3) and png.dtype == np.uint8
    np.testing.assert_array_equal(png[0, :, 0], codes)
    assert np.all(png[0, :, 1] == 188) and np.all(png[0, :, 2] == 0)
    np.testing.assert_array_equal(png[1], png[0, :, ::-1])
    np.testing.assert_array_equal(srgb8(rgb), png)
    assert listing(tmp_path) == ["p.png"]


def test_png_preview_beside_exr(tmp_path):
    ch = film()
    write_exr(tmp_path / "f.exr", ch, {}, png_path=tmp_path / "f.png")
    assert listing(tmp_path) == ["f.exr", "f.png"]
    png = read_png(tmp_path / "f.png")
    # the preview encodes R, G, B as given (already composited), ignoring A
    expect = srgb8(np.stack([ch["R"], ch["G"], ch["B"]], axis=-1))
    np.testing.assert_array_equal(png, expect)


def test_png_errors(tmp_path):
    with pytest.raises(ValueError, match=r"\(H,W,3\)"):
        write_png(tmp_path / "p.png", np.zeros((4, 4)))
    with pytest.raises(SubtraceError, match="does not exist"):
        write_png(tmp_path / "no" / "p.png", np.zeros((4, 4, 3)))
    assert listing(tmp_path) == []


# --------------------------------------------------------------------------------------
# reading
# --------------------------------------------------------------------------------------


def test_read_errors(tmp_path):
    with pytest.raises(SubtraceError, match="no such file") as info:
        read_exr(tmp_path / "missing.exr")
    assert str(tmp_path / "missing.exr") in str(info.value)
    (tmp_path / "garbage.exr").write_bytes(b"this is not an image at all")
    with pytest.raises(SubtraceError, match="cannot read") as info:
        read_exr(tmp_path / "garbage.exr")
    assert str(tmp_path / "garbage.exr") in str(info.value)
    with pytest.raises(SubtraceError, match="is a directory"):
        read_exr(tmp_path)


def tall_film(height: int, seed: int = 3) -> dict[str, np.ndarray]:
    """Every channel, ``height`` rows of the film's awkward values (repeated; noise on
    the real-valued ones)."""
    rng = np.random.default_rng(seed)
    base = film(seed)
    reps = -(-height // H)
    noise = rng.uniform(0, 1e-3, (height, W)).astype(np.float32)
    return {name: np.tile(np.asarray(a, np.float32), (reps, 1))[:height]
            + (0 if name in exr.INTEGER_CHANNELS or name == "Z" else noise)
            for name, a in base.items()}


@pytest.mark.parametrize("height, rows", [(16, 16), (50, 16), (61, 32), (40, 48), (150, 128)])
def test_bands_write_the_whole_image_file(tmp_path, height, rows):
    """ExrBands (bands of ``rows``, the last one shorter) writes the file write_exr writes
    from the whole image, byte for byte, header attributes included, and the same preview."""
    ch = tall_film(height)
    attrs = {"subtrace:time_total": 0.125, "subtrace:depth_cap_reason": "memory,precision",
             "subtrace:patches": 2**40, "worldToCamera": np.arange(16.0), "note": "bands"}
    write_exr(tmp_path / "whole.exr", ch, attrs, png_path=tmp_path / "whole.png")
    bands = exr.ExrBands(tmp_path / "bands.exr", W, height, png_path=tmp_path / "bands.png")
    for y0 in range(0, height, rows):
        y1 = min(height, y0 + rows)
        bands.write(y0, y1, {name: a[y0:y1] for name, a in ch.items()})
    assert listing(tmp_path) == ["whole.exr", "whole.png"]  # nothing before finish
    bands.finish(attrs)
    for name in ("exr", "png"):
        written = (tmp_path / f"bands.{name}").read_bytes()
        assert written == (tmp_path / f"whole.{name}").read_bytes()
    back, head = read_exr(tmp_path / "bands.exr")
    assert head["subtrace:depth_cap_reason"] == "memory,precision"
    np.testing.assert_array_equal(back["Z"], ch["Z"])


def test_bands_in_order_of_whole_blocks(tmp_path):
    """Bands come top to bottom, every band but the last whole ZIP blocks (16 rows), with
    the first band's channels; finish needs every row; each misuse is a ValueError and
    leaves no file."""
    ch = tall_film(40)
    bands = exr.ExrBands(tmp_path / "b.exr", W, 40)
    with pytest.raises(ValueError, match="in order"):
        bands.write(16, 32, {n: a[16:32] for n, a in ch.items()})
    with pytest.raises(ValueError, match="multiple of 16"):
        bands.write(0, 10, {n: a[:10] for n, a in ch.items()})
    bands.write(0, 16, {n: a[:16] for n, a in ch.items()})
    with pytest.raises(ValueError, match="differ"):
        bands.write(16, 32, {"Z": ch["Z"][16:32]})
    with pytest.raises(ValueError, match="expected"):
        bands.write(16, 32, {n: a[16:30] for n, a in ch.items()})
    with pytest.raises(ValueError, match="16 of 40 rows"):
        bands.finish({})
    assert listing(tmp_path) == []


def test_bands_to_a_missing_folder(tmp_path):
    """A file that cannot be written: SubtraceError naming it (at its first band: the
    encoded blocks wait beside it), no file left."""
    ch = tall_film(16)
    path = tmp_path / "no" / "b.exr"
    bands = exr.ExrBands(path, W, 16)
    with pytest.raises(SubtraceError, match="does not exist") as info:
        bands.write(0, 16, ch)
    assert str(path) in str(info.value)
    assert listing(tmp_path) == []
