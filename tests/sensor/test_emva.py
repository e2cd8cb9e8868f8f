"""EMVA 1288 pixel model: shot noise statistics, fixed vs temporal patterns, switches, clipping."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from bench_sim.config import SensorConfig
from bench_sim.errors import BenchSimError
from bench_sim.sensor.emva import (
    FixedPattern,
    draw_fixed_pattern,
    expose,
    pixel_mean_var_dn,
    pixel_saturation_dn,
)
from tests.conftest import ALL_OFF

#: closed forms, invariants and seeded statistical tests (make test-fast)
pytestmark = pytest.mark.physics

T_INT_S = 100e-6


def sensor(**kw) -> SensorConfig:
    base = dict(rows=16, columns=64)
    base.update(kw)
    return SensorConfig(**base)


# ---------------------------------------------------------------- must show 1: shot noise


@pytest.mark.parametrize("lam", [0.7, 4.0, 37.5, 900.0])
def test_shot_noise_is_poisson(lam: float) -> None:
    """Electrons = Poisson(QE * photons): mean z-test, variance z-test (Poisson 4th moment) and
    the chi-square dispersion test; QE < 1 thins photons into a Poisson electron count."""
    s = sensor(
        **{**ALL_OFF, "shot_noise": True, "quantization": True}, quantum_efficiency=0.5,
        conversion_gain_dn_per_e=1.0, black_offset_dn=0.0, adc_bits=16, full_well_e=1e7,
    )
    rng = np.random.default_rng(1234)
    fixed = draw_fixed_pattern(s, rng)
    x = expose(np.full((200, 16, 64), 2.0 * lam), s, fixed, T_INT_S, rng).astype(np.float64).ravel()
    n = x.size
    mean, var = x.mean(), x.var(ddof=1)
    # mean: z-test against lambda, sd sqrt(lambda / n)
    assert abs(mean - lam) / np.sqrt(lam / n) < 4.0
    # variance: z-test, Var(s^2) = (mu4 - sigma^4 (n-3)/(n-1)) / n with mu4 = lam (1 + 3 lam)
    var_of_var = (lam * (1 + 3 * lam) - lam**2 * (n - 3) / (n - 1)) / n
    assert abs(var - lam) / np.sqrt(var_of_var) < 4.0
    # dispersion index: sum (x - mean)^2 / mean ~ chi2(n - 1) for Poisson data
    d = np.sum((x - mean) ** 2) / mean
    p_value = 2 * min(stats.chi2.cdf(d, n - 1), stats.chi2.sf(d, n - 1))
    assert p_value > 1e-4


def test_shot_noise_distribution_chi_square_goodness_of_fit() -> None:
    lam = 3.0
    s = sensor(
        **{**ALL_OFF, "shot_noise": True, "quantization": True}, quantum_efficiency=1.0,
        conversion_gain_dn_per_e=1.0, black_offset_dn=0.0, adc_bits=16,
    )
    rng = np.random.default_rng(99)
    x = expose(np.full((50, 16, 64), lam), s, draw_fixed_pattern(s, rng), T_INT_S, rng).ravel()
    kmax = 10
    observed = np.bincount(np.minimum(x, kmax), minlength=kmax + 1)
    probs = stats.poisson.pmf(np.arange(kmax), lam)
    probs = np.append(probs, 1.0 - probs.sum())
    chi2, p_value = stats.chisquare(observed, x.size * probs)
    assert p_value > 1e-3, chi2


def test_pixel_mean_var_closed_form_matches_simulation() -> None:
    """EMVA linear model var = K^2 (sigma_d^2 + mu_e) + 1/12 against the simulated temporal
    variance (difference of two frames, fixed patterns cancel) at several levels."""
    s = sensor(rows=32, columns=256)
    rng = np.random.default_rng(7)
    fixed = draw_fixed_pattern(s, rng)
    for photons in (0.0, 50.0, 400.0, 5000.0):
        a, b = expose(np.full((2, 32, 256), photons), s, fixed, T_INT_S, rng).astype(np.float64)
        n = a.size
        mean_model, var_model = pixel_mean_var_dn(photons, s, T_INT_S)
        mean = 0.5 * (a.mean() + b.mean())
        var = 0.5 * np.mean(((a - a.mean()) - (b - b.mean())) ** 2)
        # the model's mean averages the fixed patterns out; use this sensor's actual averages
        k = s.conversion_gain_dn_per_e
        mean_here = mean_model + k * s.quantum_efficiency * photons * (fixed.prnu_gain.mean() - 1)
        mean_here += k * T_INT_S * (fixed.dark_current_e_s.mean() - s.dark_current_e_s)
        mean_here += fixed.column_offset_dn.mean()
        assert abs(mean - mean_here) < 5 * np.sqrt(var_model / (2 * n))
        assert abs(var / var_model - 1) < 4 * np.sqrt(2.0 / n) + 0.01


# ---------------------------------------------------------- must show 4: fixed vs temporal


def test_fixed_pattern_is_identical_across_frames_and_calls() -> None:
    """Temporal noise off, fixed patterns on: every frame is the same (also across separate
    expose calls) and equals the closed form built from the FixedPattern arrays."""
    s = sensor(
        **{**ALL_OFF, "prnu_enabled": True, "dsnu_enabled": True, "column_fpn": True},
        dark_current_e_s=5e4, dsnu_e_s=5e3, prnu=0.05, column_offset_dn=2.0,
    )
    rng = np.random.default_rng(3)
    fixed = draw_fixed_pattern(s, rng)
    photons = np.full((5, 16, 64), 300.0)
    f1 = expose(photons, s, fixed, T_INT_S, rng)
    f2 = expose(photons[:2], s, fixed, T_INT_S, rng)
    assert np.array_equal(f1[0], f1[4]) and np.array_equal(f1[0], f2[1])
    k = s.conversion_gain_dn_per_e
    expected = (
        k * (s.quantum_efficiency * 300.0 * fixed.prnu_gain + fixed.dark_current_e_s * T_INT_S)
        + s.black_offset_dn + fixed.column_offset_dn
    )
    np.testing.assert_allclose(f1[0], expected, rtol=0, atol=1e-9)
    # and the pattern is really there (not a flat field)
    assert np.std(f1[0]) > 0.5


def test_temporal_noise_is_fresh_each_frame_and_uncorrelated_with_fixed_pattern() -> None:
    s = sensor(rows=32, columns=256, prnu=0.05)
    rng = np.random.default_rng(11)
    fixed = draw_fixed_pattern(s, rng)
    frames = expose(np.full((64, 32, 256), 2000.0), s, fixed, T_INT_S, rng).astype(np.float64)
    # no two frames are equal
    assert not np.array_equal(frames[0], frames[1])
    # the per-pixel mean over frames follows the PRNU pattern (fixed) ...
    mean_img = frames.mean(axis=0)
    r_fixed = np.corrcoef(mean_img.ravel(), fixed.prnu_gain.ravel())[0, 1]
    assert r_fixed > 0.9
    # ... while a frame difference (temporal only) does not: |r| < 4 / sqrt(n)
    diff = frames[1] - frames[0]
    r_temp = np.corrcoef(diff.ravel(), fixed.prnu_gain.ravel())[0, 1]
    assert abs(r_temp) < 4 / np.sqrt(diff.size)
    # temporal variance of the difference is twice the model's (z-test on the variance)
    _, var_model = pixel_mean_var_dn(2000.0, s, T_INT_S)
    var_diff = diff.var(ddof=1)
    assert abs(var_diff / (2 * var_model) - 1) < 4 * np.sqrt(2 / diff.size) + 0.01


def test_draw_fixed_pattern_statistics_switches_and_readonly() -> None:
    s = sensor(rows=64, columns=512, prnu=0.02, dsnu_e_s=10.0, column_offset_dn=1.5)
    fp = draw_fixed_pattern(s, np.random.default_rng(5))
    n = fp.prnu_gain.size
    assert abs(fp.prnu_gain.mean() - 1) < 4 * 0.02 / np.sqrt(n)
    assert abs(fp.prnu_gain.std() / 0.02 - 1) < 4 / np.sqrt(2 * n)
    assert abs(fp.dark_current_e_s.std() / 10.0 - 1) < 4 / np.sqrt(2 * n)
    assert abs(fp.column_offset_dn.std() / 1.5 - 1) < 4 / np.sqrt(2 * 512)
    with pytest.raises(ValueError):
        fp.prnu_gain[0, 0] = 2.0
    # switching one pattern off leaves the others unchanged (same draws)
    off = draw_fixed_pattern(s.model_copy(update={"prnu_enabled": False}), np.random.default_rng(5))
    assert np.all(off.prnu_gain == 1.0)
    assert np.array_equal(off.dark_current_e_s, fp.dark_current_e_s)
    assert np.array_equal(off.column_offset_dn, fp.column_offset_dn)
    none = draw_fixed_pattern(
        s.model_copy(update={"dsnu_enabled": False, "column_fpn": False}), np.random.default_rng(5)
    )
    assert np.all(none.dark_current_e_s == s.dark_current_e_s)
    assert np.all(none.column_offset_dn == 0.0)
    assert fp.window(8, 16).shape == (8, 16)
    with pytest.raises(ValueError):
        FixedPattern(np.ones((2, 3)), np.ones((2, 3)), np.zeros(2))


@pytest.mark.parametrize(
    "switch, expected_var",
    [
        ("read_noise", lambda s: s.conversion_gain_dn_per_e**2 * s.read_noise_e**2),
        ("dark_noise", lambda s: s.conversion_gain_dn_per_e**2 * s.dark_current_e_s * T_INT_S),
        ("quantization", lambda s: 1.0 / 12.0),
    ],
)
def test_each_temporal_source_alone(switch: str, expected_var) -> None:
    """Only one temporal source on: the dark temporal variance is that source's alone."""
    s = sensor(
        **{**ALL_OFF, switch: True}, rows=32, columns=256, dark_current_e_s=2e6,
        read_noise_e=20.0, black_offset_dn=20.3,
    )
    rng = np.random.default_rng(21)
    fixed = draw_fixed_pattern(s, rng)
    f = expose(np.zeros((2, 32, 256)), s, fixed, T_INT_S, rng).astype(np.float64)
    if switch == "quantization":
        # no noise before the ADC: the rounding error is fixed (same in both frames)
        assert np.array_equal(f[0], f[1])
        assert np.all(f == np.rint(f))
        return
    diff = f[1] - f[0]
    _, var_model = pixel_mean_var_dn(0.0, s, T_INT_S)
    assert var_model == pytest.approx(expected_var(s))
    assert abs(diff.var() / (2 * var_model) - 1) < 4 * np.sqrt(2 / diff.size)


def test_all_noise_off_is_deterministic_mean_model() -> None:
    s = sensor(**ALL_OFF)
    rng = np.random.default_rng(0)
    fixed = draw_fixed_pattern(s, rng)
    photons = np.linspace(0, 20000, 16 * 64).reshape(16, 64)
    v = expose(photons, s, fixed, T_INT_S, rng)
    assert v.dtype == np.float64
    mean, _ = pixel_mean_var_dn(photons, s, T_INT_S)
    unclipped = s.quantum_efficiency * photons < s.full_well_e
    np.testing.assert_allclose(v[unclipped], mean[unclipped], rtol=1e-12)


# ------------------------------------------------------------- must show 5: pixel saturation


def test_full_well_clip_where_expected() -> None:
    """K * full_well + black < 2**b - 1: pixels saturate at the full well, exactly at
    photons = full_well / QE (shot noise on: clipped electrons are exactly the full well)."""
    s = sensor(**{**ALL_OFF, "shot_noise": True, "quantization": True})
    assert s.conversion_gain_dn_per_e * s.full_well_e + s.black_offset_dn < pixel_saturation_dn(s)
    rng = np.random.default_rng(2)
    fixed = draw_fixed_pattern(s, rng)
    p_fw = s.full_well_e / s.quantum_efficiency
    sat_dn = np.rint(s.conversion_gain_dn_per_e * s.full_well_e + s.black_offset_dn)
    above = expose(np.full((4, 16, 64), 1.05 * p_fw), s, fixed, T_INT_S, rng)
    assert np.all(above == sat_dn)
    below = expose(np.full((4, 16, 64), 0.95 * p_fw), s, fixed, T_INT_S, rng)
    assert np.all(below < sat_dn)
    assert abs(below.mean() - (0.95 * s.full_well_e * s.conversion_gain_dn_per_e + s.black_offset_dn)) < 1


def test_adc_clip_where_expected() -> None:
    """K * full_well + black > 2**b - 1: the ADC clips at 2**b - 1 before the full well."""
    s = sensor(**{**ALL_OFF, "quantization": True}, conversion_gain_dn_per_e=0.1, adc_bits=10)
    rng = np.random.default_rng(2)
    fixed = draw_fixed_pattern(s, rng)
    top = pixel_saturation_dn(s)
    assert top == 1023
    p_adc = (top - s.black_offset_dn) / (s.conversion_gain_dn_per_e * s.quantum_efficiency)
    assert p_adc * s.quantum_efficiency < s.full_well_e
    assert np.all(expose(np.full((16, 64), 1.01 * p_adc), s, fixed, T_INT_S, rng) == top)
    assert np.all(expose(np.full((16, 64), 0.99 * p_adc), s, fixed, T_INT_S, rng) < top)
    assert np.all(expose(np.full((16, 64), 1e9), s, fixed, T_INT_S, rng) == top)


# ------------------------------------------------------------------ discipline and errors


def test_same_seed_same_frames_and_no_global_state() -> None:
    s = sensor()
    np.random.seed(0)  # noqa: NPY002 - the legacy global state must stay untouched
    before = np.random.get_state()[1].copy()  # noqa: NPY002
    outs = []
    for _ in range(2):
        rng = np.random.default_rng(42)
        fixed = draw_fixed_pattern(s, rng)
        outs.append(expose(np.full((3, 16, 64), 800.0), s, fixed, T_INT_S, rng))
    assert np.array_equal(outs[0], outs[1])
    assert np.array_equal(np.random.get_state()[1], before)  # noqa: NPY002
    rng = np.random.default_rng(43)
    other = expose(np.full((3, 16, 64), 800.0), s, draw_fixed_pattern(s, rng), T_INT_S, rng)
    assert not np.array_equal(outs[0], other)


def test_bad_inputs_raise_clear_errors() -> None:
    s = sensor()
    rng = np.random.default_rng(0)
    fixed = draw_fixed_pattern(s, rng)
    with pytest.raises(BenchSimError, match="rows, columns"):
        expose(np.zeros((16, 63)), s, fixed, T_INT_S, rng)
    with pytest.raises(BenchSimError, match=">= 0"):
        expose(np.full((16, 64), -1.0), s, fixed, T_INT_S, rng)
    with pytest.raises(BenchSimError, match="t_int_s"):
        expose(np.zeros((16, 64)), s, fixed, -1.0, rng)
