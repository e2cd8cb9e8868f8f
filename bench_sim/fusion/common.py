"""Shared pieces of the fusion stage: the result type and input checks.

Every fusion function takes *stage images*: 2-D arrays of digital numbers (DN) in stage units, i.e.
the DTDI sum of ``m`` pixel reads, black offset subtracted, clipped to the ``beta``-bit output word
``0 .. 2**beta - 1`` (paper eq. 1-4; ``Phi_FS`` and the word's clip value come from
:mod:`bench_sim.sensor.model`, the one place ``beta`` is validated). Values may be integers or
floats (averaged images are fine); file-level checks (integer values, range) live in
:mod:`bench_sim.workflows.fuse`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bench_sim.errors import BenchSimError

__all__ = [
    "FusionResult",
    "check_stage_pair",
    "as_stage_image",
    "as_stage_stack",
]

@dataclass(frozen=True)
class FusionResult:
    """A fused image and where each pixel came from.

    Attributes
    ----------
    hdr
        Fused image [DN, float64] in units of stage ``unit_stage`` (the highest input stage): a
        value ``x`` means ``x`` DN summed over ``unit_stage`` reads.
    source
        Stage number ``m`` of the input each pixel was taken from (int32, same shape as ``hdr``).
        For weighted merges: the highest stage that contributed with a non-zero weight.
    unit_stage
        The stage whose units ``hdr`` is expressed in.
    full_scale_dn
        Largest value ``hdr`` can take [DN in stage ``unit_stage`` units]: the lowest stage's clip
        value ``2**beta - 1`` scaled by ``unit_stage / lowest stage``.
    saturated
        True where every input is at its clip value, i.e. ``hdr`` is a lower bound only.
    variance
        Predicted variance of ``hdr`` [DN^2] where the merge models noise (inverse-variance
        merge), else ``None``.
    """

    hdr: NDArray[np.float64]
    source: NDArray[np.int32]
    unit_stage: int
    full_scale_dn: float
    saturated: NDArray[np.bool_]
    variance: NDArray[np.float64] | None = None


def check_stage_pair(mu1: int, mu2: int) -> tuple[int, int]:
    """Validate two DTDI stages ``1 <= mu1 < mu2`` (paper section 2.2)."""
    for name, mu in (("mu1", mu1), ("mu2", mu2)):
        if isinstance(mu, bool) or not isinstance(mu, int | np.integer):
            raise BenchSimError(f"{name} = {mu!r}: must be an integer stage >= 1")
    if mu1 < 1:
        raise BenchSimError(f"mu1 = {mu1}: must be a stage >= 1")
    if mu1 >= mu2:
        raise BenchSimError(f"mu1 = {mu1}, mu2 = {mu2}: need mu1 < mu2 (1 <= mu1 < mu2 <= M)")
    return int(mu1), int(mu2)


def as_stage_image(image: ArrayLike, name: str) -> NDArray[np.float64]:
    """Return ``image`` as a float64 array; reject non-finite values (NaN, inf)."""
    arr = np.asarray(image, dtype=np.float64)
    if arr.ndim == 0:
        raise BenchSimError(f"{name}: expected an image array, got a scalar")
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise BenchSimError(
            f"{name}: non-finite value {arr[tuple(bad)]} at index {tuple(int(i) for i in bad)}; "
            "stage images must be finite DN"
        )
    return arr


def as_stage_stack(stages: Mapping[int, ArrayLike]) -> tuple[tuple[int, ...], NDArray[np.float64]]:
    """Sort a ``{stage m: image}`` mapping by stage and stack it: (stages, array (K, ...)).

    Raises :class:`BenchSimError` for an empty mapping, stages below 1, or unequal shapes.
    """
    if not stages:
        raise BenchSimError("stages: need at least one stage image")
    ms = sorted(stages)
    for m in ms:
        if isinstance(m, bool) or not isinstance(m, int | np.integer) or m < 1:
            raise BenchSimError(f"stage {m!r}: stages must be integers >= 1")
    images = [as_stage_image(stages[m], f"stage {m} image") for m in ms]
    shapes = {im.shape for im in images}
    if len(shapes) != 1:
        raise BenchSimError(
            "stage images differ in shape: "
            + ", ".join(f"stage {m}: {im.shape}" for m, im in zip(ms, images, strict=True))
        )
    return tuple(int(m) for m in ms), np.stack(images)
