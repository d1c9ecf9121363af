"""Angular-tolerance sweeps: what each tolerance costs (time, memory, refinement) and what it
buys (image error against a reference render at a much finer tolerance).

:func:`sweep` renders every scene first at the reference tolerance, then at each swept
tolerance (coarse to fine, ``repeat`` times each), and returns one :class:`SweepRecord` per
(scene, tolerance). With an output folder it also writes, per scene, the EXR of every
tolerance and of the reference and a refinement-level heat map PNG per tolerance
(``<dir>/<scene>/tol_<T>.exr``, ``tol_<T>_levels.png``, ``reference.exr``), and for the
whole sweep ``sweep.csv``, ``sweep.json`` and three log-log plots (:data:`PLOTS`).

Measurements (the columns are :data:`COLUMNS`, documented in the README):
  times   RenderStats times (total, refine, trace) of each render, the median of the
          repeats, each column separately. The reference renders first, so every swept
          render finds Numba's kernels loaded and the per-process tables built.
  memory  the render's own peak: the growth of the process's resident set over its size
          just before the render. Before each render the C heap's free memory is given
          back to the system (glibc ``malloc_trim``) and the kernel's high-water mark is
          reset (``/proc/self/clear_refs``, Linux >= 4.0), so neither an earlier render's
          peak nor memory it freed but kept is counted; the largest of the repeats is
          reported. None where /proc/self/clear_refs is not writable.
  errors  against the reference, over the pixels both cover: depth error |Z - Zref| in
          world units and as a fraction of the pixel footprint Zref * pixel angle (mean and
          max; the max includes silhouette and occlusion-step pixels where the two renders
          see different surfaces), normal angle (mean and max, degrees); over all pixels:
          coverage mismatches (:mod:`subtrace.compare`'s coverage count), colour RMSE and
          mean FLIP (:func:`subtrace.compare.compare_images`).
Tolerances are in pixels at the image centre (``--tolerance``); the reference tolerance
defaults to a quarter of the finest swept one.

``subtrace.sweep`` is this module (a package's submodule is its attribute once imported), so
the module is callable: ``subtrace.sweep(...)`` is ``subtrace.sweep.sweep(...)``.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import statistics
import sys
import types
from dataclasses import dataclass, fields

import numpy as np

from subtrace.errors import SceneError, SubtraceError
from subtrace.runtime.progress import ProgressBar

# The plots written beside sweep.csv: file name -> what it shows (log-log, a line per scene).
PLOTS = {
    "time_vs_tolerance.png": "total time (solid), refine (dashed) and trace (dotted)",
    "micro_triangles_vs_tolerance.png": "micro-triangles (solid) and pixels covered (dotted)",
    "error_vs_tolerance.png": "mean depth error (pixel footprints), mean normal error "
                              "(degrees), colour RMSE and mean FLIP",
}

# Colours of the refinement-level heat maps: level k is LEVEL_COLOURS[k] (sRGB, a rainbow
# ramp from dark blue to dark red, so that neighbouring levels differ clearly), deeper levels
# take the last; pixels without a surface are black. The same for every scene and tolerance.
LEVEL_COLOURS = (
    "#30123b", "#4662d7", "#36aaf9", "#1ae4b6", "#72fe5e", "#c8ef34", "#faba39", "#f66b19",
    "#ca2a04",
)

REFERENCE_FACTOR = 4.0  # default reference tolerance: the finest swept one over this


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


def sweep(scenes, tolerances, *, reference_tolerance=None, repeat: int = 1,
          output_dir=None, threads=None, accel=None, progress=None) -> list[SweepRecord]:
    """Render each scene at each tolerance and measure cost and error (module comment).

    scenes: :class:`subtrace.io.scene.Scene` objects, or paths of TOML scenes or OBJ cages
      (one cage per path, automatic camera); build a Scene with ``apply_overrides`` to
      change its camera or resolution.
    tolerances: angular tolerances in pixels (> 0); swept coarse to fine, duplicates once.
    reference_tolerance: pixels, finer than every swept tolerance (default: the finest / 4).
    repeat: renders per tolerance; times are their medians.
    output_dir: write the EXRs, heat maps, sweep.csv, sweep.json and plots there (created
      if missing); None writes nothing.
    threads, accel: as :func:`subtrace.render.render_scene`.
    progress: called as ``progress(done, total, label)`` before the first and after every
      render (e.g. :class:`ProgressBar`).
    Returns the records, scene by scene, coarse to fine. Raises SubtraceError (naming the
    option or file) for bad input before anything is rendered or written.
    """
    tols = check_tolerances(tolerances)
    ref_tol = check_reference(reference_tolerance, tols)
    repeat = check_repeat(repeat)
    scenes = [_as_scene(s) for s in scenes]
    if not scenes:
        raise SceneError("give at least one scene", key="scenes")
    from subtrace.render import load_objects

    for scene in scenes:
        load_objects(scene)  # bad cages fail here, before anything is written
    if output_dir is not None:
        output_dir = prepare_output_dir(output_dir)
    names = _unique_names(scenes)

    total = len(scenes) * (1 + len(tols) * repeat)
    done = 0
    if progress:
        progress(0, total, names[0])
    records = []
    for name, scene in zip(names, scenes):
        ref, _ = _render(scene, ref_tol, threads, accel)  # (a bad option fails here)
        folder = None
        if output_dir is not None:  # made once the first render has succeeded
            folder = os.path.join(output_dir, name)
            os.makedirs(folder, exist_ok=True)
        done += 1
        if progress:
            progress(done, total, f"{name} reference {ref_tol:g} px")
        if folder:
            _write_exr(os.path.join(folder, "reference.exr"), ref, scene, ref_tol)
        for tol in tols:
            runs = []
            for _ in range(repeat):
                runs.append(_render(scene, tol, threads, accel))
                done += 1
                if progress:
                    progress(done, total, f"{name} {tol:g} px")
            result = runs[0][0]
            record = _record(name, tol, ref_tol, runs, ref)
            if folder:
                stem = f"tol_{tol:g}"
                record.exr = f"{name}/{stem}.exr"
                record.levels_png = f"{name}/{stem}_levels.png"
                _write_exr(os.path.join(output_dir, record.exr), result, scene, tol)
                from subtrace.io.exr import write_png

                write_png(os.path.join(output_dir, record.levels_png),
                          level_image(result.channels["level"]))
            records.append(record)
    if output_dir is not None:
        write_csv(records, os.path.join(output_dir, "sweep.csv"))
        write_json(records, os.path.join(output_dir, "sweep.json"))
        plot(records, output_dir)
    return records


# --------------------------------------------------------------------------------------
# input checks
# --------------------------------------------------------------------------------------


def check_tolerances(values, key: str = "tolerances") -> list[float]:
    """Tolerances in pixels (numbers or their text), each > 0 and finite, sorted coarse to
    fine without duplicates. Raises SceneError naming ``key`` (the option)."""
    tols = []
    for value in values:
        number = _number(value)
        if not (number > 0 and math.isfinite(number)):
            raise SceneError(f"expected tolerances in pixels > 0, got {value!r}", key=key)
        tols.append(number)
    if not tols:
        raise SceneError("give at least one tolerance in pixels", key=key)
    return sorted(set(tols), reverse=True)


def check_reference(value, tols, key: str = "reference_tolerance") -> float:
    """The reference tolerance in pixels: ``value`` (> 0, finer than every swept tolerance)
    or, when None, the finest swept tolerance / REFERENCE_FACTOR."""
    if value is None:
        return min(tols) / REFERENCE_FACTOR
    number = _number(value)
    if not (number > 0 and math.isfinite(number)):
        raise SceneError(f"expected a tolerance in pixels > 0, got {value!r}", key=key)
    if number >= min(tols):
        raise SceneError(
            f"{number:g} px is not finer than the finest swept tolerance {min(tols):g} px: "
            f"the reference must be finer (default: {min(tols) / REFERENCE_FACTOR:g})",
            key=key,
        )
    return number


def check_repeat(value, key: str = "repeat") -> int:
    """The number of renders per tolerance, an integer >= 1."""
    try:
        number = int(str(value).strip())
    except ValueError:
        number = 0
    if number < 1:
        raise SceneError(f"expected a whole number of renders >= 1, got {value!r}", key=key)
    return number


def prepare_output_dir(path) -> str:
    """Create the output folder if missing and check that files can be written in it;
    raises SubtraceError naming the folder. Returns the path as str."""
    path = os.fsdecode(os.fspath(path))
    if os.path.exists(path) and not os.path.isdir(path):
        raise SubtraceError(f"output folder {path}: is a file, expected a folder")
    try:
        os.makedirs(path, exist_ok=True)
    except OSError as err:
        reason = "permission denied" if isinstance(err, PermissionError) else (
            err.strerror or str(err))
        raise SubtraceError(f"output folder {path}: cannot create it: {reason}") from None
    from subtrace.io.exr import check_writable

    try:
        check_writable(os.path.join(path, "sweep.csv"))
    except SubtraceError as err:
        raise SubtraceError(f"output folder {path}: {err}") from None
    return path


def _number(value) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def _as_scene(scene):
    """A Scene, or the Scene of a TOML path / of one OBJ cage."""
    from subtrace.io.scene import Scene, load_scene, scene_for_meshes

    if isinstance(scene, Scene):
        return scene
    path = os.fsdecode(os.fspath(scene))
    return load_scene(path) if path.lower().endswith(".toml") else scene_for_meshes([path])


def _unique_names(scenes) -> list[str]:
    """A folder name per scene: its file's stem (the first mesh's without a file), with
    -2, -3 ... added to repeats."""
    names, seen = [], {}
    for scene in scenes:
        source = scene.path or scene.objects[0].mesh
        base = os.path.splitext(os.path.basename(source))[0] or "scene"
        seen[base] = seen.get(base, 0) + 1
        names.append(base if seen[base] == 1 else f"{base}-{seen[base]}")
    return names


# --------------------------------------------------------------------------------------
# rendering and measuring
# --------------------------------------------------------------------------------------


def _render(scene, tol_px: float, threads, accel):
    """Render ``scene`` at ``tol_px``; returns (RenderResult, peak memory in bytes or None)."""
    from dataclasses import replace

    from subtrace.render import render_scene

    scene = replace(scene, render=replace(scene.render, tolerance_px=tol_px, tolerance_deg=None))
    probe = PeakMemory()
    probe.start()
    result = render_scene(scene, threads=threads, accel=accel)
    return result, probe.peak()


class PeakMemory:
    """The growth of this process's resident set from :meth:`start` to its highest point
    before :meth:`peak` (Linux: VmRSS and VmHWM of /proc/self/status, the high-water mark
    reset through /proc/self/clear_refs; see the module comment)."""

    def __init__(self):
        self._base = None

    def start(self) -> None:
        import gc

        gc.collect()
        _malloc_trim()
        try:
            with open("/proc/self/clear_refs", "w") as f:
                f.write("5")  # reset the peak resident set to the current one
            self._base = _status_kb("VmRSS")
        except OSError:
            self._base = None

    def peak(self) -> int | None:
        """Bytes, or None where the high-water mark cannot be reset or read."""
        if self._base is None:
            return None
        try:
            return max(0, _status_kb("VmHWM") - self._base) * 1024
        except OSError:
            return None


def _status_kb(field: str) -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1])
    raise OSError(f"no {field} in /proc/self/status")


def _malloc_trim() -> None:
    """Give the C heap's free pages back to the system (glibc only; elsewhere nothing)."""
    import ctypes
    import ctypes.util

    try:
        ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass


def _record(name, tol_px, ref_tol_px, runs, ref) -> SweepRecord:
    """The record of one tolerance from its repeated renders ``runs`` [(result, peak)]."""
    result = runs[0][0]
    st = result.stats
    cam = result.camera
    med = lambda key: statistics.median(getattr(r.stats, key) for r, _ in runs)  # noqa: E731
    peaks = [p for _, p in runs if p is not None]
    errors = image_errors(result, ref)
    return SweepRecord(
        scene=name, tolerance_px=tol_px, tolerance_deg=math.degrees(result.tolerance_rad),
        width=cam.width, height=cam.height, repeats=len(runs),
        time_total_s=med("time_total"), time_refine_s=med("time_refine"),
        time_trace_s=med("time_trace"),
        peak_memory_mb=max(peaks) / 2**20 if len(peaks) == len(runs) else None,
        patches=st.patches, patches_refined=st.patches_refined,
        micro_triangles=st.micro_triangles, max_depth=st.max_depth,
        pixels_covered=st.pixels_covered, reference_tolerance_px=ref_tol_px, **errors,
    )


def image_errors(result, ref) -> dict:
    """The error columns of a render against the reference render (module comment)."""
    from subtrace.compare import compare_images

    c, r = result.channels, ref.channels
    z = np.asarray(c["Z"], np.float64)
    z_ref = np.asarray(r["Z"], np.float64)
    both = (np.asarray(c["A"]) > 0) & (np.asarray(r["A"]) > 0)
    dz = np.abs(z[both] - z_ref[both])
    footprint = z_ref[both] * ref.camera.pixel_angle()
    dz_px = dz / footprint
    groups = compare_images(c, r).groups
    normal = groups["normals"].metrics
    colour = groups["colour"].metrics
    stat = lambda x, f: float(f(x)) if x.size else 0.0  # noqa: E731
    return {
        "depth_err_mean": stat(dz, np.mean), "depth_err_max": stat(dz, np.max),
        "depth_err_px_mean": stat(dz_px, np.mean), "depth_err_px_max": stat(dz_px, np.max),
        "normal_err_mean_deg": normal["mean_deg"], "normal_err_max_deg": normal["max_deg"],
        "coverage_mismatches": groups["coverage"].metrics["count"],
        "colour_rmse": colour["rmse"], "flip_mean": colour["mean_flip"],
    }


# --------------------------------------------------------------------------------------
# output
# --------------------------------------------------------------------------------------


def level_image(level) -> np.ndarray:
    """(H,W) refinement levels (-1: no surface) -> (H,W,3) linear RGB: LEVEL_COLOURS[level]
    (deeper levels the last colour), black where there is no surface."""
    srgb = np.array([[int(h[k:k + 2], 16) / 255.0 for k in (1, 3, 5)] for h in LEVEL_COLOURS])
    linear = np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)
    lev = np.asarray(level)
    rgb = linear[np.clip(lev, 0, len(linear) - 1).astype(np.intp)]
    rgb[lev < 0] = 0.0
    return rgb


def _write_exr(path, result, scene, tol_px) -> None:
    """The render's EXR with the header ``subtrace render`` writes (tolerance ``tol_px``)."""
    from dataclasses import replace

    from subtrace.io.exr import write_exr
    from subtrace.render import result_attributes

    scene = replace(scene, render=replace(scene.render, tolerance_px=tol_px, tolerance_deg=None))
    write_exr(path, result.channels, result_attributes(result, scene))


def write_csv(records, path) -> None:
    """sweep.csv: a header of :data:`COLUMNS`, a row per record (None: empty cell)."""
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(COLUMNS)
    for rec in records:
        writer.writerow(["" if v is None else v for v in rec.as_dict().values()])
    _write_text(path, text.getvalue())


def write_json(records, path) -> None:
    """sweep.json: ``{"columns": COLUMNS, "records": [...], "plots": ..., "level_colours":
    ...}``; non-finite numbers become strings (JSON has none)."""
    from subtrace.version import VERSION as __version__

    clean = lambda v: str(v) if isinstance(v, float) and not math.isfinite(v) else v  # noqa: E731
    doc = {
        "version": __version__,
        "columns": list(COLUMNS),
        "records": [{k: clean(v) for k, v in rec.as_dict().items()} for rec in records],
        "plots": PLOTS,
        "level_colours": list(LEVEL_COLOURS),
    }
    _write_text(path, json.dumps(doc, indent=2) + "\n")


def _write_text(path, text: str) -> None:
    """Write through a temporary beside ``path``, then rename (no half-written file)."""
    temp = f"{path}.{os.getpid()}.tmp"
    try:
        with open(temp, "w", encoding="utf-8") as f:
            f.write(text)
        os.replace(temp, path)
    except OSError as err:
        raise SubtraceError(f"{path}: cannot write the file: {err.strerror or err}") from None
    finally:
        if os.path.exists(temp):
            os.unlink(temp)


def plot(records, output_dir) -> list[str]:
    """Write :data:`PLOTS` (matplotlib, Agg) into ``output_dir``; returns their paths.
    Non-positive values (an error of exactly 0) are left out of the log axes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    by_scene: dict = {}
    for rec in records:
        by_scene.setdefault(rec.scene, []).append(rec)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]

    def series(ax, key, style="-", label=True, marker="o"):
        for k, (name, recs) in enumerate(by_scene.items()):
            pts = [(r.tolerance_px, getattr(r, key)) for r in recs]
            pts = [(t, v) for t, v in pts if v is not None and v > 0]
            if pts:
                t, v = zip(*pts)
                ax.plot(t, v, style, marker=marker, color=colours[k % len(colours)],
                        label=name if label else None)

    tols = sorted({r.tolerance_px for r in records})

    def axes(ax, ylabel):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xticks(tols, [f"{t:g}" for t in tols])  # the swept tolerances, no minor labels
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_xlabel("angular tolerance (pixels)")
        ax.set_ylabel(ylabel)
        ax.invert_xaxis()  # finer to the right
        ax.grid(True, which="both", alpha=0.3)

    paths = []

    def save(fig, name):
        path = os.path.join(output_dir, name)
        fig.tight_layout()
        fig.savefig(path, dpi=100)
        plt.close(fig)
        paths.append(path)

    fig, ax = plt.subplots(figsize=(6, 4.5))
    series(ax, "time_total_s")
    series(ax, "time_refine_s", "--", label=False, marker="")
    series(ax, "time_trace_s", ":", label=False, marker="")
    axes(ax, "time (s): total —, refine --, trace ··")
    ax.legend()
    save(fig, "time_vs_tolerance.png")

    fig, ax = plt.subplots(figsize=(6, 4.5))
    series(ax, "micro_triangles")
    series(ax, "pixels_covered", ":", label=False, marker="")
    axes(ax, "micro-triangles (pixels covered ··)")
    ax.legend()
    save(fig, "micro_triangles_vs_tolerance.png")

    fig, grid = plt.subplots(2, 2, figsize=(9, 7))
    for ax, (key, label) in zip(grid.flat, (
            ("depth_err_px_mean", "mean depth error (pixel footprints)"),
            ("normal_err_mean_deg", "mean normal error (degrees)"),
            ("colour_rmse", "colour RMSE"), ("flip_mean", "mean FLIP"))):
        series(ax, key)
        axes(ax, label)
    grid.flat[0].legend()
    save(fig, "error_vs_tolerance.png")
    return paths


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


__all__ = ["sweep", "SweepRecord", "COLUMNS", "PLOTS", "LEVEL_COLOURS", "ProgressBar",
           "format_table", "level_image", "image_errors", "check_tolerances"]


class _CallableModule(types.ModuleType):
    """This module's type: calling the module calls :func:`sweep` (module comment)."""

    def __call__(self, *args, **kwargs):
        return sweep(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule
