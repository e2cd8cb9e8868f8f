"""EMVA 1288 (Release 4) pixel model: photons per pixel per frame -> raw pixel DN.

The chain for one pixel ``(i, n)`` in one frame, with the symbols of EMVA 1288 R4 (section 2):

1. mean electrons from light ``mu_e = eta * mu_p * g[i, n]``, with ``eta`` the quantum
   efficiency and ``g`` the PRNU gain (fixed pattern, mean 1, rms ``prnu``);
2. mean dark electrons ``mu_d = I_d[i, n] * t_int`` with ``I_d`` the per-pixel dark current
   (fixed pattern: mean ``dark_current_e_s``, rms ``dsnu_e_s`` = DSNU);
3. photon shot noise and dark-current shot noise: the electrons are Poisson with mean
   ``mu_e + mu_d`` (sum of two independent Poisson variables, drawn as one);
4. full-well clip: ``min(electrons, full_well_e)``;
5. read noise: Gaussian, ``read_noise_e`` rms, added in electrons after the clip;
6. conversion gain ``K`` [DN/e-], black offset [DN] and the column offset [DN] of the column
   amplifier (fixed pattern per column, rms ``column_offset_dn``);
7. ADC: round to the nearest integer and clip to ``0 .. 2**adc_bits - 1``.

Fixed patterns (PRNU, DSNU, column offsets) are drawn once per physical sensor by
:func:`draw_fixed_pattern` and passed in to every :func:`expose` call, so they repeat exactly
from frame to frame; the temporal noise (shot, dark shot, read) is drawn fresh in every call.
Every random number comes from the ``numpy.random.Generator`` given by the caller.

The switches of :class:`~bench_sim.config.SensorConfig` turn each source off:
``shot_noise`` (photon shot noise; with ``dark_noise`` also off the electrons are the exact
means), ``dark_noise`` (shot noise of the dark current), ``read_noise``, ``prnu_enabled``,
``dsnu_enabled``, ``column_fpn`` and ``quantization``. With ``quantization`` off the ADC keeps
its range (clip at ``0`` and ``2**adc_bits - 1``) but does not round, and :func:`expose` returns
``float64`` instead of ``uint16``.

The closed forms of this model (expected mean and variance, saturation) live in
:mod:`bench_sim.sensor.model` (re-exported here).

References
----------
EMVA Standard 1288, Release 4.0 Linear, European Machine Vision Association, 2021 (section 2,
eq. 1-8).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bench_sim.config import SensorConfig
from bench_sim.errors import BenchSimError
from bench_sim.sensor.model import QUANTIZATION_VAR_DN2, pixel_mean_var_dn, pixel_saturation_dn

__all__ = [
    "FixedPattern",
    "draw_fixed_pattern",
    "expose",
    "pixel_mean_var_dn",
    "pixel_saturation_dn",
    "QUANTIZATION_VAR_DN2",
]

def _readonly(arr: np.ndarray) -> np.ndarray:
    arr = np.ascontiguousarray(arr)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class FixedPattern:
    """The fixed-pattern properties of one physical sensor (read-only arrays).

    Attributes
    ----------
    prnu_gain
        (M, N) relative gain of each pixel for the light signal (PRNU), mean 1, dimensionless.
    dark_current_e_s
        (M, N) dark current of each pixel [e-/s] (mean ``dark_current_e_s``, rms ``dsnu_e_s``).
    column_offset_dn
        (N,) offset of each column amplifier [DN], mean 0.
    """

    prnu_gain: np.ndarray
    dark_current_e_s: np.ndarray
    column_offset_dn: np.ndarray

    def __post_init__(self) -> None:
        shape = np.shape(self.prnu_gain)
        if len(shape) != 2:
            raise ValueError(f"prnu_gain must be 2-D (rows, columns), got shape {shape}")
        if np.shape(self.dark_current_e_s) != shape:
            raise ValueError(
                f"dark_current_e_s shape {np.shape(self.dark_current_e_s)} != prnu_gain shape {shape}"
            )
        if np.shape(self.column_offset_dn) != (shape[1],):
            raise ValueError(
                f"column_offset_dn shape {np.shape(self.column_offset_dn)} != ({shape[1]},)"
            )
        object.__setattr__(self, "prnu_gain", _readonly(np.asarray(self.prnu_gain, np.float64)))
        object.__setattr__(
            self, "dark_current_e_s", _readonly(np.asarray(self.dark_current_e_s, np.float64))
        )
        object.__setattr__(
            self, "column_offset_dn", _readonly(np.asarray(self.column_offset_dn, np.float64))
        )

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, columns) of the sensor."""
        return (int(self.prnu_gain.shape[0]), int(self.prnu_gain.shape[1]))

    def window(self, rows: int | None = None, columns: int | None = None) -> FixedPattern:
        """The fixed pattern of the top-left ``rows`` x ``columns`` pixels (a region of interest)."""
        r = self.shape[0] if rows is None else rows
        c = self.shape[1] if columns is None else columns
        if not (1 <= r <= self.shape[0] and 1 <= c <= self.shape[1]):
            raise ValueError(f"window {r} x {c} outside the sensor {self.shape[0]} x {self.shape[1]}")
        return FixedPattern(
            prnu_gain=self.prnu_gain[:r, :c],
            dark_current_e_s=self.dark_current_e_s[:r, :c],
            column_offset_dn=self.column_offset_dn[:c],
        )


def draw_fixed_pattern(sensor: SensorConfig, rng: np.random.Generator) -> FixedPattern:
    """Draw the fixed patterns of one physical sensor of ``sensor.rows`` x ``sensor.columns``.

    The three patterns are always drawn, in the order PRNU, DSNU, column offsets, each from
    standard normal numbers, so switching one of them off does not change the others.

    * PRNU gain ``g = max(1 + prnu * z, 0)`` (EMVA 1288 R4 section 2: the spatial standard
      deviation of the photo-response is ``prnu * mu``); ``1`` when ``prnu_enabled`` is off.
    * dark current ``I_d = max(dark_current_e_s + dsnu_e_s * z, 0)`` [e-/s];
      ``dark_current_e_s`` everywhere when ``dsnu_enabled`` is off.
    * column offsets ``column_offset_dn * z`` [DN]; ``0`` when ``column_fpn`` is off.

    Parameters
    ----------
    sensor
        Sensor geometry and pixel model.
    rng
        The run's random generator.
    """
    shape = (sensor.rows, sensor.columns)
    z_prnu = rng.standard_normal(shape)
    z_dsnu = rng.standard_normal(shape)
    z_col = rng.standard_normal(sensor.columns)
    if sensor.prnu_enabled:
        gain = np.maximum(1.0 + sensor.prnu * z_prnu, 0.0)
    else:
        gain = np.ones(shape)
    if sensor.dsnu_enabled:
        dark = np.maximum(sensor.dark_current_e_s + sensor.dsnu_e_s * z_dsnu, 0.0)
    else:
        dark = np.full(shape, float(sensor.dark_current_e_s))
    col = sensor.column_offset_dn * z_col if sensor.column_fpn else np.zeros(sensor.columns)
    return FixedPattern(prnu_gain=gain, dark_current_e_s=dark, column_offset_dn=col)


def expose(
    photons: np.ndarray,
    sensor: SensorConfig,
    fixed: FixedPattern,
    t_int_s: float,
    rng: np.random.Generator,
    *,
    saturated: np.ndarray | None = None,
) -> np.ndarray:
    """Expose the sensor: mean photons per pixel per frame -> raw pixel values [DN].

    Implements the EMVA 1288 R4 linear camera model (eq. 1-8) with the saturation and
    non-uniformity effects listed in the module docstring. Vectorised over any number of
    leading (frame) axes; call it on chunks of frames for speed.

    Parameters
    ----------
    photons
        (..., M, N) mean number of photons reaching each pixel in one frame (``mu_p``), >= 0.
        ``(M, N)`` must equal ``fixed.shape`` (use :meth:`FixedPattern.window` for a region of
        interest).
    sensor
        Pixel model and noise switches.
    fixed
        The sensor's fixed patterns (from :func:`draw_fixed_pattern`).
    t_int_s
        Integration time of one frame [s] (dark current accumulates over it).
    rng
        Random generator for the temporal noise of this call.
    saturated
        Optional boolean array of ``photons``' shape, filled with ``True`` where the pixel hit
        its full well or the ADC's top value ``2**adc_bits - 1`` (where the linear model's mean
        no longer holds).

    Returns
    -------
    numpy.ndarray
        Raw pixel values [DN] including the black offset and column offsets, same shape as
        ``photons``: ``uint16`` integers in ``0 .. 2**adc_bits - 1`` with ``quantization`` on,
        ``float64`` in the same range (not rounded) with it off.
    """
    p = np.asarray(photons, dtype=np.float64)
    if p.ndim < 2 or p.shape[-2:] != fixed.shape:
        raise BenchSimError(
            f"photons shape {p.shape}: the last two axes must be the sensor's (rows, columns) = "
            f"{fixed.shape}"
        )
    if t_int_s < 0 or not np.isfinite(t_int_s):
        raise BenchSimError(f"t_int_s = {t_int_s!r}: must be a finite time >= 0 s")
    if p.size and not (np.isfinite(p).all() and p.min() >= 0.0):
        raise BenchSimError("photons: must be finite and >= 0 (mean photons per pixel per frame)")

    light_e = p * (sensor.quantum_efficiency * fixed.prnu_gain)
    dark_e = fixed.dark_current_e_s * float(t_int_s)
    if sensor.shot_noise and sensor.dark_noise:
        electrons = rng.poisson(light_e + dark_e).astype(np.float64)
    elif sensor.shot_noise:
        electrons = rng.poisson(light_e).astype(np.float64)
        electrons += dark_e
    elif sensor.dark_noise:
        electrons = rng.poisson(np.broadcast_to(dark_e, p.shape)).astype(np.float64)
        electrons += light_e
    else:
        electrons = light_e + dark_e
    if saturated is not None:
        np.greater_equal(electrons, sensor.full_well_e, out=saturated)
    np.minimum(electrons, sensor.full_well_e, out=electrons)
    if sensor.read_noise and sensor.read_noise_e > 0:
        electrons += sensor.read_noise_e * rng.standard_normal(p.shape, dtype=np.float32)

    dn = electrons
    dn *= sensor.conversion_gain_dn_per_e
    dn += sensor.black_offset_dn + fixed.column_offset_dn
    top = float(pixel_saturation_dn(sensor))
    if saturated is not None:
        saturated |= dn >= top - (0.5 if sensor.quantization else 0.0)
    if sensor.quantization:
        np.rint(dn, out=dn)
        np.clip(dn, 0.0, top, out=dn)
        return dn.astype(np.uint16)
    np.clip(dn, 0.0, top, out=dn)
    return dn
