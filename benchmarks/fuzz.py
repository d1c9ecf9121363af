"""Long-running random fuzzer of subtrace's input readers (issue 8).

Mutates the bad-input corpus (tests/bad_inputs/) and valid cages and scenes (byte flips,
insertions of junk, truncation, line shuffles and duplications, number swaps) and feeds each
result to the OBJ reader (``subtrace.io.obj.read_obj``), the scene reader
(``subtrace.io.scene.load_scene``) and ``subtrace info``; a fraction of the cages
(``--render-fraction``) is rendered at 32x24 by ``subtrace render`` in a process of its own
(exit 0 with an image, or exit 2 with one error line and nothing left behind). An input passes when it reads or
raises a SubtraceError; anything else (another exception, a hang past ``--timeout``, a
multi-line or traceback-bearing ``info`` error) is a crash and the input is saved under
``--out``. Command lines of ``render``, ``info`` and ``intersect`` with random valid and
junk option values (as often as renders) must end with exit 0, or exit 2 and one error
line, with no temporary left. Free-form (NURBS) OBJ statements are in the corpus's ff_*
files, so their mutations are read and rendered too. USD stages (a text ``.usda`` written
here with ``pxr``: subdivision tags, creases, corners, holes, a transform, a camera, a
distant light, time samples) and the mesh formats read through trimesh (``.ply`` text and
binary, ``.stl``, ``.off``, ``.gltf``, ``.glb``, written here from the cube) are mutated the
same way and go through ``subtrace info`` (USD in a process of its own: a fault in the native
reader must not end the fuzzer) and, for a fraction, ``subtrace render``; each kind is left
out with a line when its optional library is missing. Prints inputs tried, outcomes by kind,
and crashes.

    python benchmarks/fuzz.py --seconds 3600 [--seed N] [--out fuzz_crashes] [--timeout 10]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import random
import re
import signal
import sys
import time
import traceback
import warnings
from collections import Counter
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CORPUS = REPO / "tests" / "bad_inputs"
NUMBER = re.compile(rb"-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?")
SWAPS = [b"0", b"-1", b"1", b"3", b"1e300", b"-1e308", b"nan", b"inf", b"0.5", b"99999999999",
         b"2/1/0", b"", b"1.5", b"-0", b"32768", b"180"]


class Hang(Exception):
    pass


def _alarm(signum, frame):
    raise Hang()


def seeds() -> tuple[list[bytes], list[bytes]]:
    """(OBJ seeds, TOML seeds): the corpus, the scenes' cages where present, the sample cage."""
    objs = [p.read_bytes() for p in sorted(CORPUS.glob("*.obj"))]
    tomls = [p.read_bytes() for p in sorted(CORPUS.glob("*.toml")) if p.name != "EXPECTED.toml"]
    from subtrace.data import sample_cage_path

    objs.append(Path(sample_cage_path()).read_bytes())
    shapes = REPO / "tests" / "oracle" / "shapes"
    objs += [p.read_bytes() for p in sorted(shapes.glob("*.obj"))[:40]
             if p.stat().st_size < 200_000]
    return objs, tomls


USDA_SEED = """#usda 1.0
(
    defaultPrim = "World"
    startTimeCode = 1
    endTimeCode = 3
    upAxis = "Y"
)

def Xform "World"
{
    def Mesh "Cage" (
        prepend apiSchemas = ["MaterialBindingAPI"]
    )
    {
        int[] cornerIndices = [0, 6]
        float[] cornerSharpnesses = [2, 10]
        int[] creaseIndices = [0, 1, 2, 3, 0]
        int[] creaseLengths = [5]
        float[] creaseSharpnesses = [1.5]
        int[] faceVertexCounts = [4, 4, 4, 4, 4, 3, 3]
        int[] faceVertexIndices = [0, 3, 2, 1, 4, 5, 6, 7, 0, 1, 5, 4, 2, 3, 7, 6, 1, 2, 6, 0, 4, 7, 3, 2, 6, 5]
        int[] holeIndices = [1]
        uniform token interpolateBoundary = "edgeAndCorner"
        point3f[] points.timeSamples = {
            1: [(-1, -1, -1), (1, -1, -1), (1, 1, -1), (-1, 1, -1), (-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1)],
            3: [(-1, -1, -1), (1, -1, -1), (1, 2, -1), (-1, 1, -1), (-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 2)],
        }
        color3f[] primvars:displayColor = [(0.8, 0.3, 0.2)]
        uniform token subdivisionScheme = "catmullClark"
        uniform token triangleSubdivisionRule = "smooth"
        token visibility = "inherited"
        double3 xformOp:translate = (0.5, 0, 0)
        float3 xformOp:rotateXYZ.timeSamples = {1: (0, 0, 0), 3: (0, 90, 0)}
        uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateXYZ"]
    }

    def Mesh "Tris"
    {
        int[] faceVertexCounts = [3, 3, 3, 3]
        int[] faceVertexIndices = [0, 1, 2, 0, 2, 3, 0, 3, 1, 1, 3, 2]
        point3f[] points = [(3, 0, 0), (4, 0, 0), (3, 1, 0), (3, 0, 1)]
        uniform token subdivisionScheme = "catmullClark"
        uniform token triangleSubdivisionRule = "smooth"
        uniform token purpose = "default"
    }

    def Camera "Cam"
    {
        float focalLength = 35
        float horizontalAperture = 36
        float verticalAperture = 24
        float2 clippingRange = (0.1, 1000)
        double3 xformOp:translate = (0, 1, 8)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }

    def DistantLight "Sun"
    {
        float inputs:intensity = 2
        color3f inputs:color = (1, 0.9, 0.8)
        float3 xformOp:rotateXYZ = (-45, 30, 0)
        uniform token[] xformOpOrder = ["xformOp:rotateXYZ"]
    }
}
"""


def format_seeds() -> list[tuple[str, bytes]]:
    """(extension, bytes) of the USD and mesh-format seeds: the stage above (when ``pxr``
    imports, so that the seed is one the installed reader opens) and the cube written by
    trimesh in every format subtrace reads through it (when trimesh imports)."""
    out = []
    try:
        from pxr import Usd
    except ImportError:
        print("fuzz: usd-core is not installed: no USD inputs", file=sys.stderr)
    else:
        stage = Usd.Stage.CreateInMemory()
        stage.GetRootLayer().ImportFromString(USDA_SEED)
        out.append((".usda", stage.GetRootLayer().ExportToString().encode()))
    try:
        import numpy as np
        import trimesh
    except ImportError:
        print("fuzz: trimesh is not installed: no PLY, STL, OFF or glTF inputs", file=sys.stderr)
        return out
    from subtrace.io.obj import read_obj

    d = read_obj(CORPUS / "cube.obj")
    starts = np.concatenate([[0], np.cumsum(d.face_sizes)])
    tris = [[d.face_verts[a], d.face_verts[a + k], d.face_verts[a + k + 1]]
            for a, n in zip(starts[:-1], d.face_sizes) for k in range(1, n - 1)]
    mesh = trimesh.Trimesh(d.points, np.array(tris), process=False)
    for ext, kwargs in [(".ply", {"encoding": "ascii"}), (".ply", {"encoding": "binary"}),
                        (".stl", {"file_type": "stl_ascii"}), (".stl", {}), (".off", {}),
                        (".gltf", {}), (".glb", {})]:
        data = mesh.export(file_type=kwargs.pop("file_type", ext[1:]), **kwargs)
        if isinstance(data, dict):  # gltf: the JSON with its buffer embedded
            data = trimesh.exchange.gltf.export_gltf(mesh, embed_buffers=True)["model.gltf"]
        out.append((ext, data if isinstance(data, bytes) else data.encode()))
    return out


def mutate(rng: random.Random, data: bytes) -> tuple[bytes, str]:
    """One to three random mutations of ``data``; returns (bytes, names of mutations)."""
    names = []
    for _ in range(rng.randint(1, 3)):
        kind = rng.choice(["flip", "insert", "truncate", "shuffle", "duplicate", "delete_line",
                           "number", "number", "number"])
        names.append(kind)
        if kind == "flip" and data:
            b = bytearray(data)
            for _ in range(rng.randint(1, 4)):
                i = rng.randrange(len(b))
                b[i] ^= 1 << rng.randrange(8)
            data = bytes(b)
        elif kind == "insert":
            i = rng.randint(0, len(data))
            junk = rng.choice([bytes(rng.randrange(256) for _ in range(rng.randint(1, 8))),
                               b"\r\n", b"\t", b"\\\n", b"/", b" 0", b"\x00", b"\xff\xfe"])
            data = data[:i] + junk + data[i:]
        elif kind == "truncate" and data:
            data = data[: rng.randrange(len(data))]
        elif kind in ("shuffle", "duplicate", "delete_line"):
            lines = data.split(b"\n")
            if kind == "shuffle":
                rng.shuffle(lines)
            elif kind == "duplicate":
                lines.insert(rng.randint(0, len(lines)), rng.choice(lines))
            elif len(lines) > 1:
                del lines[rng.randrange(len(lines))]
            data = b"\n".join(lines)
        elif kind == "number":
            spans = [m.span() for m in NUMBER.finditer(data)]
            if spans:
                a, b = rng.choice(spans)
                data = data[:a] + rng.choice(SWAPS) + data[b:]
    return data, "+".join(names)


def check_info_process(path: Path, timeout: float) -> str:
    """``subtrace info path`` in a process of its own (for USD: a fault in the native reader
    must not end the fuzzer): "ok" (exit 0) or "info-error" (exit 2, one error line); raise
    otherwise, ``Hang`` past ``timeout`` seconds."""
    import subprocess

    try:
        proc = subprocess.run([sys.executable, "-m", "subtrace.cli", "info", str(path)],
                              capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        raise Hang() from None
    errors = [line for line in proc.stderr.splitlines()
              if not line.startswith("subtrace: warning:")]
    if proc.returncode == 0 and not errors:
        return "ok"
    if proc.returncode == 2 and len(errors) == 1 and errors[0].startswith("subtrace: error: "):
        return "info-error"
    raise AssertionError(f"info exit {proc.returncode}, stderr {proc.stderr[-2000:]!r}")


def check(target: str, path: Path) -> str:
    """Run one target on ``path``: the outcome kind ("ok", "error:<Class>") or raise."""
    from subtrace.errors import SubtraceError

    if target == "obj":
        from subtrace.io.obj import read_obj

        try:
            read_obj(path)
        except SubtraceError as err:
            return f"error:{type(err).__name__}"
        return "ok"
    if target == "scene":
        from subtrace.io.scene import load_scene

        try:
            load_scene(path)
        except SubtraceError as err:
            return f"error:{type(err).__name__}"
        return "ok"
    # subtrace info: exit 0, or exit 2 with one error line and no traceback
    from subtrace.cli import main

    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        code = main(["info", str(path)])
    text = err.getvalue()
    errors = [line for line in text.splitlines() if not line.startswith("subtrace: warning:")]
    if code == 0:
        return "ok"
    if code == 2 and len(errors) == 1 and errors[0].startswith("subtrace: error: "):
        return "info-error"
    raise AssertionError(f"info exit {code}, stderr {text!r}")


def warm_render_cache(work: Path) -> None:
    """Render the cube once, untimed: the Numba cache is keyed by a hash of the sources, so
    after any source edit the first render compiles for 20-60 s (not a hang)."""
    import subprocess

    subprocess.run([sys.executable, "-m", "subtrace.cli", "render", str(work / "cube.obj"),
                    "--width", "8", "--height", "6", "--quiet", "-o",
                    str(work / "warm.exr")], capture_output=True, timeout=900)


def check_render(path: Path, timeout: float) -> str:
    """``subtrace render`` of the cage ``path`` at 32x24 in a process of its own (a kernel
    cannot be interrupted in-process): "ok" (exit 0 and an image), "render-error" (exit 2,
    one error line, no image and no temporary file left); raise otherwise, ``Hang`` past
    ``timeout`` seconds."""
    import subprocess

    out_dir = path.parent / "render_out"
    out_dir.mkdir(exist_ok=True)
    for old in out_dir.iterdir():
        old.unlink()
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "subtrace.cli", "render", str(path), "--width", "32",
             "--height", "24", "--quiet", "-o", str(out_dir / "r.exr")],
            capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        raise Hang() from None
    text = proc.stderr
    left = sorted(p.name for p in out_dir.iterdir())
    errors = [line for line in text.splitlines() if not line.startswith("subtrace: warning:")]
    if proc.returncode == 0 and left == ["r.exr"] and "Traceback" not in text:
        return "ok"
    if (proc.returncode == 2 and len(errors) == 1 and errors[0].startswith("subtrace: error: ")
            and not left):
        return "render-error"
    raise AssertionError(f"render exit {proc.returncode}, files {left}, stderr {text[-2000:]!r}")


# command-line options and the values tried for them: valid ones and junk (sizes stay small
# or are refused, so no trial renders a large image)
OPTION_VALUES = {
    "--width": ["16", "33", "1", "0", "-4", "abc", "1e9", "40000", "2.5", ""],
    "--height": ["12", "24", "1", "0", "-1", "x", "99999999999"],
    "--fov": ["30", "90", "179.9", "0", "180", "-5", "nan", "inf", "1e-12"],
    "--eye": ["0 0 5", "0 5 0", "1e300 0 0", "nan 0 0", "1 2", "a b c", "0,0,5"],
    "--target": ["0 0 0", "0 0 5", "1 1", "inf 0 0"],
    "--up": ["0 1 0", "0 0 1", "0 0 0", "1e-320 0 0", "x"],
    "--tolerance": ["1", "4", "0.5", "0", "-1", "nan", "1e-300", "1e300"],
    "--tolerance-deg": ["0.1", "0", "x"],
    "--scheme": ["catmark", "loop", "bilinear", ""],
    "--boundary": ["none", "edge-only", "edge-and-corner", "corners"],
    "--threads": ["1", "2", "64", "0", "-1", "two"],
    "--accel": ["bvh", "projection", "kd"],
    "--max-memory": ["500M", "1G", "1", "0", "-5M", "lots", "1e30"],
    "--bit-depth": ["8", "16", "32"],
}
OUTPUTS = ["r.exr", "r.png", "r.tif", "r.jpg", "r.txt", "missing/r.exr", ".", "r"]
INTERSECT_VALUES = {
    "--precision": ["1e-3", "0.1", "0", "-1", "nan", "inf", "x"],
    "--t-min": ["0", "-inf", "nan", "5", "x"],
    "--t-max": ["inf", "0", "1", "nan"],
    "--threads": ["1", "2", "64", "0"],
    "--boundary": ["none", "edge-and-corner", "x"],
    "--scheme": ["loop", "catmark", "z"],
}


def option_args(rng: random.Random, work: Path) -> tuple[list[str], str]:
    """A random command line for ``render``, ``info`` or ``intersect`` on the cube: a few
    options with valid or junk values (and the output's extension)."""
    command = rng.choice(["render", "render", "info", "intersect"])
    cube = str(work / "cube.obj")
    if command == "info":
        args = ["info", cube] + rng.choice([[], ["--level", rng.choice(["1", "0", "-1", "x"])],
                                            ["--boundary", rng.choice(["none", "y"])],
                                            ["--scheme", rng.choice(["loop", "q"])]])
    elif command == "intersect":
        lines = work / "lines.csv"
        lines.write_text("ox,oy,oz,dx,dy,dz\n0,0,5,0,0,-1\n0.3,0.2,-5,0,0,1\n")
        args = ["intersect", cube, "--lines", str(lines), "--precision", "1e-3",
                "-o", str(work / "opt_out" / "hits.csv")]
        for key in rng.sample(sorted(INTERSECT_VALUES), rng.randint(0, 3)):
            args += [key, rng.choice(INTERSECT_VALUES[key])]
    else:
        args = ["render", cube, "--width", "24", "--height", "18", "--quiet",
                "-o", str(work / "opt_out" / rng.choice(OUTPUTS))]
        for key in rng.sample(sorted(OPTION_VALUES), rng.randint(1, 4)):
            value = rng.choice(OPTION_VALUES[key])
            args += [key, *value.split()] if key in ("--eye", "--target", "--up") else [key, value]
        if rng.random() < 0.2:
            args.append("--png")
    return args, " ".join(args[2:])


def check_options(args: list[str], work: Path, timeout: float) -> str:
    """Run a command line from :func:`option_args` in a process of its own: "ok" (exit 0)
    or "option-error" (exit 2 and one error line), with nothing half-written left in the
    output folder either way; raise otherwise (``Hang`` past ``timeout`` seconds)."""
    import subprocess

    out_dir = work / "opt_out"
    out_dir.mkdir(exist_ok=True)
    for old in out_dir.iterdir():
        if old.is_file():
            old.unlink()
    try:
        proc = subprocess.run([sys.executable, "-m", "subtrace.cli", *args],
                              capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        raise Hang() from None
    text = proc.stderr
    temps = [p.name for p in out_dir.iterdir() if p.name.endswith(".tmp")]
    errors = [line for line in text.splitlines() if not line.startswith("subtrace: warning:")]
    if "Traceback" in text or temps:
        raise AssertionError(f"exit {proc.returncode}, temporaries {temps}, {text[-2000:]!r}")
    if proc.returncode == 0 and not errors:
        return "ok"
    if proc.returncode == 2 and len(errors) == 1 and errors[0].startswith("subtrace: "):
        return "option-error"
    raise AssertionError(f"exit {proc.returncode}, stderr {text[-2000:]!r}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="how long to run (default 60)")
    ap.add_argument("--seed", type=int, default=None, help="random seed (default: time)")
    ap.add_argument("--timeout", type=float, default=10.0,
                    help="seconds one input may take before it counts as a hang")
    ap.add_argument("--out", default="fuzz_crashes", help="folder for crashing inputs")
    ap.add_argument("--render-fraction", type=float, default=0.1,
                    help="fraction of mutated cages also rendered at 32x24 by `subtrace "
                         "render` in a process of its own (default 0.1)")
    ap.add_argument("--render-timeout", type=float, default=30.0,
                    help="seconds one render may take before it counts as a hang (default 30)")
    args = ap.parse_args(argv)
    seed = args.seed if args.seed is not None else int(time.time())
    rng = random.Random(seed)
    objs, tomls = seeds()
    formats = format_seeds()
    work = Path(args.out) / "work"
    work.mkdir(parents=True, exist_ok=True)
    (work / "cube.obj").write_bytes((CORPUS / "cube.obj").read_bytes())  # scenes' mesh
    warnings.simplefilter("ignore")
    for target in ("obj", "info"):  # untimed: the readers' kernels load (or compile) here
        check(target, work / "cube.obj")
    if args.render_fraction > 0:
        warm_render_cache(work)
    signal.signal(signal.SIGALRM, _alarm)
    outcomes: Counter = Counter()
    crashes = []
    tried = 0
    t_end = time.monotonic() + args.seconds
    while time.monotonic() < t_end:
        target = rng.choice(["obj", "obj", "info", "scene", "options"]
                            + ["format"] * (2 if formats else 0))
        if target == "options":
            if rng.random() >= args.render_fraction:
                continue  # (command lines run processes: as often as renders)
            argv_, how = option_args(rng, work)
            tried += 1
            try:
                kind = check_options(argv_, work, args.render_timeout)
            except Hang:
                kind = "CRASH:hang"
            except Exception:  # noqa: BLE001 - a crash is what we look for
                kind = "CRASH:options"
            outcomes[(target, kind)] += 1
            if kind.startswith("CRASH"):
                name = Path(args.out) / f"crash_{len(crashes):04d}_options.txt"
                name.write_text(f"seed {seed}\nsubtrace {' '.join(argv_)}\n"
                                f"{traceback.format_exc()}\n")
                crashes.append((name, kind))
                print(f"crash: {kind} on options -> {name}", file=sys.stderr)
            continue
        if target == "format":  # USD and the mesh formats: read by `info`, or rendered
            suffix, base = rng.choice(formats)
            target = "usd" if suffix == ".usda" else "mesh"
        else:
            suffix = ".toml" if target == "scene" else ".obj"
            base = rng.choice(tomls if target == "scene" else objs)
        data, how = mutate(rng, base)
        for old in work.glob("input.*"):
            old.unlink()
        path = work / f"input{suffix}"
        path.write_bytes(data)
        tried += 1
        if target == "mesh":
            target = "info"  # in this process: trimesh is Python and numpy
        if target != "scene" and rng.random() < args.render_fraction:
            target = "render"
        in_process = target not in ("render", "usd")
        signal.setitimer(signal.ITIMER_REAL, args.timeout if in_process else 0)
        detail = None
        try:
            if target == "render":
                try:
                    kind = check_render(path, args.render_timeout)
                except Hang:  # a cold cache (another process edited the sources)? once more
                    warm_render_cache(work)
                    kind = check_render(path, args.render_timeout)
            elif target == "usd":
                kind = check_info_process(path, args.render_timeout)
            else:
                kind = check(target, path)
        except Hang:
            kind = "CRASH:hang"
        except Exception as exc:  # noqa: BLE001 - a crash is what we look for
            kind = f"CRASH:{type(exc).__name__}"
            detail = traceback.format_exc()
        else:
            detail = None
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
        label = target if suffix in (".obj", ".toml") else f"{target} {suffix}"
        outcomes[(label, kind)] += 1
        if kind.startswith("CRASH"):
            name = Path(args.out) / f"crash_{len(crashes):04d}_{target}{suffix}"
            name.write_bytes(data)
            name.with_suffix(name.suffix + ".txt").write_text(
                f"target {target}, mutations {how}, seed {seed}\n{detail or kind}\n")
            crashes.append((name, kind))
            print(f"crash: {kind} on {target} -> {name}", file=sys.stderr)
    print(f"seed {seed}: {tried} inputs in {args.seconds:.0f} s, {len(crashes)} crashes")
    for (target, kind), n in sorted(outcomes.items()):
        print(f"  {target:13s} {kind:28s} {n}")
    for name, kind in crashes[:20]:
        print(f"  crash {kind}: {name}")
    return 1 if crashes else 0


if __name__ == "__main__":
    sys.exit(main())
