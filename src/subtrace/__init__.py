"""subtrace: ray tracing of exact Catmull-Clark and Loop subdivision surfaces.

Public API: :func:`load_cage`, :func:`make_cage`, :class:`Cage`, :class:`Mesh`,
:func:`compare_images` (from :mod:`subtrace.compare`, imported on first use: it loads
OpenImageIO), ``sweep(...)`` (:mod:`subtrace.sweep`, imported on first use, callable as
:func:`subtrace.sweep.sweep`), :func:`intersect_lines` (:mod:`subtrace.lines`, imported on
first use) and the error types in :mod:`subtrace.errors`.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

__version__ = "0.1.0"


def _numba_cache_dir() -> None:
    # Numba's on-disk cache only notices edits to the file of the cached function itself, not
    # to jitted helpers it calls from other modules. Keying the cache folder on a hash of the
    # package sources makes any change (or upgrade) start from a clean cache.
    if "NUMBA_CACHE_DIR" in os.environ:
        return
    root = Path(__file__).resolve().parent
    h = hashlib.sha1(__version__.encode())
    for p in sorted(root.rglob("*.py")):
        st = p.stat()
        h.update(f"{p.relative_to(root)}:{st.st_size}:{st.st_mtime_ns}".encode())
    base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "subtrace"
    folder = base / f"numba-{h.hexdigest()[:16]}"
    if not folder.exists():
        _prune(base)
    os.environ["NUMBA_CACHE_DIR"] = str(folder)


CACHES_KEPT = 8  # cache folders of other source versions kept (other checkouts, branches)


def _prune(base: Path) -> None:
    """Remove all but the ``CACHES_KEPT`` most recently used cache folders (each edit of the
    sources starts a new one)."""
    try:
        old = sorted(base.glob("numba-*"), key=lambda p: p.stat().st_mtime, reverse=True)
    except OSError:
        return
    import shutil

    for p in old[CACHES_KEPT:]:
        shutil.rmtree(p, ignore_errors=True)


_numba_cache_dir()

from .cage import Cage, Mesh, load_cage, make_cage  # noqa: E402
from .errors import ObjError, SceneError, SubtraceError, TopologyError  # noqa: E402


def __getattr__(name):
    # compare_images is imported on first use, so `import subtrace` does not load OpenImageIO
    if name == "compare_images":
        from .compare import compare_images

        return compare_images
    if name == "intersect_lines":
        # imported on first use: it loads the patch table and the line kernels
        from .lines import intersect_lines

        return intersect_lines
    if name == "sweep":
        # the module subtrace.sweep, which is callable as its function sweep(): once imported
        # a submodule is its package's attribute, so the name can only mean the module
        import importlib

        return importlib.import_module(".sweep", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "Cage",
    "Mesh",
    "load_cage",
    "make_cage",
    "compare_images",
    "sweep",
    "intersect_lines",
    "SubtraceError",
    "ObjError",
    "TopologyError",
    "SceneError",
    "__version__",
]
