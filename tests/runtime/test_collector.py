"""The garbage collector of a bench-sim process (bench_sim.runtime.collector)."""

from __future__ import annotations

import gc
import subprocess
import sys

import pytest

from bench_sim.runtime import collector


def test_settle_freezes_only_in_bench_sims_own_process(monkeypatch: pytest.MonkeyPatch) -> None:
    held = [object() for _ in range(3)] + [[]]  # a tracked object
    frozen = gc.get_freeze_count()
    assert collector.settle() is False and gc.get_freeze_count() == frozen
    monkeypatch.setattr(collector, "_OWN", True)
    try:
        assert collector.settle() is True
        assert gc.get_freeze_count() > frozen  # the list above among them
    finally:
        gc.unfreeze()  # this test process is not bench-sim's: everything back to the collector
    assert held


@pytest.mark.parametrize("enabled", [True, False])
def test_paused_turns_the_collector_off_and_back_to_what_it_was(enabled: bool) -> None:
    was = gc.isenabled()
    (gc.enable if enabled else gc.disable)()
    try:
        with collector.paused():
            assert not gc.isenabled()
        assert gc.isenabled() is enabled
        with pytest.raises(RuntimeError), collector.paused():
            raise RuntimeError("an import that fails")
        assert gc.isenabled() is enabled
    finally:
        (gc.enable if was else gc.disable)()


def test_the_program_settles_the_command_line() -> None:
    """``bench-sim`` (its program module) freezes what importing the command line made; a plain
    import of the package freezes nothing."""
    code = ("import gc, runpy, sys; sys.argv = ['bench-sim', '--help']\n"
            "try:\n    runpy.run_module('bench_sim', run_name='__main__')\n"
            "except SystemExit:\n    pass\n")
    probe = ("import atexit, gc, os\n"
             "atexit.register(lambda: os.write(2, b'FROZEN %d\\n' % gc.get_freeze_count()))\n")
    done = subprocess.run([sys.executable, "-c", probe + code], capture_output=True, text=True, timeout=120)
    lines = [ln for ln in done.stderr.splitlines() if ln.startswith("FROZEN")]
    plain = subprocess.run([sys.executable, "-c", "import gc, bench_sim.cli; print(gc.get_freeze_count())"],
                           capture_output=True, text=True, timeout=120, check=True)
    assert int(plain.stdout) == 0
    assert lines and int(lines[0].split()[1]) > 10_000, done.stderr[-2000:]


def test_settle_once_settles_the_first_time_only(monkeypatch: pytest.MonkeyPatch) -> None:
    """A worker's first task settles what its imports made; a later task's garbage is never frozen."""
    monkeypatch.setattr(collector, "_OWN", True)
    monkeypatch.setattr(collector, "_SETTLED_ONCE", False)
    try:
        assert collector.settle_once() is True
        frozen = gc.get_freeze_count()
        held = [[] for _ in range(100)]  # tracked objects made after it
        assert collector.settle_once() is False and gc.get_freeze_count() == frozen
    finally:
        gc.unfreeze()
    assert held
