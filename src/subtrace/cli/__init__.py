"""The ``subtrace`` command line: :func:`run` is the process entry point."""

from subtrace.cli.main import main, run

__all__ = ["main", "run"]
