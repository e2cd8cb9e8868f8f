"""Fusion stage: stage images [DN] -> HDR image [DN, top-stage units] -> display image.

* :mod:`bench_sim.fusion.paper` - the paper's rule, eq. 11 (:func:`fuse_dtdi_hdr_eq11`).
* :mod:`bench_sim.fusion.stage_pair` - eq. 11 of one bench's two stage words with their offsets
  removed (:func:`fuse_stage_words`, what every workflow fuses with), the true HDR target
  (:func:`true_hdr_dn`) and eq. 11 of the expected words (:func:`eq11_expected_dn`).
* :mod:`bench_sim.fusion.methods` - the two-stage rules by name (``eq11``, ``clip``), :data:`FUSE_METHODS`.
* :mod:`bench_sim.fusion.multistage` - more than two stages (highest unsaturated stage) and the
  inverse-variance merge.
* :mod:`bench_sim.fusion.classic` - Debevec-Malik and Mertens merges from OpenCV, for comparison.
* :mod:`bench_sim.fusion.tonemap` - ``Gamma_TRA`` display transforms and tone-mapping operators.
"""

from bench_sim.fusion.classic import merge_debevec_opencv, merge_mertens_opencv
from bench_sim.fusion.common import FusionResult
from bench_sim.fusion.methods import FUSE_METHODS, check_fuse_method, fuse_pair
from bench_sim.fusion.multistage import (
    fuse_stages_highest_unsaturated,
    fuse_stages_inverse_variance,
)
from bench_sim.fusion.paper import eq11_threshold_dn, fuse_dtdi_hdr_eq11
from bench_sim.fusion.stage_pair import (
    eq11_expected_dn,
    eq11_signal_threshold_dn,
    fuse_stage_words,
    stage_offsets_dn,
    true_hdr_dn,
)
from bench_sim.fusion.tonemap import TONEMAP_METHODS, gamma_tra, quantize_display, tone_map

__all__ = [
    "FusionResult",
    "FUSE_METHODS",
    "check_fuse_method",
    "fuse_pair",
    "eq11_threshold_dn",
    "fuse_dtdi_hdr_eq11",
    "fuse_stage_words",
    "stage_offsets_dn",
    "eq11_signal_threshold_dn",
    "true_hdr_dn",
    "eq11_expected_dn",
    "fuse_stages_highest_unsaturated",
    "fuse_stages_inverse_variance",
    "merge_debevec_opencv",
    "merge_mertens_opencv",
    "TONEMAP_METHODS",
    "tone_map",
    "gamma_tra",
    "quantize_display",
]
