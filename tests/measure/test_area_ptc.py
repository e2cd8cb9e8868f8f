"""``ptc --area`` (issue 33): EMVA 1288 of the area sensor's raw frames through its chain of effects
recovers each effect's quantity (LE, the offset pattern at 0 s, the dark current's
non-uniformity, the defect pixels' counts and positions, the row-noise variance) within the error
the estimator states; the estimators against independent computations."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from bench_sim.cli import app
from bench_sim.config import config_from_dict
from bench_sim.measure.area_ptc import analyse_area, area_series, compare_area, measure_area, plan_area
from bench_sim.metrics.frame_series import analyse_frames
from bench_sim.metrics.nonuniformity import spatial_components
from bench_sim.sensor.emva_terms import sensor_emva_terms
from bench_sim.sensor.fixed_pattern import draw_fixed_pattern
from bench_sim.sensor.linearity import linearity_error
from bench_sim.sensor.response_curve import chain_response_curve
from bench_sim.workflows.calibrate import calibrate

pytestmark = pytest.mark.physics

#: every built-in effect with a closed form EMVA 1288 can measure
EFFECTS = {
    "compress": {"kind": "nonlinearity", "compression": 0.03},
    "bad": {
        "kind": "defects",
        "hot_rate": 2e-3,
        "warm_rate": 2e-3,
        "cold_rate": 2e-3,
        "stuck_rate": 1e-3,
        "rts_rate": 2e-3,
    },
    "offsets": {"kind": "offset_pattern", "rms_e": 1.5},
    "rows": {"kind": "row_noise", "rms_dn": 1.0},
}


def _cfg(effects: dict) -> object:
    return config_from_dict({"sensor": {"effects": effects}})


@pytest.mark.slow
def test_ptc_area_recovers_each_effects_quantity_within_its_stated_error() -> None:
    """Every quantity within 3.5 stated standard errors of the chain's closed form (the LE of the
    chain's exact mean response on the same levels); every kind of defect pixel found with its
    count and its positions."""
    cfg = _cfg(EFFECTS)
    plan = plan_area(cfg)
    measured, predicted = analyse_area(cfg, plan, measure_area(cfg, plan, seed=1))
    cmp = compare_area(measured, predicted)
    rows = {r["quantity"]: r for r in cmp["quantities"]}
    assert set(rows) >= {
        "linearity_error_percent",
        "dsnu0_e (pixel part)",
        "dark_current_nu_e_s",
        "row_noise_var_dn2",
        "K_dn_per_e",
    }
    assert predicted["linearity_error_percent"].value > 0.5  # the 3 % compression shows
    for name, r in rows.items():
        assert abs(r["z"]) < 3.5, (name, r)
        assert r["standard_error"] < 0.15 * max(abs(r["predicted"]), 1e-3) or name.startswith(
            "dsnu0_column"
        ), r
    for kind, d in cmp["defect_pixels"].items():
        assert d["predicted"] > 0 and d["measured"] == d["predicted"] and d["positions_agree"], (kind, d)


@pytest.mark.slow
def test_the_stated_errors_have_unit_spread_over_seeds() -> None:
    """Over 20 physical sensors (seeds): (measured - drawn) / stated error of K, the offset pattern's
    pixel part, the dark current's non-uniformity and the row noise have a standard deviation in
    0.6 .. 1.5 and a mean within 0.7 of 0; the defect pixels are found exactly every time."""
    effects = {k: v for k, v in EFFECTS.items() if k != "compress"}
    cfg = _cfg(effects)
    plan = plan_area(cfg)
    names = ("K_dn_per_e", "dsnu0_e (pixel part)", "dark_current_nu_e_s", "row_noise_var_dn2")
    z: dict[str, list[float]] = {n: [] for n in names}
    for seed in range(20):
        frames = measure_area(cfg, plan, seed=1000 + seed)
        measured = analyse_frames(area_series(cfg, plan, frames))
        cmp = compare_area(measured, sensor_emva_terms(cfg.sensor, frames.fixed, plan.t_int_s))
        for r in cmp["quantities"]:
            if r["quantity"] in z:
                z[r["quantity"]].append(r["z"])
        assert all(d["positions_agree"] for d in cmp["defect_pixels"].values()), (seed, cmp["defect_pixels"])
    for name, values in z.items():
        assert 0.6 < float(np.std(values, ddof=1)) < 1.5 and abs(float(np.mean(values))) < 0.7, (name, values)


def test_le_is_the_weighted_line_of_emva_1288() -> None:
    """LE of a bent response against numpy's weighted polynomial fit (weights 1 / y: relative
    deviations) over 5-95 % of saturation; a straight line with noise reads at its noise floor."""
    x = np.linspace(100.0, 4000.0, 40)
    y = 0.5 * x * (1.0 - 0.04 * (x / 4000.0) ** 2)
    var = np.r_[x[:-6], [3900.0, 3950.0, 3800.0, 100.0, 1.0, 0.5]]  # the variance peaks at level 35
    le = linearity_error(x, y, var)
    sel = (y >= 0.05 * y[35]) & (y <= 0.95 * y[35]) & (np.arange(40) <= 35)
    b, a = np.polynomial.polynomial.polyfit(x[sel], y[sel], 1, w=1.0 / y[sel])
    dev = 100 * (y[sel] - (a * x[sel] + b)) / (a * x[sel] + b)
    assert le.saturation_index == 35 and le.le_percent == pytest.approx(
        0.5 * (dev.max() - dev.min()), rel=1e-9
    )
    assert le.slope == pytest.approx(a, rel=1e-9) and le.offset == pytest.approx(b, rel=1e-6, abs=1e-9)
    rng = np.random.default_rng(3)
    se = 0.002 * 0.5 * x
    straight = linearity_error(x, 0.5 * x + rng.normal(0, se), var, signal_se_dn=se)
    assert straight.le_percent == pytest.approx(straight.floor_percent, abs=3 * straight.le_se_percent)
    assert straight.floor_percent > 0.1


def test_the_chain_response_curve_is_the_linear_model_far_from_the_clips() -> None:
    """Without effects and below the clips the exact mean response is the linear model over the
    physical sensor: K QE mean(g) mu_p, its variance K^2 (QE g mu_p + sigma_d^2) + 1/12."""
    cfg = config_from_dict({"sensor": {"rows": 16, "columns": 32}, "fusion": {"mu1": 2, "mu2": 8}})
    s = cfg.sensor
    fixed = draw_fixed_pattern(s, np.random.default_rng(2))
    p = np.array([2000.0, 8000.0, 12000.0])
    sig, var = chain_response_curve(s, fixed, p, 1e-3)
    k = s.conversion_gain_dn_per_e
    assert sig == pytest.approx(k * s.quantum_efficiency * fixed.prnu_gain.mean() * p, rel=1e-9)
    dark = (fixed.dark_current_e_s * 1e-3).mean()
    light = s.quantum_efficiency * fixed.prnu_gain.mean() * p
    assert var == pytest.approx(k**2 * (light + dark + s.read_noise_e**2) + 1 / 12, rel=1e-9)


def test_spatial_components_recover_column_row_and_pixel_patterns() -> None:
    """Numpy maps of known column and row patterns, a pixel pattern drawn anew each time (a new
    physical sensor) and noise: over 200 draws each part less its drawn value, over its stated
    error, has unit spread and no bias; the total is the pattern's own variance."""
    rng = np.random.default_rng(7)
    m, n, noise_var = 64, 128, 0.4
    col, row = rng.normal(0, 0.3, n), rng.normal(0, 0.2, m)
    z: dict[str, list[float]] = {"column": [], "row": [], "pixel": [], "total": []}
    for _ in range(200):
        pix = rng.normal(0, 0.5, (m, n))
        pattern = col[None, :] + row[:, None] + pix
        resid = pix - pix.mean(0) - pix.mean(1)[:, None] + pix.mean()
        truth = {
            "column": col.var(ddof=1),
            "row": row.var(ddof=1),
            "pixel": float(np.sum(resid**2)) / ((m - 1) * (n - 1)),
            "total": pattern.var(),
        }
        sc = spatial_components(pattern + rng.normal(0, math.sqrt(noise_var), (m, n)), noise_var)
        for part in z:
            z[part].append((getattr(sc, part) - truth[part]) / getattr(sc, f"{part}_se"))
    for part, values in z.items():
        assert abs(np.mean(values)) < 0.25 and 0.8 < np.std(values) < 1.25, (
            part,
            np.mean(values),
            np.std(values),
        )


@pytest.mark.slow
def test_cli_area_writes_frames_that_calibrate_fits_to_the_same_numbers(tmp_path: Path) -> None:
    """``bench-sim ptc --area`` writes its set; ``calibrate`` on its ``frames.npz`` runs the same
    estimator and reports the same K, dark noise and saturation (with their errors)."""
    cfg_file = tmp_path / "bench.toml"
    cfg_file.write_text('[sensor.effects.rows]\nkind = "row_noise"\nrms_dn = 0.5\n')
    res = CliRunner().invoke(
        app, ["ptc", str(cfg_file), "--area", "--seed", "3", "--out", str(tmp_path / "a")]
    )
    assert res.exit_code == 0, res.output
    area = json.loads((tmp_path / "a" / "area_results.json").read_text())
    for name in ("frames.npz", "area_comparison.csv", "defects.csv", "area_results.json"):
        assert (tmp_path / "a" / name).is_file(), name
    cal = calibrate(tmp_path / "a" / "frames.npz", tmp_path / "c", chain=False)
    for key in ("k_dn_per_e", "k_se", "dark_noise_e", "dark_noise_e_se", "saturation_capacity_e"):
        assert cal["fit"][key] == pytest.approx(area["measured"]["fit"][key], rel=1e-12), key
    row = {r["quantity"]: r for r in area["comparison"]["quantities"]}["row_noise_var_dn2"]
    assert abs(row["z"]) < 3.5 and row["predicted"] == pytest.approx(0.25)
