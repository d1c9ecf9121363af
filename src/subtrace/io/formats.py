"""Image file formats by extension. The common ones are known without OpenImageIO (the
command line checks its options before any image library loads); any other extension is
looked up among the writers of the OpenImageIO at hand (``output_format_list``), so a
``.bmp``, ``.webp`` or ``.hdr`` output is written as what it names, and an extension no
writer takes is an error, not an EXR under another name."""

from __future__ import annotations

import functools
import os

from subtrace.errors import SceneError

EXR_EXTENSIONS = (".exr",)  # the multi-channel OpenEXR: every channel and the header
# the formats a picture (the colour alone) is written in, by file extension, known without
# OpenImageIO; the others come from it (:func:`oiio_picture_formats`)
PICTURE_FORMATS = {".png": "png", ".jpg": "jpeg", ".jpeg": "jpeg", ".tif": "tiff",
                   ".tiff": "tiff"}
WITH_ALPHA = ("png", "tiff")  # picture formats that store alpha (others: asked at writing)
DEEP = ("png", "tiff")  # picture formats that take 16 bits per channel
# picture formats of linear floating-point colour (written as rendered, not sRGB-encoded)
LINEAR = ("hdr", "fits")
# OpenImageIO writers that write no picture of the colour: no file ("null"), the terminal
# ("term"), depth alone ("zfile"); OpenEXR is the multi-channel output (".exr")
_NOT_PICTURES = ("null", "term", "zfile", "openexr")
# extensions whose writer takes the variant from the file name, which the temporary an
# output is written to first (``runtime.atomic.make_temp``: ``.tmp``) does not have: JPEG 2000
# (its codestream or container: an empty file) and the bitmap, grey and float PNM files (a
# colour PPM)
_BY_NAME = (".j2c", ".j2k", ".jp2", ".jph", ".pbm", ".pgm", ".pfm")


def picture_format(path) -> str | None:
    """The picture format of ``path`` by its extension (``png``, ``jpeg``, ``tiff``, or an
    OpenImageIO writer's name: ``bmp``, ``webp``, ``hdr``, ...), or None for ``.exr`` (the
    multi-channel EXR). Raises SceneError (one line listing the formats) for an extension
    no writer takes, or none."""
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext in EXR_EXTENSIONS:
        return None
    fmt = PICTURE_FORMATS.get(ext) or oiio_picture_formats().get(ext)
    if fmt is None:
        what = (f"the extension {ext} names no image format subtrace writes" if ext else
                "no extension to name the image format")
        raise SceneError(f"{what}: give .exr (every channel) or a picture, "
                         f"{', '.join(picture_extensions())}", path=os.fspath(path))
    return fmt


def picture_extensions() -> list[str]:
    """An extension of each picture format (its first: ``.jpg`` for JPEG, ``.tif`` for
    TIFF), sorted."""
    first: dict[str, str] = {}
    for ext, fmt in [*PICTURE_FORMATS.items(), *oiio_picture_formats().items()]:
        first.setdefault(fmt, ext)
    return sorted(first.values())


@functools.cache
def oiio_picture_formats() -> dict[str, str]:
    """Extension -> format name of every OpenImageIO writer of pictures (its
    ``output_format_list`` and ``extension_list``, less :data:`_NOT_PICTURES`)."""
    import OpenImageIO as oiio

    writers = set(oiio.get_string_attribute("output_format_list").split(","))
    out = {}
    for entry in oiio.get_string_attribute("extension_list").split(";"):
        fmt, _, exts = entry.partition(":")
        if fmt in writers and fmt not in _NOT_PICTURES:
            for ext in exts.split(","):
                if f".{ext.lower()}" not in _BY_NAME:
                    out.setdefault(f".{ext.lower()}", fmt)
    return out
