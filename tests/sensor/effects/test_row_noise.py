"""``kind = "row_noise"`` (:mod:`bench_sim.sensor.effects.row_noise`): one normal draw per row and
frame shared by the row's columns, so a stage word's residual ``dn - mean_dn`` is correlated
across the columns of a line (each line shifts as a whole) and not across lines; and its exact
truth: reads and stage words of many seeds against ``mean_dn`` and ``noise_std_dn`` with each clip
acting in turn."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from bench_sim.config import SensorConfig
from tests.sensor.effects.chain_stats import (
    assert_reads_follow_the_truth,
    assert_truth,
    clip_cfg,
    draw,
    expose_reads,
)

pytestmark = pytest.mark.physics

SIGMA_ROW_DN = 3.0
EFFECT = {"rn": {"kind": "row_noise", "rms_dn": SIGMA_ROW_DN}}


@pytest.mark.parametrize("adc_bits", [12, 9])
def test_reads_follow_the_truth(adc_bits):
    """10,000 reads per pixel of 4 x 64 pixels from 2 % to 125 % of the full well."""
    sensor = SensorConfig(rows=4, columns=64, adc_bits=adc_bits, effects=EFFECT)
    electrons = np.linspace(0.02, 1.25, 64) * sensor.full_well_e
    photons = np.broadcast_to(electrons / sensor.quantum_efficiency, (4, 64)).copy()
    assert_reads_follow_the_truth(expose_reads(sensor, photons, 10000), f"row noise, {adc_bits}-bit ADC")


CASES = [
    ("none", 1), ("full well", 1), ("ADC", 1), ("word at stage 1", 1), ("none", 80), ("word at stage 80", 80),
    pytest.param("full well", 80, marks=pytest.mark.slow), pytest.param("ADC", 80, marks=pytest.mark.slow),
]


@pytest.mark.parametrize(("clip", "stage"), CASES)
def test_stage_words_follow_the_truth(clip, stage):
    d = draw(clip_cfg(EFFECT, clip, stage), [stage])[stage]
    assert_truth(d, clip)


@pytest.mark.parametrize("stage", [1, 80])
def test_row_noise_shifts_whole_lines(stage):
    """Residuals ``e = dn - mean_dn`` of 16 seeds x 16 lines x 16 columns (no clip). A line's
    mean over its columns carries the ``m`` row draws its reads share: variance
    ``m sigma_row^2 + (sigma^2 - m sigma_row^2) / N`` (``sigma = noise_std_dn``) -- a chi-square
    test of the 256 line means, which a noise of pixels (``sigma^2 / N``) fails by a factor of
    ~7 (stage 1) and ~9 (stage 80); a column's mean over the lines has variance ``sigma^2 / L``
    (lines share no draw), and neighbouring lines' means are uncorrelated."""
    d = draw(clip_cfg(EFFECT, "none", stage), [stage])[stage]
    e = d.dn - d.mean  # (S, L, N)
    seeds, lines, cols = e.shape
    var = float(np.mean(d.sd**2))
    row_var = stage * SIGMA_ROW_DN**2
    line_means = e.mean(axis=2)
    lo, hi = stats.chi2.ppf([1e-6, 1 - 1e-6], line_means.size)
    expected = row_var + (var - row_var) / cols
    assert lo < float((line_means**2).sum()) / expected < hi
    assert float((line_means**2).sum()) / (var / cols) > hi  # not a noise of pixels
    col_means = e.mean(axis=1)
    lo, hi = stats.chi2.ppf([1e-6, 1 - 1e-6], col_means.size)
    assert lo < float((col_means**2).sum()) / (var / lines) < hi
    r = stats.pearsonr(line_means[:, :-1].ravel(), line_means[:, 1:].ravel()).statistic
    assert abs(r) < 5 / np.sqrt(seeds * (lines - 1))


def test_noise_std_dn_holds_the_row_noise():
    """Without a clip the stage word's variance is the default chain's plus ``m sigma_row^2``
    (the truth of the same sensor; the reads of a stage come from different rows and frames)."""
    for stage in (1, 80):
        with_rows = draw(clip_cfg(EFFECT, "none", stage, lines=2), [stage], seeds=1)[stage]
        plain = draw(clip_cfg({}, "none", stage, lines=2), [stage], seeds=1)[stage]
        assert np.allclose(with_rows.sd**2 - plain.sd**2, stage * SIGMA_ROW_DN**2, rtol=1e-9)
        assert np.allclose(with_rows.mean, plain.mean, rtol=1e-12)
