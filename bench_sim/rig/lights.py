"""Time behaviour of the bench's lights: the relative intensity each light has in each frame.

The scene is linear in each light (:func:`bench_sim.rig.scene.light_names`): a frame's radiance
is the sum over the lights of the radiance under that light alone times the light's mean
relative intensity over the frame's integration window ``[k T, k T + t_int]`` (``T`` the line
period, ``t_int`` the integration time). Steady lights have weight 1 in every frame.

A flickering light (``flicker_hz = f > 0``, ``flicker_depth = d``, ``flicker_phase_rad = phi``)
has the relative intensity ``w(t)`` of mean 1 (:data:`bench_sim.config.FLICKER_WAVEFORMS`)::

    sine            w(t) = 1 + d sin(2 pi f t + phi)
    rectified_sine  w(t) = 1 - d + d (pi / 2) |sin(pi f t + phi / 2)|

(the second is a lamp on mains of frequency ``f / 2``: its light follows the rectified mains
waveform, at twice the mains frequency). A frame's weight is the exact mean of ``w`` over its
window, in closed form (:func:`window_mean`)::

    sine:  1 + d sinc(pi f t_int) sin(2 pi f (t0 + t_int / 2) + phi)
    rectified_sine:  1 - d + d (pi / 2) (A(theta1) - A(theta0)) / (theta1 - theta0),
                     theta = pi f t + phi / 2,  A(theta) = 2 floor(theta / pi) + 1 - cos(theta mod pi)

with ``A`` an antiderivative of ``|sin|``. Nothing else is imposed: the banding of a stage image
along the track, and its decrease with the stage ``m``, come out of the DTDI sum of these frames.

Within a frame the weight multiplies the light's motion-smeared radiance; the covariance of the
flicker and the motion inside one line period (second order in both) is neglected.
"""

from __future__ import annotations

import math

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.rig.scene import light_names

__all__ = ["frame_weights", "window_mean", "flicker_fundamental"]


def _abs_sin_integral(theta: np.ndarray) -> np.ndarray:
    """``A(theta) = integral_0^theta |sin u| du`` (exact, any ``theta >= 0`` or < 0)."""
    n = np.floor(theta / math.pi)
    return 2.0 * n + 1.0 - np.cos(theta - n * math.pi)


def window_mean(
    waveform: str,
    depth: float,
    frequency_hz: float,
    phase_rad: float,
    t0_s: np.ndarray | float,
    t_int_s: float,
) -> np.ndarray:
    """Exact mean of the relative intensity ``w(t)`` over ``[t0, t0 + t_int]`` (dimensionless).

    Parameters
    ----------
    waveform
        ``"sine"`` or ``"rectified_sine"`` (module docstring).
    depth
        Modulation depth ``d`` in ``0 .. 1``.
    frequency_hz
        Modulation frequency ``f`` [Hz] (``0``: steady, mean 1).
    phase_rad
        Phase ``phi`` at ``t = 0`` [rad].
    t0_s
        Window starts [s] (array or scalar).
    t_int_s
        Window length [s], ``> 0``.
    """
    t0 = np.asarray(t0_s, dtype=np.float64)
    if frequency_hz <= 0 or depth <= 0:
        return np.ones_like(t0)
    if t_int_s <= 0:
        raise ValueError(f"t_int_s = {t_int_s}: must be > 0")
    f, d = float(frequency_hz), float(depth)
    if waveform == "sine":
        x = math.pi * f * t_int_s
        return 1.0 + d * (math.sin(x) / x) * np.sin(2 * math.pi * f * (t0 + 0.5 * t_int_s) + phase_rad)
    if waveform == "rectified_sine":
        th0 = math.pi * f * t0 + 0.5 * phase_rad
        th1 = th0 + math.pi * f * t_int_s
        mean_abs_sin = (_abs_sin_integral(th1) - _abs_sin_integral(th0)) / (th1 - th0)
        return 1.0 - d + d * (0.5 * math.pi) * mean_abs_sin
    raise ValueError(f"flicker_waveform = {waveform!r}: allowed 'sine', 'rectified_sine'")


def flicker_fundamental(waveform: str, depth: float) -> float:
    """Amplitude of the component of ``w(t)`` at the flicker frequency ``f``, relative to the
    mean (dimensionless): ``d`` for ``sine``; ``2 d / 3`` for ``rectified_sine``
    (``|sin u| = 2/pi - (4/pi) sum_k cos(2 k u) / (4 k^2 - 1)``, times ``pi / 2``)."""
    if waveform == "sine":
        return float(depth)
    if waveform == "rectified_sine":
        return 2.0 * float(depth) / 3.0
    raise ValueError(f"flicker_waveform = {waveform!r}: allowed 'sine', 'rectified_sine'")


def frame_weights(cfg: BenchConfig, name: str, k0: int, k1: int) -> np.ndarray:
    """Mean relative intensity of light ``name`` over the integration window
    ``[k T, k T + t_int]`` of frames ``k = k0 .. k1 - 1`` (dimensionless, float64, shape
    ``(k1 - k0,)``; 1 for a steady light), by :func:`window_mean`."""
    if name not in light_names(cfg):
        raise ValueError(f"light {name!r}: not among this bench's emitting lights {list(light_names(cfg))}")
    if k1 < k0:
        raise ValueError(f"frames {k0}..{k1}: k1 must not be below k0")
    light = cfg.lights.get(name)
    k = np.arange(int(k0), int(k1), dtype=np.float64)
    if not light.flickers:
        return np.ones_like(k)
    return window_mean(
        light.flicker_waveform,
        light.flicker_depth,
        light.flicker_hz,
        light.flicker_phase_rad,
        k * cfg.timing.line_period_s,
        cfg.timing.t_int_s,
    )
