"""Text decoding shared by the OBJ and scene readers."""

from __future__ import annotations


class BadByte(ValueError):
    """A byte that is not valid UTF-8: 1-based ``line`` and ``column``, and the byte."""

    def __init__(self, line: int, column: int, byte: int):
        self.line, self.column, self.byte = line, column, byte
        super().__init__(f"byte 0x{byte:02x} at column {column} is not valid UTF-8")


def utf8_text(data: bytes) -> str:
    """Decode UTF-8 (dropping a byte-order mark); raises :class:`BadByte` naming its line."""
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        line = data.count(b"\n", 0, err.start) + 1
        column = err.start - (data.rfind(b"\n", 0, err.start) + 1) + 1
        raise BadByte(line, column, data[err.start]) from None
