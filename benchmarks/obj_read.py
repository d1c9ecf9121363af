"""Benchmark: reading one OBJ cage in a warm process (the byte scanner's kernel loaded).

    python benchmarks/obj_read.py CAGE.obj [--runs 3]

Reads a small model first (the scanner's kernel loaded from the cache), then ``CAGE.obj``
``--runs`` times, and prints each read's wall time and the process's peak resident set.
To compare two trees, run it with each tree's ``src`` on PYTHONPATH. A cage written with
repr() (``benchmarks/lazy.py`` writes the sword refined twice so) exercises the numbers the
scanner leaves to a correctly rounded conversion.
"""

from __future__ import annotations

import argparse
import os
import resource
import time

from _common import REPO, import_subtrace  # benchmarks/ is on sys.path when run as a script


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("cage")
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    import_subtrace()
    from subtrace.io.obj import read_obj

    read_obj(REPO / "models" / "sword_quad_dominant.obj")  # (the scanner large enough to run)
    times = []
    for _ in range(args.runs):
        t = time.perf_counter()
        data = read_obj(args.cage)
        times.append(time.perf_counter() - t)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"{os.path.basename(args.cage)}: {len(data.face_sizes)} faces, reads "
          + " / ".join(f"{x:.3f}" for x in times) + f" s, peak RSS {peak:.0f} MiB")


if __name__ == "__main__":
    main()
