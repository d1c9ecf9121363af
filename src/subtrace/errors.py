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
    """A bad scene file or command-line option.

    ``SceneError(message)`` alone is a plain error. A scene-file error also carries the
    ``path`` and 1-based ``line`` (None where unknown) and the ``key`` it concerns: a TOML key
    path such as ``camera.fov`` or ``object[0].mesh``, or a command-line option such as
    ``--fov``. The message reads ``path:line: key: problem``, leaving out what is unknown;
    ``problem`` holds the bare problem text.
    """

    def __init__(self, message: str, *, path=None, line: int | None = None, key=None):
        self.path = None if path is None else str(path)
        self.line = line
        self.key = None if key is None else str(key)
        self.problem = message
        where = ""
        if self.path is not None:
            where = f"{self.path}:{line}: " if line is not None else f"{self.path}: "
        what = f"{self.key}: " if self.key else ""
        super().__init__(f"{where}{what}{message}")


class SubtraceWarning(UserWarning):
    """Input subtrace can use but that deserves a note (an ignored OBJ statement, a missing MTL)."""
