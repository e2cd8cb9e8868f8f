"""Skips fail unless listed (tests/skip_guard.py): run on small generated test files with pytest's
``pytester``, and the committed allow-list names tests that exist."""

from __future__ import annotations

import ast
import fnmatch
from pathlib import Path

import pytest

from tests import skip_guard

ROOT = Path(__file__).resolve().parents[1]

CONFTEST = (
    "from tests.skip_guard import pytest_addoption, pytest_configure, pytest_make_collect_report, "
    "pytest_runtest_makereport\n"
)
TESTS = """
import pytest

def test_runs():
    pass

def test_skips_in_the_body():
    pytest.skip("no reason to run")

@pytest.mark.skipif(True, reason="marked")
def test_skipped_by_a_mark():
    pass

@pytest.mark.xfail(reason="known", strict=True)
def test_expected_to_fail():
    assert False
"""
MODULE_SKIP = "import pytest\npytest.importorskip('no_such_module_here')\n\ndef test_x():\n    pass\n"


@pytest.fixture
def guarded(pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch) -> pytest.Pytester:
    monkeypatch.delenv("CI", raising=False)
    monkeypatch.setattr(skip_guard, "ALLOWED_SKIPS", pytester.path / "allowed.txt")
    pytester.makeconftest(CONFTEST)
    pytester.makepyfile(test_some=TESTS)
    return pytester


def _allow(pytester: pytest.Pytester, *lines: str) -> None:
    (pytester.path / "allowed.txt").write_text("# listed skips\n\n" + "\n".join(lines) + "\n")


def test_skips_pass_where_not_checked(guarded: pytest.Pytester) -> None:
    _allow(guarded)
    guarded.runpytest("-p", "no:cacheprovider").assert_outcomes(passed=1, skipped=2, xfailed=1)


@pytest.mark.parametrize("how", ["option", "CI", "xdist"])
def test_an_unlisted_skip_fails_where_checked(guarded: pytest.Pytester, monkeypatch, how: str) -> None:
    """Also in pytest-xdist's worker processes (make test), whose reports the main process counts."""
    _allow(guarded)
    args = {"option": ["--strict-skips"], "CI": [], "xdist": ["--strict-skips", "-n", "2"]}[how]
    if how == "CI":
        monkeypatch.setenv("CI", "true")
    if how == "xdist":  # the workers import tests.skip_guard (and read the committed list, which
        monkeypatch.setenv("PYTHONPATH", str(ROOT))  # lists none of these tests)
    res = guarded.runpytest("-p", "no:cacheprovider", *args)
    # the body's skip fails in the call, the mark's in the set-up; an xfail is not a skip
    res.assert_outcomes(passed=1, failed=1, errors=1, xfailed=1)
    res.stdout.fnmatch_lines(["*::test_skips_in_the_body was skipped (Skipped: no reason to run), and*"])
    assert res.ret == pytest.ExitCode.TESTS_FAILED


def test_a_listed_skip_stays_a_skip(guarded: pytest.Pytester) -> None:
    _allow(guarded, "test_some.py::test_skips_in_the_body  # a reason", "*::test_skipped_by_*  # another")
    res = guarded.runpytest("-p", "no:cacheprovider", "--strict-skips")
    res.assert_outcomes(passed=1, skipped=2, xfailed=1)
    assert res.ret == pytest.ExitCode.OK


def test_a_skipped_module_fails_collection_unless_listed(guarded: pytest.Pytester) -> None:
    guarded.makepyfile(test_module_skip=MODULE_SKIP)
    _allow(guarded, "test_some.py::*  # all of it")
    res = guarded.runpytest("-p", "no:cacheprovider", "--strict-skips")
    res.stdout.fnmatch_lines(["*test_module_skip.py was skipped*no_such_module_here*"])
    assert res.ret == pytest.ExitCode.INTERRUPTED  # a collection error stops the session
    _allow(guarded, "test_some.py::*  # all of it", "test_module_skip.py  # the module")
    res = guarded.runpytest("-p", "no:cacheprovider", "--strict-skips")
    res.assert_outcomes(passed=1, skipped=3, xfailed=1)


def test_a_listed_pattern_needs_a_reason(guarded: pytest.Pytester) -> None:
    line = "test_some.py::test_skips_in_the_body"
    _allow(guarded, line)
    res = guarded.runpytest("-p", "no:cacheprovider", "--strict-skips")
    assert res.ret == pytest.ExitCode.USAGE_ERROR
    res.stderr.fnmatch_lines([f"*allowed.txt:3: '{line}': give 'PATTERN  # reason'"])
    assert "collected" not in res.stdout.str()  # stopped before any test ran


def test_every_listed_skip_names_a_test_that_exists() -> None:
    """Each pattern of the committed list matches a test function of a file in tests/ (a list
    that outlives its tests would allow skips nobody meant)."""
    allowed = skip_guard.read_allowed()
    for pattern, reason in allowed.items():
        assert len(reason.split()) >= 3, (pattern, reason)
        file_part, _, name_part = pattern.partition("::")
        files = [p for p in ROOT.glob(file_part) if p.is_file()] if file_part else []
        assert files, f"{pattern}: no such test file"
        names = {
            f"{p.relative_to(ROOT)}::{node.name}"
            for p in files
            for node in ast.walk(ast.parse(p.read_text()))
            if isinstance(node, ast.FunctionDef) and node.name.startswith("test")
        }
        head = pattern.split("[", 1)[0]
        assert not name_part or any(fnmatch.fnmatchcase(n, head) for n in names), f"{pattern}: no such test"
