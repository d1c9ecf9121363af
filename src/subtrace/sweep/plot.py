"""The pictures of a sweep: the refinement-level heat map of a render
(:func:`level_image`) and the log-log plots written beside sweep.csv (:func:`plot`,
matplotlib with the Agg back end, imported only when plotting: it takes about half a second).
"""

from __future__ import annotations

import os

import numpy as np

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


def level_image(level) -> np.ndarray:
    """(H,W) refinement levels (-1: no surface) -> (H,W,3) linear RGB: LEVEL_COLOURS[level]
    (deeper levels the last colour), black where there is no surface."""
    srgb = np.array([[int(h[k:k + 2], 16) / 255.0 for k in (1, 3, 5)] for h in LEVEL_COLOURS])
    linear = np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)
    lev = np.asarray(level)
    rgb = linear[np.clip(lev, 0, len(linear) - 1).astype(np.intp)]
    rgb[lev < 0] = 0.0
    return rgb


def plot(records, output_dir) -> list[str]:
    """Write :data:`PLOTS` (matplotlib, Agg) into ``output_dir``; returns their paths.
    Non-positive values (an error of exactly 0) are left out of the log axes."""
    import matplotlib  # heavy: only here (module comment)

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
