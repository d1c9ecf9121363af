"""What every ``subtrace`` command shares: the program name, one-line messages, and the
Numba set-up of a command (the process-wide shortcut a command may take when it runs as a
process of its own, the first-run notice).

Imports nothing beyond the standard library, so that parsing stays fast.
"""

from __future__ import annotations

PROG = "subtrace"


def one_line(text: str) -> str:
    """``text`` on one line: its non-blank lines stripped and joined by spaces."""
    return " ".join(part.strip() for part in text.splitlines() if part.strip())


def boundary_code(args):
    """The ``--boundary`` option as OpenSubdiv's code (``subtrace.io.obj.BOUNDARY_*``), or
    None when not given (the OBJ's tag applies)."""
    name = getattr(args, "boundary", None)
    if name is None:
        return None
    from subtrace.io.scene import BOUNDARIES

    return BOUNDARIES[name]


def set_up_numba(args) -> None:
    """Numba for a command: in a process of its own (:func:`subtrace.cli.main.run`) its
    set-up is trimmed (:func:`subtrace.runtime.jit.trim_loader`; in-process callers, tests,
    keep Numba as it is); unless ``--quiet``, a terminal hears once that the kernels are
    compiling when the cache lacks them (:func:`subtrace.runtime.jit.notify_compiles`)."""
    import sys

    from subtrace.runtime import jit  # imports Numba: only for a command

    if getattr(args, "own_process", False):
        jit.trim_loader()
    if not getattr(args, "quiet", False):
        jit.notify_compiles(sys.stderr)
