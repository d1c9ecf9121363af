"""Helpers shared by the benchmark scripts."""

from __future__ import annotations

import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def import_subtrace():
    """The installed subtrace, or the source checkout's when it is not installed."""
    try:
        import subtrace
    except ModuleNotFoundError as exc:
        if exc.name != "subtrace":
            raise
        sys.path.insert(0, str(REPO / "src"))
        import subtrace
    return subtrace


def split_extra(argv):
    """``(own, extra)``: a script's arguments before ``--`` and those after it (passed on to
    ``subtrace render``), or all of them and none."""
    argv = list(argv)
    if "--" not in argv:
        return argv, []
    k = argv.index("--")
    return argv[:k], argv[k + 1:]
