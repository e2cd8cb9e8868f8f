"""The candidate table of a design: every candidate of every point, judged, as CSV and NetCDF.

One row per candidate (:class:`DesignTable`): ``candidate`` (its index), ``point`` and the
values of the point's keys, ``beta_bits``, ``rule``, ``stages`` (``"10/80"``, ``"10/30/80"``),
``mu1``, ``mu_mid`` (0 for a pair), ``mu2``, the scores
(:data:`bench_sim.measure.design_scores.SCORE_COLUMNS`), ``mtf50_along`` (the least sharp of its
stages), the judgement (``feasible``, ``on_front``, ``rank``: 1 for the recommended design, among
the feasible ones) and the DR through the chain where it was measured (``dr_chain_db``,
``dr_chain_db_extrapolated``: NaN elsewhere).

``candidates.csv`` (``pandas.read_csv`` reads it as is; units and provenance in the sidecar
``candidates.csv.json``) and ``design.nc`` (``xarray.open_dataset``: dimension ``candidate``,
every column a variable with ``units`` and ``long_name``) hold the same table.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.config import config_to_toml_text
from bench_sim.io import atomic_path, write_csv, write_json
from bench_sim.io.strict_json import strict_json
from bench_sim.measure.design_scores import SCORE_COLUMNS
from bench_sim.version import __version__
from bench_sim.workflows.design.objectives import OBJECTIVES, Choice, choose
from bench_sim.workflows.design.spec import DesignSpec
from bench_sim.workflows.sweep.points import key_units

__all__ = [
    "DesignTable", "COLUMN_DOCS", "build_table", "write_tables", "stages_label", "judge", "reference_of",
]

#: the columns besides the scores and the point's keys: name -> (units, meaning)
COLUMN_DOCS: dict[str, tuple[str, str]] = {
    "candidate": ("1", "index of the candidate"),
    "point": ("1", "index of the point (its pass)"),
    "beta_bits": ("bit", "output word of the candidate"),
    "rule": (
        "1",
        "fusion rule (eq11: the paper's; clip: highest stage below its word's top; clip_margin: below it "
        "by 4 temporal sd)",
    ),
    "stages": ("1", "the fused stages, low/high or low/middle/high"),
    "mu1": ("1", "lowest fused stage"),
    "mu_mid": ("1", "middle stage of a three-stage fusion (0: a pair)"),
    "mu2": ("1", "highest fused stage (the units of the fused image)"),
    **SCORE_COLUMNS,
    "mtf50_along": ("cycles/px", OBJECTIVES["mtf50_along"].meaning),
    "feasible": ("1", "meets every constraint of the spec"),
    "on_front": ("1", "on the Pareto front of dr_db, truth_rms and clipped_share"),
    "rank": (
        "1",
        "place by the ranking rule among the feasible candidates (1: recommended; 0: not feasible)",
    ),
    "dr_chain_db": (
        "dB",
        "DR of Gamma_HDR measured through the chain (EMVA 1288, eq. 11's fusion); NaN: not "
        "measured (the front and the chosen designs only)",
    ),
    "dr_chain_db_extrapolated": ("dB", "the same with the extrapolated saturation point"),
}


@dataclass
class DesignTable:
    """The candidate table: column -> 1-D array (text columns as ``str`` arrays)."""

    columns: dict[str, np.ndarray] = field(repr=False)
    keys: tuple[str, ...] = ()

    def __len__(self) -> int:
        return int(self.columns["candidate"].size)

    def row(self, i: int) -> dict[str, Any]:
        """Candidate ``i`` as plain values."""
        out: dict[str, Any] = {}
        for k, v in self.columns.items():
            x = v[i]
            out[k] = x.item() if isinstance(x, np.generic) else x
        return out


def stages_label(mu1: int, mu_mid: int, mu2: int) -> str:
    """``"10/80"`` or ``"10/30/80"``."""
    return "/".join(str(int(m)) for m in ((mu1, mu_mid, mu2) if mu_mid else (mu1, mu2)))


def _mtf(stage_mtf: Mapping[str, Any], stages: Sequence[int]) -> float:
    """The least sharp stage's MTF50 (NaN where none was measured)."""
    vals = [stage_mtf.get(str(int(m))) for m in stages if m]
    finite = [float(v) for v in vals if v is not None and math.isfinite(float(v))]
    return min(finite) if finite else float("nan")


def build_table(
    spec: DesignSpec, records: Mapping[int, Mapping[str, Any]], scores: Mapping[int, Mapping[str, np.ndarray]]
) -> DesignTable:
    """The candidates of the finished points (``records``: their journal records, ``scores``:
    their score columns), points in order; the judgement columns are filled by the caller."""
    parts: dict[str, list[np.ndarray]] = {}
    for i in sorted(scores):
        cols = scores[i]
        n = int(cols["mu1"].size)
        mtf = records[i].get("stage_mtf50_along") or {}
        extra = {
            "point": np.full(n, i, dtype=np.int64),
            **{k: np.asarray([records[i]["values"][k]] * n, dtype=object) for k in spec.keys},
            "stages": np.asarray(
                [
                    stages_label(a, m, b)
                    for a, m, b in zip(cols["mu1"], cols["mu_mid"], cols["mu2"], strict=True)
                ]
            ),
            "mtf50_along": np.asarray(
                [
                    _mtf(mtf, (a, m, b))
                    for a, m, b in zip(cols["mu1"], cols["mu_mid"], cols["mu2"], strict=True)
                ]
            ),
        }
        for k, v in {**extra, **cols}.items():
            parts.setdefault(k, []).append(np.asarray(v))
    order = [
        "point",
        *spec.keys,
        "beta_bits",
        "rule",
        "stages",
        "mu1",
        "mu_mid",
        "mu2",
        *SCORE_COLUMNS,
        "mtf50_along",
    ]
    columns = {k: np.concatenate(parts[k]) if k in parts else np.zeros(0) for k in order}
    n = int(columns["point"].size)
    columns = {"candidate": np.arange(n, dtype=np.int64), **columns}
    for k in spec.keys:
        columns[k] = _key_column(columns[k])
    columns.update(
        feasible=np.zeros(n, dtype=bool),
        on_front=np.zeros(n, dtype=bool),
        rank=np.zeros(n, dtype=np.int64),
        dr_chain_db=np.full(n, np.nan),
        dr_chain_db_extrapolated=np.full(n, np.nan),
    )
    return DesignTable(columns, spec.keys)


def _key_column(values: np.ndarray) -> np.ndarray:
    """A point key's values: numbers as float64, anything else as text (lists as JSON)."""
    vals = list(values)
    if all(isinstance(v, int | float) and not isinstance(v, bool) for v in vals):
        return np.asarray(vals, dtype=np.float64)
    return np.asarray([json.dumps(v) if isinstance(v, list | dict) else str(v) for v in vals])


def _cell(v: Any) -> Any:
    if isinstance(v, bool | np.bool_):
        return "true" if v else "false"
    if isinstance(v, float | np.floating):
        return "" if math.isnan(v) else float(v)
    if isinstance(v, np.integer):
        return int(v)
    return v


def _docs(table: DesignTable) -> dict[str, tuple[str, str]]:
    docs = {k: (key_units(k), f"point's value of the config key {k}") for k in table.keys}
    return {c: docs.get(c) or COLUMN_DOCS[c] for c in table.columns}


def write_tables(out: Path, table: DesignTable, spec: DesignSpec, meta: Mapping[str, Any]) -> list[str]:
    """``candidates.csv`` with its sidecar ``candidates.csv.json`` and ``design.nc``; returns their names."""
    import xarray as xr

    header = list(table.columns)
    rows = [[_cell(table.columns[c][i]) for c in header] for i in range(len(table))]
    write_csv(out / "candidates.csv", header, rows)
    docs = _docs(table)
    write_json(
        out / "candidates.csv.json",
        strict_json(
            {
                **meta,
                "columns": {c: {"units": u, "meaning": d} for c, (u, d) in docs.items()},
            }
        ),
    )
    data = {}
    for c, arr in table.columns.items():
        a = arr.astype(np.int8) if arr.dtype == bool else arr
        data[c] = ("candidate", a, {"units": docs[c][0], "long_name": docs[c][1]})
    ds = xr.Dataset(data)
    ds.attrs.update(
        title=f"bench_sim design {spec.name}",
        seed=int(spec.seed),
        noise=spec.noise,
        spec=json.dumps(spec.as_dict(), default=str),
        design_sha256=str(meta.get("design_sha256")),
        base_config=config_to_toml_text(spec.base),
        version=__version__,
    )
    with atomic_path(out / "design.nc") as tmp:
        ds.to_netcdf(tmp)
    return ["candidates.csv", "candidates.csv.json", "design.nc"]


def reference_of(spec: DesignSpec) -> tuple[int, int, int, str]:
    """The reference candidate ``(mu1, mu2, beta_bits, rule)``: the configured pair by eq. 11 (else
    the first rule) at the base's word (else the pass's)."""
    words, rules = spec.space.words, spec.space.rules
    beta = spec.base.dtdi.beta_bits if spec.base.dtdi.beta_bits in words else spec.space.pass_beta
    return (*spec.reference, beta, "eq11" if "eq11" in rules else rules[0])


def judge(table: DesignTable, spec: DesignSpec) -> Choice:
    """Judge the table by the spec's constraints and ranking rule
    (:func:`bench_sim.workflows.design.objectives.choose`) and fill its ``feasible``, ``on_front``
    and ``rank`` columns."""
    choice = choose(table.columns, spec.constraints, spec.rank, reference_of(spec))
    c = table.columns
    c["feasible"][:] = choice.feasible
    c["on_front"][:] = choice.front
    c["rank"][:] = 0
    for k, i in enumerate(choice.ranked):
        c["rank"][i] = k + 1
    return choice
