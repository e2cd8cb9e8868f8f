"""``bench-sim render`` and ``bench-sim doctor`` from the command line."""

from __future__ import annotations

import json

import numpy as np
from typer.testing import CliRunner

from bench_sim.cli import app
from bench_sim.config import DEFAULT_CONFIG_PATH
from bench_sim.io import read_exr
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
