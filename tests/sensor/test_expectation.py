"""Exact expectation of clipped reads and stage words (:mod:`bench_sim.sensor.expectation`) and
``mean_dn`` of a pass: against the exact distribution of a read (Poisson electrons, full-well
clip, normal read noise, rounding, ADC range), its exact ``m``-fold convolution, and the sample
mean of ``dn`` over many seeds on clipped pixels (full-well, ADC and word clips; stages 1 and 80).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from bench_sim.pipeline import run_pass
from bench_sim.sensor.expectation import (
    EDGEWORTH_ERROR_BOUND_SD,
    ReadModel,
    clipped_normal_moments,
    clipped_sum_mean,
    read_cumulants,
)
from tests.conftest import tiny_cfg

pytestmark = pytest.mark.physics

K, FW, SIGMA, B = 0.072, 13500.0, 13.0, 20.0


def _read_pmf(lam: float, top: int) -> np.ndarray:
    """Exact P(v = d), d = 0 .. top, of one read (summed over the Poisson electrons)."""
    sd = np.sqrt(lam)
    n = np.arange(max(0, int(lam - 12 * sd)), int(lam + 12 * sd) + 1)
    e = np.minimum(n, FW)
    d = np.arange(top + 1)
    edges = (np.append(d - 0.5, top + 0.5) - B) / K
    cdf = stats.norm.cdf((edges[None, :] - e[:, None]) / SIGMA)
    cdf[:, 0], cdf[:, -1] = 0.0, 1.0
    return stats.poisson.pmf(n, lam) @ np.diff(cdf, axis=1)


@pytest.mark.parametrize(("lam", "top", "hi"), [
    (12000.0, 1023, None), (13300.0, 1023, None), (13500.0, 1023, None), (14200.0, 1023, None),  # full well
    (6700.0, 511, None), (6900.0, 511, None),  # the ADC top (2**9 - 1) before the full well
    (10900.0, 1023, 800.0), (11100.0, 1023, 800.0),  # a word clip folded into the read
])
def test_read_mean_and_variance_match_the_exact_distribution(lam, top, hi):
    rm = ReadModel(K, FW, SIGMA, float(top), True)
    k1, k2, _ = read_cumulants(np.array([lam]), 0.0, B, rm, hi_dn=hi)
    p = _read_pmf(lam, top)
    v = np.clip(np.arange(top + 1), 0, hi if hi is not None else top)
    mean = (p * v).sum()
    var = (p * v * v).sum() - mean**2
    linear = K * lam + B
    assert k1[0] == pytest.approx(mean, abs=2e-3)
    assert k2[0] == pytest.approx(var, rel=0.02, abs=0.1)
    if abs(linear - (hi or min(top, K * FW + B))) < 8:  # near the clip the linear mean is wrong
        assert abs(linear - mean) > 0.5


@pytest.mark.parametrize(("lam", "top", "hi"), [
    (7000.0, 511, None), (7100.0, 511, None), (7200.0, 511, None), (7300.0, 511, None),  # the ADC top
    (11300.0, 1023, 800.0), (11500.0, 1023, 800.0),  # a word clip folded into the read
])
def test_a_read_pinned_to_a_clip_has_the_exact_variance(lam, top, hi):
    """A read that mostly sits at a clip barely varies: the rounding's 1/12 DN^2 counts only where
    the read is inside its clips (it was added in full: 0.083 DN^2 where the exact is 0.002)."""
    rm = ReadModel(K, FW, SIGMA, float(top), True)
    _, k2, _ = read_cumulants(np.array([lam]), 0.0, B, rm, hi_dn=hi)
    p = _read_pmf(lam, top)
    v = np.clip(np.arange(top + 1), 0, hi if hi is not None else top)
    var = (p * v * v).sum() - (p * v).sum() ** 2
    assert k2[0] == pytest.approx(var, rel=0.05, abs=2e-3)


def _small_mean_moments(lam: float, offset: float, response) -> tuple[float, float]:
    """Exact mean and variance of a read of Poisson mean ``lam`` through ``response``, offset
    ``offset`` [DN] (sum over the counts, rounding, the clip at 0)."""
    n = np.arange(int(lam + 12 * np.sqrt(lam) + 13))
    d = np.arange(200)
    mu = K * response(np.minimum(n, FW).astype(float)) + offset
    cdf = stats.norm.cdf((np.append(d - 0.5, d[-1] + 0.5)[None, :] - mu[:, None]) / (K * SIGMA))
    cdf[:, 0], cdf[:, -1] = 0.0, 1.0
    p = stats.poisson.pmf(n, lam) @ np.diff(cdf, axis=1)
    mean = (p * d).sum()
    return mean, (p * d * d).sum() - mean**2


@pytest.mark.parametrize(("offset", "curve"), [(20.0, "gamma"), (3.0, None)])
def test_reads_of_small_means_follow_the_exact_poisson_law(offset, curve):
    """Poisson means of 0 to 80 e- in one call, through a gamma curve (every read is integrated)
    or near the clip at 0 (3 DN: the linear cumulants do not apply): the exact sum over the counts
    below the hybrid sampler's switch (30 e-), the quadrature above. The Cornish-Fisher quantile
    of a mean of 0 gave 486 DN, and its far nodes handed negative electrons to the curve (NaN)."""
    lam = np.array([0.0, 0.5, 3.0, 12.0, 28.0, 40.0, 80.0])

    def gamma(e):
        return FW * (e / FW) ** 0.85

    response = gamma if curve else None
    k1, k2, _ = read_cumulants(lam, 0.0, offset, ReadModel(K, FW, SIGMA, 4095.0, True), response=response)
    exact = np.array([_small_mean_moments(m, offset, response or (lambda e: e)) for m in lam])
    assert np.allclose(k1, exact[:, 0], rtol=0, atol=2e-3)
    assert np.allclose(k2, exact[:, 1], rtol=0, atol=2e-3)


def test_clipped_normal_moments_against_quadrature():
    x = np.linspace(-30, 30, 600001)
    for mu, sd, lo, hi in [(3.0, 2.0, 0.0, 5.0), (-1.0, 0.5, 0.0, 10.0), (7.0, 3.0, -2.0, 8.0)]:
        w = stats.norm.pdf(x, mu, sd)
        c = np.clip(x, lo, hi)
        got = clipped_normal_moments(np.array(mu), sd, lo, hi)
        for k in (1, 2, 3):
            assert float(got[k - 1]) == pytest.approx(np.trapezoid(w * c**k, x), rel=1e-6, abs=1e-6)


@pytest.mark.parametrize(("m", "lam", "word"), [
    (2, 13400.0, 1990.0), (2, 13000.0, 1935.0), (3, 13500.0, 2965.0),  # sums of full-well clipped reads
    (10, 5599.0, 4095.0), (10, 5615.0, 4095.0), (80, 700.0, 4095.0), (80, 698.0, 4095.0),  # word at the mean
])
def test_stage_mean_matches_the_exact_convolution(m, lam, word):
    """The word's clip of the sum of ``m`` reads: the Edgeworth step against the exact pmf of the
    sum (the read's pmf convolved ``m`` times), within the documented bound."""
    p = _read_pmf(lam, 1023)
    size = 1024 * m
    f = np.maximum(np.fft.irfft(np.fft.rfft(p, size) ** m, size), 0.0)
    ped = 64.0
    s = np.arange(size) - m * B + ped
    exact = (f * np.clip(s, 0, word)).sum() / f.sum()
    rm = ReadModel(K, FW, SIGMA, 1023.0, True)
    k1, k2, k3 = read_cumulants(np.full(m, lam), 0.0, B, rm)
    got = float(clipped_sum_mean(k1.sum() - m * B + ped, k2.sum(), k3.sum(), 0.0, word))
    sd = np.sqrt(k2.sum())
    assert abs(got - exact) <= EDGEWORTH_ERROR_BOUND_SD * sd
    # the word sits within the sum's spread: neither the linear mean nor its clip is the answer
    assert abs(min(k1.sum() - m * B + ped, word) - exact) > 5 * EDGEWORTH_ERROR_BOUND_SD * sd


def _flat(irradiance: float, columns: int, lines: int, **sections):
    base = {"lines": lines, "sensor": {"rows": 80, "columns": columns},
            "target": {"layout": "uniform", "panel_columns": 16},
            "lights": {"strong": {"enabled": False}, "weak": {"irradiance_w_m2": irradiance}},
            "fusion": {"mu1": 1, "mu2": 80}}
    for k, v in sections.items():
        base[k] = {**base.get(k, {}), **v}
    return tiny_cfg(**base)


#: stage -> (columns, lines, seeds): stage 80 integrates 80 reads per pixel near the clip (slower)
SIZES = {1: (16, 16, 16), 80: (4, 4, 8)}


@pytest.mark.parametrize(("irradiance", "sections", "stage", "what"), [
    (515.0, {"dtdi": {"beta_bits": 20}}, 1, "full well"),
    pytest.param(515.0, {"dtdi": {"beta_bits": 20}}, 80, "full well", marks=pytest.mark.slow),
    (260.0, {"sensor": {"adc_bits": 9}, "dtdi": {"beta_bits": 20}}, 1, "ADC top"),
    pytest.param(260.0, {"sensor": {"adc_bits": 9}, "dtdi": {"beta_bits": 20}}, 80, "ADC top",
                 marks=pytest.mark.slow),
    (237.0, {"dtdi": {"beta_bits": 9}}, 1, "word"),
    (26.7, {}, 80, "word"),
])
def test_mean_dn_is_the_sample_mean_of_dn_on_clipped_pixels(irradiance, sections, stage, what):
    """Over many seeds (a new sensor and new noise each), ``dn - mean_dn`` averages to 0 within
    5 standard errors on the pixels near the clip, where ``linear_dn`` is off by more than 5."""
    columns, lines, seeds = SIZES[stage]
    cfg = _flat(irradiance, columns, lines, **sections)
    resid, lin_err = [], []
    for seed in range(seeds):
        d = run_pass(cfg, [stage], seed).dataset.sel(stage=stage)
        near = d.clipped.values | (np.abs(d.mean_dn.values - d.linear_dn.values) > 0.01)
        resid.append((d.dn.values.astype(np.float64) - d.mean_dn.values)[near])
        lin_err.append((d.linear_dn.values - d.mean_dn.values)[near])
    r = np.concatenate(resid)
    assert r.size > 0.5 * seeds * columns * lines, what
    se = r.std() / np.sqrt(r.size)
    assert abs(r.mean()) < 5 * se + 1e-3, (what, r.mean(), se)
    assert np.abs(np.concatenate(lin_err)).mean() > 5 * se, what
