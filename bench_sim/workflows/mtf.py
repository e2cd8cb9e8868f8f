"""``bench-sim mtf IMAGE``: the ISO 12233 e-SFR of a slanted edge in any image.

Input: a single-channel image, TIFF/PNG (8/16-bit), EXR (channel ``Y``, ``R`` or ``gray``, else
the first) or NPY, as ``fuse`` reads it (:func:`bench_sim.io.read_image`), linear in the
signal; ``--roi x0,y0,x1,y1`` (pixel indices, ends exclusive; default: the whole image) holding
one straight edge slanted by 1..40 degrees. Computed by :func:`bench_sim.metrics.sfr.edge_sfr`.

Before anything is computed: the output folder (:func:`bench_sim.io.check_output_dir`), the
file (exists, a supported type), the ROI against the image's size read from its header, the
pixel pitch. Then the e-SFR refuses a ROI without an edge, too small, with an edge at or near
0 or 45 degrees or a clipped edge (one line, exit status 2), before any file is written.

Clipping: ``--saturation DN`` names the value at which the camera clips; by default, when the
pixels are integers and the ROI's largest value is ``2**k - 1`` (``k`` = 8, 10, 12, 14, 16: a
full ADC or file word), that value is taken.

Outputs, written as one set into ``--out`` (:func:`bench_sim.io.output_set`):

* ``sfr.csv``: ``frequency_cyc_px``, ``frequency_cyc_mm`` (empty without a pixel pitch),
  ``sfr``, with the provenance as ``#`` lines;
* ``sfr.png``: the SFR against frequency, the Nyquist frequency and the MTF50 marked, the ESF
  beside it;
* ``summary.json``: MTF50 (cycles/px and cycles/mm), the SFR at Nyquist, the edge angle and
  orientation, the ROI, the rows used, the edge's contrast, the input file's SHA-256 and the
  package version.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.errors import BenchSimError
from bench_sim.io import (
    check_output_dir,
    image_shape,
    output_set,
    read_image,
    sha256_file,
    write_csv,
    write_figure_png,
    write_json,
)
from bench_sim.metrics.sfr import SFRResult, check_roi_bounds, edge_sfr
from bench_sim.version import __version__

__all__ = ["parse_roi", "auto_saturation", "run_mtf", "summary_line", "OUTPUT_FILES"]

#: the files ``bench-sim mtf`` writes into ``--out``
OUTPUT_FILES = ("sfr.csv", "sfr.png", "summary.json")
_WORD_BITS = (8, 10, 12, 14, 16)


def parse_roi(text: str | None, shape: tuple[int, ...]) -> tuple[int, int, int, int]:
    """``--roi x0,y0,x1,y1`` checked against an image of ``shape`` (rows, columns); ``None``:
    the whole image."""
    h, w = int(shape[0]), int(shape[1])
    if text is None:
        return 0, 0, w, h
    try:
        x0, y0, x1, y1 = (int(v) for v in text.split(","))
    except ValueError:
        raise BenchSimError(f"--roi = {text!r}: expected four integers x0,y0,x1,y1 (pixel indices)") from None
    return check_roi_bounds((x0, y0, x1, y1), w, h, f"--roi = {text!r}")


def auto_saturation(roi_pixels: np.ndarray) -> float | None:
    """The clip level taken when none is given: the ROI's largest value when the pixels are
    integers and it is a full word ``2**k - 1`` (``k`` in 8, 10, 12, 14, 16), else ``None``."""
    top = float(roi_pixels.max())
    if not np.all(roi_pixels == np.round(roi_pixels)):
        return None
    return top if any(top == 2**k - 1 for k in _WORD_BITS) else None


def _check_options(pixel_pitch_um: float | None, saturation: float | None) -> None:
    if pixel_pitch_um is not None and not (math.isfinite(pixel_pitch_um) and 0 < pixel_pitch_um <= 1000):
        raise BenchSimError(f"--pixel-pitch-um = {pixel_pitch_um!r}: must be a pixel pitch in (0, 1000] um")
    if saturation is not None and not math.isfinite(saturation):
        raise BenchSimError(f"--saturation = {saturation!r}: must be a finite number [image units]")


def _plot(path: Path, r: SFRResult, meta: dict[str, Any]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(10, 4), dpi=100, gridspec_kw={"width_ratios": [3, 2]})
    ax.plot(r.frequency_cyc_px, r.sfr, color="C0", lw=1.5, label="e-SFR (ISO 12233:2017)")
    ax.axvline(0.5, color="0.5", ls="--", lw=1, label="Nyquist, 0.5 cycles/px")
    if math.isfinite(r.mtf50_cyc_px):
        ax.plot([r.mtf50_cyc_px], [0.5], "o", color="C3", label=f"MTF50 = {r.mtf50_cyc_px:.3f} cycles/px")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, max(1.05, float(np.nanmax(r.sfr)) * 1.02))
    ax.set_xlabel("spatial frequency along the edge normal [cycles/px]")
    ax.set_ylabel("SFR")
    ax.set_title(f"{r.orientation} edge, {r.edge_angle_deg:.2f} deg, ROI {r.roi}", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    x = (np.arange(r.esf.size) - r.esf.size // 2) / 4.0
    ax2.plot(x, r.esf, color="C1", lw=1.2)
    ax2.set_xlabel("distance to the edge [px]")
    ax2.set_ylabel("ESF [image units]")
    ax2.set_title("edge-spread function (4x oversampled)", fontsize=9)
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    write_figure_png(path, fig, meta, dpi=100)


def _summary(r: SFRResult, meta: dict[str, Any]) -> dict[str, Any]:
    def num(v: float | None) -> float | None:
        return None if v is None or not math.isfinite(v) else float(v)

    return {
        **meta,
        "mtf50_cyc_px": num(r.mtf50_cyc_px),
        "mtf50_cyc_mm": num(r.mtf50_cyc_mm),
        "mtf_nyquist": num(r.mtf_nyquist),
        "edge_angle_deg": r.edge_angle_deg,
        "orientation": r.orientation,
        "roi": list(r.roi),
        "rows_used": r.rows_used,
        "contrast": r.contrast,
        "units": {"mtf50_cyc_px": "cycles/px", "mtf50_cyc_mm": "cycles/mm", "edge_angle_deg": "deg",
                  "contrast": "image units", "roi": "px (x0, y0, x1, y1; ends exclusive)"},
    }


def summary_line(summary: dict[str, Any], out: Path) -> str:
    """What ``bench-sim mtf`` prints: the edge, MTF50, the SFR at Nyquist and the folder."""
    s = summary
    mm = f" ({s['mtf50_cyc_mm']:.2f} cycles/mm)" if s["mtf50_cyc_mm"] is not None else ""
    f50 = "above 1 cycle/px" if s["mtf50_cyc_px"] is None else f"{s['mtf50_cyc_px']:.4f} cycles/px{mm}"
    nyq = "-" if s["mtf_nyquist"] is None else f"{s['mtf_nyquist']:.3f}"
    return (f"{s['orientation']} edge at {s['edge_angle_deg']:.2f} deg: MTF50 {f50}, "
            f"SFR at Nyquist {nyq}; wrote {out}")


def run_mtf(
    image: Path,
    *,
    out: Path,
    roi: str | None = None,
    pixel_pitch_um: float | None = None,
    saturation: float | None = None,
) -> dict[str, Any]:
    """``bench-sim mtf``: check every input, measure the e-SFR, write the output set (module
    docstring); returns the summary."""
    _check_options(pixel_pitch_um, saturation)
    check_output_dir(out)
    shape = image_shape(image)
    if len(shape) != 2:
        raise BenchSimError(f"{image}: shape {tuple(shape)} is not a single-channel 2-D image")
    box = parse_roi(roi, shape)
    pixels = read_image(image)
    x0, y0, x1, y1 = box
    sat = saturation if saturation is not None else auto_saturation(pixels[y0:y1, x0:x1])
    pitch_m = None if pixel_pitch_um is None else pixel_pitch_um * 1e-6
    where = f"{image} ROI {x0},{y0},{x1},{y1}"
    r = edge_sfr(pixels, box, pixel_pitch_m=pitch_m, saturation=sat, where=where)
    digest = sha256_file(image)
    meta: dict[str, Any] = {
        "command": "mtf",
        "version": __version__,
        "input": {"path": str(image), "sha256": digest, "shape": list(shape)},
        "pixel_pitch_m": pitch_m,
        "saturation": sat,
        "method": "ISO 12233:2017 e-SFR (bench_sim.metrics.sfr)",
    }
    freq_mm = r.frequency_cyc_mm if r.frequency_cyc_mm is not None else [None] * r.sfr.size
    rows = [[float(f), None if g is None else float(g), float(s)]
            for f, g, s in zip(r.frequency_cyc_px, freq_mm, r.sfr, strict=True)]
    summary = _summary(r, meta)
    record = {"command": "mtf", "version": __version__, "input_sha256": digest}
    with output_set(out, record) as tmp:
        write_csv(tmp / "sfr.csv", ["frequency_cyc_px", "frequency_cyc_mm", "sfr"], rows, meta)
        _plot(tmp / "sfr.png", r, meta)
        write_json(tmp / "summary.json", summary)
    return summary
