"""Tables: CSV files with their provenance as ``#`` comment lines, and Markdown tables.

The provenance (the dict of :func:`bench_sim.runtime.provenance.provenance`) goes into text
files as two ``#`` lines (:func:`comment_lines`): ``# bench_sim version ... seed ...
config_sha256 ...`` and ``# provenance: {JSON}``; CSV readers skip them
(``pandas.read_csv(path, comment="#")``).
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.errors import BenchSimError
from bench_sim.io.files import write_text
from bench_sim.io.strict_json import strict_dumps

__all__ = ["comment_lines", "markdown_table", "write_csv", "read_csv_columns"]

#: separator cell of each column alignment of :func:`markdown_table`
_ALIGN_RULES = {"l": "---", "r": "---:", "c": ":---:"}


def comment_lines(metadata: Mapping[str, Any] | None) -> list[str]:
    """Provenance as ``#`` lines: ``# bench_sim version ... seed ... config_sha256 ...`` and the
    JSON (none for no metadata)."""
    if not metadata:
        return []
    head = " ".join(f"{k} {metadata[k]}" for k in ("version", "seed", "config_sha256") if k in metadata)
    return [f"# bench_sim {head}".rstrip(), "# provenance: " + strict_dumps(metadata, sort_keys=True)]


def write_csv(
    path: str | os.PathLike[str],
    header: list[str],
    rows: list[list[Any]],
    metadata: Mapping[str, Any] | None = None,
) -> Path:
    """Write a CSV table: provenance ``#`` lines, the header, the rows (floats to 10 digits).

    Readers: ``pandas.read_csv(path, comment="#")``.
    """
    buf = io.StringIO()
    buf.writelines(line + "\n" for line in comment_lines(metadata))
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for r in rows:
        w.writerow([f"{v:.10g}" if isinstance(v, float) else v for v in r])
    return write_text(path, buf.getvalue())


def _md_row(cells: Sequence[str], compact_empty: bool) -> str:
    if compact_empty:
        return "|" + "".join(f" {c} |" if c else " |" for c in cells)
    return "| " + " | ".join(cells) + " |"


def markdown_table(
    header: Sequence[str],
    rows: Iterable[Sequence[Any]],
    align: str | None = None,
    *,
    fmt: Callable[[Any], str] = str,
    compact_empty: bool = False,
) -> list[str]:
    """The lines of a Markdown (GitHub) table: the header, the separator, one line per row.

    Parameters
    ----------
    header
        Column titles (as given: not passed through ``fmt``).
    rows
        Cells per row, each written as ``fmt(cell)``.
    align
        One letter per column: ``l`` (``---``, the default alignment), ``r`` (``---:``) or ``c``
        (``:---:``); ``None``: every column ``l``.
    fmt
        Text of a cell (e.g. a number format).
    compact_empty
        Write an empty cell as ``| |`` rather than ``|  |``.
    """
    rules = [_ALIGN_RULES[a] for a in (align if align is not None else "l" * len(header))]
    if len(rules) != len(header):
        raise ValueError(f"align {align!r}: one letter per column ({len(header)}) needed")
    lines = [_md_row(list(header), compact_empty), "|" + "|".join(rules) + "|"]
    lines += [_md_row([fmt(c) for c in row], compact_empty) for row in rows]
    return lines


def read_csv_columns(path: str | os.PathLike[str], label: str) -> dict[str, np.ndarray]:
    """A CSV file of numbers as ``{column name: float64 array}``: ``#`` lines skipped, one header
    row (names stripped, lower case), then rows of numbers, at least two. Anything else is one
    :class:`~bench_sim.errors.BenchSimError` line that starts with ``label`` (how the caller names
    the file) and says where."""
    path = Path(path)
    if not path.is_file():
        raise BenchSimError(f"{label}: no such file")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise BenchSimError(f"{label}: cannot be read ({exc.__class__.__name__})") from None
    lines = [line for line in text.splitlines() if line.strip() and not line.startswith("#")]
    rows = list(csv.reader(lines))
    if len(rows) < 3:
        raise BenchSimError(f"{label}: needs a header row and at least two rows of numbers")
    names = [c.strip().lower() for c in rows[0]]
    values = []
    for k, row in enumerate(rows[1:], start=2):
        try:
            values.append([float(c) for c in row])
        except ValueError:
            raise BenchSimError(f"{label}: row {k} ({','.join(row)!r}) is not all numbers") from None
        if len(row) != len(names):
            raise BenchSimError(f"{label}: row {k} has {len(row)} values, the header {len(names)} names")
    arr = np.asarray(values, dtype=np.float64)
    if not np.isfinite(arr).all():
        raise BenchSimError(f"{label}: holds NaN or inf values")
    return {n: arr[:, i] for i, n in enumerate(names)}
