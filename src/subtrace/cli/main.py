"""The ``subtrace`` process: :func:`main` parses the command line and runs the command,
:func:`run` is the process entry point (``cli.py``, ``python -m subtrace.cli``, the
``subtrace`` script).

Owns the error policy (design invariant 7): every :class:`subtrace.errors.SubtraceError`
becomes one line ``subtrace: error: <message>`` on stderr and exit code 2, with no
traceback; argparse usage errors exit 2 as well (:mod:`subtrace.cli.parser`); an interrupt
is one line ``subtrace: interrupted`` and exit code 130 (SIGINT) or 143 (SIGTERM). ``compare``
follows idiff's exit codes instead: 3 for a size or channel mismatch, 4 for an image that
cannot be read (and 0 / 1 / 2 for pass / warning / failure). A SubtraceWarning is shown as
one line ``subtrace: warning: <message>``.

Each command lives in ``subtrace.cli.<command>`` and is imported only when it runs, so
``subtrace --help`` and ``--version`` load neither numpy nor Numba nor OpenImageIO.
:func:`run` trims three fixed costs of a short process that :func:`main`, which tests call
in-process, leaves alone: Numba's loader (:func:`subtrace.cli.common.set_up_numba`, taken by
the commands), the cyclic collector's passes over old objects, and the interpreter's
teardown (:func:`subtrace.runtime.signals.exit_now`).
"""

from __future__ import annotations

import gc
import importlib
import os
import sys
import warnings

from subtrace.cli.common import PROG, one_line
from subtrace.cli.parser import build_parser
from subtrace.errors import SubtraceError, SubtraceWarning

OLD_COLLECTIONS_EVERY = 1000  # young (middle) collections between middle (full) ones


def run(argv=None):
    """Run the command line as the whole process: :func:`main`, then exit with its code.
    SIGINT and SIGTERM end it at once with one line and exit code 130 / 143, leaving no
    temporary file (:mod:`subtrace.runtime.signals`)."""
    from subtrace.runtime import signals  # standard library only: start-up stays fast

    # numpy's BLAS on one thread: subtrace's own threads do the heavy work, and BLAS
    # workers that a small matrix product wakes spin on the cores for a while after it
    # (the isolation's maps, patches/stencil.py: the trace that followed them took 0.116
    # s on Spot with two BLAS threads, 0.090 s with one); set before numpy is imported
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    os.environ.setdefault("MKL_NUM_THREADS", "1")
    signals.install()
    # The cyclic collector keeps collecting the young generation (short-lived cycles), but
    # the older ones only every 1000 young collections: importing Numba and loading kernels
    # made 15 middle and one full collection of a million long-lived objects, 0.045-0.06 s
    # of a render process (0.017 s left, gc.callbacks timings on spot and gen_vase_loop).
    gc.set_threshold(gc.get_threshold()[0], OLD_COLLECTIONS_EVERY, OLD_COLLECTIONS_EVERY)
    signals.exit_now(main(argv, own_process=True))


def main(argv=None, own_process: bool = False) -> int:
    """Run the command line; returns the exit code (0 ok, 2 bad input or usage).

    own_process: this process exists only to run this command (:func:`run`), so the
    process-wide shortcut of :func:`subtrace.cli.common.set_up_numba` is allowed.
    """
    parser = build_parser()
    try:
        args, extra = parser.parse_known_args(argv)
        if extra:  # name the subcommand whose options these are not
            sub = parser.commands.get(getattr(args, "command", None))
            (sub or parser).error("unrecognized arguments: " + " ".join(extra))
    except SystemExit as exc:  # --help / --version exit 0, usage errors exit 2
        return int(exc.code or 0) if not isinstance(exc.code, str) else 2
    args.own_process = own_process
    try:
        with _OneLineWarnings():
            command = importlib.import_module(f"subtrace.cli.{args.command}")
            return command.execute(args)
    except SubtraceError as exc:
        print(f"{PROG}: error: {one_line(str(exc))}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # `subtrace info | head`: stop quietly (Python docs' recipe)
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        except (OSError, ValueError):
            pass
        return 1


class _OneLineWarnings:
    """Show a SubtraceWarning as ``subtrace: warning: <message>`` (one line, no source)."""

    def __enter__(self):
        # every warning of every command is said, even one a previous command in the same
        # process said already (Python's default shows a message once per place)
        self._filters = warnings.catch_warnings()
        self._filters.__enter__()
        warnings.simplefilter("always", SubtraceWarning)
        self._saved = warnings.showwarning
        saved = self._saved

        def show(message, category, filename, lineno, file=None, line=None):
            if issubclass(category, SubtraceWarning):
                print(f"{PROG}: warning: {one_line(str(message))}", file=file or sys.stderr)
            else:
                saved(message, category, filename, lineno, file, line)

        warnings.showwarning = show
        return self

    def __exit__(self, *exc):
        warnings.showwarning = self._saved
        self._filters.__exit__(*exc)
        return False


if __name__ == "__main__":  # python -m subtrace.cli.main
    run()
