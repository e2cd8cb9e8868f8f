"""Figures of the reproduction: Fig. 3 (stage sweep) and Fig. 4 (Gamma_HDR and Gamma_TRA with
insets). Matplotlib with the Agg backend; written atomically as PNG with provenance."""

from __future__ import annotations

import io
import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.io import atomic_path

__all__ = ["stage_display", "fig3_stages", "fig4_hdr", "Box"]

#: (line0, line1, col0, col1) of an inset, in output-image pixels
Box = tuple[int, int, int, int]


def stage_display(stage_dn: np.ndarray, beta: int, gamma: float = 2.2) -> np.ndarray:
    """One display scale for every stage image: ``(DN / (2**beta - 1)) ** (1/gamma)`` in 0..1."""
    return np.clip(np.asarray(stage_dn, dtype=np.float64) / (2**beta - 1), 0.0, 1.0) ** (1.0 / gamma)


def _save(fig: Any, path: Path, meta: Mapping[str, Any]) -> None:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=fig.dpi, metadata={"Description": json.dumps(meta, sort_keys=True)})
    with atomic_path(path) as tmp:
        tmp.write_bytes(buf.getvalue())


def fig3_stages(
    stages: Mapping[int, np.ndarray], order: Sequence[int], beta: int, path: Path, meta: Mapping[str, Any]
) -> Path:
    """Fig. 3: the stage images ``order`` (e.g. 5, 10, ..., 100) in a grid, one display scale
    (:func:`stage_display`), each panel labelled ``(a) m = 5`` etc."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(order)
    cols = 5
    rows = -(-n // cols)
    h, w = next(iter(stages.values())).shape
    fig, axes = plt.subplots(rows, cols, figsize=(cols * 2.4, rows * 2.4 * h / w + 0.6), dpi=110)
    for k, ax in enumerate(np.atleast_1d(axes).ravel()):
        ax.set_axis_off()
        if k >= n:
            continue
        m = order[k]
        ax.imshow(stage_display(stages[m], beta), cmap="gray", vmin=0, vmax=1, interpolation="antialiased")
        ax.set_title(f"({chr(ord('a') + k)}) m = {m}", fontsize=9)
    fig.suptitle(
        f"DTDI stage images, one display scale: (DN / {2**beta - 1})^(1/2.2)", fontsize=10
    )
    fig.tight_layout()
    _save(fig, path, meta)
    plt.close(fig)
    return path


def fig4_hdr(
    hdr_display: np.ndarray,
    tra: np.ndarray,
    gamma1_display: np.ndarray,
    gamma2_display: np.ndarray,
    dark_box: Box,
    bright_box: Box,
    path: Path,
    meta: Mapping[str, Any],
    tra_name: str,
) -> Path:
    """Fig. 4: (a) Gamma_HDR (linear display) and (b) Gamma_TRA side by side; below, insets of a
    dark region (Gamma1 noise vs Gamma_TRA, detail recovered from stage mu2) and of a bright
    region (Gamma2 saturated vs Gamma_TRA, detail kept from stage mu1). Inputs in 0..1."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    fig = plt.figure(figsize=(11, 9.4), dpi=110)
    grid = fig.add_gridspec(2, 4, height_ratios=[2.2, 1.0])
    big = [fig.add_subplot(grid[0, 0:2]), fig.add_subplot(grid[0, 2:4])]
    for ax, img, title in (
        (big[0], hdr_display, "(a) $\\Gamma_{HDR}$ (linear display)"),
        (big[1], tra, f"(b) $\\Gamma_{{TRA}}$ ({tra_name} transform)"),
    ):
        ax.imshow(img, cmap="gray", vmin=0, vmax=1)
        ax.set_title(title, fontsize=10)
        ax.set_axis_off()
        for box, colour in ((dark_box, "tab:cyan"), (bright_box, "tab:orange")):
            l0, l1, c0, c1 = box
            ax.add_patch(Rectangle((c0, l0), c1 - c0, l1 - l0, fill=False, ec=colour, lw=1.5))
    insets = [
        (gamma1_display, dark_box, "tab:cyan", "dark, $\\Gamma_1$: in the noise"),
        (tra, dark_box, "tab:cyan", "dark, $\\Gamma_{TRA}$: from stage $\\mu_2$"),
        (gamma2_display, bright_box, "tab:orange", "bright, $\\Gamma_2$: saturated"),
        (tra, bright_box, "tab:orange", "bright, $\\Gamma_{TRA}$: from stage $\\mu_1$"),
    ]
    for k, (img, box, colour, title) in enumerate(insets):
        ax = fig.add_subplot(grid[1, k])
        l0, l1, c0, c1 = box
        crop = img[l0:l1, c0:c1]
        lo, hi = float(np.percentile(crop, 0.5)), float(np.percentile(crop, 99.5))
        ax.imshow(crop, cmap="gray", vmin=lo, vmax=max(hi, lo + 1e-6), interpolation="nearest")
        ax.set_title(title, fontsize=9, color=colour)
        ax.set_xticks([])
        ax.set_yticks([])
        for s in ax.spines.values():
            s.set_edgecolor(colour)
            s.set_linewidth(2)
    fig.text(0.5, 0.005, "insets stretched to their own 0.5-99.5 % range", ha="center", fontsize=8)
    fig.tight_layout()
    _save(fig, path, meta)
    plt.close(fig)
    return path
