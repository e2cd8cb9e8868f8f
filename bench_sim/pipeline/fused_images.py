"""The image variables of a pass: the fused stages and, with the truth, the true HDR target and
what judges a fusion against it.

:func:`fused_images` turns the same lines of stages ``fusion.mu1`` and ``fusion.mu2`` (their words
and, with the truth, ``linear_dn``, ``mean_dn``, ``noise_std_dn``, ``photons``) into the image
variables of :data:`bench_sim.pipeline.PASS_VARIABLES`:

- ``gamma_hdr``, ``gamma_hdr_source``: eq. 11 of the words, every stage's offset removed
  (:func:`bench_sim.fusion.stage_pair.fuse_stage_words`, the fusion of every workflow);
- ``true_hdr_dn``: the true HDR target (:func:`bench_sim.fusion.stage_pair.true_hdr_dn`);
- ``eq11_expected_dn``: eq. 11 of the expected words (:func:`bench_sim.fusion.stage_pair.eq11_expected_dn`);
- ``stage_clip_flags``, ``hdr_recoverable``: which stage is not clear of its clips
  (:func:`bench_sim.metrics.fusion_truth.clear_of_clips`), and where some stage is;
- ``gamma_hdr_error``: ``gamma_hdr`` against ``true_hdr_dn``
  (:func:`bench_sim.metrics.fusion_truth.relative_error`);
- ``tdi_light_ratio``: :func:`bench_sim.metrics.fusion_truth.tdi_light_ratio` of the photons.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.fusion.stage_pair import eq11_expected_dn, fuse_stage_words, true_hdr_dn
from bench_sim.metrics.fusion_truth import clear_of_clips, clip_flags, relative_error, tdi_light_ratio
from bench_sim.pipeline.variables import IMAGE_DIMS, IMAGE_TRUTH_INPUTS, pass_variables

__all__ = ["fused_images"]


def fused_images(
    cfg: BenchConfig, lines1: Mapping[str, np.ndarray], lines2: Mapping[str, np.ndarray]
) -> dict[str, np.ndarray]:
    """Image variable -> its lines (module docstring), from the same lines of both fused stages
    (variable -> (n, N) lines: ``dn`` and, for the truth,
    :data:`~bench_sim.pipeline.variables.IMAGE_TRUTH_INPUTS` of both), each in its dtype of
    :data:`bench_sim.pipeline.PASS_VARIABLES`."""
    mu1, mu2 = cfg.fusion.mu1, cfg.fusion.mu2
    beta = cfg.dtdi.beta_bits
    fused = fuse_stage_words(cfg, lines1["dn"], lines2["dn"])
    dtypes = {v.name: v.array_dtype(beta) for v in pass_variables(IMAGE_DIMS, maps=True)}
    out: dict[str, np.ndarray] = {"gamma_hdr": fused.hdr, "gamma_hdr_source": fused.source}
    if all(k in lines1 and k in lines2 for k in IMAGE_TRUTH_INPUTS):
        truth = true_hdr_dn(cfg, lines2["linear_dn"])
        clear = [clear_of_clips(s["linear_dn"], s["mean_dn"], s["noise_std_dn"]) for s in (lines1, lines2)]
        flags = clip_flags(*clear)
        out.update(
            true_hdr_dn=truth,
            eq11_expected_dn=eq11_expected_dn(cfg, lines1["mean_dn"], lines2["mean_dn"]),
            stage_clip_flags=flags,
            hdr_recoverable=flags < 3,
            gamma_hdr_error=relative_error(fused.hdr, truth),
            tdi_light_ratio=tdi_light_ratio(lines1["photons"], lines2["photons"], mu1, mu2),
        )
    return {name: np.asarray(v).astype(dtypes[name], copy=False) for name, v in out.items()}
