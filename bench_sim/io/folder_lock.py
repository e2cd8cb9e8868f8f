"""One writer per output folder: an advisory lock held for the whole run.

A long run that writes its folder in place (``sweep``, ``dataset``) holds
:func:`folder_lock` on it from before it reads what the folder holds until its last file is
written. A second run on the same folder is refused at once, in one line naming the run that
holds it (command, process id, host, start time) - two runs never interleave their records.

How: ``fcntl.flock`` on a small lock file *beside* the folder, ``.NAME.lock`` (beside, not
inside, so that replacing the folder cannot drop the lock). The lock file holds the owner's
description as JSON, for the message. The kernel releases the lock when its process ends,
however it ends (SIGKILL, a power cut), so the lock of a dead run is stale by construction and
the next run simply takes it over; a run that ends normally removes the file. The removal and
the taking cannot race: a run that locked a file checks that the file is still the one at the
lock's path (same inode) and starts again otherwise.

The lock is advisory and machine-local as far as ``flock`` is: two runs on different machines
writing one network folder are not guaranteed to see each other's lock.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import socket
import stat
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from bench_sim.errors import BenchSimError
from bench_sim.io.interrupts import deferred_interrupts

try:
    import fcntl
except ImportError:  # pragma: no cover - not on POSIX
    fcntl = None  # type: ignore[assignment]

__all__ = ["FolderBusyError", "folder_lock", "lock_path", "lock_owner"]

#: Folders locked by this process: path -> depth (a nested lock of the same folder is free)
_HELD: dict[Path, int] = {}


class FolderBusyError(BenchSimError):
    """Another run holds the output folder's lock (the message names it)."""


class _AimedLock(BenchSimError):
    """The lock path is not a regular file of this user (a link, a FIFO, another user's file):
    it is never opened through, written or truncated."""

    def __init__(self, path: Path, why: str) -> None:
        super().__init__(f"{path}: the lock file is {why}; bench_sim never writes through it: remove it "
                         "if it is not yours, or choose another folder")


def lock_path(out: str | os.PathLike[str]) -> Path:
    """The lock file of output folder ``out``: ``.NAME.lock`` beside it."""
    out = Path(out)
    return out.parent / f".{out.name}.lock"


def lock_owner(out: str | os.PathLike[str]) -> dict[str, Any] | None:
    """The description the current (or last) owner wrote into ``out``'s lock file, if any."""
    try:
        return dict(json.loads(lock_path(out).read_text()))
    except (OSError, ValueError, TypeError):
        return None


def _describe(owner: dict[str, Any] | None) -> str:
    if not owner:
        return "another bench-sim run (just starting)"
    return (f"another bench-sim run ({owner.get('command', '?')}, pid {owner.get('pid', '?')} on "
            f"{owner.get('host', '?')}, started {owner.get('started', '?')})")


def _try_lock(path: Path) -> int | None:
    """Open and lock ``path``; the descriptor, ``None`` if the file was replaced meanwhile.
    Raises ``BlockingIOError`` when another process holds it."""
    try:  # never through a link, never blocking on a FIFO
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK, 0o644)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise _AimedLock(path, "a symbolic link") from None
        raise
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise _AimedLock(path, "not a regular file")
        if st.st_uid != os.getuid():
            raise _AimedLock(path, f"owned by another user (uid {st.st_uid})")
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        try:
            same = os.stat(path).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
    except BaseException:
        os.close(fd)
        raise
    if not same:  # its owner removed it between our open and our lock: take the new one
        os.close(fd)
        return None
    return fd


def _acquire(out: Path, command: str, what: str) -> int:
    path = lock_path(out)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        for _ in range(100):
            try:
                fd = _try_lock(path)
            except _AimedLock as exc:
                raise BenchSimError(f"{what} = {str(out)!r}: {exc}") from None
            except BlockingIOError:
                raise FolderBusyError(
                    f"{what} = {str(out)!r}: in use by {_describe(lock_owner(out))}; wait for it to end "
                    "or choose another folder"
                ) from None
            if fd is not None:
                break
        else:  # pragma: no cover - a lock file replaced a hundred times in a row
            raise FolderBusyError(f"{what} = {str(out)!r}: its lock file {path} keeps changing")
    except OSError as exc:
        if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN):  # pragma: no cover - other platforms
            raise FolderBusyError(f"{what} = {str(out)!r}: in use by {_describe(lock_owner(out))}") from None
        raise BenchSimError(
            f"{what} = {str(out)!r}: cannot create its lock file {path} ({exc.strerror})"
        ) from None
    owner = {"command": command, "pid": os.getpid(), "host": socket.gethostname(),
             "started": time.strftime("%Y-%m-%d %H:%M:%S %Z")}
    os.ftruncate(fd, 0)
    os.pwrite(fd, (json.dumps(owner) + "\n").encode(), 0)
    return fd


@contextlib.contextmanager
def folder_lock(out: str | os.PathLike[str], command: str, what: str = "--out") -> Iterator[Path]:
    """Hold the lock of output folder ``out`` for the block (see the module docstring).

    Parameters
    ----------
    out
        The output folder (it need not exist; its parent is made if missing).
    command
        What holds it (``sweep``, ``dataset``), for the message of a refused run.
    what
        The option that named ``out``, for messages.

    Raises
    ------
    FolderBusyError
        Another live process holds the lock: one line naming it.
    """
    out = Path(out).expanduser().resolve()
    if fcntl is None or out in _HELD:  # pragma: no cover - no flock; or nested in this process
        _HELD[out] = _HELD.get(out, 0) + 1
        try:
            yield out
        finally:
            _HELD[out] -= 1
            if not _HELD[out]:
                del _HELD[out]
        return
    made = [p for p in (out.parent, *out.parent.parents) if not p.exists()]  # made for the lock
    with deferred_interrupts():  # never a lock file taken but not yet owned
        fd = _acquire(out, command, what)
        _HELD[out] = 1
    try:
        yield out
    finally:
        with deferred_interrupts():
            del _HELD[out]
            with contextlib.suppress(OSError):
                lock_path(out).unlink()  # still ours: removed before it is released
            os.close(fd)
            for folder in made:  # a run refused before it wrote anything leaves no folder behind
                with contextlib.suppress(OSError):
                    folder.rmdir()
