"""The figures of ``bench-sim mtf``: the SFR curves of the edges (``sfr.png``) and the image with
its ROIs numbered (``rois.png``), each with its provenance (:func:`bench_sim.io.write_figure_png`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.io import write_figure_png
from bench_sim.measure.sharpness import SFR_FREQUENCY_CYC_PX
from bench_sim.metrics.sfr import OVERSAMPLING
from bench_sim.metrics.sfr_table import EdgeReading, EdgeRefusal

__all__ = ["sfr_figure", "rois_figure", "stages_figure", "MAX_CURVES"]

#: at most this many curves are drawn in ``sfr.png`` (every edge is in the CSV files)
MAX_CURVES = 12
#: ``rois.png`` shows every k-th pixel of an image larger than this [px]
_SHOWN_PX = 1600


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def sfr_figure(path: Path, readings: Sequence[EdgeReading], meta: dict[str, Any], title: str = "") -> None:
    """The SFR of every edge (up to :data:`MAX_CURVES`) against frequency on its stated axis,
    Nyquist and the MTF50s marked, the ESFs beside them."""
    plt = _pyplot()
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(10, 4), dpi=100, gridspec_kw={"width_ratios": [3, 2]})
    axis = readings[0].axis_label.split()[0] if readings else "edge"
    for i, r in enumerate(readings[:MAX_CURVES]):
        s = r.result
        color = f"C{i % 10}"
        f50 = "-" if not math.isfinite(r.mtf50_cyc_px) else f"{r.mtf50_cyc_px:.3f}"
        ax.plot(r.frequency_cyc_px, s.sfr, color=color, lw=1.3,
                label=f"edge {r.edge}: {s.orientation[0]} {s.edge_angle_deg:.1f} deg, MTF50 {f50}"
                + (" (sharpened)" if s.sharpened else ""))
        if math.isfinite(r.mtf50_cyc_px):
            ax.plot([r.mtf50_cyc_px], [0.5], "o", color=color, ms=4)
        x = (np.arange(s.esf.size) - s.esf.size // 2) / OVERSAMPLING
        span = float(np.ptp(s.esf)) or 1.0
        ax2.plot(x, (s.esf - s.esf.min()) / span, color=color, lw=1.0)
    ax.axvline(0.5, color="0.5", ls="--", lw=1, label="Nyquist, 0.5 cycles/px")
    ax.set_xlim(0, 1)
    top = max(float(np.nanmax(r.result.sfr)) for r in readings) if readings else 1.0
    ax.set_ylim(0, max(1.05, top * 1.02))
    named = "edge normal" if axis == "edge" else "pixel axis"
    ax.set_xlabel(f"spatial frequency along the {named} [cycles/px]")
    ax.set_ylabel("SFR")
    ax.set_title(title or f"ISO 12233 e-SFR of {len(readings)} edge(s)", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    ax2.set_xlabel("distance to the edge [px, along the row or column]")
    ax2.set_ylabel("ESF, normalised")
    ax2.set_xlim(-12, 12)
    ax2.set_title(f"edge-spread functions ({OVERSAMPLING}x oversampled)", fontsize=9)
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    write_figure_png(path, fig, meta, dpi=100)


def rois_figure(path: Path, image: np.ndarray, valid: np.ndarray, readings: Sequence[EdgeReading],
                refusals: Sequence[EdgeRefusal], meta: dict[str, Any], title: str = "") -> None:
    """The image (1st-99th percentile stretched, invalid pixels red; every k-th pixel of a large
    one) with every measured ROI outlined and numbered, and the refused edges marked by their
    number in red."""
    from matplotlib.patches import Rectangle

    plt = _pyplot()
    h, w = image.shape
    k = max(1, math.ceil(max(h, w) / _SHOWN_PX))
    img, ok = image[::k, ::k], valid[::k, ::k]
    scale = min(10.0 / w, 8.0 / h) * 100
    fig, ax = plt.subplots(figsize=(max(w * scale / 100, 3.0), max(h * scale / 100, 2.5) + 0.4), dpi=100)
    finite = img[ok & np.isfinite(img)]
    lo, hi = np.percentile(finite, [1, 99]) if finite.size else (0.0, 1.0)
    shown = np.clip((np.where(ok, img, lo) - lo) / ((hi - lo) or 1.0), 0, 1).astype(np.float32)
    rgb = np.repeat(shown[..., None], 3, axis=-1)
    rgb[~ok] = (0.8, 0.1, 0.1)
    extent = (-0.5, img.shape[1] * k - 0.5, img.shape[0] * k - 0.5, -0.5)
    ax.imshow(rgb, interpolation="nearest", extent=extent)
    for r in readings:
        x0, y0, x1, y1 = r.result.roi
        ax.add_patch(Rectangle((x0 - 0.5, y0 - 0.5), x1 - x0, y1 - y0, fill=False, ec="lime", lw=1.2))
        ax.text(x0, y0 - 1, str(r.edge), color="lime", fontsize=8, va="bottom")
    for f in refusals:
        if f.roi is not None:
            x0, y0, x1, y1 = f.roi
            ax.add_patch(Rectangle((x0 - 0.5, y0 - 0.5), x1 - x0, y1 - y0, fill=False, ec="red", lw=0.8,
                                   ls="--"))
            at: tuple[float, float] = (x0, y0 - 1)
        elif f.centre_xy is not None:
            at = f.centre_xy
        else:
            continue
        ax.text(*at, str(f.edge), color="red", fontsize=8, va="bottom")
    ax.set_title(title or f"{len(readings)} edges measured (green), {len(refusals)} refused (red)",
                 fontsize=9)
    ax.set_xlabel("column [px]")
    ax.set_ylabel("row [px]")
    fig.tight_layout()
    write_figure_png(path, fig, meta, dpi=100)



def stages_figure(path: Path, results: Sequence[Any], meta: dict[str, Any]) -> None:
    """The mean SFR of each stage (and ``gamma_hdr``) across (solid) and along (dashed) the track,
    from :mod:`bench_sim.workflows.mtf_simulation`'s results ``(image, readings, refusals,
    directions)``; Nyquist marked."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(8, 4.5), dpi=100)
    for i, (s, _, _, dirs) in enumerate(results[:MAX_CURVES]):
        color = f"C{i % 10}"
        for d, ls in (("across", "-"), ("along", "--")):
            v = dirs[d]
            if v["edges"]:
                f50 = "-" if not math.isfinite(v["mtf50_cyc_px"]) else f"{v['mtf50_cyc_px']:.3f}"
                ax.plot(SFR_FREQUENCY_CYC_PX, v["sfr"], ls, color=color, lw=1.2,
                        label=f"{s.name} {d} ({v['edges']} edges), MTF50 {f50}")
    ax.axvline(0.5, color="0.5", ls=":", lw=1, label="Nyquist")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.1)
    ax.set_xlabel("spatial frequency [cycles/px; along the track: cycles/line]")
    ax.set_ylabel("SFR, mean over the edges")
    ax.set_title("ISO 12233 e-SFR per stage: across (solid) and along (dashed) the track", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    write_figure_png(path, fig, meta, dpi=100)
