"""The resume journal of a long run: one small JSON record per finished task, in one folder.

A sweep (``points/NNNNNN.json``) and a dataset (``samples/NNNNNNNN.json``) write each task's
record as it completes; ``--resume`` reads them back to know what is done. One rule for both:

- **Writing** is atomic and durable: the record goes to a temporary file beside its final
  name, the file is flushed to disk (``fsync``), renamed into place, and the folder is flushed
  so the rename itself survives a crash. A record is therefore either absent or whole.
- **Reading** takes every record whose name is the index (``[0-9]*.json``; temporaries start
  with a dot). A record that is empty or cannot be read (a torn write on a filesystem that
  does not order data and renames, a foreign file) counts as *not done*: its task is
  recomputed, and a one-line :class:`RuntimeWarning` names the file, once per file and process.

The content is the JSON form of :func:`bench_sim.io.write_json` (indented, keys sorted, one
newline at the end, strict JSON as :func:`bench_sim.io.strict_json.strict_dumps` writes it), so the
same run writes the same bytes.
"""

from __future__ import annotations

import contextlib
import json
import os
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bench_sim.io import atomic_path
from bench_sim.io.strict_json import strict_dumps

__all__ = ["Journal", "write_record", "read_records"]

#: Records already reported as unreadable by this process (each is warned about once)
_WARNED: set[Path] = set()


def _fsync_folder(folder: Path) -> None:
    """Flush a folder's entries (the rename of a record) to disk; a no-op where folders cannot
    be opened (Windows)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:  # pragma: no cover - not POSIX
        return
    try:
        with contextlib.suppress(OSError):
            os.fsync(fd)
    finally:
        os.close(fd)


def write_record(path: str | os.PathLike[str], record: Mapping[str, Any]) -> Path:
    """Write one journal record atomically and durably (see the module docstring).

    Parameters
    ----------
    path
        The record's final name (its folder is made if missing).
    record
        JSON-serialisable mapping (numpy scalars and arrays, paths allowed).

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    # the JSON form of bench_sim.io.write_json (tested byte for byte)
    text = strict_dumps(record, indent=2, sort_keys=True) + "\n"
    with atomic_path(path) as tmp:  # a temporary beside path, renamed onto it on success
        with open(tmp, "w") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
    _fsync_folder(path.parent)
    return path


def _unreadable(path: Path, reason: str) -> None:
    if path not in _WARNED:
        _WARNED.add(path)
        warnings.warn(
            f"bench_sim: {path}: unreadable journal record ({reason}): counted as not done, it is "
            "recomputed",
            RuntimeWarning,
            stacklevel=3,
        )


def read_records(folder: str | os.PathLike[str], key: str) -> dict[int, dict[str, Any]]:
    """Every readable record of a journal folder: index (the record's ``key`` field) -> record.

    An empty or unreadable record is left out (its task is not done) with a one-line warning;
    a missing folder is an empty journal.
    """
    out: dict[int, dict[str, Any]] = {}
    folder = Path(folder)
    if not folder.is_dir():
        return out
    for path in sorted(folder.glob("[0-9]*.json")):
        try:
            text = path.read_text()
            if not text.strip():
                _unreadable(path, "empty")
                continue
            rec = json.loads(text)
            out[int(rec[key])] = rec
        except (OSError, ValueError, KeyError, TypeError) as exc:
            _unreadable(path, type(exc).__name__)
    return out


@dataclass(frozen=True)
class Journal:
    """The journal of one run: records ``<folder>/<index, zero-padded to digits>.json``.

    Attributes
    ----------
    folder
        The journal folder (``DIR/points``, ``DIR/samples``).
    key
        The record field holding the task's index (``point``, ``sample``).
    digits
        Width of the zero-padded index in the file names.
    """

    folder: Path
    key: str
    digits: int

    def path(self, index: int) -> Path:
        """The record of task ``index``."""
        return self.folder / f"{int(index):0{self.digits}d}.json"

    def write(self, record: Mapping[str, Any]) -> Path:
        """Write ``record`` (its ``key`` field names the task) with :func:`write_record`."""
        return write_record(self.path(int(record[self.key])), record)

    def read(self) -> dict[int, dict[str, Any]]:
        """Index -> record of every readable record (:func:`read_records`)."""
        return read_records(self.folder, self.key)
