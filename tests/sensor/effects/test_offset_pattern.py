"""``kind = "offset_pattern"`` (:mod:`bench_sim.sensor.effects.offset_pattern`): each pixel's own
offset at 0 s, normal with the rms of ``rms_e`` and ``rms_dn`` in quadrature (a chi-square test),
per pixel (not per column), from its own stream; and its exact truth: reads and stage words of
many seeds against ``mean_dn`` and ``noise_std_dn`` with each clip acting in turn."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from bench_sim.config import SensorConfig
from bench_sim.sensor.fixed_pattern import draw_fixed_pattern
from tests.sensor.effects.chain_stats import (
    assert_reads_follow_the_truth,
    assert_truth,
    clip_cfg,
    draw,
    expose_reads,
)

pytestmark = pytest.mark.physics

EFFECT = {"op": {"kind": "offset_pattern", "rms_e": 30.0, "rms_dn": 1.5}}


@pytest.mark.parametrize(("rms_e", "rms_dn", "seed"),
                         [(30.0, 0.0, 0), (0.0, 2.0, 1), (30.0, 1.5, 2), (1.5, 0.0, 3)])
def test_offsets_are_normal_with_the_rms_in_quadrature(rms_e, rms_dn, seed):
    """On 200 x 150 pixels the sum of squared offsets over ``sigma^2 = (K rms_e)^2 + rms_dn^2``
    lies within the chi-square(30,000) quantiles of 1e-6; the offsets are normal (a
    Kolmogorov-Smirnov test) and belong to pixels: the column means hold only ``1/rows`` of the
    variance (a chi-square test of the column means)."""
    sensor = SensorConfig(rows=200, columns=150, effects={"op": {"kind": "offset_pattern", "rms_e": rms_e,
                                                                  "rms_dn": rms_dn}})
    o = draw_fixed_pattern(sensor, np.random.default_rng(seed)).offset_dn
    assert o is not None and o.shape == (200, 150)
    sigma2 = (sensor.conversion_gain_dn_per_e * rms_e) ** 2 + rms_dn**2
    lo, hi = stats.chi2.ppf([1e-6, 1 - 1e-6], o.size)
    assert lo < float((o**2).sum()) / sigma2 < hi
    assert stats.kstest(o.ravel() / np.sqrt(sigma2), "norm").pvalue > 1e-4
    cols = o.mean(axis=0)
    lo, hi = stats.chi2.ppf([1e-6, 1 - 1e-6], cols.size)
    assert lo < float((cols**2).sum()) / (sigma2 / 200) < hi


def test_offset_pattern_leaves_the_default_patterns():
    plain, shifted = SensorConfig(rows=30, columns=20), SensorConfig(rows=30, columns=20, effects=EFFECT)
    a = draw_fixed_pattern(plain, np.random.default_rng(9))
    b = draw_fixed_pattern(shifted, np.random.default_rng(9))
    assert a.offset_dn is None and b.offset_dn is not None
    for name in ("prnu_gain", "dark_current_e_s", "column_offset_dn"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name


@pytest.mark.parametrize("adc_bits", [12, 9])
def test_reads_follow_the_truth(adc_bits):
    """10,000 reads per pixel of 4 x 64 pixels from 2 % to 125 % of the full well."""
    sensor = SensorConfig(rows=4, columns=64, adc_bits=adc_bits, effects=EFFECT)
    electrons = np.linspace(0.02, 1.25, 64) * sensor.full_well_e
    photons = np.broadcast_to(electrons / sensor.quantum_efficiency, (4, 64)).copy()
    assert_reads_follow_the_truth(expose_reads(sensor, photons, 10000), f"offset pattern, {adc_bits}-bit ADC")


CASES = [
    ("none", 1), ("full well", 1), ("ADC", 1), ("word at stage 1", 1), ("none", 80), ("word at stage 80", 80),
    pytest.param("full well", 80, marks=pytest.mark.slow), pytest.param("ADC", 80, marks=pytest.mark.slow),
]


@pytest.mark.parametrize(("clip", "stage"), CASES)
def test_stage_words_follow_the_truth(clip, stage):
    d = draw(clip_cfg(EFFECT, clip, stage), [stage])[stage]
    assert_truth(d, clip)


def test_the_offsets_are_in_mean_dn_and_linear_dn():
    """Without a clip ``mean_dn = linear_dn``, and a stage-1 word's truth differs from the default
    chain's (same sensor seed: the same PRNU, DSNU, column offsets) by the pixel's offset in row 0."""
    cfg, plain = clip_cfg(EFFECT, "none", 1, lines=2), clip_cfg({}, "none", 1, lines=2)
    d, p = draw(cfg, [1], seeds=1)[1], draw(plain, [1], seeds=1)[1]
    assert np.allclose(d.linear, d.mean, rtol=1e-12, atol=1e-9)
    offset_row0 = d.fixed.offset_dn[0]
    assert np.allclose(d.mean - p.mean, offset_row0[None, :], atol=1e-9)
    assert np.std(offset_row0) > 1.0  # the pattern is there
