"""Where a pixel and a DTDI stage saturate in EMVA 1288's sense: the maximum of the temporal
variance, predicted in closed form from the sensor model.

:func:`bench_sim.sensor.model.stage_saturation_photons` gives the *clip point*, where the linear
response meets the clipped plateau. EMVA 1288 defines the saturation point as the irradiation
of the **maximum of the temporal variance** (what ``ptc`` and the whole-chain DR of
``reproduce`` measure), a few per cent below the clip: as the mean approaches the clip, the
clip cuts off the upper tail of the value's distribution and the variance collapses. This
module predicts that maximum from the model's clipped normal distribution:

* a stage that clips on its output word: the sum of ``m`` reads, normal with the mean and
  variance of :func:`bench_sim.sensor.model.stage_mean_var_dn`, clipped at the word's top;
* a pixel that clips on its full well: the electrons (shot noise, variance = mean) clipped at
  ``FW``, the read noise added after the clip; a stage sums ``m`` such reads;
* a pixel that clips on its ADC: the read value (shot and read noise) clipped at
  ``2**adc_bits - 1``.

The variance of a clipped normal comes from its raw moments
(:func:`bench_sim.sensor.expectation.clipped_normal_moments`); the maximum is located on a
fine grid of irradiations and refined by a parabola. The normal law is accurate where the
saturation signal holds many electrons (hundreds or more), as it does in every camera
EMVA 1288 is applied to.

:func:`full_well_for_saturation` inverts the full-well case: the clip ``FW`` whose variance
maximum lies at a given EMVA saturation capacity ``mu_e.sat`` (for turning published EMVA
results into a sensor section).

References
----------
.. [EMVA] EMVA Standard 1288, Release 4.0 Linear, European Machine Vision Association, 2021:
   section 2 (linear model), section 3 (saturation point: maximum of the temporal variance).
.. [JK] N. L. Johnson, S. Kotz, N. Balakrishnan, *Continuous Univariate Distributions*, vol. 1,
   2nd ed., Wiley, 1994, section 13.10 (truncated and censored normal distributions).
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np

from bench_sim.config import SensorConfig
from bench_sim.errors import BenchSimError
from bench_sim.sensor.expectation import clipped_normal_moments
from bench_sim.sensor.model import (
    QUANTIZATION_VAR_DN2,
    dark_electrons,
    dark_noise_e,
    stage_clips_on_word,
    stage_mean_var_dn,
    stage_saturation_photons,
    word_clip_dn,
)

__all__ = [
    "ClipKind",
    "stage_clip_kind",
    "stage_variance_dn2_clipped",
    "stage_variance_maximum_photons",
    "full_well_for_saturation",
]

ClipKind = Literal["word", "full_well", "adc"]
#: Points of the grid on which the variance maximum is searched (refined by a parabola).
_GRID = 4001


def _clipped_var(mu: np.ndarray, sd: np.ndarray, hi: float) -> np.ndarray:
    """Variance of ``min(Y, hi)``, ``Y ~ N(mu, sd^2)`` (no lower clip: the signal is far above 0)."""
    sd = np.broadcast_to(np.asarray(sd, dtype=np.float64), mu.shape)
    lo = mu - 40.0 * np.maximum(sd, 1.0)  # far below: no lower clip
    m1, m2, _ = clipped_normal_moments(mu, sd, lo, hi)
    return np.maximum(m2 - m1 * m1, 0.0)


def stage_clip_kind(
    sensor: SensorConfig, stage: int, *, beta_bits: int, subtract_black: bool = True, pedestal_dn: float = 0.0
) -> ClipKind:
    """What clips stage ``m`` first: its output ``word``, the pixel's ``full_well`` or its ``adc``."""
    if stage_clips_on_word(
        sensor, stage, beta_bits=beta_bits, subtract_black=subtract_black, pedestal_dn=pedestal_dn
    ):
        return "word"
    adc_e = (sensor.pixel_saturation_dn - sensor.black_offset_dn) / sensor.conversion_gain_dn_per_e
    return "full_well" if sensor.full_well_e <= adc_e else "adc"


def stage_variance_dn2_clipped(
    photons: np.ndarray,
    sensor: SensorConfig,
    t_int_s: float,
    stage: int,
    *,
    beta_bits: int,
    subtract_black: bool = True,
    pedestal_dn: float = 0.0,
) -> np.ndarray:
    """Temporal variance [DN^2] of a stage-``m`` value near its clip (clipped normal, see module doc).

    Parameters
    ----------
    photons
        Mean photons per pixel per frame ``mu_p``.
    sensor, t_int_s, stage
        Pixel model, integration time of one frame [s], ``m``.
    beta_bits, subtract_black, pedestal_dn
        The DTDI word: bits, whether the black offset is subtracted before the sum, pedestal [DN].
    """
    p = np.asarray(photons, dtype=np.float64)
    m = int(stage)
    kind = stage_clip_kind(
        sensor, m, beta_bits=beta_bits, subtract_black=subtract_black, pedestal_dn=pedestal_dn
    )
    k = sensor.conversion_gain_dn_per_e
    q = QUANTIZATION_VAR_DN2 if sensor.quantization else 0.0
    mu_e = sensor.quantum_efficiency * p + dark_electrons(sensor, t_int_s)
    shot_e = np.maximum(mu_e, 0.0) if sensor.shot_noise else np.zeros_like(p)
    dark_shot_e = dark_electrons(sensor, t_int_s) if sensor.dark_noise else 0.0
    read_e2 = dark_noise_e(sensor, t_int_s) ** 2 - dark_shot_e
    if kind == "word":
        mean, var = stage_mean_var_dn(
            p, sensor, t_int_s, m, subtract_black=subtract_black, pedestal_dn=pedestal_dn
        )
        return _clipped_var(mean, np.sqrt(var), float(word_clip_dn(beta_bits)))
    if kind == "full_well":
        v_e = _clipped_var(mu_e, np.sqrt(shot_e), float(sensor.full_well_e))
        return m * (k * k * (v_e + read_e2) + q)
    mean_dn = k * mu_e + sensor.black_offset_dn
    v_dn = _clipped_var(mean_dn, k * np.sqrt(shot_e + read_e2), float(sensor.pixel_saturation_dn))
    return m * (v_dn + q)


def _argmax_refined(x: np.ndarray, y: np.ndarray) -> float:
    i = int(np.argmax(y))
    if i == 0 or i == x.size - 1:
        return float(x[i])
    x0, x1, x2 = x[i - 1 : i + 2]
    y0, y1, y2 = y[i - 1 : i + 2]
    den = y0 - 2 * y1 + y2
    if den >= 0:
        return float(x1)
    return float(x1 + 0.5 * (x1 - x0) * (y0 - y2) / den)


def stage_variance_maximum_photons(
    sensor: SensorConfig,
    t_int_s: float,
    stage: int,
    *,
    beta_bits: int,
    subtract_black: bool = True,
    pedestal_dn: float = 0.0,
) -> float:
    """EMVA 1288 saturation point of stage ``m`` predicted by the model [photons per pixel per
    frame]: the irradiation of the maximum of :func:`stage_variance_dn2_clipped`.

    Searched between 70 % and 105 % of the clip point
    (:func:`bench_sim.sensor.model.stage_saturation_photons`).
    """
    clip = stage_saturation_photons(
        sensor, t_int_s, stage, beta_bits=beta_bits, subtract_black=subtract_black, pedestal_dn=pedestal_dn
    )
    p = np.linspace(0.7 * clip, 1.05 * clip, _GRID)
    var = stage_variance_dn2_clipped(
        p, sensor, t_int_s, stage, beta_bits=beta_bits, subtract_black=subtract_black, pedestal_dn=pedestal_dn
    )
    return _argmax_refined(p, var)


def full_well_for_saturation(saturation_capacity_e: float, dark_e: float = 0.0) -> float:
    """Full well ``FW`` [e-] whose variance maximum lies at the EMVA saturation capacity.

    The electrons of a read, normal with variance = mean (shot noise of light and dark
    current), are clipped at ``FW``; the variance of the clipped value peaks at a mean light
    signal ``mu_e.sat`` somewhat below ``FW``. Solved by fixed-point iteration on ``FW``.

    Parameters
    ----------
    saturation_capacity_e
        ``mu_e.sat = eta mu_p.sat`` [e-] (EMVA 1288 R4), light electrons at the variance maximum.
    dark_e
        Dark electrons of the read ``mu_d`` [e-] (added to the light electrons before the clip).
    """
    target = float(saturation_capacity_e) + float(dark_e)
    if not (math.isfinite(target) and target > 1.0):
        raise BenchSimError(f"saturation capacity {saturation_capacity_e!r} e-: must be a number > 1")
    fw = target + 2.0 * math.sqrt(target)
    for _ in range(30):
        mu = np.linspace(fw - 8.0 * math.sqrt(fw), fw, _GRID)
        peak = _argmax_refined(mu, _clipped_var(mu, np.sqrt(mu), fw))
        new = fw + (target - peak)
        if abs(new - fw) < 1e-9 * fw:
            break
        fw = new
    return float(fw)
