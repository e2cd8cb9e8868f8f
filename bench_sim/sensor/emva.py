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
from bench_sim.sensor.chain_draw import GenericPlan, expose_generic, needs_generic_path
from bench_sim.sensor.effects.chain import sensor_chain
from bench_sim.sensor.exposure_kernel import electrons_to_dn, joint_draw_dn, joint_quantile
from bench_sim.sensor.fixed_pattern import FixedPattern, draw_fixed_pattern
from bench_sim.sensor.model import QUANTIZATION_VAR_DN2, pixel_mean_var_dn, pixel_saturation_dn
from bench_sim.sensor.sampler import (
    COMBINED_READ_NOISE_MIN_E,
    FULL_WELL_SIGMAS,
    SHOT_NOISE_SWITCH_E,
    SKEWNESS_MAX,
    box_muller_normals,
    shot_and_read_electrons,
    shot_electrons,
)

__all__ = [
    "FixedPattern",
    "ExposurePlan",
    "draw_fixed_pattern",
    "expose",
    "shot_electrons",
    "shot_and_read_electrons",
    "SHOT_NOISE_SWITCH_E",
    "COMBINED_READ_NOISE_MIN_E",
    "FULL_WELL_SIGMAS",
    "SKEWNESS_MAX",
    "pixel_mean_var_dn",
    "pixel_saturation_dn",
    "QUANTIZATION_VAR_DN2",
]

def _readonly(arr: np.ndarray) -> np.ndarray:
    arr = np.ascontiguousarray(arr)
    arr.setflags(write=False)
    return arr


#: Elements per block of :func:`expose`'s loop (whole frames; a block's arrays stay in cache).
_BLOCK_ELEMENTS = 1 << 16


@dataclass(frozen=True)
class ExposurePlan:
    """What :func:`expose` computes once per sensor, fixed pattern and integration time: the
    switches and per-pixel constants, in the working precision ``work`` (float32 with
    quantisation: errors ~1e-4 DN, far below the rounding, and twice as fast; float64 without).
    Make it with :meth:`of` and pass it to every :func:`expose` call of a pass."""

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
    lam_per_photon_max: float  # largest qe_gain [e-/photon]
    dark_e_max: float  # largest dark_e [e-]
    generic: GenericPlan | None = None  # a chain drawn step by step (bench_sim.sensor.chain_draw)

    @classmethod
    def of(cls, sensor: SensorConfig, fixed: FixedPattern, t_int_s: float) -> ExposurePlan:
        """The plan of ``sensor`` with the fixed pattern ``fixed`` (the frames' ``M x N``) and
        frames of ``t_int_s`` seconds."""
        work = np.dtype(np.float32 if sensor.quantization else np.float64)
        sampler = getattr(sensor, "shot_noise_sampler", "hybrid")
        read_e = float(sensor.read_noise_e) if sensor.read_noise else 0.0
        noisy = sensor.shot_noise or sensor.dark_noise
        k = FULL_WELL_SIGMAS  # m + k sqrt(m) = FW
        qe_gain = _readonly((sensor.quantum_efficiency * fixed.prnu_gain).astype(work))
        dark_e = _readonly((fixed.dark_current_e_s * float(t_int_s)).astype(work))
        return cls(
            work=work,
            shot_noise=sensor.shot_noise,
            dark_noise=sensor.dark_noise,
            quantization=sensor.quantization,
            qe_gain=qe_gain,
            dark_e=dark_e,
            offset_dn=_readonly((sensor.black_offset_dn + fixed.column_offset_dn).astype(work)),
            gain=work.type(sensor.conversion_gain_dn_per_e),
            full_well=work.type(sensor.full_well_e),
            top=float(pixel_saturation_dn(sensor)),
            sampler=sampler,
            read_e=read_e,
            noisy=noisy,
            together=sampler == "hybrid" and noisy and read_e >= COMBINED_READ_NOISE_MIN_E,
            near_fw_e=((-k + np.sqrt(k * k + 4.0 * sensor.full_well_e)) / 2.0) ** 2,
            lam_per_photon_max=float(qe_gain.max()) if qe_gain.size else 0.0,
            dark_e_max=float(dark_e.max()) if dark_e.size else 0.0,
            generic=GenericPlan.of(sensor, fixed, t_int_s)
            if needs_generic_path(sensor_chain(sensor), fixed) else None,
        )

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, columns) of the frames the plan serves."""
        return (int(self.qe_gain.shape[0]), int(self.qe_gain.shape[1]))

    @property
    def in_cache(self) -> bool:
        """Whether :func:`expose` takes the in-cache loop of the common case: quantised output,
        shot, dark and read noise drawn together (Poisson mean ``light + dark``, nothing apart)."""
        return self.together and self.shot_noise and self.dark_noise and self.quantization


def _apart(
    plan: ExposurePlan,
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


def _near_full_well(
    plan: ExposurePlan,
    poisson_e: np.ndarray,
    fixed_e: np.ndarray,
    electrons: np.ndarray,
    s_blk: np.ndarray | None,
    rng: np.random.Generator,
) -> None:
    """Redraw, apart (:func:`_apart`), the electrons of the pixels within
    :data:`FULL_WELL_SIGMAS` of the full well, after the block's joint draws; ``s_blk`` (if
    given) is set where their full well was reached (and cleared elsewhere)."""
    if s_blk is not None:
        s_blk[...] = False
    near = (poisson_e + fixed_e) >= plan.near_fw_e
    if near.any():
        s_near = np.empty(int(near.sum()), dtype=bool)
        fixed_near = np.broadcast_to(fixed_e, near.shape)[near]
        electrons[near] = _apart(plan, poisson_e[near], fixed_near, s_near, rng)
        if s_blk is not None:
            s_blk[near] = s_near


def _block_electrons(
    plan: ExposurePlan, ph: np.ndarray, rng: np.random.Generator, s_blk: np.ndarray | None
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
    _near_full_well(plan, poisson_e, fixed_e, electrons, s_blk, rng)
    return electrons


def _expose_in_cache(
    plan: ExposurePlan, frames: np.ndarray, rng: np.random.Generator, out: np.ndarray,
    sat: np.ndarray | None, step: int,
) -> None:
    """:func:`expose`'s loop for :attr:`ExposurePlan.in_cache`, bit-identical to the general
    one (:func:`_block_electrons` with :func:`shot_and_read_electrons`): per block of ``step``
    frames the same draws (its normals, then the pixels near the full well apart), with the
    per-pixel arithmetic in one compiled pass (:mod:`bench_sim.sensor.exposure_kernel`)."""
    rows, cols = plan.shape
    lines = min(step, frames.shape[0]) * rows
    lam_buf = np.empty((lines, cols), plan.work)  # mean electrons, the Poisson mean [e-]
    z_buf = np.empty((lines, cols), plan.work)
    read_var = plan.work.type(plan.read_e * plan.read_e)
    for f0 in range(0, frames.shape[0], step):
        ph = frames[f0 : f0 + step]
        # whether a read may come near the full well: the mean electrons, rounded three times
        # in float32 (photons, product, sum), are at most this bound times (1 + 2**-24)**3
        bound = _photons_max(ph) * plan.lam_per_photon_max + plan.dark_e_max
        maybe_near = bound * (1.0 + 1e-6) >= plan.near_fw_e
        n = ph.shape[0] * rows
        lam, z = lam_buf[:n], z_buf[:n]
        lam_f = lam.reshape(ph.shape)  # a view: (frames, rows, columns)
        np.multiply(ph, plan.qe_gain, out=lam_f, dtype=plan.work)
        lam_f += plan.dark_e
        box_muller_normals(rng, z)  # as shot_and_read_electrons draws them
        dn_blk = out[f0 : f0 + step].reshape(n, cols)
        s_blk = None if sat is None else sat[f0 : f0 + step].reshape(n, cols)
        if maybe_near and bool(lam.max() >= plan.near_fw_e):
            e_blk = joint_quantile(z, lam, lam, lam, np.empty((n, cols), plan.work), read_var)
            _near_full_well(plan, lam, np.zeros((), plan.work), e_blk, s_blk, rng)
            electrons_to_dn(e_blk, plan.gain, plan.offset_dn, plan.top, True, dn_blk, s_blk)
            continue
        if s_blk is not None:
            s_blk[...] = False
        joint_draw_dn(z, lam, read_var, plan.gain, plan.offset_dn, plan.top, dn_blk, s_blk)


def _photons_max(ph: np.ndarray) -> float:
    """The largest mean photons of a block of frames; raises unless all are finite and >= 0."""
    top = float(ph.max())
    if not (ph.min() >= 0.0 and np.isfinite(top)):  # min >= 0 is False for NaN
        raise BenchSimError("photons: must be finite and >= 0 (mean photons per pixel per frame)")
    return top


def _check_photons(p: np.ndarray, fixed: FixedPattern, t_int_s: float) -> None:
    """Check the shapes and the integration time of :func:`expose` (the photons' values are
    checked block by block, :func:`_photons_max`)."""
    if p.ndim < 2 or p.shape[-2:] != fixed.shape:
        raise BenchSimError(
            f"photons shape {p.shape}: the last two axes must be the sensor's (rows, columns) = "
            f"{fixed.shape}"
        )
    if t_int_s < 0 or not np.isfinite(t_int_s):
        raise BenchSimError(f"t_int_s = {t_int_s!r}: must be a finite time >= 0 s")


def expose(
    photons: np.ndarray,
    sensor: SensorConfig,
    fixed: FixedPattern,
    t_int_s: float,
    rng: np.random.Generator,
    *,
    saturated: np.ndarray | None = None,
    plan: ExposurePlan | None = None,
) -> np.ndarray:
    """Expose the sensor: mean photons per pixel per frame -> raw pixel values [DN].

    Implements the EMVA 1288 R4 linear camera model (eq. 1-8) with the saturation and
    non-uniformity effects listed in the module docstring. Vectorised over any number of
    leading (frame) axes; call it on chunks of frames for speed. Works through the frames in
    blocks of whole frames (about 64 k pixels).

    Random draws per block: with ``sensor.shot_noise_sampler = "hybrid"``, read noise of at
    least :data:`COMBINED_READ_NOISE_MIN_E` and shot or dark noise on, shot and read noise come
    together from :func:`shot_and_read_electrons` (one normal per pixel, by Box-Muller in
    float32: :func:`bench_sim.sensor.sampler.box_muller_normals`); then the pixels within
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
    plan
        ``ExposurePlan.of(sensor, fixed, t_int_s)`` of these same arguments, made once for
        many calls (default: made here).

    Returns
    -------
    numpy.ndarray
        Raw pixel values [DN] including the black offset and column offsets, same shape as
        ``photons``: ``uint16`` integers in ``0 .. 2**adc_bits - 1`` with ``quantization`` on,
        ``float64`` in the same range (not rounded) with it off.
    """
    p = np.asarray(photons)
    _check_photons(p, fixed, t_int_s)
    if plan is None:
        plan = ExposurePlan.of(sensor, fixed, t_int_s)
    elif plan.shape != fixed.shape:
        raise BenchSimError(f"plan for {plan.shape} pixels, the frames have {fixed.shape}")
    rows, cols = fixed.shape
    frames = p.reshape(-1, rows, cols)
    out = np.empty(frames.shape, dtype=np.uint16 if sensor.quantization else np.float64)
    sat = None if saturated is None else saturated.reshape(frames.shape)
    step = max(1, _BLOCK_ELEMENTS // (rows * cols))
    if plan.generic is not None:
        expose_generic(plan.generic, frames, rng, out, sat, step)
        return out.reshape(p.shape)
    if plan.in_cache:
        _expose_in_cache(plan, frames, rng, out, sat, step)
        return out.reshape(p.shape)
    for f0 in range(0, frames.shape[0], step):
        s_blk = None if sat is None else sat[f0 : f0 + step]
        _photons_max(frames[f0 : f0 + step])
        dn = _block_electrons(plan, frames[f0 : f0 + step], rng, s_blk)
        electrons_to_dn(dn, plan.gain, plan.offset_dn, plan.top, plan.quantization,
                        out[f0 : f0 + step], s_blk)
    return out.reshape(p.shape)
