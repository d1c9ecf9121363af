"""Image file formats by extension (no OpenImageIO import: the command line checks its
options with it before any image library loads)."""

from __future__ import annotations

import os

# the formats a picture (the colour alone, sRGB) is written in, by file extension; any
# other output is the multi-channel OpenEXR
PICTURE_FORMATS = {".png": "png", ".jpg": "jpeg", ".jpeg": "jpeg", ".tif": "tiff",
                   ".tiff": "tiff"}
WITH_ALPHA = ("png", "tiff")  # picture formats that store alpha
DEEP = ("png", "tiff")  # picture formats that take 16 bits per channel


def picture_format(path) -> str | None:
    """The picture format of ``path`` by its extension (``png``, ``jpeg``, ``tiff``), or None
    for anything else (written as a multi-channel EXR)."""
    return PICTURE_FORMATS.get(os.path.splitext(os.fspath(path))[1].lower())
