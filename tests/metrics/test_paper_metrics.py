"""Eq. 15 and stage pairs, eq. 16-18 (omega, must show 4), SNR versus signal."""

from __future__ import annotations

import numpy as np
import pytest

from bench_sim.errors import BenchSimError
from bench_sim.fusion import fuse_dtdi_hdr_eq11
from bench_sim.metrics.dynamic_range import dr_increase_eq15_db, stage_pairs_for_db
from bench_sim.metrics.histogram import (
    dn_histogram,
    evaluate_eq18,
    hdr_binning,
    omega_eq17,
    stage_binning,
)
from bench_sim.metrics.snr import patch_snr, snr_versus_signal

#: closed forms, invariants and seeded statistical tests (make test-fast)
pytestmark = pytest.mark.physics


# ---------------------------------------------------------------- eq. 15
def test_eq15_values() -> None:
    assert dr_increase_eq15_db(10, 80) == pytest.approx(18.0618, abs=1e-4)
    assert dr_increase_eq15_db(5, 100) == pytest.approx(26.0206, abs=1e-4)
    with pytest.raises(BenchSimError):
        dr_increase_eq15_db(80, 10)


def test_stage_pairs_for_the_papers_26_db() -> None:
    assert stage_pairs_for_db(26.02) == [(5, 100)]
    # 18.06 dB = 20 lg 8: (5, 40), (10, 80) among 5..100 step 5
    assert stage_pairs_for_db(18.06) == [(5, 40), (10, 80)]
    assert stage_pairs_for_db(26.02, candidates=range(10, 101, 10)) == []


# ---------------------------------------------------------------- eq. 16-18
def test_omega_hand_computed() -> None:
    # 2 x 2 image, beta = 2: counts [2, 1, 0, 1], mean 1, population var (1+0+1+0)/4 = 0.5,
    # omega = 0.5 / (M*N = 4) = 0.125; sample variance 2/3 -> omega = 1/6
    img = np.array([[0, 0], [1, 3]])
    b = stage_binning(2)
    np.testing.assert_array_equal(dn_histogram(img, b), [2, 1, 0, 1])
    assert omega_eq17(img, b) == pytest.approx(0.125)
    assert omega_eq17(img, b, ddof=1) == pytest.approx(1 / 6)


def test_omega_hand_computed_hdr_binnings() -> None:
    # HDR of mu1 = 1, mu2 = 2, beta = 2: range 0..2*4 = 8 DN
    hdr = np.array([[0.0, 1.0], [2.0, 7.0]])
    rescaled = hdr_binning(2, 1, 2)  # 4 bins of 2 DN: counts [2, 1, 0, 1] -> 0.125
    integer = hdr_binning(2, 1, 2, "integer")  # 8 bins of 1 DN: [1,1,1,0,0,0,0,1]
    assert (rescaled.n_bins, rescaled.width_dn, integer.n_bins) == (4, 2.0, 8)
    assert omega_eq17(hdr, rescaled) == pytest.approx(0.125)
    # mean 0.5, deviations^2: 4 * 0.25 + 4 * 0.25 = 2 -> var 0.25 -> omega 0.0625
    assert omega_eq17(hdr, integer) == pytest.approx(0.0625)


def test_omega_extremes_and_range_check() -> None:
    b = stage_binning(4)  # 16 bins
    flat = np.arange(16).reshape(4, 4)  # one pixel per bin: variance 0
    spike = np.full((4, 4), 5)  # all 16 pixels in one bin
    assert omega_eq17(flat, b) == 0.0
    # counts: one 16, fifteen 0; mean 1; var = (15^2 + 15 * 1) / 16 = 15; omega = 15 / 16
    assert omega_eq17(spike, b) == pytest.approx(15 / 16)
    # a 32-bit word: 2**32 bins, computed without listing them; spike: omega = P (1 - 1/L) / L
    big = stage_binning(32)
    assert omega_eq17(spike, big) == pytest.approx(16 * (1 - 2.0**-32) / 2.0**32, rel=1e-12)
    with pytest.raises(BenchSimError, match="too many"):
        dn_histogram(spike, big)
    with pytest.raises(BenchSimError, match="outside the bins"):
        omega_eq17(np.array([16]), b)
    with pytest.raises(BenchSimError, match="outside the bins"):
        omega_eq17(np.array([-1]), b)


@pytest.mark.parametrize(
    ("g1", "omega1", "holds"),
    [
        # counts [1, 1, 1, 1]: variance 0, omega1 = 0 = omega(HDR): eq. 18's "<" fails
        ([[0, 1], [2, 3]], 0.0, False),
        # counts [3, 0, 0, 1]: mean 1, population variance (4 + 1 + 1 + 0) / 4 = 1.5, / 4 px
        ([[0, 0], [0, 3]], 0.375, True),
    ],
)
def test_eq18_on_hand_computed_histograms(g1, omega1, holds) -> None:
    """beta = 2 (4 bins), mu2/mu1 = 2: Gamma2 = [[0, 2], [3, 3]] has counts [1, 0, 1, 2] (mean 1,
    variance 0.5, omega 0.125); the HDR image [[0, 2], [4, 6]] falls one pixel per HDR bin of
    width 2 (omega 0). Eq. 18 holds only when omega(HDR) is below both stage omegas."""
    g2 = np.array([[0, 2], [3, 3]])
    hdr = np.array([[0.0, 2.0], [4.0, 6.0]])
    res = evaluate_eq18(np.array(g1), g2, hdr, mu1=1, mu2=2, beta=2)
    assert res.omega1 == pytest.approx(omega1)
    assert res.omega2 == pytest.approx(0.125)
    assert res.omega_hdr == pytest.approx(0.0)
    assert res.holds is holds
    d = res.as_dict()
    assert d["hdr_binning"]["n_bins"] == 4 and d["variance"].startswith("population")


def test_eq18_fails_for_the_fused_image_of_a_dark_scene() -> None:
    """A scene that never reaches the eq. 11 threshold: Gamma_HDR is Gamma2, so their omegas are
    equal and eq. 18 cannot hold however the values spread."""
    rng = np.random.default_rng(5)
    g1 = rng.integers(0, 64, (64, 64))
    g2 = np.minimum(8 * g1 + rng.integers(0, 8, g1.shape), 4095)
    hdr = fuse_dtdi_hdr_eq11(g1, g2, mu1=10, mu2=80, beta=12).hdr
    np.testing.assert_array_equal(hdr, g2)
    res = evaluate_eq18(g1, g2, hdr, mu1=10, mu2=80, beta=12)
    assert res.omega_hdr > 0 and not res.holds


# ---------------------------------------------------------------- SNR
def test_snr_of_patches_and_series() -> None:
    rng = np.random.default_rng(2)
    fpn = 50 * rng.standard_normal((100, 100))  # fixed pattern: cancels in the pair
    a = 1000 + fpn + 3 * rng.standard_normal(fpn.shape)
    b = 1000 + fpn + 3 * rng.standard_normal(fpn.shape)
    (p,) = patch_snr(a, b, [(slice(0, 50), slice(0, 50))], dark_mean_dn=10.0)
    assert p["mean_dn"] == pytest.approx(1000, abs=8)
    assert p["temporal_std_dn"] == pytest.approx(3.0, rel=0.05)
    assert p["snr"] == pytest.approx(p["signal_dn"] / p["temporal_std_dn"])
    assert p["snr"] == pytest.approx(990 / 3, rel=0.06)
    sig, snr = snr_versus_signal([1000.0, 20.0, 4105.0], [3.0, 2.0, 0.0], dark_mean_dn=10.0)
    np.testing.assert_allclose(sig, [990.0, 10.0, 4095.0])
    np.testing.assert_allclose(snr, [330.0, 5.0, 0.0])  # fully clipped level: no SNR
