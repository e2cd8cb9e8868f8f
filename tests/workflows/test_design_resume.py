"""``bench-sim design`` with a line-period axis of three values on two Dask workers: it survives
``kill -9`` of one worker, and a design killed outright finishes with ``--resume``, both with the
scores of an uninterrupted run (the issue's must-show)."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import psutil
import pytest

from bench_sim.errors import BenchSimError
from bench_sim.workflows.design.run import run_design
from bench_sim.workflows.design.tasks import plan_design

ROOT = Path(__file__).resolve().parents[2]

SPEC = f"""
base = "{ROOT / 'scenes' / 'paper_rig.toml'}"
seed = 5
rules = ["eq11", "clip"]
chain_dr = "chosen"
objectives = ["dr_db", "truth_rms", "clipped_share", "snr_dark"]

[overrides]
lines = 48
sensor = {{ rows = 16, columns = 48 }}
target = {{ panel_lines = 48, panel_columns = 48 }}
render = {{ spp = 4 }}
fusion = {{ mu1 = 2, mu2 = 12 }}

[[parameters]]
key = "timing.line_period_s"
values = [80e-6, 100e-6, 120e-6]
"""


@pytest.fixture(scope="module")
def spec(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("spec") / "periods.toml"
    path.write_text(SPEC)
    return path


@pytest.fixture(scope="module")
def uninterrupted(spec: Path, tmp_path_factory: pytest.TempPathFactory) -> pd.DataFrame:
    out = tmp_path_factory.mktemp("runs") / "whole"
    run_design(spec, out, workers=0, progress=False)
    return pd.read_csv(out / "candidates.csv")


def _start(spec: Path, out: Path) -> subprocess.Popen[bytes]:
    argv = [sys.executable, "-m", "bench_sim", "design", str(spec), "--out", str(out), "--workers", "2",
            "--no-plots"]
    return subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


def _wait_for_a_point(proc: subprocess.Popen[bytes], out: Path) -> None:
    """Until the first point record is written (the other points are on the workers then)."""
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and proc.poll() is None:
        if len(list((out / "points").glob("[0-9]*.json"))) >= 1:
            return
        time.sleep(0.02)
    raise AssertionError(f"no point record before the design ended or timed out: {proc.poll()}")


def _workers(proc: subprocess.Popen[bytes]) -> list[psutil.Process]:
    """The Dask worker processes of a design (started by its nannies, the ``multiprocessing``
    children running ``spawn_main``)."""
    found = []
    for p in psutil.Process(proc.pid).children(recursive=True):
        with contextlib.suppress(psutil.NoSuchProcess):
            if "spawn_main" in " ".join(p.cmdline()):
                found.append(p)
    return found


def _busy_worker(proc: subprocess.Popen[bytes], out: Path) -> psutil.Process:
    """The worker of the design that uses the most CPU once both are there and the design has
    laid out its folder (``design.json``; its tasks go to the workers then: the shared inputs,
    then the points). A point takes 0.04-0.15 s at this size and the three finish together, so
    this is taken before the first point's files (``points/`` appears with them: waiting for
    it, the test killed a worker of a finished run under load)."""
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and proc.poll() is None:
        workers = _workers(proc) if (out / "design.json").is_file() else []
        if len(workers) >= 2:
            usage = {}
            for p in workers:
                with contextlib.suppress(psutil.NoSuchProcess):
                    usage[p] = p.cpu_percent(interval=0.1)
            if usage and max(usage.values()) > 0:
                return max(usage, key=lambda p: usage[p])
        time.sleep(0.02)
    raise AssertionError(f"no busy worker before the design ended or timed out: {proc.poll()}")


@pytest.mark.slow
def test_a_killed_worker_is_survived(spec: Path, uninterrupted: pd.DataFrame, tmp_path: Path) -> None:
    out = tmp_path / "killed_worker"
    proc = _start(spec, out)
    try:
        busy = _busy_worker(proc, out)
        os.kill(busy.pid, signal.SIGKILL)
        assert len(list((out / "points").glob("[0-9]*.json"))) < 3  # killed while points were to do
        _, err = proc.communicate(timeout=600)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err.decode()[-2000:]
    pd.testing.assert_frame_equal(pd.read_csv(out / "candidates.csv"), uninterrupted)


@pytest.mark.slow
def test_a_killed_design_finishes_with_resume(
    spec: Path, uninterrupted: pd.DataFrame, tmp_path: Path
) -> None:
    out = tmp_path / "killed"
    proc = _start(spec, out)
    family: list[psutil.Process] = []
    try:
        _wait_for_a_point(proc, out)
        family = psutil.Process(proc.pid).children(recursive=True)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=60)
    finally:
        for p in family:  # the cluster's processes of the killed design
            if p.is_running():
                p.kill()
        if proc.poll() is None:
            proc.kill()
    done = sorted(int(p.stem) for p in (out / "points").glob("[0-9]*.json"))
    assert 1 <= len(done) <= 3
    with pytest.raises(BenchSimError, match="holds an unfinished design: add --resume"):
        plan_design(spec, out)
    summary = run_design(spec, out, workers=2, resume=True, progress=False)
    assert summary.skipped == len(done) and summary.ran == [i for i in range(3) if i not in done]
    pd.testing.assert_frame_equal(pd.read_csv(out / "candidates.csv"), uninterrupted)
