"""EMVA 1288 analysis functions against closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from bench_sim.errors import BenchSimError
from bench_sim.metrics.emva1288 import (
    analyse_photon_transfer,
    dark_temporal_noise_e,
    dynamic_range_db,
    dynamic_range_from_series,
    mean_var_from_pair,
    photons_at_snr,
    photons_min_model,
    saturation_point,
    spatial_nonuniformity,
    stack_mean_var,
)
from bench_sim.metrics.emva_fit import fit_camera
from bench_sim.metrics.ptc_table import make_table

#: closed forms, invariants and seeded statistical tests (make test-fast)
pytestmark = pytest.mark.physics


def clipped_normal_mean_var(mu: np.ndarray, sigma: np.ndarray, clip: float) -> tuple[np.ndarray, np.ndarray]:
    """Mean and variance of min(X, clip) for X ~ N(mu, sigma^2) (closed form)."""
    a = (clip - mu) / sigma
    phi, cdf = stats.norm.pdf(a), stats.norm.cdf(a)
    # E[X; X < c] = mu Phi(a) - sigma phi(a); E[X^2; X < c] = (mu^2 + sigma^2) Phi - sigma (mu + c) phi
    m1 = mu * cdf - sigma * phi + clip * (1 - cdf)
    m2 = (mu**2 + sigma**2) * cdf - sigma * (mu + clip) * phi + clip**2 * (1 - cdf)
    return m1, m2 - m1**2


K, ETA, SIGMA_D_E, CLIP_DN, DARK_DN = 0.08, 0.6, 12.0, 3000.0, 40.0


def model_series(photons: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
    """A linear camera (EMVA eq. 5, 7) whose signal is clipped at CLIP_DN."""
    mu = DARK_DN + K * ETA * photons
    sigma = np.sqrt(K**2 * (SIGMA_D_E**2 + ETA * photons) + 1 / 12)
    mean, var = clipped_normal_mean_var(mu, sigma, CLIP_DN)
    dark_var = K**2 * SIGMA_D_E**2 + 1 / 12
    return mean, var, DARK_DN, dark_var


def test_mean_var_from_pair_cancels_fixed_pattern() -> None:
    rng = np.random.default_rng(0)
    fpn = rng.normal(0, 10.0, size=(128, 128))
    a = 100 + fpn + rng.normal(0, 2.0, size=fpn.shape)
    b = 100 + fpn + rng.normal(0, 2.0, size=fpn.shape)
    mean, var = mean_var_from_pair(a, b)
    assert mean == pytest.approx(100 + fpn.mean(), abs=0.05)
    assert abs(var / 4.0 - 1) < 4 * math.sqrt(2 / a.size)
    with pytest.raises(BenchSimError):
        mean_var_from_pair(a, b[:10])


def test_analysis_recovers_linear_model_exactly() -> None:
    photons = np.concatenate([np.geomspace(5, 40000, 40), np.linspace(58000, 64000, 13), [80000]])
    mean, var, dmean, dvar = model_series(photons)
    res = analyse_photon_transfer(photons, mean, var, dmean, dvar)
    assert res.k_dn_per_e == pytest.approx(K, rel=1e-3)
    assert res.quantum_efficiency == pytest.approx(ETA, rel=1e-3)
    assert res.dark_temporal_noise_e == pytest.approx(SIGMA_D_E, rel=1e-3)
    assert res.photons_min_model == pytest.approx(
        (math.sqrt(dvar / K**2 + 0.25) + 0.5) / ETA, rel=1e-3
    )
    # the measured SNR = 1 point agrees with the model on a dense enough grid
    assert res.photons_min == pytest.approx(res.photons_min_model, rel=0.02)
    assert res.saturation_capacity_e == pytest.approx(res.saturation_signal_dn / res.k_dn_per_e)
    assert res.dr_db == pytest.approx(20 * math.log10(res.photons_sat / res.photons_min))


def test_saturation_interpolated_between_levels_and_extrapolated() -> None:
    """The true maximum of the variance (a clipped normal) from a fine grid; on a 1 % grid the
    interpolated saturation is within 0.1 dB of it, the grid maximum within one step; the
    extrapolated one is exactly plateau / R."""
    fine = np.linspace(50000, 68000, 200001)
    m_f, v_f, _, _ = model_series(fine)
    p_true = fine[np.argmax(v_f)]
    for offset in (0.0, 0.3, 0.6):  # grids not aligned with the peak
        grid = p_true * (0.9 + 0.01 * offset + 0.01 * np.arange(15))
        photons = np.concatenate([np.geomspace(5, 40000, 30), grid])
        mean, var, dmean, _ = model_series(photons)
        sig = mean - dmean
        sat_i = saturation_point(photons, sig, var, "interpolated")
        sat_g = saturation_point(photons, sig, var, "max_variance")
        assert abs(20 * math.log10(sat_i.photons / p_true)) < 0.1
        assert abs(sat_g.photons / p_true - 1) <= 0.0101
        r = K * ETA
        sat_e = saturation_point(photons, sig, var, "extrapolated", responsivity=r)
        assert sat_e.photons == pytest.approx(sig.max() / r, rel=1e-12)
        assert sat_e.photons == pytest.approx((CLIP_DN - DARK_DN) / r, rel=1e-3)


def test_unsaturated_series_and_unbracketed_snr_raise() -> None:
    photons = np.geomspace(5, 20000, 30)
    mean, var, dmean, dvar = model_series(photons)
    with pytest.raises(BenchSimError, match="does not reach saturation"):
        saturation_point(photons, mean - dmean, var)
    with pytest.raises(BenchSimError, match="darkest level"):
        photons_at_snr(np.array([100.0, 200.0]), np.array([2.0, 3.0]))
    with pytest.raises(BenchSimError, match="never reaches"):
        photons_at_snr(np.array([1.0, 2.0]), np.array([0.1, 0.2]))


def test_photons_at_snr_is_exact_on_power_laws_and_from_dark() -> None:
    p = np.geomspace(1, 1000, 7)
    assert photons_at_snr(p, 0.1 * np.sqrt(p)) == pytest.approx(100.0, rel=1e-12)
    assert photons_at_snr(p, 0.02 * p) == pytest.approx(50.0, rel=1e-12)
    # a dark level (photons 0, SNR 0) brackets the crossing linearly
    assert photons_at_snr(np.array([0.0, 10.0]), np.array([0.0, 2.0])) == pytest.approx(5.0)


def test_dynamic_range_from_series_works_without_a_gain() -> None:
    """A fused-like image type: two regimes with different gains and noise (no single K).
    DR = mu_p.sat / mu_p.min from the series alone, matching the closed forms."""
    p = np.concatenate([[0.0], np.geomspace(0.5, 5000, 60), np.linspace(5100, 6000, 10)])
    signal = 8.0 * p
    std = np.where(p < 1000, np.sqrt(64.0 + 8.0 * p), 8 * np.sqrt(9.0 + p))
    sat_index = np.searchsorted(p, 5600)
    std[sat_index:] = std[sat_index:] * np.linspace(0.3, 0.0, p.size - sat_index)
    dr = dynamic_range_from_series(p, signal + 100.0, std, dark_signal=100.0)
    # SNR = 1 where 8 p = sqrt(64 + 8 p), i.e. 64 p^2 - 8 p - 64 = 0
    p_min_true = (8 + math.sqrt(64 + 4 * 64 * 64)) / (2 * 64)
    assert dr.photons_min == pytest.approx(p_min_true, rel=0.01)
    assert p[sat_index - 2] <= dr.photons_sat <= p[sat_index]
    assert dr.dr_db == pytest.approx(dynamic_range_db(dr.photons_sat, dr.photons_min))


@pytest.mark.parametrize(
    ("eta", "k", "dark_var_dn"), [(0.5, 0.1, 1.0), (0.9, 0.072, 0.98**2), (0.2, 2.0, 40.0)]
)
def test_sensitivity_threshold_gives_unit_snr_in_the_linear_model(eta, k, dark_var_dn) -> None:
    """At ``photons_min_model`` the linear model's SNR, eta p / sqrt(sigma_y.dark^2 / K^2 +
    eta p) (signal and noise in electrons), is exactly 1, and it grows monotonically past it."""
    p = photons_min_model(eta, k, dark_var_dn)

    def snr(photons: float) -> float:
        return eta * photons / math.sqrt(dark_var_dn / k**2 + eta * photons)

    assert snr(p) == pytest.approx(1.0, rel=1e-12)
    assert snr(0.9 * p) < 1.0 < snr(1.1 * p)


def test_dark_noise_in_electrons_inverts_the_dn_variance() -> None:
    """sigma_d [e-] from the dark variance [DN^2]: K^2 sigma_d^2 + sigma_q^2 gives the variance
    back; m roundings of a stage-m word are taken off; a variance below the quantisation floor
    clamps to 0."""
    for var, k, q in ((1.0 + 1 / 12, 0.1, 1 / 12), (9.0, 0.072, 10 / 12)):
        sd = dark_temporal_noise_e(var, k, q)
        assert (k * sd) ** 2 + q == pytest.approx(var)
    assert dark_temporal_noise_e(0.05, 0.1, 1 / 12) == 0.0
    assert dynamic_range_db(1000.0, 1.0) == pytest.approx(60.0)
    with pytest.raises(BenchSimError):
        dynamic_range_db(0.0, 1.0)


def test_conversion_gain_is_the_photon_transfer_slope_over_the_linear_range() -> None:
    """Poisson electrons times K (plus a dark floor), clipped: the fitted slope is K within its
    reported standard error (absolute weights: one pixel, n samples per level); levels above
    70 % of saturation are not in the fit."""
    rng = np.random.default_rng(11)
    k, n = 0.25, 20000
    electrons = np.geomspace(50, 30000, 36)
    reads = rng.poisson(electrons[:, None], (36, n)) * k + rng.normal(0, 2.0, (36, n))
    samples = np.minimum(reads, k * 21000)
    dark = rng.normal(0, 2.0, (2, n))
    mean, var = samples.mean(axis=1), samples.var(axis=1, ddof=1)
    tab = make_table(
        np.ones(37), photons_per_pixel=np.r_[0.0, electrons / 0.5], mean_dn=np.r_[dark.mean(), mean],
        var_dn2=np.r_[dark.var(ddof=1), var], pixels=1, images=n, dark_images=2 * n,
    )
    fit = fit_camera(tab)
    assert abs(fit.k_dn_per_e - k) < 3.5 * fit.k_se and fit.k_se < 0.01 * k
    assert fit.linear.any() and mean[fit.linear].max() - dark.mean() <= 0.7 * fit.saturation_signal_dn


def test_spatial_nonuniformity_from_stacks() -> None:
    rng = np.random.default_rng(4)
    n, shape = 16, (64, 128)
    dsnu_dn, prnu, k = 2.0, 0.01, 0.1
    offset = rng.normal(0, dsnu_dn, shape)
    gain = 1 + rng.normal(0, prnu, shape)
    dark = 50 + offset + rng.normal(0, 3.0, (n, *shape))
    bright = 50 + offset + 1000 * gain + rng.normal(0, 10.0, (n, *shape))
    mu, s2, t2 = stack_mean_var(dark)
    assert t2 == pytest.approx(9.0, rel=0.02)
    assert math.sqrt(s2) == pytest.approx(offset.std(), rel=0.03)
    res = spatial_nonuniformity(bright, dark, k)
    assert res["dsnu_e"] == pytest.approx(offset.std() / k, rel=0.03)
    assert res["prnu"] == pytest.approx(1000 * gain.std() / 1000, rel=0.05)
