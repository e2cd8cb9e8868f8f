"""Ctrl-C (SIGINT) and SIGTERM: held back while a step must not be cut in half, never raised
inside an import, and the same at every moment of a ``bench-sim`` process.

Python runs a signal's handler in the main thread, between two bytecodes, wherever the program
is: in the middle of creating a temporary folder (which would then be left behind), of removing
one, or of importing a module. An exception raised inside the import machinery (for instance
between ``_imp.acquire_lock()`` and its ``try`` in ``importlib._bootstrap``, or in the weakref
callback of a module lock) leaves the import lock held: the next import in any thread waits for
ever, and the process hangs instead of stopping.

* :func:`deferred_interrupts` holds such signals for the duration of a block: its handler only
  records the signal (nothing else runs in it, so it is safe wherever it fires), and at the end
  of the block the previous handlers are restored and each held signal is raised again, so the
  usual ``KeyboardInterrupt`` (or :class:`Terminated`) happens at a clean point, just after the
  step. Blocks nest; outside the main thread the block runs as is.
* :func:`command_signals` is the handling of a command's run: SIGINT raises
  ``KeyboardInterrupt`` and SIGTERM :class:`Terminated`, except while the main thread is inside
  an import (an ``importlib`` frame on its stack, :func:`importing`): then the signal is
  sent again a moment later (:data:`REDELIVER_S`) by a thread started beforehand, until the
  import has ended. An import that does not end within :data:`IMPORT_PATIENCE_S` is given up:
  one line and the exit status at once (a killed run's temporaries are removed by the next run).
* :func:`own_process_signals` (called by ``bench-sim``'s entry point once the command line is
  imported) makes that handling the process's own, and :func:`command_signals` then ends the
  process at once, with one line and the signal's exit status (130, 143), for a signal that
  comes after the command's work (while the interpreter exits): a signal never ends in status 0.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time
import warnings
from collections.abc import Iterator
from types import FrameType
from typing import Any

__all__ = [
    "EXIT_STATUS",
    "HELD_SIGNALS",
    "IMPORT_PATIENCE_S",
    "REDELIVER_S",
    "Terminated",
    "command_signals",
    "deferred_interrupts",
    "importing",
    "leave_if_pending",
    "leave_now",
    "own_process_signals",
    "signal_exception",
    "signal_raised",
]

#: The signals held back: Ctrl-C and the polite termination request
HELD_SIGNALS = (signal.SIGINT, signal.SIGTERM)
#: Exit status of the command line after each signal (128 + its number)
EXIT_STATUS: dict[int, int] = {signal.SIGINT: 130, signal.SIGTERM: 143}
#: How soon a signal that came during an import is sent again [s]
REDELIVER_S = 0.02
#: Longest wait for an import to end before a signal ends the process regardless [s]
IMPORT_PATIENCE_S = 60.0
#: What each signal is called in the one line
_NAMES: dict[int, tuple[str, str]] = {
    signal.SIGINT: ("interrupted", "Ctrl-C"),
    signal.SIGTERM: ("terminated", "SIGTERM"),
}


class Terminated(BaseException):
    """SIGTERM, raised in the main thread (as ``KeyboardInterrupt`` is for SIGINT) so that
    output sets clean up and the command line says what was kept."""


def signal_exception(signum: int) -> BaseException:
    """The exception a command's run raises for signal ``signum``."""
    return KeyboardInterrupt() if signum == signal.SIGINT else Terminated()


def importing(frame: FrameType | None) -> bool:
    """Whether the main thread, stopped at ``frame``, is inside an import: an ``importlib``
    frame on its stack (the import system, a module being executed by it, a module lock's
    callback). The global import lock (``_imp.lock_held``) is not asked: it says that *some*
    thread holds it, and another thread importing at a low priority can hold it for seconds on a
    loaded machine, which held back a Ctrl-C that long; the main thread takes it only inside
    ``importlib`` frames."""
    f = frame
    while f is not None:
        name = f.f_code.co_filename
        if name.startswith("<frozen importlib") or "importlib/_bootstrap" in name:
            return True
        f = f.f_back
    return False


def _one_line(signum: int, when: str) -> bytes:
    kind, what = _NAMES.get(signum, ("terminated", f"signal {signum}"))
    return f"bench-sim: {kind}: stopped by {what}{when}\n".encode()


#: set by the first :func:`leave_now` of the process: the process is on its way out
_LEAVING: list[int] = []


def leave_now(signum: int, when: str) -> None:
    """One line on stderr, ``bench-sim: interrupted: stopped by Ctrl-C`` + ``when`` (or
    ``terminated ... SIGTERM``), and the signal's exit status, at once (no unwinding). Once:
    a handler that runs inside it (a signal sent again meanwhile, run between its last two
    bytecodes) returns, and the first call ends the process (one line, never two)."""
    if _LEAVING:
        return
    _LEAVING.append(signum)
    with contextlib.suppress(Exception):  # the main thread may be inside a write to stdout
        sys.stdout.flush()
    os.write(2, _one_line(signum, when))
    os._exit(EXIT_STATUS.get(signum, 128 + signum))


class _Redelivery:
    """A thread, started before it is needed, that sends a signal again to this process a
    moment after the handler found the main thread inside an import (the handler only writes
    one byte to a pipe: no lock is taken in it)."""

    def __init__(self) -> None:
        self.pid = os.getpid()
        self.since: dict[int, float] = {}
        read_fd, self.write_fd = os.pipe()
        os.set_blocking(self.write_fd, False)
        threading.Thread(target=self._run, args=(read_fd,), name="bench-sim signals", daemon=True).start()

    def _run(self, read_fd: int) -> None:
        while True:
            data = os.read(read_fd, 64)
            if not data:  # pragma: no cover - the pipe is never closed
                return
            time.sleep(REDELIVER_S)
            for signum in dict.fromkeys(data):
                if getattr(signal.getsignal(signum), "bench_sim_handler", False):
                    os.kill(self.pid, signum)
                else:  # the run has ended meanwhile and its handlers are gone (a run in a
                    # test or a notebook): the signal was for that run, not for what follows
                    self.since.pop(signum, None)

    def later(self, signum: int) -> None:
        first = self.since.setdefault(signum, time.monotonic())
        if time.monotonic() - first > IMPORT_PATIENCE_S:
            leave_now(signum, f" (an import did not end within {IMPORT_PATIENCE_S:g} s)")
        with contextlib.suppress(BlockingIOError):  # the pipe full: a byte is waiting already
            os.write(self.write_fd, bytes([signum]))


_REDELIVERY: _Redelivery | None = None
#: the signals raised as exceptions in this process so far
_RAISED: list[int] = []


def signal_raised() -> bool:
    """Whether a signal has been raised as its exception in this process (the run is being
    interrupted): what the interrupted step leaves open is then not reported."""
    return bool(_RAISED)

#: whether this process is ``bench-sim`` itself (own_process_signals was called)
_OWN_PROCESS = False


def _redelivery() -> _Redelivery:
    global _REDELIVERY
    if _REDELIVERY is None or _REDELIVERY.pid != os.getpid():  # none yet, or a forked child
        _REDELIVERY = _Redelivery()
    return _REDELIVERY


def leave_if_pending(when: str) -> None:
    """:func:`leave_now` for a signal that came during an import and is still waiting to be sent
    again (:data:`REDELIVER_S`): called before the process leaves, so that it is not lost."""
    if _REDELIVERY is not None and _REDELIVERY.pid == os.getpid():
        for signum in list(_REDELIVERY.since):
            leave_now(signum, when)


def _import_safe(redelivery: _Redelivery) -> Any:
    def handler(signum: int, frame: FrameType | None) -> None:
        if os.getpid() == redelivery.pid and importing(frame):
            redelivery.later(signum)
            return
        redelivery.since.pop(signum, None)
        _RAISED.append(signum)
        raise signal_exception(signum)

    handler.bench_sim_handler = True  # type: ignore[attr-defined]
    return handler


def _ignore_unraisable(unraisable: Any) -> None:
    """``sys.unraisablehook`` once the command has ended: nothing more is said."""


def _swallowed_signal(unraisable: Any) -> int | None:
    """The signal whose exception (raised by a handler of :func:`_import_safe`) ``unraisable`` is,
    or ``None``: one raised where it cannot propagate, in a finaliser or a garbage collector's
    callback (Dask's ``GCDiagnosis``), which Python reports as "Exception ignored" and drops."""
    exc = getattr(unraisable, "exc_value", None)
    if not _RAISED or not isinstance(exc, KeyboardInterrupt | Terminated):
        return None
    return signal.SIGINT if isinstance(exc, KeyboardInterrupt) else signal.SIGTERM


def _redeliver_swallowed(previous: Any) -> Any:
    """A ``sys.unraisablehook`` that sends a signal whose exception was swallowed
    (:func:`_swallowed_signal`) again a moment later (:data:`REDELIVER_S`), so that it is raised
    where it can stop the command, and passes anything else to ``previous``."""

    def hook(unraisable: Any) -> None:
        signum = _swallowed_signal(unraisable)
        if signum is None:
            previous(unraisable)
            return
        _RAISED.remove(signum)  # not raised after all: raised again when it comes back
        _redelivery().later(signum)

    hook.bench_sim_hook = True  # type: ignore[attr-defined]
    return hook


def _late(signum: int, frame: FrameType | None) -> None:
    leave_now(signum, " as the command ended")


_late.bench_sim_handler = True  # type: ignore[attr-defined]


def _install(handler: Any) -> dict[int, Any]:
    return {sig: signal.signal(sig, handler) for sig in HELD_SIGNALS}


def own_process_signals() -> None:
    """Make :func:`command_signals`' handling this process's own (``bench-sim``'s entry point,
    once the command line is imported): SIGINT and SIGTERM raise their exception, never inside
    an import, from now on; after a command, a signal ends the process at once."""
    global _OWN_PROCESS
    _install(_import_safe(_redelivery()))
    if not getattr(sys.unraisablehook, "bench_sim_hook", False):
        sys.unraisablehook = _redeliver_swallowed(sys.unraisablehook)
    _OWN_PROCESS = True


@contextlib.contextmanager
def command_signals() -> Iterator[None]:
    """SIGINT as ``KeyboardInterrupt``, SIGTERM as :class:`Terminated`, never raised inside an
    import, for a command's run (see the module docstring). In the ``bench-sim`` process
    (:func:`own_process_signals`), once the block ends a signal ends the process at once with
    one line and its exit status; elsewhere (a command run in a test) the previous handlers are
    restored. Outside the main thread the block runs as is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _RAISED.clear()  # a new command: nothing interrupted yet
    if _OWN_PROCESS:
        try:
            yield
        finally:
            _install(_late)
            leave_if_pending(" as the command ended")  # one that came during a last import
            # nor a warning or an "Exception ignored" after the command's own lines (a coroutine
            # of an interrupted write, or an object half-made when the signal came, collected
            # while the process exits)
            warnings.simplefilter("ignore")
            sys.unraisablehook = _ignore_unraisable
        return
    redelivery = _redelivery()
    # a signal an earlier run in this process deferred and then left to other handlers is not
    # pending for this one (its patience, counted from then, would end this process at once)
    redelivery.since.clear()
    previous = _install(_import_safe(redelivery))
    previous_hook = sys.unraisablehook
    sys.unraisablehook = _redeliver_swallowed(previous_hook)
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, signal.SIG_DFL if handler is None else handler)
        sys.unraisablehook = previous_hook
        redelivery.since.clear()


@contextlib.contextmanager
def deferred_interrupts() -> Iterator[None]:
    """Hold SIGINT and SIGTERM during the block; deliver them (once each) when it ends."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: list[int] = []

    def hold(signum: int, frame: Any) -> None:  # only records: safe at any bytecode
        held.append(signum)

    hold.bench_sim_handler = True  # type: ignore[attr-defined]  # a redelivery may come here

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
