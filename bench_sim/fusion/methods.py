"""The two-stage fusion rules a user can choose by name (``bench-sim fuse --method``).

:data:`FUSE_METHODS` is the one list of names; :func:`fuse_pair` applies one of them to two
stage words ``Gamma1`` (stage ``mu1``) and ``Gamma2`` (stage ``mu2 > mu1``) that may carry a
pedestal ``P`` (an offset besides the signal):

``eq11`` (the paper's rule, the default)
    ``Gamma2 - P`` where ``Gamma1 - P <= (Phi_FS - P) / (mu2 / mu1)``, else
    ``(mu2 / mu1) (Gamma1 - P)`` (:func:`bench_sim.fusion.paper.fuse_dtdi_hdr_eq11`). The switch
    is *predicted* from ``Gamma1``: where the light per row changes over the TDI window, ``Gamma2``
    can already be clipped below the threshold, and eq. 11 keeps the clipped value.
``clip`` (clip-aware)
    The highest unsaturated stage: ``Gamma2 - P`` wherever the word ``Gamma2`` is below its clip
    value ``2**beta - 1``, else ``(mu2 / mu1) (Gamma1 - P)``
    (:func:`bench_sim.fusion.multistage.fuse_stages_highest_unsaturated`, ``criterion="clip"``).
    It never takes a clipped ``Gamma2``.

Both return ``Gamma_HDR`` in stage-``mu2`` units [DN], pedestal removed.

References
----------
An HDR Imaging Method With DTDI Technology for Push-Broom Cameras (the reproduced paper),
eq. 4-11.
"""

from __future__ import annotations

from dataclasses import replace

from numpy.typing import ArrayLike

from bench_sim.errors import BenchSimError
from bench_sim.fusion.common import FusionResult, as_stage_image, check_stage_pair
from bench_sim.fusion.multistage import fuse_stages_highest_unsaturated
from bench_sim.fusion.paper import fuse_dtdi_hdr_eq11
from bench_sim.sensor.model import word_clip_dn

__all__ = ["FUSE_METHODS", "check_fuse_method", "fuse_pair"]

#: method name -> one-line description (the first is the default)
FUSE_METHODS: dict[str, str] = {
    "eq11": "paper eq. 11 (fuse_dtdi_hdr_eq11): Gamma2 where Gamma1 predicts it inside the word",
    "clip": "clip-aware (fuse_stages_highest_unsaturated, criterion='clip'): the highest stage "
    "whose word is below 2**beta - 1",
}


def check_fuse_method(method: str, option: str = "--method") -> str:
    """``method`` if it is one of :data:`FUSE_METHODS`, else a one-line
    :class:`~bench_sim.errors.BenchSimError` naming ``option``, the value and what is allowed."""
    if not isinstance(method, str) or method not in FUSE_METHODS:
        raise BenchSimError(f"{option} = {method!r}: allowed {', '.join(FUSE_METHODS)}")
    return method


def fuse_pair(
    gamma1: ArrayLike,
    gamma2: ArrayLike,
    *,
    method: str,
    mu1: int,
    mu2: int,
    beta: int,
    pedestal_dn: float = 0.0,
) -> FusionResult:
    """Fuse two stage words with the rule ``method`` (module docstring).

    Parameters
    ----------
    gamma1, gamma2
        Stage-``mu1`` and stage-``mu2`` words [DN], same shape, values in ``0 .. 2**beta - 1``.
    method
        One of :data:`FUSE_METHODS`.
    mu1, mu2
        Stages, ``1 <= mu1 < mu2``.
    beta
        Output word length [bits]; ``Phi_FS = 2**beta`` (paper eq. 4).
    pedestal_dn
        Offset ``P`` [DN] both words carry besides the signal; removed from the result.

    Returns
    -------
    FusionResult
        ``hdr`` [DN, stage-``mu2`` units, pedestal removed]; ``source`` = the stage each pixel
        came from; ``saturated`` where ``Gamma1`` is at the word's clip;
        ``full_scale_dn = (mu2/mu1) (2**beta - 1 - P)``.
    """
    check_fuse_method(method, "method")
    mu1, mu2 = check_stage_pair(mu1, mu2)
    p = float(pedestal_dn)
    if method == "eq11":
        return fuse_dtdi_hdr_eq11(gamma1, gamma2, mu1=mu1, mu2=mu2, beta=beta, pedestal_dn=p)
    top = float(word_clip_dn(beta, "beta"))
    if not 0.0 <= p < top:
        raise BenchSimError(f"pedestal_dn = {p:g}: must lie in 0..{top:g} (below the word clip)")
    g1, g2 = as_stage_image(gamma1, "gamma1"), as_stage_image(gamma2, "gamma2")
    if g1.shape != g2.shape:
        raise BenchSimError(f"gamma1 shape {g1.shape} differs from gamma2 shape {g2.shape}")
    # the words' clip, on the signal (pedestal removed): top - P for both stages
    result = fuse_stages_highest_unsaturated(
        {mu1: g1 - p, mu2: g2 - p}, beta=beta, criterion="clip", saturation_dn=top - p
    )
    return replace(result, full_scale_dn=(top - p) * mu2 / mu1)  # as eq. 11's, pedestal removed
