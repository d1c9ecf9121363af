"""The Chinese paper's two line / surface experiments (docs/seeds.md section 1) with
subtrace.intersect_lines, on Catmull-Clark and on Loop cages: time per line (one thread;
batch throughput on 2 threads) and peak memory, at two precisions each to show memory does
not follow the precision; the first hit only against every hit; and the per-cage setup
(patch table, Bezier conversion, isolation) that a repeated call on the same cage skips.

1. One regular patch (ptex 0 quarter of a 14 x 14 torus) at the precision that takes our
   flatness-driven descent to level 10 (1024 x 1024 cells, ~1M vertices if stored); the same
   for one regular Loop patch of Spot (a quartic triangle, 4^10 triangles at level 10).
2. The 196-face torus (784 Catmull-Clark patches) at precision 0.001 (level 9 in the
   paper); Spot's 1654-triangle Loop cage at 0.001 (the model is about 1.5 units across).

Times are medians of ``--repeat`` runs of a batch of ``--lines`` lines on a cage whose setup
is already made (kept on the cage); "setup" is the first call on a fresh copy of the cage
minus a warm call (the patch table, Bezier nets and the isolation of the irregular patches
the lines' shells meet).

Run: python benchmarks/lines.py [--lines N] [--repeat R] [--spot PATH]
"""

from __future__ import annotations

import argparse
import resource
import time
from pathlib import Path

import numpy as np

import subtrace
from subtrace.lines.api import intersect_lines
from subtrace.runtime.threads import set_threads
from subtrace.shapes import torus_cage

SPOT = Path(__file__).resolve().parents[1] / "models" / "spot_low_resolution.obj"


def _rss_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _time(cage, org, dirs, prec, threads, repeat, t_range, mode="all"):
    set_threads(threads)
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        h = intersect_lines(cage, org, dirs, prec, t_range=t_range, mode=mode)
        ts.append(time.perf_counter() - t0)
    set_threads(None)
    return float(np.median(ts)), h


def _fresh(cage):
    """A copy of ``cage`` with nothing kept on it."""
    return subtrace.make_cage(cage.points, cage.face_sizes, cage.face_verts,
                              scheme=cage.scheme)


def _setup_seconds(cage, org, dirs, prec, t_range, repeat):
    """Median over ``repeat`` fresh copies of (first call - warm call), 2 threads."""
    out = []
    for _ in range(repeat):
        c = _fresh(cage)
        t0 = time.perf_counter()
        intersect_lines(c, org, dirs, prec, t_range=t_range)
        cold = time.perf_counter() - t0
        t0 = time.perf_counter()
        intersect_lines(c, org, dirs, prec, t_range=t_range)
        out.append(cold - (time.perf_counter() - t0))
    return float(np.median(out))


def _patch_lines(cage, ptex, uv, rng, n):
    """Lines through points ``uv`` of ptex face ``ptex``, near its normal."""
    P, du, dv = cage.evaluate(np.full(n, ptex, np.int64), uv)
    nrm = np.cross(du, dv)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    dirs = -(nrm + rng.normal(scale=0.3, size=(n, 3)))
    return P - 0.05 * dirs, dirs


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--lines", type=int, default=20000)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--spot", default=str(SPOT), help="Spot's low-resolution Loop cage")
    a = ap.parse_args()
    from subtrace.patches.boxspline import box_nets, loop_regular
    from subtrace.patches.basis import net_flatness, tri_flatness
    from subtrace.patches.table import build_patch_table

    torus = torus_cage()
    spot = subtrace.load_cage(a.spot) if Path(a.spot).exists() else None
    rng = np.random.default_rng(1)
    # warm up the compile
    intersect_lines(torus, [[-3, 0, 0]], [[1, 0, 0]], 1e-3)
    if spot is not None:
        intersect_lines(spot, [[-3, 0, 0]], [[1, 0, 0]], 1e-3, t_range=(-np.inf, np.inf))
    rows = []

    def run(name, cage, org, dirs, prec, tr, threads=(1, 2), mode="all"):
        for th in threads:
            sec, h = _time(cage, org, dirs, prec, th, a.repeat, tr, mode)
            rows.append((name, f"{prec:.3g}", mode, th, sec / len(org) * 1e6,
                         len(h) / len(org), _rss_mb()))

    # 1: lines through one patch near its normal, at the precision of level 10
    uv = np.c_[rng.uniform(0.02, 0.48, a.lines), rng.uniform(0.02, 0.48, a.lines)]
    org, dirs = _patch_lines(torus, 0, uv, rng, a.lines)
    tb = build_patch_table([torus])
    prec10 = 2 * net_flatness(tb.nets[:1].copy(), 0) / 4.0**10
    run("CC: one patch, level 10", torus, org, dirs, prec10, (0.0, 0.1))
    run("CC: one patch, 1e-3 of it", torus, org, dirs, prec10 * 1e-3, (0.0, 0.1))
    if spot is not None:
        faces = np.arange(spot.n_faces)
        f = int(faces[loop_regular(spot.base, spot.options, faces)][0])
        st = rng.uniform(0.02, 0.96, (a.lines, 2))
        st[st.sum(axis=1) > 0.98] *= 0.49
        org_l, dirs_l = _patch_lines(spot, f, st, rng, a.lines)
        net = box_nets(spot.base, spot.points, np.array([f]))
        lprec10 = 2 * tri_flatness(net, 0) / 4.0**10
        run("Loop: one Spot patch, level 10", spot, org_l, dirs_l, lprec10, (0.0, 0.1))
        run("Loop: one patch, 1e-3 of it", spot, org_l, dirs_l, lprec10 * 1e-3, (0.0, 0.1))
    # 2: random lines through the models' boxes
    whole = (-np.inf, np.inf)
    models = [("CC: 196-face torus", torus)] + ([("Loop: Spot, 1654 faces", spot)]
                                              if spot is not None else [])
    setups = []
    for name, cage in models:
        lo, hi = cage.bounds()
        org = rng.uniform(lo, hi, (a.lines, 3))
        dirs = rng.normal(size=(a.lines, 3))
        run(name, cage, org, dirs, 1e-3, whole)
        run(name, cage, org, dirs, 1e-9, whole)
        run(name, cage, org, dirs, 1e-3, whole, threads=(1,), mode="first")
        for n in (100, a.lines):
            setups.append((name, n, _setup_seconds(cage, org[:n], dirs[:n], 1e-3, whole,
                                                   a.repeat)))
    print(f"{a.lines} lines, median of {a.repeat} runs (setup kept on the cage); peak RSS "
          "of the process so far")
    print(f"{'experiment':32s} {'precision':>10s} {'mode':>5s} {'threads':>7s} "
          f"{'us/line':>9s} {'hits/line':>9s} {'peak MB':>8s}")
    for r in rows:
        print(f"{r[0]:32s} {r[1]:>10s} {r[2]:>5s} {r[3]:7d} {r[4]:9.2f} {r[5]:9.2f} "
              f"{r[6]:8.0f}")
    print("\nper-cage setup skipped by a repeated call (first call on a fresh cage minus a "
          "warm call, precision 1e-3, 2 threads)")
    for name, n, sec in setups:
        print(f"{name:32s} {n:6d} lines {sec * 1e3:9.1f} ms")


if __name__ == "__main__":
    main()
