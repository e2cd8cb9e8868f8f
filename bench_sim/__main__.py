"""``python -m bench_sim`` and the ``bench-sim`` script: the command line of :mod:`bench_sim.cli`.

Ctrl-C and SIGTERM are handled from this module's first statement: while it imports the command
line (before :mod:`bench_sim.cli` can take over signals and errors) either is one line and exit
status 130 (143), not a traceback and not a silent death. (The package itself,
``bench_sim/__init__.py``, runs before this module and imports nothing.) Once the command line
is imported, :func:`bench_sim.io.interrupts.own_process_signals` takes over: the signals raise
their exception, never inside an import, and end the process at once after the command. The
process then leaves with the command's status at once (:func:`_leave`).

So importing this module makes the importing process ``bench-sim``'s own, as running it does: it
is the program, not a library module (other code calls the workflows, or :mod:`bench_sim.cli`
through typer's test runner).
"""

from __future__ import annotations

import atexit
import os
import signal
import sys
import threading
from typing import Any

_NOTHING = b" during start-up; nothing was written\n"
_EARLY: dict[int, tuple[bytes, int]] = {
    signal.SIGINT: (b"bench-sim: interrupted: stopped by Ctrl-C" + _NOTHING, 130),
    signal.SIGTERM: (b"bench-sim: terminated: stopped by SIGTERM" + _NOTHING, 143),
}


def _early_signal(signum: int, frame: Any) -> None:
    # Nothing has been written yet, and an exception raised here would land inside whatever
    # module is importing (a C extension's initialisation, the import lock held): leave at once,
    # with one line, without unwinding (no Python code of the interrupted import runs again).
    line, status = _EARLY[signum]
    os.write(2, line)
    os._exit(status)


for _sig in _EARLY:
    signal.signal(_sig, _early_signal)

from bench_sim.cli import app  # noqa: E402 - imported with Ctrl-C and SIGTERM handled
from bench_sim.io.interrupts import Terminated, leave_if_pending, leave_now, own_process_signals  # noqa: E402
from bench_sim.runtime import collector  # noqa: E402
from bench_sim.runtime.allocator import one_arena  # noqa: E402

own_process_signals()
one_arena()  # before the command starts its threads (bench_sim.runtime.allocator)
collector.own()  # the command line's objects settled (bench_sim.runtime.collector)


#: Longest wait for the libraries' exit functions before the process leaves regardless [s]
EXIT_FUNCTIONS_S = 10.0


def _leave(code: object) -> None:
    """Leave with the status of ``sys.exit(code)`` once the command has ended (its output
    committed or cleaned up): the libraries' exit functions run (multiprocessing releases its
    semaphores, Dask closes what is left), within :data:`EXIT_FUNCTIONS_S`, and then the process
    leaves without the interpreter's teardown. So there is no wait for the threads of an
    interrupted step (a pool's worker mid-task, or one started but not yet registered when
    Ctrl-C came, which the interpreter would wait for for ever), and no moment in which Python
    no longer runs signal handlers (while it collects its modules) and a signal would kill the
    process without its one line."""
    leave_if_pending(" as the command ended")  # one that came during a last import: not lost
    if isinstance(code, str):
        print(code, file=sys.stderr)
    status = 0 if code is None else code if isinstance(code, int) else 1

    def flush_and_exit() -> None:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):  # a closed pipe: nothing more to say to it
                pass
        # the last instant: a signal that comes from here on is held (pending), not lost between
        # the last bytecode (where its handler would run) and the exit; one already pending is said
        try:
            signal.pthread_sigmask(signal.SIG_BLOCK, set(_EARLY))
            pending = signal.sigpending() & set(_EARLY)
        except (AttributeError, OSError, ValueError):  # pragma: no cover - no signal masks
            pending = set()
        if pending:
            leave_now(min(pending), " as the command ended")
        os._exit(status)

    watchdog = threading.Timer(EXIT_FUNCTIONS_S, flush_and_exit)
    watchdog.daemon = True
    watchdog.start()
    atexit._run_exitfuncs()
    flush_and_exit()


def _children_skip_the_script() -> None:
    """Run from the ``bench-sim`` console script, ``__main__`` is that script, and the ``spawn``
    start method runs the parent's main script again in every child it starts (as
    ``__mp_main__``): each worker process of a local Dask cluster imported this module, so the
    whole command line (0.35 s), and made itself ``bench-sim``'s own (its signals, its allocator,
    its collector), which under ``python -m bench_sim`` it did not (spawn never re-runs a
    package's ``__main__``). With the script's ``__spec__`` naming this module, as under
    ``python -m``, the children of either start alike, without it."""
    script = sys.modules.get("__main__")
    if script is not None and script is not sys.modules.get(__name__) and script.__spec__ is None:
        script.__spec__ = __spec__


def main() -> None:
    """Run the command line."""
    _children_skip_the_script()
    try:
        app()
    except SystemExit as exc:
        _leave(exc.code)
    except KeyboardInterrupt:  # after a usage error's line, before its exit
        leave_now(signal.SIGINT, "; nothing was written")
    except Terminated:
        leave_now(signal.SIGTERM, "; nothing was written")


if __name__ == "__main__":
    main()
