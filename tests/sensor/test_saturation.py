"""EMVA saturation point of the model (variance maximum): the clipped-normal variance against a
seeded Monte Carlo of the pixel model's clip, and the full-well inversion."""

from __future__ import annotations

import numpy as np
import pytest

from bench_sim.config import SensorConfig
from bench_sim.sensor.model import stage_saturation_photons
from bench_sim.sensor.saturation import (
    full_well_for_saturation,
    stage_clip_kind,
    stage_variance_dn2_clipped,
    stage_variance_maximum_photons,
)

pytestmark = pytest.mark.physics


def test_clipped_variance_matches_a_monte_carlo_of_the_full_well_clip() -> None:
    """Electrons ~ Poisson(mu) clipped at FW, read noise after: the variance near the clip."""
    s = SensorConfig(full_well_e=5000.0, read_noise_e=3.0, dark_current_e_s=0.0, conversion_gain_dn_per_e=0.2,
                     adc_bits=12, quantum_efficiency=0.5)
    assert stage_clip_kind(s, 1, beta_bits=32) == "full_well"
    rng = np.random.default_rng(4)
    n = 400_000
    for mu_e in (4700.0, 4900.0, 5000.0):
        e = np.minimum(rng.poisson(mu_e, n), s.full_well_e) + rng.normal(0, s.read_noise_e, n)
        dn = np.rint(s.conversion_gain_dn_per_e * e + s.black_offset_dn)
        model = float(stage_variance_dn2_clipped(mu_e / 0.5, s, 0.0, 1, beta_bits=32))
        # sampling error of a variance: sqrt(2 / n) relative (plus the Poisson-vs-normal skew)
        assert dn.var() == pytest.approx(model, rel=0.03), mu_e


def test_variance_maximum_lies_below_the_clip_and_inverts() -> None:
    s = SensorConfig(full_well_e=8000.0, read_noise_e=5.0, dark_current_e_s=0.0, adc_bits=12,
                     conversion_gain_dn_per_e=0.4)
    p_max = stage_variance_maximum_photons(s, 1e-4, 1, beta_bits=32)
    p_clip = stage_saturation_photons(s, 1e-4, 1, beta_bits=32)
    # about three sqrt(FW) below the clip (where the clip starts to cut the distribution's tail)
    assert p_clip - 4 * 8000**0.5 / 0.55 < p_max < p_clip - 2 * 8000**0.5 / 0.55
    mu_e_sat = s.quantum_efficiency * p_max
    assert full_well_for_saturation(mu_e_sat) == pytest.approx(8000.0, rel=2e-4)
