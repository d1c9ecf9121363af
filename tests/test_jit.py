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

from shared_data import COMPILE_LISTENER, run_fresh
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
    helper = b / "trace" / "prims.py"
    helper.write_bytes(helper.read_bytes().replace(b"    ", b"   \t", 1))  # still valid
    db2 = jit.source_digests(b)
    assert {k for k in da if da[k] != db2[k]} == {"trace/prims.py"}
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
    helper = b / "trace" / "prims.py"
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


def test_object_symbols_are_what_the_object_code_defines():
    """The names read from an object file's ELF symbol table (what the cache loader tells
    Numba's engine a loaded kernel defines, instead of parsing its bitcode) are the
    module's defined functions and globals, as LLVM lists them, and not what it only
    declares; data that is not an ELF object gives None (the loader then parses the
    bitcode as Numba does)."""
    import llvmlite.binding as ll

    ll.initialize_native_target()
    ll.initialize_native_asmprinter()
    module = ll.parse_assembly("""
        @table = global [4 x double] zeroinitializer
        @hidden = internal global i64 3
        declare double @elsewhere(double)
        define double @twice(double %x) {
          %y = fadd double %x, %x
          ret double %y
        }
        define linkonce_odr double @shared(double %x) {
          %y = call double @elsewhere(double %x)
          ret double %y
        }
        define i64 @peek() {
          %v = load i64, ptr @hidden
          ret i64 %v
        }
    """)
    machine = ll.Target.from_default_triple().create_target_machine()
    names = jit.object_symbols(machine.emit_object(module))
    defined = {g.name for gs in (module.functions, module.global_variables) for g in gs
               if not g.is_declaration}
    assert defined == {"table", "hidden", "twice", "shared", "peek"}
    assert defined <= names and "elsewhere" not in names
    assert jit.object_symbols(b"not an object file") is None
    assert jit.object_symbols(b"\x7fELF\x01\x01" + bytes(100)) is None  # 32-bit: not read


def test_inlined_callees_copy_their_scope_once_and_compute_the_same():
    """The inliner's copy (jit._inline_copies_scope_once) is applied on this Numba, shares one
    scope among a copy's blocks, and an inlined callee of many blocks, inlined at two call
    sites, computes what plain Python does."""
    import copy

    from numba.core import inline_closurecall as icc

    @numba.njit(inline="always")
    def clamp_sum(x, lo, hi):
        s = 0.0
        for k in range(len(x)):
            v = x[k]
            if v < lo:
                v = lo
            elif v > hi:
                v = hi
            s += v
        return s

    @numba.njit
    def twice(x):
        return clamp_sum(x, -1.0, 1.0) + 10 * clamp_sum(x, 0.0, 0.5)

    import numpy as np

    x = np.array([-3.0, -0.5, 0.25, 0.75, 4.0])
    expected = sum(min(max(v, -1.0), 1.0) for v in x) + 10 * sum(min(max(v, 0.0), 0.5)
                                                                 for v in x)
    assert twice(x) == pytest.approx(expected, abs=1e-12)
    assert jit.INLINE_PATCHED and icc.copy is not copy  # (applied at the first compile)

    # a copy of a function's blocks under the patch: one scope, as the original has
    from numba.core import compiler

    func_ir = compiler.run_frontend(clamp_sum.py_func)
    assert len({id(b.scope) for b in func_ir.blocks.values()}) == 1 and len(func_ir.blocks) > 3
    seen = []
    original = icc.InlineWorker.inline_ir
    try:
        def spy(self, caller_ir, block, i, callee_ir, *args, **kwargs):
            out = original(self, caller_ir, block, i, callee_ir, *args, **kwargs)
            seen.append({id(b.scope) for b in out[0].blocks.values()})
            return out

        icc.InlineWorker.inline_ir = spy

        @numba.njit
        def once(x):
            return clamp_sum(x, 0.0, 1.0)

        assert once(x) == pytest.approx(sum(min(max(v, 0.0), 1.0) for v in x))
    finally:
        icc.InlineWorker.inline_ir = original
    assert seen and all(len(scopes) == 1 for scopes in seen)  # (one per block without it)


def test_subtrace_callees_compile_for_plain_types_not_the_call_sites_constants():
    """jit._calls_without_literals: a jitted function of subtrace's, called from a kernel
    with constants (two call sites, 0 and 1), compiles one specialisation, for int64, and
    computes the same; a function of another module still gets Numba's literal ones."""
    from numba.core import types

    def make(module):
        fn = lambda x, k: x[k] * 2.0 + k  # noqa: E731  (a fresh function object per module)
        fn.__module__ = module
        return numba.njit(fn)

    ours, theirs = make("subtrace._calls_probe"), make("elsewhere._calls_probe")

    @numba.njit
    def caller(x):
        return ours(x, 0) + ours(x, 1) + theirs(x, 0) + theirs(x, 1)

    import numpy as np

    x = np.array([1.5, -2.0])
    assert caller(x) == 2 * ((1.5 * 2.0) + (-2.0 * 2.0 + 1))
    assert jit.INLINE_PATCHED  # (applied at the process's first compile)
    assert [s.args[1] for s in ours.nopython_signatures] == [types.int64]
    assert all(isinstance(s.args[1], types.IntegerLiteral) for s in theirs.nopython_signatures)
    assert len(theirs.nopython_signatures) == 2


def test_kernels_compile_no_c_callable_wrapper():
    """jit.nb.njit compiles without the C-callable wrapper (kept by numba.njit), and the
    function still runs from Python and from other kernels."""
    plain = numba.njit(lambda x: x + 1)
    ours = jit.nb.njit(lambda x: x + 1)
    twice = jit.nb.njit(lambda x: 2 * ours(x))
    assert plain(1) == ours(1) == 2 and twice(1) == 4
    for fn, wrapped in ((plain, True), (ours, False)):
        cres = fn.overloads[fn.signatures[0]]
        assert cres.library.get_pointer_to_function(cres.fndesc.llvm_cpython_wrapper_name)
        assert bool(cres.library.get_pointer_to_function(
            cres.fndesc.llvm_cfunc_wrapper_name)) == wrapped


_ENV_PROBE = """
import json, sys
from subtrace.runtime import jit
if sys.argv[1] == "trimmed":
    jit.trim_loader()
from subtrace.accel.bvh import STACK_SIZE, traversal_stack  # allocates (numba.np.arrayobj)
ids, ts = traversal_stack()
ids[:] = 7
ts[:] = 0.5
st = traversal_stack.stats
from numba.core import environment
print(json.dumps({"hits": sum(st.cache_hits.values()), "sizes": [len(ids), len(ts)],
                  "restored": environment._rebuild_env.__module__ == environment.__name__,
                  "sums": [int(ids.sum()), float(ts.sum())], "size": STACK_SIZE,
                  "arrayobj": "numba.np.arrayobj" in sys.modules}))
"""


def test_a_trimmed_load_rebuilds_numbas_environments_without_importing_them(tmp_path):
    """jit._NumbaEnvironmentsUnimported: a command's process (jit.trim_loader) loads a
    cached kernel that allocates arrays without importing numba.np.arrayobj, whose
    functions it links, and the kernel runs; an untrimmed process imports it, as Numba
    does; after the load Numba's own rebuild is back in place (a compile pickles
    environments that name it)."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(SUBTRACE_CACHE_DIR=str(tmp_path / "cache"), PYTHONDONTWRITEBYTECODE="1")

    def probe(mode):
        proc = subprocess.run([sys.executable, "-c", _ENV_PROBE, mode], capture_output=True,
                              text=True, env=env, timeout=600)
        assert proc.returncode == 0, proc.stderr
        return json.loads(proc.stdout)

    probe("plain")  # compiles and caches it
    for mode, imported in (("trimmed", False), ("plain", True)):
        out = probe(mode)
        assert out["hits"] == 1 and out["arrayobj"] == imported and out["restored"]
        n = out["size"]
        assert out["sizes"] == [n, n] and out["sums"] == [7 * n, 0.5 * n]


_RUNTIME_PROBE = """
import json, sys
from subtrace.runtime import jit
from numba.core.runtime import nrtdynmod
made = []
create = nrtdynmod.create_nrt_module
nrtdynmod.create_nrt_module = lambda ctx: made.append(1) or create(ctx)
jit.trim_loader()
from subtrace.accel.bvh import traversal_stack  # a cached kernel that allocates
ids, ts = traversal_stack()
ids[:] = 3
import numba, numpy as np

@numba.njit(cache=False)
def shared(n):  # compiled here: links the runtime, counts references on its arrays
    a = np.ones(n)
    b = a
    return a, b.sum()

a, total = shared(5)
path = jit.KERNEL_DIR / "runtime" / f"nrt-{numba.__version__}.pkl"
print(json.dumps({"made": len(made), "stored": path.is_file(), "sums": [int(ids.sum()),
                  float(total), float(a.sum())], "size": len(ids), "path": str(path)}))
"""


def test_the_runtime_is_compiled_once_and_loaded_from_the_kernel_folder(tmp_path):
    """jit._runtime_from_the_kernel_folder: a command's process (jit.trim_loader) compiles
    Numba's runtime functions once and stores them beside the kernels; the next process
    loads them (compiles none) and both a cached kernel and a fresh compile that links
    them run; a damaged file is compiled again and replaced."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(SUBTRACE_CACHE_DIR=str(tmp_path / "cache"), PYTHONDONTWRITEBYTECODE="1")

    def probe():
        proc = subprocess.run([sys.executable, "-c", _RUNTIME_PROBE], capture_output=True,
                              text=True, env=env, timeout=600)
        assert proc.returncode == 0, proc.stderr
        out = json.loads(proc.stdout)
        assert out["stored"] and out["sums"] == [3 * out["size"], 5.0, 5.0]
        return out

    first = probe()
    assert first["made"] == 1
    assert probe()["made"] == 0
    Path(first["path"]).write_bytes(b"not a pickle")
    assert probe()["made"] == 1
    assert probe()["made"] == 0  # (rewritten whole)


_EXTENSIONS_PROBE = """
import json, sys
from importlib import metadata
searched = []
entry_points = metadata.entry_points
metadata.entry_points = lambda *a, **k: searched.append(1) or entry_points(*a, **k)
from subtrace.runtime import jit
if sys.argv[1] == "trimmed":
    jit.trim_loader()
from subtrace.accel.bvh import traversal_stack
ids, ts = traversal_stack()
print(json.dumps({"searched": len(searched), "size": len(ids)}))
"""


def test_a_command_does_not_search_the_installed_packages_for_numba_extensions(tmp_path):
    """jit._no_extension_search: a command's process (jit.trim_loader) calls a kernel
    without Numba reading every installed distribution's entry points; an untrimmed
    process reads them, as Numba does."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(SUBTRACE_CACHE_DIR=str(tmp_path / "cache"), PYTHONDONTWRITEBYTECODE="1")
    out = {}
    for mode in ("plain", "trimmed", "plain"):  # (the first compiles the kernel)
        proc = subprocess.run([sys.executable, "-c", _EXTENSIONS_PROBE, mode],
                              capture_output=True, text=True, env=env, timeout=600)
        assert proc.returncode == 0, proc.stderr
        out[mode] = json.loads(proc.stdout)
    assert out["trimmed"]["searched"] == 0 and out["trimmed"]["size"] > 0
    assert out["plain"]["searched"] >= 1


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


_MASKED = """
import json, sys
import numpy as np
from numba import typeof
from subtrace.runtime import jit

jit._arrays_typed_without_numpy_ma()
ro = np.zeros(3)
ro.flags.writeable = False
arrays = [np.zeros(3), np.zeros((2, 3), np.float32), np.zeros((2, 3)).T,
          np.zeros((4, 4))[::2], np.zeros(5, np.int8), np.zeros((2, 2, 2), np.int64), ro,
          np.zeros(0, np.uint8), np.zeros(2, bool), np.zeros((2, 3)), np.zeros((1, 3)),
          np.zeros((3, 1)).T, np.zeros(3, np.float32)]
ours = [str(typeof(a)) for a in arrays]
again = [str(typeof(a)) for a in arrays]  # (from the kinds typed already)
imported = "numpy.ma" in sys.modules
import numpy.ma
numbas = [str(typeof(a)) for a in arrays]
try:
    typeof(np.ma.zeros(3))
    masked = None
except Exception as e:
    masked = type(e).__name__
print(json.dumps({"ours": ours, "again": again, "numbas": numbas, "imported": imported,
                  "masked": masked}))
"""

_WARM_MODULES = """
import json, sys
from subtrace.cli.main import main

codes = [main(["render", "--width", "48", "--height", "32", "--quiet", "-o", sys.argv[1]],
              own_process=True) for _ in range(2)]
print(json.dumps({"codes": codes, "ma": "numpy.ma" in sys.modules}))
"""


def test_arrays_are_typed_as_numba_types_them_without_importing_numpy_ma():
    """jit._arrays_typed_without_numpy_ma: until numpy.ma is imported, arrays of several
    dtypes, dimensions, layouts and writeabilities get the very types Numba's own typing
    gives them afterwards, the first time and again (each kind is typed once: arrays of one
    dtype and dimension that differ in layout or writeability are not confused), and
    nothing has imported numpy.ma; once it is imported, a masked array is still refused as
    Numba refuses it."""
    proc = subprocess.run([sys.executable, "-c", _MASKED], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["ours"] == out["numbas"] == out["again"]
    assert len(set(out["ours"])) >= 9  # (C, F, A, read-only, 1, 2 and 3 dimensions, dtypes)
    assert not out["imported"]
    assert out["masked"] is not None


def test_a_command_imports_no_numpy_ma(tmp_path):
    """A render command (the default scene, with its shadows, ground and anti-aliasing) in
    a process of its own imports no numpy.ma: neither Numba's typing of arrays nor
    np.unique / np.isin on the render's path (each would import it, about 5 ms)."""
    proc = subprocess.run([sys.executable, "-c", _WARM_MODULES, str(tmp_path / "x.exr")],
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["codes"] == [0, 0] and not out["ma"]


def test_compiler_flags_list_the_same_values_from_the_defaults_table():
    """_flag_values_from_defaults: a flags object's values (what Numba hashes and compares
    to find an overload's implementation) are the dict Numba's own properties give, for
    flags with nothing set, some options set, set to their defaults, copied and unset."""
    from numba.core.compiler import Flags

    def by_properties(flags):
        return {k: getattr(flags, k) for k in type(flags).options}

    assert jit._flag_values_from_defaults()
    plain = Flags()
    some = Flags()
    some.nrt = True
    some.error_model = "numpy"
    some.boundscheck = False
    as_default = Flags()
    for name in ("nrt", "error_model", "boundscheck", "fastmath", "no_cpython_wrapper"):
        setattr(as_default, name, Flags.options[name].default)
    copied = Flags(copy_from=some)
    unset = Flags(copy_from=some)
    del unset.nrt
    for flags in (plain, some, as_default, copied, unset):
        assert flags.values() == by_properties(flags)
        assert list(flags.values()) == list(by_properties(flags))  # the same order
    assert plain == as_default and hash(plain) == hash(as_default)
    assert some == copied and hash(some) == hash(copied)
    assert some != plain and unset != some


def test_numbas_overloads_compile_once_for_callers_whose_inherited_flags_agree():
    """jit._overloads_shared_across_flags: ``np.empty`` for the same argument types, typed
    inside two functions whose flags differ only where an overload does not inherit them
    (``nogil``, the Python wrapper), is compiled once; a caller with another
    ``error_model`` (an inherited flag) gets its own; every caller computes the same."""
    import numpy as np
    from numba.core import event

    compiled = []

    class Impls(event.Listener):
        def on_start(self, ev):
            fn = getattr(ev.data["dispatcher"], "py_func", None)
            if getattr(fn, "__qualname__", "").startswith("ol_np_empty."):
                compiled.append((str(ev.data["args"]), ev.data["dispatcher"]))

        def on_end(self, ev):
            pass

    def fill(n):  # a shape and dtype no kernel of subtrace allocates: uncompiled so far
        a = np.empty((n, 2, 1, 1, 1, 1), np.uint16)
        a[:] = 7
        return a.sum()

    plain = numba.njit(fill)
    released = numba.njit(nogil=True)(fill)
    as_numpy = numba.njit(error_model="numpy")(fill)
    listener = Impls()
    event.register("numba:compile", listener)
    try:
        results = [f(3) for f in (plain, released, as_numpy)]
    finally:
        event.unregister("numba:compile", listener)
    assert jit.INLINE_PATCHED  # (applied at the process's first compile)
    assert results == [42, 42, 42]
    shaped = [args for args, _ in compiled if "UniTuple(int64, 6)" in args]
    assert len(shaped) == 2, compiled  # plain and nogil share one; error_model="numpy" not
    assert len({id(d) for args, d in compiled if "UniTuple(int64, 6)" in args}) == 2


# a helper too large for LLVM to inline at three call sites of its own accord
LLVM_INLINE_MODULE = "\n".join([
    "from subtrace.runtime.jit import llvm_inline_njit, nb",
    "",
    "@llvm_inline_njit",
    "def scaled_sum(a, x):",
    "    s = 0.0",
    "    for k in range(len(a)):",
    "        s += a[k] * x",
    *[f"    s = s * 1.000001 + (x * {i}.5 if s > {i} else s / (1.0 + x * {i}))" for i in range(60)],
    "    return s",
    "",
    "@nb.njit(cache=False)",
    "def caller(a, n):",
    "    t = 0.0",
    "    for i in range(n):",
    "        t += scaled_sum(a, 1.5 + i) - scaled_sum(a, 0.5 + i) * scaled_sum(a, 2.5)",
    "    return t",
])


def _probe_sum(a, x):
    s = 0.0
    for v in a:
        s += v * x
    for i in range(60):
        s = s * 1.000001 + (x * (i + 0.5) if s > i else s / (1.0 + x * i))
    return s


def test_llvm_inlined_helpers_leave_no_call_in_their_callers(tmp_path, monkeypatch):
    """jit.llvm_inline_njit: the helper's compiled name is marked (its prefix, then the ABI
    tags), and a kernel that calls it computes the same as Python with no call to it left
    in its optimized code (LLVM inlined it)."""
    import importlib
    import re

    import numpy as np

    import subtrace.trace.prims  # noqa: F401  (its import marks ray_triangle)

    assert jit._mangled_prefix("subtrace.trace.prims", "ray_triangle") == \
        "_ZN8subtrace5trace5prims12ray_triangle"
    assert jit._marked("_ZN8subtrace5trace5prims12ray_triangleB2v2B38xyzE")
    assert not jit._marked("_ZN8subtrace5trace5prims14ray_triangle_xB2v2E")  # another name
    (tmp_path / "llvm_inline_probe.py").write_text(LLVM_INLINE_MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    probe = importlib.import_module("llvm_inline_probe")
    a = np.arange(5.0)
    expected = sum(_probe_sum(a, 1.5 + i) - _probe_sum(a, 0.5 + i) * _probe_sum(a, 2.5)
                   for i in range(7))
    assert probe.caller(a, 7) == pytest.approx(expected, rel=1e-9)
    assert jit._marked(jit._mangled_prefix("llvm_inline_probe", "scaled_sum") + "B2v2E")
    llvm = probe.caller.inspect_llvm(probe.caller.signatures[0])
    calls = re.findall(r"call [^@\n]*@\"?([\w.$]+)", llvm)
    assert calls, "the kernel's code calls nothing at all: the probe checks nothing"
    assert not [c for c in calls if "scaled_sum" in c], calls


_LINKED_ONLY_PROBE = """
import json, sys
from subtrace.runtime import jit
if sys.argv[1] == "trimmed":
    jit.trim_loader()
""" + COMPILE_LISTENER + """
import numba
from subtrace.trace.prims import shear  # a leaf_njit helper: no wrapper, cached

caller = numba.njit(cache=False)(lambda x, y, z: shear(x, y, z))
got = [list(caller(*d)) for d in ((0.3, -2.0, 0.5), (1.0, 0.2, -0.1), (-0.1, 0.2, -3.0))]
want = [list(shear.py_func(*d)) for d in ((0.3, -2.0, 0.5), (1.0, 0.2, -0.1), (-0.1, 0.2, -3.0))]
(sig,) = shear.signatures
lib = shear.overloads[sig].library
name = shear.overloads[sig].fndesc.mangled_name
engine = lib.codegen._engine
index = list((jit.KERNEL_DIR / "subtrace" / "trace").glob("prims.shear-*.nbi"))
print(json.dumps({"got": got, "want": want, "compiled": compiled,
                  "linked_only": bool(getattr(lib, "_subtrace_linked_only", False)),
                  "code": bool(engine.is_symbol_defined(name)), "cached": len(index),
                  "applied": jit.HELPERS_LINKED_ONLY}))
"""


@pytest.mark.parametrize("mode", ["trimmed", "plain"])
def test_helpers_are_kept_as_bitcode_and_linked_from_the_cache(tmp_path, mode):
    """jit._helpers_linked_only: a helper without wrappers is compiled to bitcode, not to
    machine code of its own, and cached so; a caller compiled in this process and one in
    the next process (which loads the helper from the cache, compiling only the caller)
    link it and compute what the helper's Python computes."""
    def probe():
        out = json.loads(run_fresh(_LINKED_ONLY_PROBE, mode, cache=tmp_path / "cache"))
        assert out["applied"] and out["got"] == out["want"]
        assert out["linked_only"] and not out["code"] and out["cached"] == 1
        return [c.rpartition(".")[2] for c in out["compiled"]]

    assert "shear" in probe()  # compiled and stored
    assert probe() == ["<lambda>"]  # only the caller: the helper's bitcode came from the cache


def _numba_listing(val):
    """Numba's own recursion for an instruction's variables (the reference)."""
    from numba.core import ir

    if isinstance(val, ir.Var):
        return [val]
    if isinstance(val, ir.Inst):
        return _numba_listing(val._kws if isinstance(val, ir.Expr) else val.__dict__)
    if isinstance(val, (list, tuple)):
        return [v for item in val for v in _numba_listing(item)]
    if isinstance(val, dict):
        return [v for item in val.values() for v in _numba_listing(item)]
    return []


def test_ir_variables_are_listed_as_numbas_recursion_lists_them():
    """jit._ir_variables_listed_directly: every statement and expression of the IR of real
    kernels (the trace, the secondary rays, the refinement, shading) lists the same
    variables in the same order as Numba's recursion."""
    from numba.core import ir
    from numba.core.compiler import run_frontend

    from subtrace import shade
    from subtrace.subdiv import refine
    from subtrace.trace import kernels, rays

    assert jit._ir_variables_listed_directly()
    count = 0
    for fn in (kernels._trace_task, rays._rays_task, refine._refine_points_kernel,
               shade._shade_task):
        func_ir = run_frontend(fn.py_func)
        for block in func_ir.blocks.values():
            for stmt in block.body:
                values = [stmt] + [v for v in stmt.__dict__.values() if isinstance(v, ir.Expr)]
                for inst in values:
                    assert inst.list_vars() == _numba_listing(inst), inst
                    count += 1
    assert count > 1000


def test_function_types_resolve_as_numba_does_and_failures_still_raise():
    """jit._function_types_resolved_once: a call of one of Numba's function types resolves
    to the signature Numba's own resolution gives, from the memo the second time; a call
    no template accepts raises every time (failures are not kept)."""
    import operator

    import numpy as np
    from numba.core import errors, types
    from numba.core.registry import cpu_target

    assert jit._function_types_resolved_once()
    ctx = cpu_target.typing_context
    ctx.refresh()
    f64, i64 = types.float64, types.int64
    arr = types.Array(f64, 2, "C")
    calls = [(operator.add, (f64, f64)), (operator.add, (i64, f64)), (operator.add, (arr, f64)),
             (operator.lt, (i64, i64)), (operator.truediv, (i64, i64)), (abs, (i64,)),
             (min, (f64, i64)), (np.sqrt, (arr,)),
             (operator.getitem, (arr, types.UniTuple(i64, 2))),
             (np.empty, (i64, types.NumberClass(f64)))]
    for fn, args in calls:
        fnty = ctx.resolve_value_type(fn)
        first = fnty.get_call_type(ctx, args, {})
        again = fnty.get_call_type(ctx, args, {})
        numbas = fnty.get_call_type.__wrapped__(fnty, ctx, args, {})
        assert first is again  # (the memo's)
        assert first == numbas and first.return_type == numbas.return_type, (fn, args)
    fnty = ctx.resolve_value_type(operator.add)
    for _ in range(2):
        with pytest.raises(errors.TypingError):
            fnty.get_call_type(ctx, (types.unicode_type, i64), {})


_TRIM_PROBE = """
import json
import llvmlite.binding.ffi as ffi
import numba.core.base  # noqa: F401  (registers its hooks on LLVM's lock)
from subtrace.runtime import jit

def numbas():
    return sum(getattr(a, "__module__", "") == "numba.core.base" for a, _ in ffi.lib._lock._cblist)

before = numbas()
jit.trim_compiler()
print(json.dumps([before, numbas()]))
"""


def test_a_compiling_process_drops_numbas_hooks_on_llvms_lock():
    """jit.trim_compiler (the render's helper process): the callbacks Numba hangs on
    llvmlite's lock, which only time compile events, are removed."""
    proc = subprocess.run([sys.executable, "-c", _TRIM_PROBE], capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    before, after = json.loads(proc.stdout)
    assert before >= 1 and after == 0


_TARGET_PROBE = """
import json
import llvmlite.binding as ll
from numba.core.registry import cpu_target
from subtrace.runtime import jit

codegen = cpu_target.target_context.codegen()
plain = codegen.magic_tuple()
jit._target_described_once()
asked = []
host = ll.get_host_cpu_name
ll.get_host_cpu_name = lambda: asked.append(1) or host()
first, second = codegen.magic_tuple(), codegen.magic_tuple()
print(json.dumps([repr(plain), repr(first), repr(second), len(asked)]))
"""


def test_the_target_is_described_once_and_as_numba_describes_it():
    """jit._target_described_once: the code generator's target description (in every
    kernel's cache key) is the one Numba gives, asked of LLVM at most once however often a
    load needs it."""
    proc = subprocess.run([sys.executable, "-c", _TARGET_PROBE], capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    plain, first, second, asked = json.loads(proc.stdout)
    assert plain == first == second and asked <= 1
