"""``subtrace warmup [--jobs N]``: compile every kernel into the kernel cache
(:func:`compile_all`) and say where the cache is, with a line of progress
(:func:`progress_line`) after each of its commands and every few seconds between.

Run it once after installing (or in a cluster's image, or on one worker of a shared cache
folder) so that the first real command loads its kernels instead of compiling them.

:func:`compile_all` runs small commands of every kind (the default render, which compiles in
two processes itself, :mod:`subtrace.startup.warmup`; then, side by side, renders of a Loop
cage and of trimmed NURBS surfaces, the BVH, line queries on both schemes and on surfaces,
the cage report) so that the kernel cache holds every kernel before the first real command,
e.g. once per machine or image before a cluster's workers start.

    python -m subtrace.cli.warmup --commands JSON  # a chain of subtrace warmup's commands
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from subtrace.cli.common import set_up_numba
from subtrace.errors import SubtraceError
from subtrace.runtime import signals


def execute(args) -> int:
    """Compile what the cache lacks; print the cache folder and what it holds."""
    jobs = _jobs(args.jobs)
    set_up_numba(args)
    from subtrace.runtime import jit

    before = _files(jit.KERNEL_DIR)
    if not args.quiet:
        print(f"kernel cache: {jit.KERNEL_DIR}", flush=True)
    report = None if args.quiet else _reporter(jit.KERNEL_DIR)
    seconds = compile_all(jobs, report)
    after = _files(jit.KERNEL_DIR)
    if not args.quiet:
        kernels = sum(1 for name in after if name.endswith(".nbi"))
        new = len(after - before)
        what = (f"compiled in {seconds:.1f} s" if new
                else f"every kernel was cached already ({seconds:.1f} s)")
        print(f"{kernels} kernels, {_megabytes(jit.KERNEL_DIR):.1f} MB: {what}")
    return 0


def progress_line(done: int, total: int, kernels: int, seconds: float) -> str:
    """One line of ``subtrace warmup``'s progress: commands done of all, the kernels the
    cache holds so far, the seconds since it started."""
    return f"warmup: {done}/{total} commands done, {kernels} kernels in the cache, {seconds:.0f} s"


def _reporter(folder):
    """``progress(done, total, seconds)`` for compile_all: a :func:`progress_line`, with the
    kernels counted in ``folder``, printed at once."""

    def report(done, total, seconds):
        kernels = sum(1 for name in _files(folder) if name.endswith(".nbi"))
        print(progress_line(done, total, kernels, seconds), flush=True)

    return report


def _jobs(text) -> int:
    """``--jobs``: commands compiled at once (default: the usable cores)."""
    if text is None:
        return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
                   else os.cpu_count() or 1)
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise SubtraceError(f"--jobs: expected an integer >= 1, got {text!r}")
    return value


def _files(folder) -> set[str]:
    """The cache files under ``folder`` (relative paths)."""
    return {str(p.relative_to(folder)) for p in folder.rglob("*.nb[ic]")}


def _megabytes(folder) -> float:
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file()) / 2**20


def compile_all(jobs: int, progress=None) -> float:
    """Compile every kernel of every command into the kernel cache (``subtrace warmup``),
    running up to ``jobs`` commands at once; returns the seconds it took. ``progress(done,
    total, seconds)``, where given, hears the commands done so far after each one and every
    :data:`HEARTBEAT_S` in between (a cold default render alone compiles for half a minute
    or more). A command that fails raises :class:`subtrace.errors.SubtraceError` naming it
    and its error line."""
    t0 = time.perf_counter()
    folder = Path(tempfile.mkdtemp(prefix="subtrace-warmup-"))
    try:
        stages = _stages(folder)
        counter = _Counter(sum(len(chain) for stage in stages for chain in stage), progress, t0)
        for stage in stages:
            _run_side_by_side(stage, max(1, jobs), counter)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    return time.perf_counter() - t0


HEARTBEAT_S = 10.0  # the longest compile_all's progress stays silent, in seconds


class _Counter:
    """The commands of :func:`compile_all` done so far, told to ``progress(done, total,
    seconds)`` after each one and at least every :data:`HEARTBEAT_S`."""

    def __init__(self, total: int, progress, t0: float):
        self.done, self.total, self.progress, self.t0 = 0, total, progress, t0
        self.said = t0

    def step(self) -> None:
        self.done += 1
        self.say()

    def timeout(self) -> float:
        """Seconds until the next line is due."""
        return max(0.05, HEARTBEAT_S - (time.perf_counter() - self.said))

    def tick(self) -> None:
        if time.perf_counter() - self.said >= HEARTBEAT_S:
            self.say()

    def say(self) -> None:
        self.said = time.perf_counter()
        if self.progress is not None:
            self.progress(self.done, self.total, self.said - self.t0)


def _stages(folder: Path) -> list[list[list[list[str]]]]:
    """What :func:`compile_all` runs: stages one after the other, each a list of chains run
    side by side, each chain a list of ``subtrace`` commands (argument lists) run in order
    by one process. The default render comes first (it compiles the shared loading kernels,
    and its trace kernels in a second process); then the line queries and the cage report
    beside the renders of a Loop cage, of trimmed NURBS surfaces and through the BVH, on
    inputs written to ``folder``; commands that share kernels share a chain, so that no two
    processes compile the same kernel."""
    from subtrace.data import sample_cage_path, sample_surfaces_path

    tris = folder / "spot_triangles.obj"
    tris.write_text(_triangulated(sample_cage_path().read_text()))
    creased = folder / "creased_cube.obj"
    creased.write_text(_CREASED_CUBE)
    lines = folder / "lines.csv"
    lines.write_text("ox,oy,oz,dx,dy,dz\n0,0.1,5,0,0,-1\n0.2,0.3,-5,0,0,1\n0.3,-3,0.2,0.1,1,0\n")
    small = ["--width", "48", "--height", "32", "--quiet"]

    def intersect(cage):
        return [["intersect", str(cage), "--lines", str(lines), "--precision", "1e-3", *mode,
                 "-o", str(folder / "hits.csv")] for mode in ([], ["--first"])]

    first = [["render", *small, "-o", str(folder / "default.exr")]]
    queries = [*intersect(sample_cage_path()), *intersect(tris),
               ["info", str(tris), "--level", "1"],
               # (boundary "none": the tagging kernel, which cages of the other modes skip)
               ["info", str(creased), "--level", "2", "--boundary", "none"]]
    renders = [["render", str(tris), *small, "--ao", "4", "-o", str(folder / "loop.exr")],
               ["render", str(creased), *small, "-o", str(folder / "creased.exr")],
               ["render", *small, "--accel", "bvh", "--ao", "4", "-o", str(folder / "bvh.exr")],
               ["render", str(sample_surfaces_path()), *small, "--ao", "4",
                "-o", str(folder / "nurbs.exr")],
               *intersect(sample_surfaces_path())]
    return [[first], [queries, renders]]


# an open box (five faces of a cube: a boundary) with a semi-sharp and two infinitely sharp
# crease edges, a corner and a hole: the kernels of creases, corners, boundaries and holes
# that Spot does not reach
_CREASED_CUBE = """v -1 -1 -1
v 1 -1 -1
v 1 1 -1
v -1 1 -1
v -1 -1 1
v 1 -1 1
v 1 1 1
v -1 1 1
f 1 4 3 2
f 5 6 7 8
f 1 2 6 5
f 2 3 7 6
f 3 4 8 7
t crease 2/1/0 0 1 2.5
t crease 4/1/0 1 2 2 6 10
t corner 1/1/0 7 3
t hole 1/0/0 4
"""


def _triangulated(obj_text: str) -> str:
    """An OBJ cage's text with each face split into a fan of triangles (a Loop cage)."""
    out = []
    for line in obj_text.splitlines():
        parts = line.split()
        if parts and parts[0] == "f":
            corners = parts[1:]
            out += [f"f {corners[0]} {corners[k]} {corners[k + 1]}"
                    for k in range(1, len(corners) - 1)]
        else:
            out.append(line)
    return "\n".join(out) + "\n"


def _run_side_by_side(chains: list[list[list[str]]], jobs: int, counter: _Counter) -> None:
    """Run each chain of ``subtrace`` commands in a process of its own (``python -m
    subtrace.cli.warmup --commands JSON``), at most ``jobs`` processes at once; each says
    a line on its output when one of its commands is done (``counter``)."""
    import select

    pending = list(chains)
    running = []
    try:
        while pending or running:
            while pending and len(running) < jobs:
                running.append(_start_chain(pending.pop(0)))
            ready = select.select([p.stdout for p in running], [], [], counter.timeout())[0]
            for proc in [p for p in running if p.stdout in ready]:
                if proc.stdout.readline():
                    counter.step()
                else:  # its output closed: it ended
                    running.remove(proc)
                    _finish_chain(proc)
            counter.tick()
    finally:
        for proc in running:
            proc.kill()
            proc.wait()
            _finish_chain(proc, check=False)


def _start_chain(chain: list[list[str]]):
    """The process running ``chain``: its output unbuffered (one line per command done),
    its errors in a temporary file (read when it ends)."""
    errors = tempfile.TemporaryFile(mode="w+")
    proc = subprocess.Popen([sys.executable, "-m", "subtrace.cli.warmup", "--commands",
                             json.dumps(chain)], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=errors, bufsize=0)
    proc.errors = errors
    signals.register_child(proc)
    return proc


def _finish_chain(proc, check: bool = True) -> None:
    """Wait for a chain's process; with ``check``, a failure is a SubtraceError naming its
    last error line."""
    proc.wait()
    signals.forget_child(proc)
    proc.stdout.close()
    proc.errors.seek(0)
    err = proc.errors.read()
    proc.errors.close()
    if check and proc.returncode != 0:
        last = (err.strip().splitlines() or ["no message"])[-1]
        raise SubtraceError(f"warmup: a command failed (exit code {proc.returncode}): {last}")


def _run_commands(chain: list[list[str]]) -> int:
    """Run the ``subtrace`` commands of ``chain`` in this process, in order, each saying
    ``done`` on this process's output when it ends (what the commands print is dropped);
    the first failure's exit code (its error line is on stderr, followed by the command),
    else 0."""
    import contextlib
    import io

    from subtrace.cli import main
    from subtrace.io import obj_scan

    obj_scan.STATEMENT_READER_BYTES = 0  # (the OBJ scanner compiles too, whatever the size)
    out = sys.stdout
    for argv in chain:
        with contextlib.redirect_stdout(io.StringIO()):
            code = main(argv)
        if code != 0:
            print(f"subtrace warmup: `subtrace {' '.join(argv)}` failed", file=sys.stderr)
            return code
        print("done", file=out, flush=True)
    return 0


if __name__ == "__main__":  # subtrace warmup: a chain of commands (JSON)
    signals.unblock()  # the mask of a parent that hands its signals to a watcher thread
    sys.exit(_run_commands(json.loads(sys.argv[2])))
