"""Score any fusion of a dataset's stage words against the true HDR target, over a split.

:func:`score_fusion` ``(DIR, fuse, split="test")`` applies ``fuse`` to every sample of the split
(a function of a :class:`~bench_sim.workflows.dataset.reader.Sample` that returns its fused image
in stage-``mu2`` DN, offsets removed, or the name of a stored image variable such as
``"gamma_hdr"`` or ``"eq11_expected_dn"``) and measures its relative error against the sample's
``true_hdr_dn`` (:func:`bench_sim.metrics.fusion_truth.relative_error`: nan where the truth is
below 1 DN) per region, over all pixels of the split together:

============== ===================================================================================
``whole``      every pixel
``spot``       under the spot, ``fill`` under the fill alone, ``spot_edge`` where the TDI window's
               light ratio leaves ``1 +- 5 %`` (:func:`bench_sim.metrics.fusion_truth.illumination_regions`
               of stage ``mu2``'s truth)
``clipped``    some fused stage is not clear of its clips (``stage_clip_flags > 0``) and the pixel is
               still recoverable (``hdr_recoverable``): where eq. 11 has to switch, and can err
``recoverable`` ``hdr_recoverable``: some stage is clear of its clips
``lost``       no stage is (``stage_clip_flags == 3``): no fusion of these words can give the truth
============== ===================================================================================
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.errors import BenchSimError
from bench_sim.metrics.fusion_truth import TRUTH_REGIONS, clip_regions, illumination_regions, relative_error
from bench_sim.workflows.dataset.loaders import split_samples
from bench_sim.workflows.dataset.reader import Sample, iter_samples, read_info

__all__ = ["FusionScore", "score_fusion", "REGIONS"]

#: the regions :func:`score_fusion` reports (module docstring)
REGIONS = TRUTH_REGIONS
#: what :func:`score_fusion` reads of each sample besides what ``fuse`` needs
_TRUTH = ("true_hdr_dn", "photons", "reflectance", "tdi_light_ratio", "stage_clip_flags", "hdr_recoverable")


@dataclass(frozen=True)
class FusionScore:
    """What :func:`score_fusion` measured.

    Attributes
    ----------
    split
        The split scored (``None``: every sample).
    samples
        The samples scored.
    regions
        Region -> ``{"bias": mean relative error, "rms": root mean square relative error,
        "pixels": pixels with a finite error}`` over the split (``bias`` and ``rms`` ``None``
        where a region has no pixel).
    """

    split: str | None
    samples: list[int]
    regions: dict[str, dict[str, Any]] = field(default_factory=dict)

    def table(self) -> list[list[Any]]:
        """Rows ``[region, bias, rms, pixels]`` (for printing)."""
        return [[k, v["bias"], v["rms"], v["pixels"]] for k, v in self.regions.items()]


def _regions(sample: Sample, mu2_index: int) -> dict[str, np.ndarray]:
    a = sample.arrays
    light = illumination_regions(
        a["photons"][mu2_index], a["reflectance"][mu2_index], a["tdi_light_ratio"]
    )
    return {**light, **clip_regions(a["stage_clip_flags"])}


def score_fusion(
    folder: str | Path,
    fuse: Callable[[Sample], np.ndarray] | str,
    split: str | None = "test",
    *,
    variables: list[str] | None = None,
    incomplete: bool = False,
) -> FusionScore:
    """Score a fusion against the true HDR target over a split (module docstring).

    Parameters
    ----------
    folder
        The dataset folder (two fused stages).
    fuse
        ``fuse(sample) -> (lines, columns)`` fused image [DN, stage-``mu2`` units, offsets
        removed], or the name of a stored image variable (``"gamma_hdr"``, ``"eq11_expected_dn"``).
    split
        The split (``None``: every complete sample).
    variables
        The variables ``fuse`` reads (default: all); the truth it is scored with is read besides.
    incomplete
        Score the complete samples of an incomplete dataset.

    Returns
    -------
    FusionScore
        Bias, RMS and pixels per region of :data:`REGIONS`.
    """
    info = read_info(folder)
    if not info.get("fused"):
        raise BenchSimError(f"{str(folder)!r}: no fused stages ({info.get('stages')}): nothing to score")
    mu2_index = [int(m) for m in info["stages"]].index(int(info["mu2"]))
    chosen = split_samples(folder, split, incomplete=incomplete)
    name = fuse if isinstance(fuse, str) else None
    need = None
    if variables is not None or name is not None:
        need = sorted({*(variables or []), *_TRUTH, *([name] if name else [])})
    sums = {k: [0.0, 0.0, 0] for k in REGIONS}
    for sample in iter_samples(folder, variables=need, only=chosen, incomplete=incomplete):
        hdr = sample.arrays[name] if name is not None else np.asarray(fuse(sample))  # type: ignore[operator]
        err = relative_error(hdr, sample.arrays["true_hdr_dn"])
        for region, mask in _regions(sample, mu2_index).items():
            e = err[mask & np.isfinite(err)]
            sums[region][0] += float(e.sum())
            sums[region][1] += float((e * e).sum())
            sums[region][2] += int(e.size)
    regions = {
        k: {"bias": s / n if n else None, "rms": float(np.sqrt(q / n)) if n else None, "pixels": n}
        for k, (s, q, n) in sums.items()
    }
    return FusionScore(split, list(chosen), regions)
