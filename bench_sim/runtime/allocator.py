"""The C allocator of a ``bench-sim`` process (glibc's ``mallopt`` and ``malloc_trim``).

A pass's threads (the render thread, the thread pool's workers, the workflow's lane) allocate
and free arrays of megabytes, chunk after chunk. With glibc's defaults -- an arena per thread
(up to eight per core), and blocks below a threshold that rises to 32 MiB kept in the arenas --
the memory freed in one thread's arena is neither reused by the others nor given back, and the
holes that freed temporaries leave inside an arena stay resident: the process's resident memory
grew 150-250 MiB past what it held (issue 38). So a ``bench-sim`` process

- uses one arena for all its threads (:func:`one_arena`, set at its start by
  :mod:`bench_sim.__main__`; the threads' numpy work allocates a few large blocks, not many
  small ones, so the arena's lock is seldom contended: the same time);
- gives the free memory inside the arena back when a large working set has just been let go
  (:func:`give_back`: ``reproduce`` after its pass, and before its largest figures);
- maps blocks of 4 MiB and more on their own while a workflow makes its outputs
  (:func:`large_blocks_mapped`: metrics, figures, the companion pass beside them), so their
  temporaries leave no holes (a page fault per 4 KiB page of them: a fraction of a second).

Nothing is changed on import: a program that imports bench_sim keeps its own allocator
(:func:`large_blocks_mapped` changes nothing unless :func:`one_arena` was set in the process).
Off glibc, or with ``MALLOC_ARENA_MAX`` set in the environment (the user's choice, which glibc
read at start-up), nothing is changed either. The arrays' values never depend on any of it.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
from collections.abc import Iterator
from typing import Any

__all__ = [
    "one_arena", "give_back", "large_blocks_mapped", "M_ARENA_MAX", "M_MMAP_THRESHOLD",
    "OUTPUTS_MMAP_THRESHOLD", "DYNAMIC_MMAP_THRESHOLD_MAX",
]

#: glibc's ``mallopt`` parameter numbers (``malloc.h``)
M_ARENA_MAX = -8
M_MMAP_THRESHOLD = -3
#: blocks mapped on their own by :func:`large_blocks_mapped` [bytes]
OUTPUTS_MMAP_THRESHOLD = 4 * 2**20
#: glibc's largest dynamic mmap threshold on 64-bit systems [bytes]: set after
#: :func:`large_blocks_mapped` (a set threshold stops glibc's own adjustment)
DYNAMIC_MMAP_THRESHOLD_MAX = 32 * 2**20

_TUNED = False


def _glibc() -> Any | None:
    """The process's C library if it is glibc, else ``None``."""
    try:
        libc = ctypes.CDLL(None)  # the process's own symbols, its C library's among them
    except OSError:  # pragma: no cover - no C library to ask
        return None
    return libc if hasattr(libc, "gnu_get_libc_version") else None


def one_arena() -> bool:
    """Ask glibc for one malloc arena for every thread the process starts from now on (module
    docstring). Returns whether it was set (False off glibc, or with ``MALLOC_ARENA_MAX`` set)."""
    global _TUNED
    libc = _glibc()
    if libc is None or "MALLOC_ARENA_MAX" in os.environ:
        return False
    _TUNED = bool(libc.mallopt(M_ARENA_MAX, 1))
    return _TUNED


def give_back() -> bool:
    """Give the allocator's free memory back to the system (glibc's ``malloc_trim(0)``: the free
    pages inside its arenas too, not only at their tops), so that the next working set does not
    add its pages to the holes the last one left. Returns whether memory was given back."""
    libc = _glibc()
    return bool(libc.malloc_trim(0)) if libc is not None else False


@contextlib.contextmanager
def large_blocks_mapped(threshold: int = OUTPUTS_MMAP_THRESHOLD) -> Iterator[None]:
    """Within the block, blocks of ``threshold`` bytes or more are mapped on their own and given
    back to the system when freed (``M_MMAP_THRESHOLD``); after it, glibc's largest dynamic
    threshold (:data:`DYNAMIC_MMAP_THRESHOLD_MAX`). Only in a process where :func:`one_arena`
    was set (``bench-sim`` itself); elsewhere nothing changes."""
    libc = _glibc() if _TUNED else None
    if libc is not None:
        libc.mallopt(M_MMAP_THRESHOLD, int(threshold))
    try:
        yield
    finally:
        if libc is not None:
            libc.mallopt(M_MMAP_THRESHOLD, DYNAMIC_MMAP_THRESHOLD_MAX)
