"""One ``ast.parse`` at a time, on the CPython releases whose AST conversion is not thread-safe.

CPython 3.11.0-3.11.7 and 3.12.0-3.12.1 keep the recursion depth of the conversion of a parsed
tree to Python objects (``ast.parse``) in state that all the interpreter's threads share. A thread
switch inside one conversion (a garbage collection running a finaliser's bytecode) lets another
thread's conversion change that depth, and one of the two fails with ``SystemError: AST
constructor recursion depth mismatch`` (python/cpython#106905; fixed in 3.11.8 and 3.12.2 by a
depth per conversion). bench_sim's own threads parse beside the main thread: numba's loading of
a pass's compiled loops (:func:`bench_sim.runtime.jit.warm_up`) calls ``inspect.signature`` of
builtins, which parses, while the main thread sets Mitsuba's variant, whose Dr.Jit ``@dr.syntax``
functions are parsed. On those releases :func:`guard_ast_parse` puts ``ast.parse`` (the function
``inspect``, Dr.Jit and the rest of the process call) behind one re-entrant lock: the trees are
the same, the conversions no longer overlap. Elsewhere it does nothing.

References
----------
python/cpython#106905, "Error in AST recursion depth tracking change of gh-95185", and its fix
python/cpython#113035 (backported as #113472 to 3.12 and #113476 to 3.11).
"""

from __future__ import annotations

import ast
import functools
import sys
import threading
from typing import Any

__all__ = ["AFFECTED", "affected", "guard_ast_parse"]

#: the releases whose ``ast.parse`` is not thread-safe: [first, first fixed) per minor version
AFFECTED = (((3, 11, 0), (3, 11, 8)), ((3, 12, 0), (3, 12, 2)))

_install = threading.Lock()


def affected(version: tuple[int, ...] | None = None) -> bool:
    """Whether CPython ``version`` (major, minor, micro; default: this interpreter) has the race
    (:data:`AFFECTED`)."""
    v = tuple(sys.version_info[:3]) if version is None else tuple(version[:3])
    return sys.implementation.name == "cpython" and any(lo <= v < hi for lo, hi in AFFECTED)


def guard_ast_parse() -> bool:
    """On an affected interpreter, replace ``ast.parse`` once by the same function behind a
    process-wide re-entrant lock (before bench_sim starts threads that may parse). Returns
    whether ``ast.parse`` is guarded now."""
    if not affected():
        return False
    with _install:
        if getattr(ast.parse, "bench_sim_guarded", False):
            return True
        parse = ast.parse
        lock = threading.RLock()

        @functools.wraps(parse)
        def guarded(*args: Any, **kwargs: Any) -> Any:
            with lock:
                return parse(*args, **kwargs)

        guarded.bench_sim_guarded = True  # type: ignore[attr-defined]
        ast.parse = guarded
    return True
