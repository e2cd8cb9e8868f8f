"""Defect pixels of EMVA 1288 R4 (section 8): found in the dark and flat images, counted, mapped
and kept out of the non-uniformities and the fits.

The kinds are those of the defects effect (:data:`bench_sim.sensor.effects.defects.KINDS`), in
the order they are tested (a pixel takes the first that fits):

``stuck``
    the same value in every image, dark and lit (no temporal noise, no response);
``hot`` / ``warm``
    an outlier above the population in the DSNU image: the per-pixel dark current [e-/s] of a
    dark series (:func:`bench_sim.metrics.nonuniformity.dark_series_maps`), or the dark image of
    one exposure time over it; ``hot`` where the excess reaches ``hot_dark_current_e_s``, else
    ``warm``; value: the excess dark current [e-/s] (a pixel clipped at all but one exposure is
    ``hot``, its value a lower bound);
``cold``
    an outlier below the population in the PRNU image (the dark-subtracted flat at about 50 % of
    saturation over its median); value: its relative gain (0: dead);
``rts``
    an outlier above the population in the dark temporal variance (a random-telegraph or
    otherwise noisy pixel); value: the telegraph step ``2 sqrt(excess variance)`` [DN] of a
    two-state pixel spending half its time in each state.

Outliers: a pixel deviates by more than ``z`` robust standard deviations of its image
(``1.4826`` times the median absolute deviation), ``z = Phi^-1(1 - alpha / P)`` for ``P`` pixels
with ``alpha`` (:data:`FALSE_ALARMS`) false detections expected per image; the temporal variance's
outliers by the chi-square quantile of the same probability, with :data:`VARIANCE_SPREAD` for the
pixels' own spread of dark shot noise. The histograms of the DSNU and PRNU images (at most 256
bins, with the thresholds) are reported, as R4's histograms are.

References
----------
EMVA Standard 1288, Release 4.0 Linear (2021), section 8 (defect pixels: DSNU and PRNU images,
their histograms; defect pixels left out of DSNU and PRNU).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bench_sim.sensor.effects.defects import KINDS

__all__ = [
    "FALSE_ALARMS",
    "HOT_DARK_CURRENT_E_S",
    "VARIANCE_SPREAD",
    "DefectImages",
    "DefectPixels",
    "find_defects",
    "robust_sigma",
]

#: Expected false detections per image and test
FALSE_ALARMS = 1e-3
#: Excess dark current [e-/s] from which a dark outlier is hot rather than warm
HOT_DARK_CURRENT_E_S = 5000.0
#: Allowed spread of the pixels' own dark temporal variance (dark shot noise of a non-uniform
#: dark current) beyond the chi-square spread of its estimate
VARIANCE_SPREAD = 1.25


def robust_sigma(values: np.ndarray) -> tuple[float, float]:
    """Median and ``1.4826 MAD`` of the finite values (a normal law's sigma, robust to outliers)."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    med = float(np.median(v))
    return med, 1.4826 * float(np.median(np.abs(v - med)))


@dataclass(frozen=True)
class DefectImages:
    """What the tests look at, (M, N) each: ``dark_rate_dn_s`` (the DSNU image as a dark rate
    [DN/s]: a dark series' slope map, or one dark image over its exposure; NaN: clipped),
    ``dark_level_dn`` (the dark image of the shortest exposure [DN]), ``response`` (the PRNU
    image: dark-subtracted flat over its median, or None), ``dark_var_dn2`` (pooled dark temporal
    variance) with ``dark_var_dof``, ``constant`` (no temporal noise in any image and the same
    value dark and lit), ``clip_dn`` (M, N: each pixel's clip) and ``shortest_exposure_s``."""

    dark_rate_dn_s: np.ndarray
    dark_level_dn: np.ndarray
    response: np.ndarray | None
    dark_var_dn2: np.ndarray | None
    dark_var_dof: int
    constant: np.ndarray
    clip_dn: np.ndarray
    shortest_exposure_s: float


@dataclass(frozen=True)
class DefectPixels:
    """The defect pixels found (module docstring): ``code`` (M, N) (0 good, ``1 + index`` in
    :data:`KINDS`), ``value`` (M, N), the thresholds used, the histograms."""

    code: np.ndarray = field(repr=False)
    value: np.ndarray = field(repr=False)
    thresholds: dict[str, float] = field(default_factory=dict)
    histograms: dict[str, dict[str, Any]] = field(default_factory=dict, repr=False)

    @property
    def good(self) -> np.ndarray:
        """(M, N) mask of the pixels that are not defects."""
        return self.code == 0

    def counts(self) -> dict[str, int]:
        """Number of pixels of each kind."""
        return {k: int(np.sum(self.code == j + 1)) for j, k in enumerate(KINDS)}

    def positions(self, kind: str) -> list[tuple[int, int]]:
        """(row, column) of the pixels of ``kind``, row by row."""
        return [(int(r), int(c)) for r, c in np.argwhere(self.code == KINDS.index(kind) + 1)]

    def rows(self) -> list[list[Any]]:
        """``row, column, kind, value`` of every defect: the defects effect's ``map_file`` format."""
        out: list[list[Any]] = []
        for r, c in np.argwhere(self.code > 0):
            out.append([int(r), int(c), KINDS[int(self.code[r, c]) - 1], float(self.value[r, c])])
        return out

    def summary(self) -> dict[str, Any]:
        """Counts, thresholds and positions (JSON-ready)."""
        return {
            "counts": self.counts(),
            "thresholds": dict(self.thresholds),
            "positions": {k: self.positions(k) for k in KINDS},
        }


def _z(pixels: int) -> float:
    from scipy.stats import norm

    return float(norm.isf(FALSE_ALARMS / max(pixels, 1)))


def _histogram(values: np.ndarray, lo: float, hi: float) -> dict[str, Any]:
    v = values[np.isfinite(values)]
    bins = int(min(256, max(8, np.sqrt(v.size))))
    counts, edges = np.histogram(v, bins=bins)
    return {"edges": edges.tolist(), "counts": counts.tolist(), "threshold_low": lo, "threshold_high": hi}


def _dark_outliers(
    img: DefectImages, k: float, hot_e_s: float, z: float, code: np.ndarray, value: np.ndarray
) -> dict[str, Any]:
    """Hot and warm pixels (in place); returns the DSNU image's histogram."""
    rate = img.dark_rate_dn_s / k  # e-/s
    med, sig = robust_sigma(rate)
    clipped = ~np.isfinite(rate)
    over = np.where(clipped, np.inf, rate - med)
    sel = (over > z * max(sig, 1e-300)) & (code == 0)
    excess = np.where(clipped, (img.clip_dn - img.dark_level_dn) / k / img.shortest_exposure_s, over)
    hot = sel & (excess >= hot_e_s)
    code[hot], value[hot] = KINDS.index("hot") + 1, excess[hot]
    warm = sel & ~hot
    code[warm], value[warm] = KINDS.index("warm") + 1, excess[warm]
    return _histogram(rate, med - z * sig, med + z * sig)


def _cold(img: DefectImages, z: float, code: np.ndarray, value: np.ndarray) -> dict[str, Any] | None:
    if img.response is None:
        return None
    med, sig = robust_sigma(img.response)
    sel = (img.response < med - z * max(sig, 1e-300)) & (code == 0) & np.isfinite(img.response)
    code[sel], value[sel] = KINDS.index("cold") + 1, img.response[sel] / med
    return _histogram(img.response, med - z * sig, med + z * sig)


def _noisy(img: DefectImages, code: np.ndarray, value: np.ndarray) -> float:
    """Random-telegraph (noisy) pixels in place; returns the variance threshold [DN^2]."""
    if img.dark_var_dn2 is None or img.dark_var_dof < 1:
        return math.nan
    from scipy.stats import chi2

    nu = img.dark_var_dof
    med = float(np.nanmedian(img.dark_var_dn2))
    ratio = float(chi2.isf(FALSE_ALARMS / img.constant.size, nu) / chi2.ppf(0.5, nu))
    thr = med * ratio * VARIANCE_SPREAD
    sel = (img.dark_var_dn2 > thr) & (code == 0)
    code[sel] = KINDS.index("rts") + 1
    value[sel] = 2.0 * np.sqrt(np.maximum(img.dark_var_dn2[sel] - med, 0.0))
    return thr


def find_defects(
    img: DefectImages, k_dn_per_e: float, *, hot_dark_current_e_s: float = HOT_DARK_CURRENT_E_S
) -> DefectPixels:
    """The defect pixels of the images (module docstring).

    Parameters
    ----------
    img
        The DSNU, PRNU and temporal-variance images.
    k_dn_per_e
        The camera's ``K`` [DN/e-] (dark rates in e-/s).
    hot_dark_current_e_s
        Excess dark current [e-/s] from which a dark outlier is ``hot``.
    """
    shape = img.constant.shape
    code = np.zeros(shape, dtype=np.int8)
    value = np.zeros(shape)
    z = _z(int(np.prod(shape)))
    stuck = np.asarray(img.constant, dtype=bool)
    code[stuck], value[stuck] = KINDS.index("stuck") + 1, img.dark_level_dn[stuck]
    hists = {"dsnu_e_s": _dark_outliers(img, k_dn_per_e, hot_dark_current_e_s, z, code, value)}
    prnu = _cold(img, z, code, value)
    if prnu is not None:
        hists["prnu_relative"] = prnu
    thr = _noisy(img, code, value)
    thresholds = {
        "sigmas": z,
        "false_alarms_per_image": FALSE_ALARMS,
        "hot_dark_current_e_s": hot_dark_current_e_s,
        "rts_variance_dn2": thr,
    }
    return DefectPixels(code=code, value=value, thresholds=thresholds, histograms=hists)
