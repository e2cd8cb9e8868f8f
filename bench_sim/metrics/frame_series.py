"""EMVA 1288 R4 from the images themselves: a series of lit levels and dark stacks of an area
sensor, analysed into the photon-transfer table, the one fit (:func:`bench_sim.metrics.emva_fit.fit_camera`),
the defect pixels, the non-uniformities (DSNU at the series' exposure, its split into the offset
pattern at 0 s and the dark current's non-uniformity, PRNU) and the row noise. ``bench-sim ptc
--area`` (raw frames of the sensor chain) and ``bench-sim calibrate`` (a lab's images) both call
:func:`analyse_frames`.

Steps
-----
1. per dark exposure: the mean image and the temporal variance (every image less its own mean,
   the variance over the images, ``ddof = 1``: for two images EMVA 1288's pair formula);
2. a first table and fit over every pixel that is not constant, for ``K``;
3. the defect pixels (:func:`bench_sim.metrics.defect_pixels.find_defects`) from the dark series'
   slope map (or the dark image), the PRNU image (the lit level nearest 50 % of the saturation
   signal) and the pooled dark temporal variance;
4. the table and the fit again over the good pixels only: every mean and variance, the dark
   current, DSNU and PRNU leave the defects out;
5. the spatial statistics of the good pixels (:mod:`bench_sim.metrics.nonuniformity`).

References
----------
EMVA Standard 1288, Release 4.0 Linear (2021), sections 6 (photon transfer from image pairs),
8 (non-uniformity, defect pixels).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bench_sim.errors import BenchSimError
from bench_sim.metrics.defect_pixels import HOT_DARK_CURRENT_E_S, DefectImages, DefectPixels, find_defects
from bench_sim.metrics.emva_fit import CameraFit, fit_camera
from bench_sim.metrics.nonuniformity import (
    RowNoise,
    dark_series_maps,
    own_temporal_var,
    row_noise_variance,
    spatial_components,
    temporal_mean_var,
)
from bench_sim.metrics.ptc_table import PtcTable, make_table

__all__ = ["LitLevel", "FrameSeries", "FrameAnalysis", "analyse_frames"]


@dataclass(frozen=True)
class LitLevel:
    """A lit level: ``images`` (L >= 2, M, N) [DN] taken with ``exposure_s`` [s] at
    ``irradiance`` (photons per pixel, a relative irradiance, or None)."""

    exposure_s: float
    irradiance: float | None
    images: np.ndarray = field(repr=False)


@dataclass(frozen=True)
class FrameSeries:
    """Lit levels (in increasing irradiation) and dark stacks ``(exposure_s, images)``; the
    irradiation's kind (``photons``, ``relative_irradiance``, ``exposure`` or ``none``), the ADC's
    bits (None: unknown), the wavelength [nm] and where it came from."""

    lit: tuple[LitLevel, ...]
    dark: tuple[tuple[float, np.ndarray], ...]
    irradiance_kind: str = "photons"
    bits: int | None = None
    wavelength_nm: float | None = None
    source: str = "images"

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, columns) of the images."""
        return (int(self.lit[0].images.shape[1]), int(self.lit[0].images.shape[2]))


@dataclass(frozen=True)
class FrameAnalysis:
    """What :func:`analyse_frames` gives: the table, the fit, the defects, the spatial results
    (``spatial``: DSNU at the series' exposure [e-], PRNU, their components; ``dsnu_split``: the
    offset pattern at 0 s [e-] and the dark current's non-uniformity [e-/s], or None with one dark
    exposure), the row noise and the pixels used."""

    table: PtcTable
    fit: CameraFit
    defects: DefectPixels
    spatial: dict[str, Any]
    dsnu_split: dict[str, Any] | None
    row_noise: RowNoise | None
    good_pixels: int

    def summary(self) -> dict[str, Any]:
        """The results (JSON-ready)."""
        rn = self.row_noise
        return {
            "fit": self.fit.summary(),
            "defects": self.defects.summary(),
            "spatial": self.spatial,
            "dsnu_split": self.dsnu_split,
            "good_pixels": self.good_pixels,
            "row_noise": None
            if rn is None
            else {
                "var_dn2": rn.var_dn2,
                "var_se_dn2": rn.var_se_dn2,
                "pixel_var_dn2": rn.pixel_var_dn2,
                "dof": rn.dof,
            },
        }


def _check(series: FrameSeries) -> None:
    if len(series.lit) < 3 or not series.dark:
        raise BenchSimError(f"{series.source}: need at least 3 lit levels and a dark stack")
    shape = series.shape
    for what, imgs in [*(("lit", lv.images) for lv in series.lit), *(("dark", d[1]) for d in series.dark)]:
        if imgs.ndim != 3 or imgs.shape[0] < 2 or imgs.shape[1:] != shape:
            raise BenchSimError(
                f"{series.source}: a {what} stack of shape {imgs.shape}: every level needs >= 2 images "
                f"of {shape[0]} x {shape[1]} pixels"
            )


@dataclass(frozen=True)
class _Dark:
    exposure_s: np.ndarray  # (J,) distinct, increasing
    stacks: list[np.ndarray]


def _darks(series: FrameSeries) -> _Dark:
    """The dark stacks merged per exposure time."""
    by_t: dict[float, list[np.ndarray]] = {}
    for t, imgs in series.dark:
        key = next((k for k in by_t if math.isclose(k, t, rel_tol=1e-6)), float(t))
        by_t.setdefault(key, []).append(np.asarray(imgs))
    ts = sorted(by_t)
    return _Dark(np.asarray(ts), [np.concatenate(by_t[t]) for t in ts])


def _table(series: FrameSeries, dark: _Dark, mask: np.ndarray, row_var: float = 0.0) -> PtcTable:
    """The photon-transfer table of the pixels of ``mask``: every lit level and dark stack (a row
    noise ``row_var`` [DN^2] widens its errors)."""
    rows: list[tuple[float, float, float, float, bool]] = []
    for t, st in zip(dark.exposure_s, dark.stacks, strict=True):
        mean, var, _ = temporal_mean_var(st, mask)
        rows.append((float(t), 0.0, mean, var, True))
    for lv in series.lit:
        mean, var, _ = temporal_mean_var(lv.images, mask)
        rows.append(
            (lv.exposure_s, lv.irradiance if lv.irradiance is not None else math.nan, mean, var, False)
        )
    arr = np.array([r[:4] for r in rows], dtype=np.float64)
    flag = np.array([r[4] for r in rows])
    kind = series.irradiance_kind
    irr: dict[str, Any] = {}
    if kind in ("photons", "relative_irradiance"):
        irr["photons_per_pixel" if kind == "photons" else "relative_irradiance"] = arr[:, 1]
    return make_table(
        arr[:, 0],
        mean_dn=arr[:, 2],
        var_dn2=arr[:, 3],
        dark=flag,
        pixels=int(mask.sum()),
        bits=series.bits,
        wavelength_nm=series.wavelength_nm,
        images=min(lv.images.shape[0] for lv in series.lit),
        dark_images=min(s.shape[0] for s in dark.stacks),
        row_noise_var_dn2=row_var,
        columns=int(np.ceil(mask.sum() / max(int(np.any(mask, axis=1).sum()), 1))),
        source=series.source,
        **irr,
    )


def _constant(series: FrameSeries, dark: _Dark) -> np.ndarray:
    """Pixels with the same value in every image, dark and lit."""
    lo = hi = None
    for st in [*dark.stacks, *(lv.images for lv in series.lit)]:
        a, b = st.min(axis=0), st.max(axis=0)
        lo = a if lo is None else np.minimum(lo, a)
        hi = b if hi is None else np.maximum(hi, b)
    assert lo is not None and hi is not None
    return np.asarray(lo == hi)


#: Fraction of its own range (dark to plateau) below which a pixel's dark value is unclipped
CLIP_FRACTION = 0.9


def _clip_map(series: FrameSeries, dark0: np.ndarray) -> np.ndarray:
    """(M, N) value [DN] above which a pixel's dark value counts as clipped:
    :data:`CLIP_FRACTION` of its own range, from its dark level to its plateau (its largest mean
    over the lit levels: its full well or the ADC's top); a pixel that barely responds (a dead
    one) takes the population's range."""
    top = (1 << series.bits) - 1 if series.bits is not None else np.inf
    plateau = np.max(np.stack([lv.images.mean(axis=0, dtype=np.float64) for lv in series.lit]), axis=0)
    span = plateau - dark0
    typical = float(np.median(span))
    span = np.where(span < 0.5 * typical, typical, span)
    return np.minimum(dark0 + CLIP_FRACTION * span, top - 0.5)


def _level_near(tab: PtcTable, fit: CameraFit, fraction: float) -> int:
    sig = tab.signal_dn[: fit.saturation_index + 1]
    return int(np.argmin(np.abs(sig - fraction * fit.saturation_signal_dn)))


def _defect_images(series: FrameSeries, dark: _Dark, tab: PtcTable, fit: CameraFit) -> DefectImages:
    means = np.stack([st.mean(axis=0, dtype=np.float64) for st in dark.stacks])
    clip = _clip_map(series, means[0])
    if dark.exposure_s.size >= 2:
        var_j = [temporal_mean_var(st)[1] for st in dark.stacks]
        maps = dark_series_maps(dark.exposure_s, means, var_j, [s.shape[0] for s in dark.stacks], clip)
        rate = maps.slope_dn_s
    else:
        rate = np.where(means[0] < clip, means[0] / max(float(dark.exposure_s[0]), 1e-300), np.nan)
    lv = series.lit[_level_near(tab, fit, 0.5)]
    dmean = means[int(np.argmin(np.abs(dark.exposure_s - lv.exposure_s)))]
    flat = lv.images.mean(axis=0, dtype=np.float64) - dmean
    response = flat / float(np.median(flat)) if float(np.median(flat)) > 0 else None
    dof = sum(st.shape[0] - 1 for st in dark.stacks)
    pooled = sum((st.shape[0] - 1) * temporal_mean_var(st)[2] for st in dark.stacks) / dof
    return DefectImages(
        dark_rate_dn_s=rate,
        dark_level_dn=means[0],
        response=response,
        dark_var_dn2=pooled,
        dark_var_dof=dof,
        constant=_constant(series, dark),
        clip_dn=clip,
        shortest_exposure_s=max(float(dark.exposure_s[0]), 1e-300),
    )


def _spatial(
    series: FrameSeries, dark: _Dark, tab: PtcTable, fit: CameraFit, good: np.ndarray, row_var: float
) -> dict[str, Any]:
    """DSNU at the exposure of the 50 % level [e-] and PRNU (fraction), with their components
    (the row noise's share of the temporal residue taken off the row part)."""
    k = fit.k_dn_per_e
    i50 = _level_near(tab, fit, 0.5)
    lv = series.lit[i50]
    j = int(np.argmin(np.abs(dark.exposure_s - lv.exposure_s)))
    dst = dark.stacks[j]
    d_mean = dst.mean(axis=0, dtype=np.float64)
    _, d_var, _ = temporal_mean_var(dst, good)
    _, f_var, _ = temporal_mean_var(lv.images, good)
    ld, lf = dst.shape[0], lv.images.shape[0]
    own_d = own_temporal_var(dst, good)
    dsnu = spatial_components(np.where(good, d_mean, np.nan), own_d / ld, row_var / ld)
    flat = lv.images.mean(axis=0, dtype=np.float64) - d_mean
    own = own_temporal_var(lv.images, good) / lf + own_d / ld
    prnu = spatial_components(np.where(good, flat, np.nan), own, row_var / lf + row_var / ld)
    signal = float(np.mean(flat[good]))
    return {
        "exposure_s": float(dark.exposure_s[j]),
        "prnu_level_signal_dn": signal,
        "dsnu_e": dsnu.summary(1.0 / k, "_e", fit.k_se / k),
        "prnu": prnu.summary(1.0 / signal, ""),
    }


def _dsnu_split(
    series: FrameSeries, dark: _Dark, fit: CameraFit, good: np.ndarray, row_var: float
) -> dict[str, Any] | None:
    """The offset pattern at 0 s [e-] and the dark current's non-uniformity [e-/s]."""
    if dark.exposure_s.size < 3:
        return None
    k = fit.k_dn_per_e
    means = np.stack([st.mean(axis=0, dtype=np.float64) for st in dark.stacks])
    var_j = [own_temporal_var(st, good) for st in dark.stacks]
    images = [s.shape[0] for s in dark.stacks]
    maps = dark_series_maps(dark.exposure_s, means, var_j, images, _clip_map(series, means[0]))
    rows = dark_series_maps(dark.exposure_s, means, [row_var] * len(images), images, np.inf)
    full = good & (maps.exposures_used == dark.exposure_s.size)
    off = spatial_components(
        np.where(full, maps.offset_dn, np.nan), maps.offset_noise_dn2, rows.offset_noise_dn2
    )
    rate = spatial_components(
        np.where(full, maps.slope_dn_s, np.nan), maps.slope_noise_dn2_s2, rows.slope_noise_dn2_s2
    )
    return {
        "exposures_s": dark.exposure_s.tolist(),
        "dsnu0_e": off.summary(1.0 / k, "_e", fit.k_se / k),
        "dark_current_nu_e_s": rate.summary(1.0 / k, "_e_s", fit.k_se / k),
        "dark_current_mean_e_s": float(np.nanmean(np.where(full, maps.slope_dn_s, np.nan))) / k,
        "offset_noise_e": math.sqrt(maps.offset_noise_dn2) / k,
        "slope_noise_e_s": math.sqrt(maps.slope_noise_dn2_s2) / k,
    }


def analyse_frames(
    series: FrameSeries, *, hot_dark_current_e_s: float = HOT_DARK_CURRENT_E_S
) -> FrameAnalysis:
    """EMVA 1288 R4 of an image series (module docstring).

    Raises
    ------
    BenchSimError
        Fewer than 3 lit levels or no dark stack, a stack of fewer than 2 images or of another
        size, or a table the fit refuses (too few levels in the linear range).
    """
    _check(series)
    dark = _darks(series)
    constant = _constant(series, dark)
    tab0 = _table(series, dark, ~constant)
    fit0 = fit_camera(tab0)
    defects = find_defects(
        _defect_images(series, dark, tab0, fit0), fit0.k_dn_per_e, hot_dark_current_e_s=hot_dark_current_e_s
    )
    good = defects.good
    if int(good.sum()) < 4:
        raise BenchSimError(f"{series.source}: fewer than 4 pixels are not defects")
    stacks: Sequence[np.ndarray] = dark.stacks
    rn = row_noise_variance(stacks, good)
    row_var = max(rn.var_dn2, 0.0)
    tab = _table(series, dark, good, row_var)
    fit = fit_camera(tab)
    return FrameAnalysis(
        table=tab,
        fit=fit,
        defects=defects,
        spatial=_spatial(series, dark, tab, fit, good, row_var),
        dsnu_split=_dsnu_split(series, dark, fit, good, row_var),
        row_noise=rn,
        good_pixels=int(good.sum()),
    )
