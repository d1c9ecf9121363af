"""A one-line progress bar for the command line (shown only on a terminal)."""

from __future__ import annotations

import sys


class ProgressBar:
    """A one-line progress bar on ``stream`` (default stderr), redrawn in place; called as
    ``bar(done, total, label)``. Ends its line when done == total."""

    WIDTH = 30

    def __init__(self, stream=None):
        self.stream = stream or sys.stderr

    def __call__(self, done: int, total: int, label: str) -> None:
        filled = self.WIDTH * done // max(total, 1)
        bar = "#" * filled + "." * (self.WIDTH - filled)
        end = "\n" if done >= total else ""
        self.stream.write(f"\r[{bar}] {done}/{total} {label}\033[K{end}")
        self.stream.flush()
