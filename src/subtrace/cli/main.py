"""The ``subtrace`` command line: ``subtrace info [CAGE.obj] [--scheme S] [--level N]``,
``subtrace render ...``, ``subtrace compare A.exr B.exr ...`` and ``subtrace sweep ...``.

Owns argument parsing, the text report and the error policy (design invariant 7): every
:class:`subtrace.errors.SubtraceError` becomes one line ``subtrace: error: <message>`` on
stderr and exit code 2, with no traceback; argparse usage errors exit 2 as well.
``compare`` follows idiff's exit codes instead: 3 for a size or channel mismatch, 4 for an
image that cannot be read (and 0 / 1 / 2 for pass / warning / failure).
This module imports only argparse at the top; the cage, subdivision and limit code are
imported by the subcommand that needs them. (``import subtrace`` itself loads numpy and
Numba, about 0.3 s, which ``subtrace --help`` still pays.)

:func:`run` is the process entry point (``cli.py``, ``python -m subtrace.cli.main``, the
``subtrace`` script); it trims two fixed costs of a short process that :func:`main`, which
tests call in-process, leaves alone: see :func:`_trim_numba` and :func:`_exit_now`.
"""

from __future__ import annotations

import argparse
import os
import sys

PROG = "subtrace"

BOUNDARY_NAMES = {0: "none", 1: "edge-and-corner", 2: "edge-only"}


def _level_arg(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid level {text!r}: expected an integer >= 0")
    if value < 0:
        raise argparse.ArgumentTypeError(f"invalid level {value}: expected an integer >= 0")
    return value


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line, ``subtrace: error: <problem>
    (see <command> --help)``, exit code 2 (design invariant 7), instead of argparse's usage
    text followed by the error."""

    def error(self, message):
        unknown = "unrecognized arguments: "
        if message.startswith(unknown):
            first = message[len(unknown):].split()[0]
            kind = "option" if first.startswith("-") else "argument"
            message = f"unknown {kind} {first!r}"
        print(f"{PROG}: error: {_one_line(message)} (see {self.prog} --help)", file=sys.stderr)
        raise SystemExit(2)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog=PROG,
        description="Exact Catmull-Clark and Loop subdivision surfaces (OpenSubdiv rules).",
    )
    from subtrace.version import VERSION as __version__

    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    info = sub.add_parser(
        "info",
        help="summarise a control cage: topology, tags, bounds",
        description=(
            "Print the scheme, options, counts, tags, valences, Euler characteristic and "
            "bounds of a control cage. Without CAGE the built-in sample cage (Spot, by "
            "Keenan Crane, public domain) is used. The limit-surface bounds are the bounds "
            "of the exact limit points of the level-1 vertices (an inner estimate of the "
            "surface's bounds); the cage's bounds contain the whole limit surface."
        ),
    )
    info.add_argument("cage", nargs="?", metavar="CAGE.obj", help="OBJ control cage")
    info.add_argument(
        "--scheme",
        metavar="S",
        help="catmark (Catmull-Clark) or loop; default: loop for all-triangle cages, "
        "catmark otherwise",
    )
    info.add_argument(
        "--level",
        type=_level_arg,
        metavar="N",
        help="also print the counts after N uniform refinements",
    )
    info.set_defaults(func=_cmd_info)

    render = sub.add_parser(
        "render",
        help="ray trace the exact limit surface of a scene or of OBJ cages to EXR",
        description=(
            "Render a TOML scene, or OBJ cages with an automatic camera, as the exact "
            "Catmull-Clark / Loop limit surface: one ray per pixel, patches refined only "
            "where a ray reaches them and only until they are below the angular tolerance. "
            "Without inputs the built-in default scene (Spot) is rendered. Writes a "
            "multi-channel EXR (R,G,B,A, Z, N.X/N.Y/N.Z, level, patch_id, object_id, u, v)."
        ),
    )
    render.add_argument("inputs", nargs="*", metavar="SCENE.toml | CAGE.obj",
                        help="one TOML scene, or one or more OBJ cages")
    render.add_argument("-o", "--output", metavar="OUT.exr",
                        help="output EXR (default: the scene's output, else render.exr)")
    _add_camera_options(render)
    tol = render.add_mutually_exclusive_group()
    tol.add_argument("--tolerance", metavar="PIXELS",
                     help="angular tolerance in pixels at the image centre (default 1)")
    tol.add_argument("--tolerance-deg", metavar="DEG", help="angular tolerance in degrees")
    _add_render_options(render)
    render.add_argument("--png", action="store_true",
                        help="also write an sRGB PNG preview next to the EXR")
    render.add_argument("--quiet", action="store_true", help="print nothing on success")
    render.set_defaults(func=_cmd_render)

    compare = sub.add_parser(
        "compare",
        help="compare two EXR renders channel group by channel group (idiff-style verdict)",
        description=(
            "Compare two EXR images by channel group: colour (R,G,B: RMSE, PSNR, max abs, "
            "mean FLIP), coverage (A: pixels with the surface in one image only), depth (Z: "
            "relative error), normals (N.X,N.Y,N.Z: angle in degrees) and ids (level, "
            "patch_id, object_id: pixels that differ). A group fails when more than "
            "FAILPERCENT %% of its pixels have an error above FAIL, or one above HARDFAIL; it "
            "warns likewise with WARN and WARNPERCENT. Threshold options take GROUP=VALUE "
            "(repeatable) or a bare VALUE for the colour group. Exit codes as idiff's: 0 pass, "
            "1 warning, 2 failure (or bad options), 3 size or channel mismatch, 4 a file that "
            "cannot be read."
        ),
    )
    compare.add_argument("image_a", metavar="A.exr", help="first image (the test image)")
    compare.add_argument("image_b", metavar="B.exr", help="second image (the reference)")
    for name in ("fail", "failpercent", "warn", "warnpercent", "hardfail"):
        compare.add_argument(f"--{name}", action="append", default=[],
                             metavar="[GROUP=]VALUE",
                             help=f"{name} threshold of a group (default: see the README)")
    compare.add_argument("--diff", metavar="OUT.exr",
                         help="write the per-pixel differences and a normalised 'heat' channel")
    compare.add_argument("--png", action="store_true",
                         help="with --diff: also write a heat-map PNG next to it")
    compare.add_argument("--json", action="store_true", help="print the metrics as JSON")
    compare.add_argument("--no-flip", action="store_true",
                         help="skip the FLIP metric (the slowest one on large images)")
    compare.set_defaults(func=_cmd_compare)

    sweep = sub.add_parser(
        "sweep",
        help="render scenes at several angular tolerances: time, memory, refinement, error",
        description=(
            "Render each scene at each angular tolerance (pixels) and at a much finer "
            "reference tolerance, and measure what each costs (total / refine / trace time, "
            "the median of --repeat renders; peak memory; patches refined, micro-triangles, "
            "deepest level) and its error against the reference (depth in world units and "
            "pixel footprints, normal angle, coverage mismatches, colour RMSE, mean FLIP). "
            "Prints a table and writes DIR/sweep.csv, DIR/sweep.json, log-log plots and, per "
            "scene, DIR/<scene>/tol_<T>.exr, tol_<T>_levels.png (refinement-level heat map) "
            "and reference.exr. Each SCENE is a TOML scene or one OBJ cage; without SCENE the "
            "built-in default scene is swept."
        ),
    )
    sweep.add_argument("inputs", nargs="*", metavar="SCENE",
                       help="TOML scenes or OBJ cages, one scene each")
    sweep.add_argument("--tolerances", nargs="+", required=True, metavar="T",
                       help="angular tolerances in pixels at the image centre, e.g. 8 4 2 1")
    sweep.add_argument("--reference-tolerance", metavar="T",
                       help="tolerance of the reference render in pixels (default: the "
                            "finest of --tolerances / 4)")
    sweep.add_argument("--repeat", default="1", metavar="N",
                       help="renders per tolerance; times are their medians (default 1)")
    sweep.add_argument("-o", "--output", required=True, metavar="DIR",
                       help="folder for the table, images and plots (created if missing)")
    _add_camera_options(sweep)
    _add_render_options(sweep)
    sweep.add_argument("--quiet", action="store_true",
                       help="print nothing on success (no table, no progress bar)")
    sweep.set_defaults(func=_cmd_sweep)

    intersect = sub.add_parser(
        "intersect",
        help="every intersection of lines with the limit surface, to a precision",
        description=(
            "Intersect lines with the exact Catmull-Clark or Loop limit surface of CAGE: "
            "every hit, each within --precision (model units) of the surface. Lines come "
            "from a CSV with columns ox,oy,oz,dx,dy,dz (a header row naming them); hits go "
            "to a CSV with columns line,t,x,y,z,ptex,u,v,nx,ny,nz,tangent (sorted by line, "
            "then t), or JSON with --json; to stdout without -o."
        ),
    )
    intersect.add_argument("cage", metavar="CAGE.obj", help="OBJ cage")
    intersect.add_argument("--scheme", metavar="S",
                           help="catmark or loop (default: loop for an all-triangle cage, "
                                "else catmark)")
    intersect.add_argument("--lines", required=True, metavar="LINES.csv",
                           help="CSV with columns ox,oy,oz,dx,dy,dz")
    intersect.add_argument("--precision", required=True, metavar="D",
                           help="distance in model units, > 0")
    intersect.add_argument("-o", "--output", metavar="HITS.csv",
                           help="output file (default: stdout)")
    intersect.add_argument("--json", action="store_true", help="write JSON instead of CSV")
    intersect.add_argument("--first", action="store_true", help="only each line's nearest hit")
    intersect.add_argument("--t-min", default="0", metavar="T",
                           help="lines start at origin + T direction (default 0; -inf: "
                                "whole lines)")
    intersect.add_argument("--t-max", default="inf", metavar="T", help="and end at T (inf)")
    intersect.add_argument("--threads", type=_level_arg, metavar="N",
                           help="worker threads (default: all cores)")
    intersect.set_defaults(func=_cmd_intersect)
    return parser


def _add_render_options(parser) -> None:
    """The options of how objects are rendered, shared by ``render`` and ``sweep``."""
    parser.add_argument("--scheme", metavar="S", help="catmark or loop, for every object")
    parser.add_argument("--threads", type=_level_arg, metavar="N",
                        help="worker threads (default: all cores)")
    parser.add_argument("--accel", choices=("projection", "bvh"), default=None,
                        help="how rays find the patch shells they enter: shells projected "
                             "onto image tiles (default) or a BVH")
    parser.add_argument("--max-memory", metavar="SIZE",
                        help="memory budget of a render, e.g. 500M or 2G (a bare number is "
                             "MiB; default: half the memory available at the start). "
                             "Refinement that would exceed it is capped at a coarser level, "
                             "with a warning")


def _add_camera_options(parser) -> None:
    """The camera and resolution flags shared by ``render`` and ``sweep``."""
    parser.add_argument("--width", metavar="W", help="image width in pixels")
    parser.add_argument("--height", metavar="H", help="image height in pixels")
    parser.add_argument("--fov", metavar="DEG", help="vertical field of view in degrees")
    parser.add_argument("--eye", nargs=3, metavar=("X", "Y", "Z"), help="camera position")
    parser.add_argument("--target", nargs=3, metavar=("X", "Y", "Z"), help="point looked at")
    parser.add_argument("--up", nargs=3, metavar=("X", "Y", "Z"), help="camera up vector")


def _scene_from_inputs(inputs, args, **overrides):
    """The scene of ``inputs`` (one TOML scene, or OBJ cages; none: the built-in default
    scene) with the camera / resolution / scheme flags of ``args`` and ``overrides``
    (further :func:`subtrace.io.scene.apply_overrides` keywords) applied."""
    from subtrace.errors import SceneError
    from subtrace.io.scene import apply_overrides, load_scene, scene_for_meshes

    if not inputs:
        from subtrace.data import default_scene_path

        scene = load_scene(default_scene_path())
    elif len(inputs) == 1 and inputs[0].lower().endswith(".toml"):
        scene = load_scene(inputs[0])
    elif all(not p.lower().endswith(".toml") for p in inputs):
        scene = scene_for_meshes(inputs, scheme=args.scheme)
    else:
        raise SceneError("give one TOML scene, or OBJ cages, not both")
    vec = lambda v: None if v is None else " ".join(v)  # noqa: E731
    return apply_overrides(
        scene, width=args.width, height=args.height, fov=args.fov, eye=vec(args.eye),
        target=vec(args.target), up=vec(args.up), scheme=args.scheme,
        max_memory=getattr(args, "max_memory", None), **overrides,
    )


def run(argv=None):
    """Run the command line as the whole process: :func:`main`, then exit with its code."""
    _exit_now(main(argv, own_process=True))


def main(argv=None, own_process: bool = False) -> int:
    """Run the command line; returns the exit code (0 ok, 2 bad input or usage).

    own_process: this process exists only to run this command (:func:`run`), so the
    process-wide shortcut of :func:`_trim_numba` is allowed.
    """
    parser = build_parser()
    try:
        args, extra = parser.parse_known_args(argv)
        if extra:  # name the subcommand whose options these are not
            sub = parser._subparsers._group_actions[0].choices.get(getattr(args, "command", None))
            (sub or parser).error("unrecognized arguments: " + " ".join(extra))
    except SystemExit as exc:  # --help / --version exit 0, usage errors exit 2
        return int(exc.code or 0) if not isinstance(exc.code, str) else 2
    args.own_process = own_process
    from subtrace.errors import SubtraceError

    try:
        with _one_line_warnings():
            return args.func(args)
    except SubtraceError as exc:
        print(f"{PROG}: error: {_one_line(str(exc))}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # `subtrace info | head`: stop quietly (Python docs' recipe)
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        except (OSError, ValueError):
            pass
        return 1


def _trim_numba(args) -> None:
    """Trim Numba's set-up (:func:`subtrace.runtime.jit.trim_loader`) in a process of its
    own (:func:`run`); in-process callers (tests) keep Numba as it is."""
    if getattr(args, "own_process", False):
        from subtrace.runtime.jit import trim_loader

        trim_loader()


def _exit_now(code: int):
    """End the process with ``code`` once output is flushed and the exit handlers have run,
    skipping the interpreter's teardown of every module (Numba's typing registries alone
    take about 0.2 s to free). Everything written was closed before this point."""
    import atexit

    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # closed or broken pipe: nothing more can be said
            pass
    atexit._run_exitfuncs()
    os._exit(code)


def _one_line(text: str) -> str:
    return " ".join(part.strip() for part in text.splitlines() if part.strip())


class _one_line_warnings:
    """Show a SubtraceWarning as ``subtrace: warning: <message>`` (one line, no source)."""

    def __enter__(self):
        import warnings

        self._saved = warnings.showwarning
        saved = self._saved

        def show(message, category, filename, lineno, file=None, line=None):
            from subtrace.errors import SubtraceWarning

            if issubclass(category, SubtraceWarning):
                print(f"{PROG}: warning: {_one_line(str(message))}", file=file or sys.stderr)
            else:
                saved(message, category, filename, lineno, file, line)

        warnings.showwarning = show
        return self

    def __exit__(self, *exc):
        import warnings

        warnings.showwarning = self._saved
        return False


# --------------------------------------------------------------------------------------
# subtrace info
# --------------------------------------------------------------------------------------


def _cmd_info(args) -> int:
    from subtrace import load_cage

    _trim_numba(args)
    if args.cage is None:
        from subtrace.data import sample_cage_path

        path = sample_cage_path()
        label = f"{path} (built-in sample: Spot by Keenan Crane, public domain)"
    else:
        path = args.cage
        label = str(path)
    cage = load_cage(path, scheme=args.scheme)
    rows = [("file", label)] + cage_report(cage, args.level)
    width = max(len(k) for k, _ in rows) + 1
    for key, value in rows:
        print(f"{key + ':':<{width}} {value}")
    return 0


# --------------------------------------------------------------------------------------
# subtrace render
# --------------------------------------------------------------------------------------


def _cmd_render(args) -> int:
    inputs = list(args.inputs)
    # the default scene lives in the package: write into the working directory
    if not inputs and args.output is None:
        args.output = "render.exr"
    scene = _scene_from_inputs(inputs, args, tolerance=args.tolerance,
                               tolerance_deg=args.tolerance_deg, output=args.output)
    out = scene.output or "render.exr"
    png = os.path.splitext(out)[0] + ".png" if args.png else scene.preview
    from subtrace.io.exr import check_writable, write_exr

    check_writable(out)
    if png:
        check_writable(png)
    from subtrace.render import render_scene, result_attributes

    _trim_numba(args)
    from subtrace.runtime.progress import ProgressBar

    progress = ProgressBar() if sys.stderr.isatty() and not args.quiet else None
    result = render_scene(scene, threads=args.threads, accel=args.accel, progress=progress)
    import time

    t0 = time.perf_counter()
    write_exr(out, result.channels, result_attributes(result, scene), png_path=png)
    st = result.stats
    if not args.quiet:
        cam = result.camera
        print(
            f"{out}: {cam.width}x{cam.height}, tolerance "
            f"{result.tolerance_rad / cam.pixel_angle():.3g} px, {st.pixels_covered} pixels "
            f"covered; {st.patches_refined} of {st.patches} patches refined, "
            f"{st.micro_triangles} micro-triangles, deepest level {st.max_depth}; "
            f"total {st.time_total:.3f} s (load {st.time_load:.3f}, preprocess "
            f"{st.time_preprocess:.3f}, refine {st.time_refine:.3f}, trace {st.time_trace:.3f}, "
            f"shade {st.time_shade:.3f}, write {time.perf_counter() - t0:.3f})"
            + (f"; preview {png}" if png else "")
        )
    return 0


# --------------------------------------------------------------------------------------
# subtrace sweep
# --------------------------------------------------------------------------------------


def _cmd_sweep(args) -> int:
    """Sweep the tolerances (:func:`subtrace.sweep.sweep`); the table on stdout, a progress
    bar on stderr when it is a terminal."""
    from subtrace.runtime.progress import ProgressBar
    from subtrace.sweep import (check_reference, check_repeat, check_tolerances,
                        format_table, sweep)

    tols = check_tolerances(args.tolerances, key="--tolerances")
    reference = check_reference(args.reference_tolerance, tols, key="--reference-tolerance")
    repeat = check_repeat(args.repeat, key="--repeat")
    scenes = [_scene_from_inputs([path], args) for path in args.inputs] or [
        _scene_from_inputs([], args)]
    progress = ProgressBar() if sys.stderr.isatty() and not args.quiet else None
    _trim_numba(args)
    records = sweep(scenes, tols, reference_tolerance=reference, repeat=repeat,
                    output_dir=args.output, threads=args.threads, accel=args.accel,
                    progress=progress)
    if not args.quiet:
        print(format_table(records))
        print(f"wrote {os.path.join(args.output, 'sweep.csv')}, sweep.json, plots and images "
              f"in {args.output}")
    return 0


# --------------------------------------------------------------------------------------
# subtrace intersect
# --------------------------------------------------------------------------------------


def _cmd_intersect(args) -> int:
    """Every hit of the lines of a CSV with a cage's limit surface
    (:func:`subtrace.lines.api.intersect_lines`), written as CSV or JSON (temporary file, then
    rename: no partial output)."""
    import json
    import math
    import tempfile

    import numpy as np

    from subtrace.mesh.cage import load_cage
    from subtrace.errors import SubtraceError
    from subtrace.lines.api import intersect_lines

    def number(text, key):
        try:
            return float(text)
        except ValueError:
            raise SubtraceError(f"--{key} {text}: expected a number") from None

    precision = number(args.precision, "precision")
    if not (precision > 0 and math.isfinite(precision)):
        raise SubtraceError(f"--precision {args.precision}: expected a finite number > 0")
    t_range = (number(args.t_min, "t-min"), number(args.t_max, "t-max"))
    for value, key in zip(t_range, ("t-min", "t-max")):
        if math.isnan(value):
            raise SubtraceError(f"--{key} {value}: expected a number (or -inf / inf), not nan")
    if not t_range[0] < t_range[1]:
        raise SubtraceError(f"--t-max {args.t_max}: expected a number above --t-min "
                            f"{args.t_min}")
    data = _read_lines_csv(args.lines)
    cage = load_cage(args.cage, scheme=args.scheme)
    from subtrace import config
    from subtrace.io.obj import check_coordinates, check_valences

    check_coordinates(cage.path, cage.points, config.MAX_COORDINATE)
    check_valences(cage.path, cage.face_sizes, np.diff(cage.base.vert_edge_offsets),
                   config.MAX_VALENCE, cage.scheme == "catmark")
    out = args.output
    if out is not None:
        folder = os.path.dirname(os.path.abspath(out))
        if not os.path.isdir(folder):
            raise SubtraceError(f"{out}: no such folder {folder}")
    _trim_numba(args)
    hits = intersect_lines(cage, data[:, :3], data[:, 3:], precision, t_range=t_range,
                           mode="first" if args.first else "all", threads=args.threads)
    if args.json:
        text = json.dumps({
            "precision": precision, "lines": int(len(data)),
            "hits": [{"line": int(hits.line[k]), "t": float(hits.t[k]),
                      "point": hits.point[k].tolist(), "ptex": int(hits.ptex[k]),
                      "uv": hits.uv[k].tolist(), "normal": hits.normal[k].tolist(),
                      "tangent": bool(hits.tangent[k])} for k in range(len(hits))],
        }, indent=1) + "\n"
    else:
        lines = ["line,t,x,y,z,ptex,u,v,nx,ny,nz,tangent"]
        ln, tt, pt = hits.line.tolist(), hits.t.tolist(), hits.point.tolist()
        px, uvs, nrm = hits.ptex.tolist(), hits.uv.tolist(), hits.normal.tolist()
        for k in range(len(hits)):
            p, uv, nr = pt[k], uvs[k], nrm[k]
            lines.append(f"{ln[k]},{tt[k]!r},{p[0]!r},{p[1]!r},{p[2]!r},"
                         f"{px[k]},{uv[0]!r},{uv[1]!r},{nr[0]!r},{nr[1]!r},{nr[2]!r},"
                         f"{int(hits.tangent[k])}")
        text = "\n".join(lines) + "\n"
    if out is None:
        sys.stdout.write(text)
        return 0
    try:
        fd, tmp = tempfile.mkstemp(prefix=".subtrace-", dir=os.path.dirname(os.path.abspath(out)))
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        os.replace(tmp, out)
    except OSError as exc:
        raise SubtraceError(f"{out}: {exc.strerror or exc}") from None
    return 0


_LINE_COLUMNS = ("ox", "oy", "oz", "dx", "dy", "dz")


def _read_lines_csv(path):
    """(n, 6) float64 origins and directions from a CSV with a header naming the columns
    ox,oy,oz,dx,dy,dz (others are ignored). Raises SubtraceError naming the file, the line
    and the problem: an unreadable or non-UTF-8 file, no header, a missing column, a row of
    the wrong length, a value that is not a finite number, a zero direction."""
    import csv
    import math

    import numpy as np

    from subtrace.errors import SubtraceError
    from subtrace.io.text import BadByte, utf8_text

    try:
        with open(path, "rb") as fh:
            raw = fh.read()
    except OSError as exc:
        raise SubtraceError(f"{path}: cannot read the lines: {exc.strerror or exc}") from None
    try:
        text = utf8_text(raw)
    except BadByte as err:
        raise SubtraceError(f"{path}:{err.line}: {err}; save the file as UTF-8") from None
    if not text.strip():
        raise SubtraceError(f"{path}: empty file: expected a header ox,oy,oz,dx,dy,dz and "
                            "a row of numbers per line")
    reader = csv.reader(text.splitlines())
    header = [h.strip() for h in next(reader)]
    missing = [c for c in _LINE_COLUMNS if c not in header]
    if missing:
        raise SubtraceError(f"{path}:{reader.line_num}: missing column(s) {', '.join(missing)} "
                            "(expected a header ox,oy,oz,dx,dy,dz)")
    index = [header.index(c) for c in _LINE_COLUMNS]
    rows = []
    for row in reader:
        where = f"{path}:{reader.line_num}"
        if not any(cell.strip() for cell in row):
            continue  # blank line
        if len(row) != len(header):
            raise SubtraceError(f"{where}: expected {len(header)} values "
                                f"({','.join(header)}), got {len(row)}")
        values = []
        for c, k in zip(_LINE_COLUMNS, index):
            cell = row[k].strip()
            try:
                v = float(cell)
            except ValueError:
                raise SubtraceError(f"{where}: {c}: {cell!r} is not a number") from None
            if not math.isfinite(v):
                raise SubtraceError(f"{where}: {c}: {cell!r} is not a finite number")
            values.append(v)
        if values[3] == values[4] == values[5] == 0.0:
            raise SubtraceError(f"{where}: the direction (0, 0, 0) is zero: a line needs a "
                                "direction")
        rows.append(values)
    return np.array(rows, dtype=np.float64).reshape(-1, 6)


# --------------------------------------------------------------------------------------
# subtrace compare
# --------------------------------------------------------------------------------------


def _cmd_compare(args) -> int:
    """Compare two images; exit code by idiff's convention (see the subparser)."""
    import json

    from subtrace.compare import (EXIT_MISMATCH, EXIT_UNREADABLE, ImageMismatchError,
                          UnreadableImageError, compare_images)
    from subtrace.errors import SubtraceError

    thresholds = _compare_thresholds(args)
    png = None
    if args.png:
        if not args.diff:
            raise SubtraceError("--png writes the heat map of --diff: give --diff OUT.exr too")
        png = os.path.splitext(args.diff)[0] + ".png"
    if args.diff:
        from subtrace.io.exr import check_writable

        check_writable(args.diff)
        if png:
            check_writable(png)
    try:
        result = compare_images(args.image_a, args.image_b, thresholds, flip=not args.no_flip)
    except (UnreadableImageError, ImageMismatchError) as exc:
        print(f"{PROG}: error: {_one_line(str(exc))}", file=sys.stderr)
        return EXIT_UNREADABLE if isinstance(exc, UnreadableImageError) else EXIT_MISMATCH
    if args.diff:
        result.write_diff(args.diff, png_path=png)
    if args.json:
        report = {"a": args.image_a, "b": args.image_b, **result.as_dict()}
        if args.diff:
            report["diff"] = args.diff
        print(json.dumps(report, indent=2))
    else:
        print(f"A: {args.image_a}\nB: {args.image_b}")
        print(result.table())
        if args.diff:
            print(f"difference: {args.diff}" + (f", heat map: {png}" if png else ""))
    return result.exit_code


def _compare_thresholds(args) -> dict:
    """--fail/--warn/... values as {group: {field: value}}; a bare value is the colour
    group's. Raises SubtraceError naming the option for a bad group or number."""
    from subtrace.compare import GROUPS
    from subtrace.errors import SubtraceError

    thresholds: dict = {}
    for name in ("fail", "failpercent", "warn", "warnpercent", "hardfail"):
        for text in getattr(args, name):
            group, _, value = text.rpartition("=")
            group = group.strip() or "colour"
            if group not in GROUPS:
                raise SubtraceError(
                    f"--{name} {text}: unknown channel group {group!r}: use one of "
                    f"{', '.join(GROUPS)}"
                )
            try:
                number = float(value)
            except ValueError:
                number = float("nan")
            if not number >= 0:  # also NaN
                raise SubtraceError(f"--{name} {text}: expected a number >= 0, got {value!r}")
            thresholds.setdefault(group, {})[name] = number
    return thresholds


def cage_report(cage, level: int | None = None) -> list[tuple[str, str]]:
    """The rows ``subtrace info`` prints for ``cage`` (key, value), in order."""
    import numpy as np

    base = cage.base
    opts = cage.options
    rows: list[tuple[str, str]] = []
    scheme_name = "Catmull-Clark" if cage.scheme == "catmark" else "Loop"
    rows.append(("scheme", f"{cage.scheme} ({scheme_name})"))
    if cage.scheme == "catmark":
        tri_rule = "smooth" if opts.smooth_triangles else "catmark"
    else:
        tri_rule = "n/a (Loop)"
    rows.append(
        (
            "options",
            f"boundary {BOUNDARY_NAMES.get(opts.boundary, str(opts.boundary))}, "
            f"crease method {'chaikin' if opts.chaikin else 'uniform'}, "
            f"triangle rule {tri_rule}",
        )
    )

    n_v, n_f, n_e = base.n_verts, base.n_faces, base.n_edges
    rows.append(("vertices", str(n_v)))
    rows.append(("faces", str(n_f)))
    rows.append(("edges", str(n_e)))
    sizes, counts = np.unique(cage.face_sizes, return_counts=True)
    rows.append(
        ("face sizes", ", ".join(f"{_size_name(int(s))} {int(c)}" for s, c in zip(sizes, counts)))
    )

    edge_uses = np.diff(base.edge_face_offsets)
    has_faces = np.diff(base.vert_face_offsets) > 0
    interior_manifold_edge = (edge_uses == 2) & ~base.edge_nonmanifold
    # boundary: one incident face; degenerate edges (a face repeating a vertex) also have
    # one, but OpenSubdiv treats them as non-manifold, and so are they counted here
    boundary_edge = (edge_uses == 1) & ~base.edge_nonmanifold
    rows.append(("boundary edges", str(int(np.count_nonzero(boundary_edge)))))
    rows.append(
        (
            "non-manifold",
            f"{int(np.count_nonzero(base.edge_nonmanifold))} edges, "
            f"{int(np.count_nonzero(~base.vert_manifold & has_faces))} vertices",
        )
    )
    rows.append(("isolated vertices", str(int(np.count_nonzero(~has_faces)))))

    # creases: interior manifold edges with a tag (boundary / non-manifold edges are sharp
    # anyway, so a tag on them changes nothing and is not counted)
    s_e = base.edge_sharpness[interior_manifold_edge]
    n_inf = int(np.count_nonzero(s_e >= _INF))
    n_semi = int(np.count_nonzero((s_e > 0) & (s_e < _INF)))
    rows.append(
        ("crease edges", f"{n_inf + n_semi} ({n_semi} semi-sharp, {n_inf} infinitely sharp)")
    )
    s_v = base.vert_sharpness
    n_vinf = int(np.count_nonzero(s_v >= _INF))
    n_vsemi = int(np.count_nonzero((s_v > 0) & (s_v < _INF)))
    rows.append(
        (
            "sharp vertices",
            f"{n_vinf + n_vsemi} ({n_vsemi} semi-sharp, {n_vinf} infinitely sharp; corner "
            "tags plus automatic corners / non-manifold vertices)",
        )
    )
    rows.append(("hole faces", str(int(np.count_nonzero(base.face_hole)))))

    valence = np.diff(base.vert_edge_offsets)
    used = valence[has_faces]
    if len(used):
        rows.append(("valence", f"{int(used.min())}..{int(used.max())}"))
    else:
        rows.append(("valence", "n/a"))
    rows.append(("extraordinary vertices", str(extraordinary_count(cage))))
    rows.append(("Euler characteristic", f"{n_v - n_e + n_f} (V - E + F)"))

    lo, hi = cage.points.min(axis=0), cage.points.max(axis=0)
    rows.append(("cage bounds", _bounds(lo, hi)))
    rows.append(("limit bounds", _limit_bounds(cage)))

    if level is not None:
        lev = cage.level_topology(level)
        rows.append(
            (
                f"level {level}",
                f"{lev.n_verts} vertices, {lev.n_faces} faces, {lev.n_edges} edges, "
                f"Euler characteristic {lev.n_verts - lev.n_edges + lev.n_faces}",
            )
        )
    return rows


_INF = 10.0  # sharpness at or above this is infinite (config.SHARPNESS_INFINITE)
_SIZE_NAMES = {3: "triangles", 4: "quads", 5: "pentagons", 6: "hexagons"}


def _size_name(size: int) -> str:
    return _SIZE_NAMES.get(size, f"{size}-gons")


def extraordinary_count(cage) -> int:
    """Manifold vertices whose valence is not the regular one of the scheme.

    Regular valence: 4 (Catmark) / 6 (Loop) for interior vertices, 3 / 4 on a boundary;
    boundary vertices with a single face (corners) count as regular. Non-manifold and
    isolated vertices are reported separately and not counted here.
    """
    import numpy as np

    base = cage.base
    reg = 4 if cage.scheme == "catmark" else 6
    valence = np.diff(base.vert_edge_offsets)
    n_faces = np.diff(base.vert_face_offsets)
    boundary = valence == n_faces + 1
    regular = np.where(boundary, (valence == reg // 2 + 1) | (n_faces == 1), valence == reg)
    return int(np.count_nonzero(base.vert_manifold & (n_faces > 0) & ~regular))


def _fmt(v) -> str:
    return "(" + ", ".join(f"{x:.6g}" for x in v) + ")"


def _bounds(lo, hi) -> str:
    return f"min {_fmt(lo)} max {_fmt(hi)} size {_fmt(hi - lo)}"


def _limit_bounds(cage) -> str:
    try:
        P, _, _ = cage.limit(1)
    except ModuleNotFoundError as exc:  # limit evaluation not part of this build yet
        if exc.name and exc.name.startswith("subtrace"):
            return "n/a (limit evaluation is not available in this build)"
        raise
    # vertices on hole faces only, or on no face at all, are not on the surface
    on_surface = _surface_vertices(cage.level_topology(1))
    if not on_surface.any():
        return "n/a (every face is a hole)"
    P = P[on_surface]
    return _bounds(P.min(axis=0), P.max(axis=0)) + " (limit points of the level-1 vertices)"


def _surface_vertices(lev):
    """(V,) bool: the vertex is a corner of a face that is not a hole."""
    import numpy as np

    sizes = np.diff(lev.face_offsets)
    corner_in_hole = np.repeat(lev.face_hole, sizes)
    keep = np.zeros(lev.n_verts, dtype=bool)
    keep[lev.face_verts[~corner_in_hole]] = True
    return keep


if __name__ == "__main__":  # python -m subtrace.cli.main
    run()
