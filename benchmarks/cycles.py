"""Benchmark: subtrace side by side with Blender Cycles' adaptive subdivision.

    python benchmarks/cycles.py [--scenes NAME ...] [--rounds 5] [--width W --height H]
                                [--bpy-python PATH] [--subtrace CMD] [--threads 2]
                                [--images DIR] [--json OUT] [--list]

Scenes: every ``scenes/*.toml`` plus feature-rich cages this script builds (deterministic
OBJ files with OpenSubdiv tags, in a temporary folder) or takes from OpenSubdiv's regression
shapes (``tests/oracle/shapes``, Modified Apache 2.0):

    gen_pawn         Catmull-Clark lathe (chess-pawn-like): open bottom (boundary), semi-sharp
                     and infinitely sharp crease rings, fluted stem (semi-sharp edges), corner
                     tags, a 24-gon top
    gen_nut          Catmull-Clark hexagon nut (genus 1): pentagons on both faces, infinitely
                     sharp rims, semi-sharp vertical edges, corner tags on the inner rim
    gen_vase_loop    Loop lathe (vase): open lip (boundary), crease rings of both kinds,
                     semi-sharp meridians, corner tags, a valence-24 pole
    osd_loop_icos_semisharp    OpenSubdiv's Loop icosahedron with semi-sharp creases, corners
    osd_catmark_nonquads       OpenSubdiv's n-gon cage (triangles to hexagons), boundaries

and hard-surface cages as artists model them, from OpenSubdiv's regression shapes committed
in ``models/opensubdiv/`` (Modified Apache 2.0, ``models/README.md``), turned Y up:

    chess      pawn, bishop and rook side by side in one view (2,333 faces, 176 of them
               triangles; 624 semi-sharp creases of sharpness 6 and 7.9; open at the
               bases): subtrace cannot move an object, so the three become one OBJ, the
               vertices offset, the tags re-indexed
    car        the car body (1,575 quads, 314 semi-sharp creases of sharpness 6)
    helmet     the helmet shell (58 quads, 38 creases of sharpness 7, open, edge-and-corner)
    helmet_fine  the helmet refined twice by Catmull-Clark's rules (928 quads, its creases of
               sharpness 5, the same limit surface): a hard-surface cage of 500-2,000 faces

Each scene's camera (eye, target, up, vertical fov, resolution) is resolved here and given to
both renderers, subtrace on its command line: the two images frame the same view.

Renderers, each a separate process per render:

* subtrace: ``--subtrace`` (default: ``python cli.py`` of this checkout, which uses the
  installed package if there is one; put ``src`` on PYTHONPATH to time the checkout), run as
  ``render SCENE.toml -o OUT.exr --threads 2 --eye ... --quiet``. Its render time is the EXR
  header's ``subtrace:time_total`` (load, preprocess, refine, trace, shade; not the write).
* Cycles: Blender ``bpy`` (default 5.0.1) in a virtual environment of its own, created on
  first use in ``~/.cache/subtrace-benchmarks/bpy-venv`` (``pip install bpy==5.0.1``; the wheel needs
  Python 3.11) unless ``--bpy-python`` names a Python that imports bpy. bpy is never a
  dependency of subtrace. ``_cycles_worker.py`` (beside this file) builds the cage with
  ``from_pydata``, edge creases in the ``crease_edge`` attribute and corners in
  ``crease_vert``, a Subdivision Surface modifier with adaptive subdivision (pixel space,
  dicing rate 1 px, boundary smooth from the cage's boundary mode), the same camera, sun
  lights without shadows, CPU, 1 sample, box filter, no denoising, no bounces, 2 threads.
  Its render time is ``bpy.ops.render.render()`` measured inside that process (Blender's
  start-up and the scene build excluded), split at Cycles' first "Sample" status into
  *sync* (mesh sync, adaptive tessellation, BVH build) and *samples*.

  Crease units: Cycles (``intern/cycles/subd/osd.cpp``) passes ``crease * 10`` to OpenSubdiv
  as the sharpness, so an OpenSubdiv sharpness s becomes ``min(s / 10, 1)``, and a corner tag
  ``crease_vert = min(s / 10, 1)``. (Blender's own Subdivision Surface modifier squares the
  crease, ``10 c^2``; that mapping is not the one Cycles uses.) Cycles subdivides every cage
  with Catmull-Clark: Loop cages get Catmull-Clark in Cycles (marked in the table). Chaikin
  creases (``t creasemethod``) become uniform creases, boundary mode "none" becomes
  edge-only; the table's notes say where.

Timing: per scene one warm-up render of each renderer (Numba's cache, the file cache), then
``--rounds`` rounds, each running subtrace then Cycles, the order swapped every round.
Recorded per render: the renderer's own render time, the whole process's wall time
(interpreter start, imports, scene load, EXR write) and its peak RSS (``os.wait4``, in a
bare launcher so that this script's own memory does not count: see ``run_process``). The
table gives medians per renderer, ratios subtrace / Cycles (below 1: subtrace is faster or
smaller) and the geometric mean of each ratio over the scenes. A third table gives each
renderer's time per covered pixel (its render time over the pixels subtrace covered) and
subtrace's refine time per patch refined (``subtrace:time_refine`` over
``subtrace:patches_refined`` of the EXR header): what a hard-surface cage costs beside a
smooth one.

``--images DIR`` also renders every scene at 480x270 with both renderers and writes
``DIR/<scene>_subtrace.png``, ``DIR/<scene>_cycles.png`` and a side-by-side
``DIR/<scene>_pair.png`` (subtrace left), and reports how well the two coverage masks agree
(intersection over union of the pixels each renderer covers): matching cameras give IoU
near 1 (silhouette pixels differ: Cycles jitters its one sample inside the pixel, subtrace
shoots through the centre).

Both renderers get the same environment, minus PYTHONDONTWRITEBYTECODE (as in
``benchmarks/render.py``: a normal installation keeps Python's bytecode cache).
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import math
import os
import shlex
import shutil
import statistics
import subprocess
import sys
import tempfile
import tomllib
from dataclasses import dataclass, field
from decimal import Decimal
from pathlib import Path

from _common import bench_cache  # benchmarks/ is on sys.path when run as a script

REPO = Path(__file__).resolve().parents[1]
WORKER = Path(__file__).resolve().with_name("_cycles_worker.py")
OSD_SHAPES = REPO / "tests" / "oracle" / "shapes"
BPY_VERSION = "5.0.1"
BPY_PYTHON_VERSION = (3, 11)  # the bpy wheels are built for one CPython version
DEFAULT_VENV = bench_cache("bpy-venv")
IMAGE_SIZE = (480, 270)
INF_SHARP = 10.0  # OpenSubdiv: sharpness >= 10 is infinitely sharp

# OBJ interpolateboundary values (OpenSubdiv's shape tags) -> names
BOUNDARY_NAMES = {0: "none", 1: "edge-and-corner", 2: "edge-only"}
# Blender's boundary smooth option for each boundary mode ("none" has no equivalent)
BLENDER_BOUNDARY = {"edge-only": "ALL", "edge-and-corner": "PRESERVE_CORNERS", "none": "ALL"}


class BenchError(Exception):
    """A problem that ends the benchmark with one line on stderr."""


# ------------------------------------------------------------------------------------ cages
@dataclass
class Cage:
    """An OBJ control mesh with its OpenSubdiv tags (0-based indices)."""

    positions: list  # [(x, y, z)]
    faces: list  # [[v0, v1, ...]]
    creases: list = field(default_factory=list)  # [(v0, v1, sharpness)]
    corners: list = field(default_factory=list)  # [(v, sharpness)]
    boundary: str | None = None  # from "t interpolateboundary"; None: absent
    crease_method: str | None = None  # from "t creasemethod"
    holes: int = 0
    hole_faces: list = field(default_factory=list)  # the faces "t hole" names

    def to_obj(self, header: str) -> str:
        lines = [f"# {line}" for line in header.splitlines()]
        lines += [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in self.positions]
        lines += ["f " + " ".join(str(v + 1) for v in f) for f in self.faces]
        if self.boundary is not None:
            code = {v: k for k, v in BOUNDARY_NAMES.items()}[self.boundary]
            lines.append(f"t interpolateboundary 1/0/0 {code}")
        lines += [f"t crease 2/1/0 {a} {b} {s:g}" for a, b, s in self.creases]
        lines += [f"t corner 1/1/0 {v} {s:g}" for v, s in self.corners]
        if self.hole_faces:
            lines.append(f"t hole {len(self.hole_faces)}/0/0 "
                         + " ".join(map(str, self.hole_faces)))
        return "\n".join(lines) + "\n"

    def features(self) -> str:
        """A short description: faces by size, creases, corners, boundary edges."""
        sizes = [len(f) for f in self.faces]
        tris, quads = sizes.count(3), sizes.count(4)
        ngons = len(sizes) - tris - quads
        parts = [f"{len(sizes):,} faces"]
        if tris and tris != len(sizes):
            parts.append(f"{tris} tri")
        if ngons:
            parts.append(f"{ngons} n-gon{'s' if ngons > 1 else ''} (max {max(sizes)})")
        semi = sum(1 for *_, s in self.creases if 0.0 < s < INF_SHARP)
        inf = sum(1 for *_, s in self.creases if s >= INF_SHARP)
        if semi:
            parts.append(f"{semi} semi-sharp")
        if inf:
            parts.append(f"{inf} sharp")
        if self.corners:
            parts.append(f"{len(self.corners)} corners")
        edges: dict = {}
        for f in self.faces:
            for a, b in zip(f, f[1:] + f[:1]):
                key = (min(a, b), max(a, b))
                edges[key] = edges.get(key, 0) + 1
        open_edges = sum(1 for n in edges.values() if n == 1)
        if open_edges:
            parts.append(f"{open_edges} boundary edges")
        if self.crease_method:
            parts.append(f"{self.crease_method} creases")
        return ", ".join(parts)


def read_obj(path: Path) -> Cage:
    """Positions, faces and OpenSubdiv ``t`` tags of an OBJ file (enough for this script)."""
    positions, faces, cage = [], [], Cage([], [])
    with open(path, encoding="utf-8", errors="replace") as f:
        for number, line in enumerate(f, 1):
            parts = line.split()
            if not parts or parts[0].startswith("#"):
                continue
            try:
                if parts[0] == "v":
                    positions.append(tuple(float(c) for c in parts[1:4]))
                elif parts[0] == "f":
                    face = []
                    for token in parts[1:]:
                        i = int(token.split("/")[0])
                        face.append(i - 1 if i > 0 else len(positions) + i)
                    faces.append(face)
                elif parts[0] == "t":
                    _read_tag(cage, parts)
            except (ValueError, IndexError) as exc:
                raise BenchError(f"{path}:{number}: cannot read '{line.strip()}' ({exc})")
    cage.positions, cage.faces = positions, faces
    return cage


def _read_tag(cage: Cage, parts: list) -> None:
    name = parts[1]
    n_ints, n_floats, _ = (int(c) for c in parts[2].split("/"))
    values = parts[3:]
    ints = [int(v) for v in values[:n_ints]]
    floats = [float(v) for v in values[n_ints : n_ints + n_floats]]
    strings = values[n_ints + n_floats :]
    if name == "crease":  # pairs of vertices; one sharpness for all or one per pair
        for k in range(n_ints // 2):
            s = floats[k] if len(floats) > 1 else floats[0]
            cage.creases.append((ints[2 * k], ints[2 * k + 1], s))
    elif name == "corner":
        for k, v in enumerate(ints):
            cage.corners.append((v, floats[k] if len(floats) > 1 else floats[0]))
    elif name == "interpolateboundary":
        cage.boundary = BOUNDARY_NAMES[ints[0]]
    elif name == "creasemethod":
        cage.crease_method = strings[0]
    elif name == "hole":
        cage.holes += len(ints)
        cage.hole_faces += ints


# ------------------------------------------------------------------ generated feature cages
def _lathe(rings, around, *, triangles=False, top_cap=None, bottom_pole=False):
    """Vertices and faces of a surface of revolution about +Y.

    rings: [(radius, y)] from bottom to top; ring i, segment j is vertex i * around + j
    (then the optional bottom pole). Faces face outwards; ``top_cap="ngon"`` closes the top
    ring with one polygon; ``bottom_pole`` closes the bottom ring with a fan to a centre
    vertex (triangles). ``triangles`` splits each quad along the same diagonal (a regular
    Loop mesh away from the pole and the boundary).
    """
    positions = []
    for r, y in rings:
        for j in range(around):
            a = 2.0 * math.pi * j / around
            positions.append((r * math.cos(a), y, r * math.sin(a)))
    faces = []
    for i in range(len(rings) - 1):
        for j in range(around):
            a, b = i * around + j, (i + 1) * around + j
            c, d = (i + 1) * around + (j + 1) % around, i * around + (j + 1) % around
            if not triangles:
                faces.append([a, b, c, d])
            else:  # one diagonal direction everywhere: interior vertices of valence 6
                faces += [[a, b, c], [a, c, d]]
    top = (len(rings) - 1) * around
    if top_cap == "ngon":  # decreasing angle: the normal points up
        faces.append([top + j for j in reversed(range(around))])
    if bottom_pole:
        pole = len(positions)
        positions.append((0.0, rings[0][1], 0.0))
        faces += [[pole, j, (j + 1) % around] for j in range(around)]
    return positions, faces


def _ring_creases(i, around, s):
    return [(i * around + j, i * around + (j + 1) % around, s) for j in range(around)]


def cage_pawn() -> Cage:
    """Chess-pawn-like lathe: open bottom, crease rings, fluted stem, corners, 24-gon top."""
    around = 24
    rings = [(0.95, 0.00), (1.00, 0.10), (0.92, 0.22), (0.80, 0.30), (0.62, 0.38),
             (0.45, 0.55), (0.36, 0.80), (0.34, 1.05), (0.55, 1.15), (0.58, 1.22),
             (0.38, 1.28), (0.46, 1.40), (0.52, 1.60), (0.44, 1.80), (0.22, 1.93)]
    positions, faces = _lathe(rings, around, top_cap="ngon")
    creases = (_ring_creases(1, around, 3.0) + _ring_creases(3, around, 2.0)
               + _ring_creases(8, around, INF_SHARP) + _ring_creases(9, around, INF_SHARP)
               + _ring_creases(14, around, 1.0))
    for i in range(4, 7):  # flutes: semi-sharp meridian edges along the stem
        creases += [(i * around + j, (i + 1) * around + j, 2.0) for j in range(0, around, 4)]
    corners = [(1 * around + j, 3.0) for j in range(0, around, 6)]
    return Cage(positions, faces, creases, corners, boundary="edge-only")


def cage_nut() -> Cage:
    """Hexagon nut (genus 1): pentagon faces, sharp rims, semi-sharp vertical edges."""
    outer_r, inner_r, half_h = 1.0, 0.5, 0.35
    positions, outer, inner = [], [], []
    for y in (-half_h, 0.0, half_h):  # layers: bottom, middle, top
        ring = []
        for k in range(12):  # even: hexagon corner; odd: middle of a side
            a = math.radians(30.0 * k)
            r = outer_r if k % 2 == 0 else outer_r * math.cos(math.radians(30.0))
            ring.append(len(positions))
            positions.append((r * math.cos(a), y, r * math.sin(a)))
        outer.append(ring)
        ring = []
        for k in range(6):
            a = math.radians(60.0 * k)
            ring.append(len(positions))
            positions.append((inner_r * math.cos(a), y, inner_r * math.sin(a)))
        inner.append(ring)
    faces = []
    for k in range(6):
        c0, m, c1 = 2 * k, 2 * k + 1, (2 * k + 2) % 12
        i0, i1 = k, (k + 1) % 6
        faces.append([outer[0][c0], outer[0][m], outer[0][c1], inner[0][i1], inner[0][i0]])
        faces.append([inner[2][i0], inner[2][i1], outer[2][c1], outer[2][m], outer[2][c0]])
    for lo in range(2):
        for j in range(12):
            faces.append([outer[lo][j], outer[lo + 1][j], outer[lo + 1][(j + 1) % 12],
                          outer[lo][(j + 1) % 12]])
        for j in range(6):
            faces.append([inner[lo][j], inner[lo][(j + 1) % 6], inner[lo + 1][(j + 1) % 6],
                          inner[lo + 1][j]])
    creases = []
    for layer in (0, 2):
        creases += [(outer[layer][j], outer[layer][(j + 1) % 12], INF_SHARP) for j in range(12)]
        creases += [(inner[layer][j], inner[layer][(j + 1) % 6], 1.5) for j in range(6)]
    for k in range(6):
        creases += [(outer[lo][2 * k], outer[lo + 1][2 * k], 2.5) for lo in range(2)]
    corners = [(inner[2][k], INF_SHARP) for k in range(6)]
    return Cage(positions, faces, creases, corners)


def cage_vase_loop() -> Cage:
    """Loop lathe (vase): open lip, crease rings, semi-sharp meridians, corners, a pole."""
    around = 24
    rings = [(0.45, 0.00), (0.50, 0.08), (0.30, 0.20), (0.22, 0.45), (0.30, 0.62),
             (0.60, 0.80), (0.75, 1.10), (0.70, 1.40), (0.55, 1.60), (0.62, 1.75)]
    positions, faces = _lathe(rings, around, triangles=True, bottom_pole=True)
    creases = (_ring_creases(0, around, INF_SHARP) + _ring_creases(1, around, 2.0)
               + _ring_creases(4, around, 1.5) + _ring_creases(7, around, INF_SHARP))
    for i in range(5, 7):  # meridians between the belly rings and the shoulder
        creases += [(i * around + j, (i + 1) * around + j, 3.0) for j in range(0, around, 6)]
    corners = [(4 * around + j, 2.0) for j in range(3, around, 6)]
    return Cage(positions, faces, creases, corners, boundary="edge-only")


# ------------------------------------------------------------ hard-surface cages (committed)
HARD_SURFACE = REPO / "models" / "opensubdiv"  # OpenSubdiv's shapes; models/README.md
CHESS_SPACING = 0.55  # centre to centre along +X (the pieces are 0.31-0.45 wide)


def _hard_surface(name: str) -> Cage:
    """``models/opensubdiv/catmark_<name>.obj`` turned a quarter about +X: its +Z (up in
    these shapes) becomes +Y, the extra scenes' up (a rotation: faces keep their winding)."""
    cage = read_obj(HARD_SURFACE / f"catmark_{name}.obj")
    cage.positions = [(x, z, -y) for x, y, z in cage.positions]
    return cage


def _joined(parts: list) -> Cage:
    """One cage of several, side by side along +X, ``CHESS_SPACING`` apart, each centred
    on its slot, standing on y = 0. Indices of faces and tags are shifted with their
    vertices (subtrace places no object by a transform, so the cages become one)."""
    out = Cage([], [])
    for slot, cage in enumerate(parts):
        lo = [min(p[k] for p in cage.positions) for k in range(3)]
        hi = [max(p[k] for p in cage.positions) for k in range(3)]
        move = (slot * CHESS_SPACING - (lo[0] + hi[0]) / 2.0, -lo[1], -(lo[2] + hi[2]) / 2.0)
        n = len(out.positions)
        out.positions += [tuple(c + m for c, m in zip(p, move)) for p in cage.positions]
        out.faces += [[v + n for v in f] for f in cage.faces]
        out.creases += [(a + n, b + n, s) for a, b, s in cage.creases]
        out.corners += [(v + n, s) for v, s in cage.corners]
        out.hole_faces += [f + len(out.faces) - len(cage.faces) for f in cage.hole_faces]
        out.boundary = out.boundary or cage.boundary
    out.holes = len(out.hole_faces)
    return out


def cage_chess() -> Cage:
    """OpenSubdiv's pawn, bishop and rook side by side (semi-sharp creases of 6 and 7.9)."""
    return _joined([_hard_surface(n) for n in ("pawn", "bishop", "rook")])


def cage_car() -> Cage:
    """OpenSubdiv's car body (semi-sharp creases of sharpness 6), Y up."""
    return _hard_surface("car")


def cage_helmet() -> Cage:
    """OpenSubdiv's helmet shell (open, edge-and-corner, creases of sharpness 7), Y up."""
    return _hard_surface("helmet")


def cage_helmet_fine() -> Cage:
    """The helmet shell refined twice by Catmull-Clark's rules (subtrace's own uniform
    refinement, which matches OpenSubdiv's: tests/test_oracle.py): 928 quads with its
    creases two levels down (sharpness 5 where the shell had 7, each crease now four
    edges), the same limit surface: a helmet-like hard-surface cage of the size artists
    model (500-2,000 faces). The refined level's sharpness is written as tags (boundary
    edges and corners as infinitely sharp ones, which the boundary rule makes them anyway)."""
    import numpy as np

    import subtrace

    coarse = _hard_surface("helmet")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "helmet.obj"
        path.write_text(coarse.to_obj("helmet, Y up"), encoding="utf-8")
        cage = subtrace.load_cage(path)
    level, mesh = cage.level_topology(2), cage.refine(2)
    starts = np.r_[0, np.cumsum(mesh.face_sizes)[:-1]]
    faces = [[int(v) for v in mesh.face_verts[a:a + n]]
             for a, n in zip(starts, mesh.face_sizes)]
    creases = [(int(a), int(b), min(float(s), INF_SHARP))
               for (a, b), s in zip(level.edge_verts, level.edge_sharpness) if s > 0]
    corners = [(int(v), min(float(s), INF_SHARP))
               for v, s in enumerate(level.vert_sharpness) if s > 0]
    return Cage([tuple(map(float, p)) for p in mesh.points], faces, creases, corners,
                boundary=coarse.boundary, crease_method=coarse.crease_method)


HARD_ORIGIN = ("OpenSubdiv regression shapes (models/opensubdiv), Modified Apache 2.0; "
               "turned Y up by benchmarks/cycles.py")

# (name, builder or OpenSubdiv shape, view direction from the target, licence / origin)
EXTRA_CAGES = [
    ("gen_pawn", cage_pawn, (1.0, 0.9, 1.6), "built by benchmarks/cycles.py"),
    ("gen_nut", cage_nut, (0.9, 1.6, 1.4), "built by benchmarks/cycles.py"),
    ("gen_vase_loop", cage_vase_loop, (1.0, 1.0, 1.6), "built by benchmarks/cycles.py"),
    ("osd_loop_icos_semisharp", "loop_icos_semisharp", (1.0, 0.6, 1.6),
     "OpenSubdiv regression shape, Modified Apache 2.0"),
    ("osd_catmark_nonquads", "catmark_nonquads", (0.4, 1.6, 1.2),
     "OpenSubdiv regression shape, Modified Apache 2.0"),
    # hard-surface cages as artists model them: many semi-sharp creases of sharpness 6-8
    ("chess", cage_chess, (0.35, 0.55, 1.6), HARD_ORIGIN),
    ("car", cage_car, (1.6, 0.7, 0.9), HARD_ORIGIN),
    ("helmet", cage_helmet, (1.0, 0.6, 1.6), HARD_ORIGIN),
    ("helmet_fine", cage_helmet_fine, (1.0, 0.6, 1.6), HARD_ORIGIN + ", refined twice"),
]


def frame_camera(positions, view, width, height, fov=30.0, fill=1.0):
    """Eye and target so that the cage's bounding sphere just fits the frame (``fill`` > 1
    leaves a margin). The limit surface lies inside the cage's hull, so inside the sphere."""
    lo = [min(p[k] for p in positions) for k in range(3)]
    hi = [max(p[k] for p in positions) for k in range(3)]
    centre = [(a + b) / 2.0 for a, b in zip(lo, hi)]
    radius = max(math.dist(p, centre) for p in positions)
    half_v = math.radians(fov) / 2.0
    half_h = math.atan(math.tan(half_v) * width / height)
    distance = fill * radius / math.sin(min(half_v, half_h))
    n = math.sqrt(sum(c * c for c in view))
    eye = [c + distance * v / n for c, v in zip(centre, view)]
    return [round(c, 6) for c in eye], [round(c, 6) for c in centre]


def write_extra_scenes(folder: Path) -> list[Path]:
    """Write the extra cages (OBJ) and a TOML scene for each into ``folder``."""
    scenes = []
    for name, source, view, origin in EXTRA_CAGES:
        if callable(source):
            cage = source()
            mesh = folder / f"{name}.obj"
            mesh.write_text(cage.to_obj(f"{name}: {source.__doc__}\n{origin}"))
        else:
            mesh = OSD_SHAPES / f"{source}.obj"
            if not mesh.exists():
                print(f"cycles.py: skipping {name}: {mesh} not found", file=sys.stderr)
                continue
            cage = read_obj(mesh)
        eye, target = frame_camera(cage.positions, view, 1280, 720)
        scheme = 'scheme = "loop"\n' if all(len(f) == 3 for f in cage.faces) else ""
        text = (
            f"# {name}: {origin}\n"
            f'[[object]]\nmesh = "{mesh.as_posix()}"\n{scheme}color = [0.8, 0.7, 0.55]\n\n'
            f"[camera]\neye = {eye}\ntarget = {target}\nup = [0, 1, 0]\nfov = 30.0\n"
            "width = 1280\nheight = 720\n\n"
            "[render]\ntolerance = 1.0\nbackground = [0.05, 0.06, 0.08]\n"
            "headlight_intensity = 0.8\n\n"
            "[[light]]\ndirection = [-0.4, -1.0, -0.5]\nintensity = 0.5\n"
        )
        path = folder / f"{name}.toml"
        path.write_text(text)
        scenes.append(path)
    return scenes


# ---------------------------------------------------------------------------------- scenes
@dataclass
class Scene:
    name: str
    toml: Path
    objects: list  # [(Cage, scheme "catmark" | "loop", boundary name, colour)]
    camera: dict  # eye, target, up, fov, width, height
    background: list
    headlight: float
    lights: list
    notes: list = field(default_factory=list)

    def features(self) -> str:
        parts = []
        for cage, scheme, boundary, _ in self.objects:
            text = ("Loop: " if scheme == "loop" else "") + cage.features()
            if boundary != "edge-only" and "boundary" in text:
                text += f" ({boundary})"
            parts.append(text)
        return "; ".join(parts)


def load_scene(path: Path) -> Scene:
    """The parts of a subtrace TOML scene that both renderers need."""
    try:
        data = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise BenchError(f"{path}: {exc}")
    objects = data.get("object", [])
    objects = [objects] if isinstance(objects, dict) else objects
    cam = data.get("camera", {})
    rnd = data.get("render", {})
    items, notes = [], []
    for obj in objects:
        mesh = Path(obj["mesh"])
        cage = read_obj(mesh if mesh.is_absolute() else path.parent / mesh)
        scheme = obj.get("scheme", "loop" if all(len(f) == 3 for f in cage.faces) else
                         "catmark")
        scheme = "catmark" if scheme == "catmull-clark" else scheme
        boundary = obj.get("boundary", cage.boundary or "edge-only")
        if scheme == "loop":
            notes.append("Loop cage: Cycles subdivides it with Catmull-Clark")
        if boundary == "none":
            notes.append("boundary 'none': Cycles has no such mode (edge-only used)")
        if cage.crease_method and cage.crease_method != "uniform":
            notes.append(f"{cage.crease_method} creases: Cycles has uniform creases only")
        if cage.holes:
            notes.append("hole tags: ignored by Cycles")
        items.append((cage, scheme, boundary, obj.get("color", [0.8, 0.8, 0.8])))
    if "eye" not in cam or "target" not in cam:
        allpos = [p for c, *_ in items for p in c.positions]
        eye, target = frame_camera(allpos, (1.0, 0.6, 1.6), cam.get("width", 640),
                                   cam.get("height", 480), cam.get("fov", 30.0), fill=1.1)
        cam = dict(cam, eye=eye, target=target)
    camera = {
        "eye": list(cam["eye"]), "target": list(cam["target"]),
        "up": list(cam.get("up", [0.0, 1.0, 0.0])), "fov": float(cam.get("fov", 30.0)),
        "width": int(cam.get("width", 640)), "height": int(cam.get("height", 480)),
    }
    headlight = rnd.get("headlight_intensity", 1.0) if rnd.get("headlight", True) else 0.0
    lights = [{"direction": list(li["direction"]), "color": list(li.get("color", [1, 1, 1])),
               "intensity": float(li.get("intensity", 1.0))} for li in data.get("light", [])]
    background = rnd.get("background", [0, 0, 0])
    if background and isinstance(background[0], list):  # a gradient: Cycles gets its top
        background = background[0]
    return Scene(path.stem, path, items, camera, list(background), float(headlight), lights,
                 notes)


def cycles_job(scene: Scene, width: int, height: int, threads: int, exr: str) -> dict:
    """The worker's job: cages in Blender's units, camera, lights, output."""
    objects = []
    for cage, _scheme, boundary, colour in scene.objects:
        objects.append({
            "positions": cage.positions,
            "faces": cage.faces,
            # Cycles: OpenSubdiv sharpness = 10 * crease (linear; see the module comment)
            "edge_creases": [(a, b, min(s / INF_SHARP, 1.0)) for a, b, s in cage.creases
                             if s > 0.0],
            "vertex_creases": [(v, min(s / INF_SHARP, 1.0)) for v, s in cage.corners if s > 0],
            "boundary_smooth": BLENDER_BOUNDARY[boundary],
            "color": colour,
        })
    return {
        "objects": objects,
        "camera": dict(scene.camera, width=width, height=height),
        "background": scene.background,
        "headlight": scene.headlight,
        "lights": scene.lights,
        "threads": threads,
        "dicing_rate": 1.0,
        "exr": exr,
    }


# ------------------------------------------------------------------------------- processes
# A child's peak RSS (ru_maxrss) starts at its parent's peak: Linux's exec keeps the peak
# of the address space it replaces (and posix_spawn's child borrows its parent's). So every
# render is started by a bare Python (-S, only os, sys and time: about 9 MiB) that waits
# for it and reports its exit code, wall time and peak RSS: a renderer smaller than this
# script (numpy, OpenImageIO; embree.py's driver takes tens of MiB) is measured as itself.
_LAUNCHER = """
import os, sys, time
out = [(os.POSIX_SPAWN_OPEN, 1, sys.argv[1], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644),
       (os.POSIX_SPAWN_DUP2, 1, 2)]
t0 = time.perf_counter()
pid = os.posix_spawnp(sys.argv[2], sys.argv[2:], os.environ, file_actions=out)
_, status, usage = os.wait4(pid, 0)
print(os.waitstatus_to_exitcode(status), time.perf_counter() - t0, usage.ru_maxrss)
"""


def run_process(cmd, log_path, env):
    """Run ``cmd``; return (exit code, wall s, peak RSS MiB) of that process alone."""
    launcher = [sys.executable, "-S", "-c", _LAUNCHER, str(log_path), *map(str, cmd)]
    out = subprocess.run(launcher, capture_output=True, text=True, env=env)
    try:
        rc, wall, rss_kib = out.stdout.split()
    except ValueError:
        last = (out.stderr.strip().splitlines() or ["no report"])[-1]
        raise BenchError(f"could not run {cmd[0]}: {last}") from None
    return int(rc), float(wall), int(rss_kib) / 1024.0  # Linux: ru_maxrss in KiB


def _log_tail(path, n=6):
    try:
        lines = Path(path).read_text(errors="replace").strip().splitlines()
    except OSError:
        return ""
    return " | ".join(lines[-n:])


def exr_header(path) -> dict:
    """subtrace's ``subtrace:*`` EXR header attributes, without the prefix."""
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise BenchError(f"cannot read {path}: {oiio.geterror()}")
    spec = inp.spec()
    attrs = {a.name.split(":", 1)[1]: a.value for a in spec.extra_attribs
             if a.name.startswith("subtrace:")}
    inp.close()
    return attrs


def cli_number(value) -> str:
    """``value`` exactly, without an exponent: argparse takes "-1e-06" for an option."""
    return format(Decimal(repr(float(value))), "f")


class Renderers:
    """Runs one render of a scene in either renderer, each a separate process."""

    def __init__(self, args, bpy_python, work: Path):
        self.args, self.bpy_python, self.work = args, bpy_python, work
        self.subtrace = shlex.split(args.subtrace)
        self.env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}

    def size(self, scene):
        return (self.args.width or scene.camera["width"],
                self.args.height or scene.camera["height"])

    def subtrace_cmd(self, scene, exr, width, height):
        cam = scene.camera
        cmd = self.subtrace + [
            "render", str(scene.toml), "-o", str(exr), "--threads", str(self.args.threads),
            "--width", str(width), "--height", str(height), "--fov", repr(cam["fov"]),
            "--eye", *map(cli_number, cam["eye"]), "--target",
            *map(cli_number, cam["target"]), "--up", *map(cli_number, cam["up"]), "--quiet",
            # like for like with Cycles' one sample and sun lights without shadows or AO
            "--samples", "1", "--no-shadows", "--ao", "0"]
        return cmd

    def run_subtrace(self, scene, width=None, height=None, exr=None) -> dict:
        width, height = (width, height) if width else self.size(scene)
        exr = exr or self.work / f"{scene.name}_subtrace.exr"
        log = self.work / f"{scene.name}_subtrace.log"
        rc, wall, rss = run_process(self.subtrace_cmd(scene, exr, width, height), log,
                                    self.env)
        if rc != 0:
            raise BenchError(f"subtrace failed on {scene.name} (exit {rc}): {_log_tail(log)}")
        head = exr_header(exr)
        return {"render": float(head["time_total"]), "wall": wall, "rss_mb": rss,
                **{k: v for k, v in head.items() if isinstance(v, (int, float))},
                "scheme": head.get("scheme")}

    def run_cycles(self, scene, width=None, height=None, exr=None) -> dict:
        width, height = (width, height) if width else self.size(scene)
        exr = exr or self.work / f"{scene.name}_cycles.exr"
        job = self.work / f"{scene.name}_job_{width}x{height}.json"
        if not job.exists():
            job.write_text(json.dumps(cycles_job(scene, width, height, self.args.threads,
                                                 str(exr))))
        result = self.work / f"{scene.name}_cycles.json"
        result.unlink(missing_ok=True)
        log = self.work / f"{scene.name}_cycles.log"
        rc, wall, rss = run_process([self.bpy_python, str(WORKER), str(job), str(result)],
                                    log, self.env)
        if rc != 0 or not result.exists():
            raise BenchError(f"Cycles failed on {scene.name} (exit {rc}): {_log_tail(log)}")
        res = json.loads(result.read_text())
        return {"render": res["time_render"], "wall": wall, "rss_mb": rss, **res}


# ------------------------------------------------------------------------------------- bpy
def bpy_version(python) -> str | None:
    """Blender's version string if ``python`` imports bpy, else None."""
    try:
        out = subprocess.run([str(python), "-c", "import bpy; print(bpy.app.version_string)"],
                             capture_output=True, text=True, timeout=300)
    except (OSError, subprocess.TimeoutExpired):
        return None
    lines = out.stdout.strip().splitlines()
    return lines[-1] if out.returncode == 0 and lines else None


def _find_python311():
    if sys.version_info[:2] == BPY_PYTHON_VERSION:
        return sys.executable
    name = "python%d.%d" % BPY_PYTHON_VERSION
    return shutil.which(name) or (f"/usr/bin/{name}" if Path(f"/usr/bin/{name}").exists()
                                  else None)


def ensure_bpy(args) -> tuple[str, str]:
    """(python, Blender version): ``--bpy-python``, else the cached virtual environment,
    created and filled with ``bpy==BPY_VERSION`` on first use."""
    if args.bpy_python:
        version = bpy_version(args.bpy_python)
        if version is None:
            raise BenchError(f"--bpy-python {args.bpy_python}: that Python cannot import bpy "
                             f"(install it with: {args.bpy_python} -m pip install "
                             f"bpy=={BPY_VERSION})")
        return args.bpy_python, version
    python = DEFAULT_VENV / "bin" / "python"
    if python.exists():
        version = bpy_version(python)
        if version is not None:
            return str(python), version
    base = _find_python311()
    if base is None:
        raise BenchError(f"bpy {BPY_VERSION} needs Python 3.11, and none was found (give "
                         "--bpy-python PATH: a Python that imports bpy)")
    print(f"cycles.py: installing bpy {BPY_VERSION} into {DEFAULT_VENV} (once; a ~380 MB "
          "download)", file=sys.stderr, flush=True)
    DEFAULT_VENV.parent.mkdir(parents=True, exist_ok=True)
    log = DEFAULT_VENV.parent / "bpy-venv-install.log"
    with open(log, "w") as out:
        ok = subprocess.run([base, "-m", "venv", str(DEFAULT_VENV)], stdout=out,
                            stderr=subprocess.STDOUT).returncode == 0
        ok = ok and subprocess.run([str(python), "-m", "pip", "install", "--quiet",
                                    f"bpy=={BPY_VERSION}"], stdout=out,
                                   stderr=subprocess.STDOUT).returncode == 0
    version = bpy_version(python) if ok else None
    if version is None:
        raise BenchError(f"could not install bpy=={BPY_VERSION} into {DEFAULT_VENV} (see "
                         f"{log}); install it yourself and pass --bpy-python PATH")
    return str(python), version


# ---------------------------------------------------------------------------------- images
def _srgb(linear):
    import numpy as np

    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def _read_rgba(path):
    import numpy as np
    import OpenImageIO as oiio

    buf = oiio.ImageBuf(str(path))
    spec = buf.spec()
    names = list(spec.channelnames)
    px = buf.get_pixels(oiio.FLOAT).reshape(spec.height, spec.width, spec.nchannels)
    take = [names.index(c) for c in ("R", "G", "B", "A")]
    return np.ascontiguousarray(px[:, :, take])


def _write_png(path, rgb):
    import numpy as np
    import OpenImageIO as oiio

    h, w, _ = rgb.shape
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(w, h, 3, oiio.UINT8))
    out.write_image((np.clip(rgb, 0, 1) * 255.0 + 0.5).astype(np.uint8))
    out.close()


def image_check(renderers, scene, folder: Path) -> dict:
    """Render ``scene`` small with both; write the PNGs; coverage agreement (IoU)."""
    import numpy as np

    w, h = IMAGE_SIZE
    s_exr, c_exr = folder / f"{scene.name}_subtrace.exr", folder / f"{scene.name}_cycles.exr"
    renderers.run_subtrace(scene, w, h, exr=s_exr)
    renderers.run_cycles(scene, w, h, exr=str(c_exr))
    s, c = _read_rgba(s_exr), _read_rgba(c_exr)
    bg = np.asarray(scene.background, dtype=np.float32)
    c_rgb = c[:, :, :3] + (1.0 - c[:, :, 3:4]) * bg  # Cycles' film is transparent
    s_rgb = s[:, :, :3] * s[:, :, 3:4] + (1.0 - s[:, :, 3:4]) * bg
    s_img, c_img = _srgb(s_rgb), _srgb(c_rgb)
    _write_png(folder / f"{scene.name}_subtrace.png", s_img)
    _write_png(folder / f"{scene.name}_cycles.png", c_img)
    gap = np.ones((h, 4, 3))
    _write_png(folder / f"{scene.name}_pair.png", np.concatenate([s_img, gap, c_img], axis=1))
    s_cov, c_cov = s[:, :, 3] > 0.5, c[:, :, 3] > 0.5
    union = int(np.count_nonzero(s_cov | c_cov))
    both = int(np.count_nonzero(s_cov & c_cov))
    for p in (s_exr, c_exr):
        p.unlink(missing_ok=True)
    return {"iou": both / union if union else 1.0, "subtrace_px": int(s_cov.sum()),
            "cycles_px": int(c_cov.sum()), "differ_px": union - both}


# ----------------------------------------------------------------------------------- table
def _median(runs, key):
    values = [r[key] for r in runs if r.get(key) is not None]
    return statistics.median(values) if values else float("nan")


def _geomean(values):
    values = [v for v in values if v > 0 and math.isfinite(v)]
    return math.exp(sum(map(math.log, values)) / len(values)) if values else float("nan")


def summarize(results) -> dict:
    rows = []
    for r in results:
        s, c = r["subtrace"], r["cycles"]
        row = {"scene": r["scene"], "features": r["features"], "notes": r["notes"],
               "px": int(_median(s, "pixels_covered")), "scheme": s[0].get("scheme")}
        for key in ("render", "wall", "rss_mb", "time_load", "time_preprocess", "time_refine",
                    "time_trace", "time_shade", "micro_triangles", "patches_refined"):
            row["subtrace_" + key] = _median(s, key)
        for key in ("render", "wall", "rss_mb", "time_sync", "time_tessellate", "time_bvh",
                    "time_samples", "time_build", "cycles_mem_mb"):
            row["cycles_" + key] = _median(c, key)
        for key in ("render", "wall", "rss_mb"):
            row["ratio_" + key] = row["subtrace_" + key] / row["cycles_" + key]
        px = max(row["px"], 1)  # the pixels subtrace covered (the same view for both)
        row["subtrace_us_per_px"] = 1e6 * row["subtrace_render"] / px
        row["cycles_us_per_px"] = 1e6 * row["cycles_render"] / px
        row["subtrace_ms_per_refined"] = (1e3 * row["subtrace_time_refine"]
                                          / max(row["subtrace_patches_refined"], 1))
        rows.append(row)
    geo = {k: _geomean([row["ratio_" + k] for row in rows]) for k in ("render", "wall", "rss_mb")}
    return {"rows": rows, "geomean": geo}


def cost_table(rows) -> list[str]:
    """Lines of the table of costs per covered pixel and per refined patch."""
    out = ["", "Cost per covered pixel (render time / pixels subtrace covered) and per patch "
           "refined\n(subtrace's refine time / its patches refined; medians).", "",
           "| scene | covered px | subtrace us/px | Cycles us/px | patches refined "
           "| refine ms/patch |", "|---|---:|---:|---:|---:|---:|"]
    for row in rows:
        out.append(
            f"| {row['scene']} | {row['px']:,} | {row['subtrace_us_per_px']:.2f} "
            f"| {row['cycles_us_per_px']:.2f} | {row['subtrace_patches_refined']:,.0f} "
            f"| {row['subtrace_ms_per_refined']:.3f} |")
    return out


def note_marks(row_notes, notes) -> str:
    """A table row's footnote marks (``<sup>k</sup>``), its notes numbered in ``notes`` (the
    table's, in order of first use: new ones appended)."""
    marks = ""
    for note in row_notes:
        if note not in notes:
            notes.append(note)
        marks += f"<sup>{notes.index(note) + 1}</sup>"
    return marks


def markdown(summary, images=None) -> str:
    rows, geo = summary["rows"], summary["geomean"]
    notes, out = [], []
    out.append("| scene | cage | covered px | subtrace s | Cycles s (sync + samples) | ratio "
               "| subtrace process s | Cycles process s | ratio | subtrace MB | Cycles MB "
               "| ratio |")
    out.append("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for row in rows:
        marks = note_marks(row["notes"], notes)
        out.append(
            f"| {row['scene']}{marks} | {row['features']} | {row['px']:,} "
            f"| {row['subtrace_render']:.3f} | {row['cycles_render']:.3f} "
            f"({row['cycles_time_sync']:.2f} + {row['cycles_time_samples']:.2f}) "
            f"| **{row['ratio_render']:.2f}** | {row['subtrace_wall']:.2f} "
            f"| {row['cycles_wall']:.2f} | **{row['ratio_wall']:.2f}** "
            f"| {row['subtrace_rss_mb']:.0f} | {row['cycles_rss_mb']:.0f} "
            f"| **{row['ratio_rss_mb']:.2f}** |")
    out.append(f"| **geometric mean** | | | | | **{geo['render']:.2f}** | | | "
               f"**{geo['wall']:.2f}** | | | **{geo['rss_mb']:.2f}** |")
    out += [""] + [f"<sup>{i + 1}</sup> {n}." for i, n in enumerate(notes)]
    out += ["", "Where the time goes (medians, s): subtrace's header timings; Cycles' status "
            "phases\n(tessellate and BVH are parts of sync).", "",
            "| scene | load | preprocess | refine | trace | shade | micro-tris | "
            "Cycles tessellate | BVH | sync | samples |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for row in rows:
        out.append(
            f"| {row['scene']} | {row['subtrace_time_load']:.3f} "
            f"| {row['subtrace_time_preprocess']:.3f} | {row['subtrace_time_refine']:.3f} "
            f"| {row['subtrace_time_trace']:.3f} | {row['subtrace_time_shade']:.3f} "
            f"| {row['subtrace_micro_triangles']:,.0f} | {row['cycles_time_tessellate']:.3f} "
            f"| {row['cycles_time_bvh']:.3f} | {row['cycles_time_sync']:.3f} "
            f"| {row['cycles_time_samples']:.3f} |")
    out += cost_table(rows)
    if images:
        out += ["", f"Image check ({IMAGE_SIZE[0]}x{IMAGE_SIZE[1]}): pixels covered by each "
                "renderer and the intersection over union of\nthe two coverage masks.", "",
                "| scene | subtrace px | Cycles px | differing px | IoU |",
                "|---|---:|---:|---:|---:|"]
        for name, im in images.items():
            out.append(f"| {name} | {im['subtrace_px']:,} | {im['cycles_px']:,} "
                       f"| {im['differ_px']:,} | {im['iou']:.4f} |")
    return "\n".join(out)


# ------------------------------------------------------------------------------------ main
def default_subtrace() -> str:
    launcher = REPO / "cli.py"
    if launcher.exists():
        return shlex.join([sys.executable, str(launcher)])
    return shlex.join([sys.executable, "-m", "subtrace.cli"])


def parse_args(argv):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", metavar="NAME",
                    help="only these scenes (names as in --list, or patterns: 'gen_*')")
    ap.add_argument("--rounds", type=int, default=5, help="timed rounds per scene (default 5)")
    ap.add_argument("--width", type=int, help="override every scene's width (quick checks)")
    ap.add_argument("--height", type=int, help="override every scene's height")
    ap.add_argument("--threads", type=int, default=2, help="threads of each renderer (2)")
    ap.add_argument("--bpy-python", metavar="PATH",
                    help="a Python that imports bpy (default: a virtual environment in "
                         f"{DEFAULT_VENV}, made on first use)")
    ap.add_argument("--subtrace", default=default_subtrace(), metavar="CMD",
                    help="command that runs subtrace's CLI (default: %(default)s)")
    ap.add_argument("--images", metavar="DIR", help="also write small PNGs of every scene "
                    "from both renderers into DIR and check that the framings match")
    ap.add_argument("--json", metavar="OUT", help="write every measurement to OUT")
    ap.add_argument("--list", action="store_true", help="list the scenes and exit")
    ap.add_argument("--write-scenes", metavar="DIR", type=Path,
                    help="write the extra scenes (TOML and OBJ) into DIR and exit (for "
                         "benchmarks/ab.py, render.py and profile_kernels.py)")
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
    except BenchError as exc:
        print(f"cycles.py: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("cycles.py: interrupted", file=sys.stderr)
        return 130


def _main(args) -> int:
    if args.write_scenes:
        args.write_scenes.mkdir(parents=True, exist_ok=True)
        for path in write_extra_scenes(args.write_scenes.resolve()):
            print(path)
        return 0
    with tempfile.TemporaryDirectory(prefix="subtrace-cycles-") as tmp:
        work = Path(tmp)
        paths = sorted((REPO / "scenes").glob("*.toml")) + write_extra_scenes(work)
        scenes = [load_scene(p) for p in paths]
        # free-form (NURBS) surfaces: Cycles has no such primitive, so there is nothing to
        # compare (benchmarks/trim.py --renders times subtrace's NURBS scenes alone)
        freeform = [s.name for s in scenes if any(not c.faces for c, *_ in s.objects)]
        scenes = [s for s in scenes if s.name not in freeform]
        if freeform and not args.list:
            print(f"cycles.py: skipping {', '.join(freeform)}: free-form surfaces, which "
                  "Cycles does not render", file=sys.stderr)
        if args.list:
            for s in scenes:
                print(f"{s.name:28} {s.features()}")
            return 0
        if args.scenes:
            scenes = [s for s in scenes if any(fnmatch.fnmatchcase(s.name, n)
                                               for n in args.scenes)]
            if not scenes:
                raise BenchError(f"no scene matches {' '.join(args.scenes)} (see --list)")
        bpy_python, blender = ensure_bpy(args)
        renderers = Renderers(args, bpy_python, work)
        w0, h0 = renderers.size(scenes[0])
        print(f"subtrace ({args.subtrace}) vs Blender {blender} Cycles (adaptive subdivision, "
              f"CPU); {args.threads} threads each; {args.rounds} rounds after a warm-up; "
              f"{len(scenes)} scenes at {w0}x{h0}", file=sys.stderr, flush=True)
        results, loads = [], [os.getloadavg()[0]]
        for scene in scenes:
            renderers.run_subtrace(scene)  # warm-up: Numba's cache, file caches
            renderers.run_cycles(scene)
            runs = {"subtrace": [], "cycles": []}
            for r in range(args.rounds):
                order = ("subtrace", "cycles") if r % 2 == 0 else ("cycles", "subtrace")
                for which in order:
                    run = renderers.run_subtrace if which == "subtrace" else renderers.run_cycles
                    runs[which].append(run(scene))
            results.append({"scene": scene.name, "features": scene.features(),
                            "notes": scene.notes, **runs})
            loads.append(os.getloadavg()[0])
            s, c = (statistics.median(x["render"] for x in runs[k]) for k in runs)
            print(f"  {scene.name}: subtrace {s:.3f} s, Cycles {c:.3f} s", file=sys.stderr,
                  flush=True)
        images = None
        if args.images:
            folder = Path(args.images)
            folder.mkdir(parents=True, exist_ok=True)
            images = {s.name: image_check(renderers, s, folder) for s in scenes}
        summary = summarize(results)
        print(f"\nsubtrace vs Blender {blender} Cycles, {w0}x{h0}, {args.threads} threads, "
              f"medians of {args.rounds} rounds; ratio = subtrace / Cycles; {os.cpu_count()} "
              f"CPUs, 1-minute load average {min(loads):.1f}-{max(loads):.1f} during the "
              "timings\n")
        print(markdown(summary, images))
        if args.json:
            Path(args.json).write_text(json.dumps(
                {"blender": blender, "subtrace": args.subtrace, "threads": args.threads,
                 "rounds": args.rounds, "size": [w0, h0], "load_averages": loads,
                 "runs": results,
                 "summary": summary, "images": images}, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
