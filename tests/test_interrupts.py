"""Interrupts and concurrent writers (runtime/signals.py, runtime/atomic.py).

A ``subtrace`` process that gets SIGINT or SIGTERM, whatever it is doing (starting, loading,
tracing, writing), ends promptly with one line ``subtrace: interrupted``, exit code 130 /
143, no traceback, no temporary file, and a complete earlier output left as it was (or
replaced by the complete new one, when the signal came after the rename). Trials are
seeded: the moments are random but the same on every run.
"""

from __future__ import annotations

import os
import random
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from shared_data import MODELS

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "scenes" / "spot.toml"
SMALL = ["--width", "160", "--height", "90", "--threads", "2"]
TRIALS = 50
MOMENT_SPAN = 1.6  # signals land over 1.6 times a command's run time
STOP_LIMIT_S = 1.0  # asserted; the command's own budget is 0.5 s (benchmarks/interrupts.py)


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT / "src") + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _default_signals():
    # a test run started in the background (``pytest &``, nohup) ignores SIGINT, and its
    # children would inherit that (subtrace then leaves the signal ignored, as it should)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_DFL)


def _start(args):
    return subprocess.Popen([sys.executable, "-m", "subtrace.cli", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=_env(),
                            preexec_fn=_default_signals)


def _wait_until_watched(proc, limit_s=30.0):
    """Wait until the process hands SIGINT to its watcher thread (its main thread blocks
    it: /proc's SigBlk mask), i.e. until subtrace's own code runs; before that the
    interpreter is starting and Python's own handling applies (runtime/signals.py)."""
    status = Path(f"/proc/{proc.pid}/status")
    end = time.perf_counter() + limit_s
    while time.perf_counter() < end and proc.poll() is None:
        try:
            mask = next(int(line.split()[1], 16) for line in status.read_text().splitlines()
                        if line.startswith("SigBlk:"))
        except (OSError, StopIteration):
            return
        if mask & (1 << (signal.SIGINT - 1)):
            return
        time.sleep(0.002)


def _commands(tmp: Path):
    """(name, arguments, the output files it writes) of the commands the trials interrupt."""
    exr = tmp / "out.exr"
    return [
        ("render", ["render", str(SCENE), "-o", str(exr), *SMALL], [exr]),
        ("render+png", ["render", str(MODELS / "spot_control_mesh.obj"), "-o", str(exr),
                        "--png", *SMALL], [exr, exr.with_suffix(".png")]),
        ("sweep", ["sweep", str(SCENE), "--tolerances", "4", "-o", str(tmp / "sw"),
                   *SMALL], [tmp / "sw" / "sweep.csv", tmp / "sw" / "sweep.json"]),
    ]


def _complete_image(path: Path) -> bool:
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        return False
    try:
        pixels = inp.read_image(oiio.FLOAT)
        return pixels is not None and pixels.shape[:2] == (90, 160)
    finally:
        inp.close()


def _leftovers(folder: Path):
    return [p.name for p in folder.rglob("*") if p.name.endswith(".tmp")]


@pytest.fixture(scope="module")
def earlier(tmp_path_factory):
    """Each command run once to the end: its arguments, complete outputs (bytes), to be
    interrupted while rewriting them, and how long it ran once watched (the trials' signals
    land anywhere in that time and a little after it)."""
    tmp = tmp_path_factory.mktemp("earlier")
    out = {}
    for name, args, files in _commands(tmp):
        durations = []
        for _ in range(3):  # the first may compile kernels; the faster of the rest counts
            proc = _start(args)
            _wait_until_watched(proc)
            t0 = time.perf_counter()
            _, err = proc.communicate(timeout=300)
            assert proc.returncode == 0, err.decode()
            durations.append(time.perf_counter() - t0)
        out[name] = (args, {f.relative_to(tmp): f.read_bytes() for f in files},
                     min(durations[1:]))
    return tmp, out


def _moments(rng, names):
    """Each trial's moment as a fraction of its command's run time (as the trials estimate
    it): stratified over [0, MOMENT_SPAN) per command, so that both outcomes (stopped and
    finished) come up among its trials."""
    fractions = []
    counts = {name: 0 for name in names}
    slots = {}
    for trial in range(TRIALS):
        counts[names[trial % len(names)]] += 1
    for name, n in counts.items():
        order = list(range(n))
        rng.shuffle(order)
        slots[name] = [MOMENT_SPAN * (k + rng.random()) / n for k in order]
    for trial in range(TRIALS):
        fractions.append(slots[names[trial % len(names)]].pop())
    return fractions


def test_interrupts_at_random_moments(earlier, tmp_path):
    """At least 50 seeded trials: render, render with a PNG beside, and sweep, each over a
    complete earlier output, interrupted by SIGINT or SIGTERM at a random moment."""
    base, runs = earlier
    rng = random.Random(20261124)
    names = sorted(runs)
    stopped = finished = 0
    moments = _moments(rng, names)
    # each command's run time, as the trials see it: the machine's speed drifts (other
    # work, a cache), so it follows the trials, down to a run that finished before its
    # signal (its own time), up to the moment of a late signal that still stopped one
    took = {name: [runs[name][2]] for name in names}
    for trial in range(TRIALS):
        name = names[trial % len(names)]
        args, files, _ = runs[name]
        duration = statistics.median(took[name])
        folder = tmp_path / f"t{trial}"
        for rel, data in files.items():
            (folder / rel).parent.mkdir(parents=True, exist_ok=True)
            (folder / rel).write_bytes(data)
        args = [str(folder / Path(a).relative_to(base)) if a.startswith(str(base)) else a
                for a in args]
        sig = rng.choice([signal.SIGINT, signal.SIGTERM])
        proc = _start(args)
        _wait_until_watched(proc)
        watched = time.perf_counter()
        moment = moments[trial] * duration
        try:  # (its output is a few lines: the pipes do not fill while it runs)
            proc.wait(timeout=moment)
            took[name].append(time.perf_counter() - watched)
        except subprocess.TimeoutExpired:
            if moments[trial] >= 1.0:  # later than the estimate, and it still ran
                took[name] = [max(t, moment) for t in took[name]]
        sent = time.perf_counter()
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=60)
        waited = time.perf_counter() - sent
        err = err.decode()
        where = f"trial {trial} ({name}, {sig.name})"
        if proc.returncode == 0:  # it had finished before the signal
            finished += 1
            assert "Traceback" not in err, where
        else:
            stopped += 1
            assert proc.returncode == {signal.SIGINT: 130, signal.SIGTERM: 143}[sig], where
            assert err == "subtrace: interrupted\n", f"{where}: {err!r}"
            assert waited < STOP_LIMIT_S, f"{where}: took {waited:.2f} s to stop"
        assert not _leftovers(folder), f"{where}: {_leftovers(folder)}"
        for rel, data in files.items():
            path = folder / rel
            assert path.exists(), f"{where}: {rel} is gone"
            if path.read_bytes() != data:  # replaced: then by a complete file
                assert path.suffix in (".exr", ".png") and _complete_image(path) or \
                    path.suffix in (".csv", ".json") and path.read_text().strip(), where
    # the moments cover both outcomes (otherwise the trials would test nothing)
    assert stopped >= TRIALS // 2 and finished >= 1, (stopped, finished, took)


def test_two_renders_to_one_path(tmp_path):
    """Two processes rendering to one path at once: both succeed, the file is one complete
    image (one of theirs), and no temporary file remains."""
    out = tmp_path / "same.exr"
    procs = [_start(["render", str(SCENE), "-o", str(out), *SMALL, "--fov", str(fov)])
             for fov in (30.0, 45.0)]
    for proc in procs:
        _, err = proc.communicate(timeout=300)
        assert proc.returncode == 0, err.decode()
    assert not _leftovers(tmp_path)
    assert _complete_image(out)
    # the file is one of the two renders, not a mixture: render each alone and compare
    singles = []
    for k, fov in enumerate((30.0, 45.0)):
        single = tmp_path / f"single{k}.exr"
        proc = _start(["render", str(SCENE), "-o", str(single), *SMALL, "--fov", str(fov)])
        assert proc.wait(timeout=300) == 0
        singles.append(_pixels(single))
    got = _pixels(out)
    assert any(np.array_equal(got, s, equal_nan=True) for s in singles)


def _pixels(path):
    inp = oiio.ImageInput.open(str(path))
    try:
        return inp.read_image(oiio.FLOAT)
    finally:
        inp.close()



def test_no_temporary_reappears_after_the_cleanup(tmp_path):
    """The interrupt's clean-up (the watcher thread: it takes the temporaries' lock for
    good, then removes every registered temporary) may land after a temporary was created
    and before its writer opens it by name: the writer must not create it again. Here the
    clean-up runs at exactly that moment (from the pixels callable) and holds the lock for
    0.4 s, watching the folder: before the writers opened their temporaries under the
    lock, OpenImageIO created the file again within that time (1 of 50 seeded trials of
    the interrupt test, under load)."""
    import threading

    from subtrace.runtime.atomic import open_temp
    from subtrace.io.exr import _png_spec, _write_all
    from subtrace.runtime import signals

    seen = []
    holding, release, opened = threading.Event(), threading.Event(), threading.Event()

    def cleanup():
        with signals.temp_lock():
            for path in list(signals._temps):
                os.unlink(path)
                signals.forget_temp(path)
            holding.set()
            deadline = time.perf_counter() + 0.4
            while time.perf_counter() < deadline:
                seen.extend(p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp"))
                time.sleep(0.01)
            release.wait(5)

    def pixels():
        threading.Thread(target=cleanup, daemon=True).start()
        holding.wait(5)
        return np.zeros((4, 4, 3), np.uint8)

    def write():
        try:
            _write_all([(tmp_path / "out.png", "png", _png_spec(4, 4), pixels)])
        except Exception:  # noqa: BLE001 - (its temporary was removed under it)
            pass

    def open_text():
        holding.wait(5)
        with open_temp(str(tmp_path / ".x.tmp"), "w"):
            opened.set()

    jobs = [threading.Thread(target=f, daemon=True) for f in (write, open_text)]
    try:
        for job in jobs:
            job.start()
        assert holding.wait(5), "the clean-up never ran"
        time.sleep(0.5)
        assert not seen, f"a temporary came back after the clean-up: {sorted(set(seen))}"
        assert not opened.is_set()  # open_temp waits for the lock too
    finally:
        release.set()
        for job in jobs:
            job.join(10)


CUBE = ("v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n"
        "f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 3 4 8 7\nf 2 3 7 6\nf 1 5 8 4\n")


@pytest.mark.parametrize("after_s", [0.0, 0.4])
def test_an_interrupted_tiled_dask_job_leaves_no_tiles(tmp_path, after_s):
    """``--tile N --dask`` interrupted while its workers write tiles (``after_s`` after the
    first tile's file appears): one line, exit 130, and neither a tile's file (169 MB at
    4K were left before), nor a temporary, nor a partial image in the folder."""
    pytest.importorskip("distributed", reason="dask[distributed] is not installed")
    cube = tmp_path / "cube.obj"
    cube.write_text(CUBE)
    out = tmp_path / "out.exr"
    proc = _start(["render", str(cube), "-o", str(out), "--width", "128", "--height", "96",
                   "--tile", "16", "--dask"])
    _wait_until_watched(proc)
    end = time.perf_counter() + 240
    while not list(tmp_path.glob(".*.tile.npz")) and proc.poll() is None:
        assert time.perf_counter() < end, "no tile was written"
        time.sleep(0.01)
    time.sleep(after_s)
    assert proc.poll() is None, "the job ended before the signal"
    tiles_then = len(list(tmp_path.glob(".*.tile.npz")))
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and err.decode() == "subtrace: interrupted\n", err.decode()
    assert tiles_then >= 1
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == ["cube.obj"] or left == ["cube.obj", "out.exr"] and _complete_at(
        out, 96, 128), left


def _complete_at(path: Path, height: int, width: int) -> bool:
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        return False
    try:
        pixels = inp.read_image(oiio.FLOAT)
        return pixels is not None and pixels.shape[:2] == (height, width)
    finally:
        inp.close()
