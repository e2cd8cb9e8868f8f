"""Output sets: the files of a command written as one, and the checks made before any work.

* :func:`output_set`: the files of a command, written into a temporary folder beside the output
  folder; the completion record (:data:`OUTPUT_MARKER`) is written last and the folder replaces
  the output folder whole (an atomic exchange where the file system has one), so a rerun never
  mixes old and new files and an interrupted run leaves the previous complete set or nothing.
* :func:`output_files`: the same for a few loose files (``bench-sim fuse``).
* :func:`check_output_dir`, :func:`check_output_file`, :func:`check_free_space`: refuse, before
  any computation, an output that cannot be written or would not fit.

Single files, temporaries, locks, write failures and fault injection:
:mod:`bench_sim.io.atomic`.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import os
import shutil
import tempfile
import time
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from bench_sim.errors import BenchSimError
from bench_sim.io.atomic import (
    _OPEN_SETS,
    OutputWriteError,
    _deferred_path,
    _fault,
    _lock,
    _remove_stale_temporaries,
    _reset_file_count,
    umask,
    write_failure,
)
from bench_sim.io.files import format_bytes, write_json
from bench_sim.io.images import carries_provenance
from bench_sim.io.interrupts import deferred_interrupts
from bench_sim.io.ownership import (
    OUTPUT_MARKER,
    entries,
    listed_files,
    read_output_record,
    refuse_foreign,
    remove_listed,
)

__all__ = [
    "OUTPUT_MARKER",
    "check_free_space",
    "check_output_dir",
    "check_output_file",
    "output_files",
    "output_set",
    "read_output_record",
]

_RENAME_EXCHANGE = 2


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths atomically (Linux ``renameat2(RENAME_EXCHANGE)``); ``False`` where the
    system or the file system has no such operation."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        return False
    at_fdcwd = -100
    rc = fn(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), _RENAME_EXCHANGE)
    if rc == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP, errno.EOPNOTSUPP):
        return False
    raise OSError(err, os.strerror(err), str(b))


def _nearest_existing(path: Path) -> Path:
    p = path
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def _probe_writable(folder: Path, what: str, out: Path) -> None:
    """Create and remove a temporary folder in ``folder`` (the real test: permissions, a
    read-only file system, no inodes left)."""
    try:
        probe = tempfile.mkdtemp(prefix=".bench-sim-probe-", dir=folder)
        os.rmdir(probe)
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise OutputWriteError(f"{what} = {str(out)!r}: cannot write in {folder} ({reason})") from None


def check_output_dir(out: str | os.PathLike[str], what: str = "--out") -> Path:
    """Check, before any computation, that ``out`` can receive an output set.

    Returns the resolved path. Raises :class:`BenchSimError` (one line) when ``out`` is a file,
    lies under a file, is a non-empty folder holding anything its bench_sim record does not list
    (:mod:`bench_sim.io.ownership`), is the current folder or one that holds it, or the folder
    that will hold it cannot be written.
    """
    given = str(out)
    if not given.strip():
        raise BenchSimError(f"{what} = {given!r}: empty; give a folder name")
    if "\x00" in given:
        raise BenchSimError(f"{what} = {given!r}: holds a NUL character")
    try:
        out = Path(out).expanduser().resolve()
    except (OSError, RuntimeError) as exc:
        raise BenchSimError(f"{what} = {given!r}: cannot resolve the path ({exc})") from None
    for anc in (out, *out.parents):
        if anc.exists():
            if not anc.is_dir():
                raise BenchSimError(f"{what} = {given!r}: {anc} is a file, not a folder")
            break
    if out == out.parent or Path.cwd().resolve().is_relative_to(out):
        raise BenchSimError(
            f"{what} = {given!r}: is the current folder or holds it (a rerun replaces the whole "
            "folder): choose a new folder"
        )
    if out.is_dir():
        try:
            busy = any(out.iterdir())
        except OSError as exc:
            raise BenchSimError(f"{what} = {given!r}: cannot list the folder ({exc.strerror})") from None
        if busy:
            refuse_foreign(out, what)
    _probe_writable(_nearest_existing(out.parent), what, out)
    return out


def check_output_file(
    path: str | os.PathLike[str], what: str, suffix: str, inputs: Sequence[Path] = ()
) -> Path:
    """Check, before any computation, that the file ``path`` (with ``suffix``) can be written:
    not a folder, not under a file, not one of ``inputs``, its folder writable, and not an
    existing file that bench_sim did not write (only a file carrying our provenance is replaced).
    Returns the absolute path."""
    given = str(path)
    p = Path(path).expanduser()
    if p.suffix.lower() != suffix:
        got = p.suffix or "no suffix"
        raise BenchSimError(f"{what} = {given}: must be a {suffix} file (got '{got}')")
    if p.is_dir():
        raise BenchSimError(f"{what} = {given}: is a directory; give a {suffix} file name")
    if p.resolve() in {q.resolve() for q in inputs}:
        raise BenchSimError(f"{what} = {given}: is one of the input files; choose another name")
    if p.is_symlink() or (p.exists() and not p.is_file()):
        raise BenchSimError(f"{what} = {given}: is a link or a special file; give a new {suffix} file name")
    if p.exists() and not carries_provenance(p):
        raise BenchSimError(
            f"{what} = {given}: exists and was not written by bench_sim (it carries no bench_sim "
            "provenance), so it is not overwritten: give a new file name"
        )
    parent = _nearest_existing(p.absolute().parent)
    if not parent.is_dir():
        raise BenchSimError(f"{what} = {given}: {parent} is not a directory")
    _probe_writable(parent, what, p)
    return p.absolute()


def _replace_set(tmp: Path, out: Path, what: str) -> None:
    """Put the complete set ``tmp`` in the place of ``out``: a rename where ``out`` is absent, an
    atomic exchange where the file system has one, else ``out`` moved aside (into a locked
    ``.NAME.old-PID-XXXX`` folder, put back by the next run if this one is killed) and two
    renames. ``out`` is checked once more first (an entry that appeared in it during the run is
    not ours: refused); of the previous set only the files its record lists are removed."""
    if not out.exists():
        os.replace(tmp, out)
        return
    if any(out.iterdir()):
        refuse_foreign(out, what)
    old_files = listed_files(out) or []
    if _exchange(tmp, out):
        left = remove_listed(tmp, old_files)  # tmp now holds the previous set
        if left:  # pragma: no cover - an entry added between the check and the exchange
            os.replace(tmp, out.with_name(f"{out.name}.kept-{os.getpid()}"))
        return
    old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-{os.getpid()}-", dir=out.parent))
    old_fd = os.open(old, os.O_RDONLY)
    _lock(old_fd)
    try:
        os.replace(out, old / "set")
        os.replace(tmp, out)
        if remove_listed(old / "set", old_files):  # pragma: no cover - as above
            os.replace(old / "set", out.with_name(f"{out.name}.kept-{os.getpid()}"))
        shutil.rmtree(old, ignore_errors=True)
    finally:
        os.close(old_fd)


def _remove_temporary(tmp: Path, tries: int = 20, pause_s: float = 0.05) -> None:
    """Remove an output set's temporary folder; again a moment later while it is still there (a
    step on another thread, cut short by Ctrl-C in this one, may still be writing a file into
    it: the removal then finds the folder not empty)."""
    for _ in range(tries):
        shutil.rmtree(tmp, ignore_errors=True)
        if not tmp.exists():
            return
        time.sleep(pause_s)


@contextlib.contextmanager
def output_set(
    out: str | os.PathLike[str], record: Mapping[str, Any] | None = None, what: str = "--out"
) -> Iterator[Path]:
    """Write a set of output files as one: yield a temporary folder, rename it onto ``out``.

    The folder is created beside ``out`` (same file system) as ``.NAME.partial-PID-XXXX`` and
    locked while this run lives. When the block completes, :data:`OUTPUT_MARKER` (``record`` as
    JSON) is written last and the folder replaces ``out`` whole (an atomic exchange where the
    file system has one): files of an earlier run never mix with the new ones. On any exception
    (Ctrl-C included) the temporary folder is removed and ``out`` keeps its previous complete set
    (or stays absent); a write failure (no room, no permission) becomes an
    :class:`OutputWriteError`. Temporaries of killed runs are removed by the next run.

    Parameters
    ----------
    out
        Destination folder. It must not exist, be empty, or hold an earlier bench_sim output
        set (see :func:`check_output_dir`).
    record
        Content of the completion record (command, version, ...). No wall-clock times in it, so
        two runs with the same config and seed give identical files.
    what
        Name of the option or argument for error messages.
    """
    out = check_output_dir(out, what)
    with deferred_interrupts():  # Ctrl-C here would leave a temporary nobody removes
        try:
            out.parent.mkdir(parents=True, exist_ok=True)
            _remove_stale_temporaries(out)
            tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-{os.getpid()}-", dir=out.parent))
        except OSError as exc:
            raise OutputWriteError(
                f"{what} = {str(out)!r}: cannot create a folder there ({exc.strerror})"
            ) from None
        fd = os.open(tmp, os.O_RDONLY)
        _lock(fd)
        _reset_file_count()  # fault points count the files of this set
        _OPEN_SETS.append(tmp)
    try:
        yield tmp
        write_json(tmp / OUTPUT_MARKER, {**dict(record or {}), "files": entries(tmp)})
        _fault("commit", out)
        os.chmod(tmp, 0o777 & ~umask())  # mkdtemp creates 0700
        _replace_set(tmp, out, what)
    except BaseException as exc:
        with deferred_interrupts():  # a second Ctrl-C must not cut the clean-up short
            _remove_temporary(tmp)
        failure = write_failure(exc, out, what)
        if failure is not None:
            raise failure from None
        raise
    finally:
        _OPEN_SETS.remove(tmp)
        os.close(fd)


@contextlib.contextmanager
def output_files(
    paths: Sequence[str | os.PathLike[str]], what: Sequence[str] = ("--out", "--tra")
) -> Iterator[list[Path]]:
    """Write a few loose output files as one set: yield a temporary path beside each (same
    suffix), rename them all into place when the block completes. On any exception every
    temporary is removed and no destination is touched; a write failure becomes an
    :class:`OutputWriteError` naming the option (``what``, one per path) of the file that failed."""
    dests = [Path(p) for p in paths]
    _reset_file_count()
    with contextlib.ExitStack() as stack:
        tmps = [stack.enter_context(_deferred_path(d)) for d in dests]
        _OPEN_SETS.extend(t for t, _ in tmps)
        try:
            yield [t for t, _ in tmps]
        except BaseException as exc:
            fname = Path(str(getattr(exc, "filename", None) or ""))
            k = next((i for i, (t, _) in enumerate(tmps) if fname in (t, dests[i])), 0)
            failure = write_failure(exc, dests[k], what[k] if k < len(what) else "output")
            if failure is not None:
                raise failure from None
            raise
        finally:
            for t, _ in tmps:
                _OPEN_SETS.remove(t)
        for _, commit in tmps:
            commit()


def check_free_space(
    out: str | os.PathLike[str], needed_bytes: int, what: str = "--out", detail: str = ""
) -> int:
    """Refuse, before any computation, an output that would not fit on its file system.

    ``needed_bytes`` is the caller's estimate of what it will write under ``out`` (an upper
    bound: e.g. uncompressed array sizes). Raises :class:`BenchSimError` (one line) when it
    exceeds the free space of the file system holding ``out`` (or its nearest existing parent);
    returns the free bytes otherwise. ``detail`` (e.g. ``"16 samples x 3.5 MiB"``) is shown in
    the message.
    """
    out = Path(out).expanduser().resolve()
    anc = out
    while not anc.exists():
        anc = anc.parent
    free = shutil.disk_usage(anc).free
    if needed_bytes > free:
        how = f" ({detail})" if detail else ""
        raise BenchSimError(
            f"{what} = {str(out)!r}: needs about {format_bytes(needed_bytes)}{how} but its file system "
            f"has {format_bytes(free)} free: free space, choose another disk or make less"
        )
    return int(free)
