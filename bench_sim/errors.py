"""User-facing errors and warnings.

The CLI prints a :class:`BenchSimError`'s message as one line and exits with status 2, and a
:class:`ConfigWarning` as one line starting ``bench-sim: warning:`` (the run goes on).
"""

from __future__ import annotations

__all__ = ["BenchSimError", "ConfigWarning"]


class BenchSimError(ValueError):
    """A bad config, input file, argument or environment (no room, no permission). The message
    is one line naming what is wrong: the key or file, the value, and what is allowed."""


class ConfigWarning(UserWarning):
    """A legal but odd config (e.g. an output word narrower than one pixel's range): one line
    with the numbers, the run goes on."""
