"""Benchmark: the trim test, the kd-tree (nurbs/trimtree.py) against the naive parity test
over all curve units, for trim loops of 10, 100, 1,000 and 10,000 monotone units.

    python benchmarks/trim.py [--units 10 100 1000 10000] [--queries 100000] [--repeat 5]
                              [--patent-stops] [--renders [--only-renders]]

The loop: a wavy closed curve (a "flower" r = 0.35 (1 + 0.25 sin(k theta)) around (0.5, 0.5),
k lobes) made of Hermite cubic segments, their number chosen so that the loop has exactly
the stated number of monotone units (a segment holding an extremum of u or v is two or
three units). Queries: points uniform in the loop's box grown by 10 % ("uniform"), and
points within 1e-3 of the curve ("near": the hard case, where unit boxes straddle the
point and the exact bisection runs). Both methods classify the same points with the same
unit test (nurbs/trimtree.py: crosses) on one thread; the naive test visits every unit.
Each round times both methods once, alternating which goes first; figures are the medians
over ``repeat`` rounds of the time per query (the naive test gets fewer points on long
loops to keep rounds short). One warm-up call of each kernel comes first (compilation and
Numba's cache are outside the timings). ``--patent-stops`` adds rows with the patent's leaf
stops (relative area 0.0006, relative side 0.025) in place of the leaf size alone.

``--renders`` adds the render times of the NURBS sample scenes (``scenes/nurbs_*.toml``) at
1280x720 and 1 px (their own settings): one warm-up render of each at 160x90 first (kernels
compiled or loaded), then ``repeat`` renders per scene on all threads, scenes in turn; the
medians of the total, CPU (all threads; on a shared machine steadier than the wall time)
and trace times (``--threads``: how many threads render), the rays per second of the trace, the pixels covered
and the deepest level. ``--only-renders`` skips the trim table.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

import numpy as np

from _common import REPO, import_subtrace


def flower(n: int, lobes: int, amp: float = 0.25):
    """A closed loop of n Hermite cubic segments on the flower curve."""
    from subtrace.nurbs.trim import TrimLoop

    th = np.linspace(0, 2 * np.pi, n, endpoint=False)
    r = 0.35 * (1 + amp * np.sin(lobes * th))
    dr = 0.35 * amp * lobes * np.cos(lobes * th)
    P = np.column_stack([0.5 + r * np.cos(th), 0.5 + r * np.sin(th)])
    D = np.column_stack([dr * np.cos(th) - r * np.sin(th), dr * np.sin(th) + r * np.cos(th)])
    h = 2 * np.pi / n / 3
    nxt = np.roll(np.arange(n), -1)
    ctrl = np.stack([P, P + h * D, P[nxt] - h * D[nxt], P[nxt]], axis=1)
    segs = tuple(np.concatenate([c, np.ones((4, 1))], axis=1) for c in ctrl)
    return TrimLoop(False, segs, P.copy())


def loop_of_units(target: int):
    """(loop, units) whose monotone units number exactly ``target`` (or the closest found):
    the flower of the fewest lobes (3 to 7, more on long loops) that gets there."""
    from subtrace.nurbs.trim import monotone_units

    best = None
    for lobes in ((3, 4, 5, 2) if target < 200 else (7, 6, 5)):
        n = max(target // 2, 3)
        for _ in range(30):
            loop = flower(n, lobes)
            units = monotone_units([loop])
            if best is None or abs(len(units) - target) < abs(len(best[1]) - target):
                best = (loop, units)
            if len(units) == target:
                return best
            step = (target - len(units)) // 2 or (1 if target > len(units) else -1)
            n = max(3, n + step)
    return best


def near_points(units, count, rng, distance=1e-3):
    """Points within ``distance`` of the loop: curve points moved by up to that much."""
    from subtrace.nurbs.trim import bezier_points, project

    pick = rng.integers(0, len(units), count)
    t = rng.random(count)
    pts = np.empty((count, 2))
    for k in range(count):
        i = pick[k]
        ctrl = units.ctrl[i, : units.degree[i] + 1]
        pts[k] = project(bezier_points(ctrl, t[k : k + 1]))[0]
    return pts + rng.uniform(-distance, distance, (count, 2))


def time_per_query(fn, points) -> float:
    t0 = time.perf_counter()
    fn(points)
    return (time.perf_counter() - t0) / len(points)


def bench(target, queries, repeat, rng, stops):
    from subtrace.nurbs.trimtree import build_tree, classify_naive

    loop, units = loop_of_units(target)
    t0 = time.perf_counter()
    tree = build_tree(units, *stops)
    build = time.perf_counter() - t0
    lo = np.minimum(units.p0, units.p1).min(axis=0)
    hi = np.maximum(units.p0, units.p1).max(axis=0)
    grow = 0.1 * (hi - lo)
    sets = {"uniform": rng.uniform(lo - grow, hi + grow, (queries, 2)),
            "near": near_points(units, queries, rng)}
    naive_count = max(200, min(queries, int(2e7 / max(len(units), 1))))
    out = {}
    for name, pts in sets.items():
        # warm-up, and the two methods agree on every point the naive test classifies
        assert np.array_equal(tree.classify(pts[:naive_count]),
                              classify_naive(units, pts[:naive_count])), name
        kd, nv = [], []
        for r in range(repeat):
            pair = [("kd", lambda: time_per_query(tree.classify, pts)),
                    ("naive", lambda: time_per_query(lambda p: classify_naive(units, p),
                                                     pts[:naive_count]))]
            for label, run in (pair if r % 2 == 0 else pair[::-1]):
                (kd if label == "kd" else nv).append(run())
        out[name] = (statistics.median(kd), statistics.median(nv))
    leaves = tree.node_axis < 0
    stats = dict(units=len(units), segments=len(loop.segments), tree_units=len(tree.units),
                 nodes=len(tree.node_axis),
                 empty=int(np.count_nonzero(leaves & (tree.node_count == 0))),
                 full=int(np.count_nonzero(leaves & (tree.node_count > 0))), depth=tree.depth,
                 max_leaf=int(tree.node_count.max()), build=build)
    return stats, out


def render_rows(repeat: int, threads=None) -> None:
    """Print the render-time table of the NURBS sample scenes (module comment) on
    ``threads`` threads (None: all cores)."""
    from subtrace.io.scene import apply_overrides, load_scene
    from subtrace.render import render_scene
    from subtrace.runtime.threads import thread_count

    scenes = sorted((REPO / "scenes").glob("nurbs_*.toml"))
    for path in scenes:
        render_scene(apply_overrides(load_scene(path), width=160, height=90), threads=threads)
    times = {p.stem: [] for p in scenes}
    for _ in range(repeat):
        for path in scenes:
            scene = apply_overrides(load_scene(path), width=1280, height=720)
            t0, c0 = time.perf_counter(), time.process_time()
            result = render_scene(scene, threads=threads)
            times[path.stem].append((time.perf_counter() - t0, time.process_time() - c0,
                                     result.stats))
    print(f"\nNURBS sample scenes at 1280x720, 1 px, {thread_count()} threads "
          f"(medians of {repeat} renders)")
    header = ("| scene | patches | total s | CPU s | trace s | rays/s (trace) | pixels covered | "
              "deepest level |")
    print(header)
    print("|---" * (header.count("|") - 1) + "|")
    for name, runs in times.items():
        total = statistics.median(t for t, _, _ in runs)
        cpu = statistics.median(c for _, c, _ in runs)
        trace = statistics.median(st.time_trace for _, _, st in runs)
        st = runs[0][2]
        print(f"| {name} | {st.patches:,} | {total:.2f} | {cpu:.2f} | {trace:.2f} | "
              f"{st.rays / trace:,.0f} | {st.pixels_covered:,} | {st.max_level} |", flush=True)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--units", type=int, nargs="+", default=[10, 100, 1000, 10000])
    parser.add_argument("--queries", type=int, default=100000)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--patent-stops", action="store_true")
    parser.add_argument("--renders", action="store_true")
    parser.add_argument("--only-renders", action="store_true")
    parser.add_argument("--threads", type=int, default=None, help="render threads")
    args = parser.parse_args(argv)
    import_subtrace()
    if args.only_renders:
        render_rows(args.repeat, args.threads)
        return 0
    from subtrace.config import TRIM_LEAF_UNITS, TRIM_MIN_AREA, TRIM_MIN_SIDE

    variants = [("leaf size", (TRIM_MIN_AREA, TRIM_MIN_SIDE))]
    if args.patent_stops:
        variants.append(("patent stops", (0.0006, 0.025)))
    rng = np.random.default_rng(2026)
    from subtrace.nurbs.trim import monotone_units
    from subtrace.nurbs.trimtree import build_tree, classify_naive

    warm = monotone_units([flower(8, 3)])  # load (or compile) every kernel before timing
    build_tree(warm).classify(np.zeros((1, 2)))
    classify_naive(warm, np.zeros((1, 2)))
    print(f"trim test, time per query (medians of {args.repeat} alternated rounds; "
          f"{args.queries} queries per round; leaf size {TRIM_LEAF_UNITS})")
    header = ("| tree | units | segments | kd units | nodes | empty / full leaves | depth | "
              "max leaf | build s | uniform kd ns | uniform naive ns | speed-up | near kd ns "
              "| near naive ns | speed-up |")
    print(header)
    print("|---" * (header.count("|") - 1) + "|")
    for label, stops in variants:
        for target in args.units:
            st, t = bench(target, args.queries, args.repeat, rng, stops)
            (uk, un), (nk, nn) = t["uniform"], t["near"]
            print(f"| {label} | {st['units']:,} | {st['segments']:,} | {st['tree_units']:,} | "
                  f"{st['nodes']:,} | {st['empty']:,} / {st['full']:,} | {st['depth']} | "
                  f"{st['max_leaf']} | {st['build']:.3f} | {uk * 1e9:.0f} | {un * 1e9:,.0f} | "
                  f"{un / uk:,.0f}x | {nk * 1e9:.0f} | {nn * 1e9:,.0f} | {nn / nk:,.0f}x |",
                  flush=True)
    if args.renders:
        render_rows(args.repeat, args.threads)
    return 0


if __name__ == "__main__":
    sys.exit(main())
