"""A/B: one change measured against a base, side by side, with its images checked.

    python benchmarks/ab.py [--base REV] [--rounds 5] [--threads 2] [--picture] SCENE.toml ...
                            [-- extra render options]

*A* is the commit ``--base`` (default ``HEAD``) checked out into a temporary git worktree;
*B* is this checkout as it stands, uncommitted edits included. Each side has its own
Numba cache (``~/.cache/subtrace-benchmarks/ab/<tree>``: a source edit changes the cache key, so the
two sides would otherwise evict each other's kernels), filled by one untimed render of
every scene. Then ``--rounds`` rounds render every scene with both sides, in the order AB
in even rounds and BA in odd ones (the machine's speed drifts within minutes: alternating
spreads the drift over both), each a fresh ``subtrace render`` process.

The table gives the medians per scene of the process's wall time, its peak RSS
(``os.wait4``), the renderer's own timings (``subtrace:time_*`` in the EXR header), the
micro-triangles and the memo's bytes, and B / A. The last column says whether B's image
is A's bit for bit (every channel, NaNs equal): ``same``, or the channels that differ
with their count of differing pixels and largest difference. A speed change should leave
the images the same; a change that moves them needs its own reason.

Default render options: ``--threads 2 --samples 1 --no-shadows --ao 0`` (the primary rays
alone); ``--picture`` leaves out all but ``--threads`` (the scenes' own shadows,
anti-aliasing and AO); options after ``--`` are appended (later ones win).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from _common import REPO, bench_cache, render_from_tree, split_extra  # benchmarks/ is on sys.path when run as a script

TIMES = ("total", "refine", "trace", "shade", "shadows", "ao")


def run_render(tree: Path, cache: Path, scene: str, out: Path, options: list[str]):
    """One ``subtrace render`` of ``scene`` from source tree ``tree``; (wall s, peak MiB)."""
    wall, usage = render_from_tree(tree, cache, [scene, "-o", str(out), *options], "ab")
    return wall, usage.ru_maxrss / 1024.0


def header(path: Path) -> dict:
    """The header's timings and counts of an EXR written by subtrace."""
    import OpenImageIO as oiio

    spec = oiio.ImageInput.open(str(path)).spec()
    attrs = {a.name: a.value for a in spec.extra_attribs}
    row = {k: float(attrs[f"subtrace:time_{k}"]) for k in TIMES}
    row["micro"] = float(attrs["subtrace:micro_triangles"])
    row["memo MB"] = float(attrs["subtrace:memo_bytes"]) / 1e6
    return row


def differences(a: Path, b: Path) -> str:
    """``same`` when the two images are equal bit for bit, else the channels that differ."""
    import numpy as np
    import OpenImageIO as oiio

    ia, ib = oiio.ImageBuf(str(a)), oiio.ImageBuf(str(b))
    pa, pb = ia.get_pixels(oiio.FLOAT), ib.get_pixels(oiio.FLOAT)
    names = ia.spec().channelnames
    if pa.shape != pb.shape or names != ib.spec().channelnames:
        return "different layout"
    out = []
    for k, name in enumerate(names):
        x, y = pa[..., k], pb[..., k]
        differ = ~((x == y) | (np.isnan(x) & np.isnan(y)))
        if differ.any():
            out.append(f"{name} {int(differ.sum())} px (max {np.nanmax(np.abs(x - y)):.3g})")
    return "same" if not out else "; ".join(out)


def inspect(a: Path, b: Path) -> tuple:
    """(header of a, header of b, differences) read by a child process: the images' pixels
    never enter this one, whose resident memory each render's peak would otherwise include
    (Linux carries a process's high-water mark across the exec of its forked child)."""
    code = ("import json, sys; sys.path.insert(0, sys.argv[3]); import ab; "
            "a, b = map(ab.Path, sys.argv[1:3]); "
            "print(json.dumps([ab.header(a), ab.header(b), ab.differences(a, b)]))")
    out = subprocess.run([sys.executable, "-c", code, str(a), str(b), str(Path(__file__).parent)],
                         check=True, capture_output=True, text=True).stdout
    return tuple(json.loads(out))


def cache_for(tree: Path) -> Path:
    key = hashlib.sha1(str(tree.resolve()).encode()).hexdigest()[:12]
    return bench_cache("ab") / key


def main(argv=None) -> int:
    argv, extra = split_extra(sys.argv[1:] if argv is None else argv)
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--base", default="HEAD", help="the commit A is (default HEAD)")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--picture", action="store_true",
                    help="render the scenes' own picture (shadows, anti-aliasing, AO)")
    args = ap.parse_args(argv)
    options = ["--threads", str(args.threads),
               *([] if args.picture else ["--samples", "1", "--no-shadows", "--ao", "0"]),
               *extra]
    scenes = [str(Path(s).resolve()) for s in args.scenes]
    base = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", args.base],
                          check=True, capture_output=True, text=True).stdout.strip()
    work = Path(tempfile.mkdtemp(prefix="subtrace-ab-"))
    tree_a = work / f"a-{base}"
    subprocess.run(["git", "-C", str(REPO), "worktree", "add", "--detach", "-q", str(tree_a),
                    base], check=True)
    trees = {"A": tree_a, "B": REPO}
    caches = {"A": cache_for(REPO) / f"base-{base}", "B": cache_for(REPO) / "checkout"}
    try:
        for side in "AB":  # warm-up: compiles each side's kernels into its cache
            for scene in scenes:
                run_render(trees[side], caches[side], scene, work / f"{side}.exr", options)
        rows = {}
        same = {}
        for r in range(args.rounds):
            for k, scene in enumerate(scenes):
                run = {}
                for side in ("AB" if r % 2 == 0 else "BA"):
                    run[side] = run_render(trees[side], caches[side], scene,
                                           work / f"{side}{k}.exr", options)
                head_a, head_b, diff = inspect(work / f"A{k}.exr", work / f"B{k}.exr")
                for side, row in (("A", head_a), ("B", head_b)):
                    row["process"], row["peak MB"] = run[side]
                    rows.setdefault((scene, side), []).append(row)
                if r == 0:
                    same[scene] = diff
                print(f"round {r + 1}/{args.rounds}: {Path(scene).stem}", file=sys.stderr,
                      flush=True)
    finally:
        subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force", str(tree_a)],
                       check=False)
        shutil.rmtree(work, ignore_errors=True)
    metrics = ["process", "peak MB", *TIMES, "micro", "memo MB"]
    print(f"A = {base}, B = the checkout; medians of {args.rounds} alternated rounds; "
          f"render options: {' '.join(options)}; {os.cpu_count()} CPUs\n")
    print("| scene | " + " | ".join(f"{m} A / B" for m in metrics) + " | B's image |")
    print("|---|" + "---:|" * len(metrics) + "---|")
    for scene in scenes:
        cells = []
        for m in metrics:
            a = statistics.median(x[m] for x in rows[(scene, "A")])
            b = statistics.median(x[m] for x in rows[(scene, "B")])
            fmt = "{:.0f}" if m in ("micro", "peak MB", "memo MB") else "{:.3f}"
            ratio = f" ({b / a:.2f})" if a else ""
            cells.append(f"{fmt.format(a)} / {fmt.format(b)}{ratio}")
        print(f"| {Path(scene).stem} | " + " | ".join(cells) + f" | {same[scene]} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
