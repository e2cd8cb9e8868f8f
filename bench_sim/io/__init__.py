"""File input/output with metadata: atomic writes, output sets, EXR, TIFF, PNG, NPY, JSON, CSV,
text and EMVA 1288 descriptor files.

Every file carries its provenance in one format (the dict of
:func:`bench_sim.runtime.provenance.provenance`: ``version``, ``seed``, ``config_sha256``,
``config``): as a JSON attribute (EXR header, TIFF ImageDescription, PNG ``tEXt`` chunk
``bench_sim``), as ``#`` comment lines (CSV, EMVA descriptors), or as keys (JSON).

Writing
-------
* :func:`atomic_path`: one file, written under a temporary name beside it and renamed into place
  when complete.
* :func:`output_set`: the files of a command, written into a temporary folder beside the output
  folder; the completion record (:data:`OUTPUT_MARKER`) is written last and the folder replaces
  the output folder whole (an atomic exchange where the file system has one), so a rerun never
  mixes old and new files and an interrupted run leaves the previous complete set or nothing.
* :func:`output_files`: the same for a few loose files (``bench-sim fuse``).

A write that fails for want of room or permission (``ENOSPC``, ``EDQUOT``, ``EFBIG``, ``EROFS``,
``EACCES``, and the C writers' own reports of them) becomes one :class:`OutputWriteError` line;
the temporaries are removed first. Temporaries are named ``.NAME.partial-PID-XXXX``; a set's
folder holds an ``flock`` while its run lives. A killed run's temporaries (``SIGKILL`` leaves
them: unlocked, their process gone, or older than a minute with their process's number reused)
are removed by the next run writing there, and a set moved aside just before a kill is put back.

Fault injection (tests): ``BENCH_SIM_FAULT=KIND@POINT`` makes this process fail at ``POINT``:
``N`` (the N-th file written through :func:`atomic_path`, after its temporary file is written,
before the rename) or ``commit`` (an output set complete, its record written, before the
rename); ``KIND`` is ``enospc`` (raise ``OSError(ENOSPC)``), ``sigint``, ``sigterm`` or
``sigkill`` (the process signals itself).
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import glob
import hashlib
import json
import os
import re
import shutil
import signal
import tempfile
import threading
import time
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.errors import BenchSimError

try:
    import fcntl
except ImportError:  # pragma: no cover - not on POSIX
    fcntl = None  # type: ignore[assignment]

__all__ = [
    "atomic_path",
    "sha256_file",
    "output_set",
    "output_files",
    "check_output_dir",
    "check_output_file",
    "check_free_space",
    "format_bytes",
    "read_output_record",
    "write_failure",
    "OutputWriteError",
    "OUTPUT_MARKER",
    "write_json",
    "read_json",
    "write_exr",
    "read_exr",
    "write_tiff16",
    "write_png",
    "write_figure_png",
    "read_png_text",
    "write_text",
    "write_csv",
    "write_emva_descriptor",
    "read_image",
    "image_shape",
    "sha256_text",
    "ImageReadError",
]


class ImageReadError(BenchSimError):
    """An input image file that cannot be read or is not of a supported kind."""


class OutputWriteError(BenchSimError):
    """An output that could not be written (no room, no permission): one line; nothing written."""


#: File written last into every output folder made by :func:`output_set`; its presence marks a
#: complete set, and only folders holding it (or empty ones) are ever replaced by a rerun.
OUTPUT_MARKER = ".bench-sim-output.json"

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

# --- fault injection (see the module docstring) ---------------------------------------------------

_FILES_WRITTEN = 0


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


_FILES_LOCK = threading.Lock()


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


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _display_name(path: Path) -> str:
    """A file named for the user: relative to the output set it belongs to, without the
    temporary's ``.NAME.partial-PID-XXXX`` decoration."""
    inner = next((t for t in _OPEN_SETS if path.is_relative_to(t) and path != t), None)
    parts = list(path.relative_to(inner).parts if inner else [path.name])
    m = re.fullmatch(r"\.(.+)\.partial-\d+-.*", parts[-1])
    if m:
        parts[-1] = m.group(1)
    return str(Path(*parts))


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
    else:
        return None
    name = f" {_display_name(Path(str(exc.filename)))}" if isinstance(exc, OSError) and exc.filename else ""
    return OutputWriteError(
        f"{what} = {str(target)!r}: cannot write the output{name}: {reason}; nothing was written "
        "(an earlier complete output there is kept)"
    )


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


#: files whose provenance marks a folder written by a bench_sim older than the completion record
_LEGACY_RECORDS = ("metrics.json", "meta.json", "ptc_results.json")


def _written_by_bench_sim(out: Path) -> bool:
    """``out`` holds a bench_sim output set: its completion record, or (sets written before the
    record existed) a JSON file carrying bench_sim's provenance."""
    if (out / OUTPUT_MARKER).is_file():
        return True
    for name in _LEGACY_RECORDS:
        try:
            data = json.loads((out / name).read_text())
        except (OSError, ValueError):
            continue
        if isinstance(data, dict) and {"version", "config_sha256"} <= data.keys():
            return True
    return False


def check_output_dir(out: str | os.PathLike[str], what: str = "--out") -> Path:
    """Check, before any computation, that ``out`` can receive an output set.

    Returns the resolved path. Raises :class:`BenchSimError` (one line) when ``out`` is a file,
    lies under a file, is a non-empty folder that bench_sim did not write, is the current folder
    or one that holds it, or the folder that will hold it cannot be written.
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
        if busy and not _written_by_bench_sim(out):
            raise BenchSimError(
                f"{what} = {given!r}: folder exists, is not empty and was not written by bench_sim "
                "(a rerun replaces the whole folder): choose a new or empty folder"
            )
    _probe_writable(_nearest_existing(out.parent), what, out)
    return out


def check_output_file(path: str | os.PathLike[str], what: str, suffix: str) -> Path:
    """Check, before any computation, that the file ``path`` (with ``suffix``) can be written:
    not a folder, not under a file, its folder writable. Returns the absolute path."""
    given = str(path)
    p = Path(path).expanduser()
    if p.suffix.lower() != suffix:
        got = p.suffix or "no suffix"
        raise BenchSimError(f"{what} = {given}: must be a {suffix} file (got '{got}')")
    if p.is_dir():
        raise BenchSimError(f"{what} = {given}: is a directory; give a {suffix} file name")
    parent = _nearest_existing(p.absolute().parent)
    if not parent.is_dir():
        raise BenchSimError(f"{what} = {given}: {parent} is not a directory")
    _probe_writable(parent, what, p)
    return p.absolute()


def read_output_record(out: str | os.PathLike[str]) -> dict[str, Any] | None:
    """The completion record of the output set in ``out``; ``None`` if ``out`` holds no complete
    set (readers of a folder written in place check it before trusting the files)."""
    try:
        data = json.loads((Path(out) / OUTPUT_MARKER).read_text())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


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
    global _FILES_WRITTEN
    _FILES_WRITTEN = 0  # fault points count the files of this set
    _OPEN_SETS.append(tmp)
    try:
        yield tmp
        write_json(tmp / OUTPUT_MARKER, dict(record or {}))
        _fault("commit", out)
        os.chmod(tmp, 0o777 & ~_umask())  # mkdtemp creates 0700
        if not out.exists():
            os.replace(tmp, out)
        elif _exchange(tmp, out):
            shutil.rmtree(tmp, ignore_errors=True)  # tmp now holds the previous set
        else:
            old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-{os.getpid()}-", dir=out.parent))
            old_fd = os.open(old, os.O_RDONLY)
            _lock(old_fd)
            try:
                os.replace(out, old / "set")
                os.replace(tmp, out)
                shutil.rmtree(old, ignore_errors=True)
            finally:
                os.close(old_fd)
    except BaseException as exc:
        shutil.rmtree(tmp, ignore_errors=True)
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
    global _FILES_WRITTEN
    _FILES_WRITTEN = 0
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


@contextlib.contextmanager
def _deferred_path(path: Path) -> Iterator[tuple[Path, Any]]:
    """A temporary beside ``path`` and a function that renames it into place; removed on exit
    unless committed. Files are not locked (writers such as HDF5 lock the files they write, and
    an flock held here would make them fail); a stale one is told by its dead process or age."""
    path.parent.mkdir(parents=True, exist_ok=True)
    _remove_stale_temporaries(path)
    prefix = f".{path.name}.partial-{os.getpid()}-"
    fd, tmp = tempfile.mkstemp(prefix=prefix, suffix=path.suffix, dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)

    def commit() -> None:
        os.chmod(tmp_path, 0o666 & ~_umask())
        os.replace(tmp_path, path)

    try:
        yield tmp_path, commit
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()


def format_bytes(n: float) -> str:
    """``n`` bytes for a message: ``'512 B'``, ``'3.4 MiB'``, ``'2.1 TiB'`` (binary prefixes)."""
    n = float(n)
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} EiB"  # pragma: no cover - unreachable


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


def sha256_text(text: str) -> str:
    """SHA-256 hex digest of a UTF-8 string."""
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def write_json(path: str | os.PathLike[str], data: Mapping[str, Any]) -> Path:
    """Write ``data`` as indented, key-sorted JSON, atomically."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(data, indent=2, sort_keys=True, default=_json_default) + "\n")
    return path


def read_json(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read a JSON file."""
    return json.loads(Path(path).read_text())


def write_exr(
    path: str | os.PathLike[str],
    channels: Mapping[str, np.ndarray],
    metadata: Mapping[str, Any] | None = None,
) -> Path:
    """Write 2-D float32 channels of equal shape to one OpenEXR file (ZIP compression).

    Parameters
    ----------
    path
        Destination ``.exr`` file.
    channels
        Channel name to 2-D array (height, width); stored as 32-bit float.
    metadata
        Stored as the header attribute ``bench_sim`` (a JSON string): config, seed, version, units.
    """
    import OpenEXR

    path = Path(path)
    shapes = {np.asarray(a).shape for a in channels.values()}
    if len(shapes) != 1 or len(next(iter(shapes))) != 2:
        raise ValueError(f"EXR channels must be 2-D arrays of one shape, got {sorted(shapes)}")
    header: dict[str, Any] = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    if metadata is not None:
        header["bench_sim"] = json.dumps(metadata, sort_keys=True, default=_json_default)
    chans = {
        name: np.ascontiguousarray(np.asarray(arr, dtype=np.float32))
        for name, arr in channels.items()
    }
    with atomic_path(path) as tmp, OpenEXR.File(header, chans) as f:
        f.write(str(tmp))
    return path


def read_exr(path: str | os.PathLike[str]) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Read an OpenEXR file: (channel name -> 2-D float array, bench_sim metadata or {})."""
    import OpenEXR

    try:
        with OpenEXR.File(str(path), separate_channels=True) as f:
            # copy out while the file is open: the header does not outlive it
            meta_raw = f.header().get("bench_sim")
            meta_text = str(meta_raw) if isinstance(meta_raw, str) else None
            channels = {name: np.array(ch.pixels, copy=True) for name, ch in f.channels().items()}
    except Exception as exc:  # OpenEXR raises plain Exceptions with varying texts
        raise ImageReadError(f"{path}: not a readable OpenEXR file ({exc})") from exc
    meta = json.loads(meta_text) if meta_text else {}
    return channels, meta


def write_tiff16(
    path: str | os.PathLike[str], image_dn: np.ndarray, metadata: Mapping[str, Any] | None = None
) -> Path:
    """Write a 2-D array of non-negative integers below 65536 as a 16-bit grayscale TIFF.

    The metadata goes into the TIFF ImageDescription tag as JSON.
    """
    import tifffile

    arr = np.asarray(image_dn)
    if arr.ndim != 2:
        raise ValueError(f"{path}: a 16-bit TIFF needs a 2-D image, got shape {arr.shape}")
    if arr.size and (arr.min() < 0 or arr.max() > 65535):
        raise ValueError(f"{path}: values must lie in 0..65535, got {arr.min()}..{arr.max()}")
    desc = json.dumps(metadata or {}, sort_keys=True, default=_json_default)
    with atomic_path(path) as tmp:
        tifffile.imwrite(tmp, arr.astype(np.uint16), description=desc, metadata=None)
    return Path(path)


def _png_info(metadata: Mapping[str, Any] | None) -> Any:
    from PIL import PngImagePlugin

    info = PngImagePlugin.PngInfo()
    if metadata is not None:
        info.add_text("bench_sim", json.dumps(metadata, sort_keys=True, default=_json_default))
    return info


#: zlib level of the PNGs written: on the reproduction's figures level 3 encodes in half the time
#: of Pillow's default 6 and gives files no larger (729 vs 834 kB for Fig. 3)
PNG_COMPRESS_LEVEL = 3


def write_png(
    path: str | os.PathLike[str], image: np.ndarray, metadata: Mapping[str, Any] | None = None
) -> Path:
    """Write an 8- or 16-bit grayscale (2-D) or 8-bit RGB (H, W, 3) PNG (Pillow); ``metadata``
    as JSON in the ``tEXt`` chunk ``bench_sim`` (Pillow's ``PngInfo``)."""
    from PIL import Image

    arr = np.asarray(image)
    if arr.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"{path}: PNG needs uint8 or uint16 data, got {arr.dtype}")
    if not (arr.ndim == 2 or (arr.ndim == 3 and arr.shape[2] == 3 and arr.dtype == np.uint8)):
        raise ValueError(f"{path}: PNG needs a 2-D image or 8-bit (H, W, 3) RGB, got {arr.shape} {arr.dtype}")
    img = Image.fromarray(np.ascontiguousarray(arr))
    with atomic_path(path) as tmp:
        img.save(tmp, format="PNG", pnginfo=_png_info(metadata), compress_level=PNG_COMPRESS_LEVEL)
    return Path(path)


def write_figure_png(
    path: str | os.PathLike[str], fig: Any, metadata: Mapping[str, Any] | None = None, dpi: float = 110
) -> Path:
    """Render a matplotlib figure to PNG with the ``bench_sim`` text chunk (Pillow ``PngInfo``)
    and close it."""
    import io as _io

    import matplotlib.pyplot as plt

    buf = _io.BytesIO()  # encoded once, with the text chunk (Pillow's PngInfo through matplotlib)
    fig.savefig(buf, format="png", dpi=dpi,
                pil_kwargs={"pnginfo": _png_info(metadata), "compress_level": PNG_COMPRESS_LEVEL})
    plt.close(fig)
    with atomic_path(path) as tmp:
        tmp.write_bytes(buf.getvalue())
    return Path(path)


def read_png_text(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The ``bench_sim`` metadata of a PNG written by :func:`write_png` (``{}`` if none)."""
    from PIL import Image

    with Image.open(path) as img:
        text = getattr(img, "text", {}).get("bench_sim")
    return json.loads(text) if text else {}


def write_text(path: str | os.PathLike[str], text: str) -> Path:
    """Write a text file atomically (UTF-8)."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def _comment_lines(metadata: Mapping[str, Any] | None) -> list[str]:
    """Provenance as ``#`` lines: ``# version ... seed ... config_sha256 ...`` and the JSON."""
    if not metadata:
        return []
    head = " ".join(f"{k} {metadata[k]}" for k in ("version", "seed", "config_sha256") if k in metadata)
    return [f"# bench_sim {head}".rstrip(), "# provenance: " + json.dumps(
        metadata, sort_keys=True, default=_json_default
    )]


def write_csv(
    path: str | os.PathLike[str],
    header: list[str],
    rows: list[list[Any]],
    metadata: Mapping[str, Any] | None = None,
) -> Path:
    """Write a CSV table: provenance ``#`` lines, the header, the rows (floats to 10 digits).

    Readers: ``pandas.read_csv(path, comment="#")``.
    """
    import csv
    import io as _io

    buf = _io.StringIO()
    buf.writelines(line + "\n" for line in _comment_lines(metadata))
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for r in rows:
        w.writerow([f"{v:.10g}" if isinstance(v, float) else v for v in r])
    return write_text(path, buf.getvalue())


def write_emva_descriptor(
    path: str | os.PathLike[str],
    *,
    bits: int,
    width: int,
    height: int,
    bright: list[tuple[float, float, list[str]]],
    dark: list[tuple[float, list[str]]],
    title: str = "",
    metadata: Mapping[str, Any] | None = None,
) -> Path:
    """Write an EMVA 1288 descriptor file (the format the ``emva1288`` reference package reads).

    Lines: ``v 4.0``, ``n bits width height``; per bright level ``b exposure_ns photons`` and per
    dark level ``d exposure_ns``, each followed by its ``i path`` lines (2 images: a temporal
    pair; more: a spatial stack). Comment lines (``#``) carry ``title`` and the provenance.

    Parameters
    ----------
    bright
        ``(exposure_ns, photons, image paths)`` per bright level (paths relative to the file).
    dark
        ``(exposure_ns, image paths)`` per dark level.
    """
    lines = ([f"# {title}"] if title else []) + _comment_lines(metadata)
    lines += ["v 4.0", f"n {int(bits)} {int(width)} {int(height)}"]
    for exposure_ns, photons, names in bright:
        lines.append(f"b {exposure_ns:.3f} {photons:.9g}")
        lines += [f"i {n}" for n in names]
    for exposure_ns, names in dark:
        lines.append(f"d {exposure_ns:.3f}")
        lines += [f"i {n}" for n in names]
    return write_text(path, "\n".join(lines) + "\n")


_IMAGE_SUFFIXES = (".tif", ".tiff", ".png", ".exr", ".npy")


def _image_file(path: str | os.PathLike[str]) -> tuple[Path, str]:
    """An existing image file and its lower-case suffix, or :class:`ImageReadError` (one line)."""
    path = Path(path)
    if not path.is_file():
        raise ImageReadError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix not in _IMAGE_SUFFIXES:
        allowed = ", ".join(_IMAGE_SUFFIXES)
        raise ImageReadError(f"{path}: unsupported file type '{suffix}' (allowed: {allowed})")
    return path, suffix


def read_image(path: str | os.PathLike[str]) -> np.ndarray:
    """Read a single-channel image as a float64 2-D array.

    Supported: 8/16-bit grayscale TIFF and PNG, single-channel (or first-channel) EXR, and NPY.
    Raises :class:`ImageReadError` with the file name for anything else.
    """
    path, suffix = _image_file(path)
    try:
        if suffix == ".npy":
            arr = np.load(path, allow_pickle=False)
        elif suffix == ".exr":
            channels, _ = read_exr(path)
            name = next((n for n in ("Y", "R", "gray") if n in channels), sorted(channels)[0])
            arr = channels[name]
        elif suffix in (".tif", ".tiff"):
            import tifffile

            arr = tifffile.imread(path)
        elif suffix == ".png":
            import imageio.v3 as iio

            arr = iio.imread(path)
    except Exception as exc:
        raise ImageReadError(f"{path}: cannot read image ({exc})") from exc
    arr = np.asarray(arr)
    if arr.ndim != 2:
        raise ImageReadError(f"{path}: expected a single-channel 2-D image, got shape {arr.shape}")
    if not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
        raise ImageReadError(f"{path}: unsupported pixel type {arr.dtype}")
    return arr.astype(np.float64)


def sha256_file(path: str | os.PathLike[str]) -> str:
    """SHA-256 (hex) of a file's bytes, read in blocks (input files' provenance)."""
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


def image_shape(path: str | os.PathLike[str]) -> tuple[int, ...]:
    """The array shape of an image file from its header, without decoding the pixels (for the
    up-front memory estimate). Same formats as :func:`read_image`; raises
    :class:`ImageReadError` (one line) for a missing, unsupported or unreadable file."""
    path, suffix = _image_file(path)
    try:
        if suffix == ".npy":
            return tuple(np.load(path, mmap_mode="r", allow_pickle=False).shape)
        if suffix in (".tif", ".tiff"):
            import tifffile

            with tifffile.TiffFile(path) as tif:
                return tuple(tif.series[0].shape)
        if suffix == ".png":
            from PIL import Image

            with Image.open(path) as img:
                bands = len(img.getbands())
                return (img.height, img.width) if bands == 1 else (img.height, img.width, bands)
        if suffix == ".exr":
            import OpenEXR

            with OpenEXR.File(str(path), header_only=True) as f:
                (x0, y0), (x1, y1) = f.header()["dataWindow"]
                return (int(y1 - y0 + 1), int(x1 - x0 + 1))
    except Exception as exc:  # the readers raise many kinds for a broken file
        detail = " ".join(str(exc).split())[:120]
        raise ImageReadError(f"{path}: cannot read image header ({detail})") from None
    raise AssertionError(suffix)  # _image_file allows only the suffixes handled above
