"""A render command's kernels read ahead, on a thread of their own.

A command that finds its kernels in the cache still loads each one when it is first called:
about 1-2 ms a kernel (its index and data read and unpickled, its object code linked into
the process by LLVM), twenty-odd kernels in a render, one after another on the thread that
renders: about 35 of the 160 ms of a small cage's render (osd_catmark_nonquads), 45 of the
sword's 250.

Here the render command remembers which kernels it asked for, with their signatures, in
the order it asked (a *manifest*, kept beside the kernels in :data:`jit.KERNEL_DIR` per kind
of render: :func:`render_key`), and the next render of that kind starts a thread that reads
them from the cache in that order while the render reads its cages and builds its tables.
A kernel is still installed only where the render calls it: Numba's dispatcher asks its
cache (``jit.trim_loader``'s loader, ``runtime.numba_patches``), which hands over what the
thread read (``numba_patches.READ_AHEAD``) instead of reading it again; one the thread has
not reached yet is read by the render as before (Numba's compiler lock keeps the two from
reading at once). So the manifest lists
what the render asked for, not what was read ahead, and a kernel a render no longer uses
drops out of it. Reading holds Python's lock while it unpickles (about 60 % of a read), so
the thread overlaps the render only where the render runs kernels that let go of that lock
(``nogil``) or the thread is inside LLVM: the sword's render 0.207 -> 0.195 s, while a cage
so small that its render is all Python gains nothing (BENCHMARKS.md, Cycles "Latest run").
The kernels are Numba's own, read by its own loader, so the images are the same bit for
bit.

What a manifest lists is only ever read from the cache, never compiled (a kernel missing
from the cache is left to the render, which compiles it as before). A manifest that cannot
be read is ignored and written again; at most :data:`MANIFESTS_KEPT` are kept. Where
``jit.trim_loader`` is not applied (Numba's internals unpatched: ``runtime.numba_patches``;
a process that is not a command's own), nothing is read ahead.
"""

from __future__ import annotations

import hashlib
import os
import pickle
import sys
import threading
from contextlib import contextmanager

from subtrace.runtime import numba_patches

MANIFESTS_KEPT = 32  # manifests kept per cache folder (kinds of render), least recent removed

# The loader's ledger (``runtime.numba_patches``, which appends to the one and takes from the
# other): the kernels this process's dispatchers took from the cache, in order, as (module,
# qualname, signature); the compile results read ahead and not yet taken, (python function,
# signature) -> result. Its reader, lock and the manifests' folder are
# ``numba_patches.LOADER``'s, empty where ``jit.trim_loader`` is not applied.
LOADED: list = numba_patches.LOADED
_READ_AHEAD: dict = numba_patches.READ_AHEAD


def render_key(scene, *options) -> str:
    """The kind of render whose kernels a manifest lists: the scene's cages (files, scheme,
    boundary, USD prim and time: the cage's arrays, and so the kernels' signatures), what
    adds passes (shadows, ambient occlusion, extra samples, a ground) and ``options`` (the
    command's acceleration, how the image is written, ...). Not the camera, the colours or
    the tolerance, which change no kernel."""
    render = scene.render
    what = ([(o.mesh, o.scheme, o.boundary, o.prim, o.time) for o in scene.objects],
            bool(scene.lights) and render.shadows, render.ao > 0, (render.samples or 1) > 1,
            scene.ground is not None, options)
    return hashlib.blake2b(repr(what).encode(), digest_size=12).hexdigest()


def _manifest_path(key: str):
    return numba_patches.LOADER["folder"] / f"{key}.pkl"


def _read_manifest(key: str) -> list | None:
    """The manifest of ``key``: a list of (module, qualname, signature), or None (none, or
    unreadable)."""
    try:
        items = pickle.loads(_manifest_path(key).read_bytes())
    except Exception:  # noqa: BLE001 - absent, partial or foreign: none
        return None
    if not isinstance(items, list) or not all(
            isinstance(i, tuple) and len(i) == 3 for i in items):
        return None
    return items


def _write_manifest(key: str, items: list) -> None:
    """Store ``items`` as the manifest of ``key`` (atomically); keep the
    :data:`MANIFESTS_KEPT` most recent manifests. Failures are silent: it only speeds up
    the next render."""
    from subtrace.errors import SubtraceError
    from subtrace.runtime.atomic import write_bytes

    path = _manifest_path(key)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_bytes(path, pickle.dumps(items, protocol=4))
        old = sorted(path.parent.glob("*.pkl"), key=lambda p: p.stat().st_mtime, reverse=True)
        for p in old[MANIFESTS_KEPT:]:
            p.unlink(missing_ok=True)
    except (OSError, pickle.PicklingError, SubtraceError):
        pass


def _dispatcher(module: str, qualname: str):
    """The kernel ``module.qualname`` when its module is imported and it is a cached
    dispatcher of Numba's; else None."""
    obj = sys.modules.get(module)
    for part in qualname.split("."):
        obj = getattr(obj, part, None)
    if getattr(obj, "_cache", None) is None or not hasattr(obj, "overloads"):
        return None
    return obj


def read_ahead(dispatcher, sig) -> bool:
    """Read ``dispatcher``'s compile result for the argument types ``sig`` from the cache
    and keep it for the loader to take (``numba_patches.READ_AHEAD``), unless the
    dispatcher has that overload or it was read already; never compile. True when it is
    there afterwards."""
    sig = tuple(sig)
    func = dispatcher.py_func
    with numba_patches.LOADER["lock"]:
        if dispatcher.overloads.get(sig) is not None or (func, sig) in _READ_AHEAD:
            return True
        cres = numba_patches.LOADER["read"](dispatcher._cache, sig, dispatcher.targetctx)
        if cres is None:
            return False
        _READ_AHEAD[(func, sig)] = cres
        return True


class Preloader:
    """The thread reading a manifest's kernels ahead (:func:`start`); :meth:`finish` stops
    it and stores what this process's dispatchers took as the manifest when that changed."""

    def __init__(self, key: str):
        self.key = key
        self.items = None  # the manifest read (None: none)
        self.read = 0  # kernels the thread read
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True,
                                        name="subtrace-preload")
        self._thread.start()

    def _run(self):
        self.items = _read_manifest(self.key)
        for module, qualname, sig in self.items or ():
            if self._stop.is_set():
                return
            dispatcher = _dispatcher(module, qualname)
            try:
                if dispatcher is not None and read_ahead(dispatcher, sig):
                    self.read += 1
            except Exception:  # noqa: BLE001 - left to the render, which reads it as before
                pass

    def finish(self, store: bool = True) -> None:
        """Stop reading (after the kernel being read) and, with ``store``, keep what this
        process's dispatchers took as the manifest when it differs from the one read."""
        self._stop.set()
        self._thread.join()
        if store and LOADED and LOADED != self.items:
            _write_manifest(self.key, list(LOADED))


def start(key: str) -> Preloader | None:
    """Start reading the kernels of ``key``'s manifest ahead on a thread of their own; None
    where ``jit.trim_loader`` is not applied (or ``SUBTRACE_NO_PRELOAD`` is set)."""
    if "read" not in numba_patches.LOADER or os.environ.get("SUBTRACE_NO_PRELOAD"):
        return None
    return Preloader(key)


@contextmanager
def loading(key: str):
    """The block (a render) with ``key``'s kernels read ahead (:func:`start`); on leaving
    it normally, what the dispatchers took is kept as ``key``'s manifest where it changed.
    An error or interrupt stops the thread and keeps nothing."""
    loader = start(key)
    try:
        yield loader
    except BaseException:
        if loader is not None:
            loader.finish(store=False)
        raise
    if loader is not None:
        loader.finish()
