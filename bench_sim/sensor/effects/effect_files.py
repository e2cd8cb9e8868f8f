"""Files an effect reads: a measured response curve, a map of defect pixels.

Both are plain CSV (a header line of names is allowed, ``#`` lines are comments) so that a lab's
spreadsheet export works as is; a problem is one line naming the file and what is wrong.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bench_sim.errors import BenchSimError

__all__ = ["read_response_table", "read_csv_columns"]


def read_csv_columns(path: Path, where: str, columns: int) -> list[list[str]]:
    """The rows of a CSV file as lists of ``columns`` text fields (comments and blank lines
    skipped; a first row that is not numeric is taken as a header and skipped)."""
    if not path.is_file():
        raise BenchSimError(f"{where} = {str(path)!r}: no such file")
    try:
        lines = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise BenchSimError(f"{where} = {str(path)!r}: cannot read it ({exc})") from None
    rows = [
        [f.strip() for f in ln.split(",")] for ln in lines if ln.strip() and not ln.lstrip().startswith("#")
    ]
    if rows and not _numeric(rows[0][0]):
        rows = rows[1:]
    for i, row in enumerate(rows):
        if len(row) < columns:
            raise BenchSimError(
                f"{where} = {str(path)!r}: row {i + 1} has {len(row)} fields, expected {columns}"
            )
    return rows


def _numeric(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def read_response_table(path: Path, where: str) -> tuple[np.ndarray, np.ndarray]:
    """A response curve ``(input, output)`` (two columns): at least two points, finite, input
    increasing, output non-decreasing (monotone), both >= 0."""
    rows = read_csv_columns(path, where, 2)
    try:
        data = np.array([[float(r[0]), float(r[1])] for r in rows], dtype=np.float64)
    except ValueError as exc:
        raise BenchSimError(f"{where} = {str(path)!r}: not a table of numbers ({exc})") from None
    if data.shape[0] < 2 or not np.all(np.isfinite(data)) or np.any(data < 0):
        raise BenchSimError(f"{where} = {str(path)!r}: needs at least two rows of finite values >= 0")
    x, y = data[:, 0], data[:, 1]
    if np.any(np.diff(x) <= 0):
        raise BenchSimError(f"{where} = {str(path)!r}: the input column must increase from row to row")
    if np.any(np.diff(y) < 0):
        i = int(np.argmax(np.diff(y) < 0))
        raise BenchSimError(
            f"{where} = {str(path)!r}: the response falls between input {x[i]:g} and "
            f"{x[i + 1]:g}; it must be monotone (non-decreasing)"
        )
    return x, y
