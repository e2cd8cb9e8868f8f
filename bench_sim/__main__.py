"""``python -m bench_sim`` and the ``bench-sim`` script: the command line of :mod:`bench_sim.cli`.

Ctrl-C while this module imports the command line (before :mod:`bench_sim.cli` takes over
signals and errors) is one line and exit status 130 as well, not a traceback. (The package
itself, ``bench_sim/__init__.py``, runs before this module and imports nothing.)
"""

from __future__ import annotations

import os
import signal
from typing import Any


def _early_interrupt(signum: int, frame: Any) -> None:
    # Nothing has been written yet, and an exception raised here would land inside whatever
    # module is importing (a C extension's initialisation, the import lock held): leave at once,
    # with one line, without unwinding (no Python code of the interrupted import runs again).
    os.write(2, b"bench-sim: interrupted: stopped by Ctrl-C during start-up; nothing was written\n")
    os._exit(130)


_PREVIOUS_SIGINT = signal.signal(signal.SIGINT, _early_interrupt)
from bench_sim.cli import app  # noqa: E402 - imported with Ctrl-C handled

signal.signal(signal.SIGINT, _PREVIOUS_SIGINT)


def main() -> None:
    """Run the command line."""
    app()


if __name__ == "__main__":
    main()
