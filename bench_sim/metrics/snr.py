"""Signal-to-noise ratio versus signal, per image: from a photon-transfer series or uniform patches.

Temporal noise comes from two images of the same scene, so fixed-pattern noise cancels (EMVA 1288
R4; :func:`bench_sim.metrics.emva1288.mean_var_from_pair`)::

    mu_y      = (mean(a) + mean(b)) / 2
    sigma_y^2 = mean(((a - mean(a)) - (b - mean(b)))**2) / 2
    SNR       = (mu_y - mu_y.dark) / sigma_y

These helpers apply the definitions of :mod:`bench_sim.metrics.emva1288` to any image type
(stage images, the fused ``Gamma_HDR``): per level of a series (:func:`snr_versus_signal`), or
per uniform patch of one image pair, e.g. the step-wedge fields of the target (:func:`patch_snr`).

References
----------
.. [EMVA] EMVA Standard 1288, Release 4.0 Linear: Standard for Characterization of Image
   Sensors and Cameras, European Machine Vision Association, 2021,
   section 3 (temporal noise from image pairs, SNR
   curve).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bench_sim.metrics.emva1288 import mean_var_from_pair, snr_curve

__all__ = ["snr_versus_signal", "patch_snr"]


def snr_versus_signal(
    mean_dn: ArrayLike, temporal_std_dn: ArrayLike, dark_mean_dn: float = 0.0
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """SNR versus signal of a series: ``signal = mean - dark`` [DN], ``SNR = signal / std``.

    Parameters
    ----------
    mean_dn
        Mean signal per level [DN].
    temporal_std_dn
        Temporal standard deviation per level [DN].
    dark_mean_dn
        Mean dark signal [DN].

    Returns
    -------
    (signal, snr)
        Arrays per level; the SNR is 0 where the temporal noise is 0 (a fully clipped level
        carries no measurable signal variation; EMVA's ``snr_curve`` gives ``inf`` there).
    """
    signal = np.asarray(mean_dn, dtype=np.float64) - float(dark_mean_dn)
    std = np.asarray(temporal_std_dn, dtype=np.float64)
    snr = snr_curve(signal, std)
    return signal, np.where(np.isfinite(snr), snr, 0.0)


def patch_snr(
    image_a: ArrayLike,
    image_b: ArrayLike,
    patches: Sequence[tuple[slice, slice]],
    dark_mean_dn: float = 0.0,
) -> list[dict[str, float]]:
    """SNR of uniform patches of an image pair (two exposures of the same static scene).

    Parameters
    ----------
    image_a, image_b
        The two images [DN], same shape.
    patches
        ``(rows, columns)`` slices of uniform regions (at least 2 pixels each).
    dark_mean_dn
        Mean dark signal [DN] subtracted from each patch mean.

    Returns
    -------
    list of dict
        Per patch: ``mean_dn``, ``signal_dn`` (mean - dark), ``temporal_std_dn`` and ``snr``.
    """
    a = np.asarray(image_a, dtype=np.float64)
    b = np.asarray(image_b, dtype=np.float64)
    out: list[dict[str, float]] = []
    for sl in patches:
        mean, var = mean_var_from_pair(a[sl], b[sl])
        signal = mean - dark_mean_dn
        std = math.sqrt(max(var, 0.0))
        out.append(
            {
                "mean_dn": mean,
                "signal_dn": signal,
                "temporal_std_dn": std,
                "snr": signal / std if std > 0 else 0.0,
            }
        )
    return out
