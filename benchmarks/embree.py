"""Benchmark: subtrace side by side with Intel Embree's own subdivision surfaces.

    python benchmarks/embree.py [--scenes NAME ...] [--rounds 5] [--width W --height H]
                                [--threads 2] [--subtrace CMD] [--subtrace-args ARGS]
                                [--build-dir DIR] [--images DIR] [--json OUT] [--list]

A native anchor: what a tuned C++ ray tracer does with the same cages. Embree 3's
``RTC_GEOMETRY_TYPE_SUBDIVISION`` (Debian's ``libembree-dev``, 3.13) tessellates the limit
surface at per-edge levels and builds its BVH over the grids; ``embree_driver.cpp`` (beside
this file, subtrace's own code) feeds it a cage, shoots one primary ray per pixel and writes
its times, a hit mask and the ray distances. This script builds the driver with ``g++``
(or ``$CXX``) into a cache folder on first use (``~/.cache/subtrace-benchmarks/embree-driver``, or
``--build-dir``; a new binary whenever the source changes) and skips with one message, exit
0, where the compiler or Embree's headers or library are missing. Embree is never a
dependency of subtrace.

Scenes: ``benchmarks/cycles.py``'s (every ``scenes/*.toml`` and the cages it writes, the
hard-surface ``chess``, ``car``, ``helmet`` included), with the same cameras, the
Catmull-Clark ones only: Embree has no Loop scheme, and no free-form surfaces. A scene with
a face of more than 15 vertices (``gen_pawn``'s 24-gon top) is skipped: Embree takes faces
of 3 to 15 vertices.

Like for like:

* Cage: the same OBJ data (positions, faces, ``t crease`` as edge crease weights, ``t
  corner`` as vertex crease weights, sharpness >= 10 as infinite, ``t hole`` as holes) and
  the boundary mode subtrace uses (the scene's, else the OBJ's ``interpolateboundary``,
  else edge-only): edge-only is Embree's ``SMOOTH_BOUNDARY``, edge-and-corner its
  ``PIN_CORNERS``, none its ``NO_BOUNDARY``.
* Rays: ``subtrace.camera.camera_frame`` of the scene's camera is given to the driver,
  which forms every pixel centre's ray as subtrace does (``p00 + col dx + row dy``,
  normalised, in doubles), then rounds it to Embree's floats.
* Edge levels: as Cycles dices at 1 px (``intern/cycles/subd`` DiagSplit: every patch split
  once at its middle, then per half ``T = max(1, ceil(2 max(L1, L2)))`` with L1, L2 the
  pixel lengths of its two quarters), measured on the limit surface (Embree's
  ``rtcInterpolate`` at five points of every edge; the exact rule is in the driver's
  comment). That costs time Cycles spends too: it is part of the build (``levels`` in the
  second table). Measured on the cage's straight edges instead, the levels would be
  larger by as much as the cage stands off its limit (Spot's mean level 60 instead of 53).
* Threads: ``threads=N`` in ``rtcNewDevice``'s config (the BVH build and tessellation) and
  N threads taking rows for the trace; subtrace runs ``render --tolerance 1 --samples 1
  --threads N`` with the same camera on its command line (plus ``--subtrace-args``, e.g.
  ``"--no-shadows --ao 0"``: by default the scene's shadows and ambient occlusion stay).

Embree's rules differ from OpenSubdiv's (which subtrace follows exactly) in a few places
(Embree 3.13.5, ``kernels/subdiv``):

* Semi-sharp creases: at a vertex where exactly two creases meet, Embree always averages
  their sharpness as Chaikin's rule does (``0.25 (3 s0 + s1) - 1``); OpenSubdiv's default
  (uniform) subtracts 1 from each. The same where both sharpnesses are equal (chess's,
  car's and helmet's creases have one value per piece); not where mixed semi-sharp
  creases meet. Nor is it OpenSubdiv's ``t creasemethod chaikin``: on the ``chaikin``
  scene (sharpness varying along its creases) about 2,800 pixels disagree off
  silhouettes at 1280x720, Embree's end of the box the rounder.
* Three or more semi-sharp creases at a vertex: Embree takes the corner rule whatever
  their sharpness; OpenSubdiv blends corner and crease rules by the sharpness of the edges
  about to vanish. The ``creases`` scene's cube has such corners (edges of sharpness 0.1,
  5 and 5): about 1,000 pixels disagree off silhouettes at 1280x720, none once its 0.1
  edge is made 5; ``gen_nut``'s hexagon corners (two infinitely sharp rim edges and one
  of 2.5) about 30, Embree's corners the sharper.
* Corner tags (vertex sharpness): Embree blends smooth and corner positions by the vertex
  weight and then ignores the edges' creases at that vertex; OpenSubdiv blends with the
  rule the edges give. They differ at fractional corner tags on crease vertices.
* Limits: a face of more than 16 vertices or a vertex ring of more than 64 faces (128
  ring edges; valence > 64) is invalid to Embree, which drops those faces. Around
  extraordinary vertices and creases Embree subdivides 10 levels, then evaluates Gregory
  (irregular) or bicubic (regular) patches: the remaining crease sharpness is then
  ignored (sharpness above 10 only) and the corner pieces, 2^-10 of a face wide, are
  approximate. Positions are floats (subtrace: doubles).
* Debian's library keeps Embree's internal assertions (they fire: see the driver's vertex
  buffer), so it is not quite an upstream release build: an anchor on the slow side.
* The tessellation is a chord approximation of the limit at about 1 px; subtrace's hits
  are on the limit within its 1 px angular tolerance.

Timing: per scene one warm-up run of each (Numba's cache, the file cache), then
``--rounds`` rounds, each running subtrace then Embree, the order swapped every round;
every run a fresh process. subtrace's render time is the EXR header's
``subtrace:time_total`` (load, preprocess, refine, trace, shade; not the EXR write), shown
with its refine + trace part; Embree's is build (geometry, edge levels, ``rtcCommitScene``:
tessellation and BVH) + trace (one ``rtcIntersect1`` per pixel), with the device's creation
(TBB's start) shown apart. Also per run: the process's wall time and its peak RSS
(``os.wait4`` in cycles.py's bare launcher, so that this script's own memory does not
count). The table gives medians, ratios subtrace / Embree and their geometric means.

Coverage agreement (on the last round's outputs): subtrace covers a pixel where its ``Z``
is finite, Embree where its ray hit. *Off silhouettes* counts the pixels where the two
disagree and at least one of the masks has the pixel's whole 3x3 neighbourhood hit or
missed: a one-pixel shift of a silhouette is not counted, a hole, a missing sliver two
pixels wide or a thin part one renderer lost is. Depth: the relative difference of the
two ray distances on pixels whose 3x3 neighbourhoods both renderers hit (median and 99th
percentile). ``--images DIR`` writes ``DIR/<scene>_coverage.png`` (grey: both hit, red:
subtrace only, blue: Embree only).

On a shared machine absolute times mean little; the ratios of one run, rounds alternated,
are what to compare (the header line says the load average during the timings).
"""

from __future__ import annotations

import argparse
import fnmatch
import hashlib
import json
import os
import shlex
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import cycles  # beside this file: the scenes, cameras, cage reader and process timing
from _common import bench_cache, import_subtrace

DRIVER_SOURCE = Path(__file__).resolve().with_name("embree_driver.cpp")
DEFAULT_BUILD_DIR = bench_cache("embree-driver")
CXX_FLAGS = ["-O2", "-std=c++17"]
LIBS = ["-lembree3", "-lpthread"]
INSTALL_HINT = "Debian / Ubuntu: apt-get install libembree-dev"
MAX_FACE = 15  # Embree's largest face (vertices)
MAX_RING = 64  # Embree's largest vertex ring (faces)


class Skip(Exception):
    """The benchmark cannot run here (no compiler, no Embree): one line, exit 0."""


# ---------------------------------------------------------------------------------- driver
def build_driver(build_dir: Path) -> Path:
    """The driver's binary, compiled on first use (one per source and flags)."""
    cxx = os.environ.get("CXX") or shutil.which("g++")
    if not cxx or not shutil.which(cxx):
        raise Skip(f"no C++ compiler ({os.environ.get('CXX') or 'g++'}) found")
    key = hashlib.sha1(DRIVER_SOURCE.read_bytes() + " ".join([cxx, *CXX_FLAGS, *LIBS])
                       .encode()).hexdigest()[:12]
    binary = build_dir / f"embree_driver-{key}"
    if binary.exists():
        return binary
    build_dir.mkdir(parents=True, exist_ok=True)
    tmp = binary.with_suffix(".tmp")
    out = subprocess.run([cxx, *CXX_FLAGS, "-o", str(tmp), str(DRIVER_SOURCE), *LIBS],
                         capture_output=True, text=True)
    if out.returncode != 0:
        text = out.stderr
        if "embree3/rtcore.h" in text or "-lembree3" in text:
            raise Skip(f"Embree 3's headers or library not found ({INSTALL_HINT})")
        log = build_dir / "build.log"
        log.write_text(text)
        raise cycles.BenchError(f"could not compile {DRIVER_SOURCE.name} (see {log}): "
                                f"{text.strip().splitlines()[-1] if text.strip() else ''}")
    tmp.replace(binary)
    return binary


def camera_frame(camera: dict, width: int, height: int):
    """subtrace's own frame (eye, dx, dy, p00) of the scene's camera at width x height."""
    import_subtrace()
    from subtrace.camera import Camera
    from subtrace.camera import camera_frame as frame_of

    cam = Camera(tuple(camera["eye"]), tuple(camera["target"]), tuple(camera["up"]),
                 camera["fov"], width, height)
    return frame_of(cam)[:4]


def job_text(scene, width: int, height: int, threads: int) -> str:
    """The driver's job: image, camera frame, cages (see embree_driver.cpp)."""
    frame = camera_frame(scene.camera, width, height)
    lines = ["embree-job 1", f"threads {threads}", f"image {width} {height}",
             "frame " + " ".join(repr(float(v)) for v in frame.ravel()), "dicing_rate 1",
             f"objects {len(scene.objects)}"]
    for cage, _scheme, boundary, _colour in scene.objects:
        lines.append(f"object {boundary}")
        lines.append(f"vertices {len(cage.positions)}")
        lines += [f"{x!r} {y!r} {z!r}" for x, y, z in cage.positions]
        lines.append(f"faces {len(cage.faces)}")
        lines += [f"{len(f)} " + " ".join(map(str, f)) for f in cage.faces]
        lines.append(f"creases {len(cage.creases)}")
        lines += [f"{a} {b} {s!r}" for a, b, s in cage.creases]
        lines.append(f"corners {len(cage.corners)}")
        lines += [f"{v} {s!r}" for v, s in cage.corners]
        lines.append(f"holes {len(cage.hole_faces)}")
        lines += [str(f) for f in cage.hole_faces]
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------- scenes
def embree_problem(scene) -> str | None:
    """Why Embree cannot render ``scene`` as subtrace does, or None."""
    for cage, scheme, _boundary, _colour in scene.objects:
        if not cage.faces:
            return "free-form surfaces"
        if scheme != "catmark":
            return "Loop subdivision (Embree has Catmull-Clark only)"
        big = max(len(f) for f in cage.faces)
        if big > MAX_FACE:
            return f"a face of {big} vertices (Embree takes 3 to {MAX_FACE})"
    return None


def ring_note(scene) -> str | None:
    """A note where a vertex has more faces than Embree's ring holds (it drops them)."""
    worst = 0
    for cage, *_ in scene.objects:
        count: dict = {}
        for f in cage.faces:
            for v in f:
                count[v] = count.get(v, 0) + 1
        worst = max(worst, max(count.values(), default=0))
    if worst > MAX_RING:
        return f"a vertex of valence {worst}: Embree drops the faces around it"
    return None


def load_scenes(work: Path, names) -> tuple[list, list]:
    """(scenes Embree can render, [(name, why not)]), cycles.py's list and cameras."""
    paths = sorted((cycles.REPO / "scenes").glob("*.toml")) + cycles.write_extra_scenes(work)
    scenes, skipped = [], []
    for scene in map(cycles.load_scene, paths):
        if names and not any(fnmatch.fnmatchcase(scene.name, n) for n in names):
            continue
        why = embree_problem(scene)
        if why:
            skipped.append((scene.name, why))
        else:
            scenes.append(scene)
    return scenes, skipped


# ------------------------------------------------------------------------------- processes
class Runner:
    """One render of a scene by either renderer, each a fresh process."""

    def __init__(self, args, driver: Path, work: Path):
        self.args, self.driver, self.work = args, driver, work
        self.subtrace = shlex.split(args.subtrace)
        self.extra = shlex.split(args.subtrace_args or "")
        self.env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}

    def size(self, scene):
        return (self.args.width or scene.camera["width"],
                self.args.height or scene.camera["height"])

    def subtrace_cmd(self, scene, exr):
        cam, (w, h), num = scene.camera, self.size(scene), cycles.cli_number
        return self.subtrace + [
            "render", str(scene.toml), "-o", str(exr), "--tolerance", "1", "--samples", "1",
            "--threads", str(self.args.threads), "--width", str(w), "--height", str(h),
            "--fov", num(cam["fov"]), "--eye", *map(num, cam["eye"]),
            "--target", *map(num, cam["target"]), "--up", *map(num, cam["up"]),
            "--quiet", *self.extra]

    def run_subtrace(self, scene) -> dict:
        exr = self.work / f"{scene.name}_subtrace.exr"
        log = self.work / f"{scene.name}_subtrace.log"
        rc, wall, rss = cycles.run_process(self.subtrace_cmd(scene, exr), log, self.env)
        if rc != 0:
            raise cycles.BenchError(f"subtrace failed on {scene.name} (exit {rc}): "
                                    f"{cycles._log_tail(log)}")
        head = cycles.exr_header(exr)
        run = {k: v for k, v in head.items() if isinstance(v, (int, float))}
        run.update(render=float(head["time_total"]), wall=wall, rss_mb=rss,
                   refine_trace=float(head["time_refine"]) + float(head["time_trace"]))
        return run

    def run_embree(self, scene) -> dict:
        w, h = self.size(scene)
        job = self.work / f"{scene.name}_job_{w}x{h}.txt"
        if not job.exists():
            job.write_text(job_text(scene, w, h, self.args.threads))
        out = self.work / f"{scene.name}_embree"
        log = self.work / f"{scene.name}_embree.log"
        rc, wall, rss = cycles.run_process([str(self.driver), str(job), str(out)], log,
                                           self.env)
        if rc != 0:
            raise cycles.BenchError(f"the Embree driver failed on {scene.name} (exit {rc}): "
                                    f"{cycles._log_tail(log)}")
        run = {}
        for line in Path(f"{out}.txt").read_text().splitlines():
            key, value = line.split()
            run[key] = float(value)
        run.update(render=run["build_s"] + run["trace_s"], wall=wall, rss_mb=rss)
        return run


# -------------------------------------------------------------------------------- coverage
def _uniform(mask):
    """Pixels whose 3x3 neighbourhood (clipped at the border) is all True or all False."""
    import numpy as np

    pad = np.pad(mask, 1, mode="edge").astype(np.int8)
    h, w = mask.shape
    total = sum(pad[dy:dy + h, dx:dx + w] for dy in range(3) for dx in range(3))
    return (total == 0) | (total == 9)


def coverage(runner, scene, images: Path | None) -> dict:
    """Agreement of the last outputs of both renderers (see the module comment)."""
    import numpy as np

    w, h = runner.size(scene)
    z_s = _read_z(runner.work / f"{scene.name}_subtrace.exr")
    s_hit = np.isfinite(z_s)
    e_hit = np.fromfile(runner.work / f"{scene.name}_embree.mask", np.uint8).reshape(h, w) > 0
    z_e = np.fromfile(runner.work / f"{scene.name}_embree.depth", np.float32).reshape(h, w)
    differ = s_hit != e_hit
    off = differ & (_uniform(s_hit) | _uniform(e_hit))
    inside = _uniform(s_hit) & _uniform(e_hit) & s_hit & e_hit
    rel = np.abs(z_s[inside] - z_e[inside]) / z_s[inside]
    if images is not None:
        _write_coverage(images / f"{scene.name}_coverage.png", s_hit, e_hit)
    return {"subtrace_px": int(s_hit.sum()), "embree_px": int(e_hit.sum()),
            "differ_px": int(differ.sum()), "off_silhouette_px": int(off.sum()),
            "depth_rel_median": float(np.median(rel)) if rel.size else float("nan"),
            "depth_rel_p99": float(np.percentile(rel, 99)) if rel.size else float("nan")}


def _read_z(path):
    import numpy as np
    import OpenImageIO as oiio

    buf = oiio.ImageBuf(str(path))
    spec = buf.spec()
    px = buf.get_pixels(oiio.FLOAT).reshape(spec.height, spec.width, spec.nchannels)
    return np.ascontiguousarray(px[:, :, list(spec.channelnames).index("Z")])


def _write_coverage(path, s_hit, e_hit):
    import numpy as np

    rgb = np.zeros(s_hit.shape + (3,))
    rgb[s_hit & e_hit] = 0.6
    rgb[s_hit & ~e_hit] = (1.0, 0.15, 0.1)
    rgb[~s_hit & e_hit] = (0.1, 0.35, 1.0)
    cycles._write_png(path, rgb)


# ----------------------------------------------------------------------------------- table
def summarize(results) -> dict:
    med = cycles._median
    rows = []
    for r in results:
        s, e = r["subtrace"], r["embree"]
        row = {"scene": r["scene"], "features": r["features"], "notes": r["notes"],
               "px": int(med(s, "pixels_covered")), "coverage": r["coverage"]}
        for key in ("render", "refine_trace", "wall", "rss_mb", "time_load",
                    "time_preprocess", "time_refine", "time_trace", "time_shade",
                    "patches_refined", "micro_triangles"):
            row["subtrace_" + key] = med(s, key)
        for key in ("render", "device_s", "build_s", "levels_s", "trace_s", "wall", "rss_mb",
                    "level_mean", "level_max", "edges"):
            row["embree_" + key] = med(e, key)
        for key in ("render", "wall", "rss_mb"):
            row["ratio_" + key] = row["subtrace_" + key] / row["embree_" + key]
        row["ratio_refine_trace"] = row["subtrace_refine_trace"] / row["embree_render"]
        rows.append(row)
    keys = ("render", "refine_trace", "wall", "rss_mb")
    geo = {k: cycles._geomean([row["ratio_" + k] for row in rows]) for k in keys}
    return {"rows": rows, "geomean": geo}


def markdown(summary) -> str:
    rows, geo = summary["rows"], summary["geomean"]
    notes, out = [], []
    out.append("| scene | cage | covered px | subtrace s (refine + trace) | Embree s (build + "
               "trace) | ratio | ratio of refine + trace | subtrace process s | Embree "
               "process s | ratio | subtrace MB | Embree MB | ratio |")
    out.append("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for row in rows:
        marks = cycles.note_marks(row["notes"], notes)
        out.append(
            f"| {row['scene']}{marks} | {row['features']} | {row['px']:,} "
            f"| {row['subtrace_render']:.3f} ({row['subtrace_refine_trace']:.3f}) "
            f"| {row['embree_render']:.3f} ({row['embree_build_s']:.3f} + "
            f"{row['embree_trace_s']:.3f}) | **{row['ratio_render']:.2f}** "
            f"| {row['ratio_refine_trace']:.2f} | {row['subtrace_wall']:.2f} "
            f"| {row['embree_wall']:.2f} | **{row['ratio_wall']:.2f}** "
            f"| {row['subtrace_rss_mb']:.0f} | {row['embree_rss_mb']:.0f} "
            f"| **{row['ratio_rss_mb']:.2f}** |")
    out.append(f"| **geometric mean** | | | | | **{geo['render']:.2f}** "
               f"| {geo['refine_trace']:.2f} | | | **{geo['wall']:.2f}** | | "
               f"| **{geo['rss_mb']:.2f}** |")
    out += [""] + [f"<sup>{i + 1}</sup> {n}." for i, n in enumerate(notes)]
    out += detail_table(rows)
    return "\n".join(out)


def detail_table(rows) -> list[str]:
    """Where the time goes, Embree's levels, and the coverage agreement."""
    out = ["", "Where the time goes (medians, s; subtrace's header timings), Embree's edge "
           "levels (segments per cage edge)\nand the coverage agreement of the last round "
           "(off silhouettes and depth: see the module comment).", "",
           "| scene | load | preprocess | refine | trace | shade | patches refined "
           "| Embree device | build (levels) | trace | mean level | max level | subtrace px "
           "| Embree px | differ px | off silhouettes | depth rel. median | p99 |",
           "|---|" + "---:|" * 17]
    for row in rows:
        c = row["coverage"]
        out.append(
            f"| {row['scene']} | {row['subtrace_time_load']:.3f} "
            f"| {row['subtrace_time_preprocess']:.3f} | {row['subtrace_time_refine']:.3f} "
            f"| {row['subtrace_time_trace']:.3f} | {row['subtrace_time_shade']:.3f} "
            f"| {row['subtrace_patches_refined']:,.0f} | {row['embree_device_s']:.3f} "
            f"| {row['embree_build_s']:.3f} ({row['embree_levels_s']:.3f}) "
            f"| {row['embree_trace_s']:.3f} "
            f"| {row['embree_level_mean']:.1f} | {row['embree_level_max']:.0f} "
            f"| {c['subtrace_px']:,} | {c['embree_px']:,} | {c['differ_px']:,} "
            f"| **{c['off_silhouette_px']:,}** | {c['depth_rel_median']:.1e} "
            f"| {c['depth_rel_p99']:.1e} |")
    return out


# ------------------------------------------------------------------------------------ main
def parse_args(argv):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", metavar="NAME",
                    help="only these scenes (names as in --list, or patterns: 'gen_*')")
    ap.add_argument("--rounds", type=int, default=5, help="timed rounds per scene (default 5)")
    ap.add_argument("--width", type=int, help="override every scene's width (quick checks)")
    ap.add_argument("--height", type=int, help="override every scene's height")
    ap.add_argument("--threads", type=int, default=2, help="threads of each renderer (2)")
    ap.add_argument("--subtrace", default=cycles.default_subtrace(), metavar="CMD",
                    help="command that runs subtrace's CLI (default: %(default)s)")
    ap.add_argument("--subtrace-args", metavar="ARGS", help="more options for subtrace "
                    "render, e.g. '--no-shadows --ao 0'")
    ap.add_argument("--build-dir", type=Path, default=DEFAULT_BUILD_DIR, metavar="DIR",
                    help="where the driver is compiled to (default: %(default)s)")
    ap.add_argument("--images", metavar="DIR", type=Path,
                    help="write each scene's coverage comparison as DIR/<scene>_coverage.png")
    ap.add_argument("--json", metavar="OUT", help="write every measurement to OUT")
    ap.add_argument("--list", action="store_true", help="list the scenes and exit")
    args = ap.parse_args(argv)
    if args.rounds < 1 or args.threads < 1:
        ap.error("--rounds and --threads must be at least 1")
    if (args.width is None) != (args.height is None):
        ap.error("give both --width and --height, or neither")
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    try:
        return _main(args)
    except Skip as exc:
        print(f"embree.py: skipped: {exc}", file=sys.stderr)
        return 0
    except cycles.BenchError as exc:
        print(f"embree.py: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("embree.py: interrupted", file=sys.stderr)
        return 130


def time_scene(runner, scene, rounds: int) -> dict:
    """Warm-up, then ``rounds`` rounds alternating the order; the coverage of the last."""
    runner.run_subtrace(scene)  # warm-up: Numba's cache, file caches
    runner.run_embree(scene)
    runs = {"subtrace": [], "embree": []}
    for r in range(rounds):
        order = ("subtrace", "embree") if r % 2 == 0 else ("embree", "subtrace")
        for which in order:
            run = runner.run_subtrace if which == "subtrace" else runner.run_embree
            runs[which].append(run(scene))
    notes = [n for n in [ring_note(scene)] if n]  # (scene.notes are about Cycles)
    if any(c.crease_method not in (None, "uniform") for c, *_ in scene.objects):
        notes.append("Chaikin creases: Embree has its own Chaikin-like rule only (see the "
                     "module comment)")
    return {"scene": scene.name, "features": scene.features(), "notes": notes, **runs,
            "coverage": coverage(runner, scene, runner.args.images)}


def _main(args) -> int:
    with tempfile.TemporaryDirectory(prefix="subtrace-embree-") as tmp:
        work = Path(tmp)
        scenes, skipped = load_scenes(work, args.scenes)
        for name, why in skipped:
            print(f"embree.py: skipping {name}: {why}", file=sys.stderr)
        if args.list:
            for s in scenes:
                print(f"{s.name:28} {s.features()}")
            return 0
        if not scenes:
            raise cycles.BenchError("no scene to render (see --list)")
        driver = build_driver(args.build_dir)
        if args.images:
            args.images.mkdir(parents=True, exist_ok=True)
        runner = Runner(args, driver, work)
        w0, h0 = runner.size(scenes[0])
        print(f"subtrace ({args.subtrace}) vs Embree ({driver.name}); {args.threads} threads "
              f"each; {args.rounds} rounds after a warm-up; {len(scenes)} scenes at {w0}x{h0}",
              file=sys.stderr, flush=True)
        results, loads = [], [os.getloadavg()[0]]
        for scene in scenes:
            results.append(time_scene(runner, scene, args.rounds))
            loads.append(os.getloadavg()[0])
            s, e = (statistics.median(x["render"] for x in results[-1][k])
                    for k in ("subtrace", "embree"))
            print(f"  {scene.name}: subtrace {s:.3f} s, Embree {e:.3f} s", file=sys.stderr,
                  flush=True)
        summary = summarize(results)
        print(f"\nsubtrace vs Embree {embree_version(driver)} subdivision surfaces, {w0}x{h0}, "
              f"{args.threads} threads, medians of {args.rounds} rounds; ratio = subtrace / "
              f"Embree; {os.cpu_count()} CPUs, 1-minute load average "
              f"{min(loads):.1f}-{max(loads):.1f} during the timings\n")
        print(markdown(summary))
        if args.json:
            Path(args.json).write_text(json.dumps(
                {"subtrace": args.subtrace, "subtrace_args": args.subtrace_args,
                 "threads": args.threads, "rounds": args.rounds, "size": [w0, h0],
                 "load_averages": loads, "runs": results, "summary": summary},
                indent=1, default=str))
    return 0


def embree_version(driver: Path) -> str:
    """Embree's version as the driver reports it."""
    out = subprocess.run([str(driver), "--version"], capture_output=True, text=True)
    return out.stdout.strip() or "?"


if __name__ == "__main__":
    raise SystemExit(main())
