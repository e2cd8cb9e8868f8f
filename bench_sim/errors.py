"""User-facing errors: the CLI prints their message as one line and exits with status 2."""

from __future__ import annotations

__all__ = ["BenchSimError"]


class BenchSimError(ValueError):
    """A bad config, input file or argument. The message is one line naming what is wrong:
    the key or file, the value, and what is allowed."""
