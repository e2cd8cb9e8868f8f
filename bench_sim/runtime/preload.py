"""Libraries a command will need at its end, imported while its tasks run on a cluster.

A sweep or a dataset writes its tables, stores and figures in the client process; importing
xarray, Dask's arrays, netCDF4, Zarr and matplotlib when the last task is done (~1 s) would
lengthen the run's tail. :func:`import_modules` imports them in the client's own thread once
the tasks are on the cluster's workers (:func:`bench_sim.runtime.execution.run_tasks`'
``meanwhile``), while it would otherwise only wait for the first result.

Never on a thread of its own: on CPython 3.11 the conversion of a parsed tree to Python objects
(``ast.parse``) keeps its recursion depth in state the interpreter's threads share, and a
thread switch inside it (a garbage collection running a finaliser) makes the ``ast.parse`` of
another thread fail with ``SystemError: AST constructor recursion depth mismatch``
(python/cpython#106905). Imports parse: ``inspect.signature`` of builtins, matplotlib's
rc validators, Dr.Jit's ``@dr.syntax`` (Mitsuba's ``set_variant``). A worker that imported the
point's modules on a thread while its first task set Mitsuba's variant failed every point of
the run that way (a shared input's ``SystemError``), so the imports run in the thread that
needs them, one after the other.
"""

from __future__ import annotations

import contextlib
import importlib
from collections.abc import Iterable

from bench_sim.runtime import collector

__all__ = ["FIGURES", "import_modules"]

#: what bench_sim's figures are drawn with (matplotlib's figure and its Agg canvas, no GUI)
FIGURES = ("matplotlib.figure", "matplotlib.backends.backend_agg")


def import_modules(modules: Iterable[str]) -> None:
    """Import ``modules`` (dotted names), in order, in this thread; a module that fails to
    import is left for the command's own import to report (its error is not raised here).
    The garbage collector is paused meanwhile, and in ``bench-sim``'s own process what they
    made is settled after (:mod:`bench_sim.runtime.collector`)."""
    with collector.paused():
        for name in modules:
            with contextlib.suppress(Exception):
                importlib.import_module(name)
    collector.settle()
