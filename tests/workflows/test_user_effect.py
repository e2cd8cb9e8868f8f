"""A user's effect in a file outside the package (issue 33): a gamma curve declared
``truth = "monotone"`` through ``simulate`` (its truth exact: a statistical test of the words), a
2-point ``sweep`` of an effect's parameter on 2 Dask workers and a 2-sample ``dataset`` on 2
workers randomising one; an effect declared ``truth = "none"`` is labelled in every output."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats
from typer.testing import CliRunner

from bench_sim.cli import app
from bench_sim.config import DEFAULT_CONFIG_PATH

pytestmark = pytest.mark.slow

runner = CliRunner()

GAMMA = '''
def gamma_response(e, *, rng, gamma, full_well_e):
    """A gamma curve of the collected charge [e- -> e-]."""
    return full_well_e * (e / full_well_e) ** gamma


def bias(y, *, rng, dn):
    """An analog offset [DN] the truth does not know."""
    return y + dn
'''

#: an 80 x 8 sensor over a uniform panel, the gamma curve (a file next to the config)
BENCH = f"""
base = "{DEFAULT_CONFIG_PATH}"
lines = 8
[sensor]
rows = 80
columns = 8
[target]
layout = "uniform"
panel_columns = 16
[lights.strong]
enabled = false
[lights.weak]
irradiance_w_m2 = 100.0
[fusion]
mu1 = 1
mu2 = 80
[dtdi]
beta_bits = 20
[sensor.effects.gamma]
kind = "plugin"
function = "effects/gamma.py:gamma_response"   # relative to this file
point = "charge"
truth = "monotone"
args = {{ gamma = 0.85, full_well_e = 13500.0 }}
[sensor.effects.knee]
kind = "nonlinearity"
compression = 0.05
"""

UNKNOWN = """
[sensor.effects.bias]
kind = "plugin"
function = "effects/gamma.py:bias"
point = "analog"
args = { dn = 2.0 }
"""


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    (tmp_path / "effects").mkdir()
    (tmp_path / "effects" / "gamma.py").write_text(GAMMA)
    (tmp_path / "bench.toml").write_text(BENCH)
    (tmp_path / "unknown.toml").write_text(BENCH + UNKNOWN)
    return tmp_path


def _ok(result: object) -> None:
    assert result.exit_code == 0, result.stderr[-3000:]  # type: ignore[attr-defined]


def test_simulate_a_user_gamma_curve_has_the_exact_truth(folder):
    """``simulate`` of 400 lines: on a flat field each line of a stage is a new draw of the same
    pixels (stage 1: row 0; stage 80: rows 0..79), so the z-scores ``(dn - mean_dn) /
    noise_std_dn`` of 3,200 words per stage have mean 0 (within 5 standard errors) and the sum of
    their squares is chi-square(3,200) (quantiles of 1e-6); the outputs name the plug-in and say
    its truth is exact."""
    import xarray as xr

    out = folder / "sim"
    (folder / "sim.toml").write_text('base = "bench.toml"\nlines = 400\n')
    _ok(runner.invoke(app, ["simulate", str(folder / "sim.toml"), "--out", str(out), "--stages", "1,80",
                            "--seed", "3"]))
    ds = xr.open_zarr(out / "simulation.zarr")
    assert ds.attrs["truth_exact"] == 1 and "gamma (plugin)" in ds.attrs["sensor_chain"]
    assert "effects/gamma.py:gamma_response" in ds.attrs["config"]
    for m in (1, 80):
        d = ds.sel(stage=m)
        z = ((d.dn.astype(np.float64) - d.mean_dn) / d.noise_std_dn).values.ravel()
        assert abs(z.mean()) < 5 / np.sqrt(z.size), (m, z.mean())
        lo, hi = stats.chi2.ppf([1e-6, 1 - 1e-6], z.size)
        assert lo < float((z**2).sum()) < hi, (m, float((z**2).mean()))
        # the gamma curve lifts the signal above the linear camera's: the truth follows it
        assert float((d.mean_dn - d.linear_dn).mean()) != 0.0


def _flags(meta: dict) -> tuple[bool, list[str]]:
    return meta["truth_exact"], meta.get("truth_not_exact", [])


def test_sweep_an_effect_parameter_on_two_workers(folder):
    """Two points of ``sensor.effects.knee.compression`` on a real 2-worker LocalCluster: both
    run, each with its value; the truth-none plug-in is labelled in ``sweep.json``,
    ``points.csv.json`` and ``sweep.nc``."""
    import xarray as xr

    (folder / "sweep.toml").write_text(
        'base = "unknown.toml"\n[[parameters]]\nkey = "sensor.effects.knee.compression"\n'
        "values = [0.02, 0.2]\n")
    out = folder / "sweep"
    _ok(runner.invoke(app, ["sweep", str(folder / "sweep.toml"), "--out", str(out), "--workers", "2",
                            "--no-plots"]))
    points = pd.read_csv(out / "points.csv")
    assert list(points["status"]) == ["ok", "ok"]
    assert list(points["sensor.effects.knee.compression"]) == [0.02, 0.2]
    assert points["config_sha256"].nunique() == 2
    assert points["dr_db_gamma2"].nunique() == 2  # the compression changes the chain's response
    for name in ("sweep.json", "points.csv.json"):
        exact, why = _flags(json.loads((out / name).read_text()))
        assert exact is False and any("bias: plug-in" in w for w in why), name
    nc = xr.open_dataset(out / "sweep.nc")
    assert int(nc.attrs["truth_exact"]) == 0 and "bias" in nc.attrs["truth_not_exact"]
    assert "knee (nonlinearity)" in nc.attrs["sensor_chain"]


def test_a_sweep_that_switches_an_unknown_effect_on_is_not_exact(folder):
    """One point without the truth-none plug-in, one with it: the sweep's truth is exact only
    where every point's is (``sweep.json`` says which effect); the base alone would say exact."""
    (folder / "sweep.toml").write_text(
        'base = "unknown.toml"\n[[parameters]]\nkey = "sensor.effects.bias.enabled"\n'
        "values = [false, true]\n")
    (folder / "unknown.toml").write_text(BENCH + UNKNOWN.replace("[sensor.effects.bias]\n",
                                                                 "[sensor.effects.bias]\nenabled = false\n"))
    out = folder / "sweep"
    _ok(runner.invoke(app, ["sweep", str(folder / "sweep.toml"), "--out", str(out), "--workers", "0",
                            "--no-plots"]))
    meta = json.loads((out / "sweep.json").read_text())
    assert _flags(meta)[0] is False and "bias" in meta["truth_not_exact"][0]
    assert not any("bias (plugin)" in step for step in meta["sensor_chain"])  # the base's chain


def test_dataset_on_two_workers_labels_its_truth(folder):
    """Two samples randomising ``sensor.effects.knee.compression`` on 2 workers: each sample has its
    own value; the store, every truth variable, ``dataset.json`` and the manifest say the truth is
    not exact and why."""
    import xarray as xr

    (folder / "data.toml").write_text(
        'base = "unknown.toml"\nsamples = 2\nseed = 4\nstages = [1, 80]\nlines = 8\ncolumns = 8\n'
        '[randomize]\n"sensor.effects.knee.compression" = { dist = "uniform", low = 0.01, high = 0.2 }\n')
    out = folder / "data"
    _ok(runner.invoke(app, ["dataset", str(folder / "data.toml"), "--out", str(out), "--workers", "2"]))
    manifest = pd.read_csv(out / "manifest.csv")
    drawn = manifest["sensor.effects.knee.compression"]
    assert list(manifest["status"]) == ["complete", "complete"] and drawn.between(0.01, 0.2).all()
    assert drawn.nunique() == 2 and manifest["config_sha256"].nunique() == 2
    store = xr.open_zarr(out / "data.zarr")
    assert store.attrs["truth_exact"] == 0 and "bias: plug-in" in store.attrs["truth_not_exact"]
    assert "gamma (plugin)" in store.attrs["sensor_chain"]
    truths = ("mean_dn", "linear_dn", "noise_std_dn", "photons", "clipped", "reflectance", "eq11_expected_dn",
              "true_hdr_dn")
    for name in truths:
        assert store[name].attrs["truth_exact"] == 0 and "bias" in store[name].attrs["truth_not_exact"], name
    assert "truth_exact" not in store["dn"].attrs
    info = json.loads((out / "dataset.json").read_text())
    assert _flags(info["base"])[0] is False
    sidecar = json.loads((out / "manifest.csv.json").read_text())  # the manifest's provenance
    assert sidecar["truth_exact"] is False and any("bias: plug-in" in r for r in sidecar["truth_not_exact"])
