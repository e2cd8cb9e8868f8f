"""Reliability of the many-run workflows (``sweep``, ``dataset``) and of Ctrl-C, with real
processes on the loopback interface only (127.0.0.1):

1. one writer per output folder: a second run is refused at once naming the first, the first
   finishes with its own data; a lock left by a killed run is taken over;
2. Ctrl-C and SIGTERM at random moments of the long commands: ``tests/test_signals.py`` (and
   ``scripts/ctrl_c_stress.py``, 50 signals per command);
3. ``--scheduler`` at something that is not a Dask scheduler (a socket that accepts and never
   answers, an HTTP server, a bad address): refused in one line within the timeout; a scheduler
   with no worker: one line after the wait; a scheduler killed mid-sweep: one line, exit 3, the
   finished points kept, and ``--resume`` gives the data of an uninterrupted run;
4. seeds above 2**63-1 in specs refused before any work;
5. 10**9-point specs refused in under a second with the count in the message;
6. empty and truncated journal records recomputed (and an empty ``sweep.json`` rebuilt) on ``--resume``;
7. Ctrl-C with local workers is one line; no ResourceWarning; help texts keep ``[[parameters]]``
   and ``5:100:5``; a spec that is not UTF-8 is one line.
"""

from __future__ import annotations

import http.server
import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from bench_sim.cli import app
from bench_sim.config import DEFAULT_CONFIG_PATH
from bench_sim.io import OUTPUT_MARKER
from bench_sim.io.folder_lock import lock_path
from bench_sim.workflows.dataset.spec import load_spec as load_dataset_spec
from bench_sim.workflows.sweep.run import read_points, run_sweep
from bench_sim.workflows.sweep.spec import load_spec

ROOT = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "bench_sim"]
runner = CliRunner()

TINY_BASE = f"""
base = "{DEFAULT_CONFIG_PATH}"
name = "tiny"
lines = 48
[sensor]
rows = 12
columns = 48
[target]
panel_lines = 48
panel_columns = 48
[render]
spp = 8
[fusion]
mu1 = 2
mu2 = 8
"""

#: four points on one camera
SPEC = """
base = "tiny.toml"
seed = {seed}
[[parameters]]
key = "lights.strong.irradiance_w_m2"
values = [64.0, 256.0]
[[parameters]]
key = "lights.weak.irradiance_w_m2"
values = [3.0, 12.0]
"""

#: columns that depend on where and when a point ran
RUN_COLUMNS = ["wall_s", "worker", "mitsuba_renders"]


def _env(**extra: str) -> dict[str, str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "BENCH_SIM_THREADS": "1", **extra}
    env.pop("BENCH_SIM_DEBUG", None)
    return env


def _child(args: list[str], **env: str) -> subprocess.Popen:
    return subprocess.Popen([*CLI, *args], cwd=ROOT, env=_env(**env), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)


def _lines(text: str) -> list[str]:
    return [ln for ln in text.splitlines() if ln.strip()]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _wait_for(cond, timeout: float, what: str) -> None:
    t0 = time.monotonic()
    while not cond():
        if time.monotonic() - t0 > timeout:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


def _stop(procs: list[subprocess.Popen]) -> None:
    for p in procs:
        if p.poll() is None:
            p.terminate()
    for p in procs:
        try:
            p.wait(timeout=10)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
        for pipe in (p.stdout, p.stderr):
            if pipe is not None:
                pipe.close()


def _metrics(out: Path) -> pd.DataFrame:
    df = pd.read_csv(out / "points.csv", comment="#").drop(columns=RUN_COLUMNS)
    return df.sort_values("point").reset_index(drop=True)


@pytest.fixture(scope="module")
def specs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("specs")
    (folder / "tiny.toml").write_text(TINY_BASE)
    for seed in (11, 12):
        (folder / f"seed{seed}.toml").write_text(SPEC.format(seed=seed))
    return folder


@pytest.fixture(scope="module")
def reference(specs: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The uninterrupted sweep of ``seed11.toml`` (in this process)."""
    out = tmp_path_factory.mktemp("ref") / "sweep"
    run_sweep(specs / "seed11.toml", out, workers=0, progress=False, plots=False)
    return out


# --- 1. one writer per folder ----------------------------------------------------------------------


@pytest.mark.slow
def test_a_second_run_on_the_folder_is_refused_and_the_first_keeps_its_data(
    specs: Path, reference: Path, tmp_path: Path
) -> None:
    """Run A (seed 11, local Dask worker, warnings shown) holds the folder; run B (seed 12) on the
    same --out is refused at once naming A; A finishes with exactly the reference data and
    prints no ResourceWarning."""
    out = tmp_path / "shared"
    a = _child(["sweep", str(specs / "seed11.toml"), "--out", str(out), "--workers", "1", "--no-plots"],
               PYTHONWARNINGS="default")
    try:
        _wait_for(lambda: lock_path(out).is_file() and lock_path(out).read_text().strip(), 60, "A's lock")
        t0 = time.monotonic()
        b = subprocess.run([*CLI, "sweep", str(specs / "seed12.toml"), "--out", str(out), "--workers", "0"],
                           cwd=ROOT, env=_env(), capture_output=True, text=True, timeout=60)
        b_lines = _lines(b.stderr)
        assert b.returncode == 2, b.stderr
        assert len(b_lines) == 1 and f"pid {a.pid} on " in b_lines[0] and "in use by" in b_lines[0], b_lines
        assert time.monotonic() - t0 < 15  # at once: start-up, then refused before any work
        _, a_err = a.communicate(timeout=300)
    finally:
        _stop([a])
    assert a.returncode == 0, a_err
    assert "ResourceWarning" not in a_err and "Traceback" not in a_err, a_err
    pd.testing.assert_frame_equal(_metrics(out), _metrics(reference))
    records = read_points(out)
    assert {r["seed"] for r in records.values()} == {11}
    assert json.loads((out / "sweep.json").read_text())["seed"] == 11
    assert (out / OUTPUT_MARKER).is_file() and not lock_path(out).exists()


def test_a_live_lock_refuses_a_dataset_and_a_dead_ones_is_taken_over(tmp_path: Path) -> None:
    """Another process holds the lock of --out: ``dataset`` is refused in one line naming it, and
    nothing is written; once that process is killed (SIGKILL: no clean-up), the stale lock is
    taken over (the run gets past the lock to its next check)."""
    out = tmp_path / "ds"
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time\nfrom bench_sim.io.folder_lock import folder_lock\n"
         f"with folder_lock({str(out)!r}, 'dataset'):\n"
         "    print('locked', flush=True)\n    time.sleep(60)\n"],
        cwd=ROOT, env=_env(), stdout=subprocess.PIPE, text=True,
    )
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "locked"
        spec = tmp_path / "ds.toml"
        spec.write_text(f'base = "{DEFAULT_CONFIG_PATH}"\nsamples = 2\nseed = 1\nstages = [2, 8]\n')
        res = runner.invoke(app, ["dataset", str(spec), "--out", str(out), "--workers", "0"])
        assert res.exit_code == 2, res.output
        line = _lines(res.output)
        assert len(line) == 1 and f"pid {holder.pid} on {socket.gethostname()}, started " in line[0], line
        assert not out.exists()
        holder.kill()
        holder.wait()
        assert lock_path(out).is_file()  # left by the killed process
        res = runner.invoke(app, ["dataset", str(tmp_path / "missing.toml"), "--out", str(out)])
        assert res.exit_code == 2 and "in use" not in res.output and "no such file" in res.output, res.output
        assert not lock_path(out).exists()  # taken over, then released
    finally:
        _stop([holder])


# --- 3. Dask failure modes -------------------------------------------------------------------------


@pytest.fixture()
def silent_server() -> Iterator[str]:
    """A TCP socket on 127.0.0.1 that accepts connections and never sends a byte."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(8)
    conns: list[socket.socket] = []
    stop = threading.Event()

    def accept() -> None:
        srv.settimeout(0.2)
        while not stop.is_set():
            try:
                conns.append(srv.accept()[0])
            except OSError:
                continue

    t = threading.Thread(target=accept, daemon=True)
    t.start()
    try:
        yield f"tcp://127.0.0.1:{srv.getsockname()[1]}"
    finally:
        stop.set()
        t.join()
        for c in conns:
            c.close()
        srv.close()


@pytest.fixture()
def http_server() -> Iterator[str]:
    """An HTTP server on 127.0.0.1 (as a dashboard port would be) that answers at once."""

    class Quiet(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            self.send_response(200)
            self.end_headers()
            self.wfile.write(b"<html>dashboard</html>")

        def log_message(self, *args: object) -> None:
            pass

    srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Quiet)
    t = threading.Thread(target=srv.serve_forever, daemon=True)
    t.start()
    try:
        yield f"tcp://127.0.0.1:{srv.server_address[1]}"
    finally:
        srv.shutdown()
        srv.server_close()


@pytest.mark.parametrize("server", ["silent_server", "http_server"])
def test_something_that_is_not_a_scheduler_is_refused_within_the_timeout(
    specs: Path, tmp_path: Path, server: str, request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch
) -> None:
    address = request.getfixturevalue(server)
    monkeypatch.setenv("BENCH_SIM_CONNECT_TIMEOUT_S", "1.5")
    out = tmp_path / "o"
    t0 = time.monotonic()
    res = runner.invoke(app, ["sweep", str(specs / "seed11.toml"), "--out", str(out), "--scheduler", address])
    assert time.monotonic() - t0 < 1.5 + 5.0  # the timeout and the spec's checks
    assert res.exit_code == 2, res.output
    line = _lines(res.output)
    assert len(line) == 1 and line[0].startswith(f"bench-sim: error: --scheduler = '{address}': "), line
    assert "not a Dask scheduler" in line[0], line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("address", "why"),
    [("not-an-address", "not a scheduler address"), ("http://127.0.0.1:8787", "an HTTP address"),
     ("tcp://127.0.0.1:99999", "not a scheduler address"), ("tcp://127.0.0.1", "not a scheduler address")],
)
def test_bad_scheduler_addresses_are_one_line(specs: Path, tmp_path: Path, address: str, why: str) -> None:
    res = runner.invoke(app, ["sweep", str(specs / "seed11.toml"), "--out", str(tmp_path / "o"),
                              "--scheduler", address])
    assert res.exit_code == 2, res.output
    line = _lines(res.output)
    assert len(line) == 1 and why in line[0], line
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_no_worker_then_a_scheduler_killed_mid_sweep_then_resume(
    specs: Path, reference: Path, tmp_path: Path
) -> None:
    """A real ``dask scheduler`` on 127.0.0.1: with no worker the sweep is refused after the wait
    (one line, exit 3, nothing written); with a worker, the scheduler is SIGKILLed after the
    first point: one line, exit 3, the finished points kept; ``--resume`` (in this process)
    then gives the points of the uninterrupted run."""
    dask = str(Path(sys.executable).with_name("dask"))
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    out = tmp_path / "killed"
    null = subprocess.DEVNULL
    sched = subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", str(port),
                              "--no-dashboard"], env=_env(), stdout=null, stderr=null)
    procs = [sched]
    try:
        def listening() -> bool:
            with socket.socket() as s:
                return s.connect_ex(("127.0.0.1", port)) == 0

        _wait_for(listening, 60, "the scheduler")
        lonely = subprocess.run(
            [*CLI, "sweep", str(specs / "seed11.toml"), "--out", str(out), "--scheduler", address],
            cwd=ROOT, env=_env(BENCH_SIM_WORKER_WAIT_S="1"), capture_output=True, text=True, timeout=120,
        )
        assert lonely.returncode == 3, lonely.stderr
        assert _lines(lonely.stderr)[-1].startswith(f"bench-sim: error: --scheduler = '{address}': 0 workers "
                                                    "connected after 1 s"), lonely.stderr
        assert not out.exists()
        procs.append(subprocess.Popen(
            [dask, "worker", address, "--nthreads", "1", "--nworkers", "1", "--host", "127.0.0.1",
             "--no-dashboard"], env=_env(), cwd=tmp_path, stdout=null, stderr=null))
        run = _child(["sweep", str(specs / "seed11.toml"), "--out", str(out), "--scheduler", address,
                      "--no-plots"])
        procs.append(run)
        _wait_for(lambda: any((out / "points").glob("*.json")), 240, "the first point")
        sched.kill()
        _, err = run.communicate(timeout=120)
        lines = _lines(err)
        assert run.returncode == 3, err
        assert len(lines) == 1 and "lost the Dask cluster" in lines[0] and "--resume" in lines[0], lines
        kept = len(read_points(out))
        assert 1 <= kept and f"{kept} of 4 points finished are kept" in lines[0]
    finally:
        _stop(procs)
    summary = run_sweep(specs / "seed11.toml", out, workers=0, resume=True, progress=False, plots=False)
    assert summary.skipped == kept and len(summary.ran) == 4 - kept
    pd.testing.assert_frame_equal(_metrics(out), _metrics(reference))


# --- 4, 5. seeds and huge specs, checked before any work -----------------------------------------

STRONG = "[[parameters]]\nkey = 'lights.strong.irradiance_w_m2'\n"
WEAK = "[[parameters]]\nkey = 'lights.weak.irradiance_w_m2'\n"


@pytest.mark.parametrize("kind", ["sweep", "dataset"])
def test_seeds_above_2_63_are_refused_before_any_work(tmp_path: Path, kind: str) -> None:
    spec = tmp_path / "s.toml"
    if kind == "sweep":
        spec.write_text(f"seed = {2**63}\n[[parameters]]\nkey = 'dtdi.beta_bits'\nvalues = [12]\n")
    else:
        spec.write_text(f"samples = 2\nseed = {2**63}\nstages = [2, 8]\n")
    res = runner.invoke(app, [kind, str(spec), "--out", str(tmp_path / "o"), "--workers", "0"])
    assert res.exit_code == 2, res.output
    assert f"seed = {2**63}: " in res.output and "0..2**63-1" in res.output
    assert len(_lines(res.output)) == 1 and not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    ("body", "count"),
    [
        (f"{STRONG}linspace = {{ start = 1, stop = 2, num = 1000 }}\n"
         f"{WEAK}logspace = {{ start = 1, stop = 2, num = 1000 }}\n"
         "[[parameters]]\nkey = 'dtdi.beta_bits'\nrange = { start = 1, stop = 1000, step = 1 }\n", 10**9),
        (f"{STRONG}linspace = {{ start = 1, stop = 2, num = 1000000000 }}\n", 10**9),
        ("mode = 'sequential'\n[[parameters]]\nkey = 'lights.strong.irradiance_w_m2'\n"
         "range = { start = 1, stop = 1000000000, step = 1 }\n[[parameters]]\nkey = 'dtdi.beta_bits'\n"
         "values = [10, 12]\n", 10**9 + 2),
    ],
    ids=["product-1000^3", "linspace-1e9", "sequential-range-1e9"],
)
def test_a_billion_points_are_refused_in_under_a_second(tmp_path: Path, body: str, count: int) -> None:
    spec = tmp_path / "huge.toml"
    spec.write_text(f"quick = true\n{body}")
    load_spec_time = time.perf_counter()
    with pytest.raises(Exception, match=rf"{count} points .*more than 100000") as exc:
        load_spec(spec)
    assert time.perf_counter() - load_spec_time < 1.0
    assert "split the sweep" in str(exc.value)


def test_a_billion_samples_are_refused_in_under_a_second(tmp_path: Path) -> None:
    spec = tmp_path / "huge.toml"
    spec.write_text("samples = 1000000000\nseed = 0\nstages = [2, 8]\n")
    t0 = time.perf_counter()
    with pytest.raises(Exception, match=r"samples = 1000000000: .*100000"):
        load_dataset_spec(spec)
    assert time.perf_counter() - t0 < 1.0


# --- 6. damaged journals -------------------------------------------------------------------------------


def test_empty_and_truncated_records_are_recomputed(specs: Path, reference: Path, tmp_path: Path) -> None:
    """A copy of the finished reference sweep as a crash could leave it: one record empty, one
    truncated, ``sweep.json`` empty, no completion record. ``--resume`` warns once per problem,
    rebuilds ``sweep.json``, recomputes those two points and ends with the reference data. (A
    record of another spec or seed is never overwritten: ``tests/test_ownership.py``.)"""
    import shutil

    out = tmp_path / "damaged"
    shutil.copytree(reference, out)
    (out / OUTPUT_MARKER).unlink()
    (out / "sweep.json").write_text("")
    (out / "points" / "000001.json").write_text("")
    text = (out / "points" / "000002.json").read_text()
    (out / "points" / "000002.json").write_text(text[: len(text) // 2])
    res = runner.invoke(app, ["sweep", str(specs / "seed11.toml"), "--out", str(out), "--resume",
                              "--workers", "0", "--no-plots"])
    assert res.exit_code == 0, res.output
    warnings_ = [ln for ln in _lines(res.output) if ln.startswith("bench-sim: warning:")]
    assert any("000001.json" in w and "empty" in w for w in warnings_), warnings_
    assert any("000002.json" in w for w in warnings_), warnings_
    assert any("sweep.json: missing, empty or unreadable" in w for w in warnings_), warnings_
    assert "2 run, 2 skipped" in res.output
    pd.testing.assert_frame_equal(_metrics(out), _metrics(reference))
    assert (out / OUTPUT_MARKER).is_file()


# --- 7. local workers, help texts, encodings ----------------------------------------------------------


@pytest.mark.slow
def test_ctrl_c_with_local_workers_is_one_line_saying_what_was_kept(specs: Path, tmp_path: Path) -> None:
    out = tmp_path / "local"
    proc = _child(["sweep", str(specs / "seed11.toml"), "--out", str(out), "--workers", "2", "--no-plots"],
                  PYTHONWARNINGS="default")
    try:
        _wait_for(lambda: (out / "sweep.json").is_file(), 120, "the sweep to start")
        time.sleep(0.5)
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        _stop([proc])
    lines = _lines(err)
    if proc.returncode == 0:  # pragma: no cover - finished first on a fast machine
        pytest.skip("the sweep finished before the signal")
    assert proc.returncode == 130, err
    assert len(lines) == 1, lines
    assert re.match(r"bench-sim: interrupted: stopped by Ctrl-C; \d of 4 points finished are kept in .*; "
                    r"finish with 'bench-sim sweep .* --resume'", lines[0]), lines
    assert not lock_path(out).exists()


def test_help_texts_show_the_spec_shape_and_stage_ranges() -> None:
    sweep_help = runner.invoke(app, ["sweep", "--help"]).output
    assert "[[parameters]]" in sweep_help
    ptc_help = runner.invoke(app, ["ptc", "--help"]).output
    assert "5:100:5" in ptc_help


@pytest.mark.parametrize("what", ["spec", "points"])
def test_a_spec_or_points_file_that_is_not_utf8_is_one_line(tmp_path: Path, what: str) -> None:
    spec = tmp_path / "s.toml"
    if what == "spec":
        spec.write_bytes(b"name = 'caf\xe9'\n")
    else:
        spec.write_text("mode = 'custom'\npoints = 'p.csv'\n")
        (tmp_path / "p.csv").write_bytes(b"dtdi.beta_bits\n12\n# caf\xe9\n")
    res = runner.invoke(app, ["sweep", str(spec), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2, res.output
    line = _lines(res.output)
    assert len(line) == 1 and "not UTF-8" in line[0], line
