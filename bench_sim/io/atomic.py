"""The atomic-write layer: one file written under a temporary name and renamed into place,
the temporaries' names, locks and clean-up, write failures as one line, and fault injection.

Temporaries are named ``.NAME.partial-PID-XXXX`` (a set moved aside: ``.NAME.old-PID-XXXX``);
a set's folder holds an ``flock`` while its run lives. A killed run's temporaries (``SIGKILL``
leaves them: unlocked, their process gone, or older than a minute with their process's number
reused) are removed by the next run writing there, and a set moved aside just before a kill is
put back.

A write that fails for want of room or permission (``ENOSPC``, ``EDQUOT``, ``EFBIG``, ``EROFS``,
``EACCES``, and the C writers' own reports of them) becomes one :class:`OutputWriteError` line;
the temporaries are removed first.

Fault injection (tests): ``BENCH_SIM_FAULT=KIND@POINT`` makes this process fail at ``POINT``:
``N`` (the N-th file written through :func:`atomic_path`, after its temporary file is written,
before the rename) or ``commit`` (an output set complete, its record written, before the
rename); ``KIND`` is ``enospc`` (raise ``OSError(ENOSPC)``), ``sigint``, ``sigterm`` or
``sigkill`` (the process signals itself).
"""

from __future__ import annotations

import contextlib
import errno
import glob
import os
import re
import shutil
import signal
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

from bench_sim.errors import BenchSimError

try:
    import fcntl
except ImportError:  # pragma: no cover - not on POSIX
    fcntl = None  # type: ignore[assignment]

__all__ = ["OutputWriteError", "WRITE_ERRNOS", "atomic_path", "umask", "write_failure"]


class OutputWriteError(BenchSimError):
    """An output that could not be written (no room, no permission): one line; nothing written."""


#: errno values of a write that fails for want of room or permission
WRITE_ERRNOS = frozenset(
    {errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EACCES, errno.EPERM, errno.EIO}
)
#: how the C writers (OpenEXR, HDF5/netCDF, ...) word the same failures
_WRITE_FAILURE_TEXTS = (
    "no space left", "file too large", "disk quota", "read-only file system", "permission denied",
    "failed to write", "hdf error", "write error", "input/output error", "requested and",
)
#: a temporary younger than this whose process is alive may not have taken its lock yet [s]
_LOCK_GRACE_S = 60.0


def umask() -> int:
    """The process's file-mode creation mask (read without changing it)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


# --- fault injection (see the module docstring) ---------------------------------------------------

_FILES_WRITTEN = 0
_FILES_LOCK = threading.Lock()


def _fault(point: str, path: Path) -> None:
    spec = os.environ.get("BENCH_SIM_FAULT", "")
    kind, _, at = spec.partition("@")
    if not spec or at != point:
        return
    if kind == "enospc":
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))
    sig = {"sigint": signal.SIGINT, "sigterm": signal.SIGTERM, "sigkill": signal.SIGKILL}.get(kind)
    if sig is not None:
        os.kill(os.getpid(), sig)
        time.sleep(1.0)  # the handler runs here (or the process is gone)


def _reset_file_count() -> None:
    """Start the count of the fault points ``N`` again (at the start of an output set)."""
    global _FILES_WRITTEN
    with _FILES_LOCK:
        _FILES_WRITTEN = 0


def _file_written(path: Path) -> None:
    global _FILES_WRITTEN
    with _FILES_LOCK:  # files may be written from a thread pool
        _FILES_WRITTEN += 1
        n = _FILES_WRITTEN
    _fault(str(n), path)


#: temporary folders of the output sets being written by this process (a write failure inside
#: one is reported by the set, naming its ``--out``)
_OPEN_SETS: list[Path] = []


def _in_open_set(path: Path) -> bool:
    return any(path.is_relative_to(t) for t in _OPEN_SETS)


# --- temporaries and their locks ---------------------------------------------------------------------


def _lock(fd: int) -> None:
    if fcntl is not None:
        with contextlib.suppress(OSError):
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _is_stale(path: Path, pid: int) -> bool:
    """Whether the temporary ``path`` of process ``pid`` was left by a dead run: nobody holds
    its lock (folders), and its process is gone or, if a process of that number lives, the
    temporary is older than the grace time."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return False
    try:
        if fcntl is not None and path.is_dir():  # a set's folder: its run holds the lock
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                return False  # its run holds the lock: alive
            fcntl.flock(fd, fcntl.LOCK_UN)
        if not _pid_alive(pid):
            return True
        return time.time() - os.fstat(fd).st_mtime > _LOCK_GRACE_S
    finally:
        os.close(fd)


def _temporaries(folder: Path, name: str) -> Iterator[tuple[Path, str, int]]:
    """``(path, kind, pid)`` of the temporaries of ``name`` in ``folder``."""
    try:
        entries = list(folder.glob(f".{glob.escape(name)}.*-*"))
    except OSError:
        return
    for cand in entries:
        parts = cand.name[len(name) + 2 :].split("-")
        if len(parts) >= 2 and parts[0] in ("partial", "old") and parts[1].isdigit():
            yield cand, parts[0], int(parts[1])


def _remove_stale_temporaries(out: Path) -> None:
    """Remove the temporaries of ``out`` (``.NAME.partial-PID-*`` / ``.NAME.old-PID-*`` beside
    it) left by killed runs. A set moved aside (``old``) while ``out`` is missing is put back."""
    for cand, kind, pid in _temporaries(out.parent, out.name):
        if not _is_stale(cand, pid):
            continue
        if kind == "old" and (cand / "set").is_dir() and not out.exists():
            with contextlib.suppress(OSError):
                os.replace(cand / "set", out)
        if cand.is_dir():
            shutil.rmtree(cand, ignore_errors=True)
        else:
            with contextlib.suppress(OSError):
                cand.unlink()


# --- write failures ---------------------------------------------------------------------------------


def _display_name(path: Path) -> str:
    """A file named for the user: relative to the output set it belongs to, without the
    temporary's ``.NAME.partial-PID-XXXX`` decoration."""
    inner = next((t for t in _OPEN_SETS if path.is_relative_to(t) and path != t), None)
    parts = list(path.relative_to(inner).parts if inner else [path.name])
    m = re.fullmatch(r"\.(.+)\.partial-\d+-.*", parts[-1])
    if m:
        parts[-1] = m.group(1)
    return str(Path(*parts))


def _failure_reason(exc: Exception, text: str, target: str | os.PathLike[str]) -> str:
    """The reason of a write failure told by its text (not its errno): the temporary's name
    replaced by the user's, shortened, and the disk's free space when it is full."""
    reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else text
    # the C writers quote the (temporary) file: name it as the user knows it
    reason = re.sub(r"/\S*\.partial-\d+-[^\s\"']*", lambda m: _display_name(Path(m.group(0))), reason)
    if len(reason) > 200:
        reason = reason[:80] + " ... " + reason[-115:]
    reason = reason or type(exc).__name__
    free = None
    with contextlib.suppress(OSError):
        p = Path(target)
        while not p.exists() and p != p.parent:
            p = p.parent
        free = shutil.disk_usage(p).free
    if free is not None and free < 1 << 20:
        reason += f"; the disk is full ({free} bytes free)"
    return reason


def write_failure(
    exc: BaseException, target: str | os.PathLike[str], what: str = "--out"
) -> OutputWriteError | None:
    """The one-line error for an exception raised while writing ``target``, if it is a write
    failure (no room, no permission, a file size limit); ``None`` for anything else."""
    if isinstance(exc, BenchSimError) or not isinstance(exc, Exception):
        return None
    code = exc.errno if isinstance(exc, OSError) else None
    text = " ".join(str(exc).split())
    if code in WRITE_ERRNOS:
        reason = f"{os.strerror(code)} ({errno.errorcode[code]})"
    elif isinstance(exc, OSError) or any(t in text.lower() for t in _WRITE_FAILURE_TEXTS):
        reason = _failure_reason(exc, text, target)
    else:
        return None
    name = f" {_display_name(Path(str(exc.filename)))}" if isinstance(exc, OSError) and exc.filename else ""
    return OutputWriteError(
        f"{what} = {str(target)!r}: cannot write the output{name}: {reason}; nothing was written "
        "(an earlier complete output there is kept)"
    )


# --- one file ----------------------------------------------------------------------------------------


def _make_parents(folder: Path) -> None:
    """Make ``folder`` and its missing parents, but never an output set's temporary folder
    (``.NAME.partial-...``): one that is missing was removed because its run was interrupted,
    and a step still writing on another thread (a pool's worker) must fail rather than make it
    again and leave it behind."""
    missing = []
    p = folder
    while not p.exists() and p != p.parent:
        missing.append(p)
        p = p.parent
    if any(".partial-" in m.name for m in missing):
        why = "its output set was removed (the run was interrupted)"
        raise FileNotFoundError(errno.ENOENT, why, str(folder))
    folder.mkdir(parents=True, exist_ok=True)


@contextlib.contextmanager
def _deferred_path(path: Path) -> Iterator[tuple[Path, Callable[[], None]]]:
    """A temporary beside ``path`` and a function that renames it into place; removed on exit
    unless committed. Files are not locked (writers such as HDF5 lock the files they write, and
    an flock held here would make them fail); a stale one is told by its dead process or age."""
    _make_parents(path.parent)
    _remove_stale_temporaries(path)
    prefix = f".{path.name}.partial-{os.getpid()}-"
    fd, tmp = tempfile.mkstemp(prefix=prefix, suffix=path.suffix, dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)

    def commit() -> None:
        os.chmod(tmp_path, 0o666 & ~umask())
        os.replace(tmp_path, path)

    try:
        yield tmp_path, commit
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    The temporary file (``.NAME.partial-PID-XXXX.SUFFIX``) keeps the destination's suffix (some
    writers choose the format from it). On any exception it is removed and ``path`` is left
    untouched; a write failure (no room, no permission) becomes an :class:`OutputWriteError`.
    """
    path = Path(path)
    try:
        with _deferred_path(path) as (tmp, commit):
            yield tmp
            _file_written(path)
            commit()
    except BaseException as exc:
        # inside an output set the set reports the failure, naming its --out
        failure = None if _in_open_set(path) else write_failure(exc, path, path.name)
        if failure is not None:
            raise failure from None
        raise
