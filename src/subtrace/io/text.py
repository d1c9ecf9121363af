"""Reading and decoding the text files subtrace consumes (OBJ, TOML scenes, line CSVs).

One reader for all of them: :func:`read_bytes` turns a failed read into the caller's error
type with a message naming the problem, :func:`decode` turns a byte that is not UTF-8 into
an error naming its line and column. Callers pass ``error(problem, line)``, which builds
their exception (ObjError, SceneError ...) naming the file.
"""

from __future__ import annotations

from pathlib import Path

UTF8_BOM = b"\xef\xbb\xbf"


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


def decode(data: bytes, error, *, noun: str = "file") -> str:
    """UTF-8 text without a byte-order mark; a bad byte raises ``error(problem, line)``
    asking to save the ``noun`` as UTF-8."""
    try:
        return utf8_text(data)
    except BadByte as err:
        raise error(f"{err}; save the {noun} as UTF-8", err.line) from None
