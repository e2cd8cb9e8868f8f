"""Calibration fits: the round trip ptc -> table -> fit recovers the sensor within the reported
standard errors; the standard errors are right (Monte Carlo); bad tables are one line each."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from bench_sim.config import config_from_dict
from bench_sim.errors import BenchSimError
from bench_sim.measure.uniform_field import measurement_pedestal_dn
from bench_sim.metrics.emva_fit import MIN_LINEAR_POINTS, fit_camera
from bench_sim.metrics.ptc_table import make_table
from bench_sim.metrics.weighted_fit import wls_line
from bench_sim.sensor.saturation import stage_clip_kind, stage_variance_maximum_photons
from bench_sim.workflows.calibrate_inputs import read_input
from bench_sim.workflows.ptc_job import run_ptc

pytestmark = pytest.mark.physics

#: cameras of the round trip: ADC bits, and where the noise and the clip come from
CAMERAS = {
    # 10-bit, shot-noise limited above ~170 e-, full-well clip (the paper's sensor)
    "paper_10bit_full_well": {},
    # 12-bit, shot-noise limited almost everywhere (2 e- read noise), full-well clip
    "shot_12bit": {"adc_bits": 12, "conversion_gain_dn_per_e": 0.5, "full_well_e": 6000.0,
                   "read_noise_e": 2.0, "black_offset_dn": 40.0},
    # 12-bit, dark-noise limited up to 900 e- of a 3000 e- well (30 e- read noise)
    "dark_12bit": {"adc_bits": 12, "conversion_gain_dn_per_e": 1.0, "full_well_e": 3000.0,
                   "read_noise_e": 30.0, "black_offset_dn": 100.0},
    # 10-bit, the ADC clips before the full well
    "adc_10bit": {"adc_bits": 10, "conversion_gain_dn_per_e": 1.5, "full_well_e": 20000.0,
                  "read_noise_e": 4.0},
}


def _cfg(sensor: dict) -> object:
    return config_from_dict({"sensor": {"rows": 16, "columns": 64, **sensor}, "fusion": {"mu1": 2, "mu2": 8}})


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CAMERAS))
def test_round_trip_recovers_the_sensor_within_the_reported_standard_errors(
    name: str, tmp_path: Path
) -> None:
    """``ptc`` on a bench with known parameters -> its table -> the fit: K, QE, the dark noise and
    the saturation capacity (EMVA: variance maximum, predicted by the clipped-normal closed form)
    each within 3.5 standard errors, and the standard errors small enough to mean something."""
    cfg = _cfg(CAMERAS[name])
    seed = 1 + list(CAMERAS).index(name)
    run_ptc(cfg, stages=[1], seed=seed, out=tmp_path, lines=16, columns=64, spatial_images=3)
    fit = fit_camera(read_input(tmp_path / "stage_001" / "ptc_table.csv").table)
    s, t = cfg.sensor, cfg.timing.t_int_s
    ped = measurement_pedestal_dn(cfg, (1,))
    kw = {"beta_bits": cfg.dtdi.beta_bits, "pedestal_dn": ped}
    if name == "adc_10bit":
        assert stage_clip_kind(s, 1, **kw) == "adc"
    truth = {
        "K": s.conversion_gain_dn_per_e,
        "QE": s.quantum_efficiency,
        "dark noise": math.sqrt(s.read_noise_e**2 + s.dark_current_e_s * t),
        "saturation": s.quantum_efficiency * stage_variance_maximum_photons(s, t, 1, **kw),
    }
    got = {
        "K": (fit.k_dn_per_e, fit.k_se),
        "QE": (fit.quantum_efficiency, fit.quantum_efficiency_se),
        "dark noise": (fit.dark_noise_e, fit.dark_noise_e_se),
        "saturation": (fit.saturation_capacity_e, fit.saturation_capacity_e_se),
    }
    for key, (value, se) in got.items():
        assert 0 < se < 0.12 * truth[key], (name, key, se)
        assert abs(value - truth[key]) < 3.5 * se, (name, key, value, truth[key], se)
    assert fit.bits == cfg.dtdi.beta_bits and not fit.bits_inferred
    assert 0.3 < fit.chi2_red_k < 3.0  # absolute weights (pixels known): the model fits the scatter


def test_weighted_fit_standard_errors_match_the_monte_carlo_scatter() -> None:
    """Over 400 seeded synthetic photon-transfer lines with relative noise, the slope's z-scores
    (estimate - truth) / reported s.e. have unit spread, for absolute and for scaled weights."""
    rng = np.random.default_rng(0)
    x = np.geomspace(10, 3000, 25)
    sigma = 0.02 * (x + 50)
    z_abs, z_rel = [], []
    for _ in range(400):
        y = 0.3 * x + rng.normal(0, sigma)
        a = wls_line(x, y, sigma, through_origin=True, absolute_sigma=True)
        r = wls_line(x, y, sigma / 7.0, through_origin=True, absolute_sigma=False)
        z_abs.append((a.slope - 0.3) / a.slope_se)
        z_rel.append((r.slope - 0.3) / r.slope_se)
        b = wls_line(x, y + 5.0, sigma, through_origin=False, absolute_sigma=True)
        assert abs(b.intercept - 5.0) < 5 * b.intercept_se
    for z in (np.array(z_abs), np.array(z_rel)):
        assert abs(z.mean()) < 0.2 and 0.88 < z.std() < 1.12


def _table(n: int = 40, **over: np.ndarray) -> dict:
    """A clean table: a dark row, then ``n`` lit levels up to beyond a clip at 1000 DN."""
    p = np.geomspace(20, 4000, n)
    sig = np.minimum(0.25 * p, 1000.0)
    var = np.where(0.25 * p < 950, 4.0 + 0.5 * sig, 1.0)
    cols = {
        "exposure_s": np.full(n + 1, 1e-3), "photons_per_pixel": np.r_[0.0, p],
        "mean_dn": np.r_[10.0, 10.0 + sig], "var_dn2": np.r_[4.0, var],
    }
    cols.update(over)
    return cols


def test_clean_synthetic_table_gives_its_parameters() -> None:
    tab = make_table(**_table(), pixels=10000)
    fit = fit_camera(tab)
    assert fit.k_dn_per_e == pytest.approx(0.5, rel=1e-9)
    assert fit.quantum_efficiency == pytest.approx(0.5, rel=1e-9)
    assert fit.dark_noise_e == pytest.approx(math.sqrt(4 - 1 / 12) / 0.5, rel=1e-9)


@pytest.mark.parametrize(
    ("change", "needle"),
    [
        ({"var_dn2": np.r_[4.0, -1.0, np.full(39, 5.0)]}, "var_dn2 = -1 < 0: a variance cannot be negative"),
        ({"exposure_s": np.r_[1e-3, 1e-3, 1e-3, 5e-4, np.full(37, 1e-3)]}, "non-monotonic exposure"),
        ({"photons_per_pixel": np.r_[0.0, 20.0, 10.0, np.geomspace(30, 4000, 38)]}, "does not increase"),
        ({"mean_dn": np.r_[10.0, np.full(40, np.nan)]}, "mean_dn = nan is not a finite number"),
    ],
)
def test_bad_tables_are_refused_in_one_line(change: dict, needle: str) -> None:
    with pytest.raises(BenchSimError) as exc:
        make_table(**_table(**change))
    assert needle in str(exc.value) and "\n" not in str(exc.value)


def test_a_table_ending_at_the_peak_gives_a_lower_bound_and_bad_ones_are_refused() -> None:
    cols = _table()
    cut = {k: v[:30] for k, v in cols.items()}  # stops below the clip: the variance still grows
    fit = fit_camera(make_table(**cut))
    assert fit.saturation_lower_bound and fit.clips_on == "unknown"
    assert fit.saturation_index == 28
    assert fit.saturation_signal_dn == pytest.approx(cols["mean_dn"][29] - 10.0)
    assert not fit_camera(make_table(**cols)).saturation_lower_bound
    few = _table(n=6)
    with pytest.raises(BenchSimError, match=f"need at least {MIN_LINEAR_POINTS}"):
        fit_camera(make_table(**few))
    lit = {k: v[1:] for k, v in cols.items()}
    with pytest.raises(BenchSimError, match="no dark level"):
        make_table(**lit)
