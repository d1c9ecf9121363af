"""Reading and decoding the text files subtrace consumes (OBJ, TOML scenes, line CSVs).

One reader for all of them: :func:`read_bytes` turns a failed read into the caller's error
type with a message naming the problem, :func:`decode` turns a byte that is not UTF-8 into
an error naming its line and column. Callers pass ``error(problem, line)``, which builds
their exception (ObjError, SceneError ...) naming the file.
"""

from __future__ import annotations

from pathlib import Path

UTF8_BOM = b"\xef\xbb\xbf"
UTF16_BOMS = (b"\xff\xfe", b"\xfe\xff")
# the first bytes of binary files that are met under a text file's name (their formats'
# specifications), and what to call them
BINARY_MAGIC = (
    (b"\x89PNG\r\n\x1a\n", "a PNG image"), (b"\xff\xd8\xff", "a JPEG image"),
    (b"GIF87a", "a GIF image"), (b"GIF89a", "a GIF image"), (b"II*\x00", "a TIFF image"),
    (b"MM\x00*", "a TIFF image"), (b"v/1\x01", "an OpenEXR image"),
    (b"\x1f\x8b", "gzip-compressed data"), (b"BZh", "bzip2-compressed data"),
    (b"\xfd7zXZ\x00", "xz-compressed data"), (b"(\xb5/\xfd", "zstd-compressed data"),
    (b"PK\x03\x04", "a zip archive"), (b"7z\xbc\xaf'\x1c", "a 7-Zip archive"),
    (b"Rar!\x1a\x07", "a RAR archive"), (b"%PDF-", "a PDF document"),
    (b"\x7fELF", "an ELF executable"), (b"MZ", "a Windows executable"),
    (b"\x89HDF\r\n\x1a\n", "an HDF5 file"), (b"SQLite format 3\x00", "an SQLite database"),
)
SNIFF_BYTES = 8192  # how much of a file :func:`looks_binary` looks at
# shares of the sniffed bytes above which they are binary data, not text: control codes
# (text has tabs, line ends, form feeds and the separators \x1c-\x1f, whitespace to
# Python's split, alone), and bytes that are not UTF-8 (a Latin-1 text's accents are a
# few percent at most; random bytes are 10 % control codes, half not UTF-8)
BINARY_CONTROL_SHARE = 0.02
BINARY_INVALID_SHARE = 0.1
BINARY_MIN_BYTES = 64  # (the shares of fewer bytes say little: such a file is text)
_CONTROL = bytes(b for b in range(0x1c) if b not in b"\t\n\r\x0b\x0c") + b"\x7f"


class BadByte(ValueError):
    """A byte that is not valid UTF-8: 1-based ``line`` and ``column``, and the byte."""

    def __init__(self, line: int, column: int, byte: int):
        self.line, self.column, self.byte = line, column, byte
        super().__init__(f"byte 0x{byte:02x} at column {column} is not valid UTF-8")


def utf8_text(data: bytes) -> str:
    """Decode UTF-8 (dropping a byte-order mark); raises :class:`BadByte` naming its line."""
    if data.startswith(UTF8_BOM):
        data = data[3:]
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        line = data.count(b"\n", 0, err.start) + 1
        column = err.start - (data.rfind(b"\n", 0, err.start) + 1) + 1
        raise BadByte(line, column, data[err.start]) from None


def read_bytes(path, error, *, expected: str, noun: str = "file") -> bytes:
    """The bytes of ``path``; a failed read raises ``error(problem, None)``.

    expected: what a directory was given instead of (``"an OBJ file"``); noun: what is
    missing (``"no such scene file"``).
    """
    try:
        return Path(path).read_bytes()
    except IsADirectoryError:
        raise error(f"is a directory, expected {expected}", None) from None
    except FileNotFoundError:
        raise error(f"no such {noun}", None) from None
    except PermissionError:
        raise error("cannot read the file: permission denied", None) from None
    except OSError as err:
        raise error(f"cannot read the file: {err.strerror or err}", None) from None


def magic_kind(data: bytes) -> str | None:
    """The binary format ``data``'s first bytes name ("a PNG image", "gzip-compressed
    data": :data:`BINARY_MAGIC`), or None."""
    for magic, kind in BINARY_MAGIC:
        if data.startswith(magic):
            return kind
    return None


def looks_binary(data: bytes) -> bool:
    """Whether the first bytes of ``data`` (which are not all UTF-8) are binary data rather
    than text in another 8-bit encoding: shares of control codes or of bytes that are not
    UTF-8 that no text has (:data:`BINARY_CONTROL_SHARE`, :data:`BINARY_INVALID_SHARE`)."""
    head = data[:SNIFF_BYTES]
    if len(head) < BINARY_MIN_BYTES:
        return False
    controls = len(head) - len(head.translate(None, _CONTROL))
    invalid = head.decode("utf-8", errors="replace").count("\ufffd")
    return (controls > BINARY_CONTROL_SHARE * len(head)
            or invalid > BINARY_INVALID_SHARE * len(head))


def check_text(data: bytes, error, *, noun: str = "file") -> None:
    """Raise ``error(problem, None)`` when ``data`` is a binary format by its first bytes
    (:func:`magic_kind`: not a text file) or UTF-16 text (the ``noun`` is to be saved as
    UTF-8)."""
    if data.startswith(UTF16_BOMS):
        raise error(f"UTF-16 text; save the {noun} as UTF-8", None)
    kind = magic_kind(data)
    if kind is not None:
        raise error(f"not a text file: it looks like {kind}", None)


def decode(data: bytes, error, *, noun: str = "file") -> str:
    """UTF-8 text without a byte-order mark; a file that is not text raises
    ``error(problem, None)`` saying so (:func:`check_text`, :func:`looks_binary`), a bad
    byte of a text in another encoding ``error(problem, line)`` asking to save the
    ``noun`` as UTF-8."""
    check_text(data, error, noun=noun)
    try:
        return utf8_text(data)
    except BadByte as err:
        if looks_binary(data):
            raise error("not a text file: it looks like binary data", None) from None
        raise error(f"{err}; save the {noun} as UTF-8", err.line) from None
