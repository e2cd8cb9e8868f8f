"""The sensor's closed forms (bench_sim.sensor.model) against the simulated sensor and DTDI.

Every expectation here is measured on the simulation (seeded, with a statistical tolerance), or
follows from a property the formula must have (a root of SNR = 1, a monotone clip); none
restates the formula under test.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench_sim.config import DTDIConfig, SensorConfig
from bench_sim.errors import BenchSimError
from bench_sim.sensor.model import (
    check_beta_bits,
    photons_at_snr1,
    stage_dark_std_dn,
    stage_mean_var_dn,
    stage_offset_dn,
    stage_saturation_photons,
    stage_snr1_photons,
    stage_variance_dn2,
)
from bench_sim.sensor.stream import sensor_dtdi_pass

#: closed forms, invariants and seeded statistical tests (make test-fast)
pytestmark = pytest.mark.physics

T_INT_S = 100e-6
NO_FPN = {"prnu_enabled": False, "dsnu_enabled": False, "column_fpn": False}


def _temporal_mean_var(img: np.ndarray) -> tuple[float, float, int]:
    """Mean and temporal variance of a uniform stage image (variance down each column, where
    the fixed pattern is constant), with the degrees of freedom of the variance."""
    x = np.asarray(img, dtype=np.float64)
    return float(x.mean()), float(np.mean(x.var(axis=0, ddof=1))), x.shape[1] * (x.shape[0] - 1)


@pytest.mark.parametrize(
    ("photons", "stage", "quantization"),
    [(0.0, 1, True), (0.0, 12, True), (800.0, 4, True), (3000.0, 12, False), (150.0, 7, False)],
)
def test_stage_mean_and_variance_match_the_simulation(photons: float, stage: int, quantization: bool) -> None:
    """Mean and variance of simulated stage-m values agree with the closed form (z < 4)."""
    s = SensorConfig(rows=stage, columns=128, quantization=quantization, **NO_FPN)
    dtdi = DTDIConfig(beta_bits=20, pedestal_dn=200)
    lines = 300
    out = sensor_dtdi_pass(
        np.full((lines + stage - 1, stage, 128), photons), s, dtdi, T_INT_S, [stage],
        np.random.default_rng(1000 + stage), lines=lines,
    )
    mean, var, dof = _temporal_mean_var(out[stage])
    mean_model, var_model = stage_mean_var_dn(photons, s, T_INT_S, stage, pedestal_dn=dtdi.pedestal_dn)
    assert abs(var / var_model - 1) < 4 * math.sqrt(2 / dof), (var, var_model)
    se_mean = math.sqrt(var_model / out[stage].size)
    assert abs(mean - mean_model) < 4 * se_mean + 1e-9, (mean, mean_model)


def test_variance_without_pixel_quantization_keeps_one_word_rounding() -> None:
    """Noise-free electrons with a fractional DN value: the only variance left is the word's
    rounding of a uniformly spread fraction, i.e. a uniform error of 1 DN width."""
    v = stage_variance_dn2(5, 0.0, conversion_gain_dn_per_e=0.1, dark_noise_e=0.0, quantization=False)
    u = np.random.default_rng(0).uniform(0, 1, 200_000)
    assert float(v) == pytest.approx(np.var(np.rint(u) - u), rel=0.02)
    # with the ADC quantising every read, m independent roundings add up
    vq = stage_variance_dn2(5, 0.0, conversion_gain_dn_per_e=0.1, dark_noise_e=0.0)
    assert float(vq) == pytest.approx(5 * np.var(np.rint(u) - u), rel=0.02)


def test_dark_spread_matches_the_simulated_fixed_and_temporal_noise() -> None:
    """Spread of the dark stage value over columns and lines with every fixed pattern on."""
    s = SensorConfig(rows=40, columns=1024, dsnu_e_s=2000.0, column_offset_dn=0.3)
    dtdi = DTDIConfig(beta_bits=16, pedestal_dn=300)
    out = sensor_dtdi_pass(
        np.zeros((64 + 39, 40, 1024)), s, dtdi, T_INT_S, [40], np.random.default_rng(5), lines=64
    )
    spread = float(np.std(out[40].astype(np.float64)))
    # 1024 columns: the column-coherent part is sampled 1024 times, sd of the estimate ~ 1/sqrt(2*1024)
    assert spread == pytest.approx(stage_dark_std_dn(s, T_INT_S, 40), rel=0.06)


@pytest.mark.parametrize("subtract_black", [True, False])
@pytest.mark.parametrize(("beta", "stage"), [(12, 10), (12, 80), (16, 80), (9, 3)])
def test_saturation_photons_is_where_the_mean_reaches_the_clip(
    subtract_black: bool, beta: int, stage: int
) -> None:
    """Noise off: below the predicted level the stage mean is below its clip, above it clipped."""
    s = SensorConfig(
        rows=stage, columns=4, shot_noise=False, dark_noise=False, read_noise=False, quantization=False,
        **NO_FPN,
    )
    dtdi = DTDIConfig(beta_bits=beta, subtract_black=subtract_black, pedestal_dn=32)
    p_sat = stage_saturation_photons(
        s, T_INT_S, stage, beta_bits=beta, subtract_black=subtract_black, pedestal_dn=dtdi.pedestal_dn
    )
    means = [
        float(
            sensor_dtdi_pass(
                np.full((stage + 1, stage, 4), f * p_sat), s, dtdi, T_INT_S, [stage],
                np.random.default_rng(0), lines=2,
            )[stage].mean()
        )
        for f in (0.97, 1.03, 2.0)
    ]
    below, above, plateau = means
    assert below < plateau - 1.0  # 3 % below the prediction: still on the linear response
    assert above == pytest.approx(plateau, abs=0.5)  # 3 % above: clipped (word or pixel)


def test_snr1_photons_give_unit_snr() -> None:
    """At the predicted level the model's own SNR is 1 (a root, not a restatement)."""
    s = SensorConfig()
    for m in (1, 10, 80):
        p = stage_snr1_photons(s, T_INT_S, m)
        mean, var = stage_mean_var_dn(p, s, T_INT_S, m)
        dark, _ = stage_mean_var_dn(0.0, s, T_INT_S, m)
        assert (mean - dark) / math.sqrt(var) == pytest.approx(1.0, rel=1e-9)
    # read-noise limited: the SNR = 1 level falls about as 1/sqrt(m)
    ratio = stage_snr1_photons(s, T_INT_S, 1) / stage_snr1_photons(s, T_INT_S, 100)
    assert ratio == pytest.approx(10, rel=0.1)
    assert photons_at_snr1(1.0, 1.0, 0.0) == pytest.approx(1.0)  # shot noise alone: 1 photon


def test_stage_offset_and_beta_validator() -> None:
    s = SensorConfig()
    assert stage_offset_dn(s, DTDIConfig(pedestal_dn=64), 80) == 64
    assert stage_offset_dn(s, DTDIConfig(pedestal_dn=64, subtract_black=False), 80) == 64 + 80 * 20.0
    for bad in (0, 33, 2.5, True):
        with pytest.raises(BenchSimError, match="beta"):
            check_beta_bits(bad)  # type: ignore[arg-type]
    assert check_beta_bits(np.int64(12)) == 12
