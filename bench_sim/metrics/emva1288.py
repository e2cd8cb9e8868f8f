"""EMVA 1288 (Release 4) photon-transfer analysis: pure functions over measured series.

Definitions follow EMVA 1288 Release 4.0 (linear cameras):

* temporal mean and variance of a level from **two** images ``A, B`` of ``N`` pixels:
  ``mu_y = (mean(A) + mean(B)) / 2`` and
  ``sigma_y**2 = mean(((A - mean(A)) - (B - mean(B)))**2) / 2`` (fixed patterns cancel in the
  difference image, the factor 1/2 undoes the doubling of the variance);
* dark subtraction: ``mu_y - mu_y.dark``, ``sigma_y**2 - sigma_y.dark**2``;
* overall system gain ``K`` [DN/e-]: slope of the photon-transfer line
  ``sigma_y**2 - sigma_y.dark**2 = K (mu_y - mu_y.dark)`` (linear model, eq. 7), fitted through
  the origin over the points from 0 to 70 % of the saturation signal;
* responsivity ``R = eta K`` [DN/photon]: slope of ``mu_y - mu_y.dark`` versus ``mu_p`` over the
  same range; quantum efficiency ``eta = R / K``;
* dark temporal noise ``sigma_y.dark`` [DN] and, in electrons,
  ``sigma_d = sqrt(sigma_y.dark**2 - sigma_q**2) / K``;
* saturation point: the irradiation where the temporal variance is at its maximum; its signal
  ``mu_y.sat`` (dark subtracted) gives the saturation capacity ``mu_e.sat = mu_y.sat / K``;
* ``SNR = (mu_y - mu_y.dark) / sigma_y``;
* absolute sensitivity threshold ``mu_p.min``: the irradiation where SNR = 1; measured
  (interpolated on the SNR curve) and from the linear model,
  ``mu_p.min = (sqrt(sigma_y.dark**2 / K**2 + 1/4) + 1/2) / eta`` (solution of
  ``eta mu_p = sqrt(sigma_d**2 + sigma_q**2/K**2 + eta mu_p)``);
* dynamic range ``DR = mu_p.sat / mu_p.min``, in dB ``20 lg DR``.

:func:`dynamic_range_from_series` needs only photons, mean signal and temporal noise, so it
serves any image type: a DTDI stage, or a fused HDR image whose gain is not a single ``K``.
The saturation point is located between the levels (parabolic refinement of the variance
maximum) so that dynamic ranges can be compared to a few tenths of a dB even on a coarse grid.

The steps from measured images to the series (pair statistics, dark noise, saturation point,
stack statistics) live in :mod:`bench_sim.metrics.photon_transfer`; the fits of ``K``, the
responsivity, the dark level and the saturation with standard errors are the one estimator
:func:`bench_sim.metrics.emva_fit.fit_camera` (``ptc`` and ``calibrate`` alike); this module
builds the sensitivity, SNR and dynamic range on them and re-exports them, so
``bench_sim.metrics.emva1288`` is the one import.

References
----------
.. [EMVA] EMVA Standard 1288, Release 4.0 Linear: Standard for Characterization of Image
   Sensors and Cameras, European Machine Vision Association, 2021:
   sections 2 (linear model, eq. 1-8), 3 (photon
   transfer, saturation, sensitivity threshold, dynamic range) and 4 (spatial non-uniformity).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from bench_sim.errors import BenchSimError
from bench_sim.metrics.emva_fit import CameraFit, fit_camera
from bench_sim.metrics.photon_transfer import (
    LINEAR_FIT_FRACTION,
    SaturationMethod,
    SaturationPoint,
    as_1d,
    dark_temporal_noise_e,
    mean_var_from_pair,
    saturation_point,
    series_from_pairs,
    spatial_nonuniformity,
    stack_mean_var,
)
from bench_sim.metrics.ptc_table import make_table

__all__ = [
    "SaturationMethod",
    "SaturationPoint",
    "DynamicRange",
    "PhotonTransferResult",
    "mean_var_from_pair",
    "series_from_pairs",
    "dark_temporal_noise_e",
    "saturation_point",
    "snr_curve",
    "photons_at_snr",
    "photons_min_model",
    "dynamic_range_db",
    "dynamic_range_from_series",
    "analyse_photon_transfer",
    "stack_mean_var",
    "spatial_nonuniformity",
    "LINEAR_FIT_FRACTION",
]


def snr_curve(signal: np.ndarray, temporal_std: np.ndarray) -> np.ndarray:
    """``SNR = (mu_y - mu_y.dark) / sigma_y`` (EMVA 1288 R4); ``inf`` where ``sigma_y = 0``."""
    s = np.asarray(signal, dtype=np.float64)
    sd = np.asarray(temporal_std, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(sd > 0, s / np.where(sd > 0, sd, 1.0), np.inf)
    return out


def photons_at_snr(photons: np.ndarray, snr: np.ndarray, target: float = 1.0) -> float:
    """Irradiation where the measured SNR curve first reaches ``target`` (interpolated).

    Between the last level below ``target`` and the first at or above it, the crossing is
    interpolated on log(photons)-log(SNR) (a power law, exact for the shot- and
    read-noise-limited parts of the curve), or linearly when a bracketing value is <= 0 (e.g.
    the dark level, photons = 0).

    Raises
    ------
    BenchSimError
        The SNR never reaches ``target``, or already exceeds it at the darkest level.
    """
    p = as_1d("photons", photons)
    q = np.asarray(snr, dtype=np.float64).ravel()
    if q.size != p.size:
        raise BenchSimError(f"snr: expected {p.size} values, got {q.size}")
    above = np.nonzero(q >= target)[0]
    if above.size == 0:
        raise BenchSimError(f"SNR never reaches {target:g} in the series (max {np.nanmax(q):.3g})")
    i = int(above[0])
    if i == 0:
        raise BenchSimError(
            f"SNR is already {q[0]:.3g} >= {target:g} at the darkest level (photons {p[0]:.6g}); "
            "add darker levels"
        )
    p0, p1, q0, q1 = p[i - 1], p[i], q[i - 1], q[i]
    if p0 > 0 and q0 > 0 and np.isfinite(q1):
        t = (math.log(target) - math.log(q0)) / (math.log(q1) - math.log(q0))
        return float(math.exp(math.log(p0) + t * (math.log(p1) - math.log(p0))))
    if not np.isfinite(q1):
        return float(p1)
    t = (target - q0) / (q1 - q0)
    return float(p0 + t * (p1 - p0))


def photons_min_model(eta: float, k_dn_per_e: float, dark_var_dn: float) -> float:
    """Absolute sensitivity threshold from the linear model (SNR = 1) [photons].

    ``mu_p.min = (sqrt(sigma_y.dark**2 / K**2 + 1/4) + 1/2) / eta`` (EMVA 1288 R4): the
    solution of ``eta mu_p = sqrt(sigma_y.dark**2 / K**2 + eta mu_p)``.
    """
    if eta <= 0 or k_dn_per_e <= 0:
        raise BenchSimError(f"eta = {eta!r}, K = {k_dn_per_e!r}: must be > 0")
    return (math.sqrt(dark_var_dn / k_dn_per_e**2 + 0.25) + 0.5) / eta


def dynamic_range_db(photons_sat: float, photons_min: float) -> float:
    """``DR = 20 lg(mu_p.sat / mu_p.min)`` [dB] (EMVA 1288 R4)."""
    if photons_sat <= 0 or photons_min <= 0:
        raise BenchSimError(
            f"dynamic range: mu_p.sat = {photons_sat!r} and mu_p.min = {photons_min!r} must be > 0"
        )
    return 20.0 * math.log10(photons_sat / photons_min)


@dataclass(frozen=True)
class DynamicRange:
    """Dynamic range of an image type from a photon-transfer series.

    Attributes
    ----------
    photons_sat, photons_min
        ``mu_p.sat`` and ``mu_p.min`` (SNR = 1, measured) in the series' photon unit.
    signal_sat
        Dark-subtracted signal at saturation.
    dr_ratio, dr_db
        ``mu_p.sat / mu_p.min`` and ``20 lg`` of it.
    saturation
        The :class:`SaturationPoint` used.
    snr
        SNR of every level (dark subtracted signal over temporal noise).
    """

    photons_sat: float
    photons_min: float
    signal_sat: float
    dr_ratio: float
    dr_db: float
    saturation: SaturationPoint
    snr: np.ndarray = field(repr=False)


def dynamic_range_from_series(
    photons: np.ndarray,
    mean_signal: np.ndarray,
    temporal_std: np.ndarray,
    *,
    dark_signal: float = 0.0,
    saturation: SaturationMethod = "interpolated",
    responsivity: float | None = None,
) -> DynamicRange:
    """Dynamic range (EMVA 1288 R4 definition) of any image type from a measured series.

    Works on DTDI stage images and on fused HDR images alike: it uses only the irradiation,
    the mean signal and the temporal noise of each level, not a conversion gain.

    Parameters
    ----------
    photons
        Irradiation of each level, strictly increasing (e.g. mean photons per pixel per frame,
        or summed over the frames of a stage: the ratio is unit-free). A dark level
        (photons = 0) may be included.
    mean_signal
        Mean signal of each level (any unit, e.g. DN or stage-``mu2`` DN).
    temporal_std
        Temporal noise of each level, same unit (e.g. ``sqrt`` of :func:`mean_var_from_pair`).
    dark_signal
        Mean dark signal subtracted from ``mean_signal``.
    saturation
        Saturation method (see :func:`saturation_point`); default ``"interpolated"``, located
        between grid levels.
    responsivity
        For ``saturation="extrapolated"``: slope of the dark-subtracted signal versus photons
        (fitted over 0..70 % of saturation when None).

    Returns
    -------
    DynamicRange
        ``mu_p.sat``, ``mu_p.min`` (SNR = 1, interpolated on the measured SNR curve below
        saturation), ``DR`` as a ratio and in dB.
    """
    p = as_1d("photons", photons)
    sig = as_1d("mean_signal", mean_signal, p.size) - float(dark_signal)
    sd = as_1d("temporal_std", temporal_std, p.size)
    if np.any(sd < 0):
        raise BenchSimError("temporal_std: must be >= 0")
    sat = saturation_point(p, sig, sd * sd, saturation, responsivity=responsivity)
    snr = snr_curve(sig, sd)
    below = slice(0, sat.index + 1)
    p_min = photons_at_snr(p[below], snr[below], 1.0)
    return DynamicRange(
        photons_sat=sat.photons,
        photons_min=p_min,
        signal_sat=sat.signal,
        dr_ratio=sat.photons / p_min,
        dr_db=dynamic_range_db(sat.photons, p_min),
        saturation=sat,
        snr=snr,
    )


@dataclass(frozen=True)
class PhotonTransferResult:
    """EMVA 1288 results of one image type (a camera, or one DTDI stage): the one fit
    (:class:`~bench_sim.metrics.emva_fit.CameraFit`: ``K``, QE, the dark noise, the saturation
    capacity at the variance maximum, with standard errors) and the dynamic range of the series
    (its saturation point refined between the levels, :func:`saturation_point`).

    Units: DN, electrons (e-) and photons of the series (for a DTDI stage: photons summed over
    the ``m`` frames of the stage).
    """

    fit: CameraFit
    dark_mean_dn: float
    dark_temporal_noise_dn: float
    photons_sat: float
    photons_min: float
    photons_min_model: float
    dr_db: float
    dr_db_model: float
    snr_max: float
    saturation: SaturationPoint
    snr: np.ndarray = field(repr=False)

    @property
    def k_dn_per_e(self) -> float:
        """``K`` [DN/e-] of the fit."""
        return self.fit.k_dn_per_e

    @property
    def responsivity_dn_per_photon(self) -> float:
        """``R = eta K`` [DN/photon] of the fit."""
        return self.fit.responsivity_dn_per_photon

    @property
    def quantum_efficiency(self) -> float:
        """``eta`` of the fit."""
        return self.fit.quantum_efficiency

    @property
    def dark_temporal_noise_e(self) -> float:
        """``sigma_d`` [e-] of the fit."""
        return self.fit.dark_noise_e

    @property
    def saturation_signal_dn(self) -> float:
        """``mu_y.sat - mu_y.dark`` [DN] at the variance maximum (the fit's, EMVA 1288)."""
        return self.fit.saturation_signal_dn

    @property
    def saturation_capacity_e(self) -> float:
        """``mu_e.sat`` [e-] of the fit."""
        return self.fit.saturation_capacity_e

    def summary(self) -> dict[str, float | int | str]:
        """The scalar results as a JSON-friendly dict (the fit's values and standard errors)."""
        f = self.fit
        return {
            "K_dn_per_e": f.k_dn_per_e,
            "K_se_dn_per_e": f.k_se,
            "responsivity_dn_per_photon": f.responsivity_dn_per_photon,
            "responsivity_se_dn_per_photon": f.responsivity_se,
            "quantum_efficiency": f.quantum_efficiency,
            "quantum_efficiency_se": f.quantum_efficiency_se,
            "dark_mean_dn": self.dark_mean_dn,
            "dark_temporal_noise_dn": self.dark_temporal_noise_dn,
            "dark_temporal_noise_e": f.dark_noise_e,
            "dark_temporal_noise_se_e": f.dark_noise_e_se,
            "saturation_signal_dn": f.saturation_signal_dn,
            "saturation_capacity_e": f.saturation_capacity_e,
            "saturation_capacity_se_e": f.saturation_capacity_e_se,
            "clips_on": f.clips_on,
            "linearity_error_percent": f.linearity_error_percent,
            "chi2_red_k": f.chi2_red_k,
            "photons_sat": self.photons_sat,
            "photons_min": self.photons_min,
            "photons_min_model": self.photons_min_model,
            "dynamic_range_db": self.dr_db,
            "dynamic_range_db_model": self.dr_db_model,
            "snr_max": self.snr_max,
            "saturation_method": self.saturation.method,
            "saturation_level_index": self.saturation.index,
        }


def analyse_photon_transfer(
    photons: np.ndarray,
    mean_dn: np.ndarray,
    var_dn: np.ndarray,
    dark_mean_dn: float,
    dark_var_dn: float,
    *,
    quantization_var_dn2: float = 1.0 / 12.0,
    saturation: SaturationMethod = "interpolated",
    fraction: float = LINEAR_FIT_FRACTION,
    pixels: int | None = None,
    bits: int | None = None,
    exposure_s: float = 1.0,
) -> PhotonTransferResult:
    """Full EMVA 1288 analysis of one series of bright levels plus its dark level: the one fit
    (:func:`bench_sim.metrics.emva_fit.fit_camera`, what ``calibrate`` computes from the same
    table) and the series' dynamic range.

    Parameters
    ----------
    photons
        Irradiation ``mu_p`` of each bright level [photons per pixel], strictly increasing.
    mean_dn, var_dn
        Temporal mean [DN] and variance [DN^2] of each bright level (:func:`mean_var_from_pair`).
    dark_mean_dn, dark_var_dn
        The same for the dark level.
    quantization_var_dn2
        ``sigma_q**2`` removed from the dark variance for ``sigma_d`` (``m/12`` for stage ``m``).
    saturation
        Saturation method of the dynamic range (:func:`saturation_point`).
    fraction
        Upper end of the linear fit range as a fraction of the saturation signal.
    pixels, bits, exposure_s
        Pixels per image (absolute weights), the word's bits and the exposure time [s] of the
        table (:func:`bench_sim.metrics.ptc_table.make_table`).
    """
    p = as_1d("photons", photons)
    mean = as_1d("mean_dn", mean_dn, p.size)
    var = as_1d("var_dn", var_dn, p.size)
    tab = make_table(
        np.full(p.size + 1, float(exposure_s)), photons_per_pixel=np.concatenate([[0.0], p]),
        mean_dn=np.concatenate([[float(dark_mean_dn)], mean]),
        var_dn2=np.concatenate([[float(dark_var_dn)], var]),
        pixels=pixels, bits=bits, source="photon-transfer series",
    )
    fit = fit_camera(tab, fraction=fraction, quantization_var_dn2=quantization_var_dn2)
    k, eta = fit.k_dn_per_e, fit.quantum_efficiency
    if not (k > 0 and eta > 0):
        raise BenchSimError(f"photon transfer: fitted K = {k:.4g}, QE = {eta:.4g} must be > 0")
    # the dark level (photons 0, SNR 0) brackets SNR = 1 if the darkest bright level exceeds it
    dr = dynamic_range_from_series(
        np.concatenate([[0.0], p]),
        np.concatenate([[float(dark_mean_dn)], mean]),
        np.sqrt(np.maximum(np.concatenate([[float(dark_var_dn)], var]), 0.0)),
        dark_signal=dark_mean_dn, saturation=saturation, responsivity=fit.responsivity_dn_per_photon,
    )
    p_min_model = photons_min_model(eta, k, dark_var_dn)
    snr = dr.snr[1:]
    return PhotonTransferResult(
        fit=fit,
        dark_mean_dn=float(dark_mean_dn),
        dark_temporal_noise_dn=math.sqrt(max(float(dark_var_dn), 0.0)),
        photons_sat=dr.photons_sat,
        photons_min=dr.photons_min,
        photons_min_model=p_min_model,
        dr_db=dr.dr_db,
        dr_db_model=dynamic_range_db(dr.photons_sat, p_min_model),
        snr_max=float(np.max(snr[: dr.saturation.index])),
        saturation=dr.saturation,
        snr=snr,
    )
