"""Numba for subtrace's kernels: the cache folder and its key, the decorators, the first-run
notice, and a faster loader.

Every module with kernels imports Numba from here (``from subtrace.runtime.jit import nb``),
so the cache is set up before the first kernel is defined; importing :mod:`subtrace` or its
command line alone imports no Numba and sets nothing.

The kernels are cached in :data:`KERNEL_DIR`, ``<base>/numba-<key>``:

* ``<base>`` is ``$SUBTRACE_CACHE_DIR``, else ``$NUMBA_CACHE_DIR``, else
  ``$XDG_CACHE_HOME/subtrace`` (``~/.cache/subtrace``); workers that share one folder share
  the compiled kernels (Numba writes each file under a temporary name, then renames it);
* ``<key>`` hashes the bytes of every source file of the package, the Numba and Python
  versions and the CPU Numba compiles for (:func:`cache_key`): a kernel calls jitted helpers
  of other modules, and Numba's own cache only notices edits to the kernel's file. Nothing
  in the key is a file's time, so reinstalling the same sources (new modification times, or
  another folder) finds every kernel compiled;
* inside it, each kernel's index is stamped with the hash of its module's bytes, not with
  the file's modification time (:class:`_ContentLocator`, which Numba's cache uses for
  subtrace's files), and lies at the module's path in the package, not at a hash of the
  folder it was installed in.

The folders of other keys are pruned to the :data:`CACHES_KEPT` most recently used.
"""

from __future__ import annotations

import hashlib
import os
import re
import sys
import threading
from collections.abc import Mapping
from pathlib import Path

from subtrace.version import VERSION

ROOT = Path(__file__).resolve().parents[1]  # the package folder: src/subtrace
CACHES_KEPT = 8  # cache folders of other keys kept (other versions, checkouts, branches)
_FOLDER = re.compile(r"numba-[0-9a-f]{16}")  # the only names prune_caches removes


def cache_base() -> Path:
    """The folder that holds the cache folders: ``$SUBTRACE_CACHE_DIR``, else
    ``$NUMBA_CACHE_DIR``, else ``$XDG_CACHE_HOME/subtrace`` (``~/.cache/subtrace``)."""
    for name in ("SUBTRACE_CACHE_DIR", "NUMBA_CACHE_DIR"):
        if os.environ.get(name):
            return Path(os.environ[name]).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(xdg) / "subtrace"


def source_digests(root: Path = ROOT) -> dict[str, str]:
    """sha256 (hex) of the bytes of every ``.py`` file under ``root``, by its path relative
    to ``root`` (posix separators)."""
    digests = {}
    for path in sorted(root.rglob("*.py")):
        digests[path.relative_to(root).as_posix()] = hashlib.sha256(path.read_bytes()).hexdigest()
    return digests


def cache_key(digests: dict[str, str], numba_version: str, cpu: tuple) -> str:
    """The cache folder's key (16 hex digits) for sources with these ``digests``
    (:func:`source_digests`), this Numba version and CPU (:func:`compile_target`) and the
    running Python."""
    h = hashlib.sha256()
    h.update(repr((VERSION, numba_version, sys.version_info[:2], cpu)).encode())
    for rel in sorted(digests):
        h.update(f"{rel}\0{digests[rel]}\n".encode())
    return h.hexdigest()[:16]


def compile_target() -> tuple:
    """What Numba compiles for: (target triple, CPU name, CPU features), read as Numba's
    code generator reads them (``NUMBA_CPU_NAME`` / ``NUMBA_CPU_FEATURES`` override the
    host's: e.g. ``NUMBA_CPU_NAME=generic`` for one cache on machines of different CPUs).
    Call after Numba is imported (its configuration reads the environment)."""
    import llvmlite.binding as ll
    from numba.core import config

    name = config.CPU_NAME or ll.get_host_cpu_name()
    features = config.CPU_FEATURES
    if features is None:
        try:
            features = ll.get_host_cpu_features().flatten()
        except RuntimeError:  # LLVM cannot tell: Numba compiles without features too
            features = ""
    return ll.get_process_triple(), name, features


def prune_caches(base: Path) -> None:
    """Remove all but the ``CACHES_KEPT`` most recently used cache folders (``numba-`` and
    16 hex digits) of ``base``; any other file or folder there is left alone."""
    try:
        old = sorted((p for p in base.iterdir() if _FOLDER.fullmatch(p.name)),
                     key=lambda p: p.stat().st_mtime, reverse=True)
    except OSError:
        return
    import shutil

    for p in old[CACHES_KEPT:]:
        shutil.rmtree(p, ignore_errors=True)


def _set_numba_cache_dir() -> None:
    # Numba reads NUMBA_CACHE_DIR when it is first imported. Subtrace's kernels go to
    # KERNEL_DIR whatever it says (_ContentLocator); setting it to the base when it is unset
    # keeps other cached functions of the process (tests') in the same place, and child
    # processes (the warm-up, workers) inherit the base.
    if not os.environ.get("NUMBA_CACHE_DIR"):
        os.environ["NUMBA_CACHE_DIR"] = str(cache_base())
    # Numba colours its error messages through colorama, which wraps the standard streams
    # anew for every message it formats, and typing formats one for every overload it
    # tries and rejects: about 23,000 in a cold render of the default scene (0.2-0.3 s of
    # its compile). Subtrace never shows Numba's messages to its users.
    os.environ.setdefault("NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING", "1")


_set_numba_cache_dir()

import numba as _numba  # noqa: E402  (after the cache folder is set)
from numba.core import event as _event  # noqa: E402
from numba.core.registry import CPUDispatcher as _CPUDispatcher  # noqa: E402


class _Numba:
    """Numba as subtrace's modules use it (``from subtrace.runtime.jit import nb``): its
    ``types`` and version, and :meth:`njit`."""

    types = _numba.types
    __version__ = _numba.__version__

    @staticmethod
    def njit(*args, **options):
        """``numba.njit``, compiling no C-callable wrapper unless asked
        (``no_cfunc_wrapper=False``): that wrapper serves only functions passed as
        first-class function values, which subtrace never does, and generating and
        compiling it for every kernel and helper was about 5 % of a cold render's compile
        (alternated cold renders of the default scene, medians of 3: 16.8 -> 15.9 s)."""
        options.setdefault("no_cfunc_wrapper", True)
        return _numba.njit(*args, **options)


nb = _Numba()


def _writable(folder: Path) -> str | None:
    """None when ``folder`` exists (created here if need be) and takes a file, else why not.
    A folder already there is marked as used now (prune_caches keeps the most recent)."""
    try:
        if folder.is_dir():
            os.utime(folder)
        else:
            prune_caches(folder.parent)
            folder.mkdir(parents=True, exist_ok=True)
        probe = folder / f".probe-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        return exc.strerror or str(exc)
    return None


def _check_folder(folder: Path) -> None:
    """The kernel cache must be writable: a ``$SUBTRACE_CACHE_DIR`` that is not is an error
    (one line); otherwise a warning, and Numba caches the kernels where it can."""
    why = _writable(folder)
    if why is None:
        return
    chosen = os.environ.get("SUBTRACE_CACHE_DIR")
    if chosen:
        from subtrace.errors import SubtraceError

        raise SubtraceError(f"SUBTRACE_CACHE_DIR={chosen}: cannot write the kernel cache "
                            f"{folder} ({why}); name a writable folder, or unset it")
    import warnings

    from subtrace.errors import SubtraceWarning

    warnings.warn(SubtraceWarning(f"cannot write the kernel cache {folder} ({why}): kernels "
                                  "are cached where Numba can; set SUBTRACE_CACHE_DIR to a "
                                  "writable folder"), stacklevel=2)


DIGESTS = source_digests()
KERNEL_DIR = cache_base() / f"numba-{cache_key(DIGESTS, nb.__version__, compile_target())}"
_check_folder(KERNEL_DIR)


def _content_locator():
    """Numba's cache locator for subtrace's own files (None for a Numba whose cache is
    organised differently: its own locators then apply, keyed on file times)."""
    try:
        from numba.core import caching
        base = (caching._SourceFileBackedLocatorMixin, caching._CacheLocator)
        caching.CacheImpl._locator_classes  # noqa: B018  (present, or this Numba differs)
    except (ImportError, AttributeError):  # pragma: no cover - another Numba
        return None

    made = set()  # cache folders known to exist

    class _ContentLocator(*base):
        """Caches a kernel of subtrace's package in ``KERNEL_DIR/subtrace/<module's folder>``,
        its index stamped with the sha256 of the module's bytes (:data:`DIGESTS`)."""

        def __init__(self, py_func, py_file, rel):
            self._py_file = py_file
            self._lineno = py_func.__code__.co_firstlineno
            self._stamp = DIGESTS.get(rel) or hashlib.sha256(Path(py_file).read_bytes()).hexdigest()
            self._cache_path = str(KERNEL_DIR / "subtrace" / Path(rel).parent)

        def get_cache_path(self):
            return self._cache_path

        def ensure_cache_path(self):
            # the folder once per process, without Numba's write test per kernel (a
            # temporary file for each of ~200 kernels at every start): _check_folder
            # tested the cache folder these lie in
            if self._cache_path not in made:
                os.makedirs(self._cache_path, exist_ok=True)
                made.add(self._cache_path)

        def get_source_stamp(self):
            return self._stamp

        @classmethod
        def from_function(cls, py_func, py_file):
            try:
                rel = Path(py_file).resolve().relative_to(ROOT).as_posix()
            except (OSError, ValueError):
                return None  # not subtrace's: Numba's own locators
            self = cls(py_func, py_file, rel)
            try:
                self.ensure_cache_path()
            except OSError:
                return None  # an unwritable folder: Numba's own locators
            return self

    caching.CacheImpl._locator_classes = [_ContentLocator, *caching.CacheImpl._locator_classes]
    return _ContentLocator


_content_locator()


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


# Mangled-name prefixes of the functions LLVM must inline at every call (llvm_inline_njit)
_LLVM_INLINED: set[str] = set()


def _mangled_prefix(module: str, qualname: str) -> str:
    """The start of the names Numba gives the compiled versions of ``module.qualname``:
    ``_ZN`` then each dotted part preceded by its length (its ABI tags follow)."""
    return "_ZN" + "".join(f"{len(part)}{part}" for part in f"{module}.{qualname}".split("."))


def _marked(name: str) -> bool:
    """Whether the compiled function ``name`` is a version of a :func:`llvm_inline_njit`
    helper: one of the prefixes, then its ABI tags (``B``) or the name's end (``E``)."""
    return any(name.startswith(p) and name[len(p):len(p) + 1] in ("B", "E")
               for p in _LLVM_INLINED)


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


# The cache's kind of a helper kept as bitcode alone (:func:`_helpers_linked_only`)
LINKED_ONLY = "subtrace-linked-only"


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


# (at import: a process that may load a helper from the cache reads the kind it is kept as)
HELPERS_LINKED_ONLY = _helpers_linked_only()


class _PatchInliningOnCompile(_event.Listener):
    """Numba's "numba:compile" event (a cache miss, before compiling): the inliner's fix
    (:func:`_inline_copies_scope_once`), the calls' plain argument types
    (:func:`_calls_without_literals`), the flags' values (:func:`_flag_values_from_defaults`)
    and the IR's variable lists (:func:`_ir_variables_listed_directly`) are applied at the
    process's first compile, so a command whose kernels are all cached does not import
    Numba's inliner for it. Also counts the compiles under way on each thread
    (:func:`compiling_here`)."""

    def on_start(self, event):
        global INLINE_PATCHED
        _COMPILES.depth = getattr(_COMPILES, "depth", 0) + 1
        if INLINE_PATCHED is None:
            INLINE_PATCHED = _inline_copies_scope_once()
            _calls_without_literals()
            _flag_values_from_defaults()
            _overloads_shared_across_flags()
            _inline_marked_functions()
            _ir_variables_listed_directly()
            _function_types_resolved_once()

    def on_end(self, event):
        _COMPILES.depth -= 1


INLINE_PATCHED = None  # True once applied (the process's first compile), False: not here
_COMPILES = threading.local()  # depth: the compiles under way on this thread
_event.register("numba:compile", _PatchInliningOnCompile())


def compiling_here() -> bool:
    """Whether this thread is compiling a function (a kernel read from the cache now is
    one that compile links in, not one Python called)."""
    return getattr(_COMPILES, "depth", 0) > 0


# What the first-run notice says the compile takes: the first render of the default scene on
# an empty cache as benchmarks/first_run.py measured it (2026-12-02, 2 idle cores, load 0.4:
# 23.2 s; 103 s with the machine busy at load 4); the README and BENCHMARKS.md quote the same
# run. Rerun the script (on a quiet machine) when the compile changes, and update the three
# together.
COLD_COMPILE_S = 23
COLD_COMPILE = f"about {COLD_COMPILE_S} s on 2 idle cores"
_notice = {"stream": None, "said": False, "listening": False}


def notify_compiles(stream) -> None:
    """Say once on ``stream``, when this process first has to compile one of subtrace's
    kernels (the cache lacks it) or starts a process that does (:func:`compiling`), that
    the kernels are compiling, about how long that takes and where they are kept. Only a
    terminal hears it: a ``stream`` that is not a TTY (a pipe, a file, a test's capture)
    gets nothing, so logs and scripts see no difference."""
    try:
        if not stream.isatty():
            return
    except (AttributeError, OSError, ValueError):  # closed or not a real stream
        return
    _notice["stream"] = stream
    if not _notice["listening"]:
        _event.register("numba:compile", _CompileListener())
        _notice["listening"] = True


def compiling() -> None:
    """A kernel of subtrace is about to compile, here or in a helper process: the notice of
    :func:`notify_compiles`, once per process."""
    stream = _notice["stream"]
    if stream is None or _notice["said"]:
        return
    _notice["said"] = True
    try:
        print(f"subtrace: compiling the Numba kernels for these sources ({COLD_COMPILE}, "
              f"once; later runs load them from {KERNEL_DIR})", file=stream, flush=True)
    except (OSError, ValueError):  # a terminal that went away: the render goes on
        pass


class _CompileListener(_event.Listener):
    """Numba's "numba:compile" event (a cache miss, before compiling): the notice when the
    function is one of subtrace's."""

    def on_start(self, event):
        func = getattr(event.data.get("dispatcher"), "py_func", None)
        if getattr(func, "__module__", "").startswith("subtrace."):
            compiling()

    def on_end(self, event):
        pass


def leaf_njit(fn=None, *, python: bool = False):
    """Compile a helper of the per-ray path without Numba's reference counting (``_nrt=False``).

    A helper that takes arrays would otherwise count references to each array it is passed
    or views (an out-of-line atomic increment and decrement per array per call): about a
    quarter of the trace time. These helpers only read and write the arrays they are given,
    never allocate or keep them, so the counts are not needed. Division follows IEEE
    (``error_model="numpy"``: 1/0 is inf for axis-parallel rays, no check per division).

    Kernels call these; tests call some of them too. They compile without the wrapper that
    lets Python call compiled code (its generation and compile were about a tenth of a cold
    render's compile, for 70-odd helpers that Python never calls): a call from Python goes
    through a small jitted function that calls the helper (:class:`_Helper`), compiled on
    the first such call of each process and not cached. ``python=True`` (``@leaf_njit(
    python=True)``): a helper that subtrace's own Python code calls, compiled with the
    wrapper (tests/test_jit.py checks that a warm render compiles nothing).
    """
    if fn is None:
        return lambda f: leaf_njit(f, python=python)
    if python:
        return nb.njit(cache=True, _nrt=False, error_model="numpy")(fn)
    return _helper(fn, _nrt=False, error_model="numpy")


def llvm_inline_njit(fn):
    """A :func:`leaf_njit` helper that LLVM inlines into every caller (``alwaysinline``):
    the call and its arguments vanish, as with :func:`inline_njit`, but Numba types and
    lowers the helper once, not once more in every caller (a small function called at a
    few places in each of the trace kernels: its Numba-inlined copies added about 0.7 s to
    a cold render)."""
    _LLVM_INLINED.add(_mangled_prefix(fn.__module__, fn.__qualname__))
    return leaf_njit(fn)


def callee_njit(fn):
    """Compile a helper that kernels call and that may allocate (so with Numba's reference
    counting, unlike :func:`leaf_njit`): without the wrapper Python calls compiled code
    through, as :func:`leaf_njit`'s helpers (tests call some; subtrace's own Python code
    calls none of them)."""
    return _helper(fn)


def _helper(fn, **options):
    """A :class:`_Helper` of ``fn``: cached, compiled with ``options`` and neither the
    Python nor the C-callable wrapper."""
    helper = _Helper(py_func=fn, locals={}, targetoptions={
        "nopython": True, "boundscheck": None, **options, "no_cfunc_wrapper": True,
        "no_cpython_wrapper": True})
    helper.enable_caching()
    return helper


class _Helper(_CPUDispatcher):
    """A :func:`leaf_njit` or :func:`callee_njit` helper: compiled without the wrapper that
    Python calls through, called from Python through a jitted function that calls it
    (:meth:`__call__`)."""

    _from_python = None

    def __call__(self, *args):
        call = self._from_python
        if call is None:
            helper = self
            call = self._from_python = nb.njit(lambda *a: helper(*a))
        return call(*args)


def inline_njit(fn):
    """A :func:`leaf_njit` helper called once per ray (or per ray and piece) with many array
    arguments, inlined into its caller by Numba: a call passes every field of every array
    on the stack (hundreds of words), which cost more than the work of a typical call."""
    return nb.njit(cache=True, _nrt=False, error_model="numpy", inline="always")(fn)


def trim_loader() -> None:
    """Trim Numba's set-up; for a process of its own (the command line's :func:`run`).

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
      :data:`subtrace.runtime.preload.LOADED`: what the next render of the same kind reads
      ahead (:mod:`subtrace.runtime.preload`), and a kernel that was read ahead is taken
      from there instead of the cache.

    Numbas whose loader is organised differently are left alone (the command is then just
    slower); tests run the command in fresh processes on warm and cold caches.
    """
    try:
        from numba.core.caching import Cache
        from numba.core.compiler_lock import global_compiler_lock
        from numba.core.registry import cpu_target
        from numba.core.runtime import rtsys
    except ImportError:  # pragma: no cover - a Numba without these internal modules
        return
    if not all(hasattr(Cache, name) for name in ("_load_overload",
                                                   "_guard_against_spurious_io_errors")):
        return  # pragma: no cover - a Numba whose cache loader is organised differently
    from subtrace.runtime import preload

    _drop_llvm_lock_events()
    _target_described_once()
    _runtime_from_the_kernel_folder()
    _lazy_bitcode()
    _arrays_typed_without_numpy_ma()
    _no_extension_search()
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
        cres = preload.take(func, sig)  # (read ahead by the preload thread, if it was)
        if cres is None:
            cres = read_overload(self, sig, target_context)
        if cres is not None and func is not None and not compiling_here():
            # (the next render's preload manifest: what Python called, not what a compile
            # linked in)
            preload.LOADED.append((func.__module__, func.__qualname__, tuple(sig)))
        return cres

    full_refresh = context.refresh

    def refresh():
        starting.join()  # (a compile initialises the runtime too: not on two threads at once)
        with _without_scipy_linalg():
            return full_refresh()

    Cache.load_overload = load_overload
    context.refresh = refresh
    preload.READ, preload.FOLDER = read_overload, KERNEL_DIR / "preload"
    preload.LOCK = global_compiler_lock


def _runtime_from_the_kernel_folder() -> bool:
    """Make Numba's runtime load its compiled functions (atomic reference counts, the
    memory-info accessors) from :data:`KERNEL_DIR` when a previous process stored them
    there, and store them when it compiles them; True when applied (see
    :func:`trim_loader`). They are the runtime's LLVM module, compiled as Numba compiles
    it, kept as object code and bitcode as a cached kernel is (the folder's key holds the
    Numba version and the CPU), and loaded the same way. A stored file that cannot be read
    back is compiled again. A Numba organised otherwise is left alone."""
    try:
        from numba.core.runtime import nrtdynmod
    except ImportError:  # pragma: no cover - another Numba
        return False
    create = getattr(nrtdynmod, "create_nrt_module", None)
    if create is None or not hasattr(nrtdynmod, "compile_nrt_functions"):
        return False  # pragma: no cover - another Numba
    import pickle

    path = KERNEL_DIR / "runtime" / f"nrt-{_numba.__version__}.pkl"

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
        from subtrace.io.atomic import write_bytes

        try:  # (atomically: processes storing it at once each write a whole file)
            data = pickle.dumps(library.serialize_using_object_code(), protocol=4)
            path.parent.mkdir(parents=True, exist_ok=True)
            write_bytes(path, data)
        except (OSError, RuntimeError, pickle.PicklingError, SubtraceError):
            pass
        return library

    nrtdynmod.compile_nrt_functions = compile_or_load
    return True


def _no_extension_search() -> bool:
    """Mark Numba's extensions as initialised without searching the installed packages'
    entry points for them (see :func:`trim_loader`); True when applied."""
    try:
        from numba.core import entrypoints
    except ImportError:  # pragma: no cover - another Numba
        return False
    if not hasattr(entrypoints, "_already_initialized"):
        return False  # pragma: no cover - another Numba
    entrypoints._already_initialized = True
    return True


def _arrays_typed_without_numpy_ma() -> None:
    """Type NumPy arrays for Numba's dispatchers without importing numpy.ma (see
    :func:`trim_loader`). Numba's typing of an array first rejects masked arrays, and naming
    their class imports numpy.ma. No masked array exists before numpy.ma is imported, so
    until then an array is typed here from its dtype, dimensions, layout and writeability
    (what Numba's own typing reads), each kind once: Numba builds a new type object and
    then looks up its interned twin for every array of every call it types (about 10 us an
    array; a render's first calls type some 370 arrays); afterwards Numba's typing answers
    as before."""
    try:
        from numba.core import types
        from numba.core.typing.typeof import typeof_impl
        from numba.np.numpy_support import from_dtype, map_layout
    except ImportError:  # pragma: no cover - another Numba
        return
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


def _target_described_once() -> None:
    """Numba's code generator describes its target (triple, CPU name, CPU features: the
    ``magic_tuple`` of every cache key) once per process instead of at every kernel load:
    each description asked LLVM for the host's CPU name and the module's triple again,
    about 75 us a load (20 loads in a render of a small cage). Nothing in a process changes
    them."""
    try:
        from numba.core.codegen import CPUCodegen
    except ImportError:  # pragma: no cover - another Numba
        return
    describe = getattr(CPUCodegen, "magic_tuple", None)
    if describe is None or getattr(describe, "__wrapped__", None) is not None:
        return

    def magic_tuple(self):
        told = self.__dict__.get("_subtrace_magic_tuple")
        if told is None:
            told = self._subtrace_magic_tuple = describe(self)
        return told

    magic_tuple.__wrapped__ = describe
    CPUCodegen.magic_tuple = magic_tuple


def _lazy_bitcode() -> None:
    """Load cached kernels without parsing their linking bitcode (see :func:`trim_loader`):
    Numba's loader parses it to list the names the kernel defines (which the execution
    engine is asked about before any address is taken) and keeps it for kernels compiled
    later that call this one. Here the names come from the object code's ELF symbol table
    (:func:`object_symbols`), and the bitcode is parsed when a compile first links against
    the kernel. Objects that are not ELF, and Numbas organised otherwise, load as before."""
    try:
        from numba.core import codegen
        library = codegen.CPUCodeLibrary
        full_unserialize = library._unserialize.__func__
        full_linking = library._get_module_for_linking
        ll = codegen.ll
    except (ImportError, AttributeError):  # pragma: no cover - another Numba
        return

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


def trim_compiler() -> None:
    """Trim Numba's set-up for a process of its own that compiles kernels (the render's
    helper, ``runtime.warmup``): Numba's hooks on LLVM's lock are removed
    (:func:`_drop_llvm_lock_events`); they time the lock for Numba's compile events only,
    and a cold render's helper makes about 26,000 LLVM calls, each of which ran them."""
    _drop_llvm_lock_events()


def _drop_llvm_lock_events() -> None:
    """Remove the callbacks Numba hangs on llvmlite's lock (they record "numba:llvm_lock"
    events, which only time compiles); any other callback stays."""
    try:
        import llvmlite.binding.ffi as ffi

        lock = ffi.lib._lock
        hooks = list(lock._cblist)
    except (ImportError, AttributeError):  # pragma: no cover - another llvmlite
        return
    for acquire, release in hooks:
        if getattr(acquire, "__module__", "") == "numba.core.base":
            lock.unregister(acquire, release)


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
