"""Launcher for the subtrace command line from a source checkout: ``python cli.py render``.

Runs the sources in ``src/`` next to this file, even where another subtrace is installed.
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent / "src"))

from subtrace.cli import run  # noqa: E402

run()
