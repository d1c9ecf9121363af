"""The Chinese paper's two line / surface experiments (docs/seeds.md section 1) with
subtrace.intersect_lines: time per line (one thread; batch throughput on 2 threads) and peak
memory, at two precisions each to show memory does not follow the precision.

1. One regular patch (ptex 0 quarter of a 14 x 14 torus) at the precision that takes our
   flatness-driven descent to level 10 (1024 x 1024 cells, ~1M vertices if stored).
2. The 196-face torus (784 Catmull-Clark patches) at precision 0.001 (level 9 in the paper).

Run: python benchmarks/lines.py [--lines N] [--repeat R]
"""

from __future__ import annotations

import argparse
import resource
import time

import numpy as np

from subtrace.lines import intersect_lines, torus_cage
from subtrace.tasks import set_threads


def _rss_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _time(cage, org, dirs, prec, threads, repeat, t_range):
    set_threads(threads)
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        h = intersect_lines(cage, org, dirs, prec, t_range=t_range)
        ts.append(time.perf_counter() - t0)
    set_threads(None)
    return float(np.median(ts)), h


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--lines", type=int, default=20000)
    ap.add_argument("--repeat", type=int, default=5)
    a = ap.parse_args()
    cage = torus_cage()
    rng = np.random.default_rng(1)
    # warm up the compile
    intersect_lines(cage, [[-3, 0, 0]], [[1, 0, 0]], 1e-3)
    rows = []
    # 1: lines through one patch (the patch of ptex 0 around uv (0.25, 0.25)) near its normal
    uv = np.c_[rng.uniform(0.02, 0.48, a.lines), rng.uniform(0.02, 0.48, a.lines)]
    P, du, dv = cage.evaluate(np.zeros(a.lines, np.int64), uv)
    n = np.cross(du, dv)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    tilt = rng.normal(scale=0.3, size=(a.lines, 3))
    dirs = -(n + tilt)
    org = P - 0.05 * dirs
    # precision at which the descent reaches level 10: the patch net's flatness / 4^10
    from subtrace.patches.table import build_patch_table
    from subtrace.trace.lines import net_flatness

    tb = build_patch_table([cage])
    flat0 = net_flatness(tb.nets[:1].copy(), 0)
    prec10 = 2 * flat0 / 4.0**10
    for name, prec, tr in (("one patch, level 10", prec10, (0.0, 0.1)),
                           ("one patch, 1e-3 of the above", prec10 * 1e-3, (0.0, 0.1))):
        for th in (1, 2):
            sec, h = _time(cage, org, dirs, prec, th, a.repeat, tr)
            rows.append((name, f"{prec:.3g}", th, sec / a.lines * 1e6, len(h) / a.lines,
                         _rss_mb()))
    # 2: random lines through the torus' box
    lo, hi = cage.bounds()
    org = rng.uniform(lo, hi, (a.lines, 3))
    dirs = rng.normal(size=(a.lines, 3))
    for name, prec in (("196-face torus", 1e-3), ("196-face torus", 1e-9)):
        for th in (1, 2):
            sec, h = _time(cage, org, dirs, prec, th, a.repeat, (-np.inf, np.inf))
            rows.append((name, f"{prec:.3g}", th, sec / a.lines * 1e6, len(h) / a.lines,
                         _rss_mb()))
    print(f"{a.lines} lines, median of {a.repeat} runs; peak RSS of the process so far")
    print(f"{'experiment':32s} {'precision':>10s} {'threads':>7s} {'us/line':>9s} "
          f"{'hits/line':>9s} {'peak MB':>8s}")
    for r in rows:
        print(f"{r[0]:32s} {r[1]:>10s} {r[2]:7d} {r[3]:9.2f} {r[4]:9.2f} {r[5]:8.0f}")


if __name__ == "__main__":
    main()
