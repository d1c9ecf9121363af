"""A render's memory budget: whether it fits at all, the depth choice within it, and the one
warning for each way the budget changes a render (refinement capped; the BVH instead of the
projection's tile lists). The estimates are the depth criterion's (``config.MEMORY_*``)."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from subtrace import config
from subtrace.errors import SceneError, SubtraceWarning
from subtrace.patches.criterion import choose_depths, depth_cap, memory_estimate
from subtrace.runtime import threads as tasks


def mib(n: int) -> str:
    """``n`` bytes for a message: MiB, or GiB from 10 GiB."""
    return f"{n / 2**30:.1f} GiB" if n >= 10 * 2**30 else f"{n / 2**20:.0f} MiB"


def warn_capped(budget, cap, depths, estimate):
    """The one warning of a render whose refinement the memory budget capped."""
    warnings.warn(SubtraceWarning(
        f"memory budget {mib(budget)}: refinement capped at depth {max(cap, 0)} below the "
        f"patches (the tolerance needs depth {int(depths.max(initial=0))}, an estimated "
        f"{mib(estimate)}), so the image is coarser than the tolerance; raise --max-memory "
        "(or [render] max_memory in the scene) to refine fully"), stacklevel=3)


def warn_tiles(budget):
    """The one warning of a render whose tile lists the memory budget refused."""
    warnings.warn(SubtraceWarning(
        f"memory budget {mib(budget)}: the projection's tile lists would not fit (many "
        "shells reach the eye plane, e.g. with the eye inside a model), so rays walk the "
        "shells' BVH instead (same image, slower); raise --max-memory to project"),
        stacklevel=3)


def check_memory(table, n_pixels: int, budget: int, width: int, height: int):
    """Raise SceneError when even unrefined patches (depth 0) would not fit ``budget``."""
    need = (memory_estimate(table, np.zeros(table.n_patches, np.int32), n_pixels)
            + config.MEMORY_MEMO_MIN_BYTES * tasks.thread_count())
    if need > budget:
        raise SceneError(
            f"a {width}x{height} render of {table.n_patches} patches needs at least "
            f"{mib(need)} ({config.MEMORY_BYTES_PER_PIXEL} bytes per pixel, "
            f"{config.MEMORY_BYTES_PER_PATCH} per patch) but the "
            f"memory budget is {mib(budget)}: lower the resolution or raise --max-memory "
            "(or [render] max_memory in the scene)")


@dataclass
class DepthChoice:
    """The depth choice of a render: per patch grid depth, what the choice's isolation made
    (``record``, reused when the patches are built), the (tightened) shells, and the bytes
    of the memory budget left for the tile lists and the memos (None: no budget)."""

    depths: np.ndarray
    record: dict
    shell_min: np.ndarray
    shell_max: np.ndarray
    left: int | None


def choose_within_budget(table, eye, tol_rad, max_depth, max_memory, n_pixels,
                         stats) -> DepthChoice:
    """Each patch's grid depth (isolating irregular patches, which also tightens their
    shells), capped with a warning where the memory budget ``max_memory`` asks."""

    def choose(cap):
        record = {}
        shells = table.shell_min.copy(), table.shell_max.copy()
        return choose_depths(table, eye, tol_rad, cap, record, shells), record, shells

    depths, record, (shell_min, shell_max) = choose(max_depth)
    left = None
    if max_memory is not None:
        left = max_memory - config.MEMORY_MEMO_MIN_BYTES * tasks.thread_count()
        cap = depth_cap(table, depths, n_pixels, left)
        if cap is not None:
            warn_capped(max_memory, cap, depths, memory_estimate(table, depths, n_pixels))
            depths, record, (shell_min, shell_max) = choose(max(cap, 0))
            stats.depth_cap = max(cap, 0)
        left = max(left - memory_estimate(table, depths, n_pixels), 0)
    return DepthChoice(depths, record, shell_min, shell_max, left)
