"""The tables of ``bench-sim mtf``: the edges (``edges.csv``: :data:`EDGE_COLUMNS`) and their SFR
curves of an image, and, for a ``simulate`` output (:mod:`bench_sim.workflows.mtf_simulation`),
the same per stage with the mean curve of each direction and its readings."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from bench_sim.io import write_csv
from bench_sim.measure.sharpness import DIRECTIONS, SFR_FREQUENCY_CYC_PX, StageImage
from bench_sim.metrics.sfr_table import EdgeReading, EdgeRefusal

__all__ = ["StageResult", "stage_records", "write_tables", "STAGE_COLUMNS", "EDGE_COLUMNS", "edge_rows",
           "curve_rows", "reading_record", "num"]

#: columns of ``edges.csv``
EDGE_COLUMNS = ["edge", "status", "x0", "y0", "x1", "y1", "orientation", "angle_deg", "contrast",
                "frequency_axis", "mtf50_cyc_px", "mtf50_cyc_mm", "mtf50p_cyc_px", "mtf_nyquist", "sfr_peak",
                "sharpened", "rows_used", "excluded_px", "problem"]

#: one stage's image, its edges measured and refused, and per direction its mean curve's readings
StageResult = tuple[StageImage, list[EdgeReading], list[EdgeRefusal], dict[str, dict[str, Any]]]
#: columns of ``stages.csv``
STAGE_COLUMNS = ["stage", "direction", "edges", "mtf50_cyc_px", "mtf50p_cyc_px", "mtf_nyquist"]


def num(v: float | None) -> float | None:
    """A reading as a JSON / CSV value: ``None`` for NaN (and ``None``)."""
    return None if v is None or not math.isfinite(v) else float(v)


def reading_record(r: EdgeReading) -> dict[str, Any]:
    """One measured edge as plain JSON values (``None`` for NaN)."""
    s = r.result
    return {
        "edge": r.edge, "roi": list(s.roi), "orientation": s.orientation, "angle_deg": s.edge_angle_deg,
        "contrast": s.contrast, "frequency_axis": r.axis_label, "mtf50_cyc_px": num(r.mtf50_cyc_px),
        "mtf50_cyc_mm": num(r.mtf50_cyc_mm), "mtf50p_cyc_px": num(r.mtf50p_cyc_px),
        "mtf_nyquist": num(r.mtf_nyquist), "sfr_peak": s.sfr_peak, "sharpened": s.sharpened,
        "rows_used": s.rows_used, "excluded_px": s.excluded_px,
    }


def edge_rows(readings: list[EdgeReading], refusals: list[EdgeRefusal], prefix: list[Any] | None = None
              ) -> list[list[Any]]:
    """The rows of an edges table (:data:`EDGE_COLUMNS`, after ``prefix``), in edge order."""
    rows: list[tuple[int, list[Any]]] = []
    for r in readings:
        d = reading_record(r)
        rows.append((r.edge, [r.edge, "ok", *d["roi"], d["orientation"], d["angle_deg"], d["contrast"],
                              d["frequency_axis"], d["mtf50_cyc_px"], d["mtf50_cyc_mm"], d["mtf50p_cyc_px"],
                              d["mtf_nyquist"], d["sfr_peak"], d["sharpened"], d["rows_used"],
                              d["excluded_px"], ""]))
    for f in refusals:
        roi = list(f.roi) if f.roi is not None else [None] * 4
        rows.append((f.edge, [f.edge, "refused", *roi, f.orientation, f.angle_deg, *[None] * 10, f.problem]))
    return [(prefix or []) + row for _, row in sorted(rows, key=lambda x: x[0])]


def curve_rows(readings: list[EdgeReading], prefix: list[Any] | None = None) -> list[list[Any]]:
    """Every edge's SFR curve: ``edge, frequency_axis, frequency_cyc_px, frequency_cyc_mm, sfr``."""
    rows = []
    for r in readings:
        mm = r.frequency_cyc_mm if r.frequency_cyc_mm is not None else [None] * r.result.sfr.size
        for f, g, s in zip(r.frequency_cyc_px, mm, r.result.sfr, strict=True):
            mm_value = None if g is None else float(g)
            rows.append([*(prefix or []), r.edge, r.axis_label, float(f), mm_value, float(s)])
    return rows




def _label(s: StageImage) -> int | str:
    return s.name if s.stage is None else s.stage


def stage_records(results: Sequence[StageResult]) -> list[dict[str, Any]]:
    """Per stage (and ``gamma_hdr``): the readings of each direction's mean curve and the edges."""
    out = []
    for s, readings, refusals, dirs in results:
        out.append({
            "stage": _label(s),
            **{f"{k}_{d}": num(v[k]) for d, v in dirs.items() for k in ("mtf50_cyc_px", "mtf50p_cyc_px",
                                                                           "mtf_nyquist")},
            **{f"edges_{d}": int(v["edges"]) for d, v in dirs.items()},
            "sharpened_edges": sum(1 for r in readings if r.result.sharpened),
            "edges": [reading_record(r) for r in readings],
            "refused": [{"edge": f.edge, "problem": f.problem} for f in refusals],
        })
    return out


def write_tables(folder: Path, results: Sequence[StageResult], meta: dict[str, Any]) -> list[str]:
    """``edges.csv``, ``sfr_edges.csv``, ``sfr_stages.csv`` and ``stages.csv`` in ``folder``."""
    edges, curves, means, stages = [], [], [], []
    for s, readings, refusals, dirs in results:
        label = _label(s)
        edges += edge_rows(readings, refusals, [label])
        curves += curve_rows(readings, [label])
        for d, v in dirs.items():
            means += [[label, d, float(f), num(float(x))]
                      for f, x in zip(SFR_FREQUENCY_CYC_PX, v["sfr"], strict=True)]
            stages.append([label, d, int(v["edges"]), num(v["mtf50_cyc_px"]), num(v["mtf50p_cyc_px"]),
                           num(v["mtf_nyquist"])])
    write_csv(folder / "edges.csv", ["stage", *EDGE_COLUMNS], edges, meta)
    curve_header = ["stage", "edge", "frequency_axis", "frequency_cyc_px", "frequency_cyc_mm", "sfr"]
    write_csv(folder / "sfr_edges.csv", curve_header, curves, meta)
    write_csv(folder / "sfr_stages.csv", ["stage", "direction", "frequency_cyc_px", "sfr"], means,
              {**meta, "directions_edges": {d: o for d, o in DIRECTIONS.items()}})
    write_csv(folder / "stages.csv", STAGE_COLUMNS, stages, meta)
    return ["edges.csv", "sfr_edges.csv", "sfr_stages.csv", "stages.csv"]
