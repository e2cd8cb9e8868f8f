"""A fused HDR image judged against its exact truth, and where eq. 11's assumption breaks.

Eq. 11 takes ``Gamma2`` where ``Gamma1`` predicts it inside the word and ``(mu2/mu1) Gamma1``
elsewhere. Both branches aim at the same value: the stage-``mu2`` signal without any clip, which
the pass's truth knows exactly (``linear_dn`` of stage ``mu2`` less its offset, in DN). Against
it this module measures:

- :func:`relative_error`: ``(Gamma_HDR - truth) / truth`` per pixel;
- :func:`error_summary`: bias (mean) and RMS of that error over regions;
- :func:`from_clipped_stage`: the pixels the fusion took from a stage that clipped there;
- :func:`tdi_light_ratio`: ``r = (photons_mu2 / mu2) / (photons_mu1 / mu1)``, the mean light per
  row over the ``mu2`` rows of the TDI window against that over its first ``mu1`` rows. Eq. 11
  assumes ``Gamma2 = (mu2/mu1) Gamma1``, i.e. ``r = 1``; where the illumination changes along the
  track inside the window (the edge of a spot) ``r != 1`` and the branch taken from ``Gamma1``
  is off by the factor ``r`` (relative error ``1/r - 1``), while ``Gamma2`` may already clip
  where ``Gamma1`` says it does not;
- :func:`illumination_regions`: the pixels under the spot, under the fill (:func:`light_regions`)
  and at the spot's edge, from the truth's illumination (photons per unit reflectance) and the
  light ratio; :func:`clip_regions`: where a fusion has to switch, can, or cannot give the truth;
- :func:`clear_of_clips`: where a stage is clear of its clips (every clip, pixel, ADC or word,
  takes less from its expectation than from a normal read :data:`CLIP_MARGIN_SIGMAS` standard
  deviations below a clip), and :func:`clip_flags` of two fused stages.

All functions are pure (arrays in, arrays or numbers out).

References
----------
An HDR Imaging Method With DTDI Technology for Push-Broom Cameras, eq. 9-11 (the fusion and its
assumption ``Gamma_mu2 = (mu2/mu1) Gamma_mu1``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "relative_error",
    "error_summary",
    "from_clipped_stage",
    "tdi_light_ratio",
    "illumination_regions",
    "light_regions",
    "clip_regions",
    "TRUTH_REGIONS",
    "LIGHT_RATIO_TOLERANCE",
    "CLIP_MARGIN_SIGMAS",
    "clip_shortfall",
    "clear_of_clips",
    "clip_flags",
]

#: |r - 1| above which the TDI window's light counts as changing (the spot's edge)
LIGHT_RATIO_TOLERANCE = 0.05
#: The regions a fusion is scored over against its truth: :func:`illumination_regions`, then
#: :func:`clip_regions`
TRUTH_REGIONS = ("whole", "spot", "fill", "spot_edge", "clipped", "recoverable", "lost")


def relative_error(hdr: ArrayLike, truth: ArrayLike, floor: float = 1.0) -> np.ndarray:
    """``(hdr - truth) / truth`` [1]; ``nan`` where the truth is below ``floor`` [DN]."""
    h = np.asarray(hdr, dtype=np.float64)
    t = np.asarray(truth, dtype=np.float64)
    out = np.full(np.broadcast(h, t).shape, np.nan)
    ok = t >= floor
    np.divide(h - t, t, out=out, where=ok)
    return out


def error_summary(err: ArrayLike, regions: dict[str, np.ndarray]) -> dict[str, dict[str, float | None]]:
    """Per region: ``bias`` (mean relative error), ``rms`` (root mean square), ``pixels``.

    ``None`` for a region without a finite pixel."""
    e = np.asarray(err, dtype=np.float64)
    out: dict[str, dict[str, float | None]] = {}
    for name, mask in regions.items():
        v = e[np.asarray(mask, dtype=bool) & np.isfinite(e)]
        out[name] = {
            "bias": float(v.mean()) if v.size else None,
            "rms": float(np.sqrt(np.mean(v * v))) if v.size else None,
            "pixels": int(v.size),
        }
    return out


def from_clipped_stage(source: ArrayLike, clipped: Mapping[int, ArrayLike]) -> np.ndarray:
    """Pixels whose fused value came from a stage that clipped there: ``clipped[source]``.

    Parameters
    ----------
    source
        The stage each fused pixel came from.
    clipped
        Stage -> boolean map of its clipped pixels (the truth's ``clipped``, or the word at its
        top counted from the stage image).
    """
    src = np.asarray(source)
    out = np.zeros(src.shape, dtype=bool)
    for m, c in clipped.items():
        out |= (src == m) & np.asarray(c, dtype=bool)
    return out


def tdi_light_ratio(photons_mu1: ArrayLike, photons_mu2: ArrayLike, mu1: int, mu2: int) -> np.ndarray:
    """``r = (photons_mu2 / mu2) / (photons_mu1 / mu1)`` [1] per scene line and column.

    ``photons_m`` is the truth's mean photons of the stage-``m`` pixel (the sum over its ``m``
    rows), so ``r`` is the mean light per row over the ``mu2`` rows relative to the first ``mu1``
    rows; ``nan`` where stage ``mu1`` saw no light.
    """
    p1 = np.asarray(photons_mu1, dtype=np.float64) / int(mu1)
    p2 = np.asarray(photons_mu2, dtype=np.float64) / int(mu2)
    out = np.full(p1.shape, np.nan)
    np.divide(p2, p1, out=out, where=p1 > 0)
    return out


def light_regions(
    photons: ArrayLike, reflectance: ArrayLike, min_reflectance: float = 0.02
) -> dict[str, np.ndarray]:
    """Boolean maps ``whole``, ``spot`` and ``fill`` of a stage image from its truth's light.

    The illumination is ``E = photons / reflectance`` (photons per unit reflectance of the stage
    pixel, where the reflectance exceeds ``min_reflectance``). ``spot`` is where ``E`` exceeds the
    geometric mean of the fill (its 10th percentile) and the peak (its 99.5th percentile), when
    the peak is at least 1.5 times the fill; ``fill`` the rest of the lit pixels.
    """
    p = np.asarray(photons, dtype=np.float64)
    rho = np.asarray(reflectance, dtype=np.float64)
    lit = rho > min_reflectance
    whole = np.ones(p.shape, dtype=bool)
    if not lit.any():
        empty = np.zeros(p.shape, dtype=bool)
        return {"whole": whole, "spot": empty, "fill": empty.copy()}
    e = np.full(p.shape, np.nan)
    np.divide(p, rho, out=e, where=lit)
    fill_level, peak = np.percentile(e[lit], [10.0, 99.5])
    split = np.sqrt(max(fill_level, 1e-300) * peak)
    spot = lit & (e > split) if peak > 1.5 * fill_level else np.zeros(p.shape, dtype=bool)
    return {"whole": whole, "spot": spot, "fill": lit & ~spot}


def illumination_regions(
    photons: ArrayLike, reflectance: ArrayLike, ratio: ArrayLike, tolerance: float = LIGHT_RATIO_TOLERANCE,
    min_reflectance: float = 0.02,
) -> dict[str, np.ndarray]:
    """Boolean maps ``whole``, ``spot``, ``fill`` (:func:`light_regions`) and ``spot_edge`` of the
    image: ``spot_edge`` is where the TDI window's light ratio leaves ``1 +- tolerance``
    (:func:`tdi_light_ratio`), whatever the level.
    """
    r = np.asarray(ratio, dtype=np.float64)
    edge = np.isfinite(r) & (np.abs(r - 1.0) > tolerance)
    return {**light_regions(photons, reflectance, min_reflectance), "spot_edge": edge}


def clip_regions(flags: ArrayLike) -> dict[str, np.ndarray]:
    """Boolean maps ``clipped``, ``recoverable`` and ``lost`` of a fused image from its
    :func:`clip_flags` (``stage_clip_flags``): ``clipped`` where some fused stage is not clear of
    its clips and some is (where a fusion has to switch, and can err), ``recoverable`` where some
    stage is clear (``flags < 3``), ``lost`` where none is (no fusion of the words gives the truth)."""
    f = np.asarray(flags)
    ok = f < 3
    return {"clipped": (f > 0) & ok, "recoverable": ok, "lost": f == 3}


#: The margin below a clip [standard deviations of the temporal noise] at which a stage counts as
#: clear of its clips: a normal value this far below its clip is clipped in a fraction 3e-5 of its
#: draws
CLIP_MARGIN_SIGMAS = 4.0


def clip_shortfall(sigmas: float = CLIP_MARGIN_SIGMAS) -> float:
    """What one clip takes from the mean of a normal variable ``k = sigmas`` standard deviations
    below it, in standard deviations: ``E[(X - c)+] / sigma = phi(k) - k Q(k)`` (``Q`` the
    normal's upper tail): 7.1e-6 at ``k = 4``."""
    k = float(sigmas)
    return math.exp(-0.5 * k * k) / math.sqrt(2.0 * math.pi) - k * 0.5 * math.erfc(k / math.sqrt(2.0))


def clear_of_clips(
    linear_dn: ArrayLike, mean_dn: ArrayLike, noise_std_dn: ArrayLike, sigmas: float = CLIP_MARGIN_SIGMAS
) -> np.ndarray:
    """Where a stage is clear of its clips (bool), from its truth: the clips take less from its
    expectation than one clip takes from a normal value ``sigmas`` standard deviations below it,
    ``linear_dn - mean_dn <= clip_shortfall(sigmas) * noise_std_dn``.

    ``linear_dn`` is the stage word's expectation without any clip, ``mean_dn`` with every clip
    (the reads' full well and ADC top, the word's top), so their difference is what the clips
    take, whichever clips; it is 0 (to rounding) where none is near. With a non-linear response
    (a chain's ``nonlinearity``) the response's shortfall from its small-signal slope counts too.

    Parameters
    ----------
    linear_dn, mean_dn, noise_std_dn
        The stage's truth [DN] (:data:`bench_sim.pipeline.PASS_VARIABLES`).
    sigmas
        The margin [standard deviations].
    """
    lin = np.asarray(linear_dn, dtype=np.float64)
    short = lin - np.asarray(mean_dn, dtype=np.float64)
    # rounding of the two closed forms far from any clip: 1e-12 of the level
    return short <= clip_shortfall(sigmas) * np.asarray(noise_std_dn, dtype=np.float64) + 1e-12 * np.abs(lin)


def clip_flags(clear_mu1: ArrayLike, clear_mu2: ArrayLike) -> np.ndarray:
    """Per pixel of a fused image (uint8): bit 0 set where stage ``mu1`` is not clear of its clips,
    bit 1 where stage ``mu2`` is not (:func:`clear_of_clips`); 3: neither stage can give the
    true value."""
    c1 = np.asarray(clear_mu1, dtype=bool)
    c2 = np.asarray(clear_mu2, dtype=bool)
    return ((~c1).astype(np.uint8) | ((~c2).astype(np.uint8) << 1)).astype(np.uint8)
