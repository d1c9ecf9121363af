"""Profile: where a subtrace command spends its CPU time, kernels by name (Linux ``perf``).

    python benchmarks/profile_kernels.py [--top 25] [--freq 4000] [--keep DIR] -- render scene.toml -o out.exr

Numba's kernels run from memory the JIT mapped, which ``perf`` sees as anonymous code
("[JIT] tid ..."). This script runs the command in-process under ``perf record``; when it
ends, the child writes ``/tmp/perf-PID.map`` (perf's map of JIT symbols) with every
function the execution engine defined, from its address to the next one's. The table
is ``perf report``'s self time per symbol, Numba's mangled names shortened to their Python
path (``subtrace.trace.kernels._trace_task``); functions that LLVM inlined count towards
their caller. ``[k]`` rows are the kernel's (page zeroing is ``clear_page_erms``).

``--annotate NAME`` (e.g. ``_trace_task``) then breaks the kernel whose name ends in NAME
down by its machine code: the samples per ``--bucket`` bytes of the function (hottest first)
and the disassembly of the hottest buckets with the samples of each instruction. The code
is the cached object code of that kernel (the kernel cache's data file that defines the
symbol perf saw, disassembled by ``objdump``): Numba inlines most helpers into a kernel, so
this is where a kernel's time goes inside it.

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
    parser.add_argument("--annotate", metavar="NAME",
                        help="also break this kernel down by its machine code")
    parser.add_argument("--bucket", type=lambda v: int(v, 0), default=0x80,
                        help="bytes of machine code per row of --annotate (default 0x80)")
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
    code = 0
    if args.annotate and shutil.which("objdump") is None:
        print("profile_kernels: error: --annotate needs objdump (binutils)", file=sys.stderr)
        code = 2
    elif args.annotate:
        code = annotate(data, args.annotate, args.bucket)
    if args.keep is None:
        shutil.rmtree(folder, ignore_errors=True)
    return code


def annotate(data: Path, name: str, bucket: int, rows: int = 12, shown: int = 3) -> int:
    """Print the samples of the kernel whose short name ends in ``name`` per ``bucket``
    bytes of its machine code, and the hottest ``shown`` buckets' disassembly."""
    import collections

    script = subprocess.run(["perf", "script", "-i", str(data), "-F", "ip,sym,symoff"],
                            capture_output=True, text=True).stdout
    per_symbol = collections.defaultdict(collections.Counter)
    for line in script.splitlines():  # "ip symbol+0xoffset"
        symbol, _, offset = line.split()[-1].rpartition("+0x") if line.strip() else ("", "", "")
        if symbol and short_name(symbol).endswith(name):
            per_symbol[symbol][int(offset, 16)] += 1
    if not per_symbol:
        print(f"profile_kernels: error: no samples in a kernel named ...{name}", file=sys.stderr)
        return 2
    symbol, counts = max(per_symbol.items(), key=lambda kv: sum(kv[1].values()))
    lines = _disassembly(symbol)
    if lines is None:
        print(f"profile_kernels: error: no cached object code defines {short_name(symbol)}",
              file=sys.stderr)
        return 2
    total = sum(counts.values())
    buckets = collections.Counter()
    for offset, n in counts.items():
        buckets[offset // bucket * bucket] += n
    print(f"\n{short_name(symbol)}: {total} samples by {bucket:#x} bytes of machine code\n")
    print("| offset | samples | % | cumulative % |\n|---|---:|---:|---:|")
    done = 0
    for start, n in buckets.most_common(rows):
        done += n
        print(f"| {start:#06x} | {n} | {100 * n / total:.1f} | {100 * done / total:.1f} |")
    for start, _ in buckets.most_common(shown):
        print(f"\n{start:#06x} .. {start + bucket:#06x}:")
        for offset, text in lines:
            if start <= offset < start + bucket:
                print(f"{counts.get(offset, 0):6d}  {offset:6x}:  {text}")
    return 0


def _disassembly(symbol: str) -> list[tuple[int, str]] | None:
    """[(offset in the function, instruction)] of ``symbol``, disassembled from the kernel
    cache's data file that defines it (its object code, as the cache stores it), or None."""
    sys.path.insert(0, str(SRC))
    from subtrace.runtime.jit import KERNEL_DIR

    wanted = symbol.encode()
    for path in sorted(KERNEL_DIR.rglob("*.nbc"), key=lambda p: -p.stat().st_mtime):
        raw = path.read_bytes()
        start = raw.find(b"\x7fELF")
        if start < 0 or wanted not in raw:
            continue
        with tempfile.NamedTemporaryFile(suffix=".o") as obj:
            obj.write(raw[start:])
            obj.flush()
            listing = subprocess.run(["objdump", "-d", "--no-show-raw-insn",
                                      f"--disassemble={symbol}", obj.name],
                                     capture_output=True, text=True).stdout
        found = []
        base = None
        for line in listing.splitlines():
            if line.endswith(f"<{symbol}>:"):
                base = int(line.split()[0], 16)
            elif base is not None and ":\t" in line:
                address, _, text = line.partition(":\t")
                # (jump targets named by their offset in the function, not its long name)
                text = re.sub(r"<[^<>]*\+(0x[0-9a-f]+)>", r"<+\1>", text.strip())
                found.append((int(address.strip(), 16) - base, text))
        if found:
            return found
    return None


if __name__ == "__main__":
    if sys.argv[1:2] == ["--child"]:
        child(sys.argv[2:])
    sys.exit(main())
