"""Ctrl-C and SIGTERM at every moment of a ``bench-sim`` process (issue 32), with real
processes where it matters:

1. a signal while the main thread imports is not raised inside the import (where it could leave
   the import lock held and hang the process) but just after it; the import machinery's own
   frames (a module lock's callback, a finder) count as importing;
2. SIGTERM in the first second of a command (while the command line itself is imported) is one
   line and exit status 143, as Ctrl-C is one line and 130;
3. Ctrl-C while a local Dask cluster starts is held, then delivered when the start ends: exit
   130 with the usual line, never a run that goes on to the end and exits 0;
4. the stress series of ``scripts/ctrl_c_stress.py`` (SIGINT and SIGTERM at random moments of
   ``simulate``, ``reproduce``, ``sweep`` and ``dataset``, with a CPU burner running) at a reduced
   count: no hang, no exit 0 after a signal, one line, nothing partial left. The full series (50
   signals per command) and its result: ``docs/reliability.md``.
"""

from __future__ import annotations

import importlib
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import FrameType

import pytest

from bench_sim.io.interrupts import importing

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))
import ctrl_c_stress  # noqa: E402 - the stress script, run at a reduced count

CLI = [sys.executable, "-m", "bench_sim"]


def _env() -> dict[str, str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "BENCH_SIM_THREADS": "1"}
    env.pop("BENCH_SIM_DEBUG", None)
    return env


def _lines(text: str) -> list[str]:
    return [ln for ln in text.splitlines() if ln.strip()]


# --- 1. never inside an import ---------------------------------------------------------------------


#: a child process's run of one signal case: the module NAME (in TMP) sends SIG to its own process
#: half-way through its body, inside ``command_signals``; PRELUDE runs first. It prints what it saw
#: and, half a second after the block, "clean" (a late second delivery would have killed it).
_IMPORT_CASE = """
import importlib, signal, sys, threading, time, _imp
from bench_sim.io import interrupts
from bench_sim.io.interrupts import REDELIVER_S, Terminated, command_signals
sys.path.insert(0, TMP)
PRELUDE
exc = KeyboardInterrupt if SIG == signal.SIGINT else Terminated
imported, start, took = False, 0.0, None
try:
    with command_signals():
        start = time.monotonic()
        module = importlib.import_module(NAME)
        imported = module.DONE
        deadline = time.monotonic() + 50 * REDELIVER_S + 2.0
        while time.monotonic() < deadline:  # the signal comes again once the import is over
            pass
except exc:
    took = time.monotonic() - start
print("raised" if took is not None else "not raised", imported, NAME in sys.modules, took)
time.sleep(0.5)
print("clean")
"""


def _signal_in_import(tmp_path: Path, sig: int, prelude: str = "") -> list[str]:
    """Run :data:`_IMPORT_CASE` in a fresh process (a signal test in the test process itself
    would share its handlers and its pending signals with every other test there)."""
    name = f"bench_sim_test_signal_in_import_{sig}"
    (tmp_path / f"{name}.py").write_text(
        "import signal\n"
        f"signal.raise_signal({int(sig)})\n"
        "total = sum(range(200000))  # bytecodes after the signal, inside the import\n"
        "DONE = True\n"
    )
    code = (_IMPORT_CASE.replace("PRELUDE", prelude)
            .replace("TMP)", f"{str(tmp_path)!r})").replace("NAME)", f"{name!r})")
            .replace("NAME in", f"{name!r} in").replace("SIG ==", f"{int(sig)} =="))
    res = subprocess.run([sys.executable, "-c", code], env=_env(), capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0, (res.returncode, res.stdout, res.stderr[-2000:])
    return _lines(res.stdout)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_during_an_import_is_raised_just_after_it(tmp_path: Path, sig: int) -> None:
    """The module sends the signal to its own process half-way through its body: the body runs
    to its end (the import completes, the module is in ``sys.modules``), the exception comes a
    moment later, in the caller, not inside the import, and only once."""
    said = _signal_in_import(tmp_path, sig)
    assert said[0].startswith("raised True True") and said[-1] == "clean", said


def test_a_signal_an_earlier_run_left_pending_does_not_end_the_next(tmp_path: Path) -> None:
    """An earlier command run in this process whose deferred signal was then taken by other
    handlers leaves no pending mark: a signal during the next run's import is raised just after
    the import, as in a fresh process, not taken for an import that never ended (which ended the
    process: a crashed test worker)."""
    stale = ("interrupts._redelivery().since[signal.SIGINT] = "
             "time.monotonic() - 2 * interrupts.IMPORT_PATIENCE_S")
    said = _signal_in_import(tmp_path, signal.SIGINT, stale)
    assert said[0].startswith("raised True True") and said[-1] == "clean", said


_LOCK_HELD_CASE = """
import signal, threading, time, _imp
from bench_sim.io.interrupts import command_signals
held = threading.Event()
def hold():
    _imp.acquire_lock()
    held.set()
    time.sleep(5.0)
    _imp.release_lock()
threading.Thread(target=hold, daemon=True).start()
held.wait(5.0)
took = None
try:
    with command_signals():
        start = time.monotonic()
        signal.raise_signal(signal.SIGINT)
        while time.monotonic() - start < 8.0:
            pass
except KeyboardInterrupt:
    took = time.monotonic() - start
print(took)
"""


def test_another_thread_holding_the_import_lock_does_not_hold_back_a_signal() -> None:
    """A thread that holds the global import lock (an import beside the command at a low
    priority, starved on a loaded machine) does not make the main thread count as importing:
    Ctrl-C is raised at once (in a fresh process), not when that thread lets go (5 s)."""
    res = subprocess.run([sys.executable, "-c", _LOCK_HELD_CASE], env=_env(), capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0, (res.returncode, res.stdout, res.stderr[-2000:])
    assert res.stdout.strip() != "None" and float(res.stdout) < 1.0, res.stdout


_LATE_CASE = """
import signal, time
from bench_sim.io import interrupts
from bench_sim.io.interrupts import command_signals
with command_signals():
    interrupts._redelivery().later(signal.SIGINT)  # deferred, as during an import
time.sleep(0.5)  # the run is over: its signal is not sent again into what follows
print("clean")
"""


def test_a_signal_deferred_as_a_run_ends_is_not_sent_into_what_follows() -> None:
    """A signal deferred (during an import) just before an in-process run ends is dropped with
    the run's handlers, not sent again into the caller (a notebook, the test process): there it
    raised KeyboardInterrupt, or a SIGTERM killed the process, after the run had ended."""
    res = subprocess.run([sys.executable, "-c", _LATE_CASE], env=_env(), capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0 and res.stdout.strip() == "clean", (res.returncode, res.stdout, res.stderr)


_GC_CALLBACK_CASE = """
import gc, signal, time
from bench_sim.io.interrupts import command_signals
fired = []
def callback(phase, info):
    if phase == "stop" and not fired:
        fired.append(1)
        signal.raise_signal(signal.SIGINT)  # its handler runs at the next bytecode: in here
        sum(range(100))
t0 = time.monotonic()
try:
    with command_signals():
        gc.callbacks.append(callback)
        gc.collect()
        while time.monotonic() - t0 < 5.0:
            time.sleep(0.01)
    print("lost")
except KeyboardInterrupt:
    print("raised after", round(time.monotonic() - t0, 2), "s")
"""


def test_a_signal_raised_inside_a_garbage_collector_callback_is_sent_again() -> None:
    """Python drops an exception raised in a garbage collector's callback ("Exception ignored");
    a signal's exception raised there is sent again a moment later and raised where the command
    can stop (Dask's ``GCDiagnosis`` callback in a sweep's client swallowed a Ctrl-C once in the
    stress series, and the sweep exited 0)."""
    res = subprocess.run([sys.executable, "-c", _GC_CALLBACK_CASE], env=_env(), capture_output=True,
                         text=True, timeout=120)
    assert res.returncode == 0, (res.returncode, res.stdout, res.stderr[-2000:])
    assert res.stdout.startswith("raised after"), (res.stdout, res.stderr[-2000:])
    assert float(res.stdout.split()[2]) < 2.0 and "Exception ignored" not in res.stderr, res.stderr


_LEAVING_CASE = """
from bench_sim.io import interrupts
interrupts._LEAVING.append(2)  # a first leave_now on its way out (its line written)
interrupts.leave_now(2, " as the command ended")
print("returned")
"""


def test_leave_now_says_its_line_once() -> None:
    """A handler that runs inside ``leave_now`` (a signal sent again meanwhile, between its write
    and its exit) returns instead of writing a second line: the stress series once saw two."""
    res = subprocess.run([sys.executable, "-c", _LEAVING_CASE], env=_env(), capture_output=True, text=True,
                         timeout=120)
    assert (res.returncode, res.stdout.strip(), res.stderr) == (0, "returned", ""), res


def test_the_import_machinery_counts_as_importing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A frame seen from inside the import system (a finder on ``sys.meta_path``, called with
    the module locks of ``importlib._bootstrap`` around it) is importing; the test's own frame
    is not."""
    seen: list[FrameType] = []

    class Spy:
        def find_spec(self, fullname: str, path: object, target: object = None) -> None:
            if fullname == "bench_sim_test_no_such_module":
                seen.append(sys._getframe())
            return None

    monkeypatch.setattr(sys, "meta_path", [Spy(), *sys.meta_path])
    with pytest.raises(ImportError):
        importlib.import_module("bench_sim_test_no_such_module")
    assert seen and importing(seen[0])
    assert not importing(sys._getframe())


def test_what_an_interrupted_step_leaves_open_is_not_reported(capsys: pytest.CaptureFixture[str]) -> None:
    """A socket the interrupted step left open, collected while it unwinds, is no warning line
    (the stress series saw ``unclosed <socket ...>`` lines before the interrupted line)."""
    import warnings

    import typer

    from bench_sim.cli import guarded

    def body() -> None:
        try:
            signal.raise_signal(signal.SIGINT)
            time.sleep(5)  # the KeyboardInterrupt comes here
        finally:
            warnings.warn("unclosed <socket object, fd=8>", ResourceWarning, stacklevel=1)

    with pytest.raises(typer.Exit) as exc:
        guarded(body)
    err = capsys.readouterr().err
    assert exc.value.exit_code == 130
    assert err.splitlines() == ["bench-sim: interrupted: stopped by Ctrl-C; no partial output was left "
                                "(an earlier complete output is kept)"], err

    def leaves_a_socket_open() -> None:
        warnings.warn("unclosed <socket object, fd=8>", ResourceWarning, stacklevel=1)

    guarded(leaves_a_socket_open)  # without a signal, the same warning is its line
    assert "ResourceWarning: unclosed <socket object, fd=8>" in capsys.readouterr().err


# --- 2. SIGTERM from the first instruction -------------------------------------------------------


def _catches(pid: int, sig: int) -> bool:
    """Whether process ``pid`` has a handler for ``sig`` (its ``SigCgt`` mask)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    mask = int(status.split("SigCgt:")[1].split()[0], 16)
    return bool(mask >> (sig - 1) & 1)


@pytest.mark.parametrize("after_s", [0.0, 0.25])
def test_sigterm_in_the_first_second_of_simulate_is_one_line_and_143(tmp_path: Path, after_s: float) -> None:
    """SIGTERM at bench_sim's first statement (the moment its handler exists: before, the
    interpreter's own start-up, a few tens of ms, has the default action) and a moment later,
    while the command line is imported: one line and 143 (before: killed without a word)."""
    out = tmp_path / "sim"
    proc = subprocess.Popen([*CLI, "simulate", "--out", str(out)], cwd=tmp_path, env=_env(),
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    t0 = time.monotonic()
    while not _catches(proc.pid, signal.SIGTERM):
        assert proc.poll() is None and time.monotonic() - t0 < 30, "bench_sim never started"
    time.sleep(after_s)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    lines = _lines(err)
    assert proc.returncode == 143, err
    assert len(lines) == 1 and lines[0].startswith("bench-sim: terminated: stopped by SIGTERM"), lines
    assert not out.exists() and not [p for p in tmp_path.iterdir() if ".partial-" in p.name]


# --- 3. Ctrl-C while a local cluster starts --------------------------------------------------------


def _children(pid: int) -> list[int]:
    kids: list[int] = []
    for task in os.listdir(f"/proc/{pid}/task"):
        try:
            kids += [int(k) for k in Path(f"/proc/{pid}/task/{task}/children").read_text().split()]
        except OSError:
            pass
    return kids


def _is_worker(pid: int) -> bool:
    try:
        return b"spawn_main" in Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return False


@pytest.mark.slow
def test_ctrl_c_while_the_local_cluster_starts_is_delivered_when_the_start_ends(tmp_path: Path) -> None:
    """SIGINT to the process group as soon as the first worker process exists (the cluster is
    starting): before, SIGINT was ignored for the whole start and the sweep ran to its end, exit
    0. Now: exit 130, one line, no point computed, no worker's traceback, no process left."""
    ctrl_c_stress.write_specs(tmp_path)
    out = tmp_path / "sweep"
    proc = subprocess.Popen(
        [*CLI, "sweep", str(tmp_path / "sweep.toml"), "--out", str(out), "--workers", "2", "--no-plots"],
        cwd=tmp_path, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        start_new_session=True,
    )
    try:
        t0 = time.monotonic()
        while not any(_is_worker(k) for k in _children(proc.pid)):
            assert proc.poll() is None and time.monotonic() - t0 < 120, "no worker process started"
            time.sleep(0.005)
        os.killpg(proc.pid, signal.SIGINT)
        out_text, err = proc.communicate(timeout=120)
    finally:
        ctrl_c_stress._kill_session(proc.pid)
    lines = _lines(err)
    assert proc.returncode == 130, (out_text, err)
    assert len(lines) == 1 and lines[0].startswith("bench-sim: interrupted: stopped by Ctrl-C"), lines
    assert not list(out.glob("points/*.json"))
    time.sleep(1.0)
    assert not ctrl_c_stress._session_alive(proc.pid)


@pytest.mark.slow
@pytest.mark.parametrize("command", ["sweep", "dataset", "design"])
def test_ctrl_c_after_the_points_still_says_what_is_kept(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, command: str
) -> None:
    """Ctrl-C once every point (sample) is done, while the cluster closes or the last files are
    written: the line says what is kept and how to finish (before: "no partial output was left",
    while the folder held every finished record)."""
    from typer.testing import CliRunner

    from bench_sim.cli import app
    from bench_sim.workflows.dataset import run as dataset_run
    from bench_sim.workflows.design import run as design_run
    from bench_sim.workflows.sweep import run as sweep_run

    def interrupted(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    if command == "sweep":
        monkeypatch.setattr(sweep_run, "write_outputs", interrupted)
        kept = r"4 of 4 points finished are kept in .*; finish with 'bench-sim sweep .* --resume'"
    elif command == "design":
        monkeypatch.setattr(design_run, "write_report", interrupted)
        kept = r"2 of 2 points finished are kept in .*; finish with 'bench-sim design .* --resume'"
    else:
        monkeypatch.setattr(dataset_run, "write_card", interrupted)
        kept = r"4 of 4 samples complete are kept in .*; finish with 'bench-sim dataset .* --resume'"
    ctrl_c_stress.write_specs(tmp_path)
    out = tmp_path / "out"
    res = CliRunner().invoke(app, [command, str(tmp_path / f"{command}.toml"), "--out", str(out),
                                   "--workers", "0", *(["--no-plots"] if command != "dataset" else [])])
    assert res.exit_code == 130, res.output
    lines = _lines(res.stderr)
    assert len(lines) == 1, lines
    assert re.match(rf"bench-sim: interrupted: stopped by Ctrl-C; {kept}", lines[0]), lines


@pytest.mark.slow
@pytest.mark.parametrize("command", ["sweep", "design"])
def test_a_signal_during_the_netcdf_write_is_held_until_it_ends(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, command: str
) -> None:
    """SIGTERM as ``sweep.nc`` (``design.nc``) starts to be written: the write completes (whole
    and readable) and the signal is delivered just after it. Cut inside xarray and HDF5, it left
    their locks held, and the store's own close then waited for ever (the hang the stress series
    found)."""
    import xarray as xr
    from typer.testing import CliRunner

    from bench_sim.cli import app

    real = xr.Dataset.to_netcdf

    def signalled(self: xr.Dataset, *args: object, **kwargs: object) -> object:
        signal.raise_signal(signal.SIGTERM)
        return real(self, *args, **kwargs)

    monkeypatch.setattr(xr.Dataset, "to_netcdf", signalled)
    ctrl_c_stress.write_specs(tmp_path)
    out = tmp_path / "out"
    res = CliRunner().invoke(app, [command, str(tmp_path / f"{command}.toml"), "--out", str(out),
                                   "--workers", "0", "--no-plots"])
    assert res.exit_code == 143, res.output
    last = _lines(res.stderr)[-1]
    assert last.startswith("bench-sim: terminated: stopped by SIGTERM;"), last
    with xr.open_dataset(out / f"{command}.nc") as ds:  # whole: the spec's grid / every candidate
        if command == "sweep":
            assert "4 of 4 points" in last
            assert dict(ds.sizes) == {"lights.strong.irradiance_w_m2": 2, "lights.weak.irradiance_w_m2": 2}
        else:
            assert "2 of 2 points" in last
            assert ds.sizes["candidate"] == len(ds["rule"]) and set(ds["rule"].values) == {"eq11", "clip"}


# --- 4. the stress series, reduced ---------------------------------------------------------------


@pytest.mark.slow
def test_signals_at_random_moments_under_load(capsys: pytest.CaptureFixture[str]) -> None:
    """Two signals (one SIGINT, one SIGTERM) per long command at uniformly random moments of its
    first 4 s, a CPU burner running: every run passes the checks of ``scripts/ctrl_c_stress.py``."""
    args = ["-n", "2", "--burn", "1", "--window", "4", "--seed", "32", "--timeout", "60"]
    status = ctrl_c_stress.main(args)
    report = capsys.readouterr().out
    assert status == 0, report
    assert report.count("2 of 2 runs stopped cleanly") == len(ctrl_c_stress.COMMANDS), report


@pytest.mark.slow
@pytest.mark.stress
@pytest.mark.parametrize("command", sorted(ctrl_c_stress.COMMANDS))
def test_fifty_signals_at_random_moments_under_load(command: str, capsys: pytest.CaptureFixture[str]) -> None:
    """The full series of point 2 for one command: 50 signals (SIGINT and SIGTERM in turn) at
    uniformly random moments of its run, two CPU burners running; every run stops cleanly.
    ``make test-stress`` (about 7 minutes per command on 2 cores; ``make test`` deselects it)."""
    status = ctrl_c_stress.main(["-n", "50", "--burn", "2", "--seed", "32", "--commands", command])
    report = capsys.readouterr().out
    assert status == 0, report
    assert "50 of 50 runs stopped cleanly" in report, report
