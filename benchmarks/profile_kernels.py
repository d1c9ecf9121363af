"""Profile: where a subtrace command spends its CPU time, kernels by name (Linux ``perf``).

    python benchmarks/profile_kernels.py [--top 25] [--freq 4000] [--keep DIR] -- render scene.toml -o out.exr

Numba's kernels run from memory the JIT mapped, which ``perf`` sees as anonymous code
("[JIT] tid ..."). This script runs the command in-process under ``perf record``; when it
ends, the child writes ``/tmp/perf-PID.map`` (perf's map of JIT symbols) with every
function the execution engine defined, from its address to the next one's. The table
is ``perf report``'s self time per symbol, Numba's mangled names shortened to their Python
path (``subtrace.trace.kernels._trace_task``); functions that LLVM inlined count towards
their caller. ``[k]`` rows are the kernel's (page zeroing is ``clear_page_erms``).

The kernel cache must be warm (a render of the same scene first), or the table is mostly
the compiler. ``--keep DIR`` keeps ``perf.data`` there for ``perf report -i DIR/perf.data``
(while the map file is still in /tmp). Needs ``perf`` (``apt install linux-perf`` or the
distribution's ``linux-tools``) and permission to sample (``kernel.perf_event_paranoid``
at most 2, or root).
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

SRC = Path(__file__).resolve().parent.parent / "src"


def child(argv: list[str]) -> None:
    """Run the command here, then write the JIT map for perf and exit with its code."""
    sys.path.insert(0, str(SRC))
    from subtrace.cli.main import main

    code = main(argv, own_process=True)
    from numba.core.registry import cpu_target

    engine = cpu_target.target_context.codegen()._engine
    found = []
    for name in engine._defined_symbols:
        try:
            address = engine._ee.get_function_address(name)
        except (RuntimeError, ValueError):
            continue
        if address:
            found.append((address, name))
    found.sort()
    with open(f"/tmp/perf-{os.getpid()}.map", "w") as out:
        for k, (address, name) in enumerate(found):
            size = found[k + 1][0] - address if k + 1 < len(found) else 1 << 16
            out.write(f"{address:x} {min(size, 1 << 20):x} {name}\n")
    sys.stdout.flush()
    os._exit(code)


def short_name(symbol: str) -> str:
    """``_ZN8subtrace5trace7kernels11_trace_taskB2v6B52...`` -> ``subtrace.trace.kernels._trace_task``
    (the nested name's parts up to Numba's ABI tags); other names as they are."""
    if not symbol.startswith("_ZN"):
        return symbol
    parts, k = [], 3
    while k < len(symbol) and symbol[k].isdigit():
        m = re.match(r"\d+", symbol[k:])
        n = int(m.group())
        k += len(m.group())
        parts.append(symbol[k:k + n])
        k += n
    return ".".join(parts) or symbol


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--top", type=int, default=25, help="rows of the table")
    parser.add_argument("--freq", type=int, default=4000, help="samples a second")
    parser.add_argument("--keep", type=Path, help="keep perf.data in this folder")
    parser.add_argument("command", nargs=argparse.REMAINDER,
                        help="-- then the subtrace command line (render ...)")
    args = parser.parse_args()
    command = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not command:
        parser.error("give a subtrace command after --, e.g. -- render scenes/spot.toml -o x.exr")
    if shutil.which("perf") is None:
        print("profile_kernels: error: perf is not installed (linux-perf / linux-tools)",
              file=sys.stderr)
        return 2
    folder = args.keep or Path(tempfile.mkdtemp(prefix="subtrace-perf-"))
    folder.mkdir(parents=True, exist_ok=True)
    data = folder / "perf.data"
    record = subprocess.run(["perf", "record", "-q", "-F", str(args.freq), "-o", str(data),
                             sys.executable, __file__, "--child", *command])
    if record.returncode != 0:
        print(f"profile_kernels: error: the command or perf failed (exit {record.returncode})",
              file=sys.stderr)
        return 2
    report = subprocess.run(["perf", "report", "-i", str(data), "--no-children", "--sort",
                             "sym", "-g", "none", "--stdio"], capture_output=True, text=True)
    rows = []
    for line in report.stdout.splitlines():
        m = re.match(r"\s*([\d.]+)%\s+\[(.)\]\s+(\S+)", line)
        if m:
            rows.append((float(m.group(1)), m.group(2), short_name(m.group(3))))
    print(f"subtrace {' '.join(command)}: self time by symbol ({args.freq} samples/s, "
          f"perf report)\n")
    print("| % of samples | where | symbol |\n|---:|---|---|")
    for share, where, name in rows[:args.top]:
        print(f"| {share:.1f} | {'kernel' if where == 'k' else 'user'} | `{name}` |")
    if args.keep is None:
        shutil.rmtree(folder, ignore_errors=True)
    return 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["--child"]:
        child(sys.argv[2:])
    sys.exit(main())
