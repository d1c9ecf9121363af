"""``python -m subtrace.cli``: the command line."""

from subtrace.cli.main import run

run()
