"""``bench-sim mtf IMAGE``: the ISO 12233 e-SFR of every slanted edge of a photograph or image.

Input: PNG, TIFF, BMP, JPEG, EXR or NPY, 8/16-bit integers or floats, grey or colour
(:func:`bench_sim.io.read_image_channel`): a colour image needs ``--channel R``, ``G``, ``B`` or
``Y`` (ISO 12233's luminance ``0.2125 R + 0.7154 G + 0.0721 B``). The values must be linear in
the light: ``--encoding srgb`` decodes sRGB first (the default for JPEG files; ``linear``
otherwise). A ``simulate`` output (its folder, ``simulation.zarr``, ``simulation.nc`` or the TIFF
set's ``meta.json``) is measured stage by stage instead (:mod:`bench_sim.workflows.mtf_simulation`).

Invalid pixels are left out of everything: NaN and inf, the pixels where ``--mask FILE`` (an
image of the same size) is 0, and clipped pixels -- at or above ``--saturation`` (in the file's
units; for ``Y`` any of R, G, B), by default, for integer pixels whose largest value is a full
word ``2**k - 1`` (``k`` = 8, 10, 12, 14, 16), that value.

Edges: without ``--roi`` every straight edge of the image is found
(:func:`bench_sim.metrics.edge_finder.find_edges`) with a ROI clear of other edges and invalid
pixels; ``--roi x0,y0,x1,y1`` (repeatable; pixel indices, ends exclusive) measures those ROIs
instead. Each is measured by :func:`bench_sim.metrics.sfr.edge_sfr`; the frequencies are along
the edge normal (ISO 12233:2017), or along the pixel rows / columns with ``--frequency-axis
pixel`` (``f cos(angle)``), and every output says which.

Outputs, written as one set into ``--out`` (:func:`bench_sim.io.output_set`): ``edges.csv`` (one
row per edge found: ROI, orientation, angle, contrast, MTF50, MTF50P, the SFR at Nyquist, its
peak, ``sharpened``, or why it was refused), ``sfr.csv`` (every edge's SFR curve), ``sfr.png``,
``rois.png`` (the image with the ROIs numbered) and ``summary.json``. Bad input, or no usable
edge, is one line (exit status 2) before any file is written.
"""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.errors import BenchSimError
from bench_sim.io import (
    check_image_file,
    check_output_dir,
    image_shape,
    output_set,
    read_image_channel,
    read_image_data,
    sha256_file,
    write_csv,
    write_json,
)
from bench_sim.io.images import ChannelImage
from bench_sim.metrics.edge_finder import find_edges
from bench_sim.metrics.sfr import check_roi_bounds
from bench_sim.metrics.sfr_readings import FREQUENCY_AXES
from bench_sim.metrics.sfr_table import EdgeReading, EdgeRefusal, read_edges
from bench_sim.version import __version__
from bench_sim.workflows import mtf_figures, mtf_simulation
from bench_sim.workflows.mtf_tables import EDGE_COLUMNS, curve_rows, edge_rows, num, reading_record

__all__ = ["MtfRequest", "parse_roi", "auto_saturation", "run_mtf", "summary_line", "OUTPUT_FILES",
           "ENCODINGS"]

#: the files ``bench-sim mtf IMAGE`` writes into ``--out``
OUTPUT_FILES = ("edges.csv", "sfr.csv", "sfr.png", "rois.png", "summary.json")
#: ``--encoding`` values: ``auto`` is ``srgb`` for JPEG files, ``linear`` for the others
ENCODINGS = ("auto", "linear", "srgb")
_WORD_BITS = (8, 10, 12, 14, 16)


@dataclass(frozen=True)
class MtfRequest:
    """What ``bench-sim mtf`` was asked (the module docstring names each option)."""

    image: Path
    out: Path
    rois: tuple[str, ...] = ()
    channel: str | None = None
    mask: Path | None = None
    saturation: float | None = None
    encoding: str = "auto"
    frequency_axis: str = "normal"
    pixel_pitch_um: float | None = None


def parse_roi(text: str, shape: tuple[int, ...]) -> tuple[int, int, int, int]:
    """``--roi x0,y0,x1,y1`` checked against an image of ``shape`` (rows, columns, ...)."""
    h, w = int(shape[0]), int(shape[1])
    try:
        x0, y0, x1, y1 = (int(v) for v in text.split(","))
    except ValueError:
        raise BenchSimError(f"--roi = {text!r}: expected four integers x0,y0,x1,y1 (pixel indices)") from None
    return check_roi_bounds((x0, y0, x1, y1), w, h, f"--roi = {text!r}")


def auto_saturation(raw: np.ndarray, integer_top: int | None = None) -> float | None:
    """The clip level taken when none is given: the largest value when the pixels are integers
    and it is a full word ``2**k - 1`` (``k`` in 8, 10, 12, 14, 16), else ``None``."""
    finite = raw[np.isfinite(raw)]
    if finite.size == 0 or (integer_top is None and not np.all(finite == np.round(finite))):
        return None
    top = float(finite.max())
    return top if any(top == 2**k - 1 for k in _WORD_BITS) else None


def _check_options(req: MtfRequest) -> None:
    pitch, sat = req.pixel_pitch_um, req.saturation
    if pitch is not None and not (math.isfinite(pitch) and 0 < pitch <= 1000):
        raise BenchSimError(f"--pixel-pitch-um = {pitch!r}: must be a pixel pitch in (0, 1000] um")
    if sat is not None and not math.isfinite(sat):
        raise BenchSimError(f"--saturation = {sat!r}: must be a finite number [image units]")
    if req.encoding not in ENCODINGS:
        raise BenchSimError(f"--encoding = {req.encoding!r}: allowed {', '.join(ENCODINGS)}")
    if req.frequency_axis not in FREQUENCY_AXES:
        raise BenchSimError(f"--frequency-axis = {req.frequency_axis!r}: allowed {', '.join(FREQUENCY_AXES)}")


def _encoding(req: MtfRequest) -> str:
    if req.encoding != "auto":
        return req.encoding
    return "srgb" if req.image.suffix.lower() in (".jpg", ".jpeg") else "linear"


def _mask(path: Path, shape: tuple[int, ...]) -> np.ndarray:
    """``--mask FILE``: ``True`` where the mask is not 0 (any channel)."""
    check_image_file(path)
    try:
        arr = np.asarray(read_image_data(path)[0])
    except Exception as exc:
        detail = " ".join(str(exc).split())[:120]
        raise BenchSimError(f"--mask = {str(path)!r}: cannot read image ({detail})") from None
    valid = np.asarray(arr.any(axis=-1) if arr.ndim == 3 else arr.astype(bool))
    if valid.shape != tuple(shape[:2]):
        raise BenchSimError(f"--mask = {str(path)!r}: {valid.shape[1]} x {valid.shape[0]} px, the image is "
                            f"{shape[1]} x {shape[0]} px (the mask must have the image's size)")
    return valid


def _measure(req: MtfRequest, img: ChannelImage, valid: np.ndarray, sat: float | None,
             shape: tuple[int, ...]) -> tuple[list[EdgeReading], list[EdgeRefusal]]:
    """The e-SFR of the ROIs given or of every edge found; refuses when none is usable."""
    pitch_m = None if req.pixel_pitch_um is None else req.pixel_pitch_um * 1e-6
    clipped = None if sat is None else img.raw_top >= sat
    usable = valid if clipped is None else valid & ~clipped
    edges: list[Any] = [parse_roi(r, shape) for r in req.rois] if req.rois else find_edges(img.values, usable)
    readings, refusals = read_edges(img.values, edges, axis=req.frequency_axis, valid=valid, clipped=clipped,
                                    clip_level=sat, pixel_pitch_m=pitch_m, where=f"{req.image}: ")
    if readings:
        return readings, refusals
    if len(refusals) == 1 and req.rois:
        raise BenchSimError(refusals[0].problem)
    if not refusals:
        raise BenchSimError(f"{req.image}: no edge found (no straight step stands out of the noise); "
                            "give the edge's region with --roi x0,y0,x1,y1")
    shown = "; ".join(f"edge {r.edge}: {r.problem}" for r in refusals[:3])
    more = f"; and {len(refusals) - 3} more" if len(refusals) > 3 else ""
    raise BenchSimError(f"{req.image}: no usable slanted edge among the {len(refusals)} found "
                        f"({shown}{more})")


def summary_line(summary: dict[str, Any], out: Path) -> str:
    """What ``bench-sim mtf`` prints: the edges measured, their MTF50s and the folder."""
    if "stages" in summary:  # a simulate output
        parts = []
        for s in summary["stages"]:
            vals = [f"{d} {s[f'mtf50_cyc_px_{d}']:.3f}" for d in ("across", "along")
                    if s[f"mtf50_cyc_px_{d}"] is not None]
            parts.append(f"{s['stage']}: " + (", ".join(vals) or "-"))
        return f"MTF50 [cycles/px] per stage: {'; '.join(parts)}; wrote {out}"
    edges = summary["edges"]
    refused = f", {len(summary['refused'])} refused" if summary["refused"] else ""
    if len(edges) == 1:
        e = edges[0]
        mm = f" ({e['mtf50_cyc_mm']:.2f} cycles/mm)" if e["mtf50_cyc_mm"] is not None else ""
        f50 = "above 1 cycle/px" if e["mtf50_cyc_px"] is None else f"{e['mtf50_cyc_px']:.4f} cycles/px{mm}"
        nyq = "-" if e["mtf_nyquist"] is None else f"{e['mtf_nyquist']:.3f}"
        return (f"{e['orientation']} edge at {e['angle_deg']:.2f} deg: MTF50 {f50} along the "
                f"{e['frequency_axis']}, SFR at Nyquist {nyq}{refused}; wrote {out}")
    med = summary["mtf50_cyc_px_median"]
    med_txt = "-" if med is None else f"{med:.4f} cycles/px"
    sharp = sum(1 for e in edges if e["sharpened"])
    flag = f", {sharp} sharpened" if sharp else ""
    axis = "edge normal" if edges[0]["frequency_axis"] == "edge normal" else "pixel rows / columns"
    return f"{len(edges)} edges measured{refused}{flag}: median MTF50 {med_txt} along the {axis}; wrote {out}"


def run_mtf(req: MtfRequest) -> dict[str, Any]:
    """``bench-sim mtf``: check every input, measure, write the output set (module docstring);
    returns the summary."""
    _check_options(req)
    check_output_dir(req.out)
    if mtf_simulation.is_simulation_output(req.image):
        return mtf_simulation.run_simulation_mtf(req.image, out=req.out, rois=req.rois, channel=req.channel,
                                                 mask=req.mask, axis=req.frequency_axis,
                                                 pixel_pitch_um=req.pixel_pitch_um)
    shape = image_shape(req.image)
    for text in req.rois:
        parse_roi(text, shape)
    enc = _encoding(req)
    img = read_image_channel(req.image, req.channel, enc)
    valid = np.isfinite(img.values)
    if req.mask is not None:
        valid &= _mask(req.mask, img.values.shape)
    sat = req.saturation if req.saturation is not None else auto_saturation(img.raw_top, img.integer_top)
    readings, refusals = _measure(req, img, valid, sat, shape)
    meta = _meta(req, shape, enc, sat)
    summary = {**meta, "edges": [reading_record(r) for r in readings],
               "refused": [{"edge": f.edge, "roi": None if f.roi is None else list(f.roi),
                            "problem": f.problem} for f in refusals],
               "mtf50_cyc_px_median": num(statistics.median(r.mtf50_cyc_px for r in readings)),
               "units": {"mtf50_cyc_px": "cycles/px", "mtf50_cyc_mm": "cycles/mm", "angle_deg": "deg",
                         "contrast": "image units (linear)", "roi": "px (x0, y0, x1, y1; ends exclusive)"}}
    record = {"command": "mtf", "version": __version__, "input_sha256": meta["input"]["sha256"]}
    with output_set(req.out, record) as tmp:
        write_csv(tmp / "edges.csv", EDGE_COLUMNS, edge_rows(readings, refusals), meta)
        write_csv(tmp / "sfr.csv", ["edge", "frequency_axis", "frequency_cyc_px", "frequency_cyc_mm", "sfr"],
                  curve_rows(readings), meta)
        mtf_figures.sfr_figure(tmp / "sfr.png", readings, meta)
        mtf_figures.rois_figure(tmp / "rois.png", img.values, valid, readings, refusals, meta)
        write_json(tmp / "summary.json", summary)
    return summary


def _meta(req: MtfRequest, shape: tuple[int, ...], encoding: str, saturation: float | None) -> dict[str, Any]:
    """The provenance every output of an image's measurement carries."""
    axis = ("along the edge normal (ISO 12233:2017)" if req.frequency_axis == "normal" else
            "along the pixel rows (near-vertical edges) or columns (near-horizontal): f cos(angle)")
    return {
        "command": "mtf", "version": __version__,
        "input": {"path": str(req.image), "sha256": sha256_file(req.image), "shape": list(shape)},
        "channel": req.channel, "encoding": encoding,
        "mask": None if req.mask is None else {"path": str(req.mask), "sha256": sha256_file(req.mask)},
        "saturation": saturation,
        "pixel_pitch_m": None if req.pixel_pitch_um is None else req.pixel_pitch_um * 1e-6,
        "rois": "given (--roi)" if req.rois else "found (bench_sim.metrics.edge_finder)",
        "frequency_axis": axis,
        "method": "ISO 12233:2017 e-SFR (bench_sim.metrics.sfr)",
    }
