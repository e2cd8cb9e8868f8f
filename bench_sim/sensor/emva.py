"""EMVA 1288 (Release 4) pixel model: photons per pixel per frame -> raw pixel DN.

The chain for one pixel ``(i, n)`` in one frame, with the symbols of EMVA 1288 R4 (section 2):

1. mean electrons from light ``mu_e = eta * mu_p * g[i, n]``, with ``eta`` the quantum
   efficiency and ``g`` the PRNU gain (fixed pattern, mean 1, rms ``prnu``);
2. mean dark electrons ``mu_d = I_d[i, n] * t_int`` with ``I_d`` the per-pixel dark current
   (fixed pattern: mean ``dark_current_e_s``, rms ``dsnu_e_s`` = DSNU);
3. photon shot noise and dark-current shot noise: the electrons are Poisson with mean
   ``mu_e + mu_d`` (sum of two independent Poisson variables, drawn as one; exactly, or with
   the faster ``hybrid`` sampler of :func:`shot_electrons`, ``sensor.shot_noise_sampler``);
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
from typing import Any

import numpy as np

from bench_sim.config import SensorConfig
from bench_sim.errors import BenchSimError
from bench_sim.sensor.model import QUANTIZATION_VAR_DN2, pixel_mean_var_dn, pixel_saturation_dn

__all__ = [
    "FixedPattern",
    "draw_fixed_pattern",
    "expose",
    "shot_electrons",
    "shot_and_read_electrons",
    "SHOT_NOISE_SWITCH_E",
    "COMBINED_READ_NOISE_MIN_E",
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


#: Mean electron count from which ``shot_noise_sampler = "hybrid"`` draws shot noise from the
#: rounded Cornish-Fisher normal approximation instead of numpy's exact Poisson sampler.
SHOT_NOISE_SWITCH_E = 30.0
#: Largest skewness of shot + read noise drawn as one normal approximation (``"hybrid"``)
SKEWNESS_MAX = 0.05
#: Read noise [e- rms] from which ``"hybrid"`` draws shot and read noise together: the skewness
#: ``mu / (mu + sigma^2)**1.5`` of Poisson(mu) + N(0, sigma^2) peaks at ``2 / (3 sqrt(3) sigma)``
#: (at ``mu = 2 sigma^2``), at most :data:`SKEWNESS_MAX` from here on.
COMBINED_READ_NOISE_MIN_E = 2.0 / (3.0 * np.sqrt(3.0) * SKEWNESS_MAX)
#: Pixels whose mean electrons come within this many standard deviations of the full well get
#: their shot noise drawn apart (its clip at the full well comes before the read noise).
FULL_WELL_SIGMAS = 8.0
#: Elements per block of :func:`expose`'s loop (whole frames; a block's arrays stay in cache).
_BLOCK_ELEMENTS = 1 << 16


def _cornish_fisher(
    z: np.ndarray, mean: np.ndarray, var: np.ndarray, k3: np.ndarray, k4: np.ndarray
) -> np.ndarray:
    """Third-order Cornish-Fisher quantile of a distribution with the given mean, variance and
    third and fourth cumulants at the standard normal quantile ``z``::

        x = mean + s z + a (z^2 - 1) / 6 + b (z^3 - 3 z) / 24 - c (2 z^3 - 5 z) / 36

    with ``s = sqrt(var)``, ``a = s gamma_1 = k3 / var``, ``b = s gamma_2 = k4 / (var s)``,
    ``c = s gamma_1^2 = a^2 / s``; evaluated in Horner form in ``z``'s dtype."""
    s = np.sqrt(var)
    a = k3 / var
    b = k4 / (var * s)
    c = a * a / s
    c3 = b / 24 - c / 18
    x = z * c3
    x += a / 6
    x *= z
    x += s - b / 8 + c * (5 / 36)
    x *= z
    x += mean - a / 6
    return x


def shot_electrons(mean_e: np.ndarray, rng: np.random.Generator, sampler: str = "hybrid") -> np.ndarray:
    """Poisson-distributed electron counts of mean ``mean_e`` (an array of integers in
    ``mean_e``'s float dtype).

    ``sampler = "poisson"``: numpy's exact Poisson sampler. ``"hybrid"``: exact below
    :data:`SHOT_NOISE_SWITCH_E` mean electrons; above, one standard normal ``z`` per pixel
    through the third-order Cornish-Fisher expansion of the Poisson quantile (cumulants
    ``kappa_2 = kappa_3 = kappa_4 = lam``), rounded to the nearest count -- the continuity
    correction of a lattice distribution -- with Sheppard's correction: the expansion is taken
    at variance ``lam - 1/12`` so that the rounded counts have variance ``lam``::

        n = rint(CF(z; mean lam, variance lam - 1/12, kappa_3 = kappa_4 = lam))

    This is the normal approximation of sensor simulators (exact Poisson for small means, a
    continuity-corrected normal above) with the skewness ``1/sqrt(lam)`` and kurtosis terms
    added, which a plain rounded normal lacks (a large sample detects that even at thousands of
    electrons). The draws of one call: all normals first, then the exact Poisson counts of the
    pixels below the switch-over.

    References
    ----------
    E. A. Cornish, R. A. Fisher, "Moments and cumulants in the specification of distributions",
    Revue de l'Institut International de Statistique 5 (1937) 307-320.
    W. F. Sheppard, "On the calculation of the most probable values of frequency-constants, for
    data arranged according to equidistant divisions of a scale", Proc. London Math. Soc. 29
    (1898) 353-380.
    """
    lam = np.asarray(mean_e)
    dtype = lam.dtype if lam.dtype in (np.float32, np.float64) else np.dtype(np.float64)
    lam = lam.astype(dtype, copy=False)
    if sampler == "poisson":
        return rng.poisson(lam).astype(dtype)
    if sampler != "hybrid":
        raise BenchSimError(f"sensor.shot_noise_sampler = {sampler!r}: allowed 'hybrid' or 'poisson'")
    z = rng.standard_normal(lam.shape, dtype=dtype)
    big = np.maximum(lam, dtype.type(SHOT_NOISE_SWITCH_E))  # the normal branch serves big means only
    n = _cornish_fisher(z, big, big - dtype.type(1 / 12), big, big)
    np.rint(n, out=n)
    np.maximum(n, 0, out=n)
    low = lam < SHOT_NOISE_SWITCH_E
    if low.any():
        n[low] = rng.poisson(lam[low])
    return n


def shot_and_read_electrons(
    mean_e: np.ndarray, deterministic_e: np.ndarray | float, read_noise_e: float, rng: np.random.Generator
) -> np.ndarray:
    """Electrons after shot and read noise, drawn together: ``d + Poisson(mu) + N(0, sigma^2)``
    from one standard normal per pixel through its third-order Cornish-Fisher expansion
    (cumulants ``kappa_2 = mu + sigma^2``, ``kappa_3 = kappa_4 = mu``).

    For ``sigma >=`` :data:`COMBINED_READ_NOISE_MIN_E` the sum's skewness is at most
    :data:`SKEWNESS_MAX` at every ``mu``, so the expansion's error terms (order ``gamma^3``) are
    of order 1e-4, and the electron lattice is invisible under the read noise (its ripple on the
    sum's density is ``~2 exp(-2 pi^2 sigma^2)``). The full-well clip between shot and read noise
    is not applied: callers use this only where the full well is more than
    :data:`FULL_WELL_SIGMAS` standard deviations away.

    Parameters
    ----------
    mean_e
        ``mu``: mean electrons of the Poisson part (float32 or float64 array).
    deterministic_e
        ``d``: electrons without noise (a light or dark signal whose noise is switched off).
    read_noise_e
        ``sigma`` [e- rms].
    """
    lam = np.asarray(mean_e)
    z = rng.standard_normal(lam.shape, dtype=lam.dtype)
    var = lam + lam.dtype.type(read_noise_e * read_noise_e)
    return _cornish_fisher(z, lam + deterministic_e, var, lam, lam)


@dataclass(frozen=True)
class _ExposurePlan:
    """What :func:`expose` computes once per call: the switches and per-pixel constants, in the
    working precision ``work`` (float32 with quantisation: errors ~1e-4 DN, far below the
    rounding, and twice as fast; float64 without)."""

    work: np.dtype
    shot_noise: bool
    dark_noise: bool
    quantization: bool
    qe_gain: np.ndarray  # QE times PRNU gain [e-/photon]
    dark_e: np.ndarray  # dark electrons per frame [e-]
    offset_dn: np.ndarray  # black offset plus column offsets [DN]
    gain: Any  # conversion gain K [DN/e-], a scalar of dtype work
    full_well: Any  # [e-], a scalar of dtype work
    top: float  # largest raw value [DN]
    sampler: str
    read_e: float  # read noise [e-] (0: off)
    noisy: bool  # shot or dark noise on
    together: bool  # shot and read noise drawn together (shot_and_read_electrons)
    near_fw_e: float  # mean electrons from which the full well is within FULL_WELL_SIGMAS

    @classmethod
    def of(cls, sensor: SensorConfig, fixed: FixedPattern, t_int_s: float) -> _ExposurePlan:
        work = np.dtype(np.float32 if sensor.quantization else np.float64)
        sampler = getattr(sensor, "shot_noise_sampler", "hybrid")
        read_e = float(sensor.read_noise_e) if sensor.read_noise else 0.0
        noisy = sensor.shot_noise or sensor.dark_noise
        k = FULL_WELL_SIGMAS  # m + k sqrt(m) = FW
        return cls(
            work=work,
            shot_noise=sensor.shot_noise,
            dark_noise=sensor.dark_noise,
            quantization=sensor.quantization,
            qe_gain=(sensor.quantum_efficiency * fixed.prnu_gain).astype(work),
            dark_e=(fixed.dark_current_e_s * float(t_int_s)).astype(work),
            offset_dn=(sensor.black_offset_dn + fixed.column_offset_dn).astype(work),
            gain=work.type(sensor.conversion_gain_dn_per_e),
            full_well=work.type(sensor.full_well_e),
            top=float(pixel_saturation_dn(sensor)),
            sampler=sampler,
            read_e=read_e,
            noisy=noisy,
            together=sampler == "hybrid" and noisy and read_e >= COMBINED_READ_NOISE_MIN_E,
            near_fw_e=((-k + np.sqrt(k * k + 4.0 * sensor.full_well_e)) / 2.0) ** 2,
        )


def _apart(
    plan: _ExposurePlan,
    poisson_e: np.ndarray,
    fixed_e: np.ndarray,
    s_out: np.ndarray | None,
    rng: np.random.Generator,
) -> np.ndarray:
    """Shot noise, full-well clip, then read noise [e-]."""
    electrons = shot_electrons(poisson_e, rng, plan.sampler) if plan.noisy else poisson_e.astype(plan.work)
    electrons += fixed_e
    if s_out is not None:
        np.greater_equal(electrons, plan.full_well, out=s_out)
    np.minimum(electrons, plan.full_well, out=electrons)
    if plan.read_e > 0:
        noise = rng.standard_normal(electrons.shape, dtype=np.float32)
        noise *= np.float32(plan.read_e)
        electrons += noise
    return electrons


def _block_electrons(
    plan: _ExposurePlan, ph: np.ndarray, rng: np.random.Generator, s_blk: np.ndarray | None
) -> np.ndarray:
    """Electrons [e-] of a block of frames of mean photons ``ph``, with their temporal noise;
    ``s_blk`` (if given) is set where the full well was reached."""
    light_e = np.multiply(ph, plan.qe_gain, dtype=plan.work)
    # the Poisson part and the part without noise
    if plan.shot_noise and plan.dark_noise:
        light_e += plan.dark_e
        poisson_e, fixed_e = light_e, np.zeros((), plan.work)
    elif plan.shot_noise:
        poisson_e, fixed_e = light_e, np.broadcast_to(plan.dark_e, ph.shape)
    elif plan.dark_noise:
        poisson_e, fixed_e = np.broadcast_to(plan.dark_e, ph.shape), light_e
    else:
        light_e += plan.dark_e
        poisson_e, fixed_e = light_e, np.zeros((), plan.work)
    if not plan.together:
        return _apart(plan, poisson_e, fixed_e, s_blk, rng)
    electrons = shot_and_read_electrons(poisson_e, fixed_e, plan.read_e, rng)
    if s_blk is not None:
        s_blk[...] = False
    near = (poisson_e + fixed_e) >= plan.near_fw_e
    if near.any():
        s_near = np.empty(int(near.sum()), dtype=bool)
        fixed_near = np.broadcast_to(fixed_e, near.shape)[near]
        electrons[near] = _apart(plan, poisson_e[near], fixed_near, s_near, rng)
        if s_blk is not None:
            s_blk[near] = s_near
    return electrons


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
    leading (frame) axes; call it on chunks of frames for speed. Works through the frames in
    blocks of whole frames (about 64 k pixels).

    Random draws per block: with ``sensor.shot_noise_sampler = "hybrid"``, read noise of at
    least :data:`COMBINED_READ_NOISE_MIN_E` and shot or dark noise on, shot and read noise come
    together from :func:`shot_and_read_electrons` (one normal per pixel); then the pixels within
    :data:`FULL_WELL_SIGMAS` of the full well draw theirs apart. Otherwise: the shot noise
    (:func:`shot_electrons`), the full-well clip, then the read noise (a normal per pixel).

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
    p = np.asarray(photons)
    if p.ndim < 2 or p.shape[-2:] != fixed.shape:
        raise BenchSimError(
            f"photons shape {p.shape}: the last two axes must be the sensor's (rows, columns) = "
            f"{fixed.shape}"
        )
    if t_int_s < 0 or not np.isfinite(t_int_s):
        raise BenchSimError(f"t_int_s = {t_int_s!r}: must be a finite time >= 0 s")
    if p.size and not (np.isfinite(p).all() and p.min() >= 0.0):
        raise BenchSimError("photons: must be finite and >= 0 (mean photons per pixel per frame)")

    rows, cols = fixed.shape
    frames = p.reshape(-1, rows, cols)
    out = np.empty(frames.shape, dtype=np.uint16 if sensor.quantization else np.float64)
    sat = None if saturated is None else saturated.reshape(frames.shape)
    plan = _ExposurePlan.of(sensor, fixed, t_int_s)
    step = max(1, _BLOCK_ELEMENTS // (rows * cols))
    for f0 in range(0, frames.shape[0], step):
        s_blk = None if sat is None else sat[f0 : f0 + step]
        dn = _block_electrons(plan, frames[f0 : f0 + step], rng, s_blk)
        dn *= plan.gain
        dn += plan.offset_dn
        if s_blk is not None:
            s_blk |= dn >= plan.top - (0.5 if plan.quantization else 0.0)
        if plan.quantization:
            np.rint(dn, out=dn)
        np.clip(dn, 0, plan.top, out=dn)
        out[f0 : f0 + step] = dn
    return out.reshape(p.shape)
