"""Running a sweep: :func:`sweep` renders every scene at the reference tolerance and at each
swept one and measures each render (times, peak memory, refinement counts, image errors
against the reference; see :mod:`subtrace.sweep`); the checks of its inputs; the output
folder's EXRs and heat maps.

Importing the package loads numpy only: the scene reader and renderer (Numba), the image
comparison and the EXR writer (OpenImageIO) are imported by the functions that use them, so
``from subtrace.sweep import PeakMemory`` or ``format_table`` stays light.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import math
import os
import statistics
from dataclasses import replace

import numpy as np

from subtrace.errors import SceneError, SubtraceError
from subtrace.runtime.atomic import check_writable
from subtrace.sweep.plot import level_image, plot
from subtrace.sweep.report import SweepRecord, write_csv, write_json

REFERENCE_FACTOR = 4.0  # default reference tolerance: the finest swept one over this


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
    from subtrace.render import load_objects  # the kernels: once the options are checked

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
                _write_levels(os.path.join(output_dir, record.levels_png), result)
            records.append(record)
    if output_dir is not None:
        write_csv(records, os.path.join(output_dir, "sweep.csv"))
        write_json(records, os.path.join(output_dir, "sweep.json"))
        plot(records, output_dir)
    return records


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
    from subtrace.io.scene import Scene, load_scene, scene_for_meshes  # Numba (camera.py)

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


def _render(scene, tol_px: float, threads, accel):
    """Render ``scene`` at ``tol_px``; returns (RenderResult, peak memory in bytes or None)."""
    from subtrace.render import render_scene  # the kernels: once the inputs are checked

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
    from subtrace.compare import compare_images  # OpenImageIO

    c, r = result.channels, ref.channels
    z = np.asarray(c["Z"], np.float64)
    z_ref = np.asarray(r["Z"], np.float64)
    both = np.isfinite(z) & np.isfinite(z_ref)  # both centre rays hit (alpha is filtered)
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


def _write_exr(path, result, scene, tol_px) -> None:
    """The render's EXR with the header ``subtrace render`` writes (tolerance ``tol_px``)."""
    from subtrace.io.exr import write_exr  # OpenImageIO: only where a file is written
    from subtrace.render import result_attributes

    scene = replace(scene, render=replace(scene.render, tolerance_px=tol_px, tolerance_deg=None))
    write_exr(path, result.channels, result_attributes(result, scene))


def _write_levels(path, result) -> None:
    """The render's refinement-level heat map (:func:`subtrace.sweep.plot.level_image`)."""
    from subtrace.io.exr import write_png  # OpenImageIO: only where a file is written

    write_png(path, level_image(result.channels["level"]))
