"""Benchmark: how fast and how cleanly ``subtrace`` stops on SIGINT / SIGTERM.

    python benchmarks/interrupts.py [--trials 200] [--seed 1] [--width 320 --height 180]

Runs render (EXR; EXR + PNG) and sweep commands over complete earlier outputs and signals
each at a random moment of its run (uniform over the time a full run takes once subtrace's
own code is in control, plus 10 %), like ``tests/test_interrupts.py`` but for longer.
Prints, per command: trials, how many were stopped / had finished, the time from the signal
to the process's end (median, 95th percentile, max), and the failures: a wrong exit code,
anything on stderr but the one line, a temporary left behind, an earlier output damaged.
"""

from __future__ import annotations

import argparse
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CODES = {signal.SIGINT: 130, signal.SIGTERM: 143}


def start(args):
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT / "src") + os.pathsep + env.get("PYTHONPATH", "")
    return subprocess.Popen([sys.executable, "-m", "subtrace.cli", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)


def wait_watched(proc):
    """Until the process's main thread blocks SIGINT (its watcher thread has it)."""
    status = Path(f"/proc/{proc.pid}/status")
    while proc.poll() is None:
        try:
            line = next(x for x in status.read_text().splitlines() if x.startswith("SigBlk:"))
        except (OSError, StopIteration):
            return
        if int(line.split()[1], 16) & (1 << (signal.SIGINT - 1)):
            return
        time.sleep(0.002)


def commands(folder: Path, size):
    scene = str(ROOT / "scenes" / "spot.toml")
    exr = folder / "out.exr"
    return {
        "render": (["render", scene, "-o", str(exr), *size], [exr]),
        "render+png": (["render", scene, "-o", str(exr), "--png", *size],
                       [exr, exr.with_suffix(".png")]),
        "sweep": (["sweep", scene, "--tolerances", "4", "-o", str(folder / "sw"), *size],
                  [folder / "sw" / "sweep.csv", folder / "sw" / "sweep.json"]),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=180)
    args = ap.parse_args()
    size = ["--width", str(args.width), "--height", str(args.height), "--threads", "2"]
    rng = random.Random(args.seed)
    base = Path(tempfile.mkdtemp(prefix="subtrace-interrupts-"))
    try:
        ref = {}
        for name, (cmd, files) in commands(base / "ref", size).items():
            (base / "ref").mkdir(exist_ok=True)
            proc = start(cmd)
            wait_watched(proc)
            t0 = time.perf_counter()
            if proc.wait() != 0:
                sys.exit(f"{name}: the full run failed: {proc.stderr.read().decode()}")
            ref[name] = (time.perf_counter() - t0, {f.relative_to(base / "ref"): f.read_bytes()
                                                     for f in files})
        rows = {name: {"stopped": 0, "finished": 0, "waits": [], "failures": []} for name in ref}
        for trial in range(args.trials):
            name = list(ref)[trial % len(ref)]
            duration, files = ref[name]
            folder = base / f"t{trial}"
            for rel, data in files.items():
                (folder / rel).parent.mkdir(parents=True, exist_ok=True)
                (folder / rel).write_bytes(data)
            cmd, _ = commands(folder, size)[name]
            sig = rng.choice(list(CODES))
            proc = start(cmd)
            wait_watched(proc)
            time.sleep(rng.uniform(0.0, 1.1 * duration))
            sent = time.perf_counter()
            proc.send_signal(sig)
            _, err = proc.communicate()
            row = rows[name]
            if proc.returncode == 0:
                row["finished"] += 1
            else:
                row["stopped"] += 1
                row["waits"].append(time.perf_counter() - sent)
                if proc.returncode != CODES[sig] or err != b"subtrace: interrupted\n":
                    row["failures"].append(f"trial {trial}: exit {proc.returncode}, {err[-200:]!r}")
            left = [p.name for p in folder.rglob("*.tmp")]
            if left:
                row["failures"].append(f"trial {trial}: left {left}")
            for rel in files:
                if not (folder / rel).exists() or (folder / rel).stat().st_size == 0:
                    row["failures"].append(f"trial {trial}: {rel} damaged")
            shutil.rmtree(folder, ignore_errors=True)
        print(f"{args.trials} trials, seed {args.seed}, {args.width}x{args.height}")
        print("| command | full run s | trials | stopped | finished | stop median s | p95 | max | failures |")
        print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
        for name, row in rows.items():
            w = np.array(row["waits"]) if row["waits"] else np.zeros(1)
            n = row["stopped"] + row["finished"]
            print(f"| {name} | {ref[name][0]:.2f} | {n} | {row['stopped']} | {row['finished']} | "
                  f"{np.median(w):.3f} | {np.percentile(w, 95):.3f} | {w.max():.3f} | "
                  f"{len(row['failures'])} |")
        for row in rows.values():
            for line in row["failures"]:
                print("  " + line)
    finally:
        shutil.rmtree(base, ignore_errors=True)


if __name__ == "__main__":
    main()
