"""The paper's two-stage fusion rule (paper eq. 5-11).

Two stage images of one DTDI pass, ``Gamma1`` (stage ``mu1``) and ``Gamma2`` (stage ``mu2 > mu1``),
are fused pixel by pixel::

    gamma_HDR = gamma2                   where gamma1 <= Phi_FS / (mu2 / mu1)      (eq. 9, 10)
              = (mu2 / mu1) * gamma1     where gamma1 >  Phi_FS / (mu2 / mu1)      (eq. 5, 8)

with ``Phi_FS = 2**beta`` (eq. 4). The output is in stage-``mu2`` units and reaches
``(mu2 / mu1) * (2**beta - 1)`` (the paper writes ``(mu2 / mu1) * Phi_FS``).

The comparison is done as ``gamma1 * mu2 <= Phi_FS * mu1``, which is exact in float64 for integer
DN, so a value exactly at the threshold goes to ``gamma2`` as eq. 11 says.

Note (not hidden): ``Phi_FS = 2**beta`` is one more than the largest storable value
``2**beta - 1``. A pixel with ``gamma1`` exactly at the threshold has an expected ``gamma2`` of
``Phi_FS``, which the word clips to ``2**beta - 1``; eq. 11 still takes ``gamma2`` there, so the
fused response has a step of about one stage-``mu1`` DN (``mu2/mu1`` output DN) at the threshold.
With noise, pixels just below the threshold can also carry a clipped ``gamma2``.

References
----------
An HDR Imaging Method With DTDI Technology for Push-Broom Cameras (the reproduced paper),
eq. 4-11.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from bench_sim.errors import BenchSimError
from bench_sim.fusion.common import (
    FusionResult,
    as_stage_image,
    check_stage_pair,
)
from bench_sim.sensor.model import full_scale_dn, word_clip_dn

__all__ = ["eq11_threshold_dn", "fuse_dtdi_hdr_eq11"]


def eq11_threshold_dn(mu1: int, mu2: int, beta: int, pedestal_dn: float = 0.0) -> float:
    """Threshold on ``gamma1`` of eq. 11: ``Phi_FS / (mu2 / mu1)`` [DN, stage-``mu1`` units];
    with a pedestal ``P`` in ``Gamma2``'s word, ``(Phi_FS - P) / (mu2 / mu1)`` on the signal.

    Parameters
    ----------
    mu1, mu2
        DTDI stages, ``1 <= mu1 < mu2``.
    beta
        Output word length [bits]; ``Phi_FS = 2**beta`` (eq. 4).
    pedestal_dn
        Offset ``P`` of ``Gamma2``'s word [DN] (0: the paper's plain word).

    Returns
    -------
    float
        ``(2**beta - P) * mu1 / mu2`` (e.g. 512 DN for ``mu1 = 10``, ``mu2 = 80``, ``beta = 12``).
    """
    mu1, mu2 = check_stage_pair(mu1, mu2)
    return (full_scale_dn(beta, "beta") - float(pedestal_dn)) * mu1 / mu2


def fuse_dtdi_hdr_eq11(
    gamma1: ArrayLike,
    gamma2: ArrayLike,
    *,
    mu1: int,
    mu2: int,
    beta: int,
    pedestal_dn: float | tuple[float, float] = 0.0,
) -> FusionResult:
    """Fuse two DTDI stage images with the paper's rule (eq. 11).

    Parameters
    ----------
    gamma1
        Stage-``mu1`` image ``Gamma1`` [DN], values in ``0 .. 2**beta - 1`` (eq. 1).
    gamma2
        Stage-``mu2`` image ``Gamma2`` [DN], same shape (eq. 2).
    mu1, mu2
        Stages, ``1 <= mu1 < mu2``.
    beta
        Output word length [bits], ``Phi_FS = 2**beta`` (eq. 4).
    pedestal_dn
        Offset [DN] the stage words carry besides the signal (the DTDI pedestal ``dtdi.pedestal_dn``
        that keeps the dark signal above 0, plus ``m * black`` when the black offset is not
        subtracted; :func:`bench_sim.sensor.model.stage_offset_dn`): one value for both, or
        ``(P1, P2)``. It is removed from the images first, and the signal range of the words
        shrinks to ``Phi_FS - P``, so the threshold becomes ``(Phi_FS - P2) / (mu2 / mu1)``
        (``Gamma2``'s signal range decides when it clips). ``0`` (default) is exactly the
        paper's eq. 11.

    Returns
    -------
    FusionResult
        ``hdr`` = ``gamma_HDR`` [DN, stage-``mu2`` units, float64, pedestal removed]; ``source`` =
        ``mu2`` where the pixel is ``gamma2`` (eq. 10), ``mu1`` where it is
        ``(mu2/mu1) * gamma1`` (eq. 8); ``saturated`` where ``gamma1`` is at the clip value
        ``2**beta - 1``; ``full_scale_dn = (mu2/mu1) * (2**beta - 1 - P1)``.

    Raises
    ------
    BenchSimError
        Unequal shapes, non-finite values, bad stages or ``beta``.
    """
    mu1, mu2 = check_stage_pair(mu1, mu2)
    phi_fs = full_scale_dn(beta, "beta")
    g1 = as_stage_image(gamma1, "gamma1")
    g2 = as_stage_image(gamma2, "gamma2")
    if g1.shape != g2.shape:
        raise BenchSimError(f"gamma1 shape {g1.shape} differs from gamma2 shape {g2.shape}")
    clip = float(word_clip_dn(beta, "beta"))
    pedestals = np.asarray(pedestal_dn, dtype=np.float64)
    pair = pedestals if pedestals.ndim else np.stack([pedestals, pedestals])
    p1, p2 = float(pair[0]), float(pair[1])
    for p in (p1, p2):
        if not 0.0 <= p < clip:
            raise BenchSimError(f"pedestal_dn = {p:g}: must lie in 0..{clip:g} (below the word clip)")
    s1 = g1 - p1 if p1 else g1
    s2 = g2 - p2 if p2 else g2
    # eq. 5: gamma1 > Phi_FS / (mu2/mu1), as a product: exact for integer DN
    use_low = s1 * mu2 > (phi_fs - p2) * mu1  # eq11_threshold_dn(mu1, mu2, beta, p2), as a product
    hdr = np.where(use_low, s1 * mu2 / mu1, s2)  # eq. 8 / eq. 10
    source = np.where(use_low, np.int32(mu1), np.int32(mu2)).astype(np.int32)
    return FusionResult(
        hdr=hdr,
        source=source,
        unit_stage=mu2,
        full_scale_dn=(clip - p1) * mu2 / mu1,
        saturated=g1 >= clip,
    )
