"""A render's memory budget: whether it fits at all, the depth choice within it, and the one
warning for each way the budget changes a render (refinement capped; the BVH instead of the
projection's tile lists). The estimates are the depth criterion's (``config.MEMORY_*``)."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from subtrace import config
from subtrace.errors import SceneError, SubtraceWarning
from subtrace.patches.boxspline import loop_regular
from subtrace.patches.criterion import (choose_depths, depth_cap, memory_estimate,
                                        precision_depths, wanted_depths)
from subtrace.patches.isolate import IsolationTooLarge
from subtrace.runtime import threads as tasks
from subtrace.subdiv.topology import compact


def mib(n: int) -> str:
    """``n`` bytes for a message: MiB, or GiB from 10 GiB."""
    return f"{n / 2**30:.1f} GiB" if n >= 10 * 2**30 else f"{n / 2**20:.0f} MiB"


def warn_capped(budget, cap, depths, estimate):
    """The one warning of a render whose refinement the memory budget capped (and nothing
    else: :func:`warn_depth_cap` says it with the other caps)."""
    warn_depth_cap(("memory",), cap, depths.max(initial=0), budget, estimate, stacklevel=4)


def warn_depth_cap(reasons, cap, wanted, budget=None, estimate=None, stacklevel=3):
    """The one warning of a render whose refinement depth was capped: ``reasons`` among
    "memory" (the budget ``budget``, the uncapped depths' estimate ``estimate`` bytes),
    "isolation" (an isolation's frontier would pass half of ``budget``:
    ``config.MEMORY_BYTES_PER_ISOLATION_FACE``),
    "size" (isolated Loop patches, ``config.LOOP_MAX_ISOLATED_DEPTH``), "depth" (the caller's
    explicit cap) and "precision"
    (``config.PRECISION_BITS``); ``cap`` the deepest depth a capped patch was held to,
    ``wanted`` the deepest the tolerance asked for (inf: unbounded, the eye in a shell)."""
    need = "no finite depth (the eye is inside a shell)" if not np.isfinite(wanted) else (
        f"depth {int(wanted)}")
    parts = []
    if "memory" in reasons:
        parts.append(f"memory budget {mib(budget)}: refinement capped at depth {max(cap, 0)} "
                     f"below the patches (the tolerance needs {need}, an estimated "
                     f"{mib(estimate)}), so the image is coarser than the tolerance; raise "
                     "--max-memory (or [render] max_memory in the scene) to refine fully")
    if "isolation" in reasons:
        parts.append(f"refinement capped at depth {max(cap, 0)}: isolating a feature that "
                     "no level makes regular along an edge (a non-manifold edge) doubles its "
                     "pieces at every level, and the next level would pass "
                     f"{config.ISOLATION_FACES_PER_PATCH_LEVEL} faces per irregular patch "
                     "and level, or half the memory budget "
                     f"{mib(budget)} (the tolerance needs {need}), so the image is coarser "
                     "than the tolerance there")
    if "size" in reasons:
        parts.append(f"Loop patches capped at depth {config.LOOP_MAX_ISOLATED_DEPTH} where "
                     "isolated (the exact samples of their sides grow as 2^depth) and at "
                     f"{config.LOOP_MAX_INSIDE_DEPTH} where the eye is inside their shells, so "
                     "the image is coarser there than the tolerance")
    if "depth" in reasons:
        parts.append(f"refinement capped at depth {max(cap, 0)} by the caller's maximum "
                     f"depth (the tolerance needs {need}), so the image is coarser than the "
                     "tolerance")
    if "precision" in reasons:
        parts.append(f"refinement capped at depth {max(cap, 0)} where cells would fall "
                     f"below 2^-{config.PRECISION_BITS} of the coordinates, what double "
                     f"precision resolves (the tolerance needs {need}), so the image is "
                     "coarser there than the tolerance; raise the tolerance")
    warnings.warn(SubtraceWarning("; ".join(parts)), stacklevel=stacklevel)


def warn_tiles(budget):
    """The one warning of a render whose tile lists the memory budget refused."""
    warnings.warn(SubtraceWarning(
        f"memory budget {mib(budget)}: the projection's tile lists would not fit (many "
        "shells reach the eye plane, e.g. with the eye inside a model), so rays walk the "
        "shells' BVH instead (same image, slower); raise --max-memory to project"),
        stacklevel=3)


def isolated_patches(table) -> np.ndarray:
    """(P,) bool: the patches isolated level by level when a ray reaches them (priced per
    level by the memory estimate): the irregular Catmull-Clark quads and the irregular Loop
    triangles (``patches/isolate_loop.py``); the regular ones are Bezier nets split per ray
    (``trace/build.py``)."""
    iso = table.is_quad & ~table.regular
    for oid, o in enumerate(table.objects):
        if o.cage.scheme == "loop":
            rows = np.nonzero(table.object_id == oid)[0]
            iso[rows] = ~loop_regular(o.level, o.cage.options, table.face[rows])
    return iso


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
    (``record``, reused when the patches are built), the (tightened) shells, the bytes
    of the memory budget left for the tile lists and the memos (None: no budget), and which
    patches are isolated level by level (:func:`isolated_patches`)."""

    depths: np.ndarray
    record: dict
    shell_min: np.ndarray
    shell_max: np.ndarray
    left: int | None
    isolated: np.ndarray


def depth_limits(table, eye, max_depth=None, isolated=None, wanted=None):
    """(P,) int32 deepest depth of each patch and (P,) the reason code of each limit: 0
    floating point (:func:`~subtrace.patches.criterion.precision_depths`), 1 a Loop
    patch's size: an isolated one's side samples (``config.LOOP_MAX_ISOLATED_DEPTH``;
    ``isolated``: the patches of :func:`isolated_patches`) or one whose shell holds the eye
    (``config.LOOP_MAX_INSIDE_DEPTH``; ``wanted``: the tolerance's depths, inf there), 2
    the caller's ``max_depth`` (None: none)."""
    limit = precision_depths(table, eye)
    why = np.zeros(table.n_patches, np.int8)
    for rows, cap in ((isolated, config.LOOP_MAX_ISOLATED_DEPTH),
                      (None if wanted is None else ~np.isfinite(wanted),
                       config.LOOP_MAX_INSIDE_DEPTH)):
        if rows is not None:
            big = rows & ~table.is_quad & (limit > cap)
            limit[big] = cap
            why[big] = 1
    if max_depth is not None:
        low = limit > max_depth
        limit[low] = max_depth
        why[low] = 2
    return limit, why


LIMIT_REASONS = ("precision", "size", "depth", "isolation")
ISOLATION_REASON = 3  # an isolation's frontier would pass its share of the memory budget


def _reasons(codes) -> list:
    """The distinct ``LIMIT_REASONS`` of ``codes`` (indices into it), in its order
    (``topology.compact``: np.unique would import numpy.ma, about 5 ms of a render)."""
    return [LIMIT_REASONS[k] for k in compact(codes, len(LIMIT_REASONS))[0]]


def choose_within_budget(table, eye, tol_rad, max_depth, max_memory, n_pixels,
                         stats) -> DepthChoice:
    """Each patch's grid depth (isolating irregular patches, which also tightens their
    shells), within what floating point resolves (:func:`depth_limits`; ``max_depth``: an
    explicit cap, None for none) and capped where the memory budget ``max_memory`` asks.
    Any cap that holds a patch below what its tolerance asks is recorded in ``stats``
    (``depth_cap``: the deepest depth a capped patch was held to, ``depth_cap_reason``) and
    said in one warning."""

    # the isolations may take half the budget (config.MEMORY_BYTES_PER_ISOLATION_FACE)
    budget = config.default_max_memory() if max_memory is None else max_memory
    max_faces = budget // (2 * config.MEMORY_BYTES_PER_ISOLATION_FACE)

    def choose(cap):
        """The depths within ``cap`` (lowered in place, to one depth for all, where an
        isolation would pass ``max_faces``) and what their isolation made."""
        while True:
            record = {}
            shells = table.ray_min.copy(), table.ray_max.copy()
            try:
                return (choose_depths(table, eye, tol_rad, cap, record, shells, max_faces,
                                      wanted), record, shells)
            except IsolationTooLarge as err:  # (one cap for all: neighbours raise depths)
                low = cap > err.level
                cap[low] = err.level
                why[low] = ISOLATION_REASON

    isolated = isolated_patches(table)
    wanted = wanted_depths(table, eye, tol_rad)
    limit, why = depth_limits(table, eye, max_depth, isolated, wanted)
    depths, record, (shell_min, shell_max) = choose(limit)
    # held below the tolerance's depth (an isolated patch at its limit counts as held)
    held = (wanted > limit) & (depths >= limit)
    reasons = _reasons(why[held])
    left = None
    budget_cap = estimate = None
    if max_memory is not None:
        left = max_memory - config.MEMORY_MEMO_MIN_BYTES * tasks.thread_count()
        budget_cap = depth_cap(table, depths, n_pixels, left, isolated)
        if budget_cap is not None:  # (the estimate said: with the memos' minimum)
            estimate = memory_estimate(table, depths, n_pixels, isolated) + max_memory - left
            by_memory = limit > max(budget_cap, 0)
            limit = np.minimum(limit, max(budget_cap, 0))
            depths, record, (shell_min, shell_max) = choose(limit)
            held = (wanted > limit) & (depths >= limit)
            reasons = sorted(set((["memory"] if (held & by_memory).any() else [])
                                 + _reasons(why[held & ~by_memory])),
                             key=(("memory",) + LIMIT_REASONS).index)
        left = max(left - memory_estimate(table, depths, n_pixels, isolated), 0)
    if held.any():
        stats.depth_cap = int(depths[held].max())
        stats.depth_cap_reason = ",".join(reasons)
        warn_depth_cap(reasons, stats.depth_cap, wanted[held].max(), budget, estimate)
    return DepthChoice(depths, record, shell_min, shell_max, left, isolated)
