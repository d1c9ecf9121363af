"""``subtrace sweep SCENE ... --tolerances T ... -o DIR``: an angular-tolerance sweep
(:func:`subtrace.sweep.sweep`); the table on stdout, a progress bar on stderr when it is a
terminal."""

from __future__ import annotations

import os
import sys

from subtrace.cli.common import set_up_numba
from subtrace.cli.render import scene_from_inputs
from subtrace.runtime.progress import ProgressBar
from subtrace.sweep import check_reference, check_repeat, check_tolerances, format_table, sweep


def execute(args) -> int:
    """Check the options, sweep, print the table."""
    tols = check_tolerances(args.tolerances, key="--tolerances")
    reference = check_reference(args.reference_tolerance, tols, key="--reference-tolerance")
    repeat = check_repeat(args.repeat, key="--repeat")
    scenes = [scene_from_inputs([path], args) for path in args.inputs] or [
        scene_from_inputs([], args)]
    progress = ProgressBar() if sys.stderr.isatty() and not args.quiet else None
    set_up_numba(args)
    records = sweep(scenes, tols, reference_tolerance=reference, repeat=repeat,
                    output_dir=args.output, threads=args.threads, accel=args.accel,
                    progress=progress)
    if not args.quiet:
        print(format_table(records))
        print(f"wrote {os.path.join(args.output, 'sweep.csv')}, sweep.json, plots and images "
              f"in {args.output}")
    return 0
