"""The results of a sweep: :class:`SweepRecord` (one per scene and tolerance, the columns
:data:`COLUMNS`), and their reports: a fixed-width text table (:func:`format_table`),
``sweep.csv`` and ``sweep.json`` (written through :mod:`subtrace.runtime.atomic`).
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass, fields

from subtrace.runtime.atomic import write_text
from subtrace.sweep.plot import LEVEL_COLOURS, PLOTS
from subtrace.version import VERSION


@dataclass
class SweepRecord:
    """One (scene, tolerance) of a sweep; the fields are :data:`COLUMNS`. Times in seconds
    (medians of the repeats), memory in MiB (None where it cannot be measured), depth
    errors in world units and in pixel footprints, angles in degrees; ``exr`` and
    ``levels_png`` are paths relative to the output folder (None without one)."""

    scene: str
    tolerance_px: float
    tolerance_deg: float
    width: int
    height: int
    repeats: int
    time_total_s: float
    time_refine_s: float
    time_trace_s: float
    peak_memory_mb: float | None
    patches: int
    patches_refined: int
    micro_triangles: int
    max_depth: int
    pixels_covered: int
    depth_err_mean: float
    depth_err_max: float
    depth_err_px_mean: float
    depth_err_px_max: float
    normal_err_mean_deg: float
    normal_err_max_deg: float
    coverage_mismatches: int
    colour_rmse: float
    flip_mean: float | None
    reference_tolerance_px: float
    exr: str | None = None
    levels_png: str | None = None

    def as_dict(self) -> dict:
        return {name: getattr(self, name) for name in COLUMNS}


# The columns of sweep.csv, and the keys of every record in sweep.json, in this order.
COLUMNS = tuple(f.name for f in fields(SweepRecord))


def write_csv(records, path) -> None:
    """sweep.csv: a header of :data:`COLUMNS`, a row per record (None: empty cell)."""
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(COLUMNS)
    for rec in records:
        writer.writerow(["" if v is None else v for v in rec.as_dict().values()])
    write_text(path, text.getvalue())


def write_json(records, path) -> None:
    """sweep.json: ``{"columns": COLUMNS, "records": [...], "plots": ..., "level_colours":
    ...}``; non-finite numbers become strings (JSON has none)."""
    clean = lambda v: str(v) if isinstance(v, float) and not math.isfinite(v) else v  # noqa: E731
    doc = {
        "version": VERSION,
        "columns": list(COLUMNS),
        "records": [{k: clean(v) for k, v in rec.as_dict().items()} for rec in records],
        "plots": PLOTS,
        "level_colours": list(LEVEL_COLOURS),
    }
    write_text(path, json.dumps(doc, indent=2) + "\n")


def format_table(records) -> str:
    """The records as a fixed-width text table (the terminal report of ``subtrace sweep``)."""
    head = ("scene", "tol px", "total s", "refine s", "trace s", "peak MiB", "refined",
            "micro-tris", "depth", "dZ mean px", "dZ max px", "N mean°", "cov", "RMSE", "FLIP")
    rows = []
    for r in records:
        g = lambda v, p=3: "n/a" if v is None else f"{v:.{p}g}"  # noqa: E731
        rows.append((r.scene, f"{r.tolerance_px:g}", f"{r.time_total_s:.3f}",
                     f"{r.time_refine_s:.3f}", f"{r.time_trace_s:.3f}",
                     "n/a" if r.peak_memory_mb is None else f"{r.peak_memory_mb:.1f}",
                     f"{r.patches_refined}/{r.patches}", str(r.micro_triangles),
                     str(r.max_depth), g(r.depth_err_px_mean), g(r.depth_err_px_max),
                     g(r.normal_err_mean_deg), str(r.coverage_mismatches),
                     g(r.colour_rmse), g(r.flip_mean)))
    widths = [max(len(x) for x in col) for col in zip(head, *rows)]
    lines = ["  ".join(x.rjust(w) if k else x.ljust(w) for k, (x, w) in
                       enumerate(zip(row, widths))) for row in (head, *rows)]
    return "\n".join(line.rstrip() for line in lines)
