"""``subtrace sweep SCENE ... --tolerances T ... -o DIR [--html REPORT.html]``: an
angular-tolerance sweep (:func:`subtrace.sweep.sweep`); the table on stdout, a progress bar on
stderr when it is a terminal, and with --html one self-contained page of the table, plots and
level heat maps (:func:`subtrace.htmlreport.sweep_page`)."""

from __future__ import annotations

import os
import sys

from subtrace.cli.common import set_up_numba
from subtrace.cli.render import scene_from_inputs
from subtrace.runtime.atomic import check_writable
from subtrace.runtime.progress import ProgressBar
from subtrace.sweep import check_reference, check_repeat, check_tolerances, format_table, sweep


def execute(args) -> int:
    """Check the options, sweep, print the table."""
    tols = check_tolerances(args.tolerances, key="--tolerances")
    reference = check_reference(args.reference_tolerance, tols, key="--reference-tolerance")
    repeat = check_repeat(args.repeat, key="--repeat")
    scenes = [scene_from_inputs([path], args) for path in args.inputs] or [
        scene_from_inputs([], args)]
    html = getattr(args, "html", None)
    # a page in DIR itself is checked once the sweep has made DIR
    if html and os.path.dirname(os.path.abspath(html)) != os.path.abspath(args.output):
        check_writable(html)
    progress = ProgressBar() if sys.stderr.isatty() and not args.quiet else None
    set_up_numba(args)
    records = sweep(scenes, tols, reference_tolerance=reference, repeat=repeat,
                    output_dir=args.output, threads=args.threads, accel=args.accel,
                    progress=progress)
    if html:
        from subtrace.htmlreport import sweep_page, write_page

        write_page(html, sweep_page(records, args.output))
    if not args.quiet:
        print(format_table(records))
        print(f"wrote {os.path.join(args.output, 'sweep.csv')}, sweep.json, plots and images "
              f"in {args.output}" + (f"; report: {html}" if html else ""))
    return 0
