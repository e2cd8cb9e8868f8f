"""Calibration of the EMVA 1288 sensor model from a photon-transfer table: weighted least-squares
fits of ``K``, the responsivity and QE, the dark noise, the dark current and the saturation
point, with standard errors.

The table (:class:`PtcTable`, built and checked by :func:`make_table`) is the universal form of
an EMVA 1288 measurement: per illumination level the exposure time, the mean number of photons
per pixel ``mu_p``, the temporal mean ``mu_y`` and variance ``sigma_y^2`` of an image pair, and
the dark pair's ``mu_y.dark``, ``sigma_y.dark^2`` at the same exposure time.

Fits (EMVA 1288 Release 4, sections 2-3 and 6)
----------------------------------------------
* saturation point: the level with the largest temporal variance (``mu_p.sat``); the linear
  range is ``0 < mu_y - mu_y.dark <= 0.7 (mu_y.sat - mu_y.dark)``;
* ``K`` [DN/e-]: slope through the origin of ``sigma_y^2 - sigma_y.dark^2`` versus
  ``mu_y - mu_y.dark`` (eq. 7), weighted by the inverse variance of each point. The variance of
  a pair estimate of ``N`` pixels has standard error ``sigma_y^2 sqrt(2 / N)`` (normal law), so
  the weights are ``N / (2 sigma_y^4)``;
* responsivity ``R = eta K`` [DN/photon]: slope through the origin of ``mu_y - mu_y.dark`` versus
  ``mu_p`` (eq. 5), weights ``2 N / sigma_y^2`` (standard error of a pair mean); ``eta = R / K``;
* dark noise: ``sigma_y.dark^2`` of the dark level (one exposure time) or the intercept of a
  weighted line through the dark variances versus exposure time (several), and
  ``sigma_d = sqrt(sigma_y.dark^2 - sigma_q^2) / K`` [e-];
* dark current (several exposure times): slope of ``mu_y.dark`` versus exposure time over ``K``
  [e-/s] (and, as a check, of ``sigma_y.dark^2`` over ``K^2``);
* saturation capacity ``mu_e.sat = eta mu_p.sat`` [e-].

With ``pixels`` (``N``) the weights are absolute and ``chi2_red`` (reduced chi-square) tests the
fit; without it the weights are relative (``N`` unknown) and the standard errors are scaled by
the observed scatter, ``sqrt(chi2_red)`` (the usual least-squares estimate). Standard errors
account for the scatter of the points and the uncertainty of the dark level; a systematic error
of the photon calibration (the irradiance meter) is not in the data and not in them.

References
----------
.. [EMVA] EMVA Standard 1288, Release 4.0 Linear, European Machine Vision Association, 2021:
   sections 2 (linear model, eq. 1-8), 3 (saturation, sensitivity threshold) and 6 (methods).
.. [BR] P. R. Bevington, D. K. Robinson, *Data Reduction and Error Analysis for the Physical
   Sciences*, 3rd ed., McGraw-Hill, 2003, chapter 6 (weighted least squares, standard errors).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bench_sim.config.plausible import Typical, judge
from bench_sim.errors import BenchSimError
from bench_sim.metrics.emva1288 import LINEAR_FIT_FRACTION, photons_min_model, snr_curve
from bench_sim.sensor.model import QUANTIZATION_VAR_DN2

__all__ = [
    "PtcTable",
    "LineFit",
    "CameraFit",
    "make_table",
    "wls_line",
    "fit_camera",
    "MIN_LINEAR_POINTS",
    "EXPOSURE_TYPICAL",
    "QUANTIZATION_LIMIT_DN2",
]

#: Typical exposure time of an EMVA 1288 measurement: a value more than 10 times outside is
#: refused as a unit slip (milliseconds written as seconds), as a config's keys are.
EXPOSURE_TYPICAL = Typical(1e-6, 1.0, "s")
#: Fewest levels in the linear range for a fit with a standard error.
MIN_LINEAR_POINTS = 5
#: EMVA 1288: below this dark variance [DN^2] the dark noise is limited by quantisation and
#: reported as this floor (an upper bound).
QUANTIZATION_LIMIT_DN2 = 0.24


@dataclass(frozen=True)
class PtcTable:
    """A checked photon-transfer table: the lit levels, each with its matching dark level.

    Arrays (one value per lit level, in increasing photons): ``exposure_s`` [s], ``photons``
    (mean photons per pixel during the exposure), ``mean_dn`` [DN], ``var_dn2`` [DN^2],
    ``dark_mean_dn`` [DN], ``dark_var_dn2`` [DN^2]. ``dark_exposure_s``, ``dark_means_dn``,
    ``dark_vars_dn2``: the distinct dark levels. ``pixels``: pixels per image (None: unknown);
    ``bits``: ADC bits (None: unknown); ``wavelength_nm`` (None: unknown).
    """

    exposure_s: np.ndarray
    photons: np.ndarray
    mean_dn: np.ndarray
    var_dn2: np.ndarray
    dark_mean_dn: np.ndarray
    dark_var_dn2: np.ndarray
    dark_exposure_s: np.ndarray
    dark_means_dn: np.ndarray
    dark_vars_dn2: np.ndarray
    pixels: int | None = None
    bits: int | None = None
    wavelength_nm: float | None = None
    source: str = "table"


def _col(name: str, values: Any, n: int, source: str) -> np.ndarray:
    try:
        arr = np.asarray(values, dtype=np.float64).ravel()
    except (TypeError, ValueError) as exc:
        raise BenchSimError(f"{source}: column {name!r} holds values that are not numbers") from exc
    if arr.size != n:
        raise BenchSimError(f"{source}: column {name!r} has {arr.size} values, expected {n}")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        i = int(bad[0])
        raise BenchSimError(f"{source}: row {i + 1}: {name} = {float(arr[i])} is not a finite number")
    return arr


def _dark_for(
    t: float, dark_t: np.ndarray, dark_m: np.ndarray, dark_v: np.ndarray, source: str
) -> tuple[float, float]:
    same = np.isclose(dark_t, t, rtol=1e-6, atol=0.0)
    if not same.any():
        raise BenchSimError(
            f"{source}: no dark level (photons_per_pixel = 0, or dark_mean_dn/dark_var_dn2 columns) "
            f"at exposure_s = {t:.6g}; EMVA 1288 needs the dark pair of every exposure time"
        )
    return float(dark_m[same].mean()), float(dark_v[same].mean())


def _check_rows(cols: dict[str, np.ndarray], lit: np.ndarray, source: str) -> None:
    """Refuse negative values, an exposure time of 0 or in the wrong unit, too few lit rows, a
    decreasing exposure, non-increasing photons."""
    for name in ("var_dn2", "dark_var_dn2", "photons_per_pixel", "exposure_s"):
        if name in cols and (cols[name] < 0).any():
            i = int(np.flatnonzero(cols[name] < 0)[0])
            what = "a variance" if "var" in name else "it"
            raise BenchSimError(
                f"{source}: row {i + 1}: {name} = {cols[name][i]:g} < 0: {what} cannot be negative"
            )
    t = cols["exposure_s"]
    if (t == 0).any():
        i = int(np.flatnonzero(t == 0)[0])
        raise BenchSimError(
            f"{source}: row {i + 1}: exposure_s = 0: every level (dark rows too) is measured over an "
            "exposure time > 0 s"
        )
    for i, value in enumerate(t):
        slip = judge("exposure_s", float(value), EXPOSURE_TYPICAL)
        if slip:
            raise BenchSimError(f"{source}: row {i + 1}: {slip}")
    if lit.size < 3:
        raise BenchSimError(f"{source}: {lit.size} lit rows (photons_per_pixel > 0): need at least 3")
    tl, ph = cols["exposure_s"][lit], cols["photons_per_pixel"]
    if (np.diff(tl) < 0).any():
        i = int(lit[np.flatnonzero(np.diff(tl) < 0)[0] + 1])
        raise BenchSimError(
            f"{source}: row {i + 1}: exposure_s = {cols['exposure_s'][i]:g} below the row before: "
            "non-monotonic exposure (list the lit levels in the order of the series, exposure never "
            "decreasing)"
        )
    if (np.diff(ph[lit]) <= 0).any():
        i = int(lit[np.flatnonzero(np.diff(ph[lit]) <= 0)[0] + 1])
        raise BenchSimError(
            f"{source}: row {i + 1}: photons_per_pixel = {ph[i]:g} does not increase over the row before "
            "(lit levels must be listed in increasing irradiation)"
        )


def _check_above_dark(mean: np.ndarray, dark: np.ndarray, lit: np.ndarray, source: str) -> None:
    """Refuse a lit level whose mean lies below its dark level (swapped columns, or the dark
    pair of another exposure): its signal ``mu_y - mu_y.dark`` would be negative."""
    below = np.flatnonzero(mean < dark)
    if below.size:
        j = int(below[0])
        raise BenchSimError(
            f"{source}: row {int(lit[j]) + 1}: mean_dn = {mean[j]:g} below its dark level {dark[j]:g} DN: a "
            "lit level cannot be darker than the dark (mean_dn and dark_mean_dn swapped, or the dark "
            "rows of another exposure time?)"
        )


def make_table(
    exposure_s: Any,
    photons_per_pixel: Any,
    mean_dn: Any,
    var_dn2: Any,
    dark_mean_dn: Any = None,
    dark_var_dn2: Any = None,
    *,
    pixels: int | None = None,
    bits: int | None = None,
    wavelength_nm: float | None = None,
    source: str = "table",
) -> PtcTable:
    """Check a photon-transfer table and pair every lit level with its dark level.

    Rows with ``photons_per_pixel = 0`` are dark levels; the others are lit levels, each paired
    with the ``dark_mean_dn``/``dark_var_dn2`` of its row where given, else with the dark rows
    of the same exposure time.

    Raises
    ------
    BenchSimError
        One line naming the row and value: a value not finite; a negative variance, photon
        count or exposure time; the lit levels' exposure time decreasing (non-monotonic
        exposure) or their photons not increasing; a lit level without a dark level.
    """
    t = np.asarray(exposure_s, dtype=object).ravel()
    n = t.size
    cols = {
        "exposure_s": _col("exposure_s", exposure_s, n, source),
        "photons_per_pixel": _col("photons_per_pixel", photons_per_pixel, n, source),
        "mean_dn": _col("mean_dn", mean_dn, n, source),
        "var_dn2": _col("var_dn2", var_dn2, n, source),
    }
    for name in ("dark_mean_dn", "dark_var_dn2"):
        val = dark_mean_dn if name == "dark_mean_dn" else dark_var_dn2
        if val is not None:
            cols[name] = _col(name, val, n, source)
    ph = cols["photons_per_pixel"]
    lit = np.flatnonzero(ph > 0)
    dark = np.flatnonzero(ph == 0)
    _check_rows(cols, lit, source)
    tl = cols["exposure_s"][lit]
    if "dark_mean_dn" in cols and "dark_var_dn2" in cols:
        dt = cols["exposure_s"][lit]
        dm, dv = cols["dark_mean_dn"][lit], cols["dark_var_dn2"][lit]
        if dark.size:  # the dark rows count as well
            dt = np.concatenate([cols["exposure_s"][dark], dt])
            dm = np.concatenate([cols["mean_dn"][dark], dm])
            dv = np.concatenate([cols["var_dn2"][dark], dv])
        pairs = np.column_stack([dm[-lit.size :], dv[-lit.size :]])
    else:
        dt, dm, dv = cols["exposure_s"][dark], cols["mean_dn"][dark], cols["var_dn2"][dark]
        pairs = np.array([_dark_for(float(x), dt, dm, dv, source) for x in tl])
    _check_above_dark(cols["mean_dn"][lit], pairs[:, 0], lit, source)
    ut = np.unique(dt)
    dark_levels = np.array([_dark_for(float(x), dt, dm, dv, source) for x in ut]).reshape(-1, 2)
    return PtcTable(
        exposure_s=tl, photons=ph[lit], mean_dn=cols["mean_dn"][lit], var_dn2=cols["var_dn2"][lit],
        dark_mean_dn=pairs[:, 0], dark_var_dn2=pairs[:, 1], dark_exposure_s=ut,
        dark_means_dn=dark_levels[:, 0], dark_vars_dn2=dark_levels[:, 1],
        pixels=None if pixels is None else int(pixels), bits=None if bits is None else int(bits),
        wavelength_nm=wavelength_nm, source=source,
    )


@dataclass(frozen=True)
class LineFit:
    """A weighted straight-line fit ``y = slope x (+ intercept)`` and its standard errors.

    ``chi2_red``: the reduced chi-square with the given weights; ``scaled``: whether the
    standard errors were scaled by ``sqrt(chi2_red)`` (relative weights).
    """

    slope: float
    slope_se: float
    intercept: float
    intercept_se: float
    chi2_red: float
    n: int
    scaled: bool
    residuals: np.ndarray = field(repr=False)


def wls_line(
    x: np.ndarray, y: np.ndarray, sigma_y: np.ndarray, *, through_origin: bool, absolute_sigma: bool
) -> LineFit:
    """Weighted least squares of a straight line, weights ``1 / sigma_y^2`` ([BR] chapter 6).

    ``absolute_sigma=False``: ``sigma_y`` are relative; the covariance is scaled by
    ``chi2_red``. Needs one more point than parameters.
    """
    x, y, s = (np.asarray(a, dtype=np.float64) for a in (x, y, sigma_y))
    p = 1 if through_origin else 2
    if x.size <= p or not (s > 0).all():
        raise BenchSimError(f"line fit: {x.size} points with positive errors, need at least {p + 1}")
    w = 1.0 / (s * s)
    if through_origin:
        sxx = float(np.sum(w * x * x))
        slope, icp = float(np.sum(w * x * y)) / sxx, 0.0
        var_s, var_i = 1.0 / sxx, 0.0
    else:
        sw, sx, sy = float(w.sum()), float(np.sum(w * x)), float(np.sum(w * y))
        sxx, sxy = float(np.sum(w * x * x)), float(np.sum(w * x * y))
        det = sw * sxx - sx * sx
        slope, icp = (sw * sxy - sx * sy) / det, (sxx * sy - sx * sxy) / det
        var_s, var_i = sw / det, sxx / det
    res = y - (slope * x + icp)
    chi2_red = float(np.sum(w * res * res)) / (x.size - p)
    scale = 1.0 if absolute_sigma else chi2_red
    return LineFit(
        slope=slope, slope_se=math.sqrt(var_s * scale), intercept=icp, intercept_se=math.sqrt(var_i * scale),
        chi2_red=chi2_red, n=int(x.size), scaled=not absolute_sigma, residuals=res,
    )


@dataclass(frozen=True)
class CameraFit:
    """EMVA 1288 results of a table with standard errors (``*_se``; NaN where not determined).

    Units: DN, electrons (e-), photons per pixel, seconds. ``saturation_index``: the lit level
    of the variance maximum; ``linear``: mask of the lit levels in the linear range.
    """

    k_dn_per_e: float
    k_se: float
    responsivity_dn_per_photon: float
    responsivity_se: float
    quantum_efficiency: float
    quantum_efficiency_se: float
    dark_var_dn2: float
    dark_var_se: float
    dark_noise_dn: float
    dark_noise_e: float
    dark_noise_e_se: float
    dark_noise_quantization_limited: bool
    dark_offset_dn: float
    dark_current_e_s: float
    dark_current_e_s_se: float
    dark_current_from_variance_e_s: float
    exposure_s: float
    photons_sat: float
    saturation_signal_dn: float
    saturation_capacity_e: float
    saturation_capacity_e_se: float
    plateau_dn: float
    photons_min: float
    dynamic_range_db: float
    snr_max: float
    bits: int
    bits_inferred: bool
    chi2_red_k: float
    chi2_red_r: float
    saturation_index: int
    k_fit: LineFit = field(repr=False)
    r_fit: LineFit = field(repr=False)
    linear: np.ndarray = field(repr=False)
    snr: np.ndarray = field(repr=False)

    def summary(self) -> dict[str, Any]:
        """The scalar results (JSON-ready)."""
        skip = {"k_fit", "r_fit", "linear", "snr"}
        return {k: v for k, v in self.__dict__.items() if k not in skip}


def _saturation_index(var: np.ndarray, source: str) -> int:
    i = int(np.argmax(var))
    if i == var.size - 1:
        raise BenchSimError(
            f"{source}: no saturation reached: the temporal variance is largest at the brightest level; "
            "EMVA 1288 needs levels beyond the variance maximum (add brighter levels)"
        )
    return i


def _dark_fit(
    tab: PtcTable, k: float, rel: float
) -> tuple[float, float, float, float, float, float]:
    """Dark variance at the series' exposure (or at 0 s with several exposure times), its
    standard error, the dark offset [DN] at that exposure, the dark current [e-/s] from the
    mean and its standard error, the dark current from the variance [e-/s]."""
    t, m, v = tab.dark_exposure_s, tab.dark_means_dn, tab.dark_vars_dn2
    if t.size >= 3:
        absolute = tab.pixels is not None
        sv = wls_line(t, v, np.maximum(v, 1e-12) * rel, through_origin=False, absolute_sigma=absolute)
        sm = np.sqrt(np.maximum(v, 1e-12) / (2.0 * (tab.pixels or 1)))
        fm = wls_line(t, m, sm, through_origin=False, absolute_sigma=absolute)
        return sv.intercept, sv.intercept_se, fm.intercept, fm.slope / k, fm.slope_se / k, sv.slope / k**2
    var = float(v.mean())
    se = var * rel / math.sqrt(v.size)
    return var, se, float(m.mean()), math.nan, math.nan, math.nan


def fit_camera(
    tab: PtcTable,
    *,
    fraction: float = LINEAR_FIT_FRACTION,
    quantization_var_dn2: float = QUANTIZATION_VAR_DN2,
) -> CameraFit:
    """EMVA 1288 analysis of a photon-transfer table with weighted fits (see module doc).

    Raises
    ------
    BenchSimError
        No saturation reached, or fewer than :data:`MIN_LINEAR_POINTS` levels in the linear range.
    """
    x = tab.mean_dn - tab.dark_mean_dn
    yv = tab.var_dn2 - tab.dark_var_dn2
    i_sat = _saturation_index(tab.var_dn2, tab.source)
    lin = (x > 0) & (x <= fraction * x[i_sat]) & (np.arange(x.size) < i_sat)
    if int(lin.sum()) < MIN_LINEAR_POINTS:
        raise BenchSimError(
            f"{tab.source}: {int(lin.sum())} levels in the linear range (0 .. {fraction:.0%} of the "
            f"saturation signal {x[i_sat]:.6g} DN): need at least {MIN_LINEAR_POINTS} (add levels below "
            "saturation)"
        )
    absolute = tab.pixels is not None
    rel = math.sqrt(2.0 / tab.pixels) if tab.pixels else 1.0
    kf = wls_line(x[lin], yv[lin], tab.var_dn2[lin] * rel, through_origin=True, absolute_sigma=absolute)
    rel_eff = rel * (1.0 if absolute else math.sqrt(kf.chi2_red))  # relative s.e. of one variance
    k = kf.slope
    if not k > 0:
        raise BenchSimError(
            f"{tab.source}: fitted K = {k:.4g} DN/e-: the variance does not grow with the signal"
        )
    # dark level's uncertainty shifts every y alike: propagate into the slope
    w = 1.0 / (tab.var_dn2[lin] * rel) ** 2
    dvar_se = float(np.mean(tab.dark_var_dn2)) * rel_eff / math.sqrt(tab.dark_vars_dn2.size)
    k_se = math.hypot(kf.slope_se, dvar_se * float(np.sum(w * x[lin]) / np.sum(w * x[lin] ** 2)))
    s_mean = np.sqrt(np.maximum(tab.var_dn2[lin], 1e-12) / (2.0 * (tab.pixels or 1)))
    rf = wls_line(tab.photons[lin], x[lin], s_mean, through_origin=True, absolute_sigma=absolute)
    r = rf.slope
    eta = r / k
    eta_se = eta * math.hypot(rf.slope_se / r, k_se / k)
    dvar, dvar_se, doff, idark, idark_se, idark_v = _dark_fit(tab, k, rel_eff)
    limited = dvar < QUANTIZATION_LIMIT_DN2
    dvar_used = max(dvar, QUANTIZATION_LIMIT_DN2)
    sig_d = math.sqrt(max(dvar_used - quantization_var_dn2, 0.0)) / k
    sig_d_se = sig_d * math.hypot(0.5 * dvar_se / max(dvar_used - quantization_var_dn2, 1e-12), k_se / k)
    # saturation: grid maximum; its place is known to half a level step either side
    p = tab.photons
    lo, hi = p[max(i_sat - 1, 0)], p[i_sat + 1]
    p_sat = float(p[i_sat])
    mu_e_sat = eta * p_sat
    mu_e_sat_se = mu_e_sat * math.hypot(eta_se / eta, (hi - lo) / 2.0 / math.sqrt(3.0) / p_sat)
    p_min = photons_min_model(eta, k, dvar_used)
    bits = tab.bits if tab.bits is not None else max(8, math.ceil(math.log2(float(tab.mean_dn.max()) + 1.0)))
    snr = snr_curve(x, np.sqrt(np.maximum(tab.var_dn2, 0.0)))
    return CameraFit(
        k_dn_per_e=k, k_se=k_se, responsivity_dn_per_photon=r, responsivity_se=rf.slope_se,
        quantum_efficiency=eta, quantum_efficiency_se=eta_se, dark_var_dn2=dvar, dark_var_se=dvar_se,
        dark_noise_dn=math.sqrt(dvar_used), dark_noise_e=sig_d, dark_noise_e_se=sig_d_se,
        dark_noise_quantization_limited=limited, dark_offset_dn=doff, dark_current_e_s=idark,
        dark_current_e_s_se=idark_se, dark_current_from_variance_e_s=idark_v,
        exposure_s=float(np.median(tab.exposure_s)), photons_sat=p_sat, saturation_signal_dn=float(x[i_sat]),
        saturation_capacity_e=mu_e_sat, saturation_capacity_e_se=mu_e_sat_se,
        plateau_dn=float(x[i_sat:].max()), photons_min=p_min,
        dynamic_range_db=20.0 * math.log10(p_sat / p_min),
        snr_max=math.sqrt(mu_e_sat), bits=int(bits), bits_inferred=tab.bits is None,
        chi2_red_k=kf.chi2_red, chi2_red_r=rf.chi2_red, saturation_index=i_sat, k_fit=kf, r_fit=rf,
        linear=lin, snr=snr,
    )
