"""Truth-scored fusion of one pass: eq. 11 and the clip-aware rule against the exact truth.

For a pass run with its truth (``run_pass(..., truth=True)``) :func:`fusion_scores` fuses stages
``fusion.mu1`` and ``fusion.mu2`` by eq. 11 (:func:`bench_sim.fusion.stage_pair.fuse_stage_words`,
the paper's rule) and by the highest unclipped stage
(:func:`bench_sim.fusion.multistage.fuse_stages_highest_unsaturated`, ``criterion="clip"``, plain
and with a noise margin below the clip), and
scores both against the true HDR target -- the stage-``mu2`` signal without any clip
(:func:`bench_sim.fusion.stage_pair.true_hdr_dn`: ``linear_dn`` less the stage's offset) -- with
the functions of
:mod:`bench_sim.metrics.fusion_truth`: relative error per region (whole image, under the spot,
under the fill, the spot's edge), the pixels taken from a clipped stage (by the truth's
``clipped``, and by the word at its top, the count anyone can redo from ``gamma1.tiff`` and
``gamma2.tiff``), and the TDI window's light ratio ``r`` that explains them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.fusion.common import FusionResult
from bench_sim.fusion.multistage import fuse_stages_highest_unsaturated
from bench_sim.fusion.stage_pair import stage_offsets_dn, true_hdr_dn
from bench_sim.metrics.fusion_truth import (
    CLIP_MARGIN_SIGMAS,
    LIGHT_RATIO_TOLERANCE,
    error_summary,
    from_clipped_stage,
    illumination_regions,
    relative_error,
    tdi_light_ratio,
)
from bench_sim.pipeline import PassResult
from bench_sim.sensor.model import dark_noise_e, stage_variance_dn2, word_clip_dn

__all__ = ["FusionScores", "fusion_scores", "RULES", "clip_margin_dn"]

#: the rules compared: name -> what the report calls it
RULES = {
    "eq11": "eq. 11 (the paper's)",
    "clip": "highest unclipped stage (clip-aware)",
    "clip_margin": "highest stage below its clip by a noise margin",
}


def clip_margin_dn(cfg: BenchConfig, m: int, top_signal_dn: float) -> float:
    """:data:`CLIP_MARGIN_SIGMAS` temporal standard deviations [DN] of stage ``m`` at its clip
    (:func:`bench_sim.sensor.model.stage_variance_dn2`): a value this far below the clip is
    clipped in none of its noise draws but a fraction ``~3e-5``."""
    s = cfg.sensor
    e_read = top_signal_dn / (m * s.conversion_gain_dn_per_e)
    var = stage_variance_dn2(
        m, e_read, conversion_gain_dn_per_e=s.conversion_gain_dn_per_e,
        dark_noise_e=dark_noise_e(s, cfg.timing.t_int_s), quantization=s.quantization,
        shot_noise=s.shot_noise,
    )
    return CLIP_MARGIN_SIGMAS * float(np.sqrt(var))


@dataclass(frozen=True)
class FusionScores:
    """What :func:`fusion_scores` returns.

    Attributes
    ----------
    summary
        ``metrics.json``'s ``fusion_truth`` entry: ``light_ratio`` (median, 1st and 99th
        percentiles, largest ``|r - 1|``, the fraction of pixels outside ``1 +- tolerance``),
        and per rule of :data:`RULES`: ``error`` (bias and RMS relative error per region),
        ``from_clipped_fraction`` (truth), ``from_word_top_fraction`` (count from the images)
        and ``from_clipped_pixels``.
    maps
        (lines, columns) arrays: ``relative_error_eq11``,
        ``relative_error_clip``, ``relative_error_clip_margin``, ``from_clipped_<rule>``,
        ``light_ratio``.
    """

    summary: dict[str, Any]
    maps: dict[str, np.ndarray] = field(repr=False)


def _light_summary(ratio: np.ndarray, tol: float) -> dict[str, float]:
    r = ratio[np.isfinite(ratio)]
    if not r.size:
        return {"median": float("nan"), "p01": float("nan"), "p99": float("nan"), "max_abs_dev": 0.0,
                "outside_fraction": 0.0, "tolerance": tol}
    p01, med, p99 = np.percentile(r, [1.0, 50.0, 99.0])
    return {"median": float(med), "p01": float(p01), "p99": float(p99),
            "max_abs_dev": float(np.max(np.abs(r - 1.0))),
            "outside_fraction": float(np.mean(np.abs(r - 1.0) > tol)), "tolerance": tol}


def fusion_scores(cfg: BenchConfig, sim: PassResult, eq11: FusionResult) -> FusionScores:
    """Score eq. 11 (``eq11``, offsets removed as in ``reproduce``) and the clip-aware rule on
    the same pass against its truth (see the module docstring), and the clip-aware rule with a
    noise margin (:data:`CLIP_MARGIN_SIGMAS`): a stage value just below its clip is biased low by
    the draws that clipped, so the plain rule still takes biased values."""
    mu1, mu2, beta = cfg.fusion.mu1, cfg.fusion.mu2, cfg.dtdi.beta_bits
    off = stage_offsets_dn(cfg, (mu1, mu2))
    top = word_clip_dn(beta)
    words = {m: sim.stage_dn[m] for m in (mu1, mu2)}
    signal = {m: words[m].astype(np.float64) - off[m] for m in (mu1, mu2)}
    clip_rule = fuse_stages_highest_unsaturated(
        signal, beta=beta, criterion="clip", saturation_dn={m: top - off[m] for m in (mu1, mu2)}
    )
    margin_rule = fuse_stages_highest_unsaturated(
        signal, beta=beta, criterion="clip",
        saturation_dn={m: top - off[m] - clip_margin_dn(cfg, m, top - off[m]) for m in (mu1, mu2)},
    )
    truth = true_hdr_dn(cfg, sim.stage_array("linear_dn", mu2))
    photons = {m: sim.stage_array("photons", m) for m in (mu1, mu2)}
    ratio = tdi_light_ratio(photons[mu1], photons[mu2], mu1, mu2)
    regions = illumination_regions(photons[mu2], sim.stage_array("reflectance", mu2), ratio)
    clipped = {m: sim.stage_array("clipped", m) for m in (mu1, mu2)}
    at_top = {m: words[m] >= top for m in (mu1, mu2)}
    summary: dict[str, Any] = {
        "light_ratio": _light_summary(ratio, LIGHT_RATIO_TOLERANCE),
        "region_pixels": {k: int(v.sum()) for k, v in regions.items()},
        "rules": {},
    }
    maps: dict[str, np.ndarray] = {"light_ratio": ratio}  # the figures' maps (not the truth: 8 MiB)
    for name, fused in (("eq11", eq11), ("clip", clip_rule), ("clip_margin", margin_rule)):
        err = relative_error(fused.hdr, truth)
        from_clip = from_clipped_stage(fused.source, clipped)
        summary["rules"][name] = {
            "label": RULES[name],
            "error": error_summary(err, regions),
            "from_clipped_fraction": float(from_clip.mean()),
            "from_clipped_pixels": int(from_clip.sum()),
            "from_word_top_fraction": float(from_clipped_stage(fused.source, at_top).mean()),
            "source_mu2_fraction": float(np.mean(fused.source == mu2)),
        }
        maps[f"relative_error_{name}"] = err
        maps[f"from_clipped_{name}"] = from_clip
    return FusionScores(summary, maps)
