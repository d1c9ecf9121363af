"""The ``subtrace`` argument parser: one sub-parser per command, built by a function each.

Usage errors are one line, ``subtrace: error: <problem> (see <command> --help)``, exit code 2
(design invariant 7). Only the standard library and :mod:`subtrace.version` are imported:
``subtrace --help`` and ``--version`` must not load numpy, Numba or OpenImageIO. Each command
is run by the module of its name, ``subtrace.cli.<command>`` (:data:`COMMANDS`).
"""

from __future__ import annotations

import argparse
import sys

from subtrace.cli.common import PROG, one_line
from subtrace.version import VERSION

# The commands, in the order --help lists them; each is run by subtrace.cli.<name>.execute.
COMMANDS = ("info", "render", "compare", "sweep", "intersect", "warmup")
# The threshold options of ``compare``, each GROUP=VALUE or a bare VALUE, repeatable.
THRESHOLD_OPTIONS = ("fail", "failpercent", "warn", "warnpercent", "hardfail")


def level_arg(text: str) -> int:
    """An integer >= 0 (a subdivision level, a thread count), for argparse ``type=``."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid level {text!r}: expected an integer >= 0")
    if value < 0:
        raise argparse.ArgumentTypeError(f"invalid level {value}: expected an integer >= 0")
    return value


class Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line, ``subtrace: error: <problem>
    (see <command> --help)``, exit code 2 (design invariant 7), instead of argparse's usage
    text followed by the error. ``commands`` maps a command's name to its sub-parser."""

    commands: dict

    def error(self, message):
        unknown = "unrecognized arguments: "
        if message.startswith(unknown):
            first = message[len(unknown):].split()[0]
            kind = "option" if first.startswith("-") else "argument"
            message = f"unknown {kind} {first!r}"
        print(f"{PROG}: error: {one_line(message)} (see {self.prog} --help)", file=sys.stderr)
        raise SystemExit(2)


def build_parser() -> Parser:
    """The whole command line: ``--version`` and a sub-parser per command of COMMANDS."""
    parser = Parser(
        prog=PROG,
        description="Exact Catmull-Clark and Loop subdivision surfaces (OpenSubdiv rules).",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {VERSION}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    adders = {"info": _add_info, "render": _add_render, "compare": _add_compare,
              "sweep": _add_sweep, "intersect": _add_intersect, "warmup": _add_warmup}
    parser.commands = {name: adders[name](sub) for name in COMMANDS}
    return parser


def _add_info(sub) -> argparse.ArgumentParser:
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
    info.add_argument("cage", nargs="?", metavar="CAGE.obj",
                      help="OBJ control cage or USD stage (all its meshes as one cage)")
    info.add_argument(
        "--scheme",
        metavar="S",
        help="catmark (Catmull-Clark) or loop; default: loop for all-triangle cages, "
        "catmark otherwise",
    )
    _add_boundary_option(info)
    info.add_argument(
        "--level",
        type=level_arg,
        metavar="N",
        help="also print the counts after N uniform refinements",
    )
    return info


def _add_render(sub) -> argparse.ArgumentParser:
    render = sub.add_parser(
        "render",
        help="ray trace the exact limit surface of a scene or of OBJ cages to EXR",
        description=(
            "Render a TOML scene, or OBJ cages or USD stages (with the stage's camera and "
            "distant lights, else an automatic camera), as the exact "
            "Catmull-Clark / Loop limit surface: patches refined only where a ray reaches "
            "them and only until they are below the angular tolerance, with adaptive "
            "anti-aliasing (edge pixels get up to --samples rays, 4 by default; the others "
            "one). What a scene or a stage leaves out, every input gets alike: 1280x720, "
            "a soft gradient behind, a key and a fill light with shadows, a weak headlight "
            "and a shadow-catching ground. Without inputs the built-in default scene "
            "(Spot) is rendered. Writes a "
            "multi-channel EXR (R,G,B,A, Z, N.X/N.Y/N.Z, level, patch_id, object_id, u, v, "
            "P.X/P.Y/P.Z), or by the output's extension a picture of the colour."
        ),
    )
    render.add_argument("inputs", nargs="*", metavar="SCENE.toml | CAGE.obj | STAGE.usd",
                        help="one TOML scene, or one or more OBJ cages or USD stages")
    render.add_argument("-o", "--output", metavar="OUT.exr",
                        help="output file (default: the scene's output, else render.exr): "
                             "the multi-channel EXR (.exr), or by its extension a picture "
                             "of the colour in any format OpenImageIO writes: sRGB .png, "
                             ".jpg, .tif, .bmp, .webp, .tga, ..., linear .hdr; another "
                             "extension, or none, is an error")
    _add_camera_options(render)
    tol = render.add_mutually_exclusive_group()
    tol.add_argument("--tolerance", metavar="PIXELS",
                     help="angular tolerance in pixels at the image centre (default 1)")
    tol.add_argument("--tolerance-deg", metavar="DEG", help="angular tolerance in degrees")
    _add_render_options(render)
    render.add_argument("--color", metavar="RGB",
                        help="every object's diffuse colour: r,g,b in 0..1 (linear) or "
                             "#rrggbb (sRGB)")
    render.add_argument("--background", metavar="RGB[,RGB]",
                        help="background colour, or two: a vertical gradient top,bottom "
                             "(e.g. #6b7889,#181a1f)")
    render.add_argument("--samples", metavar="N",
                        help="rays per pixel at most: edge pixels (silhouettes, folds, shadow "
                             "edges) get up to N stratified rays, the others keep one "
                             "(default: the scene's, else 4)")
    render.add_argument("--ao", metavar="SAMPLES",
                        help="ambient occlusion: SAMPLES cosine-weighted rays from every hit "
                             "(0: none; default: the scene's, else 0)")
    render.add_argument("--light", action="append", metavar="KIND:KEY=VALUE,...",
                        help="a light instead of the scene's (repeat it for more): KIND "
                             "sun or directional (direction=X,Y,Z, angle), point "
                             "(position), sphere (position, radius), quad (position, u, v) "
                             "or disk (position, normal, radius), each with samples, "
                             "color=R,G,B and intensity if wanted: the keys of a [[light]] "
                             "table, a vector as 3 numbers, e.g. sun:direction=0,-1,-1 or "
                             "sphere:position=1,2,3,radius=0.5,intensity=4")
    render.add_argument("--no-shadows", dest="shadows", action="store_false", default=None,
                        help="no shadow rays (on by default where the scene has lights)")
    render.add_argument("--transparent", action="store_true", default=None,
                        help="picture outputs that store alpha (.png, .tif, .webp, .tga, "
                             "...): alpha 0 where nothing was hit (default: opaque, over "
                             "the background)")
    render.add_argument("--png", action="store_true",
                        help="also write an sRGB PNG preview next to the output (never over "
                             "it)")
    render.add_argument("--bit-depth", choices=("8", "16"), default="8",
                        help="bits per channel of a .png or .tif output (default 8)")
    render.add_argument("--turntable", metavar="N",
                        help="render N frames whose eyes orbit the target about the up axis, "
                             "one full turn, to numbered outputs (a run of # in -o is the "
                             "frame number, e.g. spin.####.exr; else .#### is added)")
    render.add_argument("--frames", metavar="A:B[:STEP]",
                        help="only these frames of --turntable (Python's range; default "
                             "all); without --turntable, these time codes of a USD stage's "
                             "animation (':' for all of them), each read at its time")
    render.add_argument("--dask", nargs="?", const="", metavar="ADDRESS",
                        help="render the frames as tasks on a Dask cluster: the scheduler at "
                             "ADDRESS (tcp://host:8786), or without one a local cluster of "
                             "worker processes (pip install 'subtrace[dask]')")
    render.add_argument("--crop", nargs=4, metavar=("X0", "Y0", "X1", "Y1"),
                        help="render only pixels X0..X1-1 of columns and Y0..Y1-1 of rows: "
                             "the EXR holds that tile as its data window (the same pixels, "
                             "bit for bit, as the whole render's)")
    render.add_argument("--tile", metavar="N",
                        help="render in tiles of at most N x N pixels (with --dask: one task "
                             "per tile) and put them together")
    render.add_argument("--resume", action="store_true",
                        help="with frames: leave out the frames whose output is already "
                             "there (a complete image: outputs are written whole or not at "
                             "all)")
    render.add_argument("--quiet", action="store_true", help="print nothing on success")
    return render


def _add_compare(sub) -> argparse.ArgumentParser:
    compare = sub.add_parser(
        "compare",
        help="compare two EXR renders channel group by channel group (idiff-style verdict)",
        description=(
            "Compare two EXR images by channel group: colour (R,G,B: RMSE, PSNR, max abs, "
            "mean FLIP), coverage (A: pixels with the surface in one image only), depth (Z: "
            "relative error), normals (N.X,N.Y,N.Z: angle in degrees) and ids (level, "
            "patch_id, object_id: pixels that differ). A group fails when more than "
            "FAILPERCENT % of its pixels have an error above FAIL, or one above HARDFAIL; it "
            "warns likewise with WARN and WARNPERCENT. Threshold options take GROUP=VALUE "
            "(repeatable) or a bare VALUE for the colour group. Exit codes as idiff's: 0 pass, "
            "1 warning, 2 failure (or bad options), 3 size or channel mismatch, 4 a file that "
            "cannot be read."
        ),
    )
    compare.add_argument("image_a", metavar="A.exr", help="first image (the test image)")
    compare.add_argument("image_b", metavar="B.exr", help="second image (the reference)")
    for name in THRESHOLD_OPTIONS:
        compare.add_argument(f"--{name}", action="append", default=[],
                             metavar="[GROUP=]VALUE",
                             help=f"{name} threshold of a group (defaults: docs/guide/"
                                  "compare-sweep-intersect.md)")
    compare.add_argument("--diff", metavar="OUT.exr",
                         help="write the per-pixel differences and a normalised 'heat' channel")
    compare.add_argument("--png", action="store_true",
                         help="with --diff: also write a heat-map PNG next to it")
    compare.add_argument("--json", action="store_true", help="print the metrics as JSON")
    compare.add_argument("--html", metavar="REPORT.html",
                         help="also write one self-contained page (images inlined, no network): "
                              "A and B under a slider, difference, heat and ids maps with "
                              "colour keys, the group table")
    compare.add_argument("--channels", nargs="+", metavar="OURS=THEIRS",
                         help="read another renderer's channels as subtrace's, by name or "
                              "prefix (e.g. N=Normal Z=depth)")
    compare.add_argument("--only", action="append", metavar="GROUP",
                         help="compare only this channel group (repeatable)")
    compare.add_argument("--ignore", action="append", metavar="GROUP",
                         help="leave this channel group out (repeatable)")
    compare.add_argument("--no-flip", action="store_true",
                         help="skip the FLIP metric (the slowest one on large images)")
    return compare


def _add_sweep(sub) -> argparse.ArgumentParser:
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
    sweep.add_argument("--html", metavar="REPORT.html",
                       help="also write one self-contained page (images inlined, no network) "
                            "of the table, the plots and each tolerance's render and "
                            "refinement-level heat map")
    sweep.add_argument("--quiet", action="store_true",
                       help="print nothing on success (no table, no progress bar)")
    return sweep


def _add_intersect(sub) -> argparse.ArgumentParser:
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
    intersect.add_argument("cage", metavar="CAGE.obj", help="OBJ cage or USD stage")
    intersect.add_argument("--scheme", metavar="S",
                           help="catmark or loop (default: loop for an all-triangle cage, "
                                "else catmark)")
    _add_boundary_option(intersect)
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
    intersect.add_argument("--threads", type=level_arg, metavar="N",
                           help="worker threads (default: all cores)")
    return intersect


def _add_warmup(sub) -> argparse.ArgumentParser:
    warmup = sub.add_parser(
        "warmup",
        help="compile every kernel into the kernel cache and print where it is",
        description=(
            "Compile the Numba kernels of every command (renders of both schemes and of "
            "trimmed NURBS surfaces, line queries, the cage report) into the kernel cache, "
            "so that later commands load them. The cache is $SUBTRACE_CACHE_DIR (else "
            "$NUMBA_CACHE_DIR, else ~/.cache/subtrace)/numba-<key>, the key a hash of the "
            "sources' bytes, the Numba and Python versions and the CPU: workers that share "
            "one folder share the kernels. Prints the folder, a line of progress after each "
            "command (commands done / all, kernels in the cache, seconds) and at least every "
            "10 s, and what the cache holds."
        ),
    )
    warmup.add_argument("--jobs", metavar="N",
                        help="commands compiled at once, each a process (default: the cores)")
    warmup.add_argument("--quiet", action="store_true", help="print nothing on success")
    return warmup


BOUNDARY_CHOICES = ("none", "edge-only", "edge-and-corner")


def _add_boundary_option(parser) -> None:
    """``--boundary``: how the limit surface ends at the cage's open edges, for every object
    (replaces the OBJ's ``interpolateboundary`` tag and a scene's ``boundary`` keys)."""
    parser.add_argument(
        "--boundary", choices=BOUNDARY_CHOICES, default=None,
        help="boundary interpolation for every object: edge-and-corner (a single quad stays "
             "a square, corners kept sharp), edge-only (boundary curves are smooth B-splines "
             "and corners round off) or none (boundary faces are left out); default: the "
             "OBJ's interpolateboundary tag, else edge-only (OpenSubdiv's OBJ default)")


def _add_render_options(parser) -> None:
    """The options of how objects are rendered, shared by ``render`` and ``sweep``."""
    parser.add_argument("--scheme", metavar="S", help="catmark or loop, for every object")
    _add_boundary_option(parser)
    parser.add_argument("--camera", metavar="PRIM",
                        help="a USD stage's camera prim to render through, e.g. /World/Cam "
                             "(default: the stage's first camera, else an automatic one)")
    parser.add_argument("--threads", type=level_arg, metavar="N",
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
    parser.add_argument("--target", nargs=3, metavar=("X", "Y", "Z"), help="point looked at (default: the objects' centre)")
    parser.add_argument("--up", nargs=3, metavar=("X", "Y", "Z"), help="camera up vector")
