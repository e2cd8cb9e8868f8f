"""Beyond the paper: fusion of more than two stages, and a noise-optimal merge.

Both functions take a mapping ``{stage m: stage image [DN]}`` and return a
:class:`~bench_sim.fusion.common.FusionResult` in units of the highest stage ``m_K``.

``fuse_stages_highest_unsaturated``
    For each pixel, the highest stage that is unsaturated, scaled by ``m_K / m_k``. With two stages
    and ``criterion="predicted"`` it *is* eq. 11.

``fuse_stages_inverse_variance``
    Inverse-variance weighted mean of all unsaturated stages, with the variance of a stage-``m``
    value from ``m`` independent reads (EMVA 1288 linear model, quantisation per read;
    :func:`bench_sim.sensor.model.stage_variance_dn2`)::

        var_m = m * (K**2 * (sigma_d**2 + mu_e) + 1/12)        [DN^2]

    ``mu_e`` [e-] is the mean signal electrons per read, estimated from the data (the highest
    unsaturated stage). Two consequences, stated rather than hidden:

    * With one ``K`` and ``sigma_d`` for all stages, every stage shares the same per-read
      variance, so the weights reduce to ``w_k ~ m_k`` (for values scaled to per-read units):
      the merge is ``m_K * sum(gamma_k) / sum(m_k)`` over the unsaturated stages.
    * It is optimal for *independent* stage images (separate passes, or disjoint row groups).
      Stages from one DTDI pass are nested sums of the same reads (``cov = min(m_i, m_j) * v``);
      for them the best linear unbiased estimate is the highest unsaturated stage alone, i.e.
      ``fuse_stages_highest_unsaturated(..., criterion="clip")``.

References
----------
EMVA Standard 1288, Release 4.0 Linear (2021), eq. 7 (the per-read variance). Inverse-variance
weighting of differently exposed images: P. E. Debevec and J. Malik, "Recovering High Dynamic
Range Radiance Maps from Photographs", SIGGRAPH 1997 (weighted merge of exposures).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bench_sim.errors import BenchSimError
from bench_sim.fusion.common import (
    FusionResult,
    as_stage_stack,
)
from bench_sim.sensor.model import full_scale_dn, stage_variance_dn2, word_clip_dn

__all__ = [
    "fuse_stages_highest_unsaturated",
    "fuse_stages_inverse_variance",
    "saturation_levels_dn",
]


def saturation_levels_dn(
    stages: tuple[int, ...], beta: int, saturation_dn: Mapping[int, float] | float | None
) -> NDArray[np.float64]:
    """Per-stage value at or above which a stage sample counts as saturated [DN].

    Parameters
    ----------
    stages
        Stage numbers, sorted.
    beta
        Output word length [bits]; the default level is the clip value ``2**beta - 1``.
    saturation_dn
        ``None`` (word clip for all), one level for all stages, or ``{m: level}`` (missing stages
        use the word clip). Use e.g. ``min(2**beta - 1, m * pixel_saturation_dn)`` when pixels
        saturate before the output word does.
    """
    clip = float(word_clip_dn(beta, "beta"))
    if saturation_dn is None:
        return np.full(len(stages), clip)
    if isinstance(saturation_dn, Mapping):
        return np.array([float(saturation_dn.get(m, clip)) for m in stages])
    return np.full(len(stages), float(saturation_dn))


def fuse_stages_highest_unsaturated(
    stages: Mapping[int, ArrayLike],
    *,
    beta: int,
    criterion: Literal["predicted", "clip"] = "predicted",
    saturation_dn: Mapping[int, float] | float | None = None,
) -> FusionResult:
    """For each pixel take the highest unsaturated stage, scaled to the top stage's units.

    Parameters
    ----------
    stages
        ``{m: image}``, stage images [DN] of equal shape from one pass (at least one).
    beta
        Output word length [bits], ``Phi_FS = 2**beta`` (paper eq. 4).
    criterion
        ``"predicted"`` (eq. 11 generalised): stage ``m_k`` (k > 1) is usable where the stage
        below predicts it inside the word, ``gamma_{k-1} * m_k / m_{k-1} <= Phi_FS`` (eq. 9); the
        lowest stage is always usable. With two stages this is exactly eq. 11.
        ``"clip"``: stage ``m_k`` is usable where its own value is below its saturation level
        (``saturation_dn``; default ``2**beta - 1``).
    saturation_dn
        See :func:`saturation_levels_dn`. Used by ``"clip"`` and for the ``saturated`` mask.

    Returns
    -------
    FusionResult
        ``hdr = gamma_k * m_K / m_k`` for the chosen ``k`` [DN, stage-``m_K`` units];
        ``source`` = chosen stage ``m_k``; ``saturated`` where the lowest stage is at or above its
        saturation level; ``full_scale_dn = (2**beta - 1) * m_K / m_1``.
    """
    ms, stack = as_stage_stack(stages)
    phi_fs = full_scale_dn(beta, "beta")
    sat = saturation_levels_dn(ms, beta, saturation_dn)
    n = len(ms)
    if criterion == "predicted":
        usable = np.ones(stack.shape, dtype=bool)
        for k in range(1, n):
            usable[k] = stack[k - 1] * ms[k] <= phi_fs * ms[k - 1]  # eq. 9, exact for integer DN
    elif criterion == "clip":
        usable = stack < sat.reshape((n,) + (1,) * (stack.ndim - 1))
        usable[0] = True
    else:
        raise BenchSimError(f"criterion = {criterion!r}: allowed 'predicted' or 'clip'")
    # highest usable index: argmax over the reversed stage axis
    k_sel = (n - 1) - np.argmax(usable[::-1], axis=0)
    chosen = np.take_along_axis(stack, k_sel[None], axis=0)[0]
    m_arr = np.asarray(ms, dtype=np.float64)
    hdr = chosen * ms[-1] / m_arr[k_sel]
    return FusionResult(
        hdr=hdr,
        source=np.asarray(ms, dtype=np.int32)[k_sel],
        unit_stage=ms[-1],
        full_scale_dn=float(word_clip_dn(beta, "beta")) * ms[-1] / ms[0],
        saturated=stack[0] >= sat[0],
    )


def _scaled_variances_dn2(
    ms: tuple[int, ...],
    mu_e: NDArray[np.float64],
    conversion_gain_dn_per_e: float,
    dark_noise_e: float,
    quantization: bool,
) -> NDArray[np.float64]:
    """``var(x_k) = (m_K / m_k)**2 * var_{m_k}`` [DN^2, stage-``m_K`` units] for each stage of
    ``ms`` (sorted, ``m_K = ms[-1]``), stacked on a first axis; ``mu_e`` [e-] per read."""
    top = ms[-1]
    return np.stack(
        [
            (top / m) ** 2
            * stage_variance_dn2(
                m,
                mu_e,
                conversion_gain_dn_per_e=conversion_gain_dn_per_e,
                dark_noise_e=dark_noise_e,
                quantization=quantization,
            )
            for m in ms
        ]
    )


def fuse_stages_inverse_variance(
    stages: Mapping[int, ArrayLike],
    *,
    beta: int,
    conversion_gain_dn_per_e: float,
    dark_noise_e: float,
    quantization: bool = True,
    saturation_dn: Mapping[int, float] | float | None = None,
) -> FusionResult:
    """Noise-optimal (inverse-variance) merge of stage images, saturated samples excluded.

    Each unsaturated stage gives an estimate ``x_k = gamma_k * m_K / m_k`` [DN, stage-``m_K``
    units] with variance ``(m_K / m_k)**2 * var_{m_k}``
    (:func:`~bench_sim.sensor.model.stage_variance_dn2`); the result is ``sum(w_k x_k) / sum(w_k)``
    with ``w_k = 1 / var(x_k)``. ``mu_e`` per read is
    estimated from the highest unsaturated stage, ``gamma_k / (m_k K)``. See the module notes on
    independent versus nested (same-pass) stages.

    Parameters
    ----------
    stages
        ``{m: image}``, stage images [DN] of equal shape.
    beta
        Output word length [bits].
    conversion_gain_dn_per_e
        Sensor conversion gain ``K`` [DN/e-], > 0.
    dark_noise_e
        Dark noise ``sigma_d`` per read [e-], >= 0.
    quantization
        Include ``1/12`` DN^2 per read.
    saturation_dn
        Saturation levels, see :func:`saturation_levels_dn` (default: the word clip).

    Returns
    -------
    FusionResult
        ``hdr`` [DN, stage-``m_K`` units], ``variance`` = ``1 / sum(w_k)`` [DN^2], ``source`` =
        highest stage with a non-zero weight. Where every stage is saturated, the lowest stage
        (scaled) is returned and ``saturated`` is True.
    """
    if not conversion_gain_dn_per_e > 0:
        raise BenchSimError(f"conversion_gain_dn_per_e = {conversion_gain_dn_per_e}: must be > 0")
    if not dark_noise_e >= 0:
        raise BenchSimError(f"dark_noise_e = {dark_noise_e}: must be >= 0")
    ms, stack = as_stage_stack(stages)
    n = len(ms)
    sat = saturation_levels_dn(ms, beta, saturation_dn).reshape((n,) + (1,) * (stack.ndim - 1))
    m_arr = np.asarray(ms, dtype=np.float64).reshape(sat.shape)
    unsat = stack < sat
    any_unsat = unsat.any(axis=0)
    top = ms[-1]
    # pilot: per-read signal from the highest unsaturated stage (lowest stage where none is)
    k_hi = np.where(any_unsat, (n - 1) - np.argmax(unsat[::-1], axis=0), 0)
    pilot_dn_per_read = np.take_along_axis(stack, k_hi[None], axis=0)[0] / m_arr.ravel()[k_hi]
    mu_e = np.maximum(pilot_dn_per_read, 0.0) / conversion_gain_dn_per_e
    scale = top / m_arr  # to stage-m_K units
    x = stack * scale
    var_x = _scaled_variances_dn2(ms, mu_e, conversion_gain_dn_per_e, dark_noise_e, quantization)
    var_x = np.maximum(var_x, 1e-12)  # noise-free model: equal-variance floor, no division by 0
    with np.errstate(divide="ignore"):
        w = np.where(unsat, 1.0 / var_x, 0.0)
    w_sum = w.sum(axis=0)
    safe = w_sum > 0
    hdr = np.where(safe, (w * x).sum(axis=0) / np.where(safe, w_sum, 1.0), x[0])
    with np.errstate(divide="ignore"):
        variance = np.where(safe, 1.0 / np.where(safe, w_sum, 1.0), var_x[0])
    return FusionResult(
        hdr=hdr,
        source=np.asarray(ms, dtype=np.int32)[k_hi],
        unit_stage=top,
        full_scale_dn=float(word_clip_dn(beta, "beta")) * top / ms[0],
        saturated=~np.asarray(any_unsat),
        variance=variance,
    )
