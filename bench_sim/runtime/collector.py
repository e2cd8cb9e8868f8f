"""Python's cyclic garbage collector in a ``bench-sim`` process.

A command imports a few hundred thousand objects that live until the process exits (typer and
pydantic for the command line; xarray, pandas, Dask and matplotlib for the outputs). Each full
collection walks all of them: in a 6-point ``--quick`` sweep the client process spent 0.42 s in
620 collections, 0.24 s of it while it imported the output modules beside the running points
and 0.1 s in one full collection between two points. So a ``bench-sim`` process

- imports the modules its outputs are written with with the collector paused
  (:func:`paused`: imports make few reference cycles, and what they make is collected later);
- moves every object it holds to the collector's permanent generation once the command line is
  imported and again once those modules are (:func:`settle`: ``gc.freeze``), so later
  collections walk only what the command itself makes.

The worker processes of a local cluster (:mod:`bench_sim.runtime.cluster`) are ``bench-sim``'s
own too: each settles what it holds as it starts and again as its first task starts (a point,
a sample or a shared input: :func:`settle_once`, from :mod:`bench_sim.runtime.execution`), once
the task's modules are imported. A worker of a 6-point sweep spent 0.23-0.31 s in collections,
most of it walking those modules' objects again at every full collection.

Nothing changes in a program that imports bench_sim: :func:`settle` freezes nothing unless
:func:`own` was called (by :mod:`bench_sim.__main__`), and :func:`paused` restores the
collector's state on the way out. No value ever depends on when garbage is collected.
"""

from __future__ import annotations

import contextlib
import gc
from collections.abc import Iterator

__all__ = ["own", "paused", "settle", "settle_once"]

_OWN = False
_SETTLED_ONCE = False


def own() -> None:
    """Mark this process as ``bench-sim``'s own (its program module, :mod:`bench_sim.__main__`),
    and :func:`settle` what it holds now."""
    global _OWN
    _OWN = True
    settle()


def settle() -> bool:
    """In ``bench-sim``'s own process, move every object tracked now to the permanent generation
    (``gc.freeze``: never walked again, never freed; what is garbage at this moment is kept).
    Returns whether it did; nothing in any other process."""
    if _OWN:
        gc.freeze()
    return _OWN


def settle_once() -> bool:
    """:func:`settle` the first time it is called in this process, nothing after: a worker of a
    local cluster calls it as its first task starts, once that task's modules are imported and
    before it has made any garbage (a later task's would be kept for ever). Returns whether it
    settled."""
    global _SETTLED_ONCE
    if _SETTLED_ONCE:
        return False
    _SETTLED_ONCE = True
    return settle()


@contextlib.contextmanager
def paused() -> Iterator[None]:
    """The collector off within the block (as it was after it)."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()
