"""Numba for subtrace's kernels: the cache folder and its key, the decorators and the
first-run notice. Every patch of Numba's internals (a faster first compile and command
start) is in :mod:`subtrace.runtime.numba_patches`, installed here; with
``SUBTRACE_NUMBA_PATCHES=0`` (or on a Numba they were not checked on) Numba runs as it is.

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
  the file's modification time (``numba_patches._content_locator``, which Numba's cache
  uses for subtrace's files), and lies at the module's path in the package, not at a hash
  of the folder it was installed in; unpatched, Numba's own locator keeps them in the
  folder too (stamped with the files' times; the key still follows their bytes), and the
  key differs from the patched one's.

The folders of other keys are pruned to the :data:`CACHES_KEPT` most recently used.
"""

from __future__ import annotations

import hashlib
import os
import re
import sys
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
    # KERNEL_DIR whatever it says (numba_patches: the content locator, else Numba's own
    # cache folder set to KERNEL_DIR in this process); setting it to the base when it is unset
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

from subtrace.runtime import numba_patches  # noqa: E402


class _Numba:
    """Numba as subtrace's modules use it (``from subtrace.runtime.jit import nb``): its
    ``types`` and version, and :meth:`njit`."""

    types = _numba.types
    __version__ = _numba.__version__

    @staticmethod
    def njit(*args, **options):
        """``numba.njit``, with the options of :data:`numba_patches.NJIT_OPTIONS` where the
        patches apply (no C-callable wrapper unless asked: ``no_cfunc_wrapper=False``)."""
        for name, value in numba_patches.NJIT_OPTIONS.items():
            options.setdefault(name, value)
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


PATCHED = numba_patches.wanted(nb.__version__)  # Numba's internals patched in this process
DIGESTS = source_digests()
# (the patches' state is in the key: a patched process keeps helpers as bitcode alone, which
# an unpatched one cannot read)
KERNEL_DIR = cache_base() / "numba-{}".format(cache_key(
    DIGESTS, nb.__version__ if PATCHED else f"{nb.__version__}+unpatched", compile_target()))
_check_folder(KERNEL_DIR)
numba_patches.install(PATCHED, KERNEL_DIR, DIGESTS, ROOT)


# What the first-run notice says the compile takes: the first render of the default scene on
# an empty cache as benchmarks/first_run.py measured it (2026-12-05, with the grid maps'
# kernels, 2 cores, a quiet machine, load 0.6: 18.6 s; 17.7 s the evening before; 103 s with
# the machine busy at load 4); the README and BENCHMARKS.md quote the same run. Rerun the
# script (on a quiet machine) when the compile changes, and update the three together.
COLD_COMPILE_S = 19
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

    Kernels call these; tests call some of them too. Where the patches apply, they compile
    without the wrapper that lets Python call compiled code
    (:func:`numba_patches.helper`), and a call from Python goes through a
    small jitted function that calls the helper. ``python=True`` (``@leaf_njit(
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
    a cold render). Where that patch is not applied, the helper is called."""
    numba_patches.mark_llvm_inline(fn)
    return leaf_njit(fn)


def callee_njit(fn):
    """Compile a helper that kernels call and that may allocate (so with Numba's reference
    counting, unlike :func:`leaf_njit`): without the wrapper Python calls compiled code
    through, as :func:`leaf_njit`'s helpers (tests call some; subtrace's own Python code
    calls none of them)."""
    return _helper(fn)


def _helper(fn, **options):
    """``fn`` cached and compiled with ``options``, with neither the Python nor the
    C-callable wrapper where the patches apply (:func:`numba_patches.helper`), else a
    plain :meth:`_Numba.njit` function."""
    helper = numba_patches.helper(fn, options)
    return helper if helper is not None else nb.njit(cache=True, **options)(fn)


def inline_njit(fn):
    """A :func:`leaf_njit` helper called once per ray (or per ray and piece) with many array
    arguments, inlined into its caller by Numba: a call passes every field of every array
    on the stack (hundreds of words), which cost more than the work of a typical call."""
    return nb.njit(cache=True, _nrt=False, error_model="numpy", inline="always")(fn)




def trim_loader() -> None:
    """Trim Numba's set-up; for a process of its own (the command line's ``run``): cached
    kernels load without Numba's full target set-up, scipy.linalg or the search for Numba's
    extensions (the ``"loader"`` stage of :mod:`subtrace.runtime.numba_patches`; nothing
    where the patches are off)."""
    numba_patches.apply("loader")


def trim_compiler() -> None:
    """Trim Numba's set-up for a process of its own that compiles kernels (the render's
    helper, ``startup.warmup``): Numba's hooks on LLVM's lock, which time it for Numba's
    compile events only, are removed (the ``"compiler"`` stage of
    :mod:`subtrace.runtime.numba_patches`; nothing where the patches are off)."""
    numba_patches.apply("compiler")
