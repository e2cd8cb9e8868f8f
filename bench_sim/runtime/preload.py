"""Libraries a command will need at its end, imported beforehand on a low-priority thread.

A sweep or a dataset writes its tables, stores and figures in the client process once every
point has run on the cluster's workers; importing xarray, Dask's arrays and matplotlib then
(~1 s) would lengthen the run's tail. :func:`import_in_background` imports them while the
points run, on a daemon thread of the lowest CPU priority (``nice`` 19 for that thread alone on
Linux), so it takes the time the workers leave over, not theirs. An import the command then
makes waits for the thread's (Python's import lock) and finds the module ready; an import that
fails here is left for the command's own import to report.
"""

from __future__ import annotations

import contextlib
import importlib
import os
import threading
from collections.abc import Iterable

__all__ = ["FIGURES", "import_in_background"]

#: what bench_sim's figures are drawn with (matplotlib's figure and its Agg canvas, no GUI)
FIGURES = ("matplotlib.figure", "matplotlib.backends.backend_agg")

#: ``nice`` of the importing thread (the lowest priority)
NICE = 19


def import_in_background(modules: Iterable[str], nice: int = NICE) -> threading.Thread:
    """Import ``modules`` (dotted names), in order, on a daemon thread of CPU priority ``nice``
    (default the lowest; ``0``: the process's own, for a process that has nothing else to do
    meanwhile, such as a cluster's worker before its first task); returns the thread (started).
    Nothing is required of the caller: its own imports of the same modules find them done or
    wait for them."""
    names = list(modules)

    def run() -> None:
        with contextlib.suppress(AttributeError, OSError):  # only this thread (Linux: per-thread nice)
            if nice:
                os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), nice)
        for name in names:
            with contextlib.suppress(Exception):  # the command's own import says what is wrong
                importlib.import_module(name)

    thread = threading.Thread(target=run, name="bench_sim-preload", daemon=True)
    thread.start()
    return thread
