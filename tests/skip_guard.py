"""Skips fail unless listed: with ``--strict-skips`` (``make test``, ``make test-fast``) or the
environment variable ``CI`` set, a test or test module that is skipped fails the session unless
its node id matches a pattern of ``tests/allowed_skips.txt``.

The file holds one ``PATTERN  # reason`` a line (``fnmatch`` patterns on node ids such as
``tests/test_x.py::test_y[param]``); a pattern without a reason is an error. Lines starting
with ``#`` and blank lines are ignored. ``tests/conftest.py`` registers the hooks below.
"""

from __future__ import annotations

import fnmatch
import os
from collections.abc import Generator
from pathlib import Path
from typing import Any

import pytest

ALLOWED_SKIPS = Path(__file__).with_name("allowed_skips.txt")
OPTION = "--strict-skips"
_ALLOWED_KEY = pytest.StashKey[dict[str, str] | None]()


def read_allowed(path: Path | None = None) -> dict[str, str]:
    """``{pattern: reason}`` of an allow-list file (default :data:`ALLOWED_SKIPS`);
    :class:`pytest.UsageError` for a line with no reason (every listed skip says why it may happen)."""
    path = ALLOWED_SKIPS if path is None else path
    allowed: dict[str, str] = {}
    for n, raw in enumerate(path.read_text().splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        pattern, sep, reason = line.partition(" #")
        if not sep or not reason.strip() or not pattern.strip():
            raise pytest.UsageError(f"{path}:{n}: '{line}': give 'PATTERN  # reason'")
        allowed[pattern.strip()] = reason.strip()
    return allowed


def is_listed(nodeid: str, allowed: dict[str, str]) -> bool:
    return any(fnmatch.fnmatchcase(nodeid, pattern) for pattern in allowed)


def strict(config: pytest.Config) -> bool:
    """Skips are checked with ``--strict-skips`` or where ``CI`` is set (and not ``0``/``false``)."""
    ci = os.environ.get("CI", "").strip().lower()
    return bool(config.getoption(OPTION)) or ci not in ("", "0", "false", "no")


def _reason(longrepr: Any) -> str:
    """The skip message of a report's ``longrepr`` (``(file, line, 'Skipped: why')`` for skips)."""
    if isinstance(longrepr, tuple) and len(longrepr) == 3:
        return str(longrepr[2])
    return str(longrepr)


def _fail_unlisted(report: pytest.CollectReport | pytest.TestReport, config: pytest.Config) -> None:
    allowed = config.stash.get(_ALLOWED_KEY, None)  # None: skips are not checked in this session
    if allowed is None or not report.skipped or hasattr(report, "wasxfail"):
        return
    if is_listed(report.nodeid, allowed):
        return
    report.outcome = "failed"
    report.longrepr = (
        f"{report.nodeid} was skipped ({_reason(report.longrepr)}), and a skip fails here unless "
        f"its node id is listed with a reason in tests/{ALLOWED_SKIPS.name}"
    )


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        OPTION, action="store_true", default=False,
        help="a skipped test fails unless listed in tests/allowed_skips.txt (also where CI is set)",
    )


def pytest_configure(config: pytest.Config) -> None:
    """Decide once whether skips are checked, and read the allow-list before any test runs (a
    line without a reason stops the session)."""
    config.stash[_ALLOWED_KEY] = read_allowed() if strict(config) else None


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(
    item: pytest.Item, call: pytest.CallInfo[None]
) -> Generator[None, pytest.TestReport, pytest.TestReport]:
    report = yield
    _fail_unlisted(report, item.config)
    return report


@pytest.hookimpl(wrapper=True)
def pytest_make_collect_report(
    collector: pytest.Collector,
) -> Generator[None, pytest.CollectReport, pytest.CollectReport]:
    report = yield
    _fail_unlisted(report, collector.config)
    return report
