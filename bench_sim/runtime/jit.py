"""Compiled loops: numba, built once per process, cached on disk, imported only when needed.

The hot loops of a pass that numpy would run as many whole-array passes (the fast engine's tap
loop, the truth's per-read cumulants and stage sums) are plain Python functions over arrays that
numba compiles (:func:`compiled`). They do the same floating-point operations in the same order
as the numpy expressions they replace, with no fused multiply-add (numba's default: ``fastmath``
off, so LLVM does not contract ``a * b + c``), so their results are bit-identical to them; the
tests compare them bit for bit.

numba is imported when a loop is first needed (``import bench_sim.cli`` never imports it). The
machine code is cached on disk (``cache=True``), so a later process loads it instead of
compiling it: in ``NUMBA_CACHE_DIR`` if set, else beside the module in ``__pycache__``, or where
that is not writable in numba's user-wide cache folder (``~/.cache/numba``); where no folder is
writable, every process compiles and nothing fails. :func:`warm_up` loads loops on a thread of
its own while the caller goes on (a pass starts it before its set-up); numba parses there
(``inspect.signature``), so ``ast.parse`` is made thread-safe first where CPython's is not
(:func:`bench_sim.runtime.ast_guard.guard_ast_parse`).
"""

from __future__ import annotations

import threading
import warnings
from collections.abc import Callable, Iterable
from typing import Any

from bench_sim.runtime.ast_guard import guard_ast_parse

__all__ = ["compiled", "warm_up", "Loop"]

#: A loop to compile: the plain function and its numba signature.
Loop = tuple[Callable[..., Any], str]

_lock = threading.Lock()
_built: dict[tuple[Callable[..., Any], str], Callable[..., Any]] = {}


def compiled(fn: Callable[..., Any], signature: str) -> Callable[..., Any]:
    """``fn`` compiled by numba for ``signature`` (numba's type names, e.g. ``"void(float32[:,
    ::1])"``), without the GIL and without bounds checks: built once per process by the first
    thread that asks (from numba's disk cache where it was compiled before), then reused."""
    key = (fn, signature)
    got = _built.get(key)
    if got is not None:
        return got
    with _lock:
        got = _built.get(key)
        if got is None:
            got = _built[key] = _build(fn, signature)
    return got


def _build(fn: Callable[..., Any], signature: str) -> Callable[..., Any]:
    import numba

    options: dict[str, Any] = {"nogil": True, "boundscheck": False, "fastmath": False}
    try:
        return numba.njit(signature, cache=True, **options)(fn)
    except (RuntimeError, OSError) as exc:
        # no writable cache folder at all (RuntimeError "cannot cache function ..."), or the
        # cache file could not be written (a full disk): compile for this process only
        warnings.warn(f"numba could not cache {fn.__qualname__} ({exc}): compiled in this process "
                      "(NUMBA_CACHE_DIR sets a writable folder)", RuntimeWarning, stacklevel=3)
        return numba.njit(signature, cache=False, **options)(fn)


def warm_up(loops: Iterable[Loop]) -> threading.Thread:
    """Build ``loops`` (``(fn, signature)`` pairs, as :func:`compiled` takes them) on a daemon
    thread; returns it (started). A later :func:`compiled` of the same loop waits for it."""

    def build() -> None:
        for fn, signature in loops:
            compiled(fn, signature)

    guard_ast_parse()  # numba parses on the thread while the caller may (Mitsuba's variant)

    thread = threading.Thread(target=build, name="bench_sim-jit", daemon=True)
    thread.start()
    return thread
