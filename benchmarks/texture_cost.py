"""What the default scene's image texture costs: ``subtrace render`` of the built-in scene
(Spot with its texture) against the same scene without its ``diffuse_texture`` line.

    python benchmarks/texture_cost.py [--rounds 5] [--tree NAME=PATH[:CACHE] ...]

Each ``--tree`` is a source checkout (``PATH/src`` on ``PYTHONPATH``) with its own kernel
cache ``CACHE`` (default: ``~/.cache/subtrace-benchmarks/texture_cost/<hash of PATH>``);
without any, this checkout alone. Per tree the untextured scene is a copy of its
``src/subtrace/data/default_scene.toml`` without the ``diffuse_texture`` line, the mesh's
path made absolute; the textured one is ``subtrace render -o OUT.exr`` with no scene.
One untimed render of each fills the caches; then ``--rounds`` rounds run every (tree,
scene) as a fresh process, the trees in turn forwards in even rounds and backwards in odd
ones, textured first in even rounds (the machine's speed drifts: alternating spreads it).

The table: per tree, medians of the renderer's own ``time_total`` (its EXR header), of
the whole command's wall time and of its CPU time (user and system, every thread: on a
machine shared with other work it drifts less than wall time), textured and untextured,
with the ratio of the medians and, in brackets, the median of the rounds' own ratios (the
two renders of a round run back to back).
"""

from __future__ import annotations

import argparse
import hashlib
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

from _common import REPO, bench_cache, load, render_from_tree  # benchmarks/ is on sys.path when run as a script


def untextured_copy(tree: Path, out: Path) -> Path:
    """The tree's default scene without its ``diffuse_texture`` line, its mesh's path
    absolute, written to ``out``."""
    data = tree / "src" / "subtrace" / "data"
    lines = []
    for line in (data / "default_scene.toml").read_text().splitlines():
        key = line.split("=")[0].strip()
        if key == "diffuse_texture":
            continue
        if key == "mesh":
            name = line.split("=", 1)[1].split("#")[0].strip().strip('"')
            line = f'mesh = "{(data / name).resolve()}"'
        lines.append(line)
    out.write_text("\n".join(lines) + "\n")
    return out


def render(tree: Path, cache: Path, scene: Path | None, out: Path) -> tuple:
    """One ``subtrace render [scene] -o out`` from ``tree``: (wall s, the header's
    ``subtrace:time_total``, the process's CPU s: user and system, all threads)."""
    import OpenImageIO as oiio

    wall, usage = render_from_tree(tree, cache, [*([str(scene)] if scene else []), "-o",
                                                 str(out)], "texture_cost")
    inp = oiio.ImageInput.open(str(out))
    total = float(inp.spec().getattribute("subtrace:time_total"))
    inp.close()
    return wall, total, usage.ru_utime + usage.ru_stime


def parse_tree(text: str) -> tuple[str, Path, Path]:
    name, _, rest = text.partition("=")
    if not rest:
        raise SystemExit(f"texture_cost: --tree {text!r}: expected NAME=PATH[:CACHE]")
    path, _, cache = rest.partition(":")
    tree = Path(path).resolve()
    if not cache:
        key = hashlib.sha1(str(tree).encode()).hexdigest()[:12]
        cache = bench_cache("texture_cost") / key
    return name, tree, Path(cache)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--tree", action="append", default=[],
                    help="NAME=PATH[:CACHE], a checkout to measure (repeatable)")
    args = ap.parse_args(argv)
    trees = [parse_tree(t) for t in args.tree] or [parse_tree(f"checkout={REPO}")]
    work = Path(tempfile.mkdtemp(prefix="subtrace-texture-cost-"))
    plain = {name: untextured_copy(tree, work / f"{name}-untextured.toml")
             for name, tree, _ in trees}
    runs: dict = {}
    load_before = load()
    for name, tree, cache in trees:  # warm-up: each tree's kernels and texture in its cache
        for scene in (None, plain[name]):
            render(tree, cache, scene, work / "out.exr")
    for r in range(args.rounds):
        order = trees if r % 2 == 0 else trees[::-1]
        for name, tree, cache in order:
            kinds = ("textured", "untextured") if r % 2 == 0 else ("untextured", "textured")
            for kind in kinds:
                scene = None if kind == "textured" else plain[name]
                runs.setdefault((name, kind), []).append(
                    render(tree, cache, scene, work / "out.exr"))
        print(f"round {r + 1}/{args.rounds}", file=sys.stderr, flush=True)
    for p in work.iterdir():
        p.unlink()
    work.rmdir()
    print(f"the default scene textured against untextured: medians of {args.rounds} "
          f"alternated rounds, {time.strftime('%Y-%m-%d %H:%M')}, {os.cpu_count()} CPUs, "
          f"load {load_before} before, {load()} after\n")
    print("| tree | what | textured | untextured | ratio (rounds' median) |")
    print("|---|---|---:|---:|---:|")
    for name, tree, _ in trees:
        tex, plain = runs[(name, "textured")], runs[(name, "untextured")]
        for i, what in ((1, "render (time_total)"), (0, "command, wall"), (2, "command, CPU")):
            a = statistics.median(x[i] for x in tex)
            b = statistics.median(x[i] for x in plain)
            paired = statistics.median(x[i] / y[i] for x, y in zip(tex, plain))
            print(f"| {name} ({tree}) | {what} | {a:.3f} s | {b:.3f} s | {a / b:.2f}x "
                  f"({paired:.2f}x) |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
