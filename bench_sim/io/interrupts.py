"""Ctrl-C (SIGINT) and SIGTERM held back while a step must not be cut in half.

Python runs a signal's handler in the main thread, between two bytecodes, wherever the program
is: in the middle of creating a temporary folder (which would then be left behind), of removing
one, or of importing a C extension such as Mitsuba/Dr.Jit (a half-initialised extension can
abort the interpreter at exit, and an import cut short can leave the import lock held).
:func:`deferred_interrupts` holds such signals for the duration of a block: its handler only
records the signal (nothing else runs in it, so it is safe wherever it fires), and at the end of
the block the previous handlers are restored and each held signal is raised again, so the usual
``KeyboardInterrupt`` (or the CLI's SIGTERM handling) happens at a clean point, just after the
step.

Blocks nest; outside the main thread (where handlers cannot be installed) the block runs as is.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from typing import Any

__all__ = ["deferred_interrupts", "HELD_SIGNALS"]

#: The signals held back: Ctrl-C and the polite termination request
HELD_SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextlib.contextmanager
def deferred_interrupts() -> Iterator[None]:
    """Hold SIGINT and SIGTERM during the block; deliver them (once each) when it ends."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: list[int] = []

    def hold(signum: int, frame: Any) -> None:  # only records: safe at any bytecode
        held.append(signum)

    previous: dict[int, Any] = {}
    try:
        for sig in HELD_SIGNALS:
            previous[sig] = signal.signal(sig, hold)
        yield
    finally:
        for signum, handler in previous.items():
            # None: a handler not installed from Python (restored as the default)
            signal.signal(signum, signal.SIG_DFL if handler is None else handler)
        for signum in dict.fromkeys(held):
            signal.raise_signal(signum)  # the restored handler runs at the next bytecode
