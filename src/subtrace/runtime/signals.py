"""Interrupts: SIGINT and SIGTERM end a ``subtrace`` command at once, with one line, exit code
130 / 143, and no temporary or partial file left behind, whatever phase they land in.

A Python signal handler runs only on the main thread and only between bytecodes: while the
main thread is inside a Numba kernel, an OpenImageIO write or a thread join, it waits until
that returns (seconds, for a large trace chunk or image). So a process of its own
(:func:`install`, called first by :func:`subtrace.cli.main.run`) blocks both signals in
every thread and leaves them to one watcher thread that waits for them with ``sigwait``.
On a signal the watcher takes the lock that guards the temporaries, points the standard
error of the threads still running at /dev/null (the one line it prints at the end is the
command's output), removes every
temporary file still registered (:mod:`subtrace.runtime.atomic` registers each one when it
creates it and forgets it when it moves it into place or removes it), ends the child
processes registered here (the kernel compiler of :mod:`subtrace.startup.warmup`) and
every descendant (a local Dask cluster's workers), waits until they are gone, runs the
clean-ups registered here (:func:`register_cleanup`: a tiled Dask job's tiles, and what
the killed workers were writing), prints ``subtrace: interrupted`` and ends the process
with ``os._exit``. Holding the lock to the
end means no temporary can be created or moved into place after the clean-up: a
destination is either the complete earlier file or the complete new one.

A signal that lands while the interpreter itself starts, before any subtrace code runs
(tens of milliseconds), gets Python's own behaviour; nothing has been written by then.

In-process callers (tests, other programs calling :func:`subtrace.cli.main.main` or the
API) keep Python's usual KeyboardInterrupt; nothing here is installed for them, and
:mod:`subtrace.runtime.atomic` then removes its temporaries on the way out of its ``with``.
"""

from __future__ import annotations

import atexit
import os
import signal
import sys
import threading

EXIT_CODES = {signal.SIGINT: 130, signal.SIGTERM: 143}  # 128 + the signal's number
MESSAGE = b"subtrace: interrupted\n"

_lock = threading.RLock()  # held by the watcher from a signal to the process's end
_temps: set[str] = set()
_children: list = []
_cleanups: list = []
_state = {"installed": False}
# how long the watcher waits for the processes it killed to be gone before its clean-ups
_KILL_WAIT_S = 0.5


def temp_lock() -> threading.RLock:
    """The lock to hold while creating, moving or removing a temporary file (and registering
    or forgetting it), so the watcher never races a writer."""
    return _lock


def register_temp(path: str) -> None:
    """A temporary file now exists at ``path``: remove it if the process is interrupted.
    Call with :func:`temp_lock` held, around the file's creation."""
    _temps.add(path)


def forget_temp(path: str) -> None:
    """``path`` was moved into place or removed: nothing to clean up for it."""
    _temps.discard(path)


def register_child(proc) -> None:
    """End the child process ``proc`` (a ``subprocess.Popen``) if this one is interrupted."""
    with _lock:
        _children.append(proc)


def forget_child(proc) -> None:
    with _lock:
        if proc in _children:
            _children.remove(proc)


def register_cleanup(fn) -> None:
    """Call ``fn()`` if this process is interrupted, once its children and descendants are
    gone (nothing of theirs can write any more): files they leave that are no output."""
    with _lock:
        _cleanups.append(fn)


def forget_cleanup(fn) -> None:
    with _lock:
        if fn in _cleanups:
            _cleanups.remove(fn)


def is_running(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie (Linux's /proc; elsewhere:
    whether it exists)."""
    if os.path.isdir("/proc"):
        try:
            with open(f"/proc/{pid}/stat", "rb") as fh:
                stat = fh.read()
        except OSError:
            return False
        return stat[stat.rindex(b")") + 2:][:1] != b"Z"
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        pass
    return True


def install() -> None:
    """Hand SIGINT and SIGTERM to the watcher thread (module comment). Call before any other
    thread starts: threads inherit the blocked mask from the thread that starts them."""
    if _state["installed"]:
        return
    # a signal the parent set to be ignored (a background job of a script, nohup) stays so
    taken = {sig for sig in EXIT_CODES if signal.getsignal(sig) is not signal.SIG_IGN}
    if not taken:
        return
    signal.pthread_sigmask(signal.SIG_BLOCK, taken)
    threading.Thread(target=_watch, args=(taken,), name="subtrace-signals", daemon=True).start()
    _state["installed"] = True


def unblock() -> None:
    """Undo an inherited mask (a child process started by an installed one inherits it
    across ``exec``)."""
    signal.pthread_sigmask(signal.SIG_UNBLOCK, set(EXIT_CODES))


def _descendants(root: int) -> list[int]:
    """Process ids of every descendant of ``root`` (Linux's /proc; elsewhere none)."""
    try:
        names = os.listdir("/proc")
    except OSError:
        return []
    parent = {}
    for name in names:
        if name.isdigit():
            try:
                with open(f"/proc/{name}/stat", "rb") as fh:
                    stat = fh.read()
                parent[int(name)] = int(stat[stat.rindex(b")") + 2:].split()[1])
            except (OSError, ValueError, IndexError):
                pass
    out, todo = [], [root]
    while todo:
        p = todo.pop()
        kids = [c for c, pp in parent.items() if pp == p]
        out += kids
        todo += kids
    return out


def _watch(taken) -> None:
    sig = signal.sigwait(taken)
    _lock.acquire()  # never released: the process ends here
    # the other threads run on until the end: what they say now (a thread relaunching a
    # process killed below) is not the command's output, which is the one line at the end
    out = _quiet_stderr()
    for path in list(_temps):
        try:
            os.unlink(path)
        except OSError:
            pass
    for proc in _children:
        try:
            proc.kill()
        except OSError:
            pass
    killed = _descendants(os.getpid())  # (a local Dask cluster's worker processes)
    for pid in killed:
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass
    if _cleanups:
        _gone([p.pid for p in _children] + killed)
        for fn in _cleanups:
            try:
                fn()
            except Exception:  # noqa: BLE001 - (the process ends: the rest still run)
                pass
    try:
        os.write(out, MESSAGE)
    except OSError:
        pass
    os._exit(EXIT_CODES.get(sig, 128 + int(sig)))


def _quiet_stderr() -> int:
    """Point file descriptor 2 at /dev/null (for this process's threads and the children
    it starts from now on); returns a descriptor of the stderr it had (2 where that fails)."""
    try:
        out = os.dup(2)
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 2)
        os.close(null)
        return out
    except OSError:
        return 2


def _gone(pids) -> None:
    """Wait (up to ``_KILL_WAIT_S``) until the processes ``pids`` have ended, killing the
    descendants that appear meanwhile too (a thread of this process relaunching a helper
    process it lost)."""
    import time

    pids = set(pids)
    end = time.monotonic() + _KILL_WAIT_S
    while time.monotonic() < end:
        for pid in set(_descendants(os.getpid())) - pids:
            pids.add(pid)
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass
        if not any(is_running(p) for p in pids):
            break
        time.sleep(0.005)


def exit_now(code: int):
    """End the process with ``code`` once output is flushed and the exit handlers have run,
    skipping the interpreter's teardown of every module (Numba's typing registries alone
    take about 0.2 s to free). Everything written was closed before this point."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # closed or broken pipe: nothing more can be said
            pass
    atexit._run_exitfuncs()
    os._exit(code)


__all__ = ["install", "unblock", "temp_lock", "register_temp", "forget_temp",
           "register_child", "forget_child", "register_cleanup", "forget_cleanup",
           "is_running", "exit_now", "EXIT_CODES"]
