"""Flicker banding: the periodic modulation a flickering light leaves along the track.

A stage image's line ``j`` is made in the line periods ``j .. j + m - 1`` (DTDI), so a light
flickering at ``f`` modulates the lines at ``f T`` cycles per line (``T`` the line period),
folded into ``0 .. 0.5`` by the line sampling. The banding amplitude is the amplitude of that
component of a line profile relative to its mean, from a least-squares fit of
``a + b cos(2 pi nu j) + c sin(2 pi nu j)`` (exact for any number of periods, no leakage from
the mean): ``sqrt(b^2 + c^2) / a``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["folded_cycles_per_line", "banding_amplitude", "illumination_profile"]


def folded_cycles_per_line(frequency_hz: float, line_period_s: float) -> float:
    """The flicker's frequency along the track [cycles per line], folded into ``0 .. 0.5``
    (``f T`` aliased by the one-line sampling); 0 when ``f`` is a multiple of the line rate."""
    nu = (float(frequency_hz) * float(line_period_s)) % 1.0
    return float(min(nu, 1.0 - nu))


def banding_amplitude(profile: np.ndarray, cycles_per_line: float) -> float:
    """Amplitude of the ``cycles_per_line`` component of a line profile, relative to its mean
    (dimensionless); NaN when the frequency is 0 (indistinguishable from the mean) or the
    profile is shorter than one period or has no positive mean.

    Parameters
    ----------
    profile
        One value per line (e.g. the mean over the columns of a stage image, offsets removed).
    cycles_per_line
        The modulation's frequency along the track, in ``(0, 0.5]``
        (:func:`folded_cycles_per_line`).
    """
    p = np.asarray(profile, dtype=np.float64)
    nu = float(cycles_per_line)
    if nu <= 0 or p.size * nu < 1 or p.size < 3:
        return float("nan")
    j = np.arange(p.size)
    basis = np.stack([np.ones(p.size), np.cos(2 * np.pi * nu * j), np.sin(2 * np.pi * nu * j)], axis=1)
    (a, b, c), *_ = np.linalg.lstsq(basis, p, rcond=None)
    return float(np.hypot(b, c) / a) if a > 0 else float("nan")


def illumination_profile(photons: np.ndarray, reflectance: np.ndarray) -> np.ndarray:
    """Mean over the columns of ``photons / reflectance`` per line: the light a stage's lines
    received, with the target's pattern divided out (shape ``(lines,)``; both inputs
    ``(lines, columns)``, e.g. ``simulate``'s truth of one stage)."""
    ph = np.asarray(photons, dtype=np.float64)
    refl = np.asarray(reflectance, dtype=np.float64)
    ratio = np.divide(ph, refl, out=np.full(ph.shape, np.nan), where=refl > 0)
    return np.nanmean(ratio, axis=1)
