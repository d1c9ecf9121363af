"""Numba for subtrace's kernels: the cache folder, the decorators, and a faster loader.

Numba reads ``NUMBA_CACHE_DIR`` when it is first imported, so every module with kernels
imports Numba from here (``from subtrace.runtime.jit import nb``): the first such import
sets the folder (unless the environment names one) and only then imports Numba. Importing
:mod:`subtrace` or its command line alone imports no Numba and sets nothing.
"""

from __future__ import annotations

import hashlib
import os
import sys
from pathlib import Path

from subtrace.version import VERSION


def _set_cache_dir() -> None:
    # Numba's on-disk cache only notices edits to the file of the cached function itself, not
    # to jitted helpers it calls from other modules. Keying the cache folder on a hash of the
    # package sources makes any change (or upgrade) start from a clean cache.
    if "NUMBA_CACHE_DIR" in os.environ:
        return
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha1(VERSION.encode())
    for p in sorted(root.rglob("*.py")):
        st = p.stat()
        h.update(f"{p.relative_to(root)}:{st.st_size}:{st.st_mtime_ns}".encode())
    base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "subtrace"
    folder = base / f"numba-{h.hexdigest()[:16]}"
    if not folder.exists():
        prune_caches(base)
    os.environ["NUMBA_CACHE_DIR"] = str(folder)


CACHES_KEPT = 8  # cache folders of other source versions kept (other checkouts, branches)


def prune_caches(base: Path) -> None:
    """Remove all but the ``CACHES_KEPT`` most recently used cache folders (each edit of the
    sources starts a new one)."""
    try:
        old = sorted(base.glob("numba-*"), key=lambda p: p.stat().st_mtime, reverse=True)
    except OSError:
        return
    import shutil

    for p in old[CACHES_KEPT:]:
        shutil.rmtree(p, ignore_errors=True)


_set_cache_dir()

import numba as nb  # noqa: E402  (after the cache folder is set)


def leaf_njit(fn):
    """Compile a helper of the per-ray path without Numba's reference counting (``_nrt=False``).

    A helper that takes arrays would otherwise count references to each array it is passed
    or views (an out-of-line atomic increment and decrement per array per call): about a
    quarter of the trace time. These helpers only read and write the arrays they are given,
    never allocate or keep them, so the counts are not needed. Division follows IEEE
    (``error_model="numpy"``: 1/0 is inf for axis-parallel rays, no check per division).
    """
    return nb.njit(cache=True, _nrt=False, error_model="numpy")(fn)


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

    Numbas whose loader is organised differently are left alone (the command is then just
    slower); tests run the command in fresh processes on warm and cold caches.
    """
    try:
        from numba.core.caching import Cache
        from numba.core.registry import cpu_target
        from numba.core.runtime import rtsys
    except ImportError:  # pragma: no cover - a Numba without these internal modules
        return
    if not all(hasattr(Cache, name) for name in ("_load_overload",
                                                   "_guard_against_spurious_io_errors")):
        return  # pragma: no cover - a Numba whose cache loader is organised differently

    def load_overload(self, sig, target_context):
        rtsys.initialize(target_context)  # idempotent; loaded code calls into the runtime
        with _without_scipy_linalg(), self._guard_against_spurious_io_errors():
            return self._load_overload(sig, target_context)
        # None (a miss: the kernel compiles) when the guard swallowed an I/O error

    context = cpu_target.target_context
    full_refresh = context.refresh

    def refresh():
        with _without_scipy_linalg():
            return full_refresh()

    Cache.load_overload = load_overload
    context.refresh = refresh


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
