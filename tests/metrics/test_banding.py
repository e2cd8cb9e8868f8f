"""Flicker banding without the target's floor (bench_sim.metrics.banding.flat_banding): true nulls
read 0 within the computed noise bound, a known modulation is the closed form of the DTDI-averaged
flicker (bench_sim.metrics.flicker_theory), on a patterned target whose image footprint is not the
truth's (the cause of the old estimator's floor)."""

from __future__ import annotations

import cmath
import math

import numpy as np
import pytest

from bench_sim.metrics.banding import (
    banding_amplitude,
    flat_banding,
    flat_target_mask,
    illumination_profile,
)
from bench_sim.metrics.flicker_theory import predicted_banding
from bench_sim.rig.lights import window_mean

pytestmark = pytest.mark.physics

T, T_INT = 1e-3, 0.6e-3  # line period, integration time [s]
LINES, COLS = 400, 48


def _target(rng: np.random.Generator) -> np.ndarray:
    """A patterned truth reflectance (lines, columns): blocks of 6..40 lines x 4..12 columns."""
    refl = np.empty((LINES, COLS))
    j = 0
    while j < LINES:
        h = int(rng.integers(6, 41))
        n = 0
        while n < COLS:
            w = int(rng.integers(4, 13))
            refl[j:j + h, n:n + w] = rng.uniform(0.02, 0.9)
            n += w
        j += h
    return refl


def _imaged(refl: np.ndarray) -> np.ndarray:
    """The reflectance the image sees: the truth blurred by (1/4, 1/2, 1/4) along and across the
    track (a footprint the truth does not model), so ``image / truth`` follows the target at edges."""
    pad = np.pad(refl, 1, mode="edge")
    along = 0.25 * pad[:-2] + 0.5 * pad[1:-1] + 0.25 * pad[2:]
    return 0.25 * along[:, :-2] + 0.5 * along[:, 1:-1] + 0.25 * along[:, 2:]


def _stage_photons(refl: np.ndarray, m: int, f_hz: float, depth: float, phi: float,
                   gradient: float = 0.0) -> np.ndarray:
    """Noise-free stage-``m`` image: line ``j`` sums rows ``i < m`` in frames ``j + i``, frame ``k``
    weighted by the light's exact mean over its window, row ``i`` lit ``1 + gradient (i/(m-1) - 1/2)``
    times a spot shape across the columns."""
    k = np.arange(LINES + m)
    w = window_mean("sine", depth, f_hz, phi, k * T, T_INT) if depth else np.ones(k.size)
    rows = 1.0 + gradient * (np.arange(m) / max(m - 1, 1) - 0.5)
    light = np.array([np.dot(rows, w[j:j + m]) for j in range(LINES)])
    spot = 5e4 * (1.0 + 0.8 * np.cos(np.linspace(0, np.pi, COLS)))
    return light[:, None] * spot[None, :] * _imaged(refl)


def _noisy(photons: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return photons + np.sqrt(photons) * rng.standard_normal(photons.shape)  # shot noise


def test_no_flicker_reads_zero_where_the_old_estimator_has_a_floor() -> None:
    refl = _target(np.random.default_rng(0))
    ph = _stage_photons(refl, 10, 0.0, 0.0, 0.0)
    nu = 0.1
    old = banding_amplitude(illumination_profile(ph, refl), nu)
    assert old > 3e-4  # the target's floor
    fb = flat_banding(ph, refl, nu)
    assert fb.amplitude < 1e-12 and fb.columns_used == 1.0
    # on a noisy image: within the computed bound
    noisy = flat_banding(_noisy(ph, np.random.default_rng(1)), refl, nu)
    assert 0 < noisy.sd < 1e-3 and noisy.amplitude < 4 * noisy.sd


def test_sinc_null_reads_zero_even_with_unevenly_lit_rows() -> None:
    # f t_int = 1: every frame integrates whole periods, so no frame differs from another: a true
    # null at every stage, whatever the light per row (the DTDI null D_m = 0 is not, see below)
    f = 1.0 / T_INT
    refl = _target(np.random.default_rng(2))
    nu, amp, _ = predicted_banding(0.9, f, 0.3, T, T_INT, 7)
    assert amp < 1e-12
    for m in (1, 7, 30):
        ph = _stage_photons(refl, m, f, 0.9, 0.3, gradient=0.2)
        assert flat_banding(ph, refl, nu).amplitude < 1e-9
        noisy = flat_banding(_noisy(ph, np.random.default_rng(m)), refl, nu)
        assert noisy.amplitude < 4 * noisy.sd, (m, noisy)


def test_noise_bound_is_the_scatter_of_nulls() -> None:
    # the reported sd against the spread of P over independent noise draws (null, stage 10)
    refl = _target(np.random.default_rng(3))
    ph = _stage_photons(refl, 10, 0.0, 0.0, 0.0)
    rng = np.random.default_rng(4)
    draws = [flat_banding(_noisy(ph, rng), refl, 0.1) for _ in range(150)]
    p = np.array([d.amplitude * cmath.exp(1j * d.phase_rad) for d in draws])
    sd = np.mean([d.sd for d in draws])
    spread = math.sqrt(0.5 * (p.real.var() + p.imag.var()))
    assert spread == pytest.approx(sd, rel=0.2)  # 150 draws: the sd of an sd is ~6 %
    assert np.mean(np.abs(p) > 4 * sd) < 0.02


@pytest.mark.parametrize("m", [1, 3, 7, 25, 33])
@pytest.mark.parametrize("f_hz", [100.0, 120.0, 50.0])
def test_known_modulation_is_the_closed_form(m: int, f_hz: float) -> None:
    depth, phi = 0.8, 0.7
    refl = _target(np.random.default_rng(5))
    ph = _stage_photons(refl, m, f_hz, depth, phi)
    nu, amp, phase = predicted_banding(depth, f_hz, phi, T, T_INT, m)
    fb = flat_banding(ph, refl, nu)
    assert fb.amplitude == pytest.approx(amp, abs=1e-9), (m, f_hz)
    if amp > 0.05:
        assert abs(math.remainder(fb.phase_rad - phase, 2 * math.pi)) < 1e-6


def test_uneven_rows_leave_the_weighted_dirichlet_at_a_dtdi_null() -> None:
    # 100 Hz at 1 ms: D_m = 0 at m = 10, but rows lit 1 +- g/2 weight the m frames unevenly: the
    # banding is F sinc |sum_i s_i e^{2 pi i x i}| / sum_i s_i (the flicker_100hz preset's residual)
    f, depth, g, m = 100.0, 0.8, 0.056, 10
    refl = _target(np.random.default_rng(6))
    nu, amp_uniform, _ = predicted_banding(depth, f, 0.0, T, T_INT, m)
    assert amp_uniform < 1e-12
    s = 1.0 + g * (np.arange(m) / (m - 1) - 0.5)
    arg = math.pi * f * T_INT
    weighted = abs(np.sum(s * np.exp(2j * np.pi * f * T * np.arange(m)))) / s.sum()
    closed = depth * abs(math.sin(arg) / arg) * weighted
    fb = flat_banding(_stage_photons(refl, m, f, depth, 0.0, gradient=g), refl, nu)
    assert closed > 1e-3 and fb.amplitude == pytest.approx(closed, rel=1e-6)


def test_flat_mask_and_degenerate_inputs() -> None:
    refl = np.ones((20, 6))
    refl[10:, 3:] = 0.5
    ok = flat_target_mask(refl, half_lines=2, half_columns=1)
    assert not ok[8:12, 2:4].any() and ok[:8].all() and ok[12:, :2].all()
    assert math.isnan(flat_banding(refl, refl, 0.0).amplitude)  # nu = 0
    assert math.isnan(flat_banding(refl, refl, 0.01).amplitude)  # 20 lines < one period
