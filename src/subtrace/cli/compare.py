"""``subtrace compare A.exr B.exr``: compare two renders channel group by channel group
(:func:`subtrace.compare.compare_images`), exit code by idiff's convention: 0 pass,
1 warning, 2 failure (or bad options), 3 size or channel mismatch, 4 an unreadable file."""

from __future__ import annotations

import json
import os
import sys

from subtrace.cli.common import PROG, one_line
from subtrace.cli.parser import THRESHOLD_OPTIONS
from subtrace.compare import (EXIT_MISMATCH, EXIT_UNREADABLE, GROUPS, ImageMismatchError,
                              UnreadableImageError, compare_images)
from subtrace.errors import SubtraceError
from subtrace.runtime.atomic import check_writable


def execute(args) -> int:
    """Compare, print the table (or JSON), write the difference image; the exit code."""
    thresholds = thresholds_of(args)
    png = None
    if args.png:
        if not args.diff:
            raise SubtraceError("--png writes the heat map of --diff: give --diff OUT.exr too")
        png = os.path.splitext(args.diff)[0] + ".png"
    if args.diff:
        check_writable(args.diff)
        if png:
            check_writable(png)
            check_writable(os.path.splitext(png)[0] + "_ids.png")
    if args.html:
        check_writable(args.html)
    try:
        result = compare_images(args.image_a, args.image_b, thresholds, flip=not args.no_flip,
                                aliases=aliases_of(args), groups=groups_of(args))
    except (UnreadableImageError, ImageMismatchError) as exc:
        print(f"{PROG}: error: {one_line(str(exc))}", file=sys.stderr)
        return EXIT_UNREADABLE if isinstance(exc, UnreadableImageError) else EXIT_MISMATCH
    pngs = result.write_diff(args.diff, png_path=png) if args.diff else []
    if args.html:
        from subtrace.htmlreport import compare_page, write_page

        name = os.path.basename(args.image_a)
        write_page(args.html, compare_page([{"name": name, "comparison": result,
                                             "a": args.image_a, "b": args.image_b}]))
    if args.json:
        report = {"a": args.image_a, "b": args.image_b, **result.as_dict()}
        if args.diff:
            report["diff"] = args.diff
        if pngs:
            report["heat_map"] = pngs[0]
            if len(pngs) > 1:
                report["ids_map"] = pngs[1]
        if args.html:
            report["html"] = args.html
        print(json.dumps(report, indent=2))
    else:
        print(f"A: {args.image_a}\nB: {args.image_b}")
        print(result.table())
        if args.diff:
            print(f"difference: {args.diff}" + (f", heat map: {pngs[0]}" if pngs else "")
                  + (f", ids map: {pngs[1]}" if len(pngs) > 1 else ""))
        if args.html:
            print(f"report: {args.html}")
    return result.exit_code


def aliases_of(args) -> dict:
    """--channels OURS=THEIRS values as {ours: theirs}; SubtraceError naming a bad one."""
    aliases = {}
    for text in getattr(args, "channels", None) or []:
        ours, eq, theirs = text.partition("=")
        if not eq or not ours.strip() or not theirs.strip():
            raise SubtraceError(f"--channels {text}: expected OURS=THEIRS, e.g. N=Normal")
        aliases[ours.strip()] = theirs.strip()
    return aliases


def groups_of(args):
    """The groups --only keeps (default all) less those --ignore names; SubtraceError
    naming the option for an unknown group or when none is left."""
    for option in ("only", "ignore"):
        for g in getattr(args, option, None) or []:
            if g not in GROUPS:
                raise SubtraceError(f"--{option} {g}: unknown channel group: use one of "
                                    f"{', '.join(GROUPS)}")
    keep = [g for g in (args.only or GROUPS) if g not in (args.ignore or [])]
    if not keep:
        raise SubtraceError("--only / --ignore leave no channel group to compare")
    return keep


def thresholds_of(args) -> dict:
    """--fail/--warn/... values as {group: {field: value}}; a bare value is the colour
    group's. Raises SubtraceError naming the option for a bad group or number."""
    thresholds: dict = {}
    for name in THRESHOLD_OPTIONS:
        for text in getattr(args, name):
            group, _, value = text.rpartition("=")
            group = group.strip() or "colour"
            if group not in GROUPS:
                raise SubtraceError(
                    f"--{name} {text}: unknown channel group {group!r}: use one of "
                    f"{', '.join(GROUPS)}"
                )
            try:
                number = float(value)
            except ValueError:
                number = float("nan")
            if not number >= 0:  # also NaN
                raise SubtraceError(f"--{name} {text}: expected a number >= 0, got {value!r}")
            thresholds.setdefault(group, {})[name] = number
    return thresholds
