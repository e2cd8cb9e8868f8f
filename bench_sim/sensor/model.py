"""Closed forms of the sensor model: one place for every expected value of a pixel and a stage.

The simulation (:func:`bench_sim.sensor.emva.expose`, :mod:`bench_sim.sensor.dtdi`) draws
random numbers; this module gives what they should average to, in the linear range of the
EMVA 1288 model. The photon-transfer measurement, the whole-chain dynamic range, the
inverse-variance merge and the tests import these functions instead of restating them.

Symbols (EMVA 1288 Release 4.0, section 2): ``mu_p`` mean photons per pixel per frame,
``eta`` quantum efficiency, ``K`` conversion gain [DN/e-], ``mu_d = I_d t_int`` dark electrons,
``sigma_d^2 = sigma_read^2 + mu_d`` dark noise [e-^2], ``sigma_q^2 = 1/12`` DN^2,
``b`` black offset [DN]. A DTDI stage ``m`` sums ``m`` independent reads (paper eq. 1-2), is
shifted by a digital pedestal ``P`` (kept in the word, as real DTDI cameras do) and stored in a
``beta``-bit word (``Phi_FS = 2**beta``, paper eq. 4).

References
----------
.. [EMVA] EMVA Standard 1288, Release 4.0 Linear: Standard for Characterization of Image
   Sensors and Cameras, European Machine Vision Association, 2021 (eq. 1-8, section 2;
   absolute sensitivity threshold, section 2.3).
.. [DTDI] An HDR Imaging Method With DTDI Technology for Push-Broom Cameras (the paper this
   package reproduces), eq. 1-4.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from bench_sim.config import BETA_BITS_MAX, BETA_BITS_MIN, word_full_scale_dn, word_top_dn
from bench_sim.errors import BenchSimError

if TYPE_CHECKING:
    from bench_sim.config import BenchConfig, DTDIConfig, SensorConfig

__all__ = [
    "word_dtype",
    "QUANTIZATION_VAR_DN2",
    "check_beta_bits",
    "full_scale_dn",
    "word_clip_dn",
    "pixel_saturation_dn",
    "pixel_saturation_electrons",
    "dark_electrons",
    "dark_noise_e",
    "pixel_mean_var_dn",
    "stage_offset_dn",
    "stage_variance_dn2",
    "stage_mean_var_dn",
    "stage_dark_std_dn",
    "stage_dsnu_dn",
    "stage_prnu",
    "stage_saturation_photons",
    "stage_clips_on_word",
    "photons_at_snr1",
    "stage_snr1_photons",
    "stage_dr_model_db",
    "hdr_dr_model_db",
]

#: Variance of the uniform quantisation error of an ideal ADC, ``sigma_q**2 = 1/12`` DN^2
#: (EMVA 1288 R4, eq. 8).
QUANTIZATION_VAR_DN2 = 1.0 / 12.0


def check_beta_bits(beta_bits: int, name: str = "beta_bits") -> int:
    """Validate an output word length ``beta`` [bits]: an integer in ``1 .. 32``.

    The one validator of ``beta`` (the config's ``dtdi.beta_bits`` uses the same bounds).
    Raises :class:`~bench_sim.errors.BenchSimError` naming ``name``.
    """
    if isinstance(beta_bits, bool) or not isinstance(beta_bits, int | np.integer):
        raise BenchSimError(
            f"{name} = {beta_bits!r}: must be an integer number of bits in {BETA_BITS_MIN}..{BETA_BITS_MAX}"
        )
    if not BETA_BITS_MIN <= int(beta_bits) <= BETA_BITS_MAX:
        raise BenchSimError(f"{name} = {beta_bits}: must lie in {BETA_BITS_MIN}..{BETA_BITS_MAX} bits")
    return int(beta_bits)


def full_scale_dn(beta_bits: int, name: str = "beta_bits") -> int:
    """``Phi_FS = 2**beta`` [DN] (paper eq. 4); the largest stored value is ``Phi_FS - 1``.
    ``beta_bits`` is validated by :func:`check_beta_bits` (errors name ``name``)."""
    return word_full_scale_dn(check_beta_bits(beta_bits, name))


def word_clip_dn(beta_bits: int, name: str = "beta_bits") -> int:
    """Largest value a ``beta``-bit stage word stores: ``2**beta - 1`` [DN]
    (:func:`bench_sim.config.schema.word_top_dn`, ``beta_bits`` checked)."""
    return word_top_dn(check_beta_bits(beta_bits, name))


def word_dtype(beta_bits: int) -> np.dtype:
    """The smallest unsigned integer type that holds a ``beta``-bit stage word: ``uint16`` up to
    16 bits, else ``uint32``."""
    return np.dtype(np.uint16 if check_beta_bits(beta_bits) <= 16 else np.uint32)


def pixel_saturation_dn(sensor: SensorConfig) -> int:
    """Largest raw pixel value: ``2**adc_bits - 1`` [DN]
    (:attr:`bench_sim.config.SensorConfig.pixel_saturation_dn`)."""
    return sensor.pixel_saturation_dn


def pixel_saturation_electrons(sensor: SensorConfig) -> float:
    """Electrons [e-] at which a pixel stops responding: the full well, or the ADC top above
    the black offset, ``(2**adc_bits - 1 - b) / K``, whichever comes first
    (:attr:`bench_sim.config.SensorConfig.pixel_saturation_electrons`)."""
    return sensor.pixel_saturation_electrons


def dark_electrons(sensor: SensorConfig, t_int_s: float) -> float:
    """Mean dark electrons of one read, ``mu_d = I_d t_int`` [e-]
    (:meth:`bench_sim.config.SensorConfig.dark_electrons`)."""
    return sensor.dark_electrons(t_int_s)


def dark_noise_e(sensor: SensorConfig, t_int_s: float) -> float:
    """Dark noise of one read ``sigma_d = sqrt(sigma_read^2 + mu_d)`` [e-] (switched-off sources
    drop out): read noise and the shot noise of the dark current (EMVA 1288 R4, eq. 7)."""
    var = (sensor.read_noise_e**2 if sensor.read_noise else 0.0) + (
        dark_electrons(sensor, t_int_s) if sensor.dark_noise else 0.0
    )
    return math.sqrt(var)


def pixel_mean_var_dn(
    photons: np.ndarray | float, sensor: SensorConfig, t_int_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form mean and temporal variance of a pixel's raw value [DN] (EMVA linear model).

    ``mu_y = K (eta mu_p + mu_d) + b`` (EMVA 1288 R4 eq. 5, dark signal ``K mu_d + b``) and
    ``sigma_y^2 = K^2 (sigma_d^2 + eta mu_p) + sigma_q^2`` (eq. 7). Switched-off sources drop
    out of the variance (``sigma_q^2 = 0`` without quantization). The fixed patterns are averaged
    out (PRNU gain 1, column offset 0, mean dark current); valid only in the linear range (well
    below full well and ``2**adc_bits - 1``, several sigma above 0 DN).

    Parameters
    ----------
    photons
        Mean photons per pixel per frame ``mu_p`` (scalar or array).
    sensor
        Pixel model.
    t_int_s
        Integration time of one frame [s].

    Returns
    -------
    (mean_dn, var_dn2)
        Arrays of the shape of ``photons``: mean [DN] and temporal variance [DN^2].
    """
    p = np.asarray(photons, dtype=np.float64)
    k = sensor.conversion_gain_dn_per_e
    mu_e = sensor.quantum_efficiency * p
    mean = k * (mu_e + dark_electrons(sensor, t_int_s)) + sensor.black_offset_dn
    var_e = dark_noise_e(sensor, t_int_s) ** 2 + (mu_e if sensor.shot_noise else 0.0 * p)
    var = k**2 * var_e + (QUANTIZATION_VAR_DN2 if sensor.quantization else 0.0)
    return mean, np.broadcast_to(var, p.shape).astype(np.float64)


def stage_offset_dn(
    sensor: SensorConfig, dtdi: DTDIConfig, stage: int, pedestal_dn: float | None = None
) -> float:
    """Dark-level offset [DN] a stage-``m`` word carries besides the dark signal: the pedestal
    ``P`` plus, with ``subtract_black`` off, the accumulated black offset ``m b``.

    ``pedestal_dn`` overrides ``dtdi.pedestal_dn``. Consumers (fusion, metrics, reports)
    subtract it to get the stage's signal.
    """
    ped = float(dtdi.pedestal_dn if pedestal_dn is None else pedestal_dn)
    return ped + (0.0 if dtdi.subtract_black else int(stage) * sensor.black_offset_dn)


def stage_variance_dn2(
    stage: int,
    signal_e_per_read: np.ndarray | float,
    *,
    conversion_gain_dn_per_e: float,
    dark_noise_e: float,
    quantization: bool = True,
    shot_noise: bool = True,
) -> np.ndarray:
    """Temporal variance of a stage-``m`` value [DN^2]: ``m`` independent reads, one word rounding.

    ``var_m = m (K^2 (sigma_d^2 + mu_e) + sigma_q^2)`` with the pixel ADC quantising every read
    (``quantization`` on; the word's own rounding of an integer sum adds nothing), else
    ``m K^2 (sigma_d^2 + mu_e) + sigma_q^2`` (only the output word rounds). EMVA 1288 R4 eq. 7
    per read; the reads of a DTDI stage are independent, so their variances add (unlike
    charge-domain TDI, the read noise grows as ``sqrt(m)``).

    Parameters
    ----------
    stage
        Number of summed reads ``m``.
    signal_e_per_read
        Mean signal electrons per read ``mu_e = eta mu_p`` [e-] (negative values count as 0).
    conversion_gain_dn_per_e
        ``K`` [DN/e-].
    dark_noise_e
        ``sigma_d`` per read [e-] (see :func:`dark_noise_e`).
    quantization
        Whether the pixel ADC rounds every read.
    shot_noise
        Whether the signal carries Poisson shot noise (``+ mu_e``).
    """
    mu_e = np.maximum(np.asarray(signal_e_per_read, dtype=np.float64), 0.0)
    m = int(stage)
    var_e = dark_noise_e**2 + (mu_e if shot_noise else 0.0 * mu_e)
    if quantization:
        return m * (conversion_gain_dn_per_e**2 * var_e + QUANTIZATION_VAR_DN2)
    return m * conversion_gain_dn_per_e**2 * var_e + QUANTIZATION_VAR_DN2


def stage_mean_var_dn(
    photons: np.ndarray | float,
    sensor: SensorConfig,
    t_int_s: float,
    stage: int,
    *,
    subtract_black: bool = True,
    pedestal_dn: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form mean [DN] and temporal variance [DN^2] of a stage-``m`` value (linear range).

    ``mean = m (mu_y - b [subtract_black]) + P`` (paper eq. 1-2 over the pixel mean of
    :func:`pixel_mean_var_dn`) and the variance of :func:`stage_variance_dn2`. Valid below pixel
    and word saturation and above 0 DN; fixed patterns averaged out.

    Parameters
    ----------
    photons
        Mean photons per pixel per frame ``mu_p`` (scalar or array).
    sensor
        Pixel model.
    t_int_s
        Integration time of one frame [s].
    stage
        ``m``.
    subtract_black
        Whether the black offset is subtracted from every read before the sum.
    pedestal_dn
        Pedestal ``P`` added to the sum [DN].
    """
    p = np.asarray(photons, dtype=np.float64)
    mean_px, _ = pixel_mean_var_dn(p, sensor, t_int_s)
    m = int(stage)
    mean = m * (mean_px - (sensor.black_offset_dn if subtract_black else 0.0)) + float(pedestal_dn)
    var = stage_variance_dn2(
        m, sensor.quantum_efficiency * p, conversion_gain_dn_per_e=sensor.conversion_gain_dn_per_e,
        dark_noise_e=dark_noise_e(sensor, t_int_s), quantization=sensor.quantization,
        shot_noise=sensor.shot_noise,
    )
    return mean, var


def stage_dsnu_dn(sensor: SensorConfig, t_int_s: float, stage: int) -> float:
    """Spatial spread [DN] of the dark value of stage ``m`` over columns (its DSNU in DN).

    Every line of a DTDI stage sums the same ``m`` pixels of its column, so the stage's fixed
    pattern is a column pattern: the DSNU of ``m`` pixels adds incoherently,
    ``m (K dsnu t)^2``; the column amplifier offset is the same in all ``m`` rows of a column
    and adds coherently, ``(m col)^2``. Switched-off sources drop out. EMVA 1288's DSNU in
    electrons is this divided by ``K``.
    """
    m = int(stage)
    k = sensor.conversion_gain_dn_per_e
    dsnu = m * (k * sensor.dsnu_e_s * t_int_s) ** 2 if sensor.dsnu_enabled else 0.0
    col = (m * sensor.column_offset_dn) ** 2 if sensor.column_fpn else 0.0
    return math.sqrt(dsnu + col)


def stage_prnu(sensor: SensorConfig, stage: int) -> float:
    """Relative spatial spread of the light signal of stage ``m`` over columns (its PRNU): the
    mean gain of ``m`` independent pixels, ``prnu / sqrt(m)`` (0 with PRNU off)."""
    return sensor.prnu / math.sqrt(int(stage)) if sensor.prnu_enabled else 0.0


def stage_dark_std_dn(sensor: SensorConfig, t_int_s: float, stage: int) -> float:
    """Model spread [DN] of the dark value of stage ``m`` over pixels and time.

    ``sigma^2 = var_m(0) + DSNU_m^2``: the temporal dark noise of ``m`` independent reads
    (:func:`stage_variance_dn2` at 0 photons) and the column pattern of :func:`stage_dsnu_dn`.
    """
    temporal = float(stage_mean_var_dn(0.0, sensor, t_int_s, int(stage))[1])
    return math.sqrt(temporal + stage_dsnu_dn(sensor, t_int_s, stage) ** 2)


def stage_saturation_photons(
    sensor: SensorConfig,
    t_int_s: float,
    stage: int,
    *,
    beta_bits: int | None,
    subtract_black: bool = True,
    pedestal_dn: float = 0.0,
) -> float:
    """Photons per pixel per frame [photons] at which the mean of stage ``m`` reaches its clip.

    The smaller of the pixel's clip (:func:`pixel_saturation_electrons`) and the word's,
    ``(2**beta - 1 - P - m b [not subtract_black]) / (m K)`` electrons per read, less the dark
    electrons, divided by ``eta``. This is where the linear response meets the clipped
    plateau; the variance maximum (EMVA 1288's saturation point) lies a few per cent below.
    ``beta_bits = None``: a word that never clips (the pixel's clip alone).
    """
    e_word = (
        math.inf if beta_bits is None
        else _word_electrons_per_read(sensor, stage, beta_bits, subtract_black, pedestal_dn)
    )
    e_sat = min(pixel_saturation_electrons(sensor), e_word) - dark_electrons(sensor, t_int_s)
    return max(e_sat, 1e-6) / sensor.quantum_efficiency


def _word_electrons_per_read(
    sensor: SensorConfig, stage: int, beta_bits: int, subtract_black: bool, pedestal_dn: float
) -> float:
    """Electrons per read at which the stage-``m`` word clips."""
    m = int(stage)
    word = word_clip_dn(beta_bits) - float(pedestal_dn)
    if not subtract_black:
        word -= m * sensor.black_offset_dn
    return word / (m * sensor.conversion_gain_dn_per_e)


def stage_clips_on_word(
    sensor: SensorConfig, stage: int, *, beta_bits: int, subtract_black: bool = True, pedestal_dn: float = 0.0
) -> bool:
    """Whether stage ``m`` saturates on its output word (True) or on the pixel (False): the
    word's clip in electrons per read lies below :func:`pixel_saturation_electrons`."""
    return _word_electrons_per_read(sensor, stage, beta_bits, subtract_black, pedestal_dn) < (
        pixel_saturation_electrons(sensor)
    )


def photons_at_snr1(eta: float, k_dn_per_e: float, dark_var_dn2: float) -> float:
    """Photons [photons] at SNR = 1 in the linear model (EMVA 1288 R4, absolute sensitivity
    threshold): ``mu_p.min = (sqrt(sigma_y.dark^2 / K^2 + 1/4) + 1/2) / eta``, the solution of
    ``eta mu_p = sqrt(sigma_y.dark^2 / K^2 + eta mu_p)``."""
    return (math.sqrt(max(dark_var_dn2, 0.0) / k_dn_per_e**2 + 0.25) + 0.5) / eta


def stage_snr1_photons(sensor: SensorConfig, t_int_s: float, stage: int) -> float:
    """Photons per pixel per frame at which stage ``m`` reaches SNR = 1 (model).

    :func:`photons_at_snr1` for the stage's dark variance (``m`` reads), with the stage's
    photon count ``m mu_p``, per frame.
    """
    m = int(stage)
    dark_var = float(stage_mean_var_dn(0.0, sensor, t_int_s, m)[1])
    return photons_at_snr1(sensor.quantum_efficiency, sensor.conversion_gain_dn_per_e, dark_var) / m


def stage_dr_model_db(cfg: BenchConfig, stage: int, pedestal_dn: float | None = None) -> float:
    """Model dynamic range of stage ``m`` [dB]: ``20 lg(mu_p.sat / mu_p.min)`` with the clip of
    :func:`stage_saturation_photons` and SNR = 1 of :func:`stage_snr1_photons`."""
    t = cfg.timing.t_int_s
    ped = cfg.dtdi.pedestal_dn if pedestal_dn is None else pedestal_dn
    sat = stage_saturation_photons(
        cfg.sensor, t, stage, beta_bits=cfg.dtdi.beta_bits, subtract_black=cfg.dtdi.subtract_black,
        pedestal_dn=ped,
    )
    return 20.0 * math.log10(sat / stage_snr1_photons(cfg.sensor, t, stage))


def hdr_dr_model_db(
    cfg: BenchConfig, mu_low: int, mu_high: int, pedestal_dn: float | None = None,
    beta_bits: int | None | str = "config",
) -> float:
    """Model dynamic range of a fusion of stages ``mu_low < ... < mu_high`` [dB] (eq. 11 and the
    clip-aware rules alike): ``20 lg(mu_p.sat(mu_low) / mu_p.min(mu_high))``, the fused image
    saturating where its lowest stage does (:func:`stage_saturation_photons`) and reaching
    SNR = 1 where its highest stage does (:func:`stage_snr1_photons`), in photons per pixel per
    frame.

    Parameters
    ----------
    cfg
        The bench (sensor, integration time, word, offsets).
    mu_low, mu_high
        The lowest and the highest fused stage.
    pedestal_dn
        The words' pedestal [DN] (default ``dtdi.pedestal_dn``).
    beta_bits
        The output word [bits] (default ``"config"``: ``dtdi.beta_bits``; ``None``: a word that
        never clips, the DR the pixel allows).

    References
    ----------
    The reproduced paper, eq. 11 and 15; EMVA 1288 R4, section 2.3 (SNR = 1) and 3 (saturation).
    """
    t = cfg.timing.t_int_s
    ped = cfg.dtdi.pedestal_dn if pedestal_dn is None else pedestal_dn
    beta = cfg.dtdi.beta_bits if beta_bits == "config" else beta_bits
    sat = stage_saturation_photons(
        cfg.sensor, t, mu_low, beta_bits=beta,  # type: ignore[arg-type]
        subtract_black=cfg.dtdi.subtract_black, pedestal_dn=ped,
    )
    return 20.0 * math.log10(sat / stage_snr1_photons(cfg.sensor, t, mu_high))
