"""Error types of subtrace, and how a value a user gave is shown in a message.

Every failure a user can cause (a malformed file, a bad option, an impossible topology) is
raised as a :class:`SubtraceError` whose message names the file, the line and the problem,
so the command-line front end can print one line and exit with code 2.
"""

from __future__ import annotations

from enum import Enum


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


class NurbsError(SubtraceError):
    """A free-form surface or trimming curve that cannot be used (a bad knot vector, a
    non-positive weight, an open trim loop). The message is the bare problem; the OBJ reader,
    which knows the statement's line, re-raises it as an :class:`ObjError`."""


class TopologyKind(str, Enum):
    """What is wrong with a cage's topology (:attr:`TopologyError.kind`). A str enum, so a
    kind also equals its name as text (``err.kind == "scheme"``)."""

    EMPTY = "empty"  # no faces
    FACE = "face"  # a face with fewer than 3 vertices, or face sizes not matching the indices
    INDEX = "index"  # a face index out of range
    POINTS = "points"  # a vertex coordinate that is not finite
    SCHEME = "scheme"  # an unknown scheme, or a Loop cage with faces other than triangles
    UV = "uv"  # UVs (face-varying data) that do not fit the faces, or an unknown mode

    def __str__(self) -> str:
        return self.value


class TopologyError(SubtraceError):
    """A cage whose topology subtrace cannot subdivide (e.g. a Loop cage with quads).

    kind: a :class:`TopologyKind` (or its text, which is converted; an unknown one is a
    ValueError, a programming error)."""

    def __init__(self, kind: TopologyKind | str, message: str, path=None):
        self.kind = TopologyKind(kind)
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


def show_value(value) -> str:
    """A value from a scene file or an option as an error message shows it: TOML's spelling
    (``true``, ``[1, 2]``, ``'text'``), ``a table`` for a table."""
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(show_value(v) for v in value) + "]"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, dict):
        return "a table"
    return str(value)
