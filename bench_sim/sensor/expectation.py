"""Exact expectation of clipped reads and clipped stage words (full-well, ADC and word clips).

The linear model (:mod:`bench_sim.sensor.model`) gives the mean of a read only where nothing
clips. Near a clip the read of :func:`bench_sim.sensor.emva.expose` is

``v = clip(rint(K (min(n + d, FW) + sigma_r eps) + o), 0, T)``

with ``n`` the shot electrons (Poisson of mean ``lam``), ``d`` the electrons without noise
(a switched-off source), ``FW`` the full well, ``sigma_r`` the read noise, ``K`` the conversion
gain, ``o = b + c`` the black and column offsets and ``T = 2**adc_bits - 1``. A DTDI stage word is
``clip(sum_i v_i - m b + P, 0, W)`` with ``W = 2**beta - 1`` (paper eq. 1-2, 4).

How the expectation is computed
-------------------------------
Per read (:func:`read_cumulants`): reads whose mean lies more than :data:`CLIP_SIGMAS` standard
deviations from every clip get the linear cumulants (``kappa_1 = K (lam + d) + o``,
``kappa_2 = K^2 (lam + sigma_r^2) + 1/12``, ``kappa_3 = K^3 lam``). The others are integrated
numerically: ``n`` is written as the Cornish-Fisher quantile of the Poisson law at a standard
normal ``z`` (the distribution the ``hybrid`` sampler draws, :func:`bench_sim.sensor.emva.
shot_electrons`), the read noise is integrated in closed form (moments of a two-sided clipped
normal), and ``z`` by 12-node Gauss-Legendre quadrature on ``[-6.5, 6.5]`` split at the kinks (where the
electrons reach the full well and where the mean reaches ``0`` and ``T``), so every piece is
smooth (:mod:`bench_sim.sensor.read_quadrature`); below
:data:`~bench_sim.sensor.sampler.SHOT_NOISE_SWITCH_E` mean electrons (where the sampler draws
the exact Poisson law and the quantile is no longer close to it) ``n`` is summed over its counts
with the Poisson weights instead. Rounding (``rint``) is unbiased there (the read's spread covers
many DN); it adds ``1/12`` DN^2 to the variance with the probability that the read is not pinned
to a clip.

Per stage (:func:`clipped_sum_mean`): the sum of ``m`` independent reads has the summed
cumulants; its clip at ``0`` and ``W`` is taken through the one-term Edgeworth expansion with
Sheppard's correction for the integer lattice (``E[(Z - c)+] = phi(c) - c (1 - Phi(c)) +
gamma c phi(c) / 6``). For ``m = 1`` the word's clip is folded into the read's own clip range
(exact; :func:`read_cumulants` with ``lo_dn``/``hi_dn``). The approximation error of the
Edgeworth step is below :data:`EDGEWORTH_ERROR_BOUND_SD` of the stage's standard deviation where
the word clips the sum of at least 2 reads, checked against the exact ``m``-fold convolution of
the read's distribution by ``tests/sensor/test_expectation.py``.

References
----------
EMVA Standard 1288, Release 4.0 Linear (2021), section 2. E. A. Cornish, R. A. Fisher (1937),
Revue de l'Institut International de Statistique 5, 307-320. W. F. Sheppard (1898), Proc. London
Math. Soc. 29, 353-380. H. Cramer, Mathematical Methods of Statistics (1946), section 17.7
(Edgeworth series).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from bench_sim.sensor.clipped_normal import clipped_normal_moments, clipped_read_moments
from bench_sim.sensor.clipped_normal import normal_cdf as _cdf
from bench_sim.sensor.clipped_normal import normal_pdf as _phi
from bench_sim.sensor.cumulant_kernel import linear_cumulants
from bench_sim.sensor.model import QUANTIZATION_VAR_DN2
from bench_sim.sensor.read_quadrature import Z_MAX as _Z_MAX
from bench_sim.sensor.read_quadrature import Moments, PoissonQuantile, quadrature, z_at
from bench_sim.sensor.sampler import SHOT_NOISE_SWITCH_E

#: A monotone response of the charge, electrons -> electrons
Response = Callable[[np.ndarray], np.ndarray]

__all__ = [
    "Response",
    "ReadModel",
    "read_cumulants",
    "clipped_sum_mean",
    "clipped_normal_moments",
    "CLIP_SIGMAS",
    "EDGEWORTH_ERROR_BOUND_SD",
]

#: Reads whose mean is further than this many standard deviations from every clip are linear.
CLIP_SIGMAS = 6.0
#: Bound of the Edgeworth step's error on a clipped stage mean, in units of the stage's sd.
EDGEWORTH_ERROR_BOUND_SD = 0.01
#: Clips further than this many sd from a normal read leave its moments unchanged in float64
#: (the tail mass beyond, ``Phi(-9) ~ 1e-19``, is below the resolution of ``1 + x``).
_FAR_CLIP_SDS = 9.0
#: Read noise [DN] below which a read's clips are split points of the quadrature through a
#: response (above it the clipped normal's moments are smooth in its mean)
_KINK_SD_DN = 0.5
#: fixed split points of the ``z`` range (the normal's shoulders)
_Z_SPLIT = 2.5
#: standard deviations from both clips beyond which a clipped sum's mean is its mean ``k1`` in
#: float64: both shortfalls are below ``4 phi(12) sd ~ 2e-31 sd`` (``1 - Phi(12)`` rounds to 0),
#: far below half an ulp of ``k1`` (``|k1| >= sd``), so ``k1 + lower - upper`` rounds to ``k1``
_FAR_SDS = 12.0
#: Sums per block of :func:`clipped_sum_mean` (its scratch stays in the CPU's cache)
_BLOCK_ELEMENTS = 16384


@dataclass(frozen=True)
class ReadModel:
    """The per-read constants of :func:`read_cumulants` (from a ``SensorConfig``).

    Attributes
    ----------
    gain_dn_per_e, full_well_e, read_noise_e, top_dn
        ``K``, ``FW``, ``sigma_r`` (0: off) and the ADC top ``T = 2**adc_bits - 1``.
    quantization
        Whether reads are rounded (adds ``1/12`` DN^2 to the variance).
    """

    gain_dn_per_e: float
    full_well_e: float
    read_noise_e: float
    top_dn: float
    quantization: bool

    @classmethod
    def of(cls, sensor: object) -> ReadModel:
        """From a :class:`bench_sim.config.SensorConfig`."""
        s = sensor
        return cls(
            gain_dn_per_e=float(s.conversion_gain_dn_per_e),  # type: ignore[attr-defined]
            full_well_e=float(s.full_well_e),  # type: ignore[attr-defined]
            read_noise_e=float(s.read_noise_e) if s.read_noise else 0.0,  # type: ignore[attr-defined]
            top_dn=float(2 ** s.adc_bits - 1),  # type: ignore[attr-defined]
            quantization=bool(s.quantization),  # type: ignore[attr-defined]
        )


def _full_read_moments(
    mu: np.ndarray, sd: float, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Raw moments of full-well reads ``clip(N(mu, sd^2), lo, hi)`` and the probability that
    each is inside its clips (:func:`~bench_sim.sensor.clipped_normal.inside_probability`): the
    normal's own (``mu``, ``mu^2 + sd^2``, ``mu^3 + 3 mu sd^2``, 1) where both clips lie more than
    :data:`_FAR_CLIP_SDS` sd away (the clipped tails are below float64's resolution there), else
    :func:`~bench_sim.sensor.clipped_normal.clipped_read_moments`."""
    far = (hi - mu > _FAR_CLIP_SDS * sd) & (mu - lo > _FAR_CLIP_SDS * sd)
    var = sd * sd
    m1, m2, m3, p_in = mu.copy(), mu * mu + var, mu * (mu * mu + 3.0 * var), np.ones(mu.shape)
    if not np.all(far):
        near = ~far
        m1[near], m2[near], m3[near], p_in[near] = clipped_read_moments(mu[near], sd, lo[near], hi[near])
    return m1, m2, m3, p_in


def _identity(e: np.ndarray) -> np.ndarray:
    return e


def _electrons_at(response: Response, target: np.ndarray, fw: float) -> np.ndarray:
    """Electrons ``e`` in ``0 .. fw`` where the monotone ``response(e)`` reaches ``target``
    (bisection; ``0`` or ``fw`` where it stays above or below it)."""
    lo, hi = np.zeros(target.shape), np.full(target.shape, fw)
    for _ in range(48):
        mid = 0.5 * (lo + hi)
        below = response(mid) < target
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    return 0.5 * (lo + hi)


#: counts of the exact Poisson sum: P(N > this) < 1e-20 for every mean below the switch
_POISSON_COUNTS = np.arange(int(SHOT_NOISE_SWITCH_E + 12.0 * np.sqrt(SHOT_NOISE_SWITCH_E) + 13.0),
                            dtype=np.float64)


def _merge(mask: np.ndarray, part: Moments, rest: Moments) -> Moments:
    """The moments of the reads of ``mask`` from ``part``, of the others from ``rest``."""
    out = tuple(np.empty(mask.shape) for _ in range(4))
    for j in range(4):
        out[j][mask], out[j][~mask] = part[j], rest[j]
    return out[0], out[1], out[2], out[3]


def _full_reads(lam: np.ndarray, det_e: np.ndarray, off: np.ndarray, rm: ReadModel, lo: np.ndarray,
                hi: np.ndarray, r: Response) -> Moments:
    """Reads full at every node: the read is the clipped normal of the full well's response."""
    top = r(np.full(lam.shape, rm.full_well_e))
    return _full_read_moments(rm.gain_dn_per_e * top + off, rm.gain_dn_per_e * rm.read_noise_e, lo, hi)


def _poisson_reads(lam: np.ndarray, det_e: np.ndarray, off: np.ndarray, rm: ReadModel, lo: np.ndarray,
                   hi: np.ndarray, r: Response) -> Moments:
    """Reads of Poisson means below :data:`~bench_sim.sensor.sampler.SHOT_NOISE_SWITCH_E`: the
    exact sum over the counts ``n`` (Poisson weights; 0 electrons at a mean of 0), in blocks."""
    from scipy.stats import poisson

    k, fw, s = rm.gain_dn_per_e, rm.full_well_e, rm.gain_dn_per_e * rm.read_noise_e
    out = tuple(np.empty(lam.shape) for _ in range(4))
    step = max(1, _BLOCK_ELEMENTS // _POISSON_COUNTS.size)
    for b in range(0, lam.size, step):
        p = slice(b, b + step)
        w = poisson.pmf(_POISSON_COUNTS[None, :], lam[p, None])
        mu = k * r(np.minimum(_POISSON_COUNTS[None, :] + det_e[p, None], fw)) + off[p, None]
        lo_p, hi_p = lo[p, None], hi[p, None]
        mom = clipped_read_moments(mu, s, lo_p, hi_p)
        total = w.sum(axis=1)
        for j in range(4):
            out[j][p] = (w * mom[j]).sum(axis=1) / total
    return out[0], out[1], out[2], out[3]


def _integrate_reads(
    lam: np.ndarray, det_e: np.ndarray, off: np.ndarray, rm: ReadModel, lo: np.ndarray, hi: np.ndarray,
    noisy: bool, response: Response | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Raw moments of the clipped reads ``lam`` (1-D arrays) and the probability that a read is
    inside its clips, by quadrature over ``z``
    (:func:`~bench_sim.sensor.read_quadrature.quadrature`); with a monotone ``response`` of the
    charge (after the full-well clip, before the read noise)."""
    k, fw, s = rm.gain_dn_per_e, rm.full_well_e, rm.gain_dn_per_e * rm.read_noise_e
    r = _identity if response is None else response
    if not noisy or not np.any(lam > 0):
        mu = k * r(np.minimum(lam + det_e, fw)) + off
        return clipped_read_moments(mu, s, lo, hi)
    # reads full at every node (the quantile at -_Z_MAX already reaches the full well; it rises
    # with z where lam is that large): the integrand is constant, the read a clipped normal
    full = lam + det_e >= fw  # (the quantile at -_Z_MAX lies below lam)
    lowest = PoissonQuantile.of(lam[full]).at(np.full(1, -_Z_MAX))
    full[full] = np.maximum(lowest, 0.0) + det_e[full] >= fw
    # small means: the exact Poisson law (what the hybrid sampler draws there; the quantile is not)
    small = ~full & (lam < SHOT_NOISE_SWITCH_E)
    for part, moments_of in ((full, _full_reads), (small, _poisson_reads)):
        if np.any(part):
            rest = ~part
            m_part = moments_of(lam[part], det_e[part], off[part], rm, lo[part], hi[part], r)
            m_rest = _integrate_reads(lam[rest], det_e[rest], off[rest], rm, lo[rest], hi[rest], noisy,
                                      response) if np.any(rest) else (np.empty(0),) * 4
            return _merge(part, m_part, m_rest)
    # kinks in z: full well, mean at lo and at hi
    targets = [fw - det_e]
    if response is None:  # the charge where the mean reaches each clip: a kink without read noise
        targets += [(lo - off) / k - det_e, (hi - off) / k - det_e]
    elif s < _KINK_SD_DN:  # through a response, found by bisection (only where the kink is sharp)
        targets += [_electrons_at(response, (b - off) / k, fw) - det_e for b in (lo, hi)]
    q = PoissonQuantile.of(lam)
    q_lo, q_hi = (q.at(np.full(1, z)) for z in (-_Z_MAX, _Z_MAX))
    cuts = [z_at(t, q, q_lo, q_hi) for t in targets]
    fixed = (-_Z_MAX, -_Z_SPLIT, _Z_SPLIT, _Z_MAX)
    edges = np.sort(np.stack([*(np.full(lam.shape, z) for z in fixed), *cuts]), axis=0)
    return quadrature(edges, q, det_e, off, (k, fw, s), lo, hi, r, shared=fixed)


def read_cumulants(
    lam_e: np.ndarray,
    det_e: np.ndarray | float,
    offset_dn: np.ndarray | float,
    rm: ReadModel,
    *,
    noisy: bool = True,
    lo_dn: np.ndarray | float = 0.0,
    hi_dn: np.ndarray | float | None = None,
    out: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    response: Response | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cumulants ``kappa_1`` [DN], ``kappa_2`` [DN^2], ``kappa_3`` [DN^3] of clipped reads.

    Parameters
    ----------
    lam_e
        Mean electrons of the Poisson part (light, and dark when its noise is on) [e-].
    det_e
        Electrons without noise (a source whose shot noise is switched off) [e-].
    offset_dn
        ``b + c``: black offset plus column offset [DN].
    rm
        The read's constants (:class:`ReadModel`).
    noisy
        Whether ``lam_e`` is Poisson (shot or dark noise on); else it is deterministic.
    lo_dn, hi_dn
        Clip range of the read [DN]; default ``0 .. T``. A stage of one read folds the word's
        clip in here (exact).
    out
        Three float64 arrays of ``lam_e``'s shape to write the cumulants into (default: new ones).
    response
        A monotone, non-decreasing response of the charge, ``e -> r(e)`` [e-], after the
        full-well clip and before the read noise (a non-linearity,
        :class:`bench_sim.sensor.effects.base.Response`): every read is then integrated through
        it by the quadrature (none is linear).

    Returns
    -------
    (kappa_1, kappa_2, kappa_3)
        Arrays of ``lam_e``'s shape; ``kappa_2`` includes the rounding's ``1/12`` (where the read
        is not pinned to a clip: a read at a clip does not vary).
    """
    lam = np.asarray(lam_e, dtype=np.float64, order="C")
    det0, off0 = np.asarray(det_e, dtype=np.float64), np.asarray(offset_dn, dtype=np.float64)
    lo0 = np.asarray(lo_dn, dtype=np.float64)
    hi0 = np.asarray(rm.top_dn if hi_dn is None else hi_dn, dtype=np.float64)
    k1, k2, k3 = out if out is not None else (np.empty(lam.shape) for _ in range(3))
    if not all(a.flags.c_contiguous for a in (k1, k2, k3)):
        raise ValueError("read_cumulants: the out arrays must be C-contiguous")
    near = np.empty(lam.shape, dtype=bool)
    top0 = np.minimum(hi0, rm.gain_dn_per_e * rm.full_well_e + off0)
    # the linear cumulants of every read, and which reads lie near a clip, in one compiled pass
    linear_cumulants(
        lam, det0, off0, lo0, top0, (k1, k2, k3), near, gain_dn_per_e=rm.gain_dn_per_e,
        read_noise_e=rm.read_noise_e, noisy=noisy, clip_sigmas=CLIP_SIGMAS,
        quantization_var_dn2=QUANTIZATION_VAR_DN2 if rm.quantization else None,
    )
    if response is not None:  # a response: no read is linear; those far from every clip are smooth
        near[...] = True
        _smooth_response_reads(lam, det0, off0, lo0, top0, rm, noisy, response, (k1, k2, k3), near)
    if np.any(near):
        det, off = (np.broadcast_to(a, lam.shape)[near] for a in (det0, off0))
        lo, hi = (np.broadcast_to(a, lam.shape)[near] for a in (lo0, hi0))
        m1, m2, m3, p_in = _integrate_reads(lam[near], det, off, rm, lo, hi, noisy, response)
        c2 = np.maximum(m2 - m1 * m1, 0.0)
        k1[near] = m1
        # the rounding's 1/12 where the read is not pinned to a clip (a pinned read does not vary)
        k2[near] = c2 + np.where(c2 > 0.0, p_in * (QUANTIZATION_VAR_DN2 if rm.quantization else 0.0), 0.0)
        k3[near] = m3 - 3.0 * m1 * m2 + 2.0 * m1**3
    return k1, k2, k3


#: Gauss-Hermite nodes and weights (probabilists', weight exp(-z^2 / 2)) of the smooth reads
_GH_X, _GH_W = np.polynomial.hermite_e.hermegauss(24)
_GH_W = _GH_W / _GH_W.sum()
#: the Cornish-Fisher quantile's terms at the nodes: (z^2 - 1) / 6 and (z^3 - 3z) / 24 - (2z^3 - 5z) / 36
_GH_A = (_GH_X**2 - 1.0) / 6.0
_GH_B = (_GH_X**3 - 3.0 * _GH_X) / 24.0 - (2.0 * _GH_X**3 - 5.0 * _GH_X) / 36.0


def _smooth_response_reads(
    lam: np.ndarray, det0: np.ndarray, off0: np.ndarray, lo0: np.ndarray, top0: np.ndarray, rm: ReadModel,
    noisy: bool, response: Response, out: tuple[np.ndarray, np.ndarray, np.ndarray], near: np.ndarray,
) -> None:
    """The reads through a ``response`` that lie :data:`CLIP_SIGMAS` standard deviations from
    every clip and from zero electrons: their moments by Gauss-Hermite quadrature of the
    Cornish-Fisher quantile (smooth there: no kink in range; the read noise's normal moments
    in closed form); written into ``out`` and cleared in ``near``."""
    k, s = rm.gain_dn_per_e, rm.gain_dn_per_e * rm.read_noise_e
    det, off, lo, top = (np.broadcast_to(a, lam.shape) for a in (det0, off0, lo0, top0))
    spread = CLIP_SIGMAS * np.sqrt(np.maximum(lam, 0.0)) if noisy else np.zeros(lam.shape)
    e_lo, e_hi = lam - spread + det, lam + spread + det
    ok = (lam - spread > 0) & (e_hi < rm.full_well_e)
    ok[ok] &= k * response(e_lo[ok]) + off[ok] - CLIP_SIGMAS * s - 1.0 > lo[ok]
    ok[ok] &= k * response(e_hi[ok]) + off[ok] + CLIP_SIGMAS * s + 1.0 < top[ok]
    if not np.any(ok):
        return
    lam_s, det_s, off_s = lam[ok][:, None], det[ok][:, None], off[ok][:, None]
    if noisy:  # the Cornish-Fisher quantile (PoissonQuantile): lam + sqrt(lam) z + A + B / sqrt(lam)
        root = np.sqrt(lam_s)
        e = (lam_s + _GH_A) + root * _GH_X + _GH_B / root
    else:
        e = lam_s
    # the far nodes (beyond CLIP_SIGMAS, weights < 1e-9) may leave 0 .. FW: the response gets charge
    y = k * response(np.clip(e + det_s, 0.0, rm.full_well_e)) + off_s
    w = _GH_W if noisy else np.ones(1)
    mean = (y * w).sum(axis=1)
    d = y - mean[:, None]  # central moments: the normal read noise adds s^2 and no skew
    k1, k2, k3 = out
    k1[ok] = mean
    k2[ok] = (d * d * w).sum(axis=1) + s * s + (QUANTIZATION_VAR_DN2 if rm.quantization else 0.0)
    k3[ok] = (d**3 * w).sum(axis=1)
    near[ok] = False


def _shortfall(c: np.ndarray, gamma: np.ndarray) -> np.ndarray:
    """``E[(Z - c)+]`` of a standardised variable with skewness ``gamma`` (one-term Edgeworth)."""
    tail = 1.0 - _cdf(c)
    return _phi(c) - c * tail + gamma * c * _phi(c) / 6.0


def clipped_sum_mean(
    k1: np.ndarray, k2: np.ndarray, k3: np.ndarray, lo: float, hi: float, *, lattice: bool = True
) -> np.ndarray:
    """``E[clip(S, lo, hi)]`` of a sum ``S`` with cumulants ``k1, k2, k3`` [DN, DN^2, DN^3].

    ``E[S] + E[(lo - S)+] - E[(S - hi)+]`` with both shortfalls from the one-term Edgeworth
    expansion (:func:`_shortfall`) of the sum; with ``lattice`` (integer words) the variance is
    reduced by Sheppard's ``1/12`` so that the continuous expansion has the lattice's spread.
    Error: below :data:`EDGEWORTH_ERROR_BOUND_SD` standard deviations for the sum of ``m >= 2``
    reads (tested against the exact convolution). Where both clips lie more than 12 standard
    deviations away the shortfalls are below half an ulp of ``k1`` and ``k1`` is returned as is
    (what the expansion rounds to in float64).
    """
    k1, k2, k3 = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (k1, k2, k3)))
    out = np.empty(k1.shape)
    f1, f2, f3 = (np.ascontiguousarray(a).reshape(-1) for a in (k1, k2, k3))
    out_flat = out.reshape(-1)
    for r in range(0, out_flat.size, _BLOCK_ELEMENTS):  # blocks that stay in the CPU's cache
        part = slice(r, r + _BLOCK_ELEMENTS)
        out_flat[part] = _clipped_sum_block(f1[part], f2[part], f3[part], lo, hi, lattice)
    return out


def _clipped_sum_block(
    k1: np.ndarray, k2: np.ndarray, k3: np.ndarray, lo: float, hi: float, lattice: bool
) -> np.ndarray:
    """:func:`clipped_sum_mean` of 1-D cumulants."""
    var = k2 - (QUANTIZATION_VAR_DN2 if lattice else 0.0)
    sd = np.sqrt(np.maximum(var, 0.0))
    out = np.clip(k1, lo, hi)
    # where both clips lie _FAR_SDS sd away the shortfalls vanish below k1's ulp: E = clip(k1) exactly
    ok = sd > 1e-9
    safe = np.where(ok, sd, 1.0)
    c_hi, c_lo = (hi - k1) / safe, (k1 - lo) / safe
    near_hi, near_lo = ok & (c_hi <= _FAR_SDS), ok & (c_lo <= _FAR_SDS)
    near = near_hi | near_lo | (ok & (np.abs(k1) < safe))
    if not np.any(near):
        return out
    k1n, sdn = k1[near], safe[near]
    gamma = np.clip(k3[near] / sdn**3, -1.0, 1.0)
    # each shortfall where its clip is near (elsewhere below 2e-31 sd: 0)
    upper, lower = np.zeros(k1n.shape), np.zeros(k1n.shape)
    for short, c, sel, sign in ((upper, c_hi, near_hi[near], 1.0), (lower, c_lo, near_lo[near], -1.0)):
        short[sel] = sdn[sel] * _shortfall(c[near][sel], sign * gamma[sel])
    out[near] = np.clip(k1n + lower - upper, lo, hi)
    return out


def _shortfall2(c: np.ndarray, gamma: np.ndarray) -> np.ndarray:
    """``E[((Z - c)+)^2]`` of a standardised variable with skewness ``gamma`` (one-term Edgeworth:
    the correction term integrates ``(z - c)^2 He_3(z) phi(z)`` to ``2 phi(c)``)."""
    return (1.0 + c * c) * (1.0 - _cdf(c)) - c * _phi(c) + gamma * _phi(c) / 3.0


def clipped_sum_var(
    k1: np.ndarray, k2: np.ndarray, k3: np.ndarray, lo: float, hi: float, *, lattice: bool = True
) -> np.ndarray:
    """``Var[clip(S, lo, hi)]`` [DN^2] of a sum ``S`` with cumulants ``k1, k2, k3``.

    ``E[clip(S)^2] - E[clip(S)]^2``, with ``clip(S)^2 = S^2 - ((S - hi)+)^2 - 2 hi (S - hi)+ -
    ((lo - S)+)^2 + 2 lo (lo - S)+`` and each shortfall from the one-term Edgeworth expansion
    (:func:`_shortfall`, :func:`_shortfall2`) of the continuous sum (variance ``k2 - 1/12``
    with ``lattice``); the lattice's ``1/12`` is added back with the probability that the sum
    lies inside the range. Where both clips lie more than 12 standard deviations away it is
    ``k2`` itself (the sum's own variance). The EMVA 1288 temporal variance of a stage word.
    """
    k1, k2, k3 = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (k1, k2, k3)))
    q = QUANTIZATION_VAR_DN2 if lattice else 0.0
    var = np.maximum(k2 - q, 0.0)
    sd = np.sqrt(var)
    ok = sd > 1e-9
    safe = np.where(ok, sd, 1.0)
    c_hi, c_lo = (hi - k1) / safe, (k1 - lo) / safe
    near = ok & ((c_hi <= _FAR_SDS) | (c_lo <= _FAR_SDS))
    out = np.where(ok, k2, 0.0)
    if not np.any(near):
        return out
    m, s, a, b = k1[near], safe[near], c_hi[near], c_lo[near]
    gamma = np.clip(k3[near] / s**3, -1.0, 1.0)
    up1, up2 = s * _shortfall(a, gamma), s * s * _shortfall2(a, gamma)
    dn1, dn2 = s * _shortfall(b, -gamma), s * s * _shortfall2(b, -gamma)
    mean = m + dn1 - up1
    second = var[near] + m * m - up2 - 2.0 * hi * up1 - dn2 + 2.0 * lo * dn1
    inside = _cdf(a) - _cdf(-b)
    out[near] = np.maximum(second - mean * mean, 0.0) + q * np.clip(inside, 0.0, 1.0)
    return out
