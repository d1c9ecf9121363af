"""The one way subtrace writes a file: to a hidden temporary in the destination folder, then
``os.replace`` onto the destination (design invariant 7).

A failure at any point (an error, an interrupt: any BaseException) removes the temporaries
and leaves an existing destination untouched, so no half-written file is ever seen.
:func:`atomic_paths` hands out temporary *paths* (for writers that open files by name, such
as OpenImageIO) and moves them all into place at the end; :func:`write_text` writes a string.
Failures raise :class:`subtrace.errors.SubtraceError` naming the destination.

Every temporary is registered with :mod:`subtrace.runtime.signals` while it exists, and is
created, opened by its writer (:func:`open_temp`), moved and removed under its lock: an
interrupted command removes what is left and never sees a temporary appear or move after
that.

Two processes writing one destination at once each write their own temporary (the names
carry the process id and a random part) and each moves it into place; the rename is
atomic, so the destination is always one complete file, the one renamed last, and both
commands succeed.
"""

from __future__ import annotations

import os
import secrets
from contextlib import contextmanager

from subtrace.errors import SubtraceError
from subtrace.runtime.signals import forget_temp, register_temp, temp_lock

TEMP_ATTEMPTS = 100  # names tried before giving up on a free temporary name


def path_str(path) -> str:
    """``path`` (str, bytes or path-like) as str."""
    path = os.fspath(path)
    return os.fsdecode(path) if isinstance(path, bytes) else path


def reason(err: OSError) -> str:
    """The short reason of an OSError for a message: ``permission denied`` or its strerror."""
    if isinstance(err, PermissionError):
        return "permission denied"
    return err.strerror or str(err)


def make_temp(path) -> str:
    """Create an empty hidden temporary beside ``path`` (mode 0666 less the umask); returns
    its path. Raises SubtraceError naming ``path`` when the folder is missing, ``path`` is a
    directory, or the folder cannot be written."""
    target = path_str(path)
    folder, name = os.path.split(os.path.abspath(target))
    if os.path.isdir(target):
        raise SubtraceError(f"{target}: is a directory, expected a file name")
    if not os.path.isdir(folder):
        what = "is not a directory" if os.path.exists(folder) else "does not exist"
        raise SubtraceError(
            f"{target}: cannot write the file: the folder {folder} {what}; create it first"
        )
    for _ in range(TEMP_ATTEMPTS):
        temp = os.path.join(folder, f".{name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
        try:
            with temp_lock():
                fd = os.open(temp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
                register_temp(temp)
        except FileExistsError:
            continue
        except OSError as err:
            raise SubtraceError(f"{target}: cannot write the file: {reason(err)}") from None
        os.close(fd)
        return temp
    raise SubtraceError(f"{target}: cannot create a temporary file in {folder}")


def orphaned_temps(path) -> list[str]:
    """The temporaries of :func:`make_temp` for ``path`` whose process is gone (a Dask
    worker killed while it wrote a tile or a frame): left behind, as no writer will move
    or remove them. A live process's temporary (another command writing ``path``) is not
    among them."""
    from subtrace.runtime.signals import is_running

    folder, name = os.path.split(os.path.abspath(path_str(path)))
    head = f".{name}."
    try:
        names = os.listdir(folder)
    except OSError:
        return []
    out = []
    for entry in names:
        pid = entry[len(head):].split(".")[0] if entry.startswith(head) else ""
        if entry.endswith(".tmp") and pid.isdigit() and not is_running(int(pid)):
            out.append(os.path.join(folder, entry))
    return out


def remove_temp(temp: str) -> None:
    """Remove the temporary ``temp`` (from :func:`make_temp`), if it is still there."""
    with temp_lock():
        try:
            os.unlink(temp)
        except OSError:
            pass
        forget_temp(temp)


def check_writable(path) -> None:
    """Raise SubtraceError now if ``path`` cannot be written (missing folder, a directory,
    no permission), so that a long job fails before it starts. Leaves nothing behind."""
    remove_temp(make_temp(path))


@contextmanager
def atomic_paths(paths):
    """Yield a temporary path for each of ``paths`` (all created first, so a bad folder fails
    before anything is written); when the block ends normally move each into place, in
    order. On any failure, and for temporaries not moved, remove them."""
    temps: list[str | None] = []
    try:
        for path in paths:
            temps.append(make_temp(path))
        yield list(temps)
        for k, path in enumerate(paths):
            try:
                with temp_lock():
                    os.replace(temps[k], path_str(path))
                    forget_temp(temps[k])
            except OSError as err:
                raise SubtraceError(
                    f"{path_str(path)}: cannot write the file: {reason(err)}"
                ) from None
            temps[k] = None
    finally:
        for temp in temps:
            if temp is not None:
                remove_temp(temp)


def open_temp(temp: str, mode: str = "wb", **kwargs):
    """``open(temp, mode)`` under the temporaries' lock: an interrupt's clean-up holds it
    from the signal on, so a writer never creates a temporary again after the clean-up
    removed it (a writer that opens files by name does the same: ``io/exr.py``)."""
    with temp_lock():
        return open(temp, mode, **kwargs)


def write_text(path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` through a temporary (module comment)."""
    _write(path, text, "w", encoding="utf-8")


def write_bytes(path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary (module comment)."""
    _write(path, data, "wb")


def _write(path, data, mode: str, **kwargs) -> None:
    with atomic_paths([path]) as (temp,):
        try:
            with open_temp(temp, mode, **kwargs) as fh:
                fh.write(data)
        except OSError as err:
            raise SubtraceError(
                f"{path_str(path)}: cannot write the file: {reason(err)}") from None


__all__ = ["atomic_paths", "write_text", "write_bytes", "check_writable", "make_temp", "remove_temp", "path_str", "reason"]
