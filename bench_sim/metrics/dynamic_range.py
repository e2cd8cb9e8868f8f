"""Dynamic range: the paper's eq. 15 and the stage pairs that give a requested value.

Eq. 15
------
``dPsi = 20 lg(mu2 / mu1)`` [dB]: the DR gain the paper predicts for fusing stages ``mu1 < mu2``
(from eq. 12-14, Barakat & Darcie's ``Psi_sys = Psi * max(E) / min(E)`` with ``E = m E_basic``).
For ``mu1 = 10, mu2 = 80`` it is 18.06 dB; the paper's 26.02 dB is ``20 lg 20``, e.g. the
stage pair (5, 100) of Fig. 3 (:func:`stage_pairs_for_db` finds such pairs).

The *measured* (EMVA 1288 style) dynamic range of an image type, ``20 lg(mu_p.sat / mu_p.min)``
from a photon-transfer series, is :func:`bench_sim.metrics.emva1288.dynamic_range_from_series`;
:mod:`bench_sim.measure.chain_dr` runs the series through the whole chain for
``Gamma1``, ``Gamma2`` and ``Gamma_HDR``.

References
----------
.. [DTDI] *An HDR Imaging Method With DTDI Technology for Push-Broom Cameras* (the paper
   bench_sim reproduces), eq. 12-15 and section 3.
.. [Barakat] N. Barakat and T. E. Darcie, minimal capture sets for multi-exposure
   enhanced-dynamic-range imaging (the paper's reference [9]; eq. 12).
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from bench_sim.errors import BenchSimError

__all__ = ["dr_increase_eq15_db", "stage_pairs_for_db"]


def dr_increase_eq15_db(mu1: float, mu2: float) -> float:
    """Eq. 15: ``dPsi = 20 lg(mu2 / mu1)`` [dB] (e.g. 18.06 dB for 10 and 80).

    Parameters
    ----------
    mu1, mu2
        DTDI stages (exposures ``E = m E_basic``, eq. 13), ``0 < mu1 < mu2``.
    """
    if not 0 < mu1 < mu2:
        raise BenchSimError(f"mu1 = {mu1}, mu2 = {mu2}: eq. 15 needs 0 < mu1 < mu2")
    return 20.0 * math.log10(mu2 / mu1)


def stage_pairs_for_db(
    target_db: float, candidates: Iterable[int] = range(5, 101, 5), tol_db: float = 0.01
) -> list[tuple[int, int]]:
    """Stage pairs ``(mu1, mu2)``, ``mu1 < mu2`` from ``candidates``, whose eq. 15 is ``target_db``.

    Parameters
    ----------
    target_db
        Requested ``dPsi`` [dB], e.g. the paper's 26.02.
    candidates
        Stages to choose from (default: Fig. 3's 5, 10, ..., 100).
    tol_db
        Accept ``|20 lg(mu2/mu1) - target_db| <= tol_db``.

    Returns
    -------
    list of (int, int)
        Sorted by ``mu1``; e.g. ``[(5, 100)]`` for 26.02 dB.
    """
    stages = sorted({int(m) for m in candidates})
    return [
        (a, b)
        for i, a in enumerate(stages)
        for b in stages[i + 1 :]
        if a > 0 and abs(dr_increase_eq15_db(a, b) - target_db) <= tol_db
    ]
