"""User-facing errors and warnings.

The CLI prints a :class:`BenchSimError`'s message as one line and exits with status 2, and a
:class:`ConfigWarning` as one line starting ``bench-sim: warning:`` (the run goes on).
"""

from __future__ import annotations

__all__ = ["BenchSimError", "ClusterError", "ConfigWarning", "note_kept", "kept_note"]


class BenchSimError(ValueError):
    """A bad config, input file, argument or environment (no room, no permission). The message
    is one line naming what is wrong: the key or file, the value, and what is allowed."""


class ConfigWarning(UserWarning):
    """A legal but odd config (e.g. an output word narrower than one pixel's range): one line
    with the numbers, the run goes on."""


class ClusterError(BenchSimError):
    """The Dask cluster was lost during a run (the scheduler went away) or never became usable
    (no worker connected): one line, exit status 3 (:attr:`exit_status`), distinct from a bad
    input's 2; the tasks finished before it are kept for ``--resume``."""

    #: exit status of the command line for this error
    exit_status = 3


#: Prefix of the note (PEP 678) by which an interrupted run says what it kept
_KEPT = "bench_sim kept: "


def note_kept(exc: BaseException, text: str) -> None:
    """Attach to ``exc`` (Ctrl-C, SIGTERM, a lost cluster) what the interrupted run kept and how
    to resume, e.g. ``"3 of 8 points kept in DIR; finish with --resume"``: the command line
    prints it in place of "no partial output was left"."""
    exc.add_note(_KEPT + text)


def kept_note(exc: BaseException) -> str | None:
    """The text of :func:`note_kept` attached to ``exc`` (the last one), if any."""
    notes = [n[len(_KEPT):] for n in getattr(exc, "__notes__", ())
             if isinstance(n, str) and n.startswith(_KEPT)]
    return notes[-1] if notes else None
