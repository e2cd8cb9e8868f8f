"""The one EMVA 1288 estimator of a camera: weighted fits of ``K``, the responsivity and QE, the
dark noise and dark current, the saturation point and where the camera clips, the linearity error
and the response curve, with standard errors. ``bench-sim ptc`` and ``bench-sim calibrate`` both
call :func:`fit_camera`, so they report the same numbers from the same table.

Fits (EMVA 1288 Release 4, sections 2-3 and 6)
----------------------------------------------
* saturation point: the level with the largest temporal variance (``mu_p.sat``); a table that
  ends at the variance peak is accepted and its saturation stated as a lower bound; the linear
  range is ``0 < mu_y - mu_y.dark <= 0.7 (mu_y.sat - mu_y.dark)``;
* response and linearity: where the irradiation is known (photons, a relative irradiance or the
  exposure time of an exposure-time series), the linearity error LE
  (:func:`bench_sim.sensor.linearity.linearity_error`) and the response polynomial
  (:func:`bench_sim.metrics.response_fit.fit_response`); when it is significantly non-linear the
  photon transfer is linearised by it: the signal becomes ``s = a_1 x`` and the variance is divided
  by ``f'(s)^2``;
* ``K`` [DN/e-]: slope through the origin of ``sigma_y^2 - sigma_y.dark^2`` versus the signal
  (eq. 7), weighted by the inverse variance of each point: a variance from ``L`` images of ``N``
  pixels has relative standard error ``sqrt(2 / (N (L - 1)))``; each dark level's error is
  shared by every point that subtracts it (generalised least squares with that covariance,
  :func:`bench_sim.metrics.weighted_fit.gls_through_origin`);
* responsivity ``R = eta K`` [DN/photon]: slope through the origin of the signal versus ``mu_p``
  (eq. 5) over the linear range, or the response's small-signal slope ``a_1`` where it is
  non-linear; ``eta = R / K``; unknown without a photon calibration;
* dark noise: ``sigma_y.dark^2`` of the dark level (one exposure time) or the intercept at 0 s
  of a weighted line through the dark variances (several), ``sigma_d = sqrt(sigma_y.dark^2 -
  sigma_q^2) / K`` [e-]; dark current from the slope of the dark mean versus exposure [e-/s];
* saturation capacity ``mu_e.sat = eta mu_p.sat`` [e-] (without photons: the linear signal at
  saturation over ``K``); where the camera clips from the plateau beyond it
  (:func:`clip_kind`).

Standard errors: with ``pixels`` the weights are absolute, ``chi2_red`` tests each fit and a
misfit widens its errors by ``sqrt(chi2_red)``
(:func:`bench_sim.metrics.weighted_fit.misfit_scale`; the statistical errors are kept beside
them); without it the weights are relative and the errors always scaled by the scatter. A
systematic error of the photon calibration (the irradiance meter) is not in the data and not in
them.

References
----------
.. [EMVA] EMVA Standard 1288, Release 4.0 Linear, European Machine Vision Association, 2021:
   sections 2 (linear model, eq. 1-8), 3 (saturation, sensitivity threshold) and 6 (methods).
.. [BR] P. R. Bevington, D. K. Robinson, *Data Reduction and Error Analysis for the Physical
   Sciences*, 3rd ed., McGraw-Hill, 2003, chapter 6.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bench_sim.errors import BenchSimError
from bench_sim.metrics.photon_transfer import LINEAR_FIT_FRACTION
from bench_sim.metrics.ptc_table import PtcTable
from bench_sim.metrics.response_fit import ResponseFit, fit_response
from bench_sim.metrics.weighted_fit import LineFit, gls_through_origin, wls_line
from bench_sim.sensor.linearity import LE_RANGE, LinearityError, linearity_error
from bench_sim.sensor.model import QUANTIZATION_VAR_DN2

__all__ = ["CameraFit", "fit_camera", "clip_kind", "MIN_LINEAR_POINTS", "QUANTIZATION_LIMIT_DN2"]

#: Fewest levels in the linear range for a fit with a standard error.
MIN_LINEAR_POINTS = 5
#: EMVA 1288: below this dark variance [DN^2] the dark noise is limited by quantisation and
#: reported as this floor (an upper bound).
QUANTIZATION_LIMIT_DN2 = 0.24
#: Plateau variance, as a fraction of the dark variance, at or below which the ADC clips (the
#: values pile up at the ADC's top: variance -> 0) and above which the pixel clips (its full
#: well, the read noise after it: variance ~ the dark variance); between: both
ADC_PLATEAU, PIXEL_PLATEAU = 0.25, 0.5


@dataclass(frozen=True)
class CameraFit:
    """EMVA 1288 results of a table with standard errors (``*_se``; NaN where not determined).

    Units: DN, electrons (e-), photons per pixel, seconds. ``saturation_index``: the lit level
    of the variance maximum; ``linear``: mask of the lit levels in the linear range;
    ``clips_on``: ``adc``, ``full_well``, ``both`` or ``unknown`` (:func:`clip_kind`).
    """

    k_dn_per_e: float
    k_se: float
    k_se_statistical: float
    responsivity_dn_per_photon: float
    responsivity_se: float
    quantum_efficiency: float
    quantum_efficiency_se: float
    qe_known: bool
    dark_var_dn2: float
    dark_var_se: float
    dark_noise_dn: float
    dark_noise_e: float
    dark_noise_e_se: float
    dark_noise_quantization_limited: bool
    dark_offset_dn: float
    dark_offset_known: bool
    dark_current_e_s: float
    dark_current_e_s_se: float
    dark_current_from_variance_e_s: float
    exposure_s: float
    exposure_min_s: float
    exposure_max_s: float
    photons_sat: float
    saturation_signal_dn: float
    saturation_capacity_e: float
    saturation_capacity_e_se: float
    saturation_lower_bound: bool
    plateau_dn: float
    plateau_var_dn2: float
    clips_on: str
    photons_min: float
    dynamic_range_db: float
    snr_max: float
    bits: int
    bits_inferred: bool
    chi2_red_k: float
    chi2_red_r: float
    k_misfit: bool
    saturation_index: int
    irradiance_kind: str
    linearized: bool
    response_degree: int
    response_coefficients: list[float]
    response_rms_relative: float
    linearity_error_percent: float
    linearity_error_se_percent: float
    k_fit: LineFit = field(repr=False)
    r_fit: LineFit | None = field(repr=False)
    linear: np.ndarray = field(repr=False)
    snr: np.ndarray = field(repr=False)
    response: ResponseFit | None = field(repr=False, default=None)
    linearity: LinearityError | None = field(repr=False, default=None)

    def summary(self) -> dict[str, Any]:
        """The scalar results (JSON-ready), with the linearity's own summary."""
        skip = {"k_fit", "r_fit", "linear", "snr", "response", "linearity"}
        out = {k: v for k, v in self.__dict__.items() if k not in skip}
        out["linearity"] = None if self.linearity is None else self.linearity.summary()
        return out


def _dark_fit(tab: PtcTable, k: float) -> tuple[float, float, float, float, float, float]:
    """Dark variance at the series' exposure (or at 0 s with several exposure times), its
    standard error, the dark offset [DN] there, the dark current [e-/s] from the mean and its
    standard error, the dark current from the variance [e-/s]."""
    t, m, v = tab.dark_exposure_s, tab.dark_means_dn, tab.dark_vars_dn2
    absolute = tab.pixels is not None
    n = float(tab.pixels or 1)
    rel = tab.var_rel_se(v, tab.dark_images)
    if t.size >= 3:
        sv = wls_line(t, v, np.maximum(v, 1e-12) * rel, through_origin=False, absolute_sigma=absolute)
        sm = np.sqrt(
            (np.maximum(v, 1e-12) + (tab.columns - 1) * tab.row_noise_var_dn2) / (tab.dark_images * n)
        )
        fm = wls_line(t, m, sm, through_origin=False, absolute_sigma=absolute)
        return sv.intercept, sv.intercept_se, fm.intercept, fm.slope / k, fm.slope_se / k, sv.slope / k**2
    var = float(v.mean())
    spread = float(np.std(v, ddof=1)) if v.size > 1 and not absolute else 0.0
    se = max(var * float(rel.mean()), spread) / math.sqrt(v.size)
    return var, se, float(m.mean()), math.nan, math.nan, math.nan


def _saturation_index(var: np.ndarray) -> tuple[int, bool]:
    i = int(np.argmax(var))
    return i, i == var.size - 1


def clip_kind(tab: PtcTable, i_sat: int) -> tuple[str, float, float]:
    """Where the camera clips, from the levels past saturation: ``(kind, plateau variance [DN^2],
    plateau signal [DN])``.

    The plateau is the levels beyond the variance maximum whose signal lies within 1 % of the
    largest; its variance (median) against the dark variance: at most :data:`ADC_PLATEAU` of it
    (the values pile up at one code) -> ``adc``; at least :data:`PIXEL_PLATEAU` (the pixel's
    full well with the read noise after it) -> ``full_well``; between -> ``both`` (some pixels
    clip on the ADC, others on their full well). No level beyond the maximum -> ``unknown``.
    """
    sig = tab.signal_dn
    after = np.arange(sig.size) > i_sat
    if not after.any():
        return "unknown", math.nan, float(sig[i_sat])
    top = float(sig[after].max())
    plateau = after & (sig >= top - 0.01 * abs(top))
    pvar = float(np.median(tab.var_dn2[plateau]))
    dvar = float(tab.dark_var_dn2[i_sat])
    if pvar <= ADC_PLATEAU * dvar:
        kind = "adc"
    elif pvar >= PIXEL_PLATEAU * dvar:
        kind = "full_well"
    else:
        kind = "both"
    return kind, pvar, top


def _k_fit(tab: PtcTable, lin: np.ndarray, s: np.ndarray, ratio: np.ndarray) -> LineFit:
    """``K`` through the origin of the dark-subtracted variance (divided by ``ratio^2``, the
    response's slope) against the (linear) signal ``s``, by generalised least squares: each
    variance's own error on the diagonal, each dark level's error shared by every point that
    subtracts it."""
    d2 = ratio[lin] ** 2
    var, dvar = tab.var_dn2[lin], tab.dark_var_dn2[lin]
    y = (var - dvar) / d2
    own = (var * tab.var_rel_se(var, tab.images) / d2) ** 2
    shared = dvar * tab.var_rel_se(dvar, tab.dark_images) / d2
    grp = tab.dark_groups()[lin]
    cov = np.diag(own) + np.where(grp[:, None] == grp[None, :], np.outer(shared, shared), 0.0)
    return gls_through_origin(s[lin], y, cov, absolute_sigma=tab.pixels is not None)


def _response(tab: PtcTable, i_sat: int) -> tuple[ResponseFit | None, LinearityError | None]:
    """The response polynomial and the linearity error, where the irradiation is known."""
    if tab.irradiance is None:
        return None, None
    sig, x = tab.signal_dn, tab.irradiance
    rng = (sig > 0) & (sig <= LE_RANGE[1] * sig[i_sat]) & (np.arange(sig.size) <= i_sat) & (x > 0)
    if int(rng.sum()) < 3:
        return None, None
    cov = tab.signal_cov_dn2()
    se = np.sqrt(np.diag(cov))
    resp = fit_response(x[rng], sig[rng], cov[np.ix_(rng, rng)], absolute=tab.pixels is not None)
    try:
        le = linearity_error(
            x, sig, tab.var_dn2, signal_se_dn=se if tab.pixels else None, saturation_index=i_sat
        )
    except BenchSimError:
        le = None
    return resp, le


def _responsivity(
    tab: PtcTable, lin: np.ndarray, resp: ResponseFit | None, linearized: bool
) -> tuple[float, float, float, LineFit | None]:
    """``R`` [DN per unit of irradiation] and its error, the R fit's ``chi2_red``, the R fit:
    the response's small-signal slope where it is non-linear, else the line through the origin
    over the linear range; NaN without an irradiation."""
    if tab.irradiance is None:
        return math.nan, math.nan, math.nan, None
    if linearized and resp is not None:
        return resp.slope, resp.slope_se, resp.chi2_red, None
    cov = tab.signal_cov_dn2()[np.ix_(lin, lin)]
    rf = gls_through_origin(
        tab.irradiance[lin], tab.signal_dn[lin], cov, absolute_sigma=tab.pixels is not None
    )
    return rf.slope, rf.slope_se, rf.chi2_red, rf


def _saturation(
    tab: PtcTable, i_sat: int, k: float, k_se: float, r: float, r_se: float
) -> tuple[float, float, float]:
    """``mu_p.sat`` (NaN without an irradiation), ``mu_e.sat`` [e-] and its error: the linear
    signal at the variance maximum over ``K``; its place known to half a level step either side."""
    x = tab.irradiance
    if x is None or not math.isfinite(r):
        s_sat = float(tab.signal_dn[i_sat])
        return math.nan, s_sat / k, s_sat / k * k_se / k
    lo, hi = x[max(i_sat - 1, 0)], x[min(i_sat + 1, x.size - 1)]
    x_sat = float(x[i_sat])
    mu_e = r * x_sat / k
    rel = math.hypot(math.hypot(r_se / r, k_se / k), (hi - lo) / 2.0 / math.sqrt(3.0) / x_sat)
    return (x_sat if tab.photons is not None else math.nan), mu_e, mu_e * rel


def _linear_range(tab: PtcTable, i_sat: int, fraction: float) -> np.ndarray:
    """Mask of the lit levels from 0 to ``fraction`` of the saturation signal (below it)."""
    x = tab.signal_dn
    lin = (x > 0) & (x <= fraction * x[i_sat]) & (np.arange(x.size) < i_sat)
    if int(lin.sum()) < MIN_LINEAR_POINTS:
        raise BenchSimError(
            f"{tab.source}: {int(lin.sum())} levels in the linear range (0 .. {fraction:.0%} of the "
            f"saturation signal {x[i_sat]:.6g} DN): need at least {MIN_LINEAR_POINTS} (add levels below "
            "saturation)"
        )
    return lin


def _dark_fields(tab: PtcTable, k: float, k_se: float, q: float) -> dict[str, Any]:
    """The dark level's fields of :class:`CameraFit` (the dark noise with ``K``'s error in it)."""
    dvar, dvar_se, doff, idark, idark_se, idark_v = _dark_fit(tab, k)
    if math.isfinite(idark):
        idark_se = abs(idark) * math.hypot(idark_se / idark if idark else 0.0, k_se / k)
    used = max(dvar, QUANTIZATION_LIMIT_DN2)
    sig_d = math.sqrt(max(used - q, 0.0)) / k
    return {
        "dark_var_dn2": dvar, "dark_var_se": dvar_se, "dark_noise_dn": math.sqrt(used), "dark_noise_e": sig_d,
        "dark_noise_e_se": sig_d * math.hypot(0.5 * dvar_se / max(used - q, 1e-12), k_se / k),
        "dark_noise_quantization_limited": dvar < QUANTIZATION_LIMIT_DN2, "dark_offset_dn": doff,
        "dark_offset_known": tab.dark_mean_known, "dark_current_e_s": idark, "dark_current_e_s_se": idark_se,
        "dark_current_from_variance_e_s": idark_v,
    }


def _response_fields(resp: ResponseFit | None, le: LinearityError | None, linearized: bool) -> dict[str, Any]:
    """The response's and the linearity's fields of :class:`CameraFit`."""
    return {
        "linearized": linearized, "response_degree": 0 if resp is None else resp.degree,
        "response_coefficients": [] if resp is None else [float(a) for a in resp.coefficients],
        "response_rms_relative": math.nan if resp is None else resp.rms_relative,
        "linearity_error_percent": math.nan if le is None else le.le_percent,
        "linearity_error_se_percent": math.nan if le is None else le.le_se_percent,
        "response": resp, "linearity": le,
    }


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
        Fewer than :data:`MIN_LINEAR_POINTS` levels in the linear range, or a ``K`` that is not
        positive.
    """
    x = tab.signal_dn
    i_sat, lower_bound = _saturation_index(tab.var_dn2)
    lin = _linear_range(tab, i_sat, fraction)
    resp, le = _response(tab, i_sat)
    linearized = resp is not None and resp.degree > 1 and tab.irradiance is not None
    if resp is not None and linearized and tab.irradiance is not None:
        s, ratio = resp.slope * tab.irradiance, resp.gain_ratio(tab.irradiance)
    else:
        s, ratio = x, np.ones(x.size)
    kf = _k_fit(tab, lin, s, ratio)
    k, k_se = kf.slope, kf.slope_se
    if not k > 0:
        raise BenchSimError(
            f"{tab.source}: fitted K = {k:.4g} DN/e-: the variance does not grow with the signal"
        )
    r, r_se, chi2_r, rf = _responsivity(tab, lin, resp, linearized)
    qe_known = tab.photons is not None and math.isfinite(r)
    eta = r / k if qe_known else math.nan
    dark = _dark_fields(tab, k, k_se, quantization_var_dn2)
    p_sat, mu_e_sat, mu_e_sat_se = _saturation(tab, i_sat, k, k_se, r, r_se)
    clips, pvar, plateau = clip_kind(tab, i_sat)
    e_min = math.sqrt(dark["dark_noise_dn"] ** 2 / k**2 + 0.25) + 0.5  # eta mu_p.min [e-] (EMVA 1288 R4)
    bits = tab.bits if tab.bits is not None else max(8, math.ceil(math.log2(float(tab.mean_dn.max()) + 1.0)))
    nan = math.nan
    snr = np.where(tab.var_dn2 > 0, x / np.sqrt(np.maximum(tab.var_dn2, 1e-300)), np.inf)
    return CameraFit(
        k_dn_per_e=k, k_se=k_se, k_se_statistical=kf.slope_se_statistical,
        responsivity_dn_per_photon=r if qe_known else nan, responsivity_se=r_se if qe_known else nan,
        quantum_efficiency=eta,
        quantum_efficiency_se=eta * math.hypot(r_se / r, k_se / k) if qe_known else nan,
        qe_known=qe_known, **dark, exposure_s=float(np.median(tab.exposure_s)),
        exposure_min_s=float(tab.exposure_s.min()), exposure_max_s=float(tab.exposure_s.max()),
        photons_sat=p_sat, saturation_signal_dn=float(x[i_sat]), saturation_capacity_e=mu_e_sat,
        saturation_capacity_e_se=mu_e_sat_se, saturation_lower_bound=lower_bound, plateau_dn=plateau,
        plateau_var_dn2=pvar, clips_on=clips, photons_min=e_min / eta if qe_known else nan,
        dynamic_range_db=20.0 * math.log10(mu_e_sat / e_min), snr_max=math.sqrt(mu_e_sat), bits=int(bits),
        bits_inferred=tab.bits is None, chi2_red_k=kf.chi2_red, chi2_red_r=chi2_r,
        k_misfit=kf.scaled and tab.pixels is not None, saturation_index=i_sat,
        irradiance_kind=tab.irradiance_kind, **_response_fields(resp, le, linearized), k_fit=kf, r_fit=rf,
        linear=lin, snr=snr,
    )
