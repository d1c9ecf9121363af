"""Error types of subtrace.

Every failure a user can cause (a malformed file, a bad option, an impossible topology) is
raised as a :class:`SubtraceError` whose message names the file, the line and the problem,
so the command-line front end can print one line and exit with code 2.
"""

from __future__ import annotations


class SubtraceError(Exception):
    """Base class of every error subtrace raises on bad input."""


class ObjError(SubtraceError):
    """A malformed OBJ (or MTL) file: carries the path and the 1-based line number."""

    def __init__(self, path, line: int | None, problem: str):
        self.path = str(path)
        self.line = line
        self.problem = problem
        where = f"{self.path}:{line}" if line is not None else self.path
        super().__init__(f"{where}: {problem}")


class TopologyError(SubtraceError):
    """A cage whose topology subtrace cannot subdivide (e.g. a Loop cage with quads)."""

    def __init__(self, kind: str, message: str, path=None):
        self.kind = kind
        self.path = None if path is None else str(path)
        prefix = f"{self.path}: " if self.path else ""
        super().__init__(f"{prefix}{message}")


class SceneError(SubtraceError):
    """A bad scene file or command-line option."""


class SubtraceWarning(UserWarning):
    """Input subtrace can use but that deserves a note (an ignored OBJ statement, a missing MTL)."""
