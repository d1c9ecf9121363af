"""Angular-tolerance sweeps: what each tolerance costs (time, memory, refinement) and what it
buys (image error against a reference render at a much finer tolerance).

:func:`sweep` renders every scene first at the reference tolerance, then at each swept
tolerance (coarse to fine, ``repeat`` times each), and returns one :class:`SweepRecord` per
(scene, tolerance). With an output folder it also writes, per scene, the EXR of every
tolerance and of the reference and a refinement-level heat map PNG per tolerance
(``<dir>/<scene>/tol_<T>.exr``, ``tol_<T>_levels.png``, ``reference.exr``), and for the
whole sweep ``sweep.csv``, ``sweep.json`` and three log-log plots (:data:`PLOTS`).

Measurements (the columns are :data:`COLUMNS`, documented in
docs/guide/compare-sweep-intersect.md):
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

``subtrace.sweep`` is this package (a package's submodule is its attribute once imported), so
the package is callable: ``subtrace.sweep(...)`` is ``subtrace.sweep.sweep(...)``.

The work is split: :mod:`subtrace.sweep.run` (the sweep, its input checks and measurements),
:mod:`subtrace.sweep.report` (records, table, CSV, JSON), :mod:`subtrace.sweep.plot` (heat
maps and plots); this package re-exports their public names.
"""

from __future__ import annotations

import sys
import types

from subtrace.runtime.progress import ProgressBar
from subtrace.sweep.plot import LEVEL_COLOURS, PLOTS, level_image
# the function plot() replaces the submodule subtrace.sweep.plot as this package's attribute
# (importing a submodule sets it; the name bound here comes after): subtrace.sweep.plot(...)
# stays the function it was before the split
from subtrace.sweep.plot import plot
from subtrace.sweep.report import COLUMNS, SweepRecord, format_table, write_csv, write_json
from subtrace.sweep.run import (REFERENCE_FACTOR, PeakMemory, check_reference, check_repeat,
                                check_tolerances, image_errors, prepare_output_dir, sweep)

__all__ = ["sweep", "SweepRecord", "COLUMNS", "PLOTS", "LEVEL_COLOURS", "ProgressBar",
           "format_table", "level_image", "image_errors", "check_tolerances"]


class _CallableModule(types.ModuleType):
    """This package's type: calling the package calls :func:`sweep` (module comment)."""

    def __call__(self, *args, **kwargs):
        return sweep(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule
