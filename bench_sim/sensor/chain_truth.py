"""The exact truth of a read under a chain of effects: each read's cumulants and the linear truth.

The default chain's reads are :func:`bench_sim.sensor.expectation.read_cumulants` of the linear
model (Poisson light and dark electrons, the full-well clip, Gaussian read noise, the ADC's clips).
An effect's :class:`~bench_sim.sensor.effects.base.ReadLaw` changes that as follows, exactly
(to the accuracy of the quadrature):

- extra Gaussian variance (row noise): the read noise of the read model grows to
  ``sqrt(sigma_r^2 + var / K^2)`` (the reads a stage sums come from different rows and frames,
  so their row-noise draws are independent);
- monotone responses of the charge: every read is integrated through them
  (:func:`~bench_sim.sensor.expectation.read_cumulants` with ``response``);
- telegraph pixels: the read is the mixture ``(1 - p) X + p (X + A)``; its raw moments are the
  mixture of both reads' raw moments;
- stuck pixels: the read is the constant ``v`` (cumulants ``v, 0, 0``), clipped as the read is.

The linear truth (``linear_dn``) of a read is what an ideal linear camera with the same fixed
patterns records: ``s0 K (eta g mu_p + d) + o + p A`` with ``s0`` the responses' small-signal
slope (:func:`linear_maps`), and a stuck pixel's value.

References
----------
EMVA Standard 1288, Release 4.0 Linear (2021), section 2; the chain's effects:
:mod:`bench_sim.sensor.effects`.
"""

from __future__ import annotations

import math

import numpy as np

from bench_sim.config import SensorConfig
from bench_sim.sensor.effects.base import ReadLaw
from bench_sim.sensor.expectation import ReadModel, read_cumulants

__all__ = ["law_read_model", "law_read_cumulants", "linear_maps", "stage_constant_dn"]


def law_read_model(sensor: SensorConfig, law: ReadLaw) -> ReadModel:
    """The read model of ``sensor`` with the chain's extra Gaussian variance in its read noise."""
    rm = ReadModel.of(sensor)
    if law.extra_read_var_dn2 <= 0:
        return rm
    read_e = math.sqrt(rm.read_noise_e**2 + law.extra_read_var_dn2 / rm.gain_dn_per_e**2)
    return ReadModel(rm.gain_dn_per_e, rm.full_well_e, read_e, rm.top_dn, rm.quantization)


def _raw(k1: np.ndarray, k2: np.ndarray, k3: np.ndarray) -> tuple[np.ndarray, ...]:
    """Raw moments of a read from its cumulants (the rounding's variance in ``k2``: the moments of
    the rounded read, which mix exactly)."""
    return k1, k2 + k1 * k1, k3 + 3.0 * k1 * k2 + k1**3


def _rows(a: np.ndarray, rows: slice | int) -> np.ndarray:
    """The rows of an (M, N) map that the reads cover."""
    return np.asarray(a)[rows]


def law_read_cumulants(
    lam: np.ndarray,
    det: np.ndarray | float,
    offset_dn: np.ndarray | float,
    rm: ReadModel,
    law: ReadLaw,
    rows: slice | int,
    *,
    noisy: bool,
    lo_dn: float = 0.0,
    hi_dn: float | None = None,
    out: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cumulants [DN, DN^2, DN^3] of reads under the chain's law (module docstring).

    Parameters
    ----------
    lam, det, offset_dn, rm, noisy, lo_dn, hi_dn, out
        As :func:`~bench_sim.sensor.expectation.read_cumulants` (``rm`` from :func:`law_read_model`).
    law
        The chain's :class:`~bench_sim.sensor.effects.base.ReadLaw`.
    rows
        The sensor rows the reads cover (``slice(0, R)`` for reads of shape (C, R, N); ``0`` for
        row 0's reads of shape (C, N)): the telegraph and stuck maps are cut to them.
    """
    response = law.response if law.responses else None
    k1, k2, k3 = read_cumulants(
        lam, det, offset_dn, rm, noisy=noisy, lo_dn=lo_dn, hi_dn=hi_dn, out=out, response=response
    )
    shape = np.shape(lam)
    hi = rm.top_dn if hi_dn is None else hi_dn
    if law.telegraph is not None:
        tel = law.telegraph
        sel = np.broadcast_to(_rows(tel.mask, rows), shape)
        if np.any(sel):
            pick = [
                np.broadcast_to(np.asarray(a, dtype=np.float64), shape)[sel] for a in (lam, det, offset_dn)
            ]
            amp = np.broadcast_to(_rows(tel.amplitude_dn, rows), shape)[sel]
            p = np.broadcast_to(_rows(tel.probability, rows), shape)[sel]
            base = _raw(k1[sel], k2[sel], k3[sel])
            on = _raw(
                *read_cumulants(
                    pick[0], pick[1], pick[2] + amp, rm, noisy=noisy, lo_dn=lo_dn, hi_dn=hi, response=response
                )
            )
            m1, m2, m3 = ((1.0 - p) * b + p * o for b, o in zip(base, on, strict=True))
            k1[sel], k2[sel] = m1, np.maximum(m2 - m1 * m1, 0.0)
            k3[sel] = m3 - 3.0 * m1 * m2 + 2.0 * m1**3
    if law.stuck is not None:
        sel = np.broadcast_to(_rows(law.stuck.mask, rows), shape)
        if np.any(sel):
            value = np.broadcast_to(_rows(law.stuck.value_dn, rows), shape)[sel]
            k1[sel] = np.clip(value, lo_dn, hi)
            k2[sel], k3[sel] = 0.0, 0.0
    return k1, k2, k3


def linear_maps(
    sensor: SensorConfig, law: ReadLaw, gain: np.ndarray, dark_e: np.ndarray, offset_dn: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The linear truth of each pixel's read, ``E_lin = K eta a mu_p + c`` [DN]: the light
    coefficient ``a`` (the gain ``g`` times the responses' slope ``s0``; 0 for a stuck pixel) and
    the constant ``c = s0 K d + o + p A`` (a stuck pixel's value), both (M, N).

    Parameters
    ----------
    sensor
        The pixel model (``K``).
    law
        The chain's law.
    gain, dark_e, offset_dn
        (M, N) relative gain [1], dark electrons per read [e-], all offsets [DN].
    """
    s0, k = law.slope0, sensor.conversion_gain_dn_per_e
    a = s0 * np.asarray(gain, dtype=np.float64)
    c = s0 * k * np.asarray(dark_e, dtype=np.float64) + np.broadcast_to(offset_dn, a.shape)
    if law.telegraph is not None:
        c = c + np.where(law.telegraph.mask, law.telegraph.probability * law.telegraph.amplitude_dn, 0.0)
    if law.stuck is not None:
        a = np.where(law.stuck.mask, 0.0, a)
        c = np.where(law.stuck.mask, law.stuck.value_dn, c)
    return a, np.ascontiguousarray(c, dtype=np.float64)


def stage_constant_dn(constant_dn: np.ndarray, stage: int, shift_dn: float) -> np.ndarray:
    """The light-independent part [DN] of the linear truth of stage ``m`` per column: the
    constants of rows ``0 .. m - 1`` (:func:`linear_maps`) summed, plus the word's shift
    (:func:`bench_sim.sensor.dtdi.word_shift_dn`). Shape (N,)."""
    return constant_dn[: int(stage)].sum(axis=0) + float(shift_dn)
