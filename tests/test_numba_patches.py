"""The patches of Numba's internals (subtrace.runtime.numba_patches): the switch turns them
all off and the images stay the same bit for bit; a patch whose internals are missing is
skipped with one debug note; and each patch does what it says on this Numba (the tests
after the switch's, skipped where the patches are off)."""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np
import pytest

from shared_data import COMPILE_LISTENER, run_fresh
from subtrace.runtime import jit, numba_patches

patched = pytest.mark.skipif(not numba_patches.ENABLED, reason="the patches are off here "
                             f"({numba_patches.SWITCH}, or a Numba they were not checked on)")


def _env(**extra) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR",
                                                            numba_patches.SWITCH)}
    env.update(PYTHONDONTWRITEBYTECODE="1", **extra)
    return env


def test_the_switch_and_the_checked_versions():
    """SUBTRACE_NUMBA_PATCHES=0 turns the patches off and =1 on, on any Numba; unset, they
    apply on a checked minor version only (a later patch release too, not the next minor)."""
    major, minor = next(iter(numba_patches.CHECKED_ON))
    version = f"{major}.{minor}.0"
    assert numba_patches.wanted(version, {})
    assert numba_patches.wanted(f"{major}.{minor}.9rc1", {"SUBTRACE_NUMBA_PATCHES": ""})
    assert not numba_patches.wanted(version, {"SUBTRACE_NUMBA_PATCHES": "0"})
    assert not numba_patches.wanted(f"{major}.{minor + 1}.0", {})
    assert numba_patches.wanted(f"{major}.{minor + 1}.0", {"SUBTRACE_NUMBA_PATCHES": "1"})
    assert not numba_patches.wanted("not a version", {})
    for stage in numba_patches.STAGES.values():
        assert set(stage) <= set(numba_patches._PATCHES)
    assert set(numba_patches._PATCHES) == {n for s in numba_patches.STAGES.values() for n in s}


def test_a_patch_that_fails_is_skipped_with_one_debug_note(monkeypatch, caplog):
    """A patch that raises, or finds Numba's internals other than it needs, is recorded as
    skipped with one debug-level note each, once per process; nothing raises and the other
    patches of its stage still apply."""
    def raises():
        raise AttributeError("module 'numba.core.caching' has no attribute 'CacheImpl'")

    ran = []
    monkeypatch.setitem(numba_patches._PATCHES, "probe_raises", raises)
    monkeypatch.setitem(numba_patches._PATCHES, "probe_differs", lambda: False)
    monkeypatch.setitem(numba_patches._PATCHES, "probe_applies", lambda: ran.append(1) or True)
    monkeypatch.setitem(numba_patches.STAGES, "probe",
                        ("probe_raises", "probe_differs", "probe_applies"))
    monkeypatch.setattr(numba_patches, "ENABLED", True)
    for name in ("probe_raises", "probe_differs", "probe_applies"):
        monkeypatch.delitem(numba_patches.APPLIED, name, raising=False)
    with caplog.at_level(logging.DEBUG, logger="subtrace.runtime.numba_patches"):
        numba_patches.apply("probe")
        applied = numba_patches.apply("probe")  # (again: nothing more)
    assert [applied[n] for n in ("probe_raises", "probe_differs", "probe_applies")] == \
        [False, False, True]
    assert ran == [1]
    notes = [r for r in caplog.records if r.name == "subtrace.runtime.numba_patches"]
    assert len(notes) == 2 and all(r.levelno == logging.DEBUG for r in notes)
    assert "probe_raises" in notes[0].getMessage() and "CacheImpl" in notes[0].getMessage()
    assert "probe_differs" in notes[1].getMessage()
    for name in ("probe_raises", "probe_differs", "probe_applies"):
        del numba_patches.APPLIED[name]


_STATE = """
import json, logging, sys
logging.basicConfig(level=logging.DEBUG, stream=sys.stderr)
from numba.core import caching, cpu
if sys.argv[1] == "no-locator-base":  # a Numba without what the cache locator builds on
    del caching._SourceFileBackedLocatorMixin
locators = list(caching.CacheImpl._locator_classes)
post_lowering = cpu.CPUContext.post_lowering
from subtrace.runtime import jit, numba_patches
jit.trim_loader()
from subtrace.geometry.prims import shear  # a leaf_njit helper, cached
got = list(shear(0.3, -2.0, 0.5))
import numba
print(json.dumps({"applied": numba_patches.APPLIED, "enabled": numba_patches.ENABLED,
                  "options": numba_patches.NJIT_OPTIONS, "folder": str(jit.KERNEL_DIR),
                  "locators_kept": list(caching.CacheImpl._locator_classes) == locators,
                  "lowering_kept": cpu.CPUContext.post_lowering is post_lowering,
                  "config": numba.config.CACHE_DIR, "got": got,
                  "want": list(shear.py_func(0.3, -2.0, 0.5)),
                  "cached": [str(p) for p in Path(jit.KERNEL_DIR).rglob("prims.shear-*.nbi")]}))
""".replace("import json,", "from pathlib import Path\nimport json,")


def _state(tmp_path, mode, **env):
    proc = subprocess.run([sys.executable, "-c", _STATE, mode], capture_output=True, text=True,
                          timeout=600, env=_env(SUBTRACE_CACHE_DIR=str(tmp_path), **env))
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1]), proc.stderr


def test_off_changes_nothing_of_numba_and_keeps_the_kernels_in_their_own_folder(tmp_path):
    """With SUBTRACE_NUMBA_PATCHES=0 no patch applies, at any stage: Numba's cache locators
    and lowering are its own, subtrace adds no compile option, and the kernels (Numba's
    own locator) are still cached inside the key's folder, which is not the patched
    processes' folder; a helper computes what its Python does."""
    off, notes = _state(tmp_path, "plain", SUBTRACE_NUMBA_PATCHES="0")
    assert not off["enabled"] and off["applied"] == {} and off["options"] == {}
    assert off["locators_kept"] and off["lowering_kept"] and off["got"] == off["want"]
    assert off["config"] == off["folder"] and off["cached"]
    assert all(Path(p).is_relative_to(off["folder"]) for p in off["cached"])
    assert "left unpatched" in notes
    on, _ = _state(tmp_path, "plain", SUBTRACE_NUMBA_PATCHES="1")
    assert on["folder"] != off["folder"] and on["got"] == on["want"]
    assert on["enabled"] and all(on["applied"][n] for n in numba_patches.STAGES["import"])
    assert not on["locators_kept"]


def test_a_missing_numba_internal_skips_its_patch_and_the_rest_apply(tmp_path):
    """A Numba without a class the cache locator builds on: importing subtrace raises
    nothing, the locator is skipped with one debug note, the other patches apply, and the
    kernels are cached in the key's folder by Numba's own locator."""
    out, notes = _state(tmp_path, "no-locator-base", SUBTRACE_NUMBA_PATCHES="1")
    assert out["enabled"] and out["applied"]["content_locator"] is False
    assert all(ok for name, ok in out["applied"].items() if name != "content_locator")
    assert notes.count("Numba patch content_locator skipped") == 1
    assert "_SourceFileBackedLocatorMixin" in notes
    assert out["config"] == out["folder"] and out["cached"] and out["got"] == out["want"]


def _render(tmp_path, switch: str) -> tuple[dict, dict]:
    """The default scene (shadows, ground, anti-aliasing), small, rendered by the command in
    a process of its own with the patches on ("1") or off ("0"): (channels, header)."""
    from subtrace.io.exr import read_exr

    out = tmp_path / f"patches-{switch}.exr"
    proc = subprocess.run([sys.executable, "-m", "subtrace.cli", "render", "--width", "64",
                           "--height", "48", "--quiet", "-o", str(out)], capture_output=True,
                          text=True, timeout=900, env=_env(SUBTRACE_NUMBA_PATCHES=switch))
    assert proc.returncode == 0, proc.stderr
    return read_exr(out)


def test_the_images_are_the_same_with_the_patches_on_and_off(tmp_path):
    """The default scene rendered by two processes, one with every patch and one with none,
    each on its own kernel folder (the switch is in the cache's key): every channel the
    same bit for bit."""
    on, _ = _render(tmp_path, "1")
    off, _ = _render(tmp_path, "0")
    assert list(on) == list(off) and len(on) >= 5
    for name in on:
        a, b = np.ascontiguousarray(on[name]), np.ascontiguousarray(off[name])
        assert a.dtype == b.dtype and a.shape == b.shape, name
        assert np.array_equal(a.view(np.uint8), b.view(np.uint8)), name


@patched
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
    names = numba_patches.object_symbols(machine.emit_object(module))
    defined = {g.name for gs in (module.functions, module.global_variables) for g in gs
               if not g.is_declaration}
    assert defined == {"table", "hidden", "twice", "shared", "peek"}
    assert defined <= names and "elsewhere" not in names
    assert numba_patches.object_symbols(b"not an object file") is None
    assert numba_patches.object_symbols(b"\x7fELF\x01\x01" + bytes(100)) is None  # 32-bit: not read


@patched
def test_inlined_callees_copy_their_scope_once_and_compute_the_same():
    """The inliner's copy (numba_patches._inline_copies_scope_once) is applied on this Numba, shares one
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
    assert numba_patches.APPLIED["inline_copies_scope_once"] and icc.copy is not copy  # (applied at the first compile)

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


@patched
def test_subtrace_callees_compile_for_plain_types_not_the_call_sites_constants():
    """numba_patches._calls_without_literals: a jitted function of subtrace's, called from a kernel
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
    assert numba_patches.APPLIED["inline_copies_scope_once"]  # (applied at the process's first compile)
    assert [s.args[1] for s in ours.nopython_signatures] == [types.int64]
    assert all(isinstance(s.args[1], types.IntegerLiteral) for s in theirs.nopython_signatures)
    assert len(theirs.nopython_signatures) == 2


@patched
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
from subtrace.runtime import jit, numba_patches
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


@patched
def test_a_trimmed_load_rebuilds_numbas_environments_without_importing_them(tmp_path):
    """numba_patches._NumbaEnvironmentsUnimported: a command's process (jit.trim_loader) loads a
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
from subtrace.runtime import jit, numba_patches
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


@patched
def test_the_runtime_is_compiled_once_and_loaded_from_the_kernel_folder(tmp_path):
    """numba_patches._runtime_from_the_kernel_folder: a command's process (jit.trim_loader) compiles
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
from subtrace.runtime import jit, numba_patches
if sys.argv[1] == "trimmed":
    jit.trim_loader()
from subtrace.accel.bvh import traversal_stack
ids, ts = traversal_stack()
print(json.dumps({"searched": len(searched), "size": len(ids)}))
"""


@patched
def test_a_command_does_not_search_the_installed_packages_for_numba_extensions(tmp_path):
    """numba_patches._no_extension_search: a command's process (jit.trim_loader) calls a kernel
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


_MASKED = """
import json, sys
import numpy as np
from numba import typeof
from subtrace.runtime import jit, numba_patches

numba_patches._arrays_typed_without_numpy_ma()
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


@patched
def test_arrays_are_typed_as_numba_types_them_without_importing_numpy_ma():
    """numba_patches._arrays_typed_without_numpy_ma: until numpy.ma is imported, arrays of several
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


@patched
def test_a_command_imports_no_numpy_ma(tmp_path):
    """A render command (the default scene, with its shadows, ground and anti-aliasing) in
    a process of its own imports no numpy.ma: neither Numba's typing of arrays nor
    np.unique / np.isin on the render's path (each would import it, about 5 ms)."""
    proc = subprocess.run([sys.executable, "-c", _WARM_MODULES, str(tmp_path / "x.exr")],
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["codes"] == [0, 0] and not out["ma"]


@patched
def test_compiler_flags_list_the_same_values_from_the_defaults_table():
    """_flag_values_from_defaults: a flags object's values (what Numba hashes and compares
    to find an overload's implementation) are the dict Numba's own properties give, for
    flags with nothing set, some options set, set to their defaults, copied and unset."""
    from numba.core.compiler import Flags

    def by_properties(flags):
        return {k: getattr(flags, k) for k in type(flags).options}

    assert numba_patches._flag_values_from_defaults()
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


@patched
def test_numbas_overloads_compile_once_for_callers_whose_inherited_flags_agree():
    """numba_patches._overloads_shared_across_flags: ``np.empty`` for the same argument types, typed
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
    assert numba_patches.APPLIED["inline_copies_scope_once"]  # (applied at the process's first compile)
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


@patched
def test_llvm_inlined_helpers_leave_no_call_in_their_callers(tmp_path, monkeypatch):
    """jit.llvm_inline_njit: the helper's compiled name is marked (its prefix, then the ABI
    tags), and a kernel that calls it computes the same as Python with no call to it left
    in its optimized code (LLVM inlined it)."""
    import importlib
    import re

    import numpy as np

    import subtrace.geometry.prims  # noqa: F401  (its import marks ray_triangle)

    assert numba_patches._mangled_prefix("subtrace.geometry.prims", "ray_triangle") == \
        "_ZN8subtrace8geometry5prims12ray_triangle"
    assert numba_patches._marked("_ZN8subtrace8geometry5prims12ray_triangleB2v2B38xyzE")
    assert not numba_patches._marked("_ZN8subtrace8geometry5prims14ray_triangle_xB2v2E")  # another name
    (tmp_path / "llvm_inline_probe.py").write_text(LLVM_INLINE_MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    probe = importlib.import_module("llvm_inline_probe")
    a = np.arange(5.0)
    expected = sum(_probe_sum(a, 1.5 + i) - _probe_sum(a, 0.5 + i) * _probe_sum(a, 2.5)
                   for i in range(7))
    assert probe.caller(a, 7) == pytest.approx(expected, rel=1e-9)
    assert numba_patches._marked(numba_patches._mangled_prefix("llvm_inline_probe", "scaled_sum") + "B2v2E")
    llvm = probe.caller.inspect_llvm(probe.caller.signatures[0])
    calls = re.findall(r"call [^@\n]*@\"?([\w.$]+)", llvm)
    assert calls, "the kernel's code calls nothing at all: the probe checks nothing"
    assert not [c for c in calls if "scaled_sum" in c], calls


_LINKED_ONLY_PROBE = """
import json, sys
from subtrace.runtime import jit, numba_patches
if sys.argv[1] == "trimmed":
    jit.trim_loader()
""" + COMPILE_LISTENER + """
import numba
from subtrace.geometry.prims import shear  # a leaf_njit helper: no wrapper, cached

caller = numba.njit(cache=False)(lambda x, y, z: shear(x, y, z))
got = [list(caller(*d)) for d in ((0.3, -2.0, 0.5), (1.0, 0.2, -0.1), (-0.1, 0.2, -3.0))]
want = [list(shear.py_func(*d)) for d in ((0.3, -2.0, 0.5), (1.0, 0.2, -0.1), (-0.1, 0.2, -3.0))]
(sig,) = shear.signatures
lib = shear.overloads[sig].library
name = shear.overloads[sig].fndesc.mangled_name
engine = lib.codegen._engine
index = list((jit.KERNEL_DIR / "subtrace" / "geometry").glob("prims.shear-*.nbi"))
print(json.dumps({"got": got, "want": want, "compiled": compiled,
                  "linked_only": bool(getattr(lib, "_subtrace_linked_only", False)),
                  "code": bool(engine.is_symbol_defined(name)), "cached": len(index),
                  "applied": numba_patches.APPLIED["helpers_linked_only"]}))
"""


@patched
@pytest.mark.parametrize("mode", ["trimmed", "plain"])
def test_helpers_are_kept_as_bitcode_and_linked_from_the_cache(tmp_path, mode):
    """numba_patches._helpers_linked_only: a helper without wrappers is compiled to bitcode, not to
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


@patched
def test_ir_variables_are_listed_as_numbas_recursion_lists_them():
    """numba_patches._ir_variables_listed_directly: every statement and expression of the IR of real
    kernels (the trace, the secondary rays, the refinement, shading) lists the same
    variables in the same order as Numba's recursion."""
    from numba.core import ir
    from numba.core.compiler import run_frontend

    from subtrace import shade
    from subtrace.subdiv import refine
    from subtrace.trace import kernels, rays

    assert numba_patches._ir_variables_listed_directly()
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


@patched
def test_function_types_resolve_as_numba_does_and_failures_still_raise():
    """numba_patches._function_types_resolved_once: a call of one of Numba's function types resolves
    to the signature Numba's own resolution gives, from the memo the second time; a call
    no template accepts raises every time (failures are not kept)."""
    import operator

    import numpy as np
    from numba.core import errors, types
    from numba.core.registry import cpu_target

    assert numba_patches._function_types_resolved_once()
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
from subtrace.runtime import jit, numba_patches

def numbas():
    return sum(getattr(a, "__module__", "") == "numba.core.base" for a, _ in ffi.lib._lock._cblist)

before = numbas()
jit.trim_compiler()
print(json.dumps([before, numbas()]))
"""


@patched
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
from subtrace.runtime import jit, numba_patches

codegen = cpu_target.target_context.codegen()
plain = codegen.magic_tuple()
numba_patches._target_described_once()
asked = []
host = ll.get_host_cpu_name
ll.get_host_cpu_name = lambda: asked.append(1) or host()
first, second = codegen.magic_tuple(), codegen.magic_tuple()
print(json.dumps([repr(plain), repr(first), repr(second), len(asked)]))
"""


@patched
def test_the_target_is_described_once_and_as_numba_describes_it():
    """numba_patches._target_described_once: the code generator's target description (in every
    kernel's cache key) is the one Numba gives, asked of LLVM at most once however often a
    load needs it."""
    proc = subprocess.run([sys.executable, "-c", _TARGET_PROBE], capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    plain, first, second, asked = json.loads(proc.stdout)
    assert plain == first == second and asked <= 1
