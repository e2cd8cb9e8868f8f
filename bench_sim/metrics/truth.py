"""Summary metrics of one simulated image against its exact truth (the manifest of a dataset).

A simulation carries, for every pixel, the word the camera outputs (``dn``), its exact
expectation (``mean_dn``), the photons behind it (``photons``) and whether a read or the word
clipped (``clipped``); see :mod:`bench_sim.workflows.simulate`. With the expectation known, the
temporal noise of a single image is measured directly: ``dn - mean_dn`` (no image pair needed,
unlike EMVA 1288's two-image method in :mod:`bench_sim.metrics.snr`).

- :func:`saturated_fraction`: the share of pixels whose value clipped.
- :func:`scene_dynamic_range_db`: ``20 lg(p_hi / p_lo)`` of the photon image, ``p_lo`` and
  ``p_hi`` its ``q``-th and ``(100 - q)``-th percentiles (robust to single pixels); the
  dynamic range the scene presents to the sensor, in the dB convention of EMVA 1288 and of the
  paper's eq. 15.
- :func:`region_masks`: the darkest and brightest ``fraction`` of the scene by photons.
- :func:`truth_snr`: ``SNR = mean(mean_dn - dark) / rms(dn - mean_dn)`` over a region: the
  region's mean signal above the stage's dark level over its measured temporal noise (EMVA
  1288's ``SNR = (mu_y - mu_y.dark) / sigma_y``).

References
----------
.. [EMVA] EMVA Standard 1288, Release 4.0 Linear, European Machine Vision Association, 2021
   (SNR, section 2.4; dynamic range, section 2.5).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bench_sim.errors import BenchSimError

__all__ = ["saturated_fraction", "scene_dynamic_range_db", "region_masks", "truth_snr"]


def saturated_fraction(clipped: ArrayLike) -> float:
    """Fraction of pixels that clipped (``clipped`` true), in 0..1."""
    c = np.asarray(clipped, dtype=bool)
    return float(c.mean()) if c.size else math.nan


def scene_dynamic_range_db(photons: ArrayLike, percentile: float = 0.1) -> float:
    """``20 lg(P_(100-q) / P_q)`` [dB] of the photon image (``q = percentile``).

    ``nan`` when the lower percentile is not positive (a black field: no finite range).
    """
    if not 0 <= percentile < 50:
        raise BenchSimError(f"percentile = {percentile}: must lie in [0, 50)")
    p = np.asarray(photons, dtype=np.float64).ravel()
    if p.size == 0:
        return math.nan
    lo, hi = np.percentile(p, [percentile, 100.0 - percentile])
    if not lo > 0:
        return math.nan
    return float(20.0 * math.log10(hi / lo))


def region_masks(photons: ArrayLike, fraction: float = 0.1) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """(dark, bright): pixels at or below the ``fraction`` quantile of ``photons`` and at or above
    the ``1 - fraction`` quantile."""
    if not 0 < fraction <= 0.5:
        raise BenchSimError(f"fraction = {fraction}: must lie in (0, 0.5]")
    p = np.asarray(photons, dtype=np.float64)
    lo, hi = np.quantile(p, [fraction, 1.0 - fraction])
    return p <= lo, p >= hi


def truth_snr(dn: ArrayLike, mean_dn: ArrayLike, dark_dn: float, mask: ArrayLike) -> float:
    """SNR of a region measured against the exact expectation.

    Parameters
    ----------
    dn
        The words [DN].
    mean_dn
        Their exact expectation [DN] (fixed patterns included).
    dark_dn
        The dark level of the image type [DN] (the expectation at 0 photons), subtracted from
        the signal.
    mask
        The region; callers leave clipped pixels out.

    Returns
    -------
    float
        ``mean(mean_dn - dark_dn) / sqrt(mean((dn - mean_dn)**2))`` over the region; ``nan`` for
        an empty region, ``inf`` where the words carry no noise.
    """
    m = np.asarray(mask, dtype=bool)
    if not m.any():
        return math.nan
    d = np.asarray(dn, dtype=np.float64)[m]
    e = np.asarray(mean_dn, dtype=np.float64)[m]
    noise = math.sqrt(float(np.mean((d - e) ** 2)))
    signal = float(np.mean(e)) - float(dark_dn)
    if noise == 0:
        return math.inf if signal > 0 else math.nan
    return signal / noise
