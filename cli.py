"""Thin launcher for the subtrace command line: ``python cli.py info [CAGE.obj]``.

Uses the installed package when there is one, else the sources in ``src/`` next to this file.
"""

import sys
from pathlib import Path

try:
    import subtrace.cli  # noqa: F401
except ModuleNotFoundError as exc:
    if exc.name != "subtrace":
        raise
    sys.path.insert(0, str(Path(__file__).resolve().parent / "src"))

from subtrace.cli import run

run()
