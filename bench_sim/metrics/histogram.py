r"""The paper's histogram coefficient ``omega`` (eq. 16-18).

Eq. 16 is the histogram ``rho(tau_k) = epsilon_k``: the number of pixels whose DN equals the
``k``-th DN value ``tau_k``. Eq. 17 is ``omega(Gamma) = sigma^2[rho(tau_k)] / (M * N)`` with
``M * N`` the number of pixels. The paper leaves open which DN values ``tau_k`` are counted and
which variance is meant. This module fixes them as follows (and reports the binning with every
value, see :class:`Binning`):

* **Bins.** One bin per possible DN value of the image's output word, *including empty bins*:
  for a ``beta``-bit stage image, ``2**beta`` bins of width 1 DN, ``tau_k = k``,
  ``k = 0 .. 2**beta - 1``. Counting only the values that occur would make an image with two
  equally populated values score a perfect 0; with all possible values counted, ``omega`` is
  smallest for a histogram spread evenly over the whole word, which is what the paper argues
  (section 3: "the more uniformly the pixels are distributed, the higher the image's DR").
* **HDR image.** The fused image spans ``0 .. (mu2/mu1) * (2**beta - 1)`` in stage-``mu2`` DN,
  more than ``beta`` bits. Default (``"rescaled"``): ``2**beta`` bins of width ``mu2/mu1`` DN,
  i.e. the same number of bins as ``Gamma1`` and ``Gamma2`` over the HDR's full range, so the
  three values of eq. 18 compare like with like. Alternative (``"integer"``): one bin per integer
  DN, ``ceil((mu2/mu1) * 2**beta)`` bins; there the upper part of the histogram is a comb (only
  every ``mu2/mu1``-th DN value can occur where the pixel comes from ``Gamma1``).
* **Binning rule.** A value ``x`` goes into bin ``floor(x / width)``; values outside
  ``0 .. n_bins * width`` are an error (stage images never are).
* **Variance.** Population variance over the ``n_bins`` bins (``ddof = 0``):
  ``sigma^2 = (1/L) * sum_k (epsilon_k - P/L)**2``, ``L`` bins, ``P`` pixels. ``ddof = 1``
  (sample variance) is available.

Hand example: the 2 x 2 image ``[[0, 0], [1, 3]]`` with ``beta = 2`` has counts ``[2, 1, 0, 1]``,
mean 1, population variance ``(1 + 0 + 1 + 0) / 4 = 0.5`` and ``omega = 0.5 / 4 = 0.125``.

References
----------
.. [DTDI] *An HDR Imaging Method With DTDI Technology for Push-Broom Cameras* (the paper
   bench_sim reproduces), eq. 16-18 and Table 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bench_sim.errors import BenchSimError

__all__ = [
    "Binning",
    "Eq18Result",
    "stage_binning",
    "hdr_binning",
    "dn_histogram",
    "omega_eq17",
    "evaluate_eq18",
    "MAX_DENSE_BINS",
    "BINCOUNT_MAX_BINS",
]


@dataclass(frozen=True)
class Binning:
    """How DN values are binned for eq. 16: ``n_bins`` bins of ``width_dn`` starting at 0 DN."""

    n_bins: int
    width_dn: float
    description: str

    def as_dict(self) -> dict[str, object]:
        return {"n_bins": self.n_bins, "width_dn": self.width_dn, "description": self.description}


def stage_binning(beta: int) -> Binning:
    """``2**beta`` bins of 1 DN: one per possible value of a ``beta``-bit stage image."""
    if not 1 <= beta <= 32:
        raise BenchSimError(f"beta = {beta}: must lie in 1..32 bits")
    return Binning(2**beta, 1.0, f"{2**beta} bins of 1 DN (one per value of the {beta}-bit word)")


def hdr_binning(
    beta: int, mu1: int, mu2: int, mode: Literal["rescaled", "integer"] = "rescaled"
) -> Binning:
    """Binning of the fused image (stage-``mu2`` units, range ``0 .. (mu2/mu1) * 2**beta``).

    ``"rescaled"``: ``2**beta`` bins of ``mu2/mu1`` DN (same bin count as the stage images).
    ``"integer"``: ``ceil((mu2/mu1) * 2**beta)`` bins of 1 DN.
    """
    if not 1 <= mu1 < mu2:
        raise BenchSimError(f"mu1 = {mu1}, mu2 = {mu2}: need 1 <= mu1 < mu2")
    ratio = mu2 / mu1
    if mode == "rescaled":
        return Binning(
            2**beta,
            ratio,
            f"{2**beta} bins of mu2/mu1 = {ratio:g} DN (HDR range rescaled to the {beta}-bit word)",
        )
    if mode == "integer":
        n = math.ceil(ratio * 2**beta)
        return Binning(n, 1.0, f"{n} bins of 1 DN (integer DN over 0..(mu2/mu1)*2**beta)")
    raise BenchSimError(f"hdr binning = {mode!r}: allowed 'rescaled' or 'integer'")


def _bin_indices(image: ArrayLike, binning: Binning) -> NDArray[np.int64]:
    x = np.asarray(image, dtype=np.float64).ravel()
    if not np.all(np.isfinite(x)):
        raise BenchSimError("histogram: image contains NaN or inf")
    k = np.floor(x / binning.width_dn).astype(np.int64)
    if k.size and (k.min() < 0 or k.max() >= binning.n_bins):
        raise BenchSimError(
            f"histogram: values {x.min():g}..{x.max():g} DN outside the bins "
            f"0..{binning.n_bins * binning.width_dn:g} DN ({binning.description})"
        )
    return k


#: Largest number of bins :func:`dn_histogram` materialises (``omega_eq17`` has no limit).
MAX_DENSE_BINS = 1 << 26
#: Most bins :func:`omega_eq17` counts with :func:`numpy.bincount` (a pass over the pixels, 8 bytes
#: a bin); more (a 32-bit word) are counted by sorting the pixels' bins (:func:`numpy.unique`)
BINCOUNT_MAX_BINS = 1 << 24


def dn_histogram(image: ArrayLike, binning: Binning) -> NDArray[np.int64]:
    """Eq. 16: ``epsilon_k``, the number of pixels in each DN bin (all ``n_bins`` bins).

    Parameters
    ----------
    image
        Image [DN], any shape, finite values in ``0 .. n_bins * width_dn``.
    binning
        The bins (:func:`stage_binning`, :func:`hdr_binning`); at most ``MAX_DENSE_BINS``.
    """
    if binning.n_bins > MAX_DENSE_BINS:
        raise BenchSimError(
            f"histogram: {binning.n_bins} bins is too many to list ({binning.description}); "
            f"omega_eq17 works without listing them"
        )
    return np.bincount(_bin_indices(image, binning), minlength=binning.n_bins)


def omega_eq17(image: ArrayLike, binning: Binning, ddof: int = 0) -> float:
    """Eq. 17: ``omega = var(epsilon_k) / (M * N)`` over all ``binning.n_bins`` bins.

    Computed from the occupied bins only, exactly in integers:
    ``sum_k (epsilon_k - P/L)**2 = sum_k epsilon_k**2 - P**2 / L`` (``P`` pixels, ``L`` bins),
    so a 32-bit word's ``2**32`` bins cost nothing extra.

    Parameters
    ----------
    image
        Image [DN] (``M * N`` pixels).
    binning
        The DN bins of eq. 16.
    ddof
        0: population variance (default); 1: sample variance.

    Returns
    -------
    float
        ``omega`` [pixels]: counts^2 / pixels.
    """
    k = _bin_indices(image, binning)
    n_pixels = int(k.size)
    if n_pixels == 0:
        raise BenchSimError("omega: empty image")
    n_bins = binning.n_bins
    if not 0 <= ddof < n_bins:
        raise BenchSimError(f"ddof = {ddof}: must lie in 0..{n_bins - 1}")
    # the occupied bins' counts (empty bins add 0 to the sum of squares): counted in place up to
    # BINCOUNT_MAX_BINS bins, sorted beyond (a 32-bit word's 2**32 bins)
    counts = np.bincount(k) if n_bins <= BINCOUNT_MAX_BINS else np.unique(k, return_counts=True)[1]
    sum_sq = int(np.sum(counts.astype(np.int64) ** 2))
    # L * sum((e_k - P/L)^2) = L * sum(e_k^2) - P^2, exact in Python integers
    scaled_ss = n_bins * sum_sq - n_pixels * n_pixels
    return float(Fraction(scaled_ss, n_bins * (n_bins - ddof) * n_pixels))


@dataclass(frozen=True)
class Eq18Result:
    """The three values of Table 1 and whether eq. 18, ``omega(HDR) < min(omega1, omega2)``, holds."""

    omega1: float
    omega2: float
    omega_hdr: float
    holds: bool
    stage_binning: Binning
    hdr_binning: Binning
    ddof: int

    def as_dict(self) -> dict[str, object]:
        return {
            "omega_gamma1": self.omega1,
            "omega_gamma2": self.omega2,
            "omega_hdr": self.omega_hdr,
            "eq18_holds": self.holds,
            "stage_binning": self.stage_binning.as_dict(),
            "hdr_binning": self.hdr_binning.as_dict(),
            "variance": "population (ddof=0)" if self.ddof == 0 else f"ddof={self.ddof}",
        }


def evaluate_eq18(
    gamma1: ArrayLike,
    gamma2: ArrayLike,
    hdr: ArrayLike,
    *,
    mu1: int,
    mu2: int,
    beta: int,
    hdr_mode: Literal["rescaled", "integer"] = "rescaled",
    ddof: int = 0,
) -> Eq18Result:
    """Compute ``omega`` (eq. 17) of ``Gamma1``, ``Gamma2``, ``Gamma_HDR`` and test eq. 18.

    Parameters
    ----------
    gamma1, gamma2
        Stage images [DN], ``beta``-bit.
    hdr
        Fused image [DN, stage-``mu2`` units].
    mu1, mu2, beta
        Stages and output word length [bits].
    hdr_mode
        Binning of the HDR image, see :func:`hdr_binning`.
    ddof
        Variance of the counts: 0 population, 1 sample.
    """
    sb = stage_binning(beta)
    hb = hdr_binning(beta, mu1, mu2, hdr_mode)
    o1 = omega_eq17(gamma1, sb, ddof)
    o2 = omega_eq17(gamma2, sb, ddof)
    oh = omega_eq17(hdr, hb, ddof)
    return Eq18Result(o1, o2, oh, bool(oh < min(o1, o2)), sb, hb, ddof)
