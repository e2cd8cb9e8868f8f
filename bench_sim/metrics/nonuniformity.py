"""Spatial non-uniformity of image stacks (EMVA 1288 R4): the spatial variance split into its
column, row and pixel parts, the dark signal split into the offset pattern at 0 s and the dark
current's non-uniformity (dark images at several exposure times), and the temporal row noise.

Spatial components (:func:`spatial_components`)
-----------------------------------------------
An average map ``Y`` (M x N; defect pixels NaN) holds the fixed pattern plus a residual temporal
noise of known variance ``v`` per pixel (``sigma_y^2 / L`` for the mean of ``L`` images). With
its column means ``c``, row means ``r`` and the residual ``e = Y - c - r + mean``:

* pixel part: ``s_pix^2 = sum e^2 / ((M - 1)(N - 1)) - v`` (a white pattern's share of ``e``);
* column part: ``s_col^2 = var(c) - (s_pix^2 + v) / M``; row part likewise with ``N``;
* total: the map's variance less the noise, ``var(Y) - v - v_row`` (the pattern's own spatial
  variance over its pixels, what EMVA 1288's DSNU and PRNU are).

A temporal noise common to a row (row noise, variance ``v_row`` in the map) is in the row means
whole and taken off the row part; it shifts every column mean alike (not in their spread) and is
not in the pixel part.

Each has the standard error of the physical sensor's own value (its drawn pattern is what it is;
the error is what the residual noise ``v`` of each mean makes of it): a variance ``s^2`` from
``dof`` values of noise variance ``v`` has ``se^2 = (2 v^2 + 4 s^2 v) / dof`` (for the column and
row parts ``v`` is the variance of a column's or a row's mean about its pattern: the noise and
the pixel pattern's share); an rms ``s`` has ``se(s^2) / (2 s)``.

Dark signal split (:func:`dark_series_maps`)
--------------------------------------------
Per pixel, the least-squares line of its mean dark value against the exposure time over the
exposures where it is below the clip: the intercept map (the offset pattern at 0 s, DSNU0) and
the slope map (the dark current [DN/s], its non-uniformity). The estimation noise of an
intercept (slope) is ``sum_j c_j^2 sigma_j^2 / L_j`` with ``c_j`` the line's coefficients and
``sigma_j^2`` the mean temporal variance at exposure ``j``; it is the ``v`` of the maps'
spatial components.

Row noise (:func:`row_noise_variance`)
--------------------------------------
In each dark stack, the temporal variance of a row's mean over the frames is
``sigma_row^2 + sigma_pix^2 / N`` and a pixel's own temporal variance ``sigma_pix^2 +
sigma_row^2``; so ``sigma_row^2 = (V_row - V_pix / N) / (1 - 1 / N)``, pooled over the stacks
by their degrees of freedom ``M (L - 1)``.

References
----------
EMVA Standard 1288, Release 4.0 Linear (2021), section 8 (spatial variances, column, row and
pixel components; DSNU's dependence on the exposure time).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from bench_sim.errors import BenchSimError

__all__ = [
    "SpatialComponents",
    "spatial_components",
    "DarkSeriesMaps",
    "dark_series_maps",
    "RowNoise",
    "row_noise_variance",
    "temporal_mean_var",
    "own_temporal_var",
]


def temporal_mean_var(stack: np.ndarray, mask: np.ndarray | None = None) -> tuple[float, float, np.ndarray]:
    """Mean [DN] and temporal variance [DN^2] of ``L >= 2`` images of a level (EMVA 1288 R4),
    over the pixels of ``mask``: each image less its own mean, the variance over the images
    (``ddof = 1``) averaged over the pixels (for two images: the pair formula
    ``<((A - <A>) - (B - <B>))^2> / 2``). Returns the per-pixel variance map as well."""
    y = np.asarray(stack, dtype=np.float64)
    keep = np.ones(y.shape[1:], dtype=bool) if mask is None else mask
    sel = y[:, keep]
    centred = sel - sel.mean(axis=1, keepdims=True)
    var_map = np.full(y.shape[1:], np.nan)
    var_px = centred.var(axis=0, ddof=1)
    var_map[keep] = var_px
    return float(sel.mean()), float(var_px.mean()), var_map


def own_temporal_var(stack: np.ndarray, mask: np.ndarray | None = None) -> float:
    """The pixels' own temporal variance [DN^2] of ``L >= 2`` images, without what a row shares
    (row noise): each image less its rows' means, the variance over the images (``ddof = 1``)
    averaged over the pixels of ``mask``, times ``N / (N - 1)`` for the row mean taken off."""
    y = np.asarray(stack, dtype=np.float64)
    keep = np.ones(y.shape[1:], dtype=bool) if mask is None else mask
    yy = np.where(keep[None], y, np.nan)
    n = float(np.mean(keep.sum(axis=1)))
    resid = (yy - np.nanmean(yy, axis=2, keepdims=True))[:, keep]
    return float(np.mean(np.var(resid, axis=0, ddof=1))) * n / max(n - 1.0, 1.0)


@dataclass(frozen=True)
class SpatialComponents:
    """Spatial variances [unit^2] of a map (module docstring) and their standard errors."""

    total: float
    column: float
    row: float
    pixel: float
    total_se: float
    column_se: float
    row_se: float
    pixel_se: float
    noise: float

    @staticmethod
    def rms(var: float, se: float) -> tuple[float, float]:
        """An rms and its standard error from a variance (0 where it is not positive)."""
        if var <= 0:
            return 0.0, math.sqrt(max(se, 0.0))
        return math.sqrt(var), se / (2.0 * math.sqrt(var))

    def summary(self, scale: float = 1.0, unit: str = "", scale_rel_se: float = 0.0) -> dict[str, float]:
        """rms of each part and its error, times ``scale`` (e.g. ``1 / K``, whose relative error
        ``scale_rel_se`` joins each part's), keys suffixed ``unit``."""
        out = {}
        for part in ("total", "column", "row", "pixel"):
            s, se = self.rms(getattr(self, part), getattr(self, f"{part}_se"))
            out[f"{part}{unit}"] = s * scale
            out[f"{part}_se{unit}"] = math.hypot(se, s * scale_rel_se) * scale
        return out


def _sensor_se(var: float, noise: float, dof: float) -> float:
    """Standard error of a pattern's variance ``var`` from ``dof`` values of noise ``noise``."""
    return math.sqrt(max(2.0 * noise**2 + 4.0 * max(var, 0.0) * noise, 0.0) / max(dof, 1.0))


def spatial_components(image: np.ndarray, noise_var: float, row_noise_var: float = 0.0) -> SpatialComponents:
    """The column, row and pixel parts of a map's spatial variance (module docstring).

    Parameters
    ----------
    image
        (M, N) average map; NaN marks pixels left out (defects).
    noise_var
        Residual temporal variance of each value of the map, the pixel's own [unit^2].
    row_noise_var
        Residual temporal variance the values of a row share (row noise) [unit^2]: it is in the
        row means whole; a column mean holds the average of the rows' shares, the same for every
        column, so not in their spread.
    """
    y = np.asarray(image, dtype=np.float64)
    if y.ndim != 2 or min(y.shape) < 2:
        raise BenchSimError(f"spatial components: need an (M >= 2, N >= 2) map, got shape {y.shape}")
    good = np.isfinite(y)
    frac = float(good.mean())
    m, n = y.shape
    mean = float(np.nanmean(y))
    col, row = np.nanmean(y, axis=0), np.nanmean(y, axis=1)
    resid = y - col[None, :] - row[:, None] + mean
    dof_pix = max((m - 1) * (n - 1) * frac, 1.0)
    raw_pix = float(np.nansum(resid**2)) / dof_pix
    pixel = raw_pix - noise_var
    var_c, var_r = float(np.var(col, ddof=1)), float(np.var(row, ddof=1))
    column = var_c - raw_pix / (m * frac)
    row_v = var_r - raw_pix / (n * frac) - row_noise_var
    se_pix = _sensor_se(pixel, noise_var, dof_pix)
    se_col = _sensor_se(column, raw_pix / (m * frac), n - 1)
    se_row = _sensor_se(row_v, raw_pix / (n * frac) + row_noise_var, m - 1)
    n_px = float(good.sum())
    total = float(np.nanvar(y)) - (noise_var + row_noise_var) * (1.0 - 1.0 / n_px)
    return SpatialComponents(
        total=total,
        column=column,
        row=row_v,
        pixel=pixel,
        total_se=_sensor_se(total, noise_var + row_noise_var, n_px),
        column_se=se_col,
        row_se=se_row,
        pixel_se=se_pix,
        noise=noise_var,
    )


@dataclass(frozen=True)
class DarkSeriesMaps:
    """The per-pixel dark line (module docstring): ``offset_dn`` (M, N) intercept at 0 s [DN],
    ``slope_dn_s`` (M, N) [DN/s] (NaN where fewer than two exposures lie below the clip),
    the mean estimation-noise variances ``offset_noise_dn2`` [DN^2] and ``slope_noise_dn2_s2``
    [DN^2/s^2] of the pixels that use every exposure, and ``exposures_used`` (M, N)."""

    offset_dn: np.ndarray = field(repr=False)
    slope_dn_s: np.ndarray = field(repr=False)
    offset_noise_dn2: float
    slope_noise_dn2_s2: float
    exposures_used: np.ndarray = field(repr=False)


def dark_series_maps(
    exposure_s: np.ndarray | Sequence[float],
    mean_maps: np.ndarray,
    temporal_var_dn2: np.ndarray | Sequence[float],
    images: np.ndarray | Sequence[int],
    clip_dn: float | np.ndarray,
) -> DarkSeriesMaps:
    """The per-pixel dark lines of a dark series (module docstring).

    Parameters
    ----------
    exposure_s
        (J,) distinct exposure times [s], J >= 2.
    mean_maps
        (J, M, N) mean dark image at each exposure [DN].
    temporal_var_dn2
        (J,) mean temporal variance of a dark image at each exposure [DN^2].
    images
        (J,) images behind each mean map.
    clip_dn
        Values at or above this [DN] are clipped (left out of a pixel's line): a number, or an
        (M, N) map of each pixel's own clip.
    """
    t = np.asarray(exposure_s, dtype=np.float64)
    y = np.asarray(mean_maps, dtype=np.float64)
    if t.size < 2 or y.shape[0] != t.size:
        raise BenchSimError(f"dark series: need dark images at >= 2 exposure times, got {t.size}")
    w = (y < clip_dn).astype(np.float64)
    s0, s1, s2 = w.sum(0), np.tensordot(t, w, 1), np.tensordot(t * t, w, 1)
    sy, sty = (w * y).sum(0), np.tensordot(t, w * y, 1)
    det = s0 * s2 - s1 * s1
    ok = (s0 >= 2) & (det > 0)
    safe = np.where(ok, det, 1.0)
    slope = np.where(ok, (s0 * sty - s1 * sy) / safe, np.nan)
    offset = np.where(ok, (s2 * sy - s1 * sty) / safe, np.nan)
    var_j = np.asarray(temporal_var_dn2, dtype=np.float64) / np.asarray(images, dtype=np.float64)
    tc = t - t.mean()
    stt = float(np.sum(tc * tc))
    c_slope = tc / stt
    c_icp = 1.0 / t.size - t.mean() * c_slope
    return DarkSeriesMaps(
        offset_dn=offset,
        slope_dn_s=slope,
        offset_noise_dn2=float(np.sum(c_icp**2 * var_j)),
        slope_noise_dn2_s2=float(np.sum(c_slope**2 * var_j)),
        exposures_used=s0.astype(np.int64),
    )


@dataclass(frozen=True)
class RowNoise:
    """Temporal row noise (module docstring): ``var_dn2`` [DN^2] of a row's common shift in one
    read, its standard error, the pixels' own temporal variance ``pixel_var_dn2`` [DN^2] and the
    degrees of freedom."""

    var_dn2: float
    var_se_dn2: float
    pixel_var_dn2: float
    dof: int


def row_noise_variance(stacks: Sequence[np.ndarray], mask: np.ndarray | None = None) -> RowNoise:
    """The temporal row noise of dark stacks (module docstring); ``mask``: the pixels used.

    Raises
    ------
    BenchSimError
        No stack of at least two images.
    """
    num = den = pix = 0.0
    vrow_all = []
    dof = 0
    for st in stacks:
        y = np.asarray(st, dtype=np.float64)
        if y.ndim != 3 or y.shape[0] < 2:
            continue
        keep = np.ones(y.shape[1:], dtype=bool) if mask is None else mask
        yy = np.where(keep[None], y, np.nan)
        n_eff = float(np.mean(keep.sum(axis=1)))
        row_means = np.nanmean(yy, axis=2)  # (L, M)
        v_row = float(np.nanmean(np.nanvar(row_means, axis=0, ddof=1)))
        v_pix = float(np.mean(np.var(y[:, keep], axis=0, ddof=1)))
        d = y.shape[1] * (y.shape[0] - 1)
        est = (v_row - v_pix / n_eff) / (1.0 - 1.0 / n_eff)
        num, den, pix, dof = num + d * est, den + d, pix + d * v_pix, dof + d
        vrow_all.append((d, v_row, n_eff))
    if not dof:
        raise BenchSimError("row noise: needs dark stacks of at least two images")
    var = num / den
    se = math.sqrt(sum((d / den) ** 2 * 2.0 * v**2 / d / (1.0 - 1.0 / n) ** 2 for d, v, n in vrow_all))
    return RowNoise(var_dn2=var, var_se_dn2=se, pixel_var_dn2=pix / den, dof=int(dof))
