"""What every ``subtrace`` command shares: the program name, one-line messages, and the
process-wide Numba shortcut a command may take when it runs as a process of its own.

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


def trim_numba(args) -> None:
    """Trim Numba's set-up (:func:`subtrace.runtime.jit.trim_loader`) in a process of its
    own (:func:`subtrace.cli.main.run`); in-process callers (tests) keep Numba as it is."""
    if getattr(args, "own_process", False):
        from subtrace.runtime.jit import trim_loader  # imports Numba: only for a command

        trim_loader()
