"""Measured DR through sensor -> DTDI -> eq. 11 fusion (must show 2 and 3)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from bench_sim.config import DTDIConfig, SensorConfig
from bench_sim.experiments.dynamic_range import (
    measure_dynamic_range,
    photon_transfer_series,
    ptc_offset_dn,
)
from bench_sim.metrics.dynamic_range import dr_increase_eq15_db

T_INT_S = 100e-6
MU1, MU2 = 10, 80
SENSOR = SensorConfig(adc_bits=10)  # 10-bit pixels, the rest the paper rig's defaults


@pytest.fixture(scope="module")
def dr12() -> dict[str, Any]:
    return measure_dynamic_range(
        SENSOR, DTDIConfig(beta_bits=12), T_INT_S, MU1, MU2, np.random.default_rng(12)
    )


@pytest.fixture(scope="module")
def dr16() -> dict[str, Any]:
    return measure_dynamic_range(
        SENSOR, DTDIConfig(beta_bits=16), T_INT_S, MU1, MU2, np.random.default_rng(16)
    )


def test_word_limited_gain_equals_eq15(dr12: dict[str, Any]) -> None:
    """beta = 12: both stages clip at the output word, so the HDR gains 20 lg(mu2/mu1) over Gamma2."""
    eq15 = dr_increase_eq15_db(MU1, MU2)
    assert dr12["eq15_db"] == pytest.approx(eq15)
    assert abs(dr12["delta_db_vs_gamma2"] - eq15) <= 0.3
    # the dark end is Gamma2's: the HDR is gamma2 wherever gamma1 is below the threshold
    img = dr12["images"]
    assert img["hdr"]["photons_min"] == pytest.approx(img["gamma2"]["photons_min"])
    # and the bright end Gamma1's (same clip of gamma1)
    assert img["hdr"]["photons_sat"] == pytest.approx(img["gamma1"]["photons_sat"], rel=0.01)
    # over Gamma1 the gain is at the dark end only: read noise grows as sqrt(m) in DTDI, so
    # about 20 lg sqrt(mu2/mu1) = 9 dB, far less than eq. 15's 18 dB
    assert 6.0 < dr12["delta_db_vs_gamma1"] < 12.0


def test_pixel_limited_gain_shrinks(dr16: dict[str, Any]) -> None:
    """beta = 16 (observation): stage 10 tops out at pixel saturation, not at Phi_FS.

    Gamma2 clips at the word (2**16 - 1 - pedestal DN = 80 reads of about 818 DN), Gamma1 and the
    HDR at the pixel's full well (about 972 DN per read): the gain over Gamma2 is only
    20 lg(972 / 818) = about 1.5 dB instead of eq. 15's 18.06 dB.
    """
    eq15 = dr_increase_eq15_db(MU1, MU2)
    k = SENSOR.conversion_gain_dn_per_e
    pixel_top = min(SENSOR.full_well_e * k, 2**SENSOR.adc_bits - 1 - SENSOR.black_offset_dn)
    word_top = (2**16 - 1 - dr16["offset_dn"]) / MU2
    predicted = 20 * math.log10(pixel_top / word_top)
    gain = dr16["delta_db_vs_gamma2"]
    assert 0.0 < gain < eq15 - 10.0
    assert gain == pytest.approx(predicted, abs=0.3)
    # Gamma2 now has the larger DR of the two inputs (same bright end, sqrt(8) lower floor)
    assert dr16["dr_db"]["gamma2"] > dr16["dr_db"]["gamma1"]


def test_hdr_monotonic_noise_off() -> None:
    """Noise off: Gamma_HDR grows with the scene signal and equals gamma2 where that is unsaturated."""
    quiet = SENSOR.model_copy(
        update={
            "shot_noise": False,
            "dark_noise": False,
            "read_noise": False,
            "prnu_enabled": False,
            "dsnu_enabled": False,
            "column_fpn": False,
        }
    )
    levels = np.linspace(0.0, 25000.0, 400)  # beyond gamma1's saturation (~10,300 photons)
    s = photon_transfer_series(
        quiet, DTDIConfig(beta_bits=12), T_INT_S, MU1, MU2, np.random.default_rng(0), levels,
        lines=2, columns=4, offset_dn=0.0,
    )
    hdr, g1, g2 = s["hdr"]["mean_dn"], s["gamma1"]["mean_dn"], s["gamma2"]["mean_dn"]
    assert np.all(np.diff(hdr) >= 0)
    assert np.all(s["hdr"]["temporal_var_dn2"] == 0)
    unsat = g2 < 4095
    assert np.all(hdr[unsat] >= g2[unsat])
    assert np.all(hdr >= g2) and hdr.max() == 8 * 4095 and g1.max() == 4095
    assert np.any(~unsat) and np.any(unsat)


def test_hdr_monotonic_averaged_with_noise(dr12: dict[str, Any]) -> None:
    """With all noise on, the level means of Gamma_HDR rise with the signal (to 4 standard errors)."""
    n_pix = dr12["lines"] * dr12["columns"] * 2
    img = dr12["images"]
    hdr = np.asarray(img["hdr"]["mean_dn"])
    se = np.asarray(img["hdr"]["temporal_std_dn"]) / math.sqrt(n_pix)
    step_se = np.sqrt(se[1:] ** 2 + se[:-1] ** 2)
    assert np.all(np.diff(hdr) >= -4 * step_se)
    assert hdr[-1] > 7 * 4095 * 0.9  # reaches the extended range
    g2 = np.asarray(img["gamma2"]["mean_dn"])
    g2_se = np.asarray(img["gamma2"]["temporal_std_dn"]) / math.sqrt(n_pix)
    top = 4095 - dr12["offset_dn"]
    unsat = g2 + 5 * np.asarray(img["gamma2"]["temporal_std_dn"]) < top
    assert np.any(unsat)
    assert np.all(hdr[unsat] >= g2[unsat] - 4 * np.sqrt(se[unsat] ** 2 + g2_se[unsat] ** 2))


def test_offset_covers_the_dark_noise() -> None:
    # 6 sigma of 80 coherent column offsets and 80 incoherent reads
    k = SENSOR.conversion_gain_dn_per_e
    read_var = k**2 * (SENSOR.read_noise_e**2 + SENSOR.dark_current_e_s * T_INT_S) + 1 / 12
    dsnu_var = (k * SENSOR.dsnu_e_s * T_INT_S) ** 2
    sigma = math.sqrt(80**2 * SENSOR.column_offset_dn**2 + 80 * (read_var + dsnu_var))
    assert ptc_offset_dn(SENSOR, DTDIConfig(), T_INT_S, 80) == math.ceil(6 * sigma)
    # without black subtraction stage 80 carries 80 x black: the offset must cover it
    no_sub = DTDIConfig(subtract_black=False)
    assert ptc_offset_dn(SENSOR, no_sub, T_INT_S, 80) >= 80 * SENSOR.black_offset_dn


def test_gain_without_black_subtraction() -> None:
    """subtract_black off (stage m carries m x black): the offset is equalised, eq. 15 still holds."""
    r = measure_dynamic_range(
        SENSOR, DTDIConfig(beta_bits=12, subtract_black=False), T_INT_S, MU1, MU2,
        np.random.default_rng(3), n_levels=30, lines=16,
    )
    assert r["offset_dn"] >= MU2 * SENSOR.black_offset_dn
    assert abs(r["delta_db_vs_gamma2"] - dr_increase_eq15_db(MU1, MU2)) <= 0.3


def test_measure_dynamic_range_is_deterministic() -> None:
    kw: dict[str, Any] = {"n_levels": 10, "lines": 4, "columns": 8}
    a = measure_dynamic_range(SENSOR, DTDIConfig(), T_INT_S, MU1, MU2, np.random.default_rng(7), **kw)
    b = measure_dynamic_range(SENSOR, DTDIConfig(), T_INT_S, MU1, MU2, np.random.default_rng(7), **kw)
    c = measure_dynamic_range(SENSOR, DTDIConfig(), T_INT_S, MU1, MU2, np.random.default_rng(8), **kw)
    assert a == b
    assert a["images"]["gamma2"]["mean_dn"] != c["images"]["gamma2"]["mean_dn"]


def test_variance_max_saturation_is_refined() -> None:
    kw: dict[str, Any] = {"n_levels": 12, "lines": 4, "columns": 8}
    r = measure_dynamic_range(
        SENSOR, DTDIConfig(), T_INT_S, MU1, MU2, np.random.default_rng(1),
        saturation="interpolated", refine_rounds=1, refine_points=4, **kw,
    )
    assert r["saturation"] == "interpolated"
    assert len(r["photons"]) > 13  # 12 lit levels + dark + refinement levels
