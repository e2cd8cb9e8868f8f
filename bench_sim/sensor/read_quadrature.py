"""The quadrature over the shot noise of :func:`bench_sim.sensor.expectation.read_cumulants`.

A read's shot electrons are the third-order Cornish-Fisher quantile of the Poisson law at a
standard normal ``z`` (:class:`PoissonQuantile`, what the ``hybrid`` sampler draws); the
expectation integrates the read's clipped-normal moments over ``z`` on ``[-Z_MAX, Z_MAX]`` by
Gauss-Legendre quadrature on pieces split at the kinks (:func:`z_at` finds where the quantile
reaches a charge; :func:`quadrature` sums the pieces). The per-read constants of the quantile
are evaluated once per read, and each expression in the same order of operations as written,
so every number is the same float64 whichever way the work is cut.

References
----------
E. A. Cornish, R. A. Fisher (1937), Revue de l'Institut International de Statistique 5,
307-320. G. H. Golub, J. H. Welsch (1969), Math. Comp. 23, 221-230 (Gauss quadrature).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import NamedTuple

import numpy as np

from bench_sim.sensor.clipped_normal import clipped_read_moments
from bench_sim.sensor.clipped_normal import normal_pdf as _phi

__all__ = ["PoissonQuantile", "z_at", "quadrature", "Moments", "Z_MAX", "NODES"]

#: Gauss-Legendre nodes per smooth piece of the ``z`` integral.
NODES = 12
#: the ``z`` range of the integral, ``[-Z_MAX, Z_MAX]``
Z_MAX = 6.5
_GL_X, _GL_W = np.polynomial.legendre.leggauss(NODES)
#: relative bound [1] of the difference between the quantile evaluated with ``z * z * z`` and
#: with ``z**3`` for ``z`` in the range (:meth:`PoissonQuantile.magnitude`)
_SURE = 2.0**-36
#: raw moments of reads and the probability that each is inside its clips
Moments = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


class PoissonQuantile(NamedTuple):
    """The Cornish-Fisher quantile of Poisson(lam) (cumulants all ``lam``), third order, with its
    per-read constants evaluated once (not at every ``z`` of a bisection or a quadrature):
    ``s = sqrt(lam)``, ``g1 = 1 / s``, ``g2 = 1 / lam`` and ``g1 * g1`` (``lam`` floored at
    ``1e-300``).

    Attributes
    ----------
    lam, s, g1, g2, g1g1
        The mean electrons [e-] and the constants, of one shape.
    """

    lam: np.ndarray
    s: np.ndarray
    g1: np.ndarray
    g2: np.ndarray
    g1g1: np.ndarray

    @classmethod
    def of(cls, lam: np.ndarray) -> PoissonQuantile:
        """The quantile of Poisson means ``lam`` [e-]."""
        s = np.sqrt(np.maximum(lam, 1e-300))
        g1 = 1.0 / s
        return cls(lam, s, g1, 1.0 / np.maximum(lam, 1e-300), g1 * g1)

    def take(self, rows: np.ndarray | slice) -> PoissonQuantile:
        """The quantile of the reads ``rows``."""
        return PoissonQuantile(*(a[rows] for a in self))

    def column(self) -> PoissonQuantile:
        """The constants as (n, 1) columns (to broadcast against (n, nodes) ``z``)."""
        return PoissonQuantile(*(a[:, None] for a in self))

    def magnitude(self) -> np.ndarray:
        """``M`` [e-]: the quantile's terms in absolute value at ``|z| = Z_MAX``, a bound of every
        intermediate of :meth:`at` (times ``s`` inside the bracket) over the range.

        Two evaluations of :meth:`at` whose ``z^3`` differ by ``D`` differ by at most
        ``s (g2 / 24 + g1^2 / 18) D`` plus two roundings of each of its operations, in all
        ``< 2^-47 M + s (g2 / 24 + g1^2 / 18) D``. ``z * z * z`` (two roundings) and ``z**3``
        (a power function of relative error ``e`` ulp) lie within ``D = (2 + 2 e) 2^-53 |z|^3``
        of each other, so the two quantiles differ by less than ``2^-47 M + (2 + 2 e) 2^-53 M``,
        below :data:`_SURE` ``M = 2^-36 M`` for any ``e`` below ``2^15`` ulp.
        """
        z = Z_MAX
        return self.lam + self.s * (z + self.g1 * (z * z + 1.0) / 6.0 + self.g2 * (z**3 + 3.0 * z) / 24.0
                                    + self.g1g1 * (2.0 * z**3 + 5.0 * z) / 36.0)

    def at(self, z: np.ndarray, z3: np.ndarray | None = None) -> np.ndarray:
        """The quantile [e-] at ``z`` (``z`` broadcast against the constants: a (1,) ``z`` is one
        ``z`` for all reads)::

            lam + s (z + g1 (z^2 - 1) / 6 + g2 (z^3 - 3 z) / 24 - g1^2 (2 z^3 - 5 z) / 36)

        evaluated in this order of operations, left to right (``z^3`` once, or ``z3`` where given,
        temporaries reused).
        """
        z3 = z**3 if z3 is None else z3
        t = self.g1 * (z * z - 1.0)
        t /= 6.0
        t += z
        u = self.g2 * (z3 - 3.0 * z)
        u /= 24.0
        t += u
        v = self.g1g1 * (2.0 * z3 - 5.0 * z)
        v /= 36.0
        t -= v
        t *= self.s
        t += self.lam
        return t


def z_at(target: np.ndarray, q: PoissonQuantile, q_lo: np.ndarray, q_hi: np.ndarray) -> np.ndarray:
    """``z`` where the quantile ``q`` reaches ``target`` [e-] (24 bisection steps; ``-Z_MAX`` or
    ``Z_MAX`` where it stays above or below it over the range); ``q_lo``, ``q_hi``: ``q`` at
    ``-Z_MAX`` and ``Z_MAX`` (shared by the targets of the same reads).

    Each step compares the quantile at the midpoint with the target. The comparison is made on
    the quantile with ``z^3`` as ``z * z * z`` (cheap) and repeated with ``z**3`` only where the
    two lie within :data:`_SURE` of the quantile's magnitude of each other: elsewhere both give
    the same answer (:meth:`PoissonQuantile.magnitude`), so the steps, and ``z``, are those of
    the comparison of ``z**3`` alone.
    """
    out = np.full(q.lam.shape, Z_MAX)  # the quantile stays below the target over the whole range
    out[q_lo >= target] = -Z_MAX  # or above it
    inside = q_hi >= target
    inside &= out > 0
    q_in, target_in = q.take(inside), np.broadcast_to(target, q.lam.shape)[inside]
    sure = _SURE * q_in.magnitude()
    lo = np.full(target_in.shape, -Z_MAX)
    hi = np.full(target_in.shape, Z_MAX)
    mid = np.empty(target_in.shape)
    for _ in range(24):
        np.add(lo, hi, out=mid)
        mid *= 0.5
        cheap = q_in.at(mid, mid * mid * mid)
        below = cheap < target_in
        cheap -= target_in
        unsure = np.flatnonzero(np.abs(cheap, out=cheap) <= sure)
        if unsure.size:
            below[unsure] = q_in.take(unsure).at(mid[unsure]) < target_in[unsure]
        np.copyto(lo, mid, where=below)
        np.copyto(hi, mid, where=~below)
    out[inside] = 0.5 * (lo + hi)
    return out


def quadrature(
    edges: np.ndarray, q: PoissonQuantile, det_e: np.ndarray, off: np.ndarray,
    read: tuple[float, float, float], lo: np.ndarray, hi: np.ndarray, r: Callable[[np.ndarray], np.ndarray],
    shared: tuple[float, ...] = (),
) -> Moments:
    """Raw moments of reads and the probability that each is inside its clips: the integral over
    ``z`` of the clipped normal's (:func:`~bench_sim.sensor.clipped_normal.clipped_read_moments`)
    weighted by the normal density, normalised by the integral of the density.

    Parameters
    ----------
    edges
        (pieces + 1, n) ``z`` edges of the pieces of each read, sorted along axis 0: :data:`NODES`
        Gauss-Legendre nodes on each piece of positive width. An empty piece (two equal edges)
        has zero weight at nodes that all lie at the same ``z``: its sum is the zero weight times
        the integrand at one node (the same numbers, evaluated once).
    q
        The reads' shot-noise quantile (n reads).
    det_e, off, lo, hi
        Electrons without noise [e-], offset [DN] and clips [DN] of each read, (n,).
    read
        Conversion gain ``K`` [DN/e-], full well [e-] and read noise [DN].
    r
        The monotone response of the charge [e- -> e-].
    shared
        Edges that every read has (sorted): a piece between two of them has the same nodes for
        every read, whose ``z^3`` is evaluated once.
    """
    n = q.lam.shape[0]
    acc = [np.zeros(n) for _ in range(4)]
    total = np.zeros(n)
    for p in range(edges.shape[0] - 1):
        a, b = edges[p], edges[p + 1]
        for rows, nodes, z3 in _groups(a, b, shared):
            at = slice(None) if np.all(rows) else np.flatnonzero(rows)
            w, mom = _piece(a[at], b[at], nodes, q.take(at).column(), det_e[at], off[at], read, lo[at],
                            hi[at], r, z3)
            total[at] += w.sum(axis=1)
            for j in range(4):
                acc[j][at] += (w * mom[j]).sum(axis=1)
    return acc[0] / total, acc[1] / total, acc[2] / total, acc[3] / total


def _nodes(a: np.ndarray, b: np.ndarray, nodes: int) -> np.ndarray:
    """The first ``nodes`` Gauss-Legendre nodes on ``[a, b]``, (n, nodes)."""
    return (0.5 * (a + b))[:, None] + (0.5 * (b - a))[:, None] * _GL_X[None, :nodes]


def _groups(
    a: np.ndarray, b: np.ndarray, shared: tuple[float, ...]
) -> Iterator[tuple[np.ndarray, int, np.ndarray | None]]:
    """The reads of one piece ``[a, b]`` in groups, each with its number of nodes and, where all
    its reads have the same nodes, their ``z^3`` (1, nodes): the empty pieces (one node), the
    pieces between two consecutive ``shared`` edges, the others."""
    wide = a < b
    if np.any(~wide):
        yield ~wide, 1, None
    for lo_z, hi_z in zip(shared[:-1], shared[1:], strict=True):
        same = wide & (a == lo_z) & (b == hi_z)
        if np.any(same):
            wide &= ~same
            yield same, NODES, _nodes(np.full(1, lo_z), np.full(1, hi_z), NODES) ** 3
    if np.any(wide):
        yield wide, NODES, None


def _piece(
    a: np.ndarray, b: np.ndarray, nodes: int, q: PoissonQuantile, det_e: np.ndarray, off: np.ndarray,
    read: tuple[float, float, float], lo: np.ndarray, hi: np.ndarray, r: Callable[[np.ndarray], np.ndarray],
    z3: np.ndarray | None = None,
) -> tuple[np.ndarray, Moments]:
    """The weights (n, nodes) of the first ``nodes`` Gauss-Legendre nodes on ``[a, b]`` times the
    normal density, and the moments of the reads at those nodes (``q``: (n, 1) columns; ``z3``:
    the nodes' ``z^3`` where known)."""
    k, fw, sd = read
    half = 0.5 * (b - a)
    z = _nodes(a, b, nodes)
    w = (half[:, None] * _GL_W[None, :nodes]) * _phi(z)
    e = q.at(z, z3)  # the electrons: the quantile, at least 0, plus the noiseless ones, at most the full well
    np.maximum(e, 0.0, out=e)
    e += det_e[:, None]
    np.minimum(e, fw, out=e)
    mu = k * r(e)
    mu += off[:, None]
    return w, clipped_read_moments(mu, sd, lo[:, None], hi[:, None])
