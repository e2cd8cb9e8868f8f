"""One progress bar for the long commands (``reproduce``'s frames, ``sweep``'s points,
``dataset``'s samples).

:func:`progress_bar` shows a `rich <https://rich.readthedocs.io>`_ bar with a description, the
count done of the total, a note (e.g. how many failed), the time elapsed and the time remaining.
It is a no-op when disabled or when the output is not a terminal (a log file gets no bar).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

__all__ = ["ProgressBar", "progress_bar"]


class ProgressBar:
    """A running bar (or nothing): :meth:`advance` it, change its :meth:`note`."""

    def __init__(self, bar: Any = None, task: Any = None) -> None:
        self._bar, self._task = bar, task

    def advance(self, n: int = 1) -> None:
        """Count ``n`` more units done."""
        if self._bar is not None:
            self._bar.update(self._task, advance=n)

    def note(self, text: str) -> None:
        """Replace the note shown after the count."""
        if self._bar is not None:
            self._bar.update(self._task, note=text)


@contextlib.contextmanager
def progress_bar(
    label: str, total: int, unit: str, *, enabled: bool = True, note: str = ""
) -> Iterator[ProgressBar]:
    """A progress bar for the ``with`` block.

    Parameters
    ----------
    label
        What runs (shown in bold first).
    total
        Units to do.
    unit
        What a unit is, after the count (``frames``, ``points``, ``samples``).
    enabled
        ``False``: nothing is shown (so is it when standard output is not a terminal).
    note
        Text after the count (:meth:`ProgressBar.note` changes it).
    """
    if not enabled:
        yield ProgressBar()
        return
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    console = Console()
    if not console.is_terminal:
        yield ProgressBar()
        return
    columns = (
        TextColumn(f"[bold]{label}"), BarColumn(), TextColumn(f"{{task.completed}}/{{task.total}} {unit}"),
        TextColumn("{task.fields[note]}"), TimeElapsedColumn(), TimeRemainingColumn(),
    )
    with Progress(*columns, console=console, transient=False) as bar:
        yield ProgressBar(bar, bar.add_task(label, total=total, note=note))
