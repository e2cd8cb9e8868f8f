"""Fig. 4's inset captions, each from what was measured inside the box it captions.

The dark insets (Gamma1 and Gamma_TRA over the darkest wedge steps) state the spatial SNR (mean /
standard deviation over the patch) of the darkest wedge step lying wholly inside the dark box (or,
when none does, over the whole box); the bright insets (Gamma2 and Gamma_TRA over the bar group)
state the fraction of the bright box's pixels at the top of the word, and for Gamma_HDR the fraction
taken from a Gamma2 at the word's top, counted in the same box. :func:`inset_facts` measures,
:func:`inset_captions` words the numbers, :func:`pass_inset_captions` does both for a pass.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from bench_sim.measure.pass_metrics import patch_slices, spatial_snr
from bench_sim.sensor.model import stage_offset_dn
from bench_sim.workflows.reproduce.wording import pct

__all__ = ["InsetFacts", "inset_facts", "inset_captions", "pass_inset_captions"]

#: (line0, line1, col0, col1) of an inset, in output-image pixels
Box = tuple[int, int, int, int]


@dataclass(frozen=True)
class InsetFacts:
    """What was measured inside Fig. 4's two boxes.

    ``dark_region``: the wedge step (patch name) inside the dark box the SNRs are measured on, or
    ``"box"`` when no step lies wholly inside it; ``dark_reflectance`` its reflectance (NaN for the
    box); ``dark_snr``: spatial SNR of ``gamma1`` and ``gamma_hdr`` there. ``bright_word_top``:
    fraction of the bright box's pixels at the word's top in ``gamma2`` and ``gamma_hdr`` (where
    Gamma1 is at the top); ``bright_from_clipped_gamma2``: fraction of the bright box's
    Gamma_HDR pixels taken from a Gamma2 at the word's top.
    """

    dark_region: str
    dark_reflectance: float
    dark_snr: dict[str, float]
    bright_word_top: dict[str, float]
    bright_from_clipped_gamma2: float


def _inside(sl: tuple[slice, slice], box: Box) -> bool:
    lines_in = box[0] <= sl[0].start and sl[0].stop <= box[1]
    return bool(lines_in and box[2] <= sl[1].start and sl[1].stop <= box[3])


def inset_facts(
    gamma1: np.ndarray, gamma_hdr: np.ndarray, gamma2_at_top: np.ndarray, hdr_at_top: np.ndarray,
    hdr_from_gamma2: np.ndarray, dark_box: Box, bright_box: Box,
    patches: Mapping[str, tuple[slice, slice]], reflectance: Mapping[str, float],
) -> InsetFacts:
    """Measure Fig. 4's boxes.

    Parameters
    ----------
    gamma1, gamma_hdr
        Gamma1 (offset removed) and Gamma_HDR [DN], shape (lines, columns).
    gamma2_at_top, hdr_at_top
        Where Gamma2's word is at its top, and where Gamma_HDR is (Gamma1 at its top) [bool].
    hdr_from_gamma2
        Where Gamma_HDR's pixel is Gamma2's [bool].
    dark_box, bright_box
        The insets' boxes (line0, line1, col0, col1).
    patches, reflectance
        Wedge step -> its (line, column) slices in the image, and its reflectance.
    """
    inside = {k: sl for k, sl in patches.items() if _inside(sl, dark_box)}
    if inside:  # the darkest step in the box, as lit (lowest mean of Gamma_HDR)
        name = min(inside, key=lambda k: float(np.mean(gamma_hdr[inside[k]])))
        region, refl = inside[name], float(reflectance.get(name, float("nan")))
    else:
        name, refl = "box", float("nan")
        region = (slice(dark_box[0], dark_box[1]), slice(dark_box[2], dark_box[3]))
    b = (slice(bright_box[0], bright_box[1]), slice(bright_box[2], bright_box[3]))
    return InsetFacts(
        dark_region=name,
        dark_reflectance=refl,
        dark_snr={"gamma1": spatial_snr(gamma1, region), "gamma_hdr": spatial_snr(gamma_hdr, region)},
        bright_word_top={
            "gamma2": float(np.mean(gamma2_at_top[b])), "gamma_hdr": float(np.mean(hdr_at_top[b]))
        },
        bright_from_clipped_gamma2=float(np.mean(hdr_from_gamma2[b] & gamma2_at_top[b])),
    )


def inset_captions(f: InsetFacts) -> list[str]:
    """The four captions (dark Gamma1, dark Gamma_TRA, bright Gamma2, bright Gamma_TRA), each
    stating what was measured inside its own box."""
    where = "over the box" if f.dark_region == "box" else f"{f.dark_reflectance:.0%} step"
    return [
        f"dark, $\\Gamma_1$: {where}, spatial SNR {f.dark_snr['gamma1']:.1f}",
        f"dark, $\\Gamma_{{TRA}}$: {where}, HDR spatial SNR {f.dark_snr['gamma_hdr']:.1f}",
        f"bright, $\\Gamma_2$: {pct(f.bright_word_top['gamma2'])} at the word's top",
        f"bright, $\\Gamma_{{TRA}}$: HDR {pct(f.bright_word_top['gamma_hdr'])} at top, "
        f"{pct(f.bright_from_clipped_gamma2)} from clipped $\\Gamma_2$",
    ]


def pass_inset_captions(
    cfg: Any, stage_images: Mapping[int, np.ndarray], fused: Any, boxes: tuple[Box, Box], panel: Any,
    geom: Any,
) -> list[str]:
    """:func:`inset_captions` of a pass for Fig. 4's ``boxes`` (the dark one, the bright one).

    Parameters
    ----------
    cfg
        The run's :class:`~bench_sim.config.BenchConfig`.
    stage_images
        Stage -> its word [DN] (with the pedestal), stages ``fusion.mu1`` and ``fusion.mu2`` at least.
    fused
        Their eq. 11 :class:`~bench_sim.fusion.common.FusionResult` (offsets removed).
    panel, geom
        The pass's target panel and rig geometry (``PassResult.setup.grid.panel``, ``.setup.geom``):
        where the wedge steps lie.
    """
    mu1, mu2 = cfg.fusion.mu1, cfg.fusion.mu2
    top = 2**cfg.dtdi.beta_bits - 1
    g1, g2 = stage_images[mu1], stage_images[mu2]
    patches = {k: v for k, v in patch_slices(panel, geom, cfg, cfg.lines).items() if k.startswith("wedge_")}
    facts = inset_facts(
        g1 - stage_offset_dn(cfg.sensor, cfg.dtdi, mu1), fused.hdr, g2 >= top, np.asarray(fused.saturated),
        np.asarray(fused.source) == fused.unit_stage, boxes[0], boxes[1], patches,
        {p.name: p.reflectance for p in panel.patches},
    )
    return inset_captions(facts)
