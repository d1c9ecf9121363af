"""subtrace: ray tracing of exact Catmull-Clark and Loop subdivision surfaces.

Public API, each name imported on first use (``import subtrace`` imports neither Numba nor
OpenImageIO and sets no environment variable):

* :func:`load_cage`, :func:`make_cage`, :class:`Cage`, :class:`Mesh` (:mod:`subtrace.mesh.cage`);
* :func:`compare_images` (:mod:`subtrace.compare`);
* ``sweep(...)``: the module :mod:`subtrace.sweep`, callable as :func:`subtrace.sweep.sweep`;
* :func:`intersect_lines` (:mod:`subtrace.lines.api`);
* :func:`render_frames` (:mod:`subtrace.frames`), :class:`FrameResult`
  (:mod:`subtrace.jobs`): frames, tiles, resume, Dask;
* the error types of :mod:`subtrace.errors` (and :class:`TopologyKind`, what a
  TopologyError is about).
"""

from __future__ import annotations

import importlib

from subtrace.version import VERSION as __version__

_LAZY = {
    "Cage": "subtrace.mesh.cage",
    "Mesh": "subtrace.mesh.cage",
    "load_cage": "subtrace.mesh.cage",
    "make_cage": "subtrace.mesh.cage",
    "compare_images": "subtrace.compare",
    "intersect_lines": "subtrace.lines.api",
    "render_frames": "subtrace.frames",
    "FrameResult": "subtrace.jobs",
    "SubtraceError": "subtrace.errors",
    "ObjError": "subtrace.errors",
    "TopologyError": "subtrace.errors",
    "TopologyKind": "subtrace.errors",
    "SceneError": "subtrace.errors",
}


def __getattr__(name):
    if name == "sweep":
        # the module subtrace.sweep, which is callable as its function sweep(): once imported
        # a submodule is its package's attribute, so the name can only mean the module
        return importlib.import_module("subtrace.sweep")
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted([*globals(), *_LAZY, "sweep"])


__all__ = [*_LAZY, "sweep", "__version__"]
