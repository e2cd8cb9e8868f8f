"""``bench-sim render`` and ``bench-sim doctor`` from the command line."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from bench_sim.cli import app
from bench_sim.config import DEFAULT_CONFIG_PATH, load_config
from bench_sim.io import read_exr
from bench_sim.render.exposures import render_photons
from bench_sim.sensor.stage_truth import row_footprints
from bench_sim.workflows import render_job
from bench_sim.workflows.render_job import read_exposures

runner = CliRunner()


def _tiny_toml(tmp_path, extra=""):
    path = tmp_path / "tiny.toml"
    path.write_text(
        f"base = '{DEFAULT_CONFIG_PATH}'\n"
        "[sensor]\nrows = 12\ncolumns = 48\n[target]\npanel_lines = 96\npanel_columns = 48\n"
        "[render]\nspp = 4\n[fusion]\nmu1 = 2\nmu2 = 8\n" + extra
    )
    return path


def test_render_writes_exposures_truth_and_meta(tmp_path):
    cfg = _tiny_toml(tmp_path)
    out = tmp_path / "out"
    res = runner.invoke(app, ["render", str(cfg), "--frames", "14", "--seed", "3", "--out", str(out)])
    assert res.exit_code == 0, res.output
    photons, meta = read_exposures(out / "exposures.exr")
    assert photons.shape == (14, 12, 48)
    assert meta["shape"] == [14, 12, 48] and meta["seed"] == 3
    assert meta["render"]["engine"] == "fast" and meta["version"]
    assert "photons" in meta["units"]
    truth, tmeta = read_exr(out / "ground_truth.exr")
    assert truth["reflectance"].shape == (3, 48)
    assert 0.0 < truth["reflectance"].min() <= truth["reflectance"].max() <= 1.0
    on_disk = json.loads((out / "meta.json").read_text())
    assert on_disk["config_sha256"] == meta["config_sha256"]
    # same config and seed -> identical exposures
    out2 = tmp_path / "out2"
    res = runner.invoke(app, ["render", str(cfg), "--frames", "14", "--seed", "3", "--out", str(out2)])
    assert res.exit_code == 0
    assert np.array_equal(read_exposures(out2 / "exposures.exr")[0], photons)


def test_bad_config_is_one_line_and_writes_nothing(tmp_path):
    cfg = _tiny_toml(tmp_path, "[lens]\nf_number = -2\n")
    out = tmp_path / "out"
    res = runner.invoke(app, ["render", str(cfg), "--frames", "2", "--out", str(out)])
    assert res.exit_code == 2
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "lens.f_number = -2" in lines[0]
    assert not out.exists()


def test_bad_arguments_are_one_line(tmp_path):
    cfg = _tiny_toml(tmp_path)
    for args, needle in (
        (["--frames", "0"], "--frames = 0"),
        (["--engine", "magic"], "--engine = 'magic'"),
    ):
        out = tmp_path / "o"
        res = runner.invoke(app, ["render", str(cfg), "--out", str(out), *args])
        assert res.exit_code == 2, res.output
        assert needle in res.stderr and len(res.stderr.strip().splitlines()) == 1
        assert not out.exists()
    res = runner.invoke(app, ["render", str(tmp_path / "missing.toml")])
    assert res.exit_code == 2 and "no such file" in res.stderr


def test_doctor_names_variant_and_llvm():
    res = runner.invoke(app, ["doctor"])
    assert res.exit_code == 0
    assert "variant" in res.stdout and "libLLVM" in res.stdout and "mitsuba" in res.stdout


@pytest.mark.physics
def test_render_truth_says_which_stage_it_is_aligned_for(tmp_path):
    """``ground_truth.exr`` is stage 1's; the header, meta.json and the printed line give the shift
    of the other stages' truth, ``e (m - 1) / (2 (1 + e))`` lines, checked against the exact truth's
    row footprints (bench_sim.sensor.stage_truth.row_footprints: each row's centroid on the drum)."""
    e = 0.2
    cfg_path = _tiny_toml(tmp_path, f"[timing]\nsync_error = {e}\n")
    out = tmp_path / "out"
    res = runner.invoke(app, ["render", str(cfg_path), "--frames", "14", "--seed", "3", "--out", str(out)])
    assert res.exit_code == 0, res.output
    _, tmeta = read_exr(out / "ground_truth.exr")
    shift12 = e * 11 / (2 * (1 + e))  # 0.917 lines for the top stage, 12
    assert tmeta["aligned_for_stage"] == 1 and tmeta["sync_error"] == e
    assert set(tmeta["stage_shift_lines"]) == {"1", "2", "8", "12"}
    assert tmeta["stage_shift_lines"]["1"] == 0.0
    assert tmeta["stage_shift_lines"]["12"] == pytest.approx(shift12, abs=1e-6)
    on_disk = json.loads((out / "meta.json").read_text())["ground_truth"]
    assert on_disk["stage_shift_lines"] == tmeta["stage_shift_lines"] and on_disk["lines"] == 3
    assert "ground_truth.exr (3 lines) is stage 1's" in res.stdout
    assert "stage 12's truth is 0.92 lines further along" in res.stdout
    # the shift against the exact truth's geometry: the centroid of stage m's m row footprints
    # (row i in frame i) less row 0's, in lines of q texels
    cfg = load_config(cfg_path)
    _, setup = render_photons(cfg, 14, np.random.default_rng(3))
    fp = row_footprints(cfg, setup.geom, setup.grid, cfg.sensor.rows)
    q = setup.grid.q
    centroid = np.array([fp.y_base[i] + np.dot(np.arange(w.size), w) for i, w in enumerate(fp.y_weights)])
    for m in (2, 8, 12):
        exact = (np.mean(centroid[:m] + np.arange(m) * q) - centroid[0]) / q
        assert abs(exact) > 0.05
        assert render_job.stage_truth_shift_lines(e, m) == pytest.approx(exact, rel=0.02), m
