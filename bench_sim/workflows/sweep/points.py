"""A sweep's point records as tables: ``points.csv`` and the :class:`xarray.Dataset` of ``sweep.nc``.

``points.csv``
    One tidy row per point: ``point``, the swept keys (lists as JSON), ``varied`` (sequential
    mode), ``seed`` and ``stream`` (the point's ``SeedSequence(seed).spawn(..)[stream]``),
    ``config_sha256``, ``status`` (``ok`` | ``failed``), ``error`` (one line), the metrics
    (:data:`bench_sim.workflows.sweep.plan.COLUMNS`, then one banding column per flickering light
    and stage), ``wall_s`` and ``worker``. The provenance and the units
    of every column are in the sidecar ``points.csv.json`` (and ``sweep.nc``'s attributes):
    ``pandas.read_csv(path)`` reads it as is.
``sweep.nc``
    The same as an :class:`xarray.Dataset` (``xarray.open_dataset``): in product mode one
    dimension per swept key, its values as the coordinate; in sequential and custom mode one
    dimension ``point`` with the keys as coordinates along it. Every variable has ``units``,
    ``long_name`` and ``kind`` (camera | scene | run); booleans are stored as 0/1 (NaN where the
    point failed).

The value helpers (numbers, labels, units of a key) serve the plots and the report too.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.config import config_to_toml_text
from bench_sim.io import write_csv, write_json
from bench_sim.io.strict_json import strict_dumps, strict_json
from bench_sim.version import __version__
from bench_sim.workflows.output_meta import provenance, store_attrs
from bench_sim.workflows.sweep.plan import SweepPlan, column_docs

__all__ = [
    "TEXT_COLUMNS",
    "all_numeric",
    "as_number",
    "csv_meta",
    "key_units",
    "points_table",
    "short_key",
    "to_dataset",
    "value_label",
    "write_points_csv",
]

LEAD = ("point",)
TAIL = ("wall_s", "worker")


def _header(plan: SweepPlan) -> list[str]:
    keys = list(plan.spec.keys)
    mid = ["varied"] if plan.spec.mode == "sequential" else []
    return [*LEAD, *keys, *mid, "seed", "stream", "config_sha256", "status", "error", *plan.columns, *TAIL]


def _cell(v: Any) -> Any:
    if v is None:
        return ""
    if isinstance(v, list | dict):
        return strict_dumps(v)
    if isinstance(v, bool):
        return "true" if v else "false"
    return v


def points_table(
    plan: SweepPlan, records: Mapping[int, Mapping[str, Any]]
) -> tuple[list[str], list[list[Any]]]:
    """Header and rows of ``points.csv`` (finished points, in point order)."""
    header = _header(plan)
    rows = []
    for i in sorted(records):
        r = records[i]
        flat = {**r["values"], **r.get("metrics", {})}
        flat.update({k: r.get(k) for k in ("point", "varied", "seed", "stream", "config_sha256", "status",
                                           "error", "wall_s", "worker")})
        rows.append([_cell(flat.get(h)) for h in header])
    return header, rows


def csv_meta(plan: SweepPlan) -> dict[str, Any]:
    units = {c: u for c, (u, _k, _d) in column_docs(plan).items()}
    units.update({"wall_s": "s", "seed": "1", "stream": "1"})
    return provenance(plan.spec.base, plan.spec.seed, covers=[p.cfg for p in plan.spec.points],
                      kind="sweep points", spec_sha256=plan.sha256, swept_keys=list(plan.spec.keys),
                      units=units)


#: the sidecar of ``points.csv``: its provenance and the units of every column
POINTS_META = "points.csv.json"


def write_points_csv(out: Path, plan: SweepPlan, records: Mapping[int, Mapping[str, Any]]) -> Path:
    """(Re)write ``points.csv`` (plain CSV: one header line, one row per finished point) and its
    sidecar :data:`POINTS_META`."""
    header, rows = points_table(plan, records)
    write_json(out / POINTS_META, strict_json(csv_meta(plan)))
    return write_csv(out / "points.csv", header, rows)


# --- values -------------------------------------------------------------------------------------


def as_number(v: Any) -> float:
    """A metric as float (bool -> 0/1, missing or text -> NaN)."""
    if isinstance(v, bool):
        return float(v)
    if isinstance(v, int | float):
        return float(v)
    return float("nan")


def value_label(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, list):
        return strict_dumps(v)
    return str(v)


def all_numeric(values: Sequence[Any]) -> bool:
    return all(isinstance(v, int | float) and not isinstance(v, bool) for v in values)


def _coord(values: Sequence[Any]) -> np.ndarray:
    if all_numeric(values):
        return np.asarray(values, dtype=np.float64)
    return np.asarray([value_label(v) for v in values])


def _metric_array(records: Mapping[int, Mapping[str, Any]], n: int, col: str, text: bool) -> np.ndarray:
    if text:
        out = np.full(n, "", dtype=object)
        for i, r in records.items():
            v = r.get("metrics", {}).get(col) if col not in r else r.get(col)
            out[i] = "" if v is None else str(v)
        return out.astype(str)
    arr = np.full(n, np.nan)
    for i, r in records.items():
        arr[i] = as_number(r.get("metrics", {}).get(col) if col not in r else r.get(col))
    return arr


TEXT_COLUMNS = (
    "darkest_patch", "brightest_patch", "no_patches", "status", "error", "worker", "config_sha256"
)


def to_dataset(
    plan: SweepPlan, records: Mapping[int, Mapping[str, Any]], sessions: Sequence[Any] = ()
) -> Any:
    """The sweep as an :class:`xarray.Dataset` (see the module docstring)."""
    import xarray as xr

    spec = plan.spec
    n = len(spec.points)
    docs = column_docs(plan)
    extra = {"status": ("1", "run", "ok | failed"), "error": ("1", "run", "one-line error of a failed point"),
             "wall_s": ("s", "run", "wall time of the point in its worker"),
             "worker": ("1", "run", "address of the worker that ran it"),
             "stream": ("1", "run", "index of the point's SeedSequence child"),
             "config_sha256": ("1", "run", "SHA-256 of the point's resolved config")}
    data = {}
    for col, (units, kind, meaning) in {**docs, **extra}.items():
        text = col in TEXT_COLUMNS
        data[col] = (_metric_array(records, n, col, text), units, kind, meaning)
    if spec.mode == "product":
        dims = tuple(spec.keys)
        shape = spec.shape
        coords = {k: (k, _coord(spec.values[k])) for k in spec.keys}
    else:
        dims, shape = ("point",), (n,)
        coords = {"point": ("point", np.arange(n))}
        for k in spec.keys:
            vals = [
                records[p.index]["values"][k] if p.index in records else p.values.get(k) for p in spec.points
            ]
            if any(v is None for v in vals):
                vals = [value_label(v) for v in vals]
            coords[k] = ("point", _coord(vals))
        if spec.mode == "sequential":
            coords["varied"] = ("point", np.asarray([p.varied or "" for p in spec.points]))
    ds = xr.Dataset(
        {col: (dims, arr.reshape(shape)) for col, (arr, *_r) in data.items()},
        coords={k: v for k, v in coords.items()},
    )
    for col, (_arr, units, kind, meaning) in data.items():
        ds[col].attrs.update(units=units, kind=kind, long_name=meaning)
    for k in spec.keys:
        ds[k].attrs.update(long_name=f"swept config key {k}", units=key_units(k))
    ds.attrs.update(
        title=f"bench_sim sweep {spec.name}",
        mode=spec.mode,
        noise=spec.noise,
        seed=int(spec.seed),
        spec=strict_dumps(spec.as_dict(), default=str),
        spec_sha256=plan.sha256,
        base_config=config_to_toml_text(spec.base),
        sessions=strict_dumps(list(sessions)),
        version=__version__,
        **store_attrs(spec.base, covers=[p.cfg for p in spec.points]),  # sensor_chain, truth_exact
    )
    return ds


def key_units(key: str) -> str:
    """Units of a config key from its name (``_m``, ``_s``, ``_w_m2``, ``_hz``, ...)."""
    suffixes = (("_w_m2", "W m-2"), ("_hz", "Hz"), ("_rad", "rad"), ("_deg", "deg"), ("_m", "m"),
                ("_s", "s"), ("_e", "e-"), ("_dn", "DN"), ("_k", "K"), ("_bits", "bit"))
    for suffix, units in suffixes:
        if key.endswith(suffix):
            return units
    return "1"


def short_key(name: str) -> str:
    """The last part of a dotted config key (``lights.strong.irradiance_w_m2`` -> ``irradiance_w_m2``)."""
    return name.split(".")[-1] if "." in name else name
