"""EMVA 1288 (Release 4) photon-transfer measurements: the temporal mean and variance of a
level, the dark noise in electrons, the saturation point, and the stack statistics of the spatial
non-uniformity. The ``K`` and responsivity fits are :func:`bench_sim.metrics.emva_fit.fit_camera`
(the one estimator).

The definitions and references are those of :mod:`bench_sim.metrics.emva1288` (which
re-exports everything here); this module holds the steps from measured images to fitted
quantities, that one the sensitivity, SNR and dynamic range built on them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from bench_sim.errors import BenchSimError

__all__ = [
    "SaturationMethod",
    "SaturationPoint",
    "LINEAR_FIT_FRACTION",
    "as_1d",
    "mean_var_from_pair",
    "series_from_pairs",
    "dark_temporal_noise_e",
    "saturation_point",
    "stack_mean_var",
    "spatial_nonuniformity",
]

SaturationMethod = Literal["max_variance", "interpolated", "extrapolated"]

#: Upper end of the linear range used for the K and responsivity fits, as a fraction of the
#: saturation signal (EMVA 1288 R4: 0 .. 70 %).
LINEAR_FIT_FRACTION = 0.7


def as_1d(name: str, a: np.ndarray | list[float], n: int | None = None) -> np.ndarray:
    """``a`` as a 1-D float64 array of ``n`` values (if given); :class:`BenchSimError` names it otherwise."""
    arr = np.asarray(a, dtype=np.float64).ravel()
    if n is not None and arr.size != n:
        raise BenchSimError(f"{name}: expected {n} values, got {arr.size}")
    if not np.all(np.isfinite(arr)):
        raise BenchSimError(f"{name}: values must be finite")
    return arr


def mean_var_from_pair(image_a: np.ndarray, image_b: np.ndarray) -> tuple[float, float]:
    """Temporal mean and variance of one level from two images (EMVA 1288 R4).

    Parameters
    ----------
    image_a, image_b
        Two images of the same level, same shape [DN].

    Returns
    -------
    (mu_y, sigma_y2)
        ``mu_y = (<A> + <B>) / 2`` [DN] and
        ``sigma_y**2 = <((A - <A>) - (B - <B>))**2> / 2`` [DN^2].
    """
    a = np.asarray(image_a, dtype=np.float64)
    b = np.asarray(image_b, dtype=np.float64)
    if a.shape != b.shape or a.size < 2:
        raise BenchSimError(f"image pair shapes {a.shape} and {b.shape}: must be equal, >= 2 pixels")
    ma, mb = float(a.mean()), float(b.mean())
    diff = (a - ma) - (b - mb)
    return 0.5 * (ma + mb), 0.5 * float(np.mean(diff * diff))


def series_from_pairs(pairs: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """Mean [DN] and temporal variance [DN^2] of each level of a series of image pairs."""
    mv = np.array([mean_var_from_pair(a, b) for a, b in pairs], dtype=np.float64).reshape(-1, 2)
    return mv[:, 0], mv[:, 1]


def _fit_through_origin(x: np.ndarray, y: np.ndarray) -> float:
    den = float(np.sum(x * x))
    if den <= 0:
        raise BenchSimError("linear fit: no points with signal in the linear range")
    return float(np.sum(x * y) / den)


def _linear_mask(signal: np.ndarray, saturation_signal: float, fraction: float) -> np.ndarray:
    mask = (signal > 0) & (signal <= fraction * saturation_signal)
    if int(mask.sum()) < 2:
        raise BenchSimError(
            f"linear fit: fewer than 2 levels between 0 and {fraction:.0%} of the saturation "
            f"signal {saturation_signal:.6g} (add light levels)"
        )
    return mask


def dark_temporal_noise_e(dark_var_dn: float, k_dn_per_e: float, quantization_var_dn2: float) -> float:
    """Dark temporal noise in electrons: ``sigma_d = sqrt(sigma_y.dark**2 - sigma_q**2) / K``.

    ``quantization_var_dn2`` is ``1/12`` for one quantised value, ``m/12`` for a DTDI stage that
    sums ``m`` independently quantised rows. Clamped at 0.
    """
    if k_dn_per_e <= 0:
        raise BenchSimError(f"K = {k_dn_per_e!r}: must be > 0")
    return math.sqrt(max(float(dark_var_dn) - float(quantization_var_dn2), 0.0)) / float(k_dn_per_e)


@dataclass(frozen=True)
class SaturationPoint:
    """Where a series saturates.

    Attributes
    ----------
    photons
        Irradiation at saturation ``mu_p.sat`` (the series' photon unit).
    signal
        Dark-subtracted mean signal there ``mu_y.sat``.
    index
        Level (grid index) with the largest temporal variance.
    method
        ``max_variance``, ``interpolated`` or ``extrapolated``.
    """

    photons: float
    signal: float
    index: int
    method: str


def _parabola_vertex(x: np.ndarray, y: np.ndarray) -> float:
    """x of the vertex of the parabola through three points (unevenly spaced allowed)."""
    x0, x1, x2 = (float(v) for v in x)
    y0, y1, y2 = (float(v) for v in y)
    den = (x0 - x1) * (x0 - x2) * (x1 - x2)
    a = (x2 * (y1 - y0) + x1 * (y0 - y2) + x0 * (y2 - y1)) / den
    b = (x2 * x2 * (y0 - y1) + x1 * x1 * (y2 - y0) + x0 * x0 * (y1 - y2)) / den
    if a >= 0:  # not a maximum: keep the grid point
        return x1
    return -b / (2 * a)


def saturation_point(
    photons: np.ndarray,
    signal: np.ndarray,
    temporal_var: np.ndarray,
    method: SaturationMethod = "interpolated",
    *,
    responsivity: float | None = None,
) -> SaturationPoint:
    """Saturation point of a series (EMVA 1288 R4: the maximum of the temporal variance).

    Parameters
    ----------
    photons
        Irradiation of each level (e.g. mean photons per pixel), increasing.
    signal
        Dark-subtracted mean signal of each level.
    temporal_var
        Temporal variance of each level.
    method
        ``"max_variance"``: the level with the largest variance (EMVA's definition, quantised to
        the level grid). ``"interpolated"``: the vertex of the parabola through that level and
        its two neighbours (clamped to the neighbours); the signal there is interpolated
        linearly. Its accuracy is a fraction of the level spacing where the peak is resolved;
        a hard clip collapses the variance within a few per cent of irradiation, so sample
        the levels at about 1 % spacing near saturation for 0.1 dB. ``"extrapolated"``: the
        irradiation at which the linear response reaches the clipped plateau,
        ``mu_p.sat = max(mu_y) / R`` with ``max(mu_y)`` the largest (dark-subtracted) mean
        signal of the series at or beyond the variance maximum and ``R`` the responsivity
        (``responsivity``, or a fit over 0..70 % of the saturation signal). It does not depend
        on the level grid (only on the fit and the plateau) but lies a few per cent above the
        variance maximum, where noise and fixed-pattern spread start to clip.
    responsivity
        Slope of signal versus photons for ``"extrapolated"`` (fitted when None).

    Raises
    ------
    BenchSimError
        Fewer than 3 levels, or the variance peaks at the last level (series not saturated).
    """
    p = as_1d("photons", photons)
    s = as_1d("signal", signal, p.size)
    v = as_1d("temporal_var", temporal_var, p.size)
    if p.size < 3:
        raise BenchSimError(f"saturation: need at least 3 levels, got {p.size}")
    if np.any(np.diff(p) <= 0):
        raise BenchSimError("saturation: photons must increase strictly from level to level")
    i = int(np.argmax(v))
    if i == p.size - 1:
        raise BenchSimError(
            f"saturation: the variance peaks at the brightest level (photons {p[-1]:.6g}); the "
            "series does not reach saturation (add brighter levels)"
        )
    if method == "max_variance":
        return SaturationPoint(float(p[i]), float(s[i]), i, method)
    if method not in ("interpolated", "extrapolated"):
        raise BenchSimError(
            f"saturation method = {method!r}: allowed 'max_variance', 'interpolated', 'extrapolated'"
        )
    if i == 0:
        p_sat, s_sat = float(p[0]), float(s[0])
    else:
        sl = slice(i - 1, i + 2)
        p_sat = min(max(_parabola_vertex(p[sl], v[sl]), float(p[i - 1])), float(p[i + 1]))
        s_sat = float(np.interp(p_sat, p[sl], s[sl]))
    if method == "interpolated":
        return SaturationPoint(p_sat, s_sat, i, method)
    r = responsivity
    if r is None:
        mask = _linear_mask(s, s_sat, LINEAR_FIT_FRACTION)
        r = _fit_through_origin(p[mask], s[mask])
    if r <= 0:
        raise BenchSimError(f"saturation: responsivity {r!r} must be > 0")
    plateau = float(np.max(s[i:]))
    return SaturationPoint(plateau / r, plateau, i, method)


def stack_mean_var(stack: np.ndarray) -> tuple[float, float, float]:
    """Mean, spatial variance and temporal variance of a stack of ``L`` images (EMVA 1288 R4).

    The spatial variance is that of the average image ``<y> = (1/L) sum_l y_l`` over the pixels,
    less the residual temporal variance ``sigma_y**2 / L`` it still holds; ``sigma_y**2`` is the
    pixel-wise variance over the stack, averaged over the pixels.

    Parameters
    ----------
    stack
        (L, H, W) images of one level, ``L >= 2`` [DN].

    Returns
    -------
    (mu_y, s_y2, sigma_y2)
        Mean [DN], spatial variance [DN^2] (clamped at 0), temporal variance [DN^2].
    """
    y = np.asarray(stack, dtype=np.float64)
    if y.ndim != 3 or y.shape[0] < 2:
        raise BenchSimError(f"image stack shape {y.shape}: expected (L >= 2, height, width)")
    n_img = y.shape[0]
    avg = y.mean(axis=0)
    temporal = float(np.mean(y.var(axis=0, ddof=1)))
    spatial = float(avg.var()) - temporal / n_img
    return float(avg.mean()), max(spatial, 0.0), temporal


def spatial_nonuniformity(
    bright_stack: np.ndarray, dark_stack: np.ndarray, k_dn_per_e: float
) -> dict[str, float]:
    """DSNU and PRNU (EMVA 1288 R4 definitions) from a bright and a dark stack.

    ``DSNU = s_y.dark / K`` [e-] and ``PRNU = sqrt(s_y**2 - s_y.dark**2) / (mu_y - mu_y.dark)``
    (a fraction), with ``s`` the spatial standard deviations of :func:`stack_mean_var`; the
    bright stack is taken at about 50 % of saturation.
    """
    mu_b, s2_b, _ = stack_mean_var(bright_stack)
    mu_d, s2_d, _ = stack_mean_var(dark_stack)
    if k_dn_per_e <= 0 or mu_b <= mu_d:
        raise BenchSimError("spatial nonuniformity: need K > 0 and a bright mean above the dark mean")
    return {
        "dark_spatial_std_dn": math.sqrt(s2_d),
        "bright_spatial_std_dn": math.sqrt(s2_b),
        "dsnu_e": math.sqrt(s2_d) / k_dn_per_e,
        "prnu": math.sqrt(max(s2_b - s2_d, 0.0)) / (mu_b - mu_d),
        "bright_signal_dn": mu_b - mu_d,
    }
