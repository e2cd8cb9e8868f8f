"""What in a folder bench_sim wrote: the one rule for removing or overwriting an output.

A folder is ours only if it carries bench_sim's own record of what it holds, and then only the
entries that record names are ours:

- an output set (every command's ``--out``) carries its completion record,
  :data:`OUTPUT_MARKER`, whose ``files`` list names every file of the set;
- a long run written in place (``sweep``, ``dataset``) carries its own metadata file
  (``sweep.json``, ``dataset.json``), and what it may hold is given by the glob patterns of that
  kind of folder (``points/[0-9]*.json``, ``data.zarr/**``, ...); when it completes it writes the
  completion record with its ``files`` too.

Nothing else is ever removed or overwritten: a folder holding any entry that its record does not
name (a ``thesis.tex``, a user's ``results/``, a subfolder that merely has one of our names) is
refused in one line that names the entry, whatever subfolder names it has. Our own temporaries
(``.NAME.partial-PID-XXXX``, ``.NAME.old-PID-XXXX``) count as ours.

Patterns are matched per path component (:func:`fnmatch.fnmatchcase`, so ``*`` never crosses a
``/``); a final ``**`` component matches everything below its folder.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import stat
from collections.abc import Iterable, Sequence
from fnmatch import fnmatchcase
from pathlib import Path
from typing import Any

from bench_sim.errors import BenchSimError

__all__ = [
    "OUTPUT_MARKER",
    "entries",
    "foreign_entries",
    "listed_files",
    "read_output_record",
    "refuse_foreign",
    "remove_listed",
]

#: File written last into every output folder; it lists the files of the set (``files``), and
#: its presence marks a complete set. Only what it lists is ever replaced by a rerun.
OUTPUT_MARKER = ".bench-sim-output.json"

#: names of bench_sim's own temporaries (:mod:`bench_sim.io.atomic`)
_TEMPORARY = re.compile(r"\..+\.(partial|old)-\d+(-.*)?")


def entries(folder: Path) -> list[str]:
    """Every file, link and special file below ``folder``, and every empty folder (with a final
    ``/``), as ``/``-separated paths relative to ``folder``, sorted. Links are not followed;
    our temporaries are left out."""
    found: list[str] = []
    for root, dirs, files in os.walk(folder, followlinks=False):
        rel = Path(root).relative_to(folder)
        keep = []
        for d in dirs:
            if _TEMPORARY.fullmatch(d):
                continue
            if os.path.islink(os.path.join(root, d)):
                found.append((rel / d).as_posix())  # a link to a folder is an entry, not a tree
            else:
                keep.append(d)
        dirs[:] = keep
        found += [(rel / f).as_posix() for f in files if not _TEMPORARY.fullmatch(f)]
        if not keep and not files and rel != Path("."):
            found.append(rel.as_posix() + "/")
    return sorted(found)


def _matches(path: str, pattern: str) -> bool:
    """Whether the entry ``path`` is named by ``pattern``; an empty folder (``path`` ends with
    ``/``) also by any pattern of something inside it."""
    parts, pat = path.rstrip("/").split("/"), pattern.rstrip("/").split("/")
    if path.endswith("/") and len(pat) > len(parts):
        pat = pat[: len(parts)]
    elif pat[-1] == "**":
        head = pat[:-1]
        return len(parts) > len(head) and all(fnmatchcase(p, q) for p, q in zip(parts, head, strict=False))
    return len(parts) == len(pat) and all(fnmatchcase(p, q) for p, q in zip(parts, pat, strict=True))


def foreign_entries(folder: Path, owned: Iterable[str]) -> list[str]:
    """The entries of ``folder`` (:func:`entries`) that no pattern of ``owned`` names; the
    completion record is always ours."""
    patterns = [OUTPUT_MARKER, *owned]
    return [e for e in entries(folder) if not any(_matches(e, p) for p in patterns)]


def read_output_record(out: str | os.PathLike[str]) -> dict[str, Any] | None:
    """The completion record of the output set in ``out``; ``None`` if ``out`` holds no complete
    set (readers of a folder written in place check it before trusting the files)."""
    try:
        data = json.loads((Path(out) / OUTPUT_MARKER).read_text())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def listed_files(out: Path) -> list[str] | None:
    """The files the completion record of ``out`` names; ``None`` where there is no record or
    it names none (a set written before bench_sim 0.4 listed its files)."""
    record = read_output_record(out)
    files = None if record is None else record.get("files")
    if not isinstance(files, list) or not all(isinstance(f, str) for f in files):
        return None
    return files


def _describe(foreign: Sequence[str]) -> str:
    more = f" (and {len(foreign) - 1} more)" if len(foreign) > 1 else ""
    return f"{foreign[0]!r}{more}"


def refuse_foreign(out: Path, what: str, owned: Iterable[str] | None = None) -> None:
    """Raise :class:`BenchSimError` (one line) unless every entry of the non-empty folder ``out``
    is ours: named by ``owned`` (patterns), or else by the files its completion record lists."""
    given = str(out)
    patterns = list(owned) if owned is not None else listed_files(out)
    if patterns is None:
        if read_output_record(out) is not None:
            raise BenchSimError(
                f"{what} = {given!r}: holds an output of an older bench_sim whose record does not list "
                "its files, so it is not replaced: remove it yourself or choose a new folder"
            )
        raise BenchSimError(
            f"{what} = {given!r}: folder exists, is not empty and was not written by bench_sim (it has "
            "no bench_sim record): choose a new or empty folder"
        )
    try:
        foreign = foreign_entries(out, patterns)
    except OSError as exc:
        raise BenchSimError(f"{what} = {given!r}: cannot list the folder ({exc.strerror})") from None
    if foreign:
        raise BenchSimError(
            f"{what} = {given!r}: holds {_describe(foreign)}, which bench_sim did not write; it never "
            "removes or overwrites what is not its own: move it away or choose a new folder"
        )


def remove_listed(folder: Path, files: Iterable[str]) -> list[str]:
    """Remove the files ``files`` (paths relative to ``folder``) and the completion record, then
    the folders they leave empty, ``folder`` last. Links are removed, never followed; a listed
    name that is now a folder is left. Returns what is left (empty when ``folder`` is gone)."""
    dirs: set[Path] = set()
    for name in [*files, OUTPUT_MARKER]:
        path = folder / name
        with contextlib.suppress(OSError):
            if not stat.S_ISDIR(os.lstat(path).st_mode):
                path.unlink()
        dirs.update(p for p in path.parents if p.is_relative_to(folder) and p != folder)
    for d in sorted(dirs, key=lambda p: len(p.parts), reverse=True):
        with contextlib.suppress(OSError):
            d.rmdir()
    with contextlib.suppress(OSError):
        folder.rmdir()
    return entries(folder) if folder.exists() else []
