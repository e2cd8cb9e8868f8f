"""Figures of the reproduction: Fig. 3 (stage sweep) and Fig. 4 (Gamma_HDR and Gamma_TRA with
insets). Matplotlib with the Agg backend; written atomically as PNG with provenance."""

from __future__ import annotations

import gc
import io
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.io import atomic_path

__all__ = ["stage_display", "fig3_stages", "fig4_hdr", "Box", "import_in_background"]

#: (line0, line1, col0, col1) of an inset, in output-image pixels
Box = tuple[int, int, int, int]
#: Largest canvas of Fig. 3 [pixels]: panels of many lines are drawn at a lower resolution
MAX_FIGURE_PIXELS = 2.0e6


def _import_matplotlib() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot  # noqa: F401


def import_in_background() -> None:
    """Import matplotlib (Agg) in a background thread, so that a caller drawing figures at its
    end does not wait for the import (about a second) after its computation."""
    import threading

    threading.Thread(target=_import_matplotlib, name="bench_sim-import-matplotlib", daemon=True).start()


def stage_display(stage_dn: np.ndarray, beta: int, gamma: float = 2.2) -> np.ndarray:
    """One display scale for every stage image: ``(DN / (2**beta - 1)) ** (1/gamma)`` in 0..1
    (float32)."""
    x = np.asarray(stage_dn, dtype=np.float32) / np.float32(2**beta - 1)
    np.clip(x, 0.0, 1.0, out=x)
    return x ** np.float32(1.0 / gamma)


def _for_display(img: np.ndarray, panel_px: float) -> np.ndarray:
    """``img`` area-averaged by the largest whole factor that keeps it at least ``panel_px``
    pixels wide: what a panel of that width cannot show anyway (the figure resamples less)."""
    from bench_sim.rig.target_sources import area_resize

    h, w = img.shape
    f = max(1, int(w // panel_px))
    return img if f == 1 else area_resize(img, max(h // f, 1), w // f)


def _save(fig: Any, path: Path, meta: Mapping[str, Any]) -> None:
    """Write ``fig`` as PNG and close it (its memory is given back now, not at the next cyclic
    garbage collection)."""
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=fig.dpi, metadata={"Description": json.dumps(meta, sort_keys=True)})
    plt.close(fig)
    gc.collect()
    with atomic_path(path) as tmp:
        tmp.write_bytes(buf.getvalue())


def fig3_stages(
    stages: Mapping[int, np.ndarray], order: Sequence[int], beta: int, path: Path, meta: Mapping[str, Any]
) -> Path:
    """Fig. 3: the stage images ``order`` (e.g. 5, 10, ..., 100) in a grid, one display scale
    (:func:`stage_display`), each panel labelled ``(a) m = 5`` etc. The canvas holds at most
    :data:`MAX_FIGURE_PIXELS` (110 dpi up to that), and each image is area-averaged to what its
    panel can show before it is drawn."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(order)
    cols = 5
    rows = -(-n // cols)
    h, w = next(iter(stages.values())).shape
    panel_in = 2.4
    size_in = (cols * panel_in, rows * panel_in * h / w + 0.6)
    # at most MAX_FIGURE_PIXELS: long runs (tall panels) get a lower resolution, not a larger canvas
    dpi = min(110.0, math.sqrt(MAX_FIGURE_PIXELS / (size_in[0] * size_in[1])))
    fig, axes = plt.subplots(rows, cols, figsize=size_in, dpi=dpi)
    for k, ax in enumerate(np.atleast_1d(axes).ravel()):
        ax.set_axis_off()
        if k >= n:
            continue
        m = order[k]
        img = _for_display(stages[m], panel_in * dpi)  # mean DN over the pixels a dot shows
        ax.imshow(stage_display(img, beta), cmap="gray", vmin=0, vmax=1, interpolation="antialiased")
        ax.set_title(f"({chr(ord('a') + k)}) m = {m}", fontsize=9, y=1.0)  # y: no auto placement
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
        # area-averaged to what the axes show; extent keeps the full-resolution coordinates
        h, w = img.shape
        box = ax.get_window_extent()
        shown = _for_display(img, w * min(box.width / w, box.height / h))
        ax.imshow(shown, cmap="gray", vmin=0, vmax=1, extent=(-0.5, w - 0.5, h - 0.5, -0.5))
        ax.set_title(title, fontsize=10, y=1.0)
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
