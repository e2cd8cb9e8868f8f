"""Flicker banding: the periodic modulation a flickering light leaves along the track.

A stage image's line ``j`` is made in the line periods ``j .. j + m - 1`` (DTDI), so a light
flickering at ``f`` modulates the lines at ``f T`` cycles per line (``T`` the line period),
folded into ``0 .. 0.5`` by the line sampling. The banding amplitude is the amplitude of that
component of a line profile relative to its mean, from a least-squares fit of
``a + b cos(2 pi nu j) + c sin(2 pi nu j)`` (exact for any number of periods, no leakage from
the mean): ``sqrt(b^2 + c^2) / a``.

Two estimators:

:func:`illumination_profile` + :func:`banding_amplitude`
    The mean over the columns of ``photons / reflectance`` per line, fitted. It has a floor on a
    patterned target: at the target's edges the image's footprint (the renderer's, optical blur)
    and the truth's ``reflectance`` differ, so ``photons / reflectance`` there follows the target,
    not the light, and the target's own spectrum at ``nu`` leaks in (0.25 % on the paper target
    with no flicker at all, at every stage).
:func:`flat_banding` (no floor)
    Only pixels whose target is flat over a window around them (reflectance constant within
    ``rel_tol`` over ``+-half_lines`` lines and ``+-half_columns`` columns) are used; there
    ``values / reflectance`` is the light alone, whatever the footprints. Each column is fitted on
    its own flat lines, ``q_n(j) = a_n + b_n cos(2 pi nu j) + c_n sin(2 pi nu j)`` (a column's
    light is fixed in the sensor's frame, so ``a_n`` absorbs the spot's shape), and the columns'
    phasors ``p_n = (c_n + i b_n) / a_n`` are averaged with fixed weights, each column's share of
    the line profile (its mean value): ``P = sum W_n p_n / sum W_n``. The banding is ``|P|``, its
    phase ``arg P`` (the convention of :func:`bench_sim.metrics.flicker_theory.banding_phasor`).
    Where every column is used, ``P`` is the banding of the image's line profile (the column sum)
    to first order in the amplitude; otherwise it is that of the columns used (``columns_used``).
    With no flicker, or at a null of the frames' sinc, it is 0 to rounding (~1e-9) on noise-free
    truth and within ``4 sd`` (``sd`` from the fits' residuals) on a noisy image. Pixels at a clip
    must be passed as NaN; where the clip follows the flicker's phase (the bright bands clip, the
    dark ones do not) leaving them out biases the fit, so measure on the truth where there is one.

References
----------
Least-squares fit of a sinusoid of known frequency to unevenly sampled data and the covariance of
its coefficients: N. R. Lomb, "Least-squares frequency analysis of unequally spaced data",
Astrophys. Space Sci. 39 (1976) 447-462; the standard error ``sigma^2 (B^T B)^-1`` of linear
least squares.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

__all__ = [
    "folded_cycles_per_line",
    "banding_amplitude",
    "illumination_profile",
    "FlatBanding",
    "flat_target_mask",
    "flat_banding",
]


def folded_cycles_per_line(frequency_hz: float, line_period_s: float) -> float:
    """The flicker's frequency along the track [cycles per line], folded into ``0 .. 0.5``
    (``f T`` aliased by the one-line sampling); 0 when ``f`` is a multiple of the line rate."""
    nu = (float(frequency_hz) * float(line_period_s)) % 1.0
    return float(min(nu, 1.0 - nu))


def _harmonic_basis(lines: int, nu: float) -> np.ndarray:
    """``(lines, 3)`` columns ``1, cos(2 pi nu j), sin(2 pi nu j)`` of the fits, ``j`` the line."""
    j = np.arange(lines)
    return np.stack([np.ones(lines), np.cos(2 * np.pi * nu * j), np.sin(2 * np.pi * nu * j)], axis=1)


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
    (a, b, c), *_ = np.linalg.lstsq(_harmonic_basis(p.size, nu), p, rcond=None)
    return float(np.hypot(b, c) / a) if a > 0 else float("nan")


def illumination_profile(photons: np.ndarray, reflectance: np.ndarray) -> np.ndarray:
    """Mean over the columns of ``photons / reflectance`` per line: the light a stage's lines
    received, with the target's pattern divided out (shape ``(lines,)``; both inputs
    ``(lines, columns)``, e.g. ``simulate``'s truth of one stage)."""
    ph = np.asarray(photons, dtype=np.float64)
    refl = np.asarray(reflectance, dtype=np.float64)
    ratio = np.divide(ph, refl, out=np.full(ph.shape, np.nan), where=refl > 0)
    return np.nanmean(ratio, axis=1)


@dataclass(frozen=True)
class FlatBanding:
    """The banding of an image measured on its flat-target pixels (:func:`flat_banding`).

    Attributes
    ----------
    amplitude
        ``|P|``, relative to the mean (dimensionless); NaN when no column could be fitted.
    phase_rad
        ``arg P`` [rad]: the profile goes as ``1 + amplitude sin(2 pi nu j + phase_rad)``.
    sd
        Standard error of each component of ``P`` (dimensionless), from the fits' residuals,
        columns taken as independent. On a noisy image a true null reads ``|P| < 4 sd`` but for
        a chance of ``exp(-8) = 3e-4`` (Rayleigh distribution). On noise-free truth the residuals
        are float rounding (not independent; a null reads ~1e-9) and whatever of the light is not
        the fitted sinusoid (a rectified sine's harmonics), so ``sd`` is no bound there.
    columns_used
        Fraction of the columns fitted (those with flat lines spanning at least one period).
    """

    amplitude: float
    phase_rad: float
    sd: float
    columns_used: float


def _window_range(refl: np.ndarray, half_lines: int, half_columns: int) -> tuple[np.ndarray, np.ndarray]:
    """Max and min of ``refl`` over the ``(2 half_lines + 1) x (2 half_columns + 1)`` window
    around each pixel (edges padded with the nearest value)."""
    pad = np.pad(refl, ((half_lines, half_lines), (half_columns, half_columns)), mode="edge")
    win = sliding_window_view(pad, (2 * half_lines + 1, 2 * half_columns + 1))
    return win.max(axis=(2, 3)), win.min(axis=(2, 3))


def flat_target_mask(
    reflectance: np.ndarray, half_lines: int = 1, half_columns: int = 1, rel_tol: float = 1e-3
) -> np.ndarray:
    """True where the target is flat around a pixel: positive reflectance, constant within
    ``rel_tol`` (relative to the window's maximum) over ``+-half_lines`` lines and
    ``+-half_columns`` columns. Shape and input ``(lines, columns)``.

    ``half_lines`` must cover how far the image's footprint reaches beyond the truth's along the
    track: the pixel and its smear (1), plus the walk of a stage's ``m`` row footprints under a
    sync error ``e`` (``|e| (m - 1)`` object pixels).
    """
    refl = np.asarray(reflectance, dtype=np.float64)
    hi, lo = _window_range(refl, int(half_lines), int(half_columns))
    return (refl > 0) & (hi - lo <= float(rel_tol) * np.maximum(hi, np.finfo(np.float64).tiny))


def _column_fits(
    q: np.ndarray, ok: np.ndarray, nu: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per column, least squares of ``a + b cos + c sin`` on its ``ok`` lines: coefficients
    ``(N, 3)`` (NaN where not fitted), their unscaled covariance ``(N, 3, 3)`` and the residual
    variance ``(N,)``."""
    lines, cols = q.shape
    basis = _harmonic_basis(lines, nu)
    w = ok.astype(np.float64)
    gram = np.einsum("jn,ja,jb->nab", w, basis, basis)
    rhs = np.einsum("jn,ja->na", np.where(ok, q, 0.0), basis)
    count = w.sum(axis=0)
    first = np.where(ok.any(axis=0), np.argmax(ok, axis=0), 0)
    last = lines - 1 - np.argmax(ok[::-1], axis=0)
    fit = (count > 3) & ((last - first) * nu >= 1.0)  # flat lines over at least one period
    coef = np.full((cols, 3), np.nan)
    cov = np.full((cols, 3, 3), np.nan)
    idx = np.flatnonzero(fit)
    if idx.size:
        inv = np.linalg.inv(gram[idx])
        coef[idx] = np.einsum("nab,nb->na", inv, rhs[idx])
        cov[idx] = inv
    model = np.einsum("na,ja->jn", np.nan_to_num(coef), basis)
    rss = np.sum(np.where(ok, (q - model) ** 2, 0.0), axis=0)
    var = np.where(fit, rss / np.maximum(count - 3, 1), np.nan)
    return coef, cov, var


def flat_banding(
    values: np.ndarray,
    reflectance: np.ndarray,
    cycles_per_line: float,
    *,
    half_lines: int = 1,
    half_columns: int = 1,
    rel_tol: float = 1e-3,
) -> FlatBanding:
    """Banding at ``cycles_per_line`` of an image, on its flat-target pixels (module docstring).

    Parameters
    ----------
    values
        ``(lines, columns)`` image proportional to the light times the reflectance, offsets
        removed: a stage's truth ``photons``, or a (noisy) image in DN less its dark offset.
    reflectance
        ``(lines, columns)`` the truth's reflectance of the same stage (0..1).
    cycles_per_line
        The flicker's frequency along the track, in ``(0, 0.5]`` (:func:`folded_cycles_per_line`).
    half_lines, half_columns, rel_tol
        The flatness window and tolerance (:func:`flat_target_mask`).

    Returns
    -------
    FlatBanding
        Amplitude (relative), phase [rad], its standard error and the fraction of columns used;
        amplitude NaN when ``nu`` is 0 or no column has flat lines over one period.
    """
    v = np.asarray(values, dtype=np.float64)
    refl = np.asarray(reflectance, dtype=np.float64)
    nu = float(cycles_per_line)
    nan = FlatBanding(float("nan"), float("nan"), float("nan"), 0.0)
    if nu <= 0 or v.ndim != 2 or v.shape != refl.shape:
        return nan
    ok = flat_target_mask(refl, half_lines, half_columns, rel_tol) & np.isfinite(v)
    q = np.divide(v, refl, out=np.zeros(v.shape), where=ok)
    coef, cov, var = _column_fits(q, ok, nu)
    a = coef[:, 0]
    used = np.isfinite(a) & (a > 0)
    finite = np.isfinite(v)
    col_mean = np.where(finite, v, 0.0).sum(axis=0) / np.maximum(finite.sum(axis=0), 1)
    weight = np.where(used & (col_mean > 0), col_mean, 0.0)  # the column's share of the profile
    total = weight.sum()
    if not total > 0:
        return nan
    share = weight / total
    a_safe = np.where(used, a, 1.0)
    phasor = np.where(used, (coef[:, 2] + 1j * coef[:, 1]) / a_safe, 0.0)
    big = complex(np.sum(share * phasor))
    # component variances: var(c)/a^2 and var(b)/a^2 per column, independent columns
    var_re = np.sum(np.where(used, share**2 * var * cov[:, 2, 2] / a_safe**2, 0.0))
    var_im = np.sum(np.where(used, share**2 * var * cov[:, 1, 1] / a_safe**2, 0.0))
    return FlatBanding(
        amplitude=float(abs(big)),
        phase_rad=float(np.angle(big)),
        sd=float(np.sqrt(max(var_re, var_im))),
        columns_used=float(np.count_nonzero(weight) / v.shape[1]),
    )
