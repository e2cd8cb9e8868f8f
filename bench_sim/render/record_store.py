"""The on-disk store of the fast engine's light records: one file per record set, shared by the
processes of this machine (every command, every Dask worker), so a new process finds the records
of a scene rendered by an earlier one instead of importing Mitsuba and rendering them again.

Where
    ``<cache folder>/records/`` with the cache folder of the backend probes
    (:mod:`bench_sim.runtime.backend`): ``$BENCH_SIM_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/bench_sim``, else ``~/.cache/bench_sim``. Removing the folder (``rm -rf``)
    clears it; the next run renders again.
Switch
    ``BENCH_SIM_RECORD_CACHE=off`` (or ``0``, ``false``, ``no``) turns the store off: nothing is
    read or written (:func:`store_dir` is ``None``). The test suite runs with it off.
Size
    At most ``BENCH_SIM_RECORD_CACHE_MIB`` MiB (default :data:`DEFAULT_MIB`; a value that is not
    a non-negative number means the default): after each write the least recently used files
    (by modification time; a load touches its file) are deleted until the rest fit.
Files
    ``<sha256>.npz`` (uncompressed :func:`numpy.savez`), the hash of the records' key
    (:func:`bench_sim.render.records.records_key`) and :func:`versions` (Mitsuba, Dr.Jit and
    bench_sim versions, :data:`FORMAT`, and a fingerprint of the source that makes the records,
    so an edited source tree renders again). A file holds the arrays ``d_rec``, ``static``,
    ``position`` and ``hit`` as they were rendered (same dtype, shape, bytes) and ``meta``: the
    key, the light names and the versions as JSON, checked on load. A set loaded from here is
    one of no renders (:func:`bench_sim.render.records.cached_records`: ``renders`` 0).
Failures
    The store never fails a run. A file that cannot be read (truncated, corrupt, not ours,
    another key or versions) is a miss and is deleted if possible; a write that fails (read-only
    or full disk) is skipped. Writes go to a temporary file in the same folder renamed into place
    (:func:`bench_sim.io.atomic.atomic_path`), so a concurrent reader never sees half a file.

Nothing here imports Mitsuba or Dr.Jit (their versions come from the installed packages'
metadata).
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import math
import mmap
import os
import re
import zipfile
from collections.abc import Callable, Mapping, Sequence
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from bench_sim.io.atomic import atomic_path
from bench_sim.runtime.backend import cache_folder
from bench_sim.version import __version__

__all__ = [
    "ENV_SWITCH", "ENV_SIZE", "DEFAULT_MIB", "FORMAT", "ARRAYS", "Stored", "store_dir", "store_on",
    "versions", "load", "save", "usage", "limit_bytes", "evict", "source_fingerprint", "package_version",
    "page_out", "mapped_arrays", "entry_path", "read_entry", "write_entry",
]

#: Environment variable that turns the store off (``off``, ``0``, ``false``, ``no``).
ENV_SWITCH = "BENCH_SIM_RECORD_CACHE"
#: Environment variable: the store's size bound [MiB].
ENV_SIZE = "BENCH_SIM_RECORD_CACHE_MIB"
#: Default size bound [MiB].
DEFAULT_MIB = 2048.0
#: Version of the file layout; raise it when the files or the records' meaning change.
FORMAT = 1

_OFF = frozenset({"off", "0", "false", "no"})
#: The arrays of a record set (:class:`bench_sim.render.records.LightRecords`) that are stored.
ARRAYS = ("d_rec", "static", "position", "hit")
#: A stored record set: its light names and its arrays (:data:`ARRAYS`), as rendered.
Stored = tuple[tuple[str, ...], dict[str, np.ndarray]]
_FILE = re.compile(r"[0-9a-f]{64}\.npz")
#: The sources that make the records (relative to the package): part of the files' names.
_SOURCES = ("render/records.py", "rig")


def store_on() -> bool:
    """Whether the on-disk stores are on (:data:`ENV_SWITCH`)."""
    return os.environ.get(ENV_SWITCH, "").strip().lower() not in _OFF


def store_dir() -> Path | None:
    """The store's folder (``<cache folder>/records``), or ``None`` when it is turned off."""
    return cache_folder() / "records" if store_on() else None


def limit_bytes() -> int:
    """A store folder's size bound [bytes] (:data:`ENV_SIZE`, else :data:`DEFAULT_MIB`)."""
    try:
        mib = float(os.environ.get(ENV_SIZE, DEFAULT_MIB))
    except ValueError:
        mib = DEFAULT_MIB
    if not mib >= 0.0:  # negative or NaN
        mib = DEFAULT_MIB
    return int(mib * 2**20)


def package_version(name: str) -> str:
    """The installed version of the package ``name`` (``"missing"``)."""
    try:
        return version(name)
    except PackageNotFoundError:
        return "missing"


def source_fingerprint(sources: Sequence[str] = _SOURCES) -> str:
    """sha256 of the ``sources`` (files or folders relative to the package) that make what is
    stored (an editable install keeps its version number while its code changes)."""
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for rel in sources:
        p = root / rel
        for f in sorted(p.rglob("*.py")) if p.is_dir() else [p]:
            with contextlib.suppress(OSError):
                h.update(str(f.relative_to(root)).encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()


@functools.cache
def versions() -> dict[str, str]:
    """What a stored record set depends on besides its key: the Mitsuba, Dr.Jit and bench_sim
    versions (package metadata: Mitsuba is not imported), :data:`FORMAT` and the sources'
    fingerprint. Computed once per process."""
    return {
        "mitsuba": package_version("mitsuba"),
        "drjit": package_version("drjit"),
        "bench_sim": __version__,
        "format": str(FORMAT),
        "source": source_fingerprint(),
    }


T = TypeVar("T")


def entry_path(folder: Path, key: str, made_with: Mapping[str, str]) -> Path:
    """The file of ``key`` in a store's ``folder``: ``<sha256>.npz`` of the key and the
    versions it was ``made_with`` (this store's and the kernel, texture and camera stores')."""
    ident = json.dumps([key, dict(made_with)], sort_keys=True)
    return folder / (hashlib.sha256(ident.encode()).hexdigest() + ".npz")


def read_entry(folder: Path | None, key: str, made_with: Mapping[str, str],
               read: Callable[[Path, dict[str, Any]], T]) -> T | None:
    """``read(path, meta)`` of the stored file of ``key`` (``meta``: its JSON member ``meta``,
    checked to name ``key`` and these versions ``made_with``), or ``None``: the store is off
    (``folder`` ``None``), has no such file, or the file is not a complete entry of ``key`` made
    with these versions (another key or versions in ``meta``, or ``read`` raises; it is then
    deleted). A file read is marked recently used (evicted last). Never raises."""
    if folder is None:
        return None
    try:
        path = entry_path(folder, key, made_with)
        if not path.is_file():
            return None
    except Exception:
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"][()]))
        if not isinstance(meta, dict) or meta.get("key") != key or meta.get("versions") != dict(made_with):
            raise ValueError("another key or versions")
        value = read(path, meta)
    except Exception:
        _remove(path)
        return None
    with contextlib.suppress(OSError):
        os.utime(path)  # recently used: evicted last
    return value


def write_entry(folder: Path | None, key: str, made_with: Mapping[str, str], meta: Mapping[str, Any],
                arrays: Callable[[], Mapping[str, np.ndarray]] = dict) -> None:
    """Write the entry of ``key`` atomically: its JSON member ``meta`` (``key``, the versions it
    was ``made_with`` and ``meta``) and ``arrays()`` (name -> array, ``np.savez``'s members);
    then delete the least recently used files of ``folder`` beyond the size bound
    (:func:`limit_bytes`). Nothing when the store is off; a write that fails (read-only or full
    disk) is skipped: the entry is only not kept. Never raises."""
    if folder is None:
        return
    try:
        folder.mkdir(parents=True, exist_ok=True)
        path = entry_path(folder, key, made_with)
        text = json.dumps({"key": key, "versions": dict(made_with), **meta})
        named: dict[str, Any] = {"meta": np.array(text), **arrays()}
        with atomic_path(path) as tmp, open(tmp, "wb") as f:
            np.savez(f, **named)
    except Exception:
        return
    evict(folder, limit_bytes())


def _remove(path: Path) -> None:
    with contextlib.suppress(OSError):
        path.unlink()


def _read(path: Path, meta: dict[str, Any]) -> Stored:
    """The record set in ``path`` (its ``meta`` checked by :func:`read_entry`); ``ValueError``
    (or the reader's own error) when the file is not a complete set."""
    arrays = mapped_arrays(path, ARRAYS)
    d_rec, static, position, hit = (arrays[name] for name in ARRAYS)
    lights = meta.get("lights")
    if not (isinstance(lights, list) and all(isinstance(n, str) for n in lights)):
        raise ValueError("no light names")
    consistent = (
        d_rec.ndim == 3 and static.ndim == 3 and hit.dtype == np.bool_
        and d_rec.shape[0] == static.shape[0] == len(lights)
        and d_rec.shape[1:] == hit.shape and position.shape == (*hit.shape, 3)
    )
    if not consistent:
        raise ValueError("inconsistent arrays")
    return tuple(lights), arrays


def mapped_arrays(path: Path, names: Sequence[str]) -> dict[str, np.ndarray]:
    """The arrays ``names`` of the uncompressed ``.npz`` file ``path``, read-only views of one
    memory map of the file (its pages shared with the system's page cache, not copied:
    :func:`page_out` lets them go from the process's resident memory once read); ``ValueError``
    for a member that is compressed, missing or not a plain array."""
    with zipfile.ZipFile(path) as zf, open(path, "rb") as f:
        where = {}
        for name in names:
            info = zf.getinfo(f"{name}.npy")
            if info.compress_type != zipfile.ZIP_STORED:
                raise ValueError(f"{name}: compressed")
            f.seek(info.header_offset)
            local = f.read(30)  # the member's local header: its name and extra field follow
            if local[:4] != b"PK\x03\x04":
                raise ValueError(f"{name}: no local header")
            f.seek(info.header_offset + 30 + int.from_bytes(local[26:28], "little")
                   + int.from_bytes(local[28:30], "little"))
            fmt = np.lib.format
            header = fmt.read_array_header_1_0 if fmt.read_magic(f)[0] == 1 else fmt.read_array_header_2_0
            shape, fortran, dtype = header(f)
            if dtype.hasobject:
                raise ValueError(f"{name}: not a plain array")
            where[name] = (shape, fortran, dtype, f.tell())
        mm = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
    out = {}
    for name, (shape, fortran, dtype, offset) in where.items():
        if offset + math.prod(shape) * dtype.itemsize > len(mm):
            raise ValueError(f"{name}: beyond the end of the file")
        out[name] = np.ndarray(shape, dtype, buffer=mm, offset=offset, order="F" if fortran else "C")
    return out


def page_out(arrays: Sequence[np.ndarray]) -> None:
    """Let the pages of memory-mapped ``arrays`` (views of :func:`mapped_arrays`'s map) go from this
    process's resident memory (``madvise(MADV_DONTNEED)``): the values stay, read again from the
    file (the page cache) when next used. Arrays in memory are left as they are."""
    for a in arrays:
        base = a.base
        while isinstance(base, np.ndarray):
            base = base.base
        if isinstance(base, mmap.mmap) and hasattr(mmap, "MADV_DONTNEED"):
            with contextlib.suppress(OSError, ValueError):
                base.madvise(mmap.MADV_DONTNEED)


def load(key: str) -> Stored | None:
    """The stored record set of ``key`` (its light names and arrays), or ``None``: the store is
    off, has no such set, or its file cannot be read (then the file is deleted). Never raises."""
    return read_entry(store_dir(), key, versions(), _read)


def save(key: str, lights: Sequence[str], arrays: Mapping[str, np.ndarray]) -> None:
    """Store the record set of ``key`` (its light names and its :data:`ARRAYS`), then delete the
    least recently used files beyond the size bound. Does nothing when the store is off; a write
    that fails is skipped (never raises)."""
    write_entry(store_dir(), key, versions(), {"lights": list(lights)},
                lambda: {name: arrays[name] for name in ARRAYS})


def _stored(folder: Path) -> list[tuple[int, int, Path]]:
    """``(mtime_ns, size, path)`` of the record files in ``folder``, least recently used first."""
    files = []
    with contextlib.suppress(OSError):
        for entry in os.scandir(folder):
            if _FILE.fullmatch(entry.name):
                with contextlib.suppress(OSError):
                    st = entry.stat()
                    files.append((st.st_mtime_ns, st.st_size, Path(entry.path)))
    return sorted(files, key=lambda t: t[0])


def usage(folder: Path | None = None) -> tuple[int, int]:
    """``(bytes, files)`` of the entries in a store's ``folder`` (default: the record sets of
    this store; ``(0, 0)`` when it is off)."""
    folder = store_dir() if folder is None else folder
    files = [] if folder is None else _stored(folder)
    return sum(size for _, size, _ in files), len(files)


def evict(folder: Path, limit: int) -> None:
    """Delete the least recently used files (``<sha256>.npz``) of ``folder`` until the rest take
    at most ``limit`` bytes."""
    files = _stored(folder)
    total = sum(size for _, size, _ in files)
    for _, size, path in files:
        if total <= limit:
            break
        _remove(path)
        total -= size
