"""Classic multi-exposure merges, for comparison with the paper's rule: taken from OpenCV.

The stage images of one DTDI pass are treated as an exposure bracket with exposure times
proportional to the stage ``m`` (paper eq. 13: ``E = m * E_basic``); the sensor is linear, so the
camera response is the identity (OpenCV's default linear response).

* :func:`merge_debevec_opencv` - Debevec & Malik (1997) radiance map, ``cv2.createMergeDebevec``:
  a weighted mean of ``value / exposure`` with OpenCV's triangle ("hat") weights, which go to zero
  at the clip value. Returned in DN of the top stage.
* :func:`merge_mertens_opencv` - Mertens, Kautz & Van Reeth (2007) exposure fusion,
  ``cv2.createMergeMertens``: a display-referred blend (contrast, saturation, well-exposedness
  weights, Laplacian pyramids), *not* a radiance map; values about 0..1.

Scaling of the inputs for OpenCV (checked against OpenCV 5.0; OpenCV 4.x accepts 8-bit only, and
the functions fall back to 8-bit there):

* Debevec: float32 ``gamma / (2**beta - 1)`` in 0..1, which OpenCV maps to its 16-bit range, so
  the clip value is the hat weight's zero; at most 16 bits of each input are resolved.
* Mertens: float32 ``255 * gamma / (2**beta - 1)`` (its weights assume 8-bit scaling), no
  rounding.

References
----------
.. [Debevec] P. E. Debevec and J. Malik, Recovering high dynamic range radiance maps from
   photographs, Proc. SIGGRAPH 1997, 369-378.
.. [Mertens] T. Mertens, J. Kautz and F. Van Reeth, Exposure fusion, Proc. Pacific Graphics 2007,
   382-390 (extended: Computer Graphics Forum 28(1), 2009, 161-171).
.. [DTDI] *An HDR Imaging Method With DTDI Technology for Push-Broom Cameras* (the paper
   bench_sim reproduces), eq. 13 (stage images as exposures ``m E_basic``).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bench_sim.fusion.common import as_stage_stack
from bench_sim.sensor.model import word_clip_dn

__all__ = ["merge_debevec_opencv", "merge_mertens_opencv"]

_CV16 = 65535.0


def _normalised(stack: NDArray[np.float64], beta: int) -> NDArray[np.float64]:
    return np.clip(stack / float(word_clip_dn(beta, "beta")), 0.0, 1.0)


def merge_debevec_opencv(stages: Mapping[int, ArrayLike], *, beta: int) -> NDArray[np.float64]:
    """Debevec-Malik radiance map of stage images (OpenCV ``MergeDebevec``, linear response).

    Parameters
    ----------
    stages
        ``{m: image}``, 2-D stage images [DN] in ``0 .. 2**beta - 1``; exposure times ``~ m``.
    beta
        Output word length [bits].

    Returns
    -------
    numpy.ndarray
        Radiance estimate [DN, in units of the top stage ``m_K``], float64, same shape as the
        inputs. Pixels saturated in every stage carry no information (OpenCV returns an arbitrary
        value there).
    """
    import cv2

    ms, stack = as_stage_stack(stages)
    norm = _normalised(stack, beta)
    times = np.asarray(ms, dtype=np.float32)
    merge = cv2.createMergeDebevec()
    try:
        rad = merge.process([np.ascontiguousarray(im, dtype=np.float32) for im in norm], times)
        per_stage = rad.astype(np.float64) / _CV16  # normalised value per unit stage
    except cv2.error:  # OpenCV 4.x: 8-bit images only
        u8 = [np.round(im * 255.0).astype(np.uint8) for im in norm]
        rad = merge.process(u8, times)
        per_stage = rad.astype(np.float64) / 255.0
    if per_stage.ndim == 3:
        per_stage = per_stage[..., 0]
    return per_stage * float(word_clip_dn(beta, "beta")) * ms[-1]


def merge_mertens_opencv(
    stages: Mapping[int, ArrayLike],
    *,
    beta: int,
    contrast_weight: float = 1.0,
    saturation_weight: float = 1.0,
    exposure_weight: float = 1.0,
) -> NDArray[np.float64]:
    """Mertens exposure fusion of stage images (OpenCV ``MergeMertens``).

    Parameters
    ----------
    stages
        ``{m: image}``, 2-D stage images [DN] in ``0 .. 2**beta - 1``.
    beta
        Output word length [bits].
    contrast_weight, saturation_weight, exposure_weight
        OpenCV's exponents of the three quality measures (defaults: OpenCV's, all 1).

    Returns
    -------
    numpy.ndarray
        Display-referred fused image, float64 clipped to ``0 .. 1`` (not proportional to radiance).
    """
    import cv2

    ms, stack = as_stage_stack(stages)
    norm = _normalised(stack, beta)
    merge = cv2.createMergeMertens(contrast_weight, saturation_weight, exposure_weight)
    try:
        fused = merge.process([np.ascontiguousarray(im * 255.0, dtype=np.float32) for im in norm])
    except cv2.error:  # OpenCV 4.x: 8-bit images only
        fused = merge.process([np.round(im * 255.0).astype(np.uint8) for im in norm])
    fused = np.asarray(fused, dtype=np.float64)
    if fused.ndim == 3:
        fused = fused[..., 0]
    return np.clip(fused, 0.0, 1.0)
