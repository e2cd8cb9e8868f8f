"""Sweeps that answer lighting questions (issue 24): flicker banding of every listed stage and
of Gamma_HDR beside its closed form, a light ratio of any two lights, keys that add a light,
plain ``points.csv``."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pandas as pd
import pytest

from bench_sim.errors import BenchSimError
from bench_sim.workflows.sweep.run import run_sweep
from bench_sim.workflows.sweep.spec import load_spec

ROOT = Path(__file__).resolve().parents[2]

#: a 100 x 8 sensor, 40 lines of 1 ms: 100 Hz is 0.1 cycle per line (nulls at m = 10, 20, ...),
#: 120 Hz 0.12 (nulls at m = 25, 50, 75, 100); the paper's wedge target under one uniform lamp
BASE = f"""
base = "{ROOT / 'scenes' / 'paper_rig.toml'}"
name = "flicker_bench"
lines = 40
[sensor]
rows = 100
columns = 8
[timing]
line_period_s = 1e-3
integration_time_s = 0.6e-3
[target]
panel_lines = 48
panel_columns = 16
[render]
spp = 4
[fusion]
mu1 = 10
mu2 = 80
[lights.strong]
enabled = false
[lights.weak]
enabled = false
"""

#: the lamp is not in the base: the points add it (a fill, 100 and 120 Hz)
SPEC = """
name = "mains_flicker"
base = "bench.toml"
quick = true
seed = 4
stages = [5, 10, 20, 25, 40, 50, 75, 100]
ratio = ["lamp", "lamp2"]
keep_images = true
[overrides]
lights.lamp2 = { kind = "directional", irradiance_w_m2 = 0.0 }
[[parameters]]
key = "lights.lamp.kind"
values = ["fill"]
[[parameters]]
key = "lights.lamp.irradiance_w_m2"
values = [0.25]
[[parameters]]
key = "lights.lamp.flicker_hz"
values = [100.0, 120.0]
[[parameters]]
key = "lights.lamp.flicker_phase_rad"
values = [0.7]
"""

#: tolerances: stages from the noise-free truth (only the neglected covariance of flicker and
#: motion within a line period), Gamma_HDR from the noisy fused image (8 columns x 40 lines)
STAGE_ATOL, HDR_ATOL = 5e-4, 4e-3


@pytest.fixture(scope="module")
def sweep(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("flicker")
    (folder / "bench.toml").write_text(BASE)
    (folder / "spec.toml").write_text(SPEC)
    run_sweep(folder / "spec.toml", folder / "out", workers=0, plots=False)
    return folder / "out"


@pytest.mark.physics
@pytest.mark.slow
def test_banding_table_follows_the_sinc_prediction_with_its_nulls(sweep):
    table = pd.read_csv(sweep / "points_images.csv")
    stages = table[table.image != "gamma_hdr"]
    assert len(stages) == 2 * 9 and set(table.flicker_hz) == {100.0, 120.0}  # 8 listed + mu1, mu2... once
    # the closed form, written out: fundamental d, sinc of the integration, Dirichlet of the sum
    for row in stages.itertuples():
        x = row.flicker_hz * 1e-3
        expected = abs(math.sin(math.pi * row.flicker_hz * 0.6e-3) / (math.pi * row.flicker_hz * 0.6e-3)
                       * math.sin(math.pi * row.stage * x) / (row.stage * math.sin(math.pi * x)))
        assert row.predicted_amplitude == pytest.approx(expected, abs=1e-9)
        assert abs(row.amplitude - row.predicted_amplitude) < STAGE_ATOL, row
        if row.predicted_amplitude > 0.05:  # the phase is defined away from the nulls
            assert abs(math.remainder(row.phase_rad - row.predicted_phase_rad, 2 * math.pi)) < 0.05, row
    nulls = stages[(stages.stage * stages.flicker_hz * 1e-3).round(6) % 1 == 0]
    assert set(zip(nulls.flicker_hz, nulls.stage, strict=True)) == {
        (100.0, 10), (100.0, 20), (100.0, 40), (100.0, 50), (100.0, 80), (100.0, 100),
        (120.0, 25), (120.0, 50), (120.0, 75), (120.0, 100)}
    assert (nulls.amplitude < STAGE_ATOL).all() and (stages.amplitude.max() > 0.5)
    hdr = table[table.image == "gamma_hdr"]
    assert len(hdr) == 2
    for row in hdr.itertuples():
        assert abs(row.amplitude - row.predicted_amplitude) < HDR_ATOL, row
    # 100 Hz: both fused stages (10, 80) sit on nulls, so Gamma_HDR shows no banding
    assert hdr[hdr.flicker_hz == 100.0].amplitude.item() < HDR_ATOL


def test_points_csv_is_plain_and_ratio_and_added_light(sweep):
    df = pd.read_csv(sweep / "points.csv")
    assert len(df) == 2 and list(df.point) == [0, 1]
    assert "light_ratio" in df.columns and df.light_ratio.isna().all()  # lamp2 does not emit
    meta = json.loads((sweep / "points.csv.json").read_text())
    assert meta["seed"] == 4 and meta["units"]["light_ratio"] == "1"
    assert not (sweep / "points.csv").read_text().startswith("#")


def test_kept_images_open_with_units(sweep):
    import xarray as xr

    ds = xr.open_zarr(sweep / "images" / "point_000001.zarr", consolidated=True)
    assert list(ds.stage.values) == [1, 5, 10, 20, 25, 40, 50, 75, 80, 100]
    assert ds.dn.attrs["units"] == "DN" and ds.gamma_hdr.dims == ("line", "column")
    assert ds.attrs["point"] == 1 and "flicker_hz = 120.0" in ds.attrs["config"]


def test_ratio_of_lights_not_in_a_point_is_one_line(tmp_path):
    (tmp_path / "bench.toml").write_text(BASE)
    (tmp_path / "spec.toml").write_text(SPEC.replace('"lamp2"]', '"lamp3"]'))
    with pytest.raises(BenchSimError, match=r"ratio = \['lamp', 'lamp3'\]: point 0 has no light 'lamp3'"):
        load_spec(tmp_path / "spec.toml")


def test_export_point_writes_a_config_simulate_loads(tmp_path):
    from typer.testing import CliRunner

    from bench_sim.cli import app
    from bench_sim.config import config_sha256, load_config

    (tmp_path / "bench.toml").write_text(BASE)
    (tmp_path / "spec.toml").write_text(SPEC)
    res = CliRunner().invoke(app, ["sweep", str(tmp_path / "spec.toml"), "--export-point", "1",
                                   str(tmp_path / "p1")])
    assert res.exit_code == 0, res.output
    point = load_spec(tmp_path / "spec.toml").points[1]
    cfg = load_config(tmp_path / "p1" / "config.toml")
    assert config_sha256(cfg) == config_sha256(point.cfg)
    assert cfg.lights.get("lamp").flicker_hz == 120.0 and cfg.lights.get("lamp").kind == "fill"
    info = json.loads((tmp_path / "p1" / "point.json").read_text())
    assert info["point"] == 1 and info["stages"][-1] == 100
    bad = CliRunner().invoke(app, ["sweep", str(tmp_path / "spec.toml"), "--export-point", "2",
                                   str(tmp_path / "p2")])
    assert bad.exit_code == 2 and "outside 0..1" in bad.output and not (tmp_path / "p2").exists()
