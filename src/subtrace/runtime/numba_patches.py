"""Every change subtrace makes to Numba's internals (``numba.core``, llvmlite), in one place.

Numba compiles subtrace's kernels on the first run (a cold render of the default scene:
about two minutes on 2 cores) and loads them from the kernel cache afterwards. The patches
here make both faster: the compile does less work (Numba's IR inliner copies a scope once,
calls are typed once per argument types, helpers are kept as LLVM bitcode, ...) and a
command's own process loads cached kernels without Numba's full set-up. None of them
changes what a kernel computes: the images are the same bit for bit with and without them
(``tests/test_numba_patches.py`` renders a scene both ways). Each patch's docstring says
what it changes and what it saved when it was written.

Checked on: Numba 0.68.1 (llvmlite 0.50.0, NumPy 2.4), Python 3.11 (:data:`CHECKED_ON`). The patches
reach into Numba's private modules, which change between releases, so they are applied
only on a Numba of a checked minor version; on any other Numba subtrace runs unpatched: the
same images, a slower first run (and command start). ``SUBTRACE_NUMBA_PATCHES=0`` turns
them all off on any Numba, ``=1`` applies them on an unchecked one too (:func:`wanted`).
Even then each patch first checks that the internals it needs are there and look as
expected; where one is missing, or applying it raises, that patch is skipped with one
debug-level note on the ``subtrace.runtime.numba_patches`` logger (never an exception),
and the others still apply. :data:`APPLIED` records what each did in this process.

Whether the patches are on is part of the kernel cache's key (``runtime.jit``): a cache
written by patched processes (helpers kept as bitcode alone) is never read by an unpatched
one, and the reverse.

They are applied in stages, all through :func:`apply` (:data:`STAGES`):

* ``"import"``, when ``runtime.jit`` is imported (:func:`install`): the cache locator that
  stamps kernels with their module's bytes, the helpers kept as bitcode, the helpers and
  kernels compiled without the wrappers nothing calls;
* ``"compile"``, at the process's first compile (a Numba compile event), so a command whose
  kernels are all cached never imports the compiler's modules for them;
* ``"loader"``, for a command in a process of its own (``jit.trim_loader``);
* ``"compiler"``, for a process that compiles kernels (the render's helper processes,
  ``jit.trim_compiler``).
"""

from __future__ import annotations

import hashlib
import logging
import os
import sys
import threading
from collections.abc import Callable, Mapping
from pathlib import Path

LOG = logging.getLogger(__name__)

# The Numba releases (major, minor) the patches were checked on: tests/test_numba_patches.py
# and the test suite with them on and off, and the images bit for bit both ways
CHECKED_ON = {(0, 68): "0.68.1"}
SWITCH = "SUBTRACE_NUMBA_PATCHES"  # "0": all off; "1": on, also on an unchecked Numba

STAGES: dict[str, tuple[str, ...]] = {
    "import": ("content_locator", "helpers_linked_only", "wrapperless_helpers",
               "no_cfunc_wrapper"),
    "compile": ("inline_copies_scope_once", "calls_without_literals",
                "flag_values_from_defaults", "overloads_shared_across_flags",
                "inline_marked_functions", "ir_variables_listed_directly",
                "function_types_resolved_once"),
    "loader": ("drop_llvm_lock_events", "target_described_once",
               "runtime_from_the_kernel_folder", "lazy_bitcode",
               "arrays_typed_without_numpy_ma", "no_extension_search", "cached_kernel_loader"),
    "compiler": ("drop_llvm_lock_events",),
}
APPLIED: dict[str, bool] = {}  # patch name -> applied (True) or skipped (False), this process
ENABLED = False  # whether the patches apply in this process (install)
_PATCHES: dict[str, Callable[[], bool]] = {}
_SETTINGS: dict = {}  # install's: the kernel folder, the sources' digests, the package root
# The cached-kernel loader's ledger (_cached_kernel_loader), which the read-ahead of
# subtrace.startup.preload reads and fills: the kernels this process's dispatchers took from
# the cache, in order, as (module, qualname, signature), appended under Numba's compiler
# lock; the compile results read ahead and not yet taken, (python function, signature) ->
# result, each handed over once; and, where the loader is patched, "read" (its reader,
# ``read(cache, sig, target_context)``: a compile result or None), "lock" (Numba's compiler
# lock, which dispatchers load under) and "folder" (where the read-ahead's manifests go)
LOADED: list = []
READ_AHEAD: dict = {}
LOADER: dict = {}


def wanted(numba_version: str, environ: Mapping[str, str] = os.environ) -> bool:
    """Whether the patches should apply under this Numba: ``SUBTRACE_NUMBA_PATCHES=0`` off,
    ``=1`` on; unset (or anything else), on where Numba's minor version is in
    :data:`CHECKED_ON`."""
    switch = environ.get(SWITCH, "").strip()
    if switch in ("0", "1"):
        return switch == "1"
    try:
        major, minor = (int(p) for p in numba_version.split(".")[:2])
    except ValueError:
        return False
    return (major, minor) in CHECKED_ON


def install(enabled: bool, kernel_dir: Path, digests: Mapping[str, str], root: Path) -> None:
    """Called once by ``runtime.jit`` at its import (every stage is applied through it:
    :func:`apply` does nothing before): remember where the kernels are kept,
    apply the ``"import"`` stage and listen for the first compile (the ``"compile"``
    stage), when ``enabled`` (:func:`wanted`); else one debug note. Without the content
    locator (off or skipped), Numba's own cache folder is set to ``kernel_dir``."""
    global ENABLED
    ENABLED = bool(enabled)
    _SETTINGS.update(kernel_dir=Path(kernel_dir), digests=dict(digests), root=Path(root))
    if ENABLED:
        apply("import")
    else:
        LOG.debug("Numba's internals left unpatched (%s=%r, Numba %s; checked on %s)",
                  SWITCH, os.environ.get(SWITCH), _numba_version(),
                  ", ".join(CHECKED_ON.values()))
    if not APPLIED.get("content_locator"):
        # Numba's own locator (stamps of the files' times) in the key's folder: the setting
        # of NUMBA_CACHE_DIR, for this process only (child processes find their own folder).
        # The environment is read first (a Numba imported before runtime.jit set its
        # variables reads them again at its next compile, and would undo the setting)
        import numba

        numba.config.reload_config()
        numba.config.CACHE_DIR = str(kernel_dir)
    if not ENABLED:
        return
    try:
        from numba.core import event
        event.register("numba:compile", type("FirstCompile", (_FirstCompile, event.Listener),
                                              {})())
    except Exception as exc:  # noqa: BLE001 - no compile events: the stage never applies
        LOG.debug("Numba patches: no compile event to listen to (%s: %s)",
                  type(exc).__name__, exc)


def apply(stage: str) -> dict[str, bool]:
    """Apply the patches of ``stage`` (:data:`STAGES`) not applied or skipped yet in this
    process; nothing where the patches are off. Returns :data:`APPLIED`."""
    if not ENABLED:
        return APPLIED
    for name in STAGES[stage]:
        if name not in APPLIED:
            APPLIED[name] = _apply_one(name)
    return APPLIED


def _apply_one(name: str) -> bool:
    """Run one patch; False, with one debug note, where it is skipped (it found this Numba's
    internals other than it needs, or raised)."""
    try:
        applied = _PATCHES[name]() is not False
    except Exception as exc:  # noqa: BLE001 - any failure of a patch: skip it, not the command
        LOG.debug("Numba patch %s skipped: %s: %s", name, type(exc).__name__, exc)
        return False
    if not applied:
        LOG.debug("Numba patch %s skipped: Numba %s's internals differ from what it needs",
                  name, _numba_version())
    return applied


def _patch(fn):
    """Register ``fn`` as the patch named after it (without the leading underscore). A patch
    returns False, changing nothing, where this Numba's internals are not what it needs
    (an ImportError or AttributeError it raises counts the same), else True."""
    _PATCHES[fn.__name__.lstrip("_")] = fn
    return fn


def _numba_version() -> str:
    numba = sys.modules.get("numba")
    return getattr(numba, "__version__", "?")


class _FirstCompile:
    """(With Numba's ``event.Listener``, :func:`install`.) Numba's "numba:compile" event (a
    cache miss, before compiling): the ``"compile"`` stage at the process's first compile,
    so a command whose kernels are all cached does not import Numba's inliner for it; and
    the count of compiles under way on each thread (:func:`compiling_here`)."""

    def on_start(self, event):
        _COMPILES.depth = getattr(_COMPILES, "depth", 0) + 1
        apply("compile")

    def on_end(self, event):
        _COMPILES.depth -= 1


_COMPILES = threading.local()  # depth: the compiles under way on this thread


def compiling_here() -> bool:
    """Whether this thread is compiling a function (a kernel read from the cache now is
    one that compile links in, not one Python called)."""
    return getattr(_COMPILES, "depth", 0) > 0


# --------------------------------------------------------------------------------------
# "import": the cache locator, the helpers and kernels without unused wrappers
# --------------------------------------------------------------------------------------

@_patch
def _content_locator() -> bool:
    """Numba's cache locator for subtrace's own files: a kernel of the package is cached in
    ``<kernel folder>/subtrace/<module's folder>``, its index stamped with the sha256 of
    the module's bytes, not the file's modification time (Numba's own locators then apply
    to every other file). Without it (the patches off) ``runtime.jit`` points Numba's own
    locator into the kernel folder, whose key still follows the sources' bytes."""
    from numba.core import caching

    base = (caching._SourceFileBackedLocatorMixin, caching._CacheLocator)
    classes = caching.CacheImpl._locator_classes
    if not isinstance(classes, list):
        return False
    kernel_dir, digests, root = (_SETTINGS[k] for k in ("kernel_dir", "digests", "root"))
    made = set()  # cache folders known to exist

    class _ContentLocator(*base):
        """Caches a kernel of subtrace's package in ``KERNEL_DIR/subtrace/<module's folder>``,
        its index stamped with the sha256 of the module's bytes (``jit.DIGESTS``)."""

        def __init__(self, py_func, py_file, rel):
            self._py_file = py_file
            self._lineno = py_func.__code__.co_firstlineno
            self._stamp = digests.get(rel) or hashlib.sha256(
                Path(py_file).read_bytes()).hexdigest()
            self._cache_path = str(kernel_dir / "subtrace" / Path(rel).parent)

        def get_cache_path(self):
            return self._cache_path

        def ensure_cache_path(self):
            # the folder once per process, without Numba's write test per kernel (a
            # temporary file for each of ~200 kernels at every start): jit's _check_folder
            # tested the cache folder these lie in
            if self._cache_path not in made:
                os.makedirs(self._cache_path, exist_ok=True)
                made.add(self._cache_path)

        def get_source_stamp(self):
            return self._stamp

        @classmethod
        def from_function(cls, py_func, py_file):
            try:
                rel = Path(py_file).resolve().relative_to(root).as_posix()
            except (OSError, ValueError):
                return None  # not subtrace's: Numba's own locators
            self = cls(py_func, py_file, rel)
            try:
                self.ensure_cache_path()
            except OSError:
                return None  # an unwritable folder: Numba's own locators
            return self

    caching.CacheImpl._locator_classes = [_ContentLocator, *classes]
    return True


# Numba's options for a kernel or helper that subtrace adds (no_cfunc_wrapper_option)
NJIT_OPTIONS: dict = {}


@_patch
def _no_cfunc_wrapper() -> bool:
    """Compile subtrace's kernels without the C-callable wrapper (``no_cfunc_wrapper``, one
    of Numba's undocumented compile options, in :data:`NJIT_OPTIONS` for ``jit.nb.njit``):
    that wrapper serves only functions passed as first-class function values, which
    subtrace never does, and generating and compiling it for every kernel and helper was
    about 5 % of a cold render's compile (alternated cold renders of the default scene,
    medians of 3: 16.8 -> 15.9 s)."""
    from numba.core import cpu

    if not hasattr(cpu.CPUTargetOptions, "no_cfunc_wrapper"):
        return False
    NJIT_OPTIONS["no_cfunc_wrapper"] = True
    return True


_HELPER_CLASS = None  # the wrapperless helpers' dispatcher class (wrapperless_helpers)


@_patch
def _wrapperless_helpers() -> bool:
    """Compile the helpers of ``jit.leaf_njit`` and ``jit.callee_njit`` without the wrapper
    that lets Python call compiled code, nor the C-callable one (:func:`helper`): their
    generation and compile were about a tenth of a cold render's compile, for 70-odd
    helpers that Python never calls. A call from Python goes through a small jitted function
    that calls the helper, compiled on the first such call of each process and not cached."""
    global _HELPER_CLASS
    import numba
    from numba.core import cpu
    from numba.core.registry import CPUDispatcher

    if not all(hasattr(cpu.CPUTargetOptions, name)
               for name in ("no_cfunc_wrapper", "no_cpython_wrapper")):
        return False

    class _Helper(CPUDispatcher):
        """A helper compiled without the wrapper that Python calls through, called from
        Python through a jitted function that calls it (:meth:`__call__`)."""

        _from_python = None

        def __call__(self, *args):
            call = self._from_python
            if call is None:
                helper = self
                call = self._from_python = numba.njit(**NJIT_OPTIONS)(lambda *a: helper(*a))
            return call(*args)

    _make_helper(_Helper, lambda: None, {})  # (a dispatcher built as helper builds them)
    _HELPER_CLASS = _Helper
    return True


def _make_helper(cls, fn, options: dict):
    dispatcher = cls(py_func=fn, locals={}, targetoptions={
        "nopython": True, "boundscheck": None, **options, "no_cfunc_wrapper": True,
        "no_cpython_wrapper": True})
    dispatcher.enable_caching()
    return dispatcher


def helper(fn, options: dict):
    """A cached dispatcher of ``fn`` compiled with ``options`` and neither the Python nor
    the C-callable wrapper (:func:`_wrapperless_helpers`); None where that patch is not
    applied (``jit`` then compiles a plain ``numba.njit`` function), or where building
    one fails (then the patch is dropped, with one debug note, for the helpers after it)."""
    global _HELPER_CLASS
    if _HELPER_CLASS is None:
        return None
    try:
        return _make_helper(_HELPER_CLASS, fn, options)
    except Exception as exc:  # noqa: BLE001 - a Numba whose dispatchers differ: plain njit
        LOG.debug("Numba patch wrapperless_helpers dropped: %s: %s", type(exc).__name__, exc)
        _HELPER_CLASS = None
        APPLIED["wrapperless_helpers"] = False
        return None

# --------------------------------------------------------------------------------------
# "compile": the first compile of the process
# --------------------------------------------------------------------------------------

@_patch
def _inline_copies_scope_once() -> bool:
    """Make Numba's IR inliner copy an inlined function's scope once per copy of its body,
    not once per block; True when applied.

    To inline a call (``inline="always"``: :func:`inline_njit`), Numba deep-copies the
    callee's IR block by block, twice. A variable's copy copies the scope it belongs to,
    and the scope holds every variable of the function, so each block's copy copied the
    whole function again: the copies grew as blocks times variables, and took about a fifth
    of a cold render's compile (a render of the default scene on an empty cache: 29.5 -> 24
    s, 47 -> 37 s of CPU). Here the blocks of one copy share one memo, so the scope and the
    variables are copied once and shared by the copied blocks, as the originals share them;
    the inliner then renames that one scope's variables. The compiled code is the same
    (images bit for bit, the oracle and render tests). A Numba whose inliner is organised
    differently is left alone."""
    try:
        import copy
        import types

        from numba.core import inline_closurecall as icc
        from numba.core import ir
    except ImportError:  # pragma: no cover - another Numba
        return False
    worker = getattr(icc, "InlineWorker", None)
    if getattr(icc, "copy", None) is not copy or not hasattr(worker, "inline_ir"):
        return False  # pragma: no cover - another Numba
    local = threading.local()

    def deepcopy(x, memo=None):
        memos = getattr(local, "memos", None)
        if memo is None and memos is not None and isinstance(x, ir.Block):
            memo = memos.setdefault(id(x.scope), {})  # one memo per scope copied
        return copy.deepcopy(x, memo)

    shim = types.SimpleNamespace(**{k: getattr(copy, k) for k in copy.__all__})
    shim.deepcopy = deepcopy
    inline_ir = worker.inline_ir

    def inline_ir_sharing(self, *args, **kwargs):
        outer = getattr(local, "memos", None)
        local.memos = {}  # the scopes of this call's copies (alive until it returns)
        try:
            return inline_ir(self, *args, **kwargs)
        finally:
            local.memos = outer

    icc.copy = shim
    worker.inline_ir = inline_ir_sharing
    return True


@_patch
def _calls_without_literals() -> bool:
    """Make a call from one of subtrace's kernels to another compile the callee for the
    arguments' plain types, not for the constants written at the call site; True when
    applied.

    Numba types a constant argument (``quadrant(net, ..., 0)``) as a literal and, calling a
    jitted function, compiles a specialisation of the callee for that literal: besides the
    one for ``int64``, another per constant and call site. A cold render of the default
    scene compiled 13 such copies (the Bezier quadrant three times, the BVH's split, the
    ray-triangle test, the memo's nodes: about 3 s of its compile). None of subtrace's
    functions asks for a literal (no ``numba.literally``, and the branches Numba prunes on
    arguments are on None). Functions of other modules (Numba's own overloads) are left
    as they are."""
    try:
        from numba.core import dispatcher, types
    except ImportError:  # pragma: no cover - another Numba
        return False
    base = getattr(dispatcher, "_DispatcherBase", None)
    get_call_template = getattr(base, "get_call_template", None)
    if get_call_template is None:
        return False  # pragma: no cover - another Numba

    def plain_call_template(self, args, kws):
        if getattr(self.py_func, "__module__", "").startswith("subtrace."):
            args = tuple(types.unliteral(a) for a in args)
            kws = {k: types.unliteral(v) for k, v in kws.items()}
        return get_call_template(self, args, kws)

    base.get_call_template = plain_call_template
    return True


@_patch
def _flag_values_from_defaults() -> bool:
    """Make Numba's compiler flags list their values from a table of the defaults; True
    when applied.

    Typing a call to one of Numba's own functions (``np.empty``, ``min``, ...) looks its
    implementation up in a cache keyed on the compiler's flags, which hashes and compares
    them as the dict of every option's value, read one property at a time (about 40
    options): a cold render of the default scene made about 100,000 such dicts. Here the
    dict is the class's defaults updated with the values set, the same dict. A Numba whose
    flags are organised differently is left alone."""
    try:
        from numba.core import targetconfig
    except ImportError:  # pragma: no cover - another Numba
        return False
    config_class = getattr(targetconfig, "TargetConfig", None)
    if not isinstance(getattr(config_class, "options", None), Mapping) or \
            "_values" not in getattr(config_class, "__slots__", ()):
        return False  # pragma: no cover - another Numba
    defaults = {}

    def values(self):
        kind = type(self)
        d = defaults.get(kind)
        if d is None:
            d = defaults[kind] = {k: option.default for k, option in kind.options.items()}
        d = dict(d)
        d.update(self._values)  # (only options are ever set: their properties' setters)
        return d

    config_class.values = values
    return True


# The compiler flags a function compiled inside another's compile takes from it (Numba's
# CPUTargetOptions.finalize: inherit_if_not_set); the others are the caller's own
INHERITED_FLAGS = ("nrt", "fastmath", "error_model", "forceinline")


@_patch
def _overloads_shared_across_flags() -> bool:
    """Key the implementations of Numba's own functions (``np.empty``, ``min``, ...) on the
    compiler flags they inherit from the function being compiled, not on all of its flags;
    True when applied.

    Numba compiles such an implementation once per argument types and flags of the caller.
    The flags differ between kernels (a kernel's ``nogil``, a callee's missing Python
    wrapper), though the implementation inherits only :data:`INHERITED_FLAGS` from them and
    is compiled the same way under each: a cold render of the default scene compiled
    ``np.empty(int64, int64)`` six times and ``min(int64, int64)`` five. Here one compiled
    implementation serves every caller whose inherited flags are equal. A Numba whose
    overload templates are organised differently is left alone."""
    try:
        from numba.core.typing import templates
    except ImportError:  # pragma: no cover - another Numba
        return False
    template = getattr(templates, "_OverloadFunctionTemplate", None)
    stack = _flag_stack()
    if template is None or not hasattr(template, "_build_impl") or stack is None:
        return False  # pragma: no cover - another Numba
    try:
        from numba.core.compiler import Flags
    except ImportError:  # pragma: no cover - another Numba
        return False
    if not all(name in Flags.options for name in INHERITED_FLAGS):
        return False  # pragma: no cover - another Numba

    def get_impl(self, args, kws):
        cache_key = self.context, tuple(args), tuple(kws.items()), _inherited(stack)
        try:
            return self._impl_cache[cache_key]
        except KeyError:  # (built outside the handler: no nested KeyError in its errors)
            pass
        return self._build_impl(cache_key, args, kws)

    template._get_impl = get_impl
    return True


@_patch
def _function_types_resolved_once() -> bool:
    """Make Numba resolve a call of one of its function types (an operator, a builtin, a
    NumPy function) once per argument types and inherited compiler flags, not at every call
    site; True when applied.

    Typing a call tries the function's templates one after another until one accepts the
    arguments (``a + b`` on two floats: the templates of integers, complex numbers, arrays,
    tuples, ... first, each failure recorded with its message). Kernels make the same calls
    thousands of times over. Here the signature the templates gave is kept, keyed on the
    function type, the target, the arguments and the flags a compiled implementation
    inherits (:data:`INHERITED_FLAGS`), and given again to the next call of those types;
    the implementation key it registered stays registered. Failures are not kept (each
    raises as before). A Numba whose function types are organised differently is left
    alone."""
    try:
        from numba.core.target_extension import get_local_target
        from numba.core.types import functions
    except ImportError:  # pragma: no cover - another Numba
        return False
    base = getattr(functions, "BaseFunction", None)
    stack = _flag_stack()
    if base is None or not hasattr(base, "get_call_type") or stack is None:
        return False  # pragma: no cover - another Numba
    if hasattr(base.get_call_type, "__wrapped__"):
        return True  # (applied before)
    resolve = base.get_call_type
    resolved = {}

    def get_call_type(self, context, args, kws):
        try:
            key = (self, context, get_local_target(context), tuple(args),
                   tuple(sorted(kws.items())), _inherited(stack))
            hash(key)
        except TypeError:  # (an unhashable argument type: typed as before)
            return resolve(self, context, args, kws)
        sig = resolved.get(key)
        if sig is None:
            sig = resolve(self, context, args, kws)
            if sig is not None:
                resolved[key] = sig
        return sig

    get_call_type.__wrapped__ = resolve
    base.get_call_type = get_call_type
    return True


def _flag_stack():
    """Numba's stack of the compiler flags of the functions being compiled
    (``targetconfig.ConfigStack``, read by :func:`_inherited`), or None in a Numba
    organised otherwise."""
    try:
        from numba.core import targetconfig
    except ImportError:  # pragma: no cover - another Numba
        return None
    stack = getattr(targetconfig, "ConfigStack", None)
    return stack if hasattr(stack, "top_or_none") else None


def _inherited(stack):
    """The values of :data:`INHERITED_FLAGS` of the function being compiled (the top of
    Numba's ``ConfigStack``), as a key; None outside a compile."""
    flags = stack.top_or_none()
    return None if flags is None else tuple(
        _hashable(getattr(flags, name)) for name in INHERITED_FLAGS)


def _hashable(value):
    """A flag's value as a key: option objects (fastmath's set of flags) by their sorted
    flags, others as they are."""
    flags = getattr(value, "flags", None)
    return ("flags", tuple(sorted(flags))) if isinstance(flags, (set, frozenset)) else value


# Mangled-name prefixes of the functions LLVM must inline at every call (jit.llvm_inline_njit)
_LLVM_INLINED: set[str] = set()


def mark_llvm_inline(fn) -> None:
    """Have LLVM inline the compiled versions of ``fn`` into every caller
    (:func:`_inline_marked_functions`; where that patch is not applied, they are called)."""
    _LLVM_INLINED.add(_mangled_prefix(fn.__module__, fn.__qualname__))


def _mangled_prefix(module: str, qualname: str) -> str:
    """The start of the names Numba gives the compiled versions of ``module.qualname``:
    ``_ZN`` then each dotted part preceded by its length (its ABI tags follow)."""
    return "_ZN" + "".join(f"{len(part)}{part}" for part in f"{module}.{qualname}".split("."))


def _marked(name: str) -> bool:
    """Whether the compiled function ``name`` is a version of a :func:`llvm_inline_njit`
    helper: one of the prefixes, then its ABI tags (``B``) or the name's end (``E``)."""
    return any(name.startswith(p) and name[len(p):len(p) + 1] in ("B", "E")
               for p in _LLVM_INLINED)


@_patch
def _inline_marked_functions() -> bool:
    """Give the functions of :func:`llvm_inline_njit` LLVM's ``alwaysinline`` attribute as
    Numba lowers them; True when applied. The attribute travels with the function's code
    (the bitcode a caller compiled later links against, from the cache too), so LLVM
    inlines it into every caller. A Numba whose lowering is organised differently is left
    alone (the functions are then called, not inlined: slower, the same results)."""
    try:
        from numba.core import cpu
    except ImportError:  # pragma: no cover - another Numba
        return False
    post_lowering = getattr(cpu.CPUContext, "post_lowering", None)
    if post_lowering is None:
        return False  # pragma: no cover - another Numba

    def marking_post_lowering(self, mod, library):
        for fn in mod.functions:
            if not fn.is_declaration and _marked(fn.name):
                fn.attributes.add("alwaysinline")
        return post_lowering(self, mod, library)

    cpu.CPUContext.post_lowering = marking_post_lowering
    return True


@_patch
def _ir_variables_listed_directly() -> bool:
    """Make Numba list the variables of an IR instruction without its generic recursion;
    True when applied.

    Numba's analyses (uses and definitions, liveness, the deletion of dead variables)
    list each instruction's variables many times per compile, through a recursion that
    asks ``isinstance`` of every attribute of the instruction: its location, names and
    constants included (1.3 million calls in a cold render's process). Here the common
    cases are recognised by their exact class first (a variable, a dict, list or tuple,
    an expression, a location or a string); anything else goes the old way. The lists
    are the same, in the same order."""
    try:
        from numba.core import ir
    except ImportError:  # pragma: no cover - another Numba
        return False
    inst = getattr(ir, "Inst", None)
    if inst is None or not hasattr(inst, "_rec_list_vars") or \
            not all(hasattr(ir, name) for name in ("Var", "Expr", "Loc")):
        return False  # pragma: no cover - another Numba
    var, expr, loc = ir.Var, ir.Expr, ir.Loc
    leaves = {loc, str, int, float, bool, type(None)}

    def collect(val, out):
        t = type(val)
        if t is var:
            out.append(val)
        elif t in leaves:
            pass
        elif t is dict:
            for v in val.values():
                collect(v, out)
        elif t is list or t is tuple:
            for v in val:
                collect(v, out)
        elif t is expr:
            collect(val._kws, out)
        elif isinstance(val, var):  # (the rest as Numba's recursion orders them)
            out.append(val)
        elif isinstance(val, inst):
            out.extend(val.list_vars())
        elif isinstance(val, (list, tuple)):
            for v in val:
                collect(v, out)
        elif isinstance(val, dict):
            for v in val.values():
                collect(v, out)

    def rec_list_vars(self, val):
        out = []
        collect(val, out)
        return out

    inst._rec_list_vars = rec_list_vars
    return True


# --------------------------------------------------------------------------------------
# "import" too: the helpers kept as bitcode (a process that may load a helper from the
# cache reads the kind it is kept as)
# --------------------------------------------------------------------------------------

# The cache's kind of a helper kept as bitcode alone (:func:`_helpers_linked_only`)
LINKED_ONLY = "subtrace-linked-only"


@_patch
def _helpers_linked_only() -> bool:
    """Make the helpers of :func:`leaf_njit` and :func:`callee_njit` compile to optimised
    LLVM bitcode only, never to machine code; True when applied.

    Numba finalises every compiled function as if Python were to call it: it optimises the
    function's module, then has the execution engine generate its machine code, and the
    cache stores that object code beside the bitcode. A helper without the Python and the
    C-callable wrappers is never called that way: every kernel that calls it links its
    bitcode in and generates the helper's code again, inlined or not, as part of its own.
    The helper's own machine code was about 0.9 s of CPU in a cold render of the default
    scene (70-odd helpers: 0.4 s in the render's process, 0.5 s in the helper process).
    Here such a library (one of subtrace's functions, neither wrapper defined) is finalised
    without the engine, and the cache keeps its bitcode alone (kind :data:`LINKED_ONLY`),
    which a kernel compiled later in another process links as before.

    Nor is the helper's module optimised as a whole: its functions are optimised one by one
    as Numba adds them (as before), and the kernel that links the helper optimises its
    whole module, the helper's code included, after linking (as before). The module pass
    of each helper (about 0.8 s of CPU in a cold render) only did that work ahead. The
    kernels' code differs a little (LLVM inlines from less simplified helpers), the images
    not at all; their speed is the same within the spread (``benchmarks/ab.py``, nine
    rounds). A Numba whose code libraries are organised differently is left alone."""
    try:
        import llvmlite.binding as ll
        from numba.core import codegen, cpu
    except ImportError:  # pragma: no cover - another Numba
        return False
    library = getattr(codegen, "CPUCodeLibrary", None)
    needed = ("_finalize_final_module", "_optimize_final_module", "_finalize_dynamic_globals",
              "_verify_declare_only_symbols", "serialize_using_object_code", "_unserialize",
              "_get_module_for_linking")
    jit_codegen = getattr(codegen, "JITCPUCodegen", None)
    if library is None or not all(hasattr(library, name) for name in needed) or \
            not hasattr(cpu.CPUContext, "get_executable") or \
            not hasattr(jit_codegen, "set_env"):
        return False  # pragma: no cover - another Numba
    set_environment = jit_codegen.set_env
    get_executable = cpu.CPUContext.get_executable
    finalize_final_module = library._finalize_final_module
    optimize_final_module = library._optimize_final_module
    serialize = library.serialize_using_object_code
    unserialize = library._unserialize.__func__

    def defines(lib, name):
        try:
            return not lib._final_module.get_function(name).is_declaration
        except NameError:
            return False

    def executable(self, lib, fndesc, env):
        # (called once lowered, before the library is finalised, and on a load)
        if not lib._finalized and fndesc.modname.startswith("subtrace.") and \
                not defines(lib, fndesc.llvm_cpython_wrapper_name) and \
                not defines(lib, fndesc.llvm_cfunc_wrapper_name):
            lib._subtrace_linked_only = True
        return get_executable(self, lib, fndesc, env)

    def set_env(self, env_name, env):
        # (a helper's environment: no code of its own to point at it)
        if self._engine.get_global_value_address(env_name):
            set_environment(self, env_name, env)

    def optimize_final(self):
        if not getattr(self, "_subtrace_linked_only", False):
            optimize_final_module(self)

    def finalize_final(self):
        if not getattr(self, "_subtrace_linked_only", False):
            return finalize_final_module(self)
        self._finalize_dynamic_globals()
        self._verify_declare_only_symbols()
        self._finalized = True

    def serialize_linked_only(self):
        if not getattr(self, "_subtrace_linked_only", False):
            return serialize(self)
        return self.name, LINKED_ONLY, self._get_module_for_linking().as_bitcode()

    def unserialize_linked_only(cls, gen, state):
        name, kind, data = state
        if kind != LINKED_ONLY:
            return unserialize(cls, gen, state)
        self = gen.create_library(name)
        self._subtrace_linked_only = True
        self._shared_module = ll.parse_bitcode(data)
        self._finalized = True
        return self

    cpu.CPUContext.get_executable = executable
    jit_codegen.set_env = set_env
    library._finalize_final_module = finalize_final
    library._optimize_final_module = optimize_final
    library.serialize_using_object_code = serialize_linked_only
    library._unserialize = classmethod(unserialize_linked_only)
    return True


# --------------------------------------------------------------------------------------
# "loader" and "compiler": a command's own process, a compiling helper process
# --------------------------------------------------------------------------------------

@_patch
def _cached_kernel_loader() -> bool:
    """Trim Numba's cache loader: the last patch of the ``"loader"`` stage (for a command in
    a process of its own, ``jit.trim_loader``), whose other patches the list below names.

    Numba's cache loader "refreshes" its CPU target before every load: it registers the
    typing and lowering of everything Numba supports (about 270 registries), and on the
    way imports scipy.linalg only to ask whether np.dot may call BLAS (about 0.2 s alone).
    A kernel read back from the cache needs none of that, only Numba's runtime (memory
    management), which its machine code links against. So here:

    * loading a cached kernel initialises the runtime and skips the refresh;
    * scipy.linalg is refused while a kernel loads (its pickled environment imports
      numba.np.arraymath, whose import asks for BLAS) and while Numba's compiler sets the
      target up for a kernel that is not in the cache; a kernel that needs BLAS still
      imports scipy.linalg when it is compiled.

    * the code generator's description of its target, part of every kernel's cache key,
      is made once (:func:`_target_described_once`);
    * the runtime is started on a thread of its own at once, while this thread goes on
      importing the renderer; the first kernel load or compile waits for it. Its few
      compiled functions are stored beside the kernels by the first process and loaded
      from there by the next (:func:`_runtime_from_the_kernel_folder`): compiling them took
      about 28 ms of CPU and brought up LLVM's optimiser and code generator, whose memory
      (22-25 MB of a warm render's peak) a command that compiles nothing no longer holds;
    * Numba's hooks on LLVM's lock, which only time the lock for Numba's compile events, are
      removed: a kernel load makes thousands of LLVM calls (its symbols, one by one), each
      of which ran them twice;
    * a cached kernel's names are read from its object code's symbol table (ELF) instead of
      from the bitcode Numba keeps beside it, which is parsed only when a kernel compiled
      later links against it (:func:`_lazy_bitcode`): parsing it was about half of every
      load's time;
    * the environments of Numba's own functions inlined in a kernel (array allocation, math)
      are rebuilt without importing the modules that define them
      (:class:`_NumbaEnvironmentsUnimported`): importing numba.np.arrayobj and arraymath
      for them took about 22 ms of every render;
    * an array is typed without importing numpy.ma (:func:`_arrays_typed_without_numpy_ma`):
      Numba asks whether each new kind of array is a masked array, and the question imported
      numpy.ma, about 5 ms of every render;
    * Numba's search of the installed packages for extensions of its own (entry points
      named ``numba_extensions``), made before a process's first call of a kernel, is
      skipped: the command runs only subtrace's kernels, which use none, and the search
      read the metadata of every installed distribution (3.7 ms of every render here, 132
      distributions);
    * each kernel loaded is listed, with its signature, in
      :data:`LOADED`: what the next render of the same kind reads ahead
      (:mod:`subtrace.startup.preload`), and a kernel that was read ahead
      (:data:`READ_AHEAD`) is taken from there instead of the cache.

    Numbas whose loader is organised differently are left alone (the command is then just
    slower); tests run the command in fresh processes on warm and cold caches. True when
    applied.
    """
    from numba.core.caching import Cache
    from numba.core.compiler_lock import global_compiler_lock
    from numba.core.registry import cpu_target
    from numba.core.runtime import rtsys

    if not all(hasattr(Cache, name) for name in ("load_overload", "_load_overload",
                                                   "_guard_against_spurious_io_errors")) or \
            not hasattr(rtsys, "initialize"):
        return False
    unimported = _NumbaEnvironmentsUnimported()
    context = cpu_target.target_context

    def start():
        try:
            rtsys.initialize(context)
        except Exception:  # noqa: BLE001 - said by the first load, which initialises again
            pass

    starting = threading.Thread(target=start, daemon=True, name="subtrace-numba-runtime")
    starting.start()

    def runtime_ready(target_context):
        starting.join()
        rtsys.initialize(target_context)  # idempotent (and the fallback if the thread failed)

    def read_overload(self, sig, target_context):
        runtime_ready(target_context)  # loaded code calls into the runtime
        cres = None  # (a miss: the kernel compiles; also when the guard swallowed an I/O error)
        with _without_scipy_linalg(), unimported, self._guard_against_spurious_io_errors():
            cres = self._load_overload(sig, target_context)
        return cres

    def load_overload(self, sig, target_context):
        func = getattr(self, "_py_func", None)
        cres = _taken(func, sig)  # (read ahead by the preload thread, if it was)
        if cres is None:
            cres = read_overload(self, sig, target_context)
        if cres is not None and func is not None and not compiling_here():
            # (the next render's preload manifest: what Python called, not what a compile
            # linked in)
            LOADED.append((func.__module__, func.__qualname__, tuple(sig)))
        return cres

    full_refresh = context.refresh

    def refresh():
        starting.join()  # (a compile initialises the runtime too: not on two threads at once)
        with _without_scipy_linalg():
            return full_refresh()

    Cache.load_overload = load_overload
    context.refresh = refresh
    LOADER.update(read=read_overload, folder=_SETTINGS["kernel_dir"] / "preload",
                  lock=global_compiler_lock)
    return True


def _taken(func, sig):
    """The compile result of ``func`` for the argument types ``sig`` if it was read ahead
    (:data:`READ_AHEAD`: handed over once), else None. Called under Numba's compiler lock."""
    if not READ_AHEAD or func is None:
        return None
    return READ_AHEAD.pop((func, tuple(sig)), None)


@_patch
def _runtime_from_the_kernel_folder() -> bool:
    """Make Numba's runtime load its compiled functions (atomic reference counts, the
    memory-info accessors) from the kernel folder (``jit.KERNEL_DIR``) when a previous process
    stored them there, and store them when it compiles them; True when applied (see
    :func:`_cached_kernel_loader`). They are the runtime's LLVM module, compiled as Numba
    compiles it, kept as object code and bitcode as a cached kernel is (the folder's key holds
    the Numba version and the CPU), and loaded the same way. A stored file that cannot be read
    back is compiled again. A Numba organised otherwise is left alone."""
    try:
        from numba.core.runtime import nrtdynmod
    except ImportError:  # pragma: no cover - another Numba
        return False
    create = getattr(nrtdynmod, "create_nrt_module", None)
    if create is None or not hasattr(nrtdynmod, "compile_nrt_functions"):
        return False  # pragma: no cover - another Numba
    import pickle

    import numba

    path = _SETTINGS["kernel_dir"] / "runtime" / f"nrt-{numba.__version__}.pkl"

    def compile_or_load(ctx):
        codegen = ctx.codegen()
        try:
            state = pickle.loads(path.read_bytes())
            return codegen.unserialize_library(state)
        except Exception:  # noqa: BLE001 - absent, partial or foreign: compiled below
            pass
        module, library = create(ctx)
        library.enable_object_caching()
        library.add_ir_module(module)
        library.finalize()
        from subtrace.errors import SubtraceError
        from subtrace.runtime.atomic import write_bytes

        try:  # (atomically: processes storing it at once each write a whole file)
            data = pickle.dumps(library.serialize_using_object_code(), protocol=4)
            path.parent.mkdir(parents=True, exist_ok=True)
            write_bytes(path, data)
        except (OSError, RuntimeError, pickle.PicklingError, SubtraceError):
            pass
        return library

    nrtdynmod.compile_nrt_functions = compile_or_load
    return True


@_patch
def _no_extension_search() -> bool:
    """Mark Numba's extensions as initialised without searching the installed packages'
    entry points for them (see :func:`_cached_kernel_loader`); True when applied."""
    try:
        from numba.core import entrypoints
    except ImportError:  # pragma: no cover - another Numba
        return False
    if not hasattr(entrypoints, "_already_initialized"):
        return False  # pragma: no cover - another Numba
    entrypoints._already_initialized = True
    return True


@_patch
def _arrays_typed_without_numpy_ma() -> bool:
    """Type NumPy arrays for Numba's dispatchers without importing numpy.ma (see
    :func:`_cached_kernel_loader`). Numba's typing of an array first rejects masked arrays,
    and naming their class imports numpy.ma. No masked array exists before numpy.ma is
    imported, so until then an array is typed here from its dtype, dimensions, layout and
    writeability (what Numba's own typing reads), each kind once: Numba builds a new type
    object and then looks up its interned twin for every array of every call it types (about
    10 us an array; a render's first calls type some 370 arrays); afterwards Numba's typing
    answers as before."""
    try:
        from numba.core import types
        from numba.core.typing.typeof import typeof_impl
        from numba.np.numpy_support import from_dtype, map_layout
    except ImportError:  # pragma: no cover - another Numba
        return False
    import numpy as np

    numba_typeof = typeof_impl.dispatch(np.ndarray)

    known = {}  # (dtype, ndim, C and F contiguity, writeable) -> the array's type

    def typeof_array(val, c):
        if "numpy.ma" in sys.modules:
            return numba_typeof(val, c)
        flags = val.flags
        key = (val.dtype, val.ndim, flags.c_contiguous, flags.f_contiguous, flags.writeable)
        typ = known.get(key)
        if typ is None:
            try:
                dtype = from_dtype(val.dtype)
            except Exception:  # noqa: BLE001 - an unsupported dtype: Numba's own message
                return numba_typeof(val, c)
            typ = known[key] = types.Array(dtype, val.ndim, map_layout(val),
                                           readonly=not flags.writeable)
        return typ

    typeof_impl.register(np.ndarray)(typeof_array)
    return True


@_patch
def _target_described_once() -> bool:
    """Numba's code generator describes its target (triple, CPU name, CPU features: the
    ``magic_tuple`` of every cache key) once per process instead of at every kernel load:
    each description asked LLVM for the host's CPU name and the module's triple again,
    about 75 us a load (20 loads in a render of a small cage). Nothing in a process changes
    them."""
    try:
        from numba.core.codegen import CPUCodegen
    except ImportError:  # pragma: no cover - another Numba
        return False
    describe = getattr(CPUCodegen, "magic_tuple", None)
    if describe is None:
        return False
    if getattr(describe, "__wrapped__", None) is not None:
        return True  # (applied before)

    def magic_tuple(self):
        told = self.__dict__.get("_subtrace_magic_tuple")
        if told is None:
            told = self._subtrace_magic_tuple = describe(self)
        return told

    magic_tuple.__wrapped__ = describe
    CPUCodegen.magic_tuple = magic_tuple
    return True


@_patch
def _lazy_bitcode() -> bool:
    """Load cached kernels without parsing their linking bitcode (see
    :func:`_cached_kernel_loader`): Numba's loader parses it to list the names the kernel
    defines (which the execution engine is asked about before any address is taken) and keeps it
    for kernels compiled later that call this one. Here the names come from the object code's
    ELF symbol table (:func:`object_symbols`), and the bitcode is parsed when a compile first
    links against the kernel. Objects that are not ELF, and Numbas organised otherwise, load as
    before."""
    try:
        from numba.core import codegen
        library = codegen.CPUCodeLibrary
        full_unserialize = library._unserialize.__func__
        full_linking = library._get_module_for_linking
        ll = codegen.ll
    except (ImportError, AttributeError):  # pragma: no cover - another Numba
        return False

    def unserialize(cls, gen, state):
        name, kind, data = state
        names = object_symbols(data[0]) if kind == "object" else None
        if names is None:
            return full_unserialize(cls, gen, state)
        self = gen.create_library(name)
        self.enable_object_caching()
        self._set_compiled_object(data[0])
        self._subtrace_bitcode = data[1]  # (parsed by get_module_for_linking)
        self._finalize_final_module()
        gen._engine._defined_symbols |= names
        return self

    def get_module_for_linking(self):
        bitcode = self.__dict__.pop("_subtrace_bitcode", None)
        if bitcode is not None:
            self._shared_module = ll.parse_bitcode(bitcode)
        return full_linking(self)

    library._unserialize = classmethod(unserialize)
    library._get_module_for_linking = get_module_for_linking
    return True


def object_symbols(data: bytes) -> set[str] | None:
    """The names an ELF64 little-endian object file defines (functions, data and untyped
    symbols of a section), or None when ``data`` is not one."""
    import numpy as np

    if len(data) < 64 or data[:6] != b"\x7fELF\x02\x01":
        return None
    try:
        shoff = int.from_bytes(data[0x28:0x30], "little")
        entsize = int.from_bytes(data[0x3A:0x3C], "little")
        count = int.from_bytes(data[0x3C:0x3E], "little")
        head = np.dtype([("name", "<u4"), ("type", "<u4"), ("flags", "<u8"), ("addr", "<u8"),
                         ("offset", "<u8"), ("size", "<u8"), ("link", "<u4"), ("info", "<u4"),
                         ("align", "<u8"), ("entsize", "<u8")])
        if entsize != head.itemsize:
            return None
        sym = np.dtype([("name", "<u4"), ("info", "u1"), ("other", "u1"), ("shndx", "<u2"),
                        ("value", "<u8"), ("size", "<u8")])
        sections = np.frombuffer(data, head, count, shoff)
        names = set()
        for sec in sections[sections["type"] == 2]:  # SHT_SYMTAB
            strtab = sections[int(sec["link"])]
            strings = data[int(strtab["offset"]):int(strtab["offset"] + strtab["size"])]
            table = np.frombuffer(data, sym, int(sec["size"]) // sym.itemsize,
                                  int(sec["offset"]))
            kind = table["info"] & 0xF
            keep = (table["shndx"] != 0) & (table["name"] != 0) & (kind <= 2)
            for at in table["name"][keep]:
                end = strings.index(b"\0", int(at))
                names.add(strings[int(at):end].decode())
        return names
    except (ValueError, IndexError, UnicodeDecodeError):
        return None


class _NumbaEnvironmentsUnimported:
    """Inside the block (a cached kernel's load, under Numba's compiler lock), rebuild the
    environments of Numba's own functions (``numba.*``: array allocation, math) without
    importing their modules, where these are not imported yet.

    Every function a kernel links has an environment: its module's globals and constants,
    read at run time only by object mode and by the wrapper that boxes a kernel's results
    for Python. Numba's loader imports each one's module to take its globals; for the array
    functions of numba.np.arrayobj and numba.np.arraymath that import was most of a warm
    render's kernel loading (about 22 ms). Those functions are compiled without a Python
    wrapper and never in object mode, so their environments get the module's name alone; a
    later compile that needs the module imports it as usual (its functions get environments
    of their own names). Outside the block Numba's own rebuild is in place, so what a
    compile pickles names it, not this one. A Numba organised otherwise is left alone."""

    def __init__(self):
        try:
            from numba.core import environment
            self._module = environment
            self._rebuild = environment._rebuild_env
            self._memo = environment.Environment._memo
        except (ImportError, AttributeError):  # pragma: no cover - another Numba
            self._module = None

    def _rebuild_env(self, modname, consts, env_name):
        if not (isinstance(modname, str) and modname.startswith("numba.")
                and modname not in sys.modules):
            return self._rebuild(modname, consts, env_name)
        env = self._memo.get(env_name)
        if env is None:
            env = self._module.Environment({"__name__": modname})
            env.consts[:] = consts
            env.env_name = env_name
            self._memo[env_name] = env
        return env

    def __enter__(self):
        if self._module is not None:
            self._module._rebuild_env = self._rebuild_env

    def __exit__(self, *exc):
        if self._module is not None:
            self._module._rebuild_env = self._rebuild


@_patch
def _drop_llvm_lock_events() -> bool:
    """Remove the callbacks Numba hangs on llvmlite's lock (they record "numba:llvm_lock"
    events, which only time compiles); any other callback stays."""
    try:
        import llvmlite.binding.ffi as ffi

        lock = ffi.lib._lock
        hooks = list(lock._cblist)
    except (ImportError, AttributeError):  # pragma: no cover - another llvmlite
        return False
    for acquire, release in hooks:
        if getattr(acquire, "__module__", "") == "numba.core.base":
            lock.unregister(acquire, release)
    return True


class _without_scipy_linalg:
    """Make ``import scipy.linalg`` raise ImportError inside the block, unless it is
    imported already (or refused by an enclosing block)."""

    def __enter__(self):
        self._refused = "scipy.linalg" not in sys.modules
        if self._refused:
            sys.modules["scipy.linalg"] = None

    def __exit__(self, *exc):
        if self._refused:
            del sys.modules["scipy.linalg"]
