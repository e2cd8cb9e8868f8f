"""The e-SFR of many edges of one image, as a table (``bench-sim mtf``): each ROI measured by
:func:`bench_sim.metrics.sfr.edge_sfr`, its readings stated on one frequency axis, the edges the
e-SFR refuses listed with the reason.

Frequency axis (:data:`~bench_sim.metrics.sfr_readings.FREQUENCY_AXES`): ``"normal"``, along the
edge normal (ISO 12233:2017, the default), or ``"pixel"``, along the pixel rows (a near-vertical
edge) or columns (near-horizontal), ``f cos(theta)`` (what ISO 12233:2000 and ``sfrmat3`` state);
every reading -- MTF50, MTF50P, the SFR at Nyquist (0.5 cycles/px on that axis), cycles/mm -- is
on the axis chosen.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from bench_sim.errors import BenchSimError
from bench_sim.metrics.edge_finder import EdgeCandidate
from bench_sim.metrics.sfr import SFRResult, edge_sfr
from bench_sim.metrics.sfr_readings import FREQUENCY_AXES, axis_frequency, mtf50, mtf50p, mtf_at

__all__ = ["EdgeReading", "EdgeRefusal", "axis_name", "read_edge", "read_edges"]


def axis_name(axis: str, orientation: str) -> str:
    """How the frequency axis of an edge's SFR is named in outputs: ``edge normal`` or ``pixel
    rows`` / ``pixel columns``."""
    if axis not in FREQUENCY_AXES:
        raise BenchSimError(f"frequency axis = {axis!r}: allowed {', '.join(FREQUENCY_AXES)}")
    if axis == "normal":
        return "edge normal"
    return "pixel rows" if orientation == "vertical" else "pixel columns"


@dataclass(frozen=True)
class EdgeReading:
    """One edge's e-SFR with its readings on the frequency axis ``axis`` (module docstring).

    ``frequency_cyc_px`` [cycles/px] and ``frequency_cyc_mm`` [cycles/mm, ``None`` without a
    pitch] are on that axis, as are ``mtf50_cyc_px``, ``mtf50_cyc_mm``, ``mtf50p_cyc_px`` and
    ``mtf_nyquist``; ``result`` is the e-SFR itself (on the edge normal).
    """

    edge: int
    axis: str
    frequency_cyc_px: np.ndarray
    frequency_cyc_mm: np.ndarray | None
    mtf50_cyc_px: float
    mtf50_cyc_mm: float | None
    mtf50p_cyc_px: float
    mtf_nyquist: float
    result: SFRResult

    @property
    def axis_label(self) -> str:
        """The axis as outputs name it (:func:`axis_name`)."""
        return axis_name(self.axis, self.result.orientation)


@dataclass(frozen=True)
class EdgeRefusal:
    """An edge (or a ROI) that gave no e-SFR, and why (one line)."""

    edge: int
    orientation: str | None
    angle_deg: float | None
    roi: tuple[int, int, int, int] | None
    problem: str
    centre_xy: tuple[float, float] | None = None


def read_edge(edge: int, r: SFRResult, axis: str, pixel_pitch_m: float | None) -> EdgeReading:
    """The readings of the e-SFR ``r`` on the frequency axis ``axis``."""
    axis_name(axis, r.orientation)
    f = r.frequency_cyc_px if axis == "normal" else axis_frequency(r.frequency_cyc_px, r.edge_angle_deg)
    pitch_mm = None if pixel_pitch_m is None else pixel_pitch_m * 1e3
    f50 = mtf50(f, r.sfr)
    return EdgeReading(
        edge=edge, axis=axis, frequency_cyc_px=f,
        frequency_cyc_mm=None if pitch_mm is None else f / pitch_mm,
        mtf50_cyc_px=f50, mtf50_cyc_mm=None if pitch_mm is None else f50 / pitch_mm,
        mtf50p_cyc_px=mtf50p(f, r.sfr), mtf_nyquist=mtf_at(f, r.sfr, 0.5), result=r,
    )


def read_edges(
    image: np.ndarray,
    edges: Sequence[EdgeCandidate | tuple[int, int, int, int]],
    *,
    axis: str = "normal",
    valid: np.ndarray | None = None,
    clipped: np.ndarray | None = None,
    clip_level: float | None = None,
    pixel_pitch_m: float | None = None,
    where: str = "",
) -> tuple[list[EdgeReading], list[EdgeRefusal]]:
    """The e-SFR of every edge (a candidate of :func:`bench_sim.metrics.edge_finder.find_edges`
    or a ROI ``(x0, y0, x1, y1)``), numbered from 1 in the given order; ``valid`` and
    ``clipped`` (and ``clip_level``) as :func:`bench_sim.metrics.sfr.edge_sfr` takes them.

    Returns
    -------
    (readings, refusals)
        The edges measured, and those without a ROI or that the e-SFR refused, with the reason.
    """
    readings: list[EdgeReading] = []
    refusals: list[EdgeRefusal] = []
    for k, e in enumerate(edges, start=1):
        if isinstance(e, EdgeCandidate):
            roi, orient, angle, problem, centre = e.roi, e.orientation, e.angle_deg, e.problem, e.centre_xy
        else:
            x0, y0, x1, y1 = (int(v) for v in e)
            roi, orient, angle, problem, centre = (x0, y0, x1, y1), None, None, None, None
        if roi is None or problem is not None:
            refusals.append(EdgeRefusal(k, orient, angle, roi, problem or "no ROI", centre))
            continue
        x0, y0, x1, y1 = roi
        try:
            r = edge_sfr(image, roi, pixel_pitch_m=pixel_pitch_m, valid=valid, clipped=clipped,
                         clip_level=clip_level, where=f"{where}edge {k} ROI {x0},{y0},{x1},{y1}")
        except BenchSimError as exc:
            refusals.append(EdgeRefusal(k, orient, angle, roi, str(exc), centre))
            continue
        readings.append(read_edge(k, r, axis, pixel_pitch_m))
    return readings, refusals
