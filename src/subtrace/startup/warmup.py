"""Compile kernels ahead of their use: the trace and shade kernels in a second process on a
cold Numba cache (``subtrace warmup``, every kernel of every command, is
:mod:`subtrace.cli.warmup`: it runs commands).

The first render with an empty cache spends most of its time compiling: the kernels of
loading and preprocessing, then the trace and shade kernels, then the picture's. The
groups do not depend on each other, so while the first process compiles (and runs) the
loading and preprocessing, a second process compiles the others on the other core, by
calling them on small inputs of exactly the types a render passes, and stores them in the
shared cache: the shading kernel first (while the first process reads the cages), then,
told the cages' schemes (:func:`tell`), the trace kernel for them (without the Loop
descents where no cage is Loop), then the picture's (:func:`compile_picture`: the ground,
lights, anti-aliasing flags, background). The first process waits for the trace kernel
before its rounds (:func:`wait_traced`) and for the rest before the picture (:func:`wait`)
and loads them from the cache. The secondary-ray kernel (shadow and anti-aliasing rays)
compiles in a third process where the machine has three cores or more, else in the first
process while it waits (``trace.rounds.trace_hits``); so do the picture's kernels other than the
ground's, for as long as the trace kernel is not ready (:func:`picture_while_tracing`), and
the BVH build of the secondary rays (``render.render_scene``). The trace's rounds, in a room
below this one, call the helpers through the :class:`Helpers` they are handed
(:meth:`Helpers.picture_while_tracing`, :meth:`Helpers.wait_traced`). A small OBJ cage is read
by the statement reader, not the byte scanner (``io.obj_scan.STATEMENT_READER_BYTES``): a
cold render of one (the default scene's) leaves the first process time for those.
On a warm cache nothing is started; a cache that holds the trace kernel only for other
schemes starts a helper for it once the cages are read (:func:`start_for`).

    python -m subtrace.startup.warmup THREADS          # the render's second process
    python -m subtrace.startup.warmup --secondary THREADS   # and its third
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from subtrace.runtime import signals


# the module of each kernel the warm-up compiles, as its cache folder and file prefix
_KERNEL_MODULES = {"_trace_task": "trace/kernels", "_shade_task": "shade",
                   "_rays_task": "trace/rays"}


def _index_pattern(name: str) -> tuple[Path, str]:
    """(folder, file name pattern) of the cache's index files of the kernel ``name`` (of
    :data:`_KERNEL_MODULES`) in this source version's folder: Numba names them
    ``<module>.<function>-<line>.py<ver>.nbi``, in the folder of the module's path
    (``numba_patches._content_locator``)."""
    from subtrace.runtime.jit import KERNEL_DIR

    folder, _, module = _KERNEL_MODULES[name].rpartition("/")
    return KERNEL_DIR / "subtrace" / folder, f"{module}.{name}-*.nbi"


def _index_files(name: str) -> list:
    """The index files of the kernel ``name`` (:func:`_index_pattern`): one folder listed,
    not the whole cache walked (that took about 1 ms of every render); the whole cache
    where Numba's own locator placed them (``numba_patches``: the patches off)."""
    from subtrace.runtime import numba_patches

    folder, pattern = _index_pattern(name)
    if numba_patches.APPLIED.get("content_locator"):
        return list(folder.glob(pattern))
    from subtrace.runtime.jit import KERNEL_DIR

    return list(KERNEL_DIR.rglob(pattern))


def _cached(name: str) -> bool:
    """Whether the kernel cache (this source version's folder) holds the kernel ``name``."""
    return bool(_index_files(name))


class Helpers:
    """The processes :func:`start` started: ``procs``; ``secondary``: whether one of them
    compiles the secondary-ray kernels (else the render's own process does, while it waits)."""

    def __init__(self, procs, secondary):
        self.procs = procs
        self.secondary = secondary

    def picture_while_tracing(self, threads: int) -> None:
        """:func:`picture_while_tracing` of these helpers."""
        picture_while_tracing(self, threads)

    def wait_traced(self) -> None:
        """:func:`wait_traced` for these helpers."""
        wait_traced(self)


def start(threads: int, check: bool = True):
    """Start compiling the trace and shade kernels for ``threads`` threads in a second
    process if the cache lacks them, and on a machine of three cores or more the
    secondary-ray kernels in a third; returns the :class:`Helpers` (or None). The helpers
    import what they compile at once, then wait for the cages' schemes (:func:`tell`): the
    kernels of a render without Loop cages are compiled without the Loop descents
    (``geometry.bezier.loop_flag``)."""
    if check and _cached("_trace_task") and _cached("_shade_task"):
        return None
    from subtrace.runtime.jit import compiling

    compiling()  # the first-run notice, where one was asked for
    jobs = [[str(int(threads))]]
    if _cores() >= 3 and not _cached("_rays_task"):
        jobs.append(["--secondary", str(int(threads))])
    procs = []
    for args in jobs:
        try:
            proc = subprocess.Popen([sys.executable, "-m", "subtrace.startup.warmup", *args],
                                    stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                    stderr=subprocess.DEVNULL)
        except OSError:  # no helper: the kernels compile when first called
            break
        signals.register_child(proc)  # ended with this process if it is interrupted
        procs.append(proc)
    return Helpers(procs, secondary=len(procs) == 2) if procs else None


def start_for(threads: int, schemes):
    """:func:`start`, told these ``schemes`` at once, where the cache holds the trace kernel
    but not for these schemes (a Loop render after Catmull-Clark ones compiles the kernel
    with the Loop descents: ``geometry.bezier.loop_flag``); else None."""
    from subtrace.geometry.bezier import loop_flag

    if not _cached("_trace_task") or _trace_variant_cached(loop_flag(schemes)):
        return None
    helpers = start(threads, check=False)
    tell(helpers, schemes)
    return helpers


def _trace_variant_cached(loop) -> bool:
    """Whether the trace kernel's index lists a signature compiled for ``loop`` (its last
    argument: None, or a bool); True where the index cannot be read (then the kernel
    compiles where it is first called, as before)."""
    import pickle

    from subtrace.runtime.jit import nb

    want = nb.types.none if loop is None else nb.types.boolean
    for path in _index_files("_trace_task"):
        try:
            with open(path, "rb") as f:
                pickle.load(f)  # the Numba version that wrote it
                _, overloads = pickle.loads(f.read())
            return any(key[0][-1] == want for key in overloads)
        except Exception:  # noqa: BLE001 - another Numba's index: not a reason to fail
            return True
    return False


def _cores() -> int:
    """The cores this process may run on."""
    import os

    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def tell(helpers, schemes) -> None:
    """Tell the processes from :func:`start` the schemes of the render's cages ("catmark",
    "loop"): they compile the kernels for those."""
    if helpers is not None:
        for proc in helpers.procs:
            _close(proc, " ".join(schemes))


def _close(proc, line: str = "") -> None:
    """Send ``line`` (once) and close the helper's input; a helper that had no line exits."""
    try:
        if not proc.stdin.closed:
            if line:
                proc.stdin.write(line.encode() + b"\n")
            proc.stdin.close()
    except OSError:  # it ended: its kernels compile when first called
        pass


def wait_traced(helpers) -> None:
    """Wait until the processes from :func:`start` have compiled the trace and shading
    kernels (or ended); the trace helper goes on with the picture's kernels
    (:func:`compile_picture`), which :func:`wait` waits for."""
    if helpers is not None:
        for proc in helpers.procs:
            _close(proc)
            try:
                proc.stdout.readline()  # "traced", or nothing when it ended
            except (OSError, ValueError):
                pass


def wait(helpers) -> None:
    """Wait for the processes from :func:`start` (whatever their outcome: a kernel they did
    not store is compiled by the caller when first called); one not told the schemes
    (:func:`tell`) compiles nothing."""
    if helpers is not None:
        for proc in helpers.procs:
            _close(proc)
            proc.wait()
            proc.stdout.close()
            signals.forget_child(proc)
        helpers.procs = []


def stop(helpers) -> None:
    """End the processes from :func:`start` (the render they served failed)."""
    if helpers is not None:
        for proc in helpers.procs:
            proc.kill()
            _close(proc)
            proc.wait()
            proc.stdout.close()
            signals.forget_child(proc)
        helpers.procs = []


def _schemes() -> list[str] | None:
    """The schemes :func:`tell` sends on this helper's input (None: it sent none)."""
    line = sys.stdin.readline()
    return line.split() or None


def compile_kernels(threads: int, schemes=None) -> None:
    """Compile ``shade._shade_task`` and ``trace.kernels._trace_task`` with the argument
    types of a render on ``threads`` threads of cages of these ``schemes`` (None: read them
    from the input, :func:`tell`, once the shading kernel is compiled; none there: compile
    no trace kernel): the bundles a render passes (``trace/pools.py``), empty, so nothing is
    traced."""
    import numpy as np

    from subtrace import config
    from subtrace.accel.bvh import no_bvh
    from subtrace.accel.projection import no_tiles
    from subtrace.runtime import threads as tasks
    from subtrace.geometry.bezier import loop_flag
    from subtrace.trace.kernels import trace_round
    from subtrace.trace.pools import Memos, Pieces, candidate_lists, hit_arrays

    compile_shading(threads, None)
    # (the shading first: the render's process is still reading the cages)
    schemes = _schemes() if schemes is None else schemes
    if schemes is None:
        return
    if loop_flag(schemes) is not None:
        compile_shading(threads, True)  # (and the Loop items' normals)
    i64 = np.zeros(0, np.int64)
    i32 = np.zeros(0, np.int32)  # (the rounds' requests)
    frame = np.zeros((4, 3))
    iso = Pieces(0).view()
    tasks.set_threads(threads)
    try:
        trace_round(i64, frame, 1, 0, no_bvh(), no_tiles(), np.zeros((0, 3)), np.zeros((0, 3)),
                    iso, Memos(threads).views(0), candidate_lists(0), config.TRI_SLACK,
                    hit_arrays(0), i32, np.zeros(threads, np.int64), loop_flag(schemes))
    finally:
        tasks.set_threads(None)


def compile_shading(threads: int, loop) -> None:
    """Compile ``shade._shade_task`` (and with ``loop`` True the Loop items' normals,
    ``shade._loop_normals_task``) with the argument types of a render on ``threads``
    threads, on two pixels that missed."""
    import numpy as np

    from subtrace.runtime import threads as tasks
    from subtrace.shade import CHANNELS, miss_values, shade
    from subtrace.trace.pools import Pieces, hit_arrays

    misses = hit_arrays(2)  # two pixels, both missed: the output planes' layout
    misses.t[:] = np.inf
    tasks.set_threads(threads)
    try:
        shade(np.zeros((4, 3)), 1, misses, Pieces(0).view(), _no_patches(),
              miss_values((0.0, 0.0, 0.0)), np.zeros((len(CHANNELS), 2), np.float32),
              np.zeros((2, 3)), np.zeros(2, np.int32), np.zeros(threads, np.int64), loop=loop)
    finally:
        tasks.set_threads(None)


# compile_picture's kernel groups
PICTURE = ("ground", "shadows", "light", "edges", "background", "textures")


def compile_picture(threads: int, parts=PICTURE) -> None:
    """Compile the kernels that colour a picture, by group (``parts``, of :data:`PICTURE`:
    the ground with and without shadow rays, the surfaces' shadow rays, the lights, the
    anti-aliasing's edge flags, the background, the image textures), with the argument types of a render on
    ``threads`` threads, on a few pixels of a camera looking down at the ground
    (tests/test_kernel_compiles.py checks that a render adds no signature to them). A cold render's helper compiles them all, the ground
    first; the render's own process compiles the others while it waits for the trace
    kernel (``trace.rounds.trace_hits``, :func:`picture_while_tracing`), and the helper then
    finds them in the cache."""
    import numpy as np

    from subtrace.lights import Light, light_array
    from subtrace.runtime import threads as tasks
    from subtrace.shade import (CHANNELS, background_pixels, edge_pixels, ground_pixels, light,
                                shadow_visibility)

    n, width = 4, 2
    frame = np.array([[0.0, 1.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.0, 0.1], [0.0, -1.0, 0.0]])
    planes = np.zeros((len(CHANNELS), n), np.float32)
    pix = np.full(n, -1, np.int32)
    lights = light_array([Light(direction=(0.0, -1.0, 0.0))])  # straight down

    def trace(origins, dirs, tmax):  # every shadow ray blocked
        return np.ones(len(tmax), np.uint8)

    trace.bounds = (np.full(3, -10.0), np.full(3, 10.0))
    rows = np.zeros((2, 3))
    tasks.set_threads(threads)
    try:
        for part in parts:
            if part == "ground":
                for shadows in (None, trace):
                    ground_pixels(frame, width, pix, (0.0, 1.0, 0.0), 0.0, shadows, lights,
                                  0.5, None, rows, planes)
            elif part == "shadows":  # every pixel hit, facing the light
                up = np.tile([0.0, 1.0, 0.0], (n, 1))
                shadow_visibility(trace, frame, width, np.ones(n), up, np.zeros(n, np.int32),
                                  lights, 1e-3)
            elif part == "light":
                light(frame, width, np.full(n, np.inf), np.zeros((n, 3)), pix, _no_patches(),
                      lights, np.array([0.5]), np.ones((1, n), np.float32), planes)
            elif part == "edges":
                edge_pixels(planes, width, n // width)
            elif part == "textures":
                _compile_textures()
            else:
                background_pixels(np.arange(n), rows, width, planes)
    finally:
        tasks.set_threads(None)


def _compile_textures() -> None:
    """The image textures' kernels (``subtrace.textures``: the hits' tangents, the linear
    mode's UVs, the footprints, the MIP-map filter) with the argument types of a render, on
    no hits of a one-quad cage with UVs and one lookup of a one-texel texture."""
    from types import SimpleNamespace

    import numpy as np

    from subtrace.io.obj import TextureMap
    from subtrace.mesh.cage import make_cage
    from subtrace.subdiv.facevarying import FVAR_ALL
    from subtrace.textures import (HitFrames, Pyramid, cage_uvs, filter_levels, footprints,
                                   hit_frames)
    from subtrace.trace.pools import Pieces, hit_arrays

    quad = make_cage(np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]),
                     np.array([4]), np.array([0, 1, 2, 3]),
                     uvs=np.array([[0.0, 0], [1, 0], [1, 1], [0, 1]]),
                     face_uvs=np.array([0, 1, 2, 3]), uv_mode=FVAR_ALL)
    cage_uvs(quad, np.zeros(1, np.int64), np.full((1, 2), 0.5))
    none = np.zeros(0, np.int64)
    no_table = SimpleNamespace(object_id=np.zeros(0, np.int32), objects=())
    hit_frames(no_table, hit_arrays(0), Pieces(0).view(), _no_patches(), none)
    # (hit_frames' tangents are views of one array, of layout A: two rows, as NumPy counts
    # an empty or one-row view contiguous)
    tangents = np.tile([1.0, 0, 0, 0, 1, 0], (2, 1))
    footprints(HitFrames(np.zeros(2, np.int64), np.zeros((2, 2)), np.zeros((2, 2, 2)),
                         tangents[:, :3], tangents[:, 3:]), np.ones(2),
               np.tile([0.0, 0.0, -1.0], (2, 1)), 1e-3)
    texel = Pyramid(np.ones(3, np.float32), np.array([[0, 1, 1]], np.int64), 3)
    filter_levels(texel, TextureMap("diffuse", "", "warm-up"), np.full((1, 2), 0.5),
                  np.full((1, 2), 0.1), np.full((1, 2), 0.1), 3)


def picture_while_tracing(helpers, threads: int) -> None:
    """In the render's own process, before it waits for the trace kernel: compile the
    picture's groups other than the ground's (:func:`compile_picture`), one at a time, while
    the helpers have not said that the trace kernel is ready (:func:`traced`)."""
    for part in PICTURE[1:]:
        if traced(helpers):
            return
        compile_picture(threads, (part,))


def traced(helpers) -> bool:
    """Whether every process from :func:`start` has said that the trace kernel is compiled
    (or ended), without reading what it said (:func:`wait_traced` reads it)."""
    import select

    for proc in helpers.procs:
        try:
            ready = proc.poll() is not None or select.select([proc.stdout], [], [], 0)[0]
        except (OSError, ValueError):
            ready = True
        if not ready:
            return False
    return True


def compile_bvh() -> None:
    """Compile the BVH build of the secondary rays (``accel.bvh.build_bvh``) on two boxes
    of the types a render passes (the shells, (P,3) float64)."""
    import numpy as np

    from subtrace.accel.bvh import build_bvh

    build_bvh(np.zeros((2, 3)), np.ones((2, 3)))


def _no_patches():
    """A ``shade.PatchShading`` of no patches, with the field types of a render's."""
    import numpy as np

    from subtrace.shade import PatchShading

    return PatchShading(np.zeros(0, np.int32), np.zeros(0, np.int32), np.zeros((0, 2)),
                        np.zeros(0), np.zeros(0, np.int8), np.zeros((0, 3)), np.zeros((0, 3)),
                        np.zeros(0), np.zeros((0, 3)), np.zeros(0))


def compile_secondary(threads: int) -> None:
    """Compile the secondary-ray kernel for ``threads`` threads
    (``trace.rays.compile_kernel``) and the schemes read from the input (:func:`tell`)."""
    from subtrace.runtime import threads as tasks
    from subtrace.trace.rays import compile_kernel

    schemes = _schemes()
    if schemes is None:
        return
    tasks.set_threads(threads)
    try:
        compile_kernel(schemes)
    finally:
        tasks.set_threads(None)


if __name__ == "__main__":
    signals.unblock()  # the mask of a parent that hands its signals to a watcher thread
    from subtrace.runtime.jit import trim_compiler

    trim_compiler()
    if sys.argv[1] == "--secondary":  # the secondary-ray kernels, a third process
        compile_secondary(int(sys.argv[2]))
    else:
        compile_kernels(int(sys.argv[1]))
        print("traced", flush=True)  # (wait_traced) the render may start its rounds
        compile_picture(int(sys.argv[1]))
    # (the kernels are in the cache: end without the interpreter's teardown of Numba's
    # registries, which the render waiting for this process (:func:`wait`) would wait for;
    # 0.2-0.5 s of a cold render while the render's process competed for the cores)
    signals.exit_now(0)
