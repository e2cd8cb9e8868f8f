"""Moments of a clipped normal variable: the read noise of a read between the ADC's clips.

A read is ``clip(Y, lo, hi)`` with ``Y`` normal given the electrons (the read noise, in closed
form); :mod:`bench_sim.sensor.expectation` integrates these moments over the shot noise.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["normal_pdf", "normal_cdf", "clipped_normal_moments", "clipped_read_moments", "inside_probability"]


def normal_pdf(x: np.ndarray) -> np.ndarray:
    """The standard normal density ``phi(x)``."""
    return np.exp(-0.5 * x * x) / math.sqrt(2.0 * math.pi)


def normal_cdf(x: np.ndarray) -> np.ndarray:
    """The standard normal distribution function ``Phi(x)``."""
    from scipy.special import ndtr

    return np.asarray(ndtr(x))


def clipped_normal_moments(
    mu: np.ndarray, sd: np.ndarray | float, lo: np.ndarray | float, hi: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Raw moments ``E[X^k]``, ``k = 1, 2, 3``, of ``X = clip(Y, lo, hi)``, ``Y ~ N(mu, sd^2)``.

    Partial moments of the normal inside ``(lo, hi)`` by the recursion
    ``M_k = mu M_{k-1} + sd^2 (k - 1) M_{k-2} - sd (hi^{k-1} phi(beta) - lo^{k-1} phi(alpha))``
    (``alpha, beta`` the standardised bounds), plus the point masses at the bounds. ``sd = 0``
    gives ``clip(mu)``.
    """
    m1, m2, m3, _ = _moments(mu, sd, lo, hi)
    return m1, m2, m3


def clipped_read_moments(
    mu: np.ndarray, sd: float, lo: np.ndarray | float, hi: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`clipped_normal_moments` and :func:`inside_probability` of the same reads in one pass.

    For ``sd > 0`` the inside probability is the normal's mass ``Phi(beta) - Phi(alpha)`` that
    the moments' recursion starts from (the same numbers, not evaluated twice).
    """
    m1, m2, m3, m0 = _moments(mu, sd, lo, hi)
    return m1, m2, m3, (m0 if sd > 0 else inside_probability(mu, sd, lo, hi))


def _moments(
    mu: np.ndarray, sd: np.ndarray | float, lo: np.ndarray | float, hi: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The raw moments of :func:`clipped_normal_moments` and the normal's mass ``M_0`` inside
    ``(lo, hi)`` (``sd = 1`` where ``sd = 0``). A scalar ``sd > 0`` skips the ``clip(mu)`` branch
    (what ``np.where`` would not pick)."""
    mu = np.asarray(mu, dtype=np.float64)
    lo_c, hi_c = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    lo_a, hi_a = np.broadcast_to(lo_c, mu.shape), np.broadcast_to(hi_c, mu.shape)
    sd_a = np.broadcast_to(np.asarray(sd, dtype=np.float64), mu.shape)
    positive = np.ndim(sd) == 0 and float(sd) > 0
    safe = np.float64(sd) if positive else np.where(sd_a > 0, sd_a, 1.0)
    a, b = (lo_a - mu) / safe, (hi_a - mu) / safe
    pa, pb = normal_pdf(a), normal_pdf(b)
    ca, cb = normal_cdf(a), normal_cdf(b)
    m0 = cb - ca
    var = safe * safe  # (what ``safe**2`` computes)
    # powers of the clips as given (a column: once per read), broadcast in the products
    lo2, hi2, above = lo_c**2, hi_c**2, 1.0 - cb  # (``x**2`` is ``x * x``, ``x**1`` is ``x``)
    m1 = mu * m0 - safe * (pb - pa)
    m2 = mu * m1 + var * m0 - safe * (hi_a * pb - lo_a * pa)
    m3 = mu * m2 + 2.0 * var * m1 - safe * (hi2 * pb - lo2 * pa)
    out = []
    for k, mk, lo_k, hi_k in ((1, m1, lo_a, hi_a), (2, m2, lo2, hi2), (3, m3, lo_c**3, hi_c**3)):
        val = mk + lo_k * ca + hi_k * above
        out.append(np.asarray(val) if positive else np.where(sd_a > 0, val, np.clip(mu, lo_a, hi_a) ** k))
    return out[0], out[1], out[2], m0


def inside_probability(
    mu: np.ndarray, sd: float, lo: np.ndarray | float, hi: np.ndarray | float
) -> np.ndarray:
    """``P(lo < Y < hi)``, ``Y ~ N(mu, sd^2)``: where a rounded read is not pinned to a clip (the
    rounding's ``1/12`` DN^2 counts with this probability; a pinned read does not vary)."""
    if sd <= 0:
        return ((mu > lo) & (mu < hi)).astype(np.float64)
    return normal_cdf((hi - mu) / sd) - normal_cdf((lo - mu) / sd)
