"""Figures of Gamma_HDR against its exact truth: the relative error map of eq. 11 (with the pixels
taken from a clipped stage outlined) beside the clip-aware rule's, and the TDI window's light
ratio map (:mod:`bench_sim.measure.fusion_scores`). Matplotlib, Agg backend, PNG with the
provenance (:func:`bench_sim.io.write_figure_png`)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.io import write_figure_png

__all__ = [
    "truth_error_figure", "light_ratio_figure", "write_truth_figures", "ERROR_FIGURE", "LIGHT_RATIO_FIGURE"
]

ERROR_FIGURE = "gamma_hdr_error.png"
LIGHT_RATIO_FIGURE = "tdi_light_ratio.png"
#: a map's panel is at most this many times as tall as wide (a longer run is drawn smaller, so the
#: canvas, and the memory it takes, stops growing with the lines)
MAX_PANEL_ASPECT = 2.0


def _panel_height_in(shape: tuple[int, ...]) -> float:
    """The figure's height [inches] for a map of ``shape`` (lines, columns) in 5.5-inch panels."""
    h, w = shape
    return 1.2 + 5.5 * min(h / max(w, 1), MAX_PANEL_ASPECT)


def truth_error_figure(maps: Mapping[str, np.ndarray], path: Path, meta: Mapping[str, Any]) -> Path:
    """Relative error ``(Gamma_HDR - truth) / truth`` of eq. 11 and of the clip-aware rules, on
    one diverging scale of +-50 %; eq. 11's pixels taken from a clipped stage in black contour."""
    import matplotlib.pyplot as plt

    titles = {"eq11": "eq. 11 (paper)", "clip": "highest unclipped stage", "clip_margin": "clip with margin"}
    panels = [(f"relative_error_{k}", t) for k, t in titles.items() if f"relative_error_{k}" in maps]
    height = _panel_height_in(maps["relative_error_eq11"].shape)
    fig, axes = plt.subplots(1, len(panels), figsize=(5.5 * len(panels), height), dpi=110, squeeze=False)
    im = None
    for ax, (key, title) in zip(axes[0], panels, strict=True):
        im = ax.imshow(maps[key], cmap="RdBu_r", vmin=-0.5, vmax=0.5, interpolation="nearest")
        if key.endswith("eq11") and maps["from_clipped_eq11"].any():
            ax.contour(maps["from_clipped_eq11"].astype(float), levels=[0.5], colors="k", linewidths=0.6)
        ax.set_title(f"{title}: (HDR - truth) / truth", fontsize=9)
        ax.set_xlabel("column")
        ax.set_ylabel("scene line")
    if im is not None:
        fig.colorbar(im, ax=axes[0].tolist(), shrink=0.8, label="relative error [1]")
    return write_figure_png(path, fig, meta, dpi=fig.dpi)


def light_ratio_figure(ratio: np.ndarray, tolerance: float, path: Path, meta: Mapping[str, Any]) -> Path:
    """The light ratio ``r`` (mean light per row over the mu2 rows / over the mu1 rows) per scene
    line and column, with the tolerance band's edge ``|r - 1| = tolerance`` outlined."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, _panel_height_in(ratio.shape)), dpi=110)
    finite = ratio[np.isfinite(ratio)]
    span = float(np.max(np.abs(np.log2(finite)))) if finite.size else 1.0
    span = max(span, 2 * tolerance)
    im = ax.imshow(np.log2(ratio), cmap="PuOr_r", vmin=-span, vmax=span, interpolation="nearest")
    outside = (np.abs(ratio - 1.0) > tolerance).astype(float)
    if outside.any():
        ax.contour(outside, levels=[0.5], colors="k", linewidths=0.6)
    ax.set_title(f"TDI window light ratio r (contour: |r - 1| = {tolerance:g})", fontsize=9)
    ax.set_xlabel("column")
    ax.set_ylabel("scene line")
    fig.colorbar(im, ax=ax, shrink=0.8, label="log2 r")
    return write_figure_png(path, fig, meta, dpi=fig.dpi)


def write_truth_figures(scores: Any, out: Path, meta: Mapping[str, Any]) -> None:
    """Both figures of a :class:`bench_sim.measure.fusion_scores.FusionScores` into ``out``."""
    truth_error_figure(scores.maps, out / ERROR_FIGURE, meta)
    tol = float(scores.summary["light_ratio"]["tolerance"])
    light_ratio_figure(scores.maps["light_ratio"], tol, out / LIGHT_RATIO_FIGURE, meta)
