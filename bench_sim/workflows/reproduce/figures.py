"""Figures of the reproduction: Fig. 3 (stage sweep), Fig. 4 (Gamma_HDR and Gamma_TRA with
insets) and the SNR of Gamma1, Gamma2 and Gamma_HDR versus signal. Matplotlib with the Agg
backend; written atomically as PNG with the provenance in the ``bench_sim`` text chunk
(:func:`bench_sim.io.write_figure_png`)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.io import write_figure_png, write_png
from bench_sim.rig.target_sources import area_resize

__all__ = [
    "stage_display", "fig3_stages", "fig4_hdr", "fig4_layout", "snr_versus_signal_figure", "Box",
]

#: (line0, line1, col0, col1) of an inset, in output-image pixels
Box = tuple[int, int, int, int]
#: Largest canvas of Fig. 3 [pixels]: panels of many lines are drawn at a lower resolution
MAX_FIGURE_PIXELS = 2.0e6


def stage_display(stage_dn: np.ndarray, beta: int, gamma: float = 2.2) -> np.ndarray:
    """One display scale for every stage image: ``(DN / (2**beta - 1)) ** (1/gamma)`` in 0..1
    (float32)."""
    x = np.asarray(stage_dn, dtype=np.float32) / np.float32(2**beta - 1)
    np.clip(x, 0.0, 1.0, out=x)
    return x ** np.float32(1.0 / gamma)


def _save(path: Path, fig: Any, meta: Mapping[str, Any]) -> Path:
    """:func:`bench_sim.io.write_figure_png`, which closes the figure. (No ``gc.collect()``
    after it: 0.07 s a figure, and the run's peak memory is the same without it.)"""
    return write_figure_png(path, fig, meta, dpi=fig.dpi)


def fig3_stages(
    stages: Mapping[int, np.ndarray], order: Sequence[int], beta: int, path: Path, meta: Mapping[str, Any]
) -> Path:
    """Fig. 3: the stage images ``order`` (e.g. 5, 10, ..., 100) in a grid, one display scale
    (:func:`stage_display`), each panel labelled ``(a) m = 5`` etc. The canvas holds at most
    :data:`MAX_FIGURE_PIXELS` (110 dpi up to that). Matplotlib draws only the text; each image
    is area-averaged to its panel's pixels and written into the drawn canvas, pixel for pixel
    (no axes per panel, no resampling by the figure, no colour-mapped copies of the canvas)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    n = len(order)
    cols = 5
    rows = -(-n // cols)
    h, w = next(iter(stages.values())).shape
    panel_in = 2.4
    title_in, label_in, gap_in, margin_in = 0.6, 0.25, 0.04 * panel_in, 0.03
    panel_h_in = panel_in * h / w
    size_in = (cols * panel_in + (cols - 1) * gap_in + 2 * margin_in,
               title_in + rows * panel_h_in + (rows - 1) * label_in + margin_in)
    # at most MAX_FIGURE_PIXELS: long runs (tall panels) get a lower resolution, not a larger canvas
    dpi = min(110.0, math.sqrt(MAX_FIGURE_PIXELS / (size_in[0] * size_in[1])))
    fig = plt.figure(figsize=size_in, dpi=dpi)
    canvas = FigureCanvasAgg(fig)
    width_px, height_px = canvas.get_width_height()
    pw, ph = max(1, int(panel_in * dpi)), max(1, int(round(panel_h_in * dpi)))
    places = []
    for k, m in enumerate(order):
        r, c = divmod(k, cols)
        x0 = int(round((margin_in + c * (panel_in + gap_in)) * dpi))
        top_in = title_in + r * (panel_h_in + label_in)  # from the top of the figure
        places.append((m, x0, int(round(top_in * dpi))))
        fig.text((x0 + pw / 2) / width_px, 1 - (top_in - 0.04) / size_in[1],
                 f"({chr(ord('a') + k)}) m = {m}", fontsize=9, ha="center", va="bottom")
    fig.suptitle(
        f"DTDI stage images, one display scale: (DN / {2**beta - 1})^(1/2.2)", fontsize=10,
        y=1 - 0.08 / size_in[1], va="top",
    )
    canvas.draw()
    rgb = np.asarray(canvas.buffer_rgba())[..., :3].copy()
    plt.close(fig)
    for m, x0, y0 in places:
        panel = stage_display(area_resize(stages[m], ph, pw), beta)  # mean DN over a dot's pixels
        grey = (panel * np.float32(255) + np.float32(0.5)).astype(np.uint8)[: height_px - y0, : width_px - x0]
        rgb[y0 : y0 + grey.shape[0], x0 : x0 + grey.shape[1]] = grey[:, :, None]
    return write_png(path, rgb, meta)


#: Fig. 4's width and margins [inches]: the heights follow the images' aspect (no empty bands)
FIG4_WIDTH_IN, FIG4_MARGIN_IN, FIG4_GAP_IN, FIG4_TITLE_IN = 11.0, 0.11, 0.12, 0.32
#: Largest height of a Fig. 4 inset [inches]
FIG4_INSET_MAX_IN = 2.8


def fig4_layout(image_shape: tuple[int, int], boxes: Sequence[Box]) -> tuple[tuple[float, float], list[Any]]:
    """Fig. 4's size [inches] and its axes' rectangles (figure fractions): the two big panels
    and the four insets (``boxes``: the dark box, then the bright box; two insets each). Each
    rectangle has its image's aspect (heights capped), and the figure is as tall as its rows, so
    that an image wider than tall (``--quick``) leaves no empty band above and below it."""
    w_in, m, gap, title = FIG4_WIDTH_IN, FIG4_MARGIN_IN, FIG4_GAP_IN, FIG4_TITLE_IN
    h, w = image_shape
    big_w = (w_in - 2 * m - gap) / 2
    big_h = min(max(big_w * h / max(w, 1), 1.0), 7.0)
    slot_w = (w_in - 2 * m - 3 * gap) / 4
    sizes = []  # (width, height) [in] of each inset: its box's aspect, at most the slot
    for b in (boxes[0], boxes[0], boxes[1], boxes[1]):
        aspect = max(b[1] - b[0], 1) / max(b[3] - b[2], 1)
        ih = min(slot_w * aspect, FIG4_INSET_MAX_IN)
        sizes.append((ih / aspect, ih))
    row_h = max(ih for _, ih in sizes)
    bottom = 0.25
    height = m + title + big_h + title + row_h + bottom
    y_big = bottom + row_h + title  # from the bottom [in]
    rects = [[(m + k * (big_w + gap)) / w_in, y_big / height, big_w / w_in, big_h / height] for k in range(2)]
    for k, (iw, ih) in enumerate(sizes):  # centred in its slot, top-aligned in the row
        x = m + k * (slot_w + gap) + (slot_w - iw) / 2
        rects.append([x / w_in, (bottom + row_h - ih) / height, iw / w_in, ih / height])
    return (w_in, height), rects


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
    inset_titles: Sequence[str] | None = None,
) -> Path:
    """Fig. 4: (a) Gamma_HDR (linear display) and (b) Gamma_TRA side by side; below, insets of a
    dark region (Gamma1 vs Gamma_TRA) and of a bright region (Gamma2 vs Gamma_TRA). Inputs in
    0..1. ``inset_titles``: the four inset captions (the caller states what was measured inside
    each box: :func:`bench_sim.workflows.reproduce.fig4_captions.pass_inset_captions`); default:
    which image each inset shows. The figure's height follows the images (:func:`fig4_layout`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    size, rects = fig4_layout(hdr_display.shape, (dark_box, bright_box))
    fig = plt.figure(figsize=size, dpi=110)  # fixed rectangles: no layout engine (it costs more)
    big = [fig.add_axes(rects[0]), fig.add_axes(rects[1])]
    for ax, img, title in (
        (big[0], hdr_display, "(a) $\\Gamma_{HDR}$ (linear display)"),
        (big[1], tra, f"(b) $\\Gamma_{{TRA}}$ ({tra_name} transform)"),
    ):
        # area-averaged to the axes' pixels (the figure then hardly resamples); extent keeps the
        # full-resolution coordinates for the inset frames
        h, w = img.shape
        extent = ax.get_window_extent()
        scale = min(extent.width / w, extent.height / h)
        shown = area_resize(img, max(1, round(h * scale)), max(1, round(w * scale))) if scale < 1 else img
        ax.imshow(shown.astype(np.float32), cmap="gray", vmin=0, vmax=1,
                  extent=(-0.5, w - 0.5, h - 0.5, -0.5))
        ax.set_title(title, fontsize=10, y=1.0)
        ax.set_axis_off()
        for frame, colour in ((dark_box, "tab:cyan"), (bright_box, "tab:orange")):
            l0, l1, c0, c1 = frame
            ax.add_patch(Rectangle((c0, l0), c1 - c0, l1 - l0, fill=False, ec=colour, lw=1.5))
    titles = list(inset_titles) if inset_titles is not None else [
        "dark, $\\Gamma_1$", "dark, $\\Gamma_{TRA}$", "bright, $\\Gamma_2$", "bright, $\\Gamma_{TRA}$"
    ]
    if len(titles) != 4:
        raise ValueError(f"inset_titles: need 4 captions, got {len(titles)}")
    insets = [
        (gamma1_display, dark_box, "tab:cyan", titles[0]),
        (tra, dark_box, "tab:cyan", titles[1]),
        (gamma2_display, bright_box, "tab:orange", titles[2]),
        (tra, bright_box, "tab:orange", titles[3]),
    ]
    for k, (img, box, colour, title) in enumerate(insets):
        ax = fig.add_axes(rects[2 + k])
        l0, l1, c0, c1 = box
        crop = img[l0:l1, c0:c1].copy()  # not a view: the figure keeps the crop, not the image
        lo, hi = float(np.percentile(crop, 0.5)), float(np.percentile(crop, 99.5))
        ax.imshow(crop, cmap="gray", vmin=lo, vmax=max(hi, lo + 1e-6), interpolation="nearest")
        ax.set_title(title, fontsize=8, color=colour)
        ax.set_xticks([])
        ax.set_yticks([])
        for s in ax.spines.values():
            s.set_edgecolor(colour)
            s.set_linewidth(2)
    fig.text(0.5, 0.06 / size[1], "insets stretched to their own 0.5-99.5 % range", ha="center", fontsize=8)
    return _save(path, fig, meta)


def snr_versus_signal_figure(
    photons: np.ndarray,
    snr: Mapping[str, np.ndarray],
    photons_min: Mapping[str, float],
    photons_sat: Mapping[str, float],
    switch_photons: float,
    path: Path,
    meta: Mapping[str, Any],
    labels: Mapping[str, str],
) -> Path:
    """SNR versus signal of ``Gamma1``, ``Gamma2`` and ``Gamma_HDR`` from one photon-transfer
    series through the chain (log-log), with each image's SNR = 1 point and saturation point
    (EMVA 1288) marked and the eq. 11 switch of ``Gamma_HDR`` drawn as a vertical line.

    Parameters
    ----------
    photons
        Levels of the series [mean photons per pixel per frame], shape (L,).
    snr
        Image name -> measured SNR per level (dimensionless; NaN/inf where undefined).
    photons_min, photons_sat
        Image name -> SNR = 1 point and saturation point [photons per pixel per frame].
    switch_photons
        Level where ``Gamma_HDR`` switches from ``Gamma2`` to the scaled ``Gamma1`` (NaN: none).
    labels
        Image name -> legend label (e.g. with its measured DR).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    p = np.asarray(photons, dtype=np.float64)
    fig, ax = plt.subplots(figsize=(7.2, 4.6), dpi=110)
    colours = {"gamma1": "tab:blue", "gamma2": "tab:orange", "gamma_hdr": "0.35"}
    for name, values in snr.items():
        y = np.asarray(values, dtype=np.float64)
        sat = photons_sat.get(name)
        # up to the saturation point: beyond it the clipped images have no temporal noise left
        ok = (p > 0) & np.isfinite(y) & (y > 0) & (p <= (sat if sat and np.isfinite(sat) else np.inf))
        c = colours.get(name)
        wide = name == "gamma_hdr"  # drawn wide underneath: it follows Gamma2, then the scaled Gamma1
        ax.plot(p[ok], y[ok], "-", lw=5 if wide else 1.5, alpha=0.45 if wide else 1.0, color=c,
                zorder=1 if wide else 3, label=labels.get(name, name))
        for x, mk in ((photons_min.get(name), "o"), (photons_sat.get(name), "s")):
            if x is not None and np.isfinite(x) and x > 0:
                ax.plot([x], [np.interp(np.log(x), np.log(p[ok]), y[ok])], mk, color=c, ms=5, mfc="none")
    if np.isfinite(switch_photons) and switch_photons > 0:
        ax.axvline(switch_photons, color="0.5", ls="--", lw=1)
        ax.text(switch_photons, ax.get_ylim()[0], " eq. 11 switch", rotation=90, va="bottom", fontsize=8,
                color="0.35")
    ax.axhline(1.0, color="0.7", lw=0.8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    from matplotlib.ticker import LogLocator

    for axis in (ax.xaxis, ax.yaxis):  # minor ticks and grid at 2 and 5 only (a tick is costly)
        axis.set_minor_locator(LogLocator(subs=(2.0, 5.0)))
    ax.set_xlabel("mean photons per pixel per frame")
    ax.set_ylabel("SNR (temporal)")
    ax.set_title("SNR versus signal through sensor, DTDI and eq. 11 (o: SNR = 1, squares: saturation)",
                 fontsize=9)
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(True, which="both", alpha=0.25)
    fig.subplots_adjust(left=0.1, right=0.98, top=0.93, bottom=0.11)  # fixed: no layout engine
    return _save(path, fig, meta)
