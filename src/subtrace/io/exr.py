"""The renderer's film on disk: multi-channel OpenEXR (written with OpenEXR's own Python
binding, read with OpenImageIO) and sRGB pictures and previews (OpenImageIO).

Channels are (H,W) arrays, row 0 at the top. Names and pixel types written:
  R, G, B, A                      half     colour (linear, already composited), coverage
  Z                               float32  ray distance t (+inf where no hit)
  N.X, N.Y, N.Z                   float32  shading normal (world space)
  level, patch_id, object_id      float32  integers stored exactly (|value| <= 2^24;
                                           -1 where no hit)
any other channel name is written as float32. OpenEXR stores channels sorted by name, so
the order a reader reports is its own; read_exr returns the order above. Compression is
ZIP. Header attributes are str, int (32-bit; larger ones are stored as decimal strings),
float (stored as 32-bit), 3 floats (V3f), 8 floats (chromaticities), 16 floats (M44f) or
bool (int 0/1); names starting with `oiio:` are OpenImageIO's own hints and are not stored.
The EXR goes through OpenEXR's binding because it takes each channel in its own pixel type:
OpenImageIO converts a float buffer to mixed half / float channels value by value, which
took 0.36 s of a 0.42 s write of a 1280x720 film with 16 channels (0.14 s this way).
Every file is written through :mod:`subtrace.runtime.atomic` (a hidden temporary in the
destination folder, then os.replace), so a failure never leaves a partial file and never
touches an existing one; failures raise SubtraceError naming the path.

A render streamed in bands of rows (``render.render_scene(sink=...)``) is written by
:class:`ExrBands`: each band is encoded as it arrives (OpenEXR's ZIP blocks of 16 lines,
compressed on every core) and its compressed blocks are set aside in an unnamed temporary
file; once the last band is in, the header (with the render's statistics, known only then)
is written, then the blocks' offsets and the blocks. The file is the one :func:`write_exr`
writes from the whole image, byte for byte (tests/test_exr.py).
"""

from __future__ import annotations

import io
import os
import shutil
import struct
import threading
import time

import numpy as np
import OpenEXR

from subtrace import config
from subtrace.errors import SubtraceError
from subtrace.io.formats import DEEP, LINEAR, PICTURE_FORMATS, WITH_ALPHA, picture_format
from subtrace.runtime.atomic import atomic_paths, check_writable, open_temp, path_str, reason
from subtrace.runtime.signals import temp_lock
from subtrace.runtime.threads import max_threads
from subtrace.version import VERSION


class _OpenImageIO:
    """OpenImageIO, imported on first use: where a picture is written or an image read. A
    render that writes only EXR (through OpenEXR) does not load it (about 20 MB and 50 ms
    of the process)."""

    def __getattr__(self, name):
        import OpenImageIO

        return getattr(OpenImageIO, name)


oiio = _OpenImageIO()

CHANNEL_ORDER = ("R", "G", "B", "A", "Z", "N.X", "N.Y", "N.Z", "level", "patch_id", "object_id")
HALF_CHANNELS = frozenset(("R", "G", "B", "A"))
INTEGER_CHANNELS = frozenset(("level", "patch_id", "object_id"))
MAX_EXACT_INTEGER = 2**24  # largest magnitude float32 holds for every integer below it
COMPRESSION = "zip"
ATTRIBUTE_PREFIX = "subtrace:"
# Header attributes written under their own name (standard OpenEXR / OIIO names); any other
# key without a ':' gets ATTRIBUTE_PREFIX.
STANDARD_ATTRIBUTES = frozenset(
    (
        "worldToCamera",
        "worldToNDC",
        "chromaticities",
        "Software",
        "ImageDescription",
        "Copyright",
        "Artist",
        "DateTime",
        "owner",
        "comments",
        "capDate",
        "utcOffset",
    )
)
_INT32 = (-(2**31), 2**31 - 1)
# header values given as float tuples, by length, as OpenEXR's binding takes them: a V3f,
# chromaticities (x, y of the red, green and blue primaries and the white point), an M44f
_FLOAT_TUPLES = {3: lambda f: np.array(f, np.float32), 8: tuple,
                 16: lambda f: np.array(f, np.float32).reshape(4, 4)}


def write_exr(path, channels: dict, attributes: dict | None = None, png_path=None,
              window=None) -> None:
    """Write a multi-channel EXR (and optionally an sRGB PNG preview of R, G, B).

    path: destination (OpenEXR whatever the extension; :func:`write_picture` writes the
      picture formats).
    channels: name -> (H,W) array, all the same shape; see the module comment for the names,
      the order and the pixel types. Values of the integer channels must be whole numbers of
      magnitude <= 2^24.
    attributes: header attributes, name -> str | int | float | bool | 3 or 16 floats. Names
      without ':' (other than STANDARD_ATTRIBUTES) are stored as ``subtrace:<name>``.
      ``subtrace:version`` and ``Software`` are always written.
    png_path: also write an 8-bit sRGB preview of R, G, B (needs those channels).
    window: None, or (x, y, width, height): the channels are a tile of a width x height
      image, from pixel (x, y): the file's data window, inside its display window (OpenEXR's
      convention; :func:`read_exr` reports both). The preview holds the tile alone.
    Raises SubtraceError naming the file when it cannot be written (no partial file is left
    behind and an existing file is left untouched); ValueError / TypeError for bad arrays or
    attribute values (programming errors).
    """
    names, arrays = _channel_arrays(channels)
    height, width = arrays[0].shape
    header = (_openexr_header(attributes) if window is None else _openexr_header(
        attributes, (int(window[0]), int(window[1]), width, height),
        (0, 0, int(window[2]), int(window[3]))))
    jobs = [(path, "openexr", header, _pixels(names, arrays))]
    if png_path is not None:
        missing = [c for c in ("R", "G", "B") if c not in channels]
        if missing:
            raise ValueError(f"a PNG preview needs channels R, G, B; missing {missing}")
        rgb = [np.asarray(channels[c]) for c in ("R", "G", "B")]
        # encoded on the thread that writes it, beside the EXR
        jobs.append((png_path, "png", _png_spec(width, height),
                     lambda: srgb8(np.stack(rgb, axis=-1))))
    _write_all(jobs)


# scanlines per ZIP block (OpenEXR): bands but the last are whole blocks, so that the blocks
# of the bands are the whole image's
LINES_PER_BLOCK = config.EXR_LINES_PER_BLOCK
# lines :class:`ExrBands` hands OpenEXR at a time, two blocks for each of two threads:
# OpenEXR copies what it encodes (at 1280 pixels a line, 27 MiB at a time with 128 lines, 15
# with 32), and each call costs a few milliseconds more than its blocks' compression (Spot
# at 1280x720: 0.109 s for the image at once, 0.122 in bands of 192 lines, 0.137 of 64
# lines, 0.149 of 32)
ENCODE_ROWS = 4 * LINES_PER_BLOCK


class ExrBands:
    """An EXR with the channels of :func:`write_exr`, written band by band (rows
    ``[y0, y1)`` in order, top to bottom; every band but the last a multiple of
    ``LINES_PER_BLOCK`` rows), and its optional sRGB PNG preview. Each band is encoded as it
    arrives and its compressed blocks go to an unnamed temporary file in the output's
    folder (no name in the folder, gone with the process), so that neither the image nor
    its encoding is held in memory; only the preview's 8-bit pixels are. ``write(y0, y1,
    channels)`` takes a band (name -> (y1 - y0, width) arrays, the same names each time);
    ``finish(attributes)`` writes the file (atomically, as :func:`write_exr`) with the
    header ``attributes``, then the blocks."""

    def __init__(self, path, width: int, height: int, png_path=None):
        self.path, self.png_path = path, png_path
        self.seconds = 0.0  # spent encoding and writing (write and finish)
        self.width, self.height = int(width), int(height)
        self.sizes: list[int] = []  # each block's record (first line, size, data): bytes
        self.spool = None  # the blocks, top to bottom
        self.rows = 0  # rows written
        self.names: list[str] | None = None
        self.rgb = None if png_path is None else np.empty((self.height, self.width, 3), np.uint8)

    def write(self, y0: int, y1: int, channels: dict) -> None:
        """Encode rows [y0, y1) of every channel (see the class comment)."""
        t0 = time.perf_counter()
        y0, y1 = int(y0), int(y1)
        if y0 != self.rows or not y0 < y1 <= self.height:
            raise ValueError(f"rows {y0}..{y1}: bands come in order, from row {self.rows}")
        if y1 < self.height and (y1 - y0) % LINES_PER_BLOCK:
            raise ValueError(f"a band but the last is a multiple of {LINES_PER_BLOCK} rows")
        names, arrays = _channel_arrays(channels)
        if arrays[0].shape != (y1 - y0, self.width):
            raise ValueError(f"expected ({y1 - y0}, {self.width}) arrays, got {arrays[0].shape}")
        if self.names is not None and names != self.names:
            raise ValueError(f"channels {names} differ from the first band's {self.names}")
        if self.rgb is not None and any(c not in channels for c in "RGB"):
            raise ValueError("a PNG preview needs channels R, G, B")
        self.names = names
        if self.spool is None:
            self.spool = _spool(self.path)
        # (a few blocks at a time: OpenEXR's copy of the lines it encodes stays small)
        for a in range(0, y1 - y0, ENCODE_ROWS):
            b = min(y1 - y0, a + ENCODE_ROWS)
            header = _openexr_header({}, (0, y0 + a, self.width, b - a),
                                     (0, 0, self.width, self.height))
            data = _encoded(header, _pixels(names, [x[a:b] for x in arrays]))
            start, sizes = _blocks(data)
            try:
                self.spool.write(memoryview(data)[start:])
            except OSError as err:
                raise SubtraceError(f"{path_str(self.path)}: cannot write the file: "
                                    f"{reason(err)}") from None
            self.sizes += sizes
        if self.rgb is not None:
            self.rgb[y0:y1] = srgb8(np.stack([np.asarray(channels[c]) for c in "RGB"], -1))
        self.rows = y1
        self.seconds += time.perf_counter() - t0

    def finish(self, attributes: dict | None = None) -> None:
        """Write the file (and the preview): the header with ``attributes`` (as
        :func:`write_exr` takes them), the blocks' offsets, the blocks."""
        if self.rows != self.height:
            raise ValueError(f"{self.rows} of {self.height} rows written")
        t0 = time.perf_counter()
        # the header: a one-row file's with the same channels and attributes, its data
        # window then widened to the image (a value of the same size, rewritten in place)
        header = _openexr_header(attributes, (0, 0, self.width, 1),
                                 (0, 0, self.width, self.height))
        one_row = {n: np.zeros((1, self.width), np.float16 if n in HALF_CHANNELS else
                               np.float32) for n in self.names}
        start, attrs, window = _header_bytes(_encoded(header, one_row))
        attrs[window:window + 16] = struct.pack("<4i", 0, 0, self.width - 1, self.height - 1)
        head = start + bytes(attrs)
        offsets = np.cumsum([0] + self.sizes[:-1], dtype=np.uint64)
        offsets += np.uint64(len(head) + 8 * len(self.sizes))
        self.spool.seek(0)
        jobs = [(self.path, "bytes", None, [head, offsets.astype("<u8").tobytes(), self.spool])]
        if self.png_path is not None:
            jobs.append((self.png_path, "png", _png_spec(self.width, self.height), self.rgb))
        try:
            _write_all(jobs)
        finally:
            self.spool.close()
            self.seconds += time.perf_counter() - t0


def _spool(path):
    """An unnamed temporary file for the blocks of ``path``, in its folder (it has no name
    there: O_TMPFILE, or removed at once); SubtraceError naming ``path`` when the folder
    cannot take it."""
    import tempfile

    folder = os.path.dirname(os.path.abspath(path_str(path)))
    try:
        return tempfile.TemporaryFile(dir=folder)
    except OSError as err:
        what = "does not exist" if not os.path.isdir(folder) else reason(err)
        raise SubtraceError(f"{path_str(path)}: cannot write the file: the folder {folder} "
                            f"{what}") from None


def _openexr_header(attributes, data=None, display=None) -> dict:
    """The header OpenEXR's binding takes: ZIP-compressed scanlines, the data and display
    windows ``data``, ``display`` ((x, y, width, height) each; None: the channels' own) and
    ``attributes`` (as :func:`write_exr` takes them)."""
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    for key, window in (("dataWindow", data), ("displayWindow", display)):
        if window is not None:
            x, y, width, height = window
            header[key] = (np.array([x, y], np.int32),
                           np.array([x + width - 1, y + height - 1], np.int32))
    for key, value in _header(attributes or {}).items():
        if not key.startswith("oiio:"):
            header[key] = _attribute_value(key, value)
    return header


def _openexr_threads() -> None:
    """OpenEXR's ZIP blocks compressed on every core (its global thread pool)."""
    if OpenEXR.global_thread_count() == 0:
        OpenEXR.set_global_thread_count(max_threads())


def _pixels(names, arrays) -> dict:
    """Each channel in its pixel type (module comment)."""
    with np.errstate(over="ignore"):  # (beyond half's range is +-inf, as OpenEXR rounds)
        return {n: a.astype(np.float16) if n in HALF_CHANNELS else np.ascontiguousarray(a)
                for n, a in zip(names, arrays)}


def _encoded(header: dict, pixels: dict) -> bytes:
    """The OpenEXR file of ``header`` and ``pixels``, in memory."""
    _openexr_threads()
    stream = io.BytesIO()
    OpenEXR.File(header, pixels).write(stream)
    return stream.getvalue()


def _header_bytes(data: bytes):
    """(magic number and version, the header's attributes with the terminating NUL as a
    bytearray, the offset of the ``dataWindow`` value in them) of a single-part scanline
    OpenEXR file ``data``."""
    at, window = 8, None
    while data[at] != 0:  # attribute: name NUL, type NUL, size (int32), value
        name_end = data.index(b"\0", at)
        type_end = data.index(b"\0", name_end + 1)
        (size,) = struct.unpack_from("<i", data, type_end + 1)
        if data[at:name_end] == b"dataWindow":
            window = type_end + 5 - 8
        at = type_end + 5 + size
    return data[:8], bytearray(data[8:at + 1]), window


def _blocks(data: bytes):
    """(where the blocks start, each block's record size) of a single-part scanline OpenEXR
    file ``data`` whose blocks follow its offset table one after another, top to bottom
    (as OpenEXR writes lines in increasing order)."""
    _, attrs, window = _header_bytes(data)
    (y_min,), (y_max,) = (struct.unpack_from("<i", attrs, window + k) for k in (4, 12))
    n = -(-(y_max - y_min + 1) // LINES_PER_BLOCK)
    table = 8 + len(attrs)
    offsets = list(struct.unpack_from(f"<{n}Q", data, table)) + [len(data)]
    sizes = [b - a for a, b in zip(offsets, offsets[1:])]
    for off, size in zip(offsets, sizes):
        (length,) = struct.unpack_from("<i", data, off + 4)
        if length + 8 != size:
            raise ValueError("an EXR whose blocks are not one after another")
    if offsets[0] != table + 8 * n:
        raise ValueError("an EXR whose blocks do not follow its offset table")
    return offsets[0], sizes


def write_png(path, rgb_linear) -> None:
    """Write (H,W,3) linear RGB as an 8-bit sRGB PNG (clipped to 0..1, NaN -> 0).

    Same temporary-then-rename policy and errors as :func:`write_exr`.
    """
    pixels = srgb8(rgb_linear)
    _write_all([(path, "png", _png_spec(pixels.shape[1], pixels.shape[0]), pixels)])


def write_picture(path, channels: dict, bits: int = 8) -> None:
    """Write the colour of ``channels`` (R, G, B, and A where the format stores alpha) as a
    picture in the format of ``path``'s extension (``io.formats.picture_format``): sRGB at
    ``bits`` (8, or 16 for PNG and TIFF) per channel, or linear floating point for the
    formats of ``io.formats.LINEAR`` (Radiance HDR, FITS). Same temporary-then-rename
    policy and errors as :func:`write_exr`."""
    fmt = picture_format(path)
    if fmt is None:
        raise ValueError(f"{path_str(path)}: not a picture format ({sorted(PICTURE_FORMATS)})")
    if bits not in (8, 16) or (bits == 16 and fmt not in DEEP):
        raise ValueError(f"{fmt} pictures take 8 bits per channel" if bits == 16 else
                         f"expected 8 or 16 bits per channel, got {bits}")
    linear = fmt in LINEAR
    planes = [np.asarray(channels[c], dtype=np.float64) for c in ("R", "G", "B")]
    encoded = [np.nan_to_num(x) if linear else srgb_encode(x) for x in planes]
    if "A" in channels and _stores_alpha(fmt):
        encoded.append(np.clip(np.nan_to_num(np.asarray(channels["A"], np.float64)), 0.0, 1.0))
    if linear:
        pixels = np.ascontiguousarray(np.stack(encoded, axis=-1).astype(np.float32))
        kind = oiio.FLOAT
    else:
        top, dtype, kind = (255.0, np.uint8, oiio.UINT8) if bits == 8 else \
            (65535.0, np.uint16, oiio.UINT16)
        pixels = np.ascontiguousarray(np.rint(np.stack(encoded, axis=-1) * top).astype(dtype))
    height, width, n = pixels.shape
    spec = oiio.ImageSpec(width, height, n, kind)
    spec.attribute("oiio:ColorSpace", "lin_rec709" if linear else "sRGB")
    spec.alpha_channel = 3 if n == 4 else -1
    _write_all([(path, fmt, spec, pixels)])


def _stores_alpha(fmt: str) -> bool:
    """Whether the picture format ``fmt`` stores an alpha channel (its writer says)."""
    if fmt in WITH_ALPHA:
        return True
    out = oiio.ImageOutput.create(fmt)
    return out is not None and bool(out.supports("alpha"))


def srgb_encode(linear) -> np.ndarray:
    """Linear values -> sRGB-encoded values in [0, 1] (IEC 61966-2-1), float64; clipped to
    [0, 1] first (NaN becomes 0, +inf 1)."""
    x = np.clip(np.nan_to_num(np.asarray(linear, dtype=np.float64), nan=0.0, posinf=1.0,
                              neginf=0.0), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def srgb8(rgb_linear) -> np.ndarray:
    """(H,W,3) linear RGB -> (H,W,3) uint8 with the sRGB transfer function (IEC 61966-2-1).

    Values are clipped to [0, 1] first (NaN becomes 0) and rounded to the nearest code:
    linear 0.5 -> 188.
    """
    rgb = np.asarray(rgb_linear, dtype=np.float64)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.shape[0] == 0 or rgb.shape[1] == 0:
        raise ValueError(f"expected an (H,W,3) RGB array, got shape {rgb.shape}")
    return np.ascontiguousarray(np.rint(srgb_encode(rgb) * 255.0).astype(np.uint8))


def read_exr(path) -> tuple[dict[str, np.ndarray], dict]:
    """Read an image (EXR, or anything OpenImageIO reads): (channels, attributes).

    channels: name -> (H,W) float32 C-contiguous array, in CHANNEL_ORDER first, then the
    others in the reader's order. attributes: every header attribute, name -> value (str,
    int, float, or a tuple for vectors / matrices), plus ``compression``; a file whose data
    window is not its display window (a tile: ``write_exr(window=...)``) adds
    ``dataWindow`` and ``displayWindow``, (x0, y0, x1, y1) inclusive, as OpenEXR states
    them (the channels are the data window's pixels).
    Raises SubtraceError naming the file when it is missing or cannot be read.
    """
    file = path_str(path)
    if not os.path.exists(file):
        raise SubtraceError(f"{file}: no such file")
    if os.path.isdir(file):
        raise SubtraceError(f"{file}: is a directory, expected an image file")
    inp = oiio.ImageInput.open(file)
    if inp is None:
        raise SubtraceError(f"{file}: cannot read the image: {_oiio_error()}")
    try:
        spec = inp.spec()
        pixels = inp.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
        if pixels is None:
            raise SubtraceError(f"{file}: cannot read the pixels: {_oiio_error(inp)}")
        attributes = {}
        for param in spec.extra_attribs:
            value = param.value
            attributes[param.name] = value
        if (spec.x, spec.y, spec.width, spec.height) != (
                spec.full_x, spec.full_y, spec.full_width, spec.full_height):
            attributes["dataWindow"] = (spec.x, spec.y, spec.x + spec.width - 1,
                                        spec.y + spec.height - 1)
            attributes["displayWindow"] = (spec.full_x, spec.full_y,
                                           spec.full_x + spec.full_width - 1,
                                           spec.full_y + spec.full_height - 1)
    finally:
        inp.close()
    pixels = np.asarray(pixels, dtype=np.float32).reshape(spec.height, spec.width, -1)
    names = list(spec.channelnames)
    order = [n for n in CHANNEL_ORDER if n in names] + [n for n in names if n not in CHANNEL_ORDER]
    channels = {n: np.ascontiguousarray(pixels[:, :, names.index(n)]) for n in order}
    return channels, attributes


# --------------------------------------------------------------------------------------
# internals
# --------------------------------------------------------------------------------------


def _channel_arrays(channels: dict) -> tuple[list[str], list[np.ndarray]]:
    """Channel names in write order and their (H,W) float32 arrays, checked."""
    if not channels:
        raise ValueError("write_exr needs at least one channel")
    for name in channels:
        if not isinstance(name, str) or not name:
            raise ValueError(f"channel names must be non-empty strings, got {name!r}")
    names = [n for n in CHANNEL_ORDER if n in channels]
    names += [n for n in channels if n not in CHANNEL_ORDER]
    arrays = []
    for name in names:
        array = np.asarray(channels[name])
        if array.ndim != 2 or 0 in array.shape:
            raise ValueError(f"channel {name}: expected a non-empty (H,W) array, got {array.shape}")
        if arrays and array.shape != arrays[0].shape:
            raise ValueError(f"channel {name}: shape {array.shape} differs from {arrays[0].shape}")
        if name in INTEGER_CHANNELS:
            _check_integers(name, array)
        arrays.append(np.asarray(array, dtype=np.float32))
    return names, arrays


def _check_integers(name: str, array: np.ndarray) -> None:
    if np.issubdtype(array.dtype, np.integer):
        if array.size and int(np.abs(array).max()) > MAX_EXACT_INTEGER:
            raise ValueError(
                f"channel {name}: values above 2^24 cannot be stored exactly in float32"
            )
        return
    # in the array's own precision: NaN fails ==, an infinity fails the magnitude test
    whole = bool(np.all(array == np.rint(array)))
    if not whole or float(np.abs(array).max()) > MAX_EXACT_INTEGER:
        raise ValueError(f"channel {name}: expected whole numbers of magnitude <= 2^24")


def _header(attributes: dict) -> dict:
    header = {"Software": f"subtrace {VERSION}", "subtrace:version": VERSION}
    for key, value in attributes.items():
        if not isinstance(key, str) or not key:
            raise TypeError(f"attribute names must be non-empty strings, got {key!r}")
        if ":" not in key and key not in STANDARD_ATTRIBUTES:
            key = ATTRIBUTE_PREFIX + key
        if key == "compression":
            raise ValueError("the compression attribute is fixed (zip)")
        header[key] = value
    return header


def _attribute_value(key: str, value):
    """A header value as OpenEXR's binding stores it (see the module comment)."""
    if isinstance(value, (bool, np.bool_)):
        return int(value)
    if isinstance(value, (int, np.integer)):
        value = int(value)
        # OpenEXR has no 64-bit integer attribute: a larger one is kept exact as text
        return value if _INT32[0] <= value <= _INT32[1] else str(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    if isinstance(value, str):
        return value
    if isinstance(value, (tuple, list, np.ndarray)) and np.size(value) in _FLOAT_TUPLES:
        floats = tuple(float(v) for v in np.asarray(value, dtype=np.float64).ravel())
        return _FLOAT_TUPLES[len(floats)](floats)
    raise TypeError(
        f"attribute {key}: unsupported value {value!r} (use str, int, float, bool, "
        "3, 8 or 16 floats)"
    )


def _png_spec(width: int, height: int):
    spec = oiio.ImageSpec(width, height, 3, oiio.UINT8)
    spec.attribute("oiio:ColorSpace", "sRGB")
    return spec


def _write_all(jobs) -> None:
    """Write each (path, format, spec, pixels) to a temporary, then move all into place
    (:func:`subtrace.runtime.atomic.atomic_paths`).

    pixels: what _write_image takes for the format, or a function returning it. Every
    temporary is created first (so a bad folder fails before anything is written); the jobs
    after the first are written on threads of their own while the first is written here
    (OpenImageIO and OpenEXR release the GIL while they encode).
    """
    errors: list[BaseException | None] = [None] * len(jobs)
    with atomic_paths([path for path, _, _, _ in jobs]) as temps:

        def write(k: int) -> None:
            path, fmt, spec, pixels = jobs[k]
            try:
                _write_image(path_str(path), temps[k], fmt, spec,
                             pixels() if callable(pixels) else pixels)
            except BaseException as exc:  # re-raised below, once every writer has finished
                errors[k] = exc

        helpers = [threading.Thread(target=write, args=(k,)) for k in range(1, len(jobs))]
        for helper in helpers:
            helper.start()
        try:
            write(0)
        finally:
            for helper in helpers:
                helper.join()
        for exc in errors:
            if exc is not None:
                raise exc


def _write_image(path_str: str, temp: str, fmt: str, spec, pixels) -> None:
    """Write ``pixels`` to ``temp``: for "openexr", ``spec`` is an OpenEXR header and
    ``pixels`` name -> (H,W) array in the channel's own type; otherwise an OpenImageIO
    ImageSpec and an (H,W,C) array."""
    if fmt == "openexr":
        _write_openexr(path_str, temp, spec, pixels)
        return
    if fmt == "bytes":  # (pixels: the file's parts, in order: bytes, or files read through)
        try:
            with open_temp(temp, "wb") as stream:
                for part in pixels:
                    if isinstance(part, (bytes, bytearray, memoryview)):
                        stream.write(part)
                    else:
                        shutil.copyfileobj(part, stream, 1 << 20)
        except OSError as err:
            raise SubtraceError(f"{path_str}: cannot write the file: {reason(err)}") from None
        return
    out = oiio.ImageOutput.create(fmt)
    if out is None:
        raise SubtraceError(f"{path_str}: OpenImageIO has no {fmt} writer: {_oiio_error()}")
    try:
        # (opened under the temporaries' lock: once an interrupt's clean-up holds it, no
        # writer can create its temporary again after the clean-up removed it)
        with temp_lock():
            opened = out.open(temp, spec)
        if not opened:
            raise SubtraceError(f"{path_str}: cannot write the file: {_oiio_error(out)}")
        if not out.write_image(pixels):
            raise SubtraceError(f"{path_str}: cannot write the pixels: {_oiio_error(out)}")
    finally:
        closed = out.close()
    if not closed:
        raise SubtraceError(f"{path_str}: cannot finish the file: {_oiio_error(out)}")


def _write_openexr(path_str: str, temp: str, header: dict, channels: dict) -> None:
    _openexr_threads()
    try:
        # written through a file opened under the temporaries' lock (see _write_image),
        # not by name: the lock is not held while the film is encoded
        with open_temp(temp, "wb") as stream:
            OpenEXR.File(header, channels).write(stream)
    except OSError as err:
        raise SubtraceError(f"{path_str}: cannot write the file: {reason(err)}") from None
    except (RuntimeError, ValueError) as exc:
        raise SubtraceError(f"{path_str}: cannot write the file: {' '.join(str(exc).split())}"
                            ) from None


def _oiio_error(obj=None) -> str:
    message = (obj.geterror() if obj is not None else "") or oiio.geterror()
    return " ".join(message.split()) or "unknown error"


__all__ = ["write_exr", "ExrBands", "write_png", "read_exr", "srgb8", "check_writable",
           "CHANNEL_ORDER"]
