"""Sweeps: specs and their points, errors before anything runs, the same results on any number of
workers and on a real scheduler, resuming a killed sweep, the outputs."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from bench_sim.cli import app
from bench_sim.errors import BenchSimError
from bench_sim.metrics.banding import banding_amplitude, folded_cycles_per_line
from bench_sim.workflows.sweep.run import plan_sweep, run_sweep
from bench_sim.workflows.sweep.spec import load_spec

ROOT = Path(__file__).resolve().parents[2]

#: a 12 x 48 sensor on the paper rig, 48 lines (spot edge and wedge in view)
TINY_BASE = f"""
base = "{ROOT / 'scenes' / 'paper_rig.toml'}"
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

#: four points on one camera: the spot and the fill, two values each
SPEC = """
name = "tiny_lights"
base = "tiny.toml"
seed = 11
[[parameters]]
key = "lights.strong.irradiance_w_m2"
values = [64.0, 256.0]
[[parameters]]
key = "lights.weak.irradiance_w_m2"
logspace = { start = 3.0, stop = 12.0, num = 2 }
"""

#: columns that depend on where and when a point ran (renders: which worker rendered the records first)
RUN_COLUMNS = ["wall_s", "worker", "mitsuba_renders"]


def _write(folder: Path, name: str, text: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / name).write_text(text)
    return folder / name


@pytest.fixture(scope="module")
def spec_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("specs")
    _write(folder, "tiny.toml", TINY_BASE)
    _write(folder, "lights.toml", SPEC)
    return folder


def _metrics(out: Path) -> pd.DataFrame:
    df = pd.read_csv(out / "points.csv")
    return df.drop(columns=RUN_COLUMNS).sort_values("point").reset_index(drop=True)


@pytest.fixture(scope="module")
def one_worker(spec_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("runs") / "one_worker"
    run_sweep(spec_dir / "lights.toml", out, workers=1, progress=False, plots=False)
    return out


# --- specs --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("mode", "params", "count"),
    [
        ("product", [("lights.strong.irradiance_w_m2", "values = [1.0, 2.0, 3.0]"),
                     ("dtdi.beta_bits", "range = { start = 12, stop = 16, step = 2 }")], 9),
        ("sequential", [("lights.strong.irradiance_w_m2", "values = [1.0, 2.0, 3.0]"),
                        ("dtdi.beta_bits", "range = { start = 12, stop = 16, step = 2 }")], 6),
        ("product", [("timing.sync_error", "linspace = { start = -0.1, stop = 0.1, num = 5 }")], 5),
    ],
)
def test_point_counts_and_values(spec_dir: Path, mode: str, params: list, count: int) -> None:
    body = f'base = "tiny.toml"\nmode = "{mode}"\n' + "".join(
        f'[[parameters]]\nkey = "{k}"\n{v}\n' for k, v in params
    )
    spec = load_spec(_write(spec_dir, f"count_{mode}_{count}.toml", body))
    assert len(spec.points) == count
    if mode == "product" and len(params) == 2:
        assert spec.values["dtdi.beta_bits"] == [12, 14, 16]
        assert [p.values for p in spec.points[:4]] == [
            {"lights.strong.irradiance_w_m2": 1.0, "dtdi.beta_bits": b} for b in (12, 14, 16)
        ] + [{"lights.strong.irradiance_w_m2": 2.0, "dtdi.beta_bits": 12}]
        p5 = spec.points[5].cfg
        assert p5.dtdi.beta_bits == 16 and p5.lights.strong.irradiance_w_m2 == 2.0
    if mode == "sequential":
        varied = [p.varied for p in spec.points]
        assert varied == ["lights.strong.irradiance_w_m2"] * 3 + ["dtdi.beta_bits"] * 3
        base = load_spec(spec_dir / "lights.toml").base
        assert spec.points[0].cfg.dtdi.beta_bits == base.dtdi.beta_bits  # the others stay at the base
        assert spec.points[4].cfg.lights.strong.irradiance_w_m2 == base.lights.strong.irradiance_w_m2
    if len(params) == 1:
        assert spec.values["timing.sync_error"] == pytest.approx([-0.1, -0.05, 0.0, 0.05, 0.1])


def test_logspace_and_custom_points(spec_dir: Path) -> None:
    body = ('base = "tiny.toml"\n[[parameters]]\nkey = "lights.weak.irradiance_w_m2"\n'
            "logspace = { start = 0.1, stop = 1000.0, num = 5 }\n")
    spec = load_spec(_write(spec_dir, "log.toml", body))
    assert spec.values["lights.weak.irradiance_w_m2"] == pytest.approx([0.1, 1.0, 10.0, 100.0, 1000.0])
    _write(spec_dir, "pts.csv", "lights.strong.position_m,target.finish,render.engine\n"
           '"[0.0, 0.2, 0.5]",glossy,reference\n"[0.1, 0.2, 0.5]",matte,fast\n')
    body = 'base = "tiny.toml"\nmode = "custom"\npoints = "pts.csv"\n'
    spec = load_spec(_write(spec_dir, "custom.toml", body))
    assert len(spec.points) == 2
    assert spec.points[0].cfg.lights.strong.position_m == (0.0, 0.2, 0.5)
    assert spec.points[0].cfg.target.finish == "glossy" and spec.points[1].cfg.render.engine == "fast"


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ('[[parameters]]\nkey = "lights.strong.irradiance"\nvalues = [1.0]\n',
         r"key 'lights.strong.irradiance': not a setting of the bench config"),
        ('[[parameters]]\nkey = "sensr.rows"\nvalues = [8]\n', r"key 'sensr.rows': not a setting"),
        # a key may add a light (issue 24): then the point's light must be complete
        ('[[parameters]]\nkey = "lights.back.irradiance_w_m2"\nvalues = [1.0]\n', r"lights: back: no kind"),
        ('[[parameters]]\nkey = "lights.strong.irradiance_w_m2"\nvalues = [5.0, -1.0]\n',
         r"point 1 \(lights.strong.irradiance_w_m2 = -1.0\): .*lights.strong.irradiance_w_m2 = -1.0: "
         r"Input should be greater than or equal to 0"),
        ('[[parameters]]\nkey = "fusion.mu2"\nvalues = [8, 40]\n',
         r"point 1 .*fusion.mu2 = 40 exceeds sensor.rows"),
        ('[[parameters]]\nkey = "target.finish"\nvalues = ["glossy"]\n',
         r"point 0: render.engine = 'fast' with target.finish = 'glossy'"),
        ('mode = "zigzag"\n', r"mode = 'zigzag': allowed product, sequential, custom"),
        ('seeds = 3\n', r"unknown key 'seeds'"),
        ('[[parameters]]\nkey = "dtdi.beta_bits"\nrange = { start = 12, stop = 8, step = 2 }\n',
         r"parameter dtdi.beta_bits: range step = 2 never goes from 12 to 8"),
        ('[[parameters]]\nkey = "dtdi.beta_bits"\nvalues = [12]\n'
         "linspace = { start = 1, stop = 2, num = 2 }\n",
         r"give exactly one of values, range, linspace, logspace"),
    ],
)
def test_bad_specs_name_the_key_before_anything_runs(
    spec_dir: Path, tmp_path: Path, body: str, message: str
) -> None:
    spec = _write(spec_dir, "bad.toml", 'base = "tiny.toml"\n' + body)
    out = tmp_path / "never"
    with pytest.raises(BenchSimError, match=message):
        plan_sweep(spec, out)
    result = CliRunner().invoke(app, ["sweep", str(spec), "--out", str(out), "--workers", "0"])
    assert result.exit_code == 2
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("bench-sim: error: sweep spec ")
    assert not out.exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--workers", "1", "--scheduler", "tcp://127.0.0.1:9"], "--workers and --scheduler: give one"),
        (["--workers", "-2"], "--workers = -2: must be >= 0"),
    ],
)
def test_bad_worker_options_are_one_line(spec_dir: Path, tmp_path: Path, args: list, message: str) -> None:
    out = tmp_path / "o"
    result = CliRunner().invoke(app, ["sweep", str(spec_dir / "lights.toml"), "--out", str(out), *args])
    assert result.exit_code == 2
    assert len(result.output.strip().splitlines()) == 1
    assert result.output.startswith(f"bench-sim: error: {message}")
    assert not out.exists()


def test_unreachable_scheduler_is_one_line_and_writes_nothing(
    spec_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """--scheduler naming an address where no scheduler listens: one line naming it, exit 2,
    nothing at --out (the connection timeout shortened from 20 s to 1 s for the test)."""
    from bench_sim.runtime import execution

    monkeypatch.setitem(execution.open_client.__wrapped__.__kwdefaults__, "connect_timeout_s", 1.0)
    with socket.socket() as sock:  # a free port: nothing listens there
        sock.bind(("127.0.0.1", 0))
        address = f"tcp://127.0.0.1:{sock.getsockname()[1]}"
    out = tmp_path / "o"
    result = CliRunner().invoke(app, ["sweep", str(spec_dir / "lights.toml"), "--out", str(out),
                                      "--scheduler", address])
    assert result.exit_code == 2
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert len(lines) == 1, result.output
    assert lines[0].startswith(f"bench-sim: error: --scheduler = '{address}': cannot reach a Dask scheduler")
    assert not out.exists() and list(tmp_path.iterdir()) == []


# --- runs ---------------------------------------------------------------------------------------


@pytest.mark.slow
def test_one_and_two_workers_give_identical_points(spec_dir: Path, one_worker: Path, tmp_path: Path) -> None:
    """The issue's test 2; and the outputs are complete and readable."""
    out = tmp_path / "two"
    run_sweep(spec_dir / "lights.toml", out, workers=2, progress=False)
    a, b = _metrics(one_worker), _metrics(out)
    pd.testing.assert_frame_equal(a, b)
    assert list(a["status"]) == ["ok"] * 4
    assert len(set(pd.read_csv(out / "points.csv")["worker"])) == 2
    # camera properties are the same for every point (one camera); scene metrics differ
    assert a["dr_db_gamma_hdr"].nunique() == 1 and a["snr_darkest_gamma_hdr"].nunique() == 4
    import xarray as xr

    with xr.open_dataset(out / "sweep.nc") as ds:
        dims = ("lights.strong.irradiance_w_m2", "lights.weak.irradiance_w_m2")
        assert ds["snr_darkest_gamma_hdr"].dims == dims
        attrs = ds["gain_db_vs_gamma1"].attrs
        assert attrs["units"] == "dB" and attrs["kind"] == "camera"
        assert list(ds["lights.weak.irradiance_w_m2"].values) == pytest.approx([3.0, 12.0])
        at = {"lights.strong.irradiance_w_m2": 256.0, "lights.weak.irradiance_w_m2": 3.0}
        got = ds["snr_darkest_gamma_hdr"].sel(at)
        row = a[(a["lights.strong.irradiance_w_m2"] == 256.0) & (a["lights.weak.irradiance_w_m2"] == 3.0)]
        assert float(got) == pytest.approx(float(row["snr_darkest_gamma_hdr"].iloc[0]), rel=1e-9)
    meta = json.loads((out / "sweep.json").read_text())
    assert meta["status"] == "complete" and meta["ok"] == 4 and meta["seed"] == 11
    assert meta["columns"]["snr_darkest_gamma_hdr"]["kind"] == "scene"
    assert (out / "report.md").read_text().count("\n| 3 |") == 1
    assert {p.name for p in (out / "plots").iterdir()} >= {
        "lights_strong_irradiance_w_m2.png", "lights_weak_irradiance_w_m2.png", "heatmaps.png"
    }


def test_report_effects_do_not_depend_on_the_order_points_finish(spec_dir: Path, one_worker: Path) -> None:
    """The main effects (their extremes' locations too, where means tie) follow the points'
    order, not the order the workers finished them in."""
    from bench_sim.workflows.sweep.plan import plan_sweep
    from bench_sim.workflows.sweep.report import _effects

    records = {int(p.stem): json.loads(p.read_text()) for p in (one_worker / "points").glob("*.json")}
    assert len(records) == 4
    plan = plan_sweep(spec_dir / "lights.toml", one_worker, resume=True)
    tie = {i: {**r, "metrics": {**r["metrics"], "snr_darkest_gamma_hdr": 1.0}} for i, r in records.items()}
    forward = _effects(plan, dict(sorted(tie.items())))
    assert forward == _effects(plan, dict(sorted(tie.items(), reverse=True)))


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_scheduler_and_worker_processes_give_the_local_results(
    spec_dir: Path, one_worker: Path, tmp_path: Path
) -> None:
    """The issue's test 3: `dask scheduler` and `dask worker` started as separate processes on
    127.0.0.1; the sweep connects with --scheduler."""
    dask = Path(sys.executable).with_name("dask")
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = dict(os.environ, BENCH_SIM_THREADS="1")
    procs = []
    try:
        procs.append(subprocess.Popen(
            [str(dask), "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env,
        ))
        procs.append(subprocess.Popen(
            [str(dask), "worker", address, "--nthreads", "1", "--nworkers", "1", "--host", "127.0.0.1",
             "--no-dashboard"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, cwd=tmp_path,
        ))
        from distributed import Client

        with Client(address, timeout="30s") as client:
            client.wait_for_workers(1, timeout=60)
        out = tmp_path / "scheduled"
        result = CliRunner().invoke(app, ["sweep", str(spec_dir / "lights.toml"), "--out", str(out),
                                          "--scheduler", address, "--no-plots"])
        assert result.exit_code == 0, result.output
        pd.testing.assert_frame_equal(_metrics(out), _metrics(one_worker))
        workers = pd.read_csv(out / "points.csv")["worker"]
        assert all(w.startswith("tcp://127.0.0.1:") for w in workers)
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in reversed(procs):
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


@pytest.mark.slow
def test_resume_after_a_kill_finishes_only_the_missing_points(
    spec_dir: Path, one_worker: Path, tmp_path: Path
) -> None:
    """The issue's test 4: kill -9 a running sweep once a point is written, then --resume (a torn
    record is recomputed)."""
    out = tmp_path / "killed"
    proc = subprocess.Popen(
        [sys.executable, "-m", "bench_sim.cli", "sweep", str(spec_dir / "lights.toml"), "--out", str(out),
         "--workers", "0", "--no-plots"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )
    journal = out / "points"
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if journal.is_dir() and len(list(journal.glob("[0-9]*.json"))) >= 1:
                break
            time.sleep(0.02)
        assert proc.poll() is None, "the sweep ended before it could be killed"
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait()
    finished = sorted(int(p.stem) for p in journal.glob("[0-9]*.json"))  # records, not temporaries
    assert 1 <= len(finished) < 4
    with pytest.raises(BenchSimError, match="holds an unfinished sweep: add --resume"):
        plan_sweep(spec_dir / "lights.toml", out)
    (journal / f"{finished[0]:06d}.json").write_text("")  # a torn record: not done, it is recomputed
    finished = finished[1:]
    with pytest.warns(RuntimeWarning, match="unreadable journal record"):
        summary = run_sweep(spec_dir / "lights.toml", out, workers=0, resume=True, progress=False,
                            plots=False)
    assert summary.ran == [i for i in range(4) if i not in finished]
    assert summary.skipped == len(finished)
    pd.testing.assert_frame_equal(_metrics(out), _metrics(one_worker))
    sessions = json.loads((out / "sweep.json").read_text())["sessions"]
    assert [s["resumed"] for s in sessions] == [False, True] and sessions[1]["ran"] == summary.ran


@pytest.mark.slow
def test_light_power_sweep_renders_once_and_its_frames_equal_a_fresh_render(
    spec_dir: Path, tmp_path: Path
) -> None:
    """The issue's test 5: a sweep of the spot's power on the fast engine makes one set of
    Mitsuba renders (hit positions, then each light alone) for all its points, and the frames
    of a swept power formed from those records equal a fresh render at that power."""
    from bench_sim.render.exposures import render_photons
    from bench_sim.render.records import clear_record_cache

    body = ('base = "tiny.toml"\nseed = 3\n[[parameters]]\nkey = "lights.strong.irradiance_w_m2"\n'
            "values = [16.0, 64.0, 256.0]\n")
    spec = _write(spec_dir, "power.toml", body)
    clear_record_cache()
    summary = run_sweep(spec, tmp_path / "power", workers=0, progress=False, plots=False)
    renders = [summary.records[i]["metrics"]["mitsuba_renders"] for i in range(3)]
    assert renders == [2, 0, 0]  # hit positions and the spot (the fill is in closed form)
    assert json.loads((tmp_path / "power" / "sweep.json").read_text())["mitsuba_renders"] == 2
    assert "2 Mitsuba renders in all" in (tmp_path / "power" / "report.md").read_text()
    cfg = load_spec(spec).points[2].cfg
    reused, setup = render_photons(cfg, 4, np.random.default_rng(0))
    assert setup.info["mitsuba_renders"] == 0
    clear_record_cache()
    fresh, setup = render_photons(cfg, 4, np.random.default_rng(0))
    assert setup.info["mitsuba_renders"] == 2
    np.testing.assert_allclose(reused, fresh, rtol=1e-6, atol=1e-6 * float(fresh.mean()))


@pytest.mark.slow
def test_a_failed_point_is_recorded_and_the_sweep_goes_on(
    spec_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A point that raises is written with its one-line error and empty metrics; the others
    finish, the outputs hold them all, and --resume runs the failed point alone."""
    from bench_sim.workflows.sweep import run as sweep

    real = sweep.measure_point

    def flaky(task, *inputs):
        if task.index == 2:
            raise MemoryError("worker ran out of memory\nsecond line")
        return real(task, *inputs)

    monkeypatch.setattr(sweep, "measure_point", flaky)
    out = tmp_path / "flaky"
    summary = run_sweep(spec_dir / "lights.toml", out, workers=0, progress=False, plots=False)
    assert (summary.ok, summary.failed) == (3, 1)
    df = pd.read_csv(out / "points.csv")
    assert list(df["status"]) == ["ok", "ok", "failed", "ok"]
    assert df.loc[2, "error"] == "MemoryError: worker ran out of memory"
    assert np.isnan(df.loc[2, "dr_db_gamma_hdr"])
    assert json.loads((out / "sweep.json").read_text())["status"] == "complete_with_failures"
    assert "point 2 (" in (out / "report.md").read_text()
    monkeypatch.setattr(sweep, "measure_point", real)
    again = run_sweep(spec_dir / "lights.toml", out, workers=0, resume=True, progress=False, plots=False)
    assert again.ran == [2] and again.failed == 0


# --- banding measurement -------------------------------------------------------------------------


@pytest.mark.physics
@pytest.mark.parametrize(("f", "period", "n"), [(100.0, 1e-3, 37), (120.0, 1e-4, 400), (9900.0, 1e-4, 250)])
def test_banding_amplitude_recovers_a_sinusoid_on_any_number_of_lines(
    f: float, period: float, n: int
) -> None:
    nu = folded_cycles_per_line(f, period)
    lines = np.arange(n)
    rng = np.random.default_rng(0)
    profile = 500.0 * (1 + 0.23 * np.sin(2 * np.pi * f * period * lines + 0.7)) + rng.normal(0, 1e-6, n)
    assert banding_amplitude(profile, nu) == pytest.approx(0.23, rel=1e-6)
    assert np.isnan(banding_amplitude(profile, folded_cycles_per_line(1e4, period)))  # the line rate: DC
