"""``python -m bench_sim`` and the ``bench-sim`` script: the command line of :mod:`bench_sim.cli`.

Ctrl-C while the command line is still being imported (before :mod:`bench_sim.cli` takes over
signals and errors) is one line and exit status 130 as well, not a traceback.
"""

from __future__ import annotations

import signal
import sys
from typing import Any


def _early_interrupt(signum: int, frame: Any) -> None:
    print("bench-sim: interrupted: stopped by Ctrl-C; nothing was written", file=sys.stderr, flush=True)
    raise SystemExit(130)


def main() -> None:
    """Import the command line with Ctrl-C handled, then run it."""
    previous = signal.signal(signal.SIGINT, _early_interrupt)
    from bench_sim.cli import app

    signal.signal(signal.SIGINT, previous)
    app()


if __name__ == "__main__":
    main()
