"""Flicker banding of a DTDI stage in closed form, and its measurement with the phase.

A light of relative intensity ``w(t)`` whose component at the flicker frequency ``f`` is
``F sin(2 pi f t + phi + delta)`` (``F`` = :func:`bench_sim.rig.lights.flicker_fundamental`;
``delta = 0`` for ``sine``, ``-pi/2`` for ``rectified_sine``) gives frame ``k`` (window
``[k T, k T + t_int]``) the weight ``1 + F sinc(pi f t_int) sin(2 pi f (k T + t_int / 2) + phi +
delta)``. Line ``j`` of stage ``m`` sums the frames ``j .. j + m - 1``, so its illumination
relative to the mean is ``1 + A_m sin(2 pi f T j + psi_m)`` with

    A_m   = F |sinc(pi f t_int)| |D_m(f T)|,   D_m(x) = sin(pi m x) / (m sin(pi x))
    psi_m = pi f t_int + phi + delta + pi f T (m - 1)   (+ pi where sinc D_m < 0)

(``D_m`` the Dirichlet kernel of the DTDI sum: nulls where ``m f T`` is an integer and ``f T``
is not). Sampled once per line, ``f T`` folds into ``nu`` in ``0 .. 0.5``; folding from
``1 - nu`` mirrors the phase (``psi -> pi - psi``). The measurement
(:func:`banding_phasor`) fits ``a + b cos(2 pi nu j) + c sin(2 pi nu j)``, so amplitude
``sqrt(b^2 + c^2) / a`` and phase ``atan2(b, c)`` compare directly with ``A_m`` and ``psi_m``.
The prediction is the fundamental's: a ``rectified_sine``'s harmonic ``k f`` (relative amplitude
``2 d / (4 k^2 - 1)``) that folds onto the same ``nu`` (``k f T = +-f T`` mod 1) adds to the
measurement (e.g. the 9th and 11th at ``f T = 0.1``: 0.5 % of ``d``).

References
----------
The DTDI stage sum (paper eq. 1-2) of frames integrated over ``t_int``; the Dirichlet kernel is
the discrete-time sinc of a moving sum of ``m`` samples (Oppenheim & Schafer, Discrete-Time
Signal Processing, 3rd ed., 2010, sec. 2.9).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["dirichlet", "predicted_banding", "banding_phasor", "fold_phase"]


def dirichlet(m: int, x: float) -> float:
    """``D_m(x) = sin(pi m x) / (m sin(pi x))`` (1 where ``x`` is an integer): the relative
    response of a sum of ``m`` consecutive samples to a sinusoid of ``x`` cycles per sample."""
    s = math.sin(math.pi * x)
    if abs(s) < 1e-12:
        return 1.0 if int(round(x)) * (m - 1) % 2 == 0 else -1.0
    return math.sin(math.pi * m * x) / (m * s)


def fold_phase(phase_rad: float, cycles_per_sample: float) -> tuple[float, float]:
    """``(nu, phase)`` of a sinusoid of ``cycles_per_sample`` sampled once per sample: ``nu`` in
    ``0 .. 0.5`` and the phase it shows at ``nu`` (wrapped to ``(-pi, pi]``)."""
    x = cycles_per_sample % 1.0
    phase = phase_rad if x <= 0.5 else math.pi - phase_rad
    nu = min(x, 1.0 - x)
    return nu, float(math.atan2(math.sin(phase), math.cos(phase)))


def predicted_banding(
    fundamental: float, frequency_hz: float, phase_rad: float, line_period_s: float, t_int_s: float,
    stage: int,
) -> tuple[float, float, float]:
    """Closed-form banding of stage ``m`` lit by one flickering light alone (module docstring).

    Parameters
    ----------
    fundamental
        ``F``, the relative amplitude of the light's component at ``f``.
    frequency_hz
        ``f`` [Hz].
    phase_rad
        ``phi + delta`` [rad]: the light's phase plus its waveform's offset of the fundamental.
    line_period_s, t_int_s
        ``T`` and ``t_int`` [s].
    stage
        ``m``.

    Returns
    -------
    (nu, amplitude, phase)
        Folded cycles per line, ``A_m`` (relative to the mean) and ``psi_m`` at ``nu`` [rad].
    """
    x = float(frequency_hz) * float(line_period_s)
    arg = math.pi * float(frequency_hz) * float(t_int_s)
    sinc = math.sin(arg) / arg if arg else 1.0
    gain = sinc * dirichlet(int(stage), x)
    psi = arg + float(phase_rad) + math.pi * x * (int(stage) - 1) + (math.pi if gain < 0 else 0.0)
    nu, phase = fold_phase(psi, x)
    return nu, abs(float(fundamental) * gain), phase


def banding_phasor(profile: np.ndarray, cycles_per_line: float) -> tuple[float, float]:
    """Amplitude (relative to the mean) and phase [rad] of the ``cycles_per_line`` component of
    a line profile: least squares of ``a + b cos(2 pi nu j) + c sin(2 pi nu j)``, amplitude
    ``sqrt(b^2 + c^2) / a``, phase ``atan2(b, c)`` (``A sin(2 pi nu j + psi)``). ``(nan, nan)``
    when ``nu`` is 0, the profile is shorter than one period or its mean is not positive.
    """
    p = np.asarray(profile, dtype=np.float64)
    nu = float(cycles_per_line)
    keep = np.isfinite(p)
    if nu <= 0 or keep.sum() * nu < 1 or keep.sum() < 3:
        return float("nan"), float("nan")
    j = np.arange(p.size)[keep]
    basis = np.stack([np.ones(j.size), np.cos(2 * np.pi * nu * j), np.sin(2 * np.pi * nu * j)], axis=1)
    (a, b, c), *_ = np.linalg.lstsq(basis, p[keep], rcond=None)
    if not a > 0:
        return float("nan"), float("nan")
    return float(np.hypot(b, c) / a), float(math.atan2(b, c))
