"""The closed-form banding of a DTDI stage against the frames' exact weights summed as DTDI sums
them (bench_sim.rig.lights.window_mean), for both waveforms, amplitude and phase."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench_sim.metrics.flicker_theory import banding_phasor, dirichlet, fold_phase, predicted_banding
from bench_sim.rig.lights import flicker_fundamental, window_mean

pytestmark = pytest.mark.physics

#: waveform -> (phase offset of its fundamental, tolerance: the rectified sine's harmonics leak a little)
WAVEFORMS = {"sine": (0.0, 1e-9), "rectified_sine": (-0.5 * math.pi, 2e-3)}


@pytest.mark.parametrize("waveform", WAVEFORMS)
@pytest.mark.parametrize("f_hz, period_s", [(120.0, 1e-3), (100.0, 1e-3), (50.0, 1.7e-3), (100.0, 8.3e-3)])
def test_prediction_matches_summed_frames(waveform, f_hz, period_s):
    offset, tol = WAVEFORMS[waveform]
    if waveform == "rectified_sine":  # harmonics k f folding onto the same nu add up to 2 d / (4 k^2 - 1)
        x = f_hz * period_s
        tol += sum(2 * 0.8 / (4 * k * k - 1) for k in range(2, 400)
                   if min(abs((k * x - x) % 1.0), abs((k * x + x) % 1.0), 1 - (k * x - x) % 1.0,
                          1 - (k * x + x) % 1.0) < 1e-9)
    t_int, phi, depth, n = 0.6 * period_s, 0.7, 0.8, 600
    fund = flicker_fundamental(waveform, depth)
    for m in (1, 3, 7, 25, 33):
        k = np.arange(n + m)
        w = window_mean(waveform, depth, f_hz, phi, k * period_s, t_int)
        lines = np.convolve(w, np.ones(m), mode="valid")[:n]  # line j sums frames j .. j + m - 1
        nu, amp_pred, phase_pred = predicted_banding(fund, f_hz, phi + offset, period_s, t_int, m)
        if nu * n < 2:
            continue
        amp, phase = banding_phasor(lines, nu)
        assert amp == pytest.approx(amp_pred, abs=tol), (m, amp, amp_pred)
        if amp_pred > 0.05:
            assert abs(math.remainder(phase - phase_pred, 2 * math.pi)) < 20 * tol + 1e-6, (m, phase)


def test_dirichlet_nulls_and_folding():
    assert dirichlet(25, 0.12) == pytest.approx(0.0, abs=1e-12)
    assert dirichlet(10, 0.1) == pytest.approx(0.0, abs=1e-12)
    assert dirichlet(1, 0.37) == 1.0 and dirichlet(4, 1.0) == -1.0  # sum of cos(pi k): sign of m - 1
    # a sinusoid of 0.7 cycles per sample is one of 0.3 with the mirrored phase
    j = np.arange(50)
    nu, phase = fold_phase(0.4, 0.7)
    folded = np.sin(2 * np.pi * nu * j + phase)
    np.testing.assert_allclose(np.sin(2 * np.pi * 0.7 * j + 0.4), folded, atol=1e-9)
