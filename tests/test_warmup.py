"""``subtrace warmup`` says how far it is: a line after each of its commands (done / total,
kernels in the cache, seconds), and one at least every HEARTBEAT_S while a command runs.

The commands are replaced by cheap ones (``subtrace --version``, and a sleep for the
heartbeat), run in child processes exactly as the real warm-up runs its chains."""

from __future__ import annotations

import re

import pytest

from subtrace.cli import main
from subtrace.cli import warmup
from subtrace.cli.warmup import progress_line

LINE = re.compile(r"warmup: (\d+)/(\d+) commands done, (\d+) kernels in the cache, (\d+) s")


def test_progress_line_says_done_total_kernels_and_seconds():
    line = progress_line(3, 13, 87, 41.4)
    assert line == "warmup: 3/13 commands done, 87 kernels in the cache, 41 s"
    assert LINE.fullmatch(line)


def _version_stages(folder):
    """Two stages: one chain of two commands, then two chains of one side by side."""
    version = ["--version"]
    return [[[version, version]], [[version], [version]]]


def test_warmup_prints_a_line_per_command(monkeypatch, capsys):
    monkeypatch.setattr(warmup, "_stages", _version_stages)
    assert main(["warmup", "--jobs", "2"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("kernel cache: ")
    progress = [LINE.fullmatch(line) for line in out[1:-1]]
    assert all(progress), out
    done = [int(m.group(1)) for m in progress]
    assert done == [1, 2, 3, 4]  # one line per command, in order, none lost
    assert {int(m.group(2)) for m in progress} == {4}
    seconds = [int(m.group(4)) for m in progress]
    assert seconds == sorted(seconds)
    assert re.fullmatch(r"\d+ kernels, [0-9.]+ MB: .*", out[-1])


def test_warmup_quiet_prints_nothing(monkeypatch, capsys):
    monkeypatch.setattr(warmup, "_stages", _version_stages)
    assert main(["warmup", "--quiet"]) == 0
    assert capsys.readouterr().out == ""


def test_a_long_command_gets_heartbeat_lines(monkeypatch):
    """A command that runs longer than HEARTBEAT_S is not silent: lines with the count so far
    come between, each within about a heartbeat of the one before."""
    import subprocess
    import sys
    import tempfile

    monkeypatch.setattr(warmup, "HEARTBEAT_S", 0.2)
    monkeypatch.setattr(warmup, "_stages", lambda folder: [[[["slow"]]]])

    def sleeper(chain):  # a chain's process that takes 1.2 s over its one command
        proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(1.2); "
                                 "print('done', flush=True)"], stdout=subprocess.PIPE,
                                bufsize=0)
        proc.errors = tempfile.TemporaryFile(mode="w+")
        return proc

    monkeypatch.setattr(warmup, "_start_chain", sleeper)
    calls = []
    warmup.compile_all(1, lambda done, total, seconds: calls.append((done, total, seconds)))
    assert calls[-1][:2] == (1, 1)
    assert sum(1 for c in calls if c[:2] == (0, 1)) >= 3  # said while the command ran
    gaps = [b[2] - a[2] for a, b in zip(calls, calls[1:])]
    assert max(gaps) < 0.2 + 0.5, gaps  # (0.5: a busy machine's scheduling)


def test_a_failing_command_names_its_error(monkeypatch):
    from subtrace.errors import SubtraceError

    monkeypatch.setattr(warmup, "_stages",
                        lambda folder: [[[["info", str(folder / "missing.obj")]]]])
    with pytest.raises(SubtraceError, match="missing.obj"):
        warmup.compile_all(1)
