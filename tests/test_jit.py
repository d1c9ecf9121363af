"""The kernel cache: its folder's key and each kernel's stamp follow the sources' bytes, not
their modification times or install folder; old folders are pruned; the first-run notice."""

from __future__ import annotations

import io
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numba
import pytest

from shared_data import COMPILE_LISTENER
from subtrace.runtime import jit

CPU = ("x86_64-unknown-linux-gnu", "generic", "")  # any fixed target: the key's other inputs


def test_prune_keeps_the_most_recent_cache_folders(tmp_path):
    n = jit.CACHES_KEPT + 3
    for k in range(n):
        d = tmp_path / f"numba-{k:016x}"
        d.mkdir()
        (d / "index.nbi").write_bytes(b"x")
        os.utime(d, (1_000_000 + k, 1_000_000 + k))  # folder k used at time k
    (tmp_path / "other").mkdir()  # not a cache folder: left alone
    (tmp_path / "numba-notakey").mkdir()  # another program's folder in a shared base: kept
    os.utime(tmp_path / "numba-notakey", (0, 0))
    jit.prune_caches(tmp_path)
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == [f"numba-{k:016x}" for k in range(3, n)] + ["numba-notakey", "other"]


def _copy_sources(dest: Path, mtime: float) -> Path:
    """The package's sources copied to ``dest/subtrace``, every file's mtime ``mtime``."""
    root = dest / "subtrace"
    shutil.copytree(jit.ROOT, root, ignore=shutil.ignore_patterns("__pycache__"))
    for p in root.rglob("*"):
        os.utime(p, (mtime, mtime))
    return root


def test_the_key_follows_the_bytes_not_the_times_or_the_folder(tmp_path):
    """Two copies at different paths and times, one of them with every file rewritten with
    the same bytes (what a reinstall does): the same digests and key. One byte changed in a
    module (a helper other modules' kernels call): only its digest changes, and the key."""
    a = _copy_sources(tmp_path / "a", 1_000_000_000)
    b = _copy_sources(tmp_path / "b", 1_700_000_000)
    for p in b.rglob("*.py"):
        p.write_bytes(p.read_bytes())  # new mtime, same bytes
    da, db = jit.source_digests(a), jit.source_digests(b)
    assert da == db and len(da) == len(list(jit.ROOT.rglob("*.py")))
    assert jit.cache_key(da, "0.60.0", CPU) == jit.cache_key(db, "0.60.0", CPU)
    helper = b / "geometry" / "prims.py"
    helper.write_bytes(helper.read_bytes().replace(b"    ", b"   \t", 1))  # still valid
    db2 = jit.source_digests(b)
    assert {k for k in da if da[k] != db2[k]} == {"geometry/prims.py"}
    assert jit.cache_key(da, "0.60.0", CPU) != jit.cache_key(db2, "0.60.0", CPU)
    # and the Numba version and the CPU are part of the key
    key = jit.cache_key(da, "0.60.0", CPU)
    assert key != jit.cache_key(da, "0.61.0", CPU)
    assert key != jit.cache_key(da, "0.60.0", (CPU[0], "znver3", CPU[2]))


_PROBE = """
import json, sys
import numpy as np
from subtrace.runtime import jit
from subtrace.accel.bvh import slab_range   # a kernel of subtrace's (cache=True)
slab_range(0.0, 0.0, -5.0, 1e300, 1e300, 1.0, -1.0, -1.0, -1.0, 1.0, 1.0, 1.0, 0.0, 10.0)
st = slab_range.stats
print(json.dumps({"folder": str(jit.KERNEL_DIR), "path": st.cache_path,
                  "stamp": slab_range._cache._impl.locator.get_source_stamp(),
                  "hits": sum(st.cache_hits.values()), "misses": sum(st.cache_misses.values()),
                  "module": jit.ROOT.as_posix()}))
"""


def _probe(src: Path, cache: Path) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(PYTHONPATH=str(src), SUBTRACE_CACHE_DIR=str(cache), PYTHONDONTWRITEBYTECODE="1")
    proc = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True,
                          env=env, timeout=600, cwd=src)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


def test_a_reinstall_elsewhere_loads_the_kernels_and_an_edit_compiles_them(tmp_path):
    """A kernel compiled from one copy of the sources is loaded, not compiled, from a copy
    in another folder with other modification times (the same cache folder and the same
    per-file stamp, which Numba checks for every kernel); after a one-byte edit of another
    module the cache folder differs and the kernel compiles again."""
    cache = tmp_path / "cache"
    a = _copy_sources(tmp_path / "a", 1_000_000_000)
    b = _copy_sources(tmp_path / "b", 1_700_000_000)
    first = _probe(a.parent, cache)
    assert first["module"] == a.as_posix() and (first["hits"], first["misses"]) == (0, 1)
    second = _probe(b.parent, cache)
    assert second["module"] == b.as_posix()
    assert (second["hits"], second["misses"]) == (1, 0)
    assert (second["folder"], second["path"], second["stamp"]) == (
        first["folder"], first["path"], first["stamp"])
    assert Path(first["path"]).relative_to(first["folder"]).as_posix() == "subtrace/accel"
    helper = b / "geometry" / "prims.py"
    helper.write_bytes(helper.read_bytes() + b"# an edit\n")
    third = _probe(b.parent, cache)
    assert third["folder"] != first["folder"] and (third["hits"], third["misses"]) == (0, 1)
    assert third["stamp"] == first["stamp"]  # bvh.py itself did not change


class _Stream(io.StringIO):
    def __init__(self, tty):
        super().__init__()
        self.tty = tty

    def isatty(self):
        return self.tty


@pytest.fixture
def fresh_notice(monkeypatch):
    """The notice's state as in a new process (restored afterwards)."""
    monkeypatch.setattr(jit, "_notice", {"stream": None, "said": False, "listening": False})


def _compile_a_function_of(module: str) -> None:
    """Compile (not from a cache) a function whose module is ``module``."""
    def f(x):
        return x + 1

    f.__module__ = module
    numba.njit(f)(1)


def test_the_first_compile_is_announced_once_on_a_terminal(fresh_notice):
    stream = _Stream(tty=True)
    jit.notify_compiles(stream)
    _compile_a_function_of("tests.elsewhere")  # not subtrace's: no notice
    assert stream.getvalue() == ""
    _compile_a_function_of("subtrace.fake")
    _compile_a_function_of("subtrace.other")
    jit.compiling()  # a helper process started
    lines = stream.getvalue().splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("subtrace: compiling the Numba kernels")
    assert jit.COLD_COMPILE in lines[0] and str(jit.KERNEL_DIR) in lines[0]


def test_no_notice_where_stderr_is_not_a_terminal(fresh_notice):
    stream = _Stream(tty=False)
    jit.notify_compiles(stream)
    _compile_a_function_of("subtrace.fake")
    jit.compiling()
    assert stream.getvalue() == ""


def _run_on_pty(argv, env) -> tuple[int, str]:
    """Run ``argv`` with stderr on a pseudo-terminal (stdout discarded): exit code, stderr."""
    import pty

    master, slave = pty.openpty()
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=slave, env=env)
    os.close(slave)
    chunks = []
    while True:
        try:
            data = os.read(master, 4096)
        except OSError:  # EIO: the child closed the terminal
            break
        if not data:
            break
        chunks.append(data)
    os.close(master)
    return proc.wait(timeout=600), b"".join(chunks).decode(errors="replace")


def test_a_cold_command_on_a_terminal_says_it_compiles_once(tmp_path):
    """``subtrace info`` (a command that compiles kernels) in its own process with stderr on
    a pseudo-terminal: an empty cache gives one notice line, a warm one none."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(PYTHONPATH=str(jit.ROOT.parent), SUBTRACE_CACHE_DIR=str(tmp_path / "cache"))
    argv = [sys.executable, "-m", "subtrace.cli", "info"]
    code, err = _run_on_pty(argv, env)
    assert code == 0
    assert err.count("subtrace: compiling the Numba kernels") == 1, err
    assert str(tmp_path / "cache") in err.replace("\r\n", "")
    code, err = _run_on_pty(argv, env)
    assert code == 0 and "compiling" not in err, err


_COMPILES = COMPILE_LISTENER + """
import json, sys
from subtrace.cli.main import main

code = main(["render", "--width", "48", "--height", "32", "--quiet", "-o", sys.argv[1]])
print(json.dumps({"code": code, "compiled": compiled}))
"""


def test_a_warm_render_compiles_nothing(tmp_path):
    """Once the kernel cache holds a render's kernels, a render of the default scene (with
    its shadows, ground and anti-aliasing) in a fresh process compiles nothing: no helper
    that subtrace's own Python code calls may lack the wrapper Python calls it through
    (jit.leaf_njit's ``python=True``), or it would compile a call of its own every time."""
    def render():
        proc = subprocess.run([sys.executable, "-c", _COMPILES, str(tmp_path / "x.exr")],
                              capture_output=True, text=True, timeout=900)
        assert proc.returncode == 0, proc.stderr
        out = json.loads(proc.stdout.strip().splitlines()[-1])
        assert out["code"] == 0
        return out["compiled"]

    render()  # (fills the cache where it lacks a kernel)
    assert render() == []
