"""Lines for ``subtrace intersect``: a UTF-8 CSV whose header names the columns
ox,oy,oz,dx,dy,dz (origin and direction; other columns are ignored) -> (n, 6) float64.

Every problem raises :class:`subtrace.errors.SubtraceError` naming the file, the 1-based
line and the problem: an unreadable or non-UTF-8 file, no header, a missing column, a row of
the wrong length, a value that is not a finite number, a zero direction.
"""

from __future__ import annotations

import csv
import math

import numpy as np

from subtrace.errors import SubtraceError
from subtrace.io.text import decode

LINE_COLUMNS = ("ox", "oy", "oz", "dx", "dy", "dz")


def read_lines_csv(path) -> np.ndarray:
    """(n, 6) float64 origins and directions of the lines of the CSV ``path`` (module
    comment). Blank rows are skipped."""
    try:
        with open(path, "rb") as fh:
            raw = fh.read()
    except OSError as exc:
        raise SubtraceError(f"{path}: cannot read the lines: {exc.strerror or exc}") from None
    text = decode(raw, lambda problem, line: SubtraceError(f"{path}:{line}: {problem}"))
    if not text.strip():
        raise SubtraceError(f"{path}: empty file: expected a header ox,oy,oz,dx,dy,dz and "
                            "a row of numbers per line")
    reader = csv.reader(text.splitlines())
    header = [h.strip() for h in next(reader)]
    missing = [c for c in LINE_COLUMNS if c not in header]
    if missing:
        raise SubtraceError(f"{path}:{reader.line_num}: missing column(s) {', '.join(missing)} "
                            "(expected a header ox,oy,oz,dx,dy,dz)")
    index = [header.index(c) for c in LINE_COLUMNS]
    rows = []
    for row in reader:
        where = f"{path}:{reader.line_num}"
        if not any(cell.strip() for cell in row):
            continue  # blank line
        if len(row) != len(header):
            raise SubtraceError(f"{where}: expected {len(header)} values "
                                f"({','.join(header)}), got {len(row)}")
        rows.append(_row_values(where, row, index))
    return np.array(rows, dtype=np.float64).reshape(-1, 6)


def _row_values(where: str, row, index) -> list[float]:
    """The six numbers of a row (columns ``index`` of LINE_COLUMNS), checked."""
    values = []
    for c, k in zip(LINE_COLUMNS, index):
        cell = row[k].strip()
        try:
            v = float(cell)
        except ValueError:
            raise SubtraceError(f"{where}: {c}: {cell!r} is not a number") from None
        if not math.isfinite(v):
            raise SubtraceError(f"{where}: {c}: {cell!r} is not a finite number")
        values.append(v)
    if values[3] == values[4] == values[5] == 0.0:
        raise SubtraceError(f"{where}: the direction (0, 0, 0) is zero: a line needs a "
                            "direction")
    return values
