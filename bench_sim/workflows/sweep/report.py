"""The outputs of a sweep: ``points.csv``, ``sweep.nc``, ``plots/`` and ``report.md``.

``points.csv``
    One tidy row per point: ``point``, the swept keys (lists as JSON), ``varied`` (sequential
    mode), ``seed`` and ``stream`` (the point's ``SeedSequence(seed).spawn(..)[stream]``),
    ``config_sha256``, ``status`` (``ok`` | ``failed``), ``error`` (one line), the metrics
    (:data:`bench_sim.workflows.sweep.run.COLUMNS`, then one banding column per flickering light
    and stage), ``wall_s`` and ``worker``. ``#`` lines on top carry the provenance and the units
    of every column (``pandas.read_csv(path, comment="#")``).
``sweep.nc``
    The same as an :class:`xarray.Dataset` (``xarray.open_dataset``): in product mode one
    dimension per swept key, its values as the coordinate; in sequential and custom mode one
    dimension ``point`` with the keys as coordinates along it. Every variable has ``units``,
    ``long_name`` and ``kind`` (camera | scene | run); booleans are stored as 0/1 (NaN where the
    point failed).
``plots/``
    ``<key>.png``: every metric group against each swept key; ``heatmaps.png`` (the main
    metrics over the grid) for two-parameter products.
``report.md``
    What was swept, which metrics are camera properties and which are scene-referred, what
    changed most (the range of each metric's mean over each key), eq. 15 per camera, failures.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from bench_sim.workflows.sweep.run import SweepPlan

__all__ = ["write_points_csv", "write_outputs", "points_table", "to_dataset", "PLOT_GROUPS"]

#: Figure panels: title -> (units, metric columns). Banding columns form one more panel.
PLOT_GROUPS: dict[str, tuple[str, tuple[str, ...]]] = {
    "measured DR (camera)": ("dB", ("dr_db_gamma1", "dr_db_gamma2", "dr_db_hdr")),
    "DR gain of Gamma_HDR (camera)": ("dB", ("gain_db_vs_gamma1", "gain_db_vs_gamma2", "eq15_db")),
    "gain over Gamma1: camera DR and wedge captured": (
        "dB", ("gain_db_vs_gamma1", "captured_gain_db_vs_gamma1")
    ),
    "wedge range captured (scene)": (
        "dB",
        ("scene_range_db", "captured_range_db_gamma1", "captured_range_db_gamma2", "captured_range_db_hdr"),
    ),
    "clipped fraction (scene)": ("1", ("clipped_fraction_gamma1", "clipped_fraction_gamma2",
                                       "clipped_fraction_hdr")),
    "SNR of the darkest step (scene)": ("1", ("snr_darkest_gamma1", "snr_darkest_gamma2", "snr_darkest_hdr")),
    "SNR of the brightest step (scene)": ("1", ("snr_brightest_gamma1", "snr_brightest_gamma2",
                                                "snr_brightest_hdr")),
    "omega, eq. 17 (scene)": ("1", ("omega_gamma1", "omega_gamma2", "omega_hdr")),
}
#: Metrics drawn as heat maps of a two-parameter product.
HEATMAPS = (
    "gain_db_vs_gamma1", "gain_db_vs_gamma2", "dr_db_hdr", "captured_gain_db_vs_gamma1", "scene_range_db",
    "snr_darkest_hdr", "clipped_fraction_hdr",
)
#: Resolution of the plots [dots per inch]
DPI = 90
#: |gain over Gamma2 (extrapolated saturation points) - eq. 15| below which eq. 15 counts as
#: holding [dB]
EQ15_TOLERANCE_DB = 0.5

LEAD = ("point",)
TAIL = ("wall_s", "worker")


def _docs(plan: SweepPlan) -> dict[str, tuple[str, str, str]]:
    from bench_sim.workflows.sweep.run import BANDING_DOC, COLUMNS

    return {c: COLUMNS.get(c, BANDING_DOC) for c in plan.columns}


def _header(plan: SweepPlan) -> list[str]:
    keys = list(plan.spec.keys)
    mid = ["varied"] if plan.spec.mode == "sequential" else []
    return [*LEAD, *keys, *mid, "seed", "stream", "config_sha256", "status", "error", *plan.columns, *TAIL]


def _cell(v: Any) -> Any:
    if v is None:
        return ""
    if isinstance(v, list | dict):
        return json.dumps(v)
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


def _csv_meta(plan: SweepPlan) -> dict[str, Any]:
    from bench_sim.runtime.provenance import provenance

    units = {c: u for c, (u, _k, _d) in _docs(plan).items()}
    units.update({"wall_s": "s", "seed": "1", "stream": "1"})
    return provenance(plan.spec.base, plan.spec.seed, kind="sweep points", spec_sha256=plan.sha256,
                      swept_keys=list(plan.spec.keys), units=units)


def write_points_csv(out: Path, plan: SweepPlan, records: Mapping[int, Mapping[str, Any]]) -> Path:
    """(Re)write ``points.csv`` with every finished point."""
    from bench_sim.io import write_csv

    header, rows = points_table(plan, records)
    return write_csv(out / "points.csv", header, rows, _csv_meta(plan))


# --- values -------------------------------------------------------------------------------------


def _num(v: Any) -> float:
    """A metric as float (bool -> 0/1, missing or text -> NaN)."""
    if isinstance(v, bool):
        return float(v)
    if isinstance(v, int | float):
        return float(v)
    return float("nan")


def _label(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, list):
        return json.dumps(v)
    return str(v)


def _numeric(values: Sequence[Any]) -> bool:
    return all(isinstance(v, int | float) and not isinstance(v, bool) for v in values)


def _coord(values: Sequence[Any]) -> np.ndarray:
    if _numeric(values):
        return np.asarray(values, dtype=np.float64)
    return np.asarray([_label(v) for v in values])


def _metric_array(records: Mapping[int, Mapping[str, Any]], n: int, col: str, text: bool) -> np.ndarray:
    if text:
        out = np.full(n, "", dtype=object)
        for i, r in records.items():
            v = r.get("metrics", {}).get(col) if col not in r else r.get(col)
            out[i] = "" if v is None else str(v)
        return out.astype(str)
    arr = np.full(n, np.nan)
    for i, r in records.items():
        arr[i] = _num(r.get("metrics", {}).get(col) if col not in r else r.get(col))
    return arr


TEXT_COLUMNS = (
    "darkest_patch", "brightest_patch", "no_patches", "status", "error", "worker", "config_sha256"
)


def to_dataset(
    plan: SweepPlan, records: Mapping[int, Mapping[str, Any]], sessions: Sequence[Any] = ()
) -> Any:
    """The sweep as an :class:`xarray.Dataset` (see the module docstring)."""
    import xarray as xr

    from bench_sim.config import config_to_toml_text

    spec = plan.spec
    n = len(spec.points)
    docs = _docs(plan)
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
                vals = [_label(v) for v in vals]
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
        ds[k].attrs.update(long_name=f"swept config key {k}", units=_key_units(k))
    ds.attrs.update(
        title=f"bench_sim sweep {spec.name}",
        mode=spec.mode,
        noise=spec.noise,
        seed=int(spec.seed),
        spec=json.dumps(spec.as_dict(), default=str),
        spec_sha256=plan.sha256,
        base_config=config_to_toml_text(spec.base),
        sessions=json.dumps(list(sessions)),
        version=_version(),
    )
    return ds


def _version() -> str:
    from bench_sim.version import __version__

    return __version__


def _key_units(key: str) -> str:
    """Units of a config key from its name (``_m``, ``_s``, ``_w_m2``, ``_hz``, ...)."""
    suffixes = (("_w_m2", "W m-2"), ("_hz", "Hz"), ("_rad", "rad"), ("_deg", "deg"), ("_m", "m"),
                ("_s", "s"), ("_e", "e-"), ("_dn", "DN"), ("_k", "K"), ("_bits", "bit"))
    for suffix, units in suffixes:
        if key.endswith(suffix):
            return units
    return "1"


# --- plots --------------------------------------------------------------------------------------


def _groups(plan: SweepPlan) -> dict[str, tuple[str, tuple[str, ...]]]:
    groups = dict(PLOT_GROUPS)
    banding = tuple(c for c in plan.columns if c.startswith("banding_"))
    if banding:
        groups["flicker banding per stage (scene)"] = ("1", banding)
    return groups


def _xaxis(values: Sequence[Any]) -> tuple[np.ndarray, list[str] | None, bool]:
    """Positions, tick labels (categorical keys) and whether to use a log axis."""
    if _numeric(values):
        x = np.asarray(values, dtype=np.float64)
        pos = x[x > 0]
        log = pos.size == x.size and x.size > 2 and pos.max() / pos.min() >= 20
        return x, None, bool(log)
    return np.arange(len(values), dtype=np.float64), [_label(v) for v in values], False


def _plot_key(out: Path, plan: SweepPlan, ds: Any, key: str, meta: Mapping[str, Any]) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from bench_sim.io import write_figure_png

    spec = plan.spec
    groups = _groups(plan)
    ncol = 3
    nrow = math.ceil(len(groups) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.6 * ncol, 3.3 * nrow), squeeze=False)
    fig.subplots_adjust(left=0.06, right=0.98, bottom=0.07, top=0.93, wspace=0.28, hspace=0.42)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    styles = ["-", "--", ":", "-."]
    markers = ["o", "s", "^", "D", "v", "P"]
    if spec.mode == "product":
        others = [k for k in spec.keys if k != key]
        sub = ds.transpose(key, *others)
        combos = list(np.ndindex(*[len(spec.values[k]) for k in others])) if others else [()]
        x, ticks, log = _xaxis(spec.values[key])
    else:
        sel = ds.where(ds["varied"] == key, drop=True) if spec.mode == "sequential" else ds
        vals = list(sel[key].values)
        order = np.argsort(np.asarray(vals)) if _numeric(vals) else np.arange(len(vals))
        x, ticks, log = _xaxis([vals[i] for i in order])
        combos = [()]
    from matplotlib.lines import Line2D

    # colour: the metric (legend in each panel); line style and marker: the values of the other
    # keys (one legend for the figure); more than six combinations: their mean and range
    many = len(combos) > 6
    for ax, (title, (units, cols)) in zip(axes.flat, groups.items(), strict=False):
        handles = []
        for ci, col in enumerate(cols):
            if col not in ds:
                continue
            color = colors[ci % len(colors)]
            handles.append(Line2D([], [], color=color, marker="o", ms=4, label=_short(col)))
            if spec.mode != "product":
                y = np.asarray(sel[col].values, dtype=np.float64)[order]
                ax.plot(x, y, marker="o", ms=4, ls="-" if spec.mode == "sequential" else "none", color=color)
            elif many:
                arr = np.asarray(sub[col].values, dtype=np.float64).reshape(len(x), -1)
                ax.fill_between(x, np.nanmin(arr, axis=1), np.nanmax(arr, axis=1), color=color, alpha=0.2)
                ax.plot(x, np.nanmean(arr, axis=1), marker="o", ms=4, color=color)
            else:
                arr = np.asarray(sub[col].values, dtype=np.float64).reshape(len(x), -1)
                for j in range(len(combos)):
                    ax.plot(x, arr[:, j], ls=styles[j % len(styles)], marker=markers[j % len(markers)],
                            color=color, ms=4, lw=1.2)
        if ticks is not None:
            ax.set_xticks(x, ticks, rotation=30, fontsize=7)
        elif not log and len(np.unique(x)) <= 8:
            ax.set_xticks(np.unique(x), [_label(float(v)) for v in np.unique(x)])
        if log:
            ax.set_xscale("log")
        if title.startswith(("omega", "SNR")):
            shown = [v for ln in ax.get_lines() for v in np.asarray(ln.get_ydata(), dtype=float)]
            pos = [v for v in shown if np.isfinite(v) and v > 0]
            if pos and max(pos) / min(pos) >= 20:
                ax.set_yscale("log")
        ax.set_title(title, fontsize=9)
        ax.set_xlabel(f"{key} [{_key_units(key)}]", fontsize=8)
        ax.set_ylabel(f"[{units}]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
        ax.legend(handles=handles, fontsize=6)
    spare = list(axes.flat)[len(groups):]
    for ax in spare:
        ax.set_axis_off()
    if spec.mode == "product" and others:
        over = ", ".join(map(_short, others))
        if many:
            keys = [Line2D([], [], color="0.4", label=f"mean and range over {over}")]
        else:
            keys = [
                Line2D([], [], color="0.4", ls=styles[j % len(styles)], marker=markers[j % len(markers)],
                       ms=4, label=", ".join(f"{_short(o)} = {_label(spec.values[o][c])}"
                                             for o, c in zip(others, combo, strict=True)))
                for j, combo in enumerate(combos)
            ]
        if spare:
            spare[0].legend(handles=keys, loc="center", fontsize=7, title=f"line style: {over}",
                            title_fontsize=7)
        else:
            fig.legend(handles=keys, loc="lower center", fontsize=7, ncol=min(len(keys), 6))
            fig.subplots_adjust(bottom=0.12)
    fig.suptitle(f"sweep {spec.name}: metrics against {key}", fontsize=10)
    return write_figure_png(out / "plots" / f"{_safe(key)}.png", fig, meta, dpi=DPI)


def _plot_heatmaps(out: Path, plan: SweepPlan, ds: Any, meta: Mapping[str, Any]) -> Path:
    """One panel per :data:`HEATMAPS` metric over the grid of a two-key product."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from bench_sim.io import write_figure_png

    spec = plan.spec
    ky, kx = spec.keys
    docs = _docs(plan)
    ncol = 3
    nrow = math.ceil(len(HEATMAPS) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.8 * ncol, 3.4 * nrow), squeeze=False)
    fig.subplots_adjust(left=0.08, right=0.97, bottom=0.09, top=0.92, wspace=0.45, hspace=0.55)
    for ax, col in zip(axes.flat, HEATMAPS, strict=False):
        arr = np.asarray(ds[col].transpose(ky, kx).values, dtype=np.float64)
        im = ax.imshow(arr, origin="lower", aspect="auto", cmap="viridis")
        finite = arr[np.isfinite(arr)]
        lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
        ax.set_xticks(range(len(spec.values[kx])), [_label(v) for v in spec.values[kx]], fontsize=7)
        ax.set_yticks(range(len(spec.values[ky])), [_label(v) for v in spec.values[ky]], fontsize=7)
        ax.set_xlabel(f"{_short(kx)} [{_key_units(kx)}]", fontsize=8)
        ax.set_ylabel(f"{_short(ky)} [{_key_units(ky)}]", fontsize=8)
        if arr.size <= 120:
            for (i, j), v in np.ndenumerate(arr):
                if np.isfinite(v):
                    bright = hi > lo and (v - lo) / (hi - lo) > 0.6  # viridis is light at the top
                    ax.text(j, i, f"{v:.3g}", ha="center", va="center", fontsize=6,
                            color="k" if bright else "w")
        fig.colorbar(im, ax=ax).ax.tick_params(labelsize=7)
        units, kind, _meaning = docs[col]
        ax.set_title(f"{col} [{units}] ({kind})", fontsize=8)
    for ax in list(axes.flat)[len(HEATMAPS):]:
        ax.set_visible(False)
    fig.suptitle(f"sweep {spec.name}: {ky} x {kx}", fontsize=10)
    return write_figure_png(out / "plots" / "heatmaps.png", fig, meta, dpi=DPI)


def _short(name: str) -> str:
    return name.split(".")[-1] if "." in name else name


def _safe(key: str) -> str:
    return key.replace(".", "_").replace("/", "_")


# --- report ------------------------------------------------------------------------------------


def _fmt(v: Any) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def _effects(plan: SweepPlan, records: Mapping[int, Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Per numeric metric and key: the range of the metric's mean over the key's values (the
    main effect), over the points that finished."""
    ok = {i: r for i, r in records.items() if r["status"] == "ok"}
    out = []
    for col, (units, kind, _meaning) in _docs(plan).items():
        vals = {i: _num(r["metrics"].get(col)) for i, r in ok.items()}
        finite = [v for v in vals.values() if math.isfinite(v)]
        if len(finite) < 2 or col in TEXT_COLUMNS:
            continue
        best = None
        for key in plan.spec.keys:
            groups: dict[str, list[float]] = {}
            for i, r in ok.items():
                p = plan.spec.points[i]
                if plan.spec.mode == "sequential" and p.varied != key:
                    continue
                v = vals[i]
                if math.isfinite(v):
                    groups.setdefault(_label(r["values"][key]), []).append(v)
            if len(groups) < 2:
                continue
            means = {g: float(np.mean(v)) for g, v in groups.items()}
            lo, hi = min(means, key=means.__getitem__), max(means, key=means.__getitem__)
            eff = means[hi] - means[lo]
            if best is None or eff > best["effect"]:
                best = {"key": key, "effect": eff, "low": (lo, means[lo]), "high": (hi, means[hi])}
        out.append({"metric": col, "units": units, "kind": kind, "min": min(finite), "max": max(finite),
                    "best": best})
    return out


def _report(plan: SweepPlan, records: Mapping[int, Mapping[str, Any]], sessions: Sequence[Any],
            files: Sequence[str]) -> str:
    from bench_sim.config import config_sha256

    spec = plan.spec
    ok = {i: r for i, r in records.items() if r["status"] == "ok"}
    failed = {i: r for i, r in records.items() if r["status"] != "ok"}
    renders = sum(int(r["metrics"].get("mitsuba_renders") or 0) for r in ok.values())
    docs = _docs(plan)
    lines = [f"# Sweep `{spec.name}`", ""]
    if spec.description:
        lines += [spec.description.strip(), ""]
    lines += [
        f"Spec `{spec.path.name}` (SHA-256 `{plan.sha256[:16]}`), mode **{spec.mode}**, "
        f"noise **{spec.noise}**, "
        f"root seed {spec.seed}{', --quick preset' if spec.quick else ''}; base config `{spec.base.name}` "
        f"(SHA-256 `{config_sha256(spec.base)[:16]}`), bench_sim {_version()}.",
        "",
        f"**{len(spec.points)} points**: {len(ok)} ok, {len(failed)} failed; "
        f"{renders} Mitsuba renders in all "
        f"({renders / max(len(ok), 1):.2g} per point: a light-power or flicker sweep on the fast engine "
        "renders each light once per worker and forms every frame as a weighted sum). "
        f"Runs: {len(sessions)} ({sum(1 for s in sessions if s.get('resumed'))} resumed).",
        "",
        "## What was swept",
        "",
        "| key | values |",
        "|---|---|",
    ]
    lines += [
        f"| `{k}` [{_key_units(k)}] | {', '.join(_label(v) for v in spec.values[k])} |" for k in spec.keys
    ]
    lines += [
        "",
        "## Camera properties and scene-referred metrics",
        "",
        "- **Camera properties** (the same under any light and target; measured once per camera through "
        "the whole chain, EMVA 1288 style, as `reproduce` does): "
        + ", ".join(f"`{c}`" for c, (_u, k, _d) in docs.items() if k == "camera") + ".",
        "- **Scene-referred** (they change with the lights and the target): "
        + ", ".join(f"`{c}`" for c, (_u, k, _d) in docs.items() if k == "scene") + ".",
        "",
        "## What changed most",
        "",
        "The main effect of a key on a metric is the range of the metric's mean over the key's values "
        "(over the other keys' values in product mode).",
        "",
        "| metric | kind | units | min | max | largest effect | from -> to |",
        "|---|---|---|---:|---:|---|---|",
    ]
    effects = sorted(
        _effects(plan, records), key=lambda e: (e["units"] != "dB", -(e["best"] or {}).get("effect", 0))
    )
    unchanged = [e["metric"] for e in effects if e["min"] == e["max"]]
    for e in effects:
        if e["min"] == e["max"]:
            continue
        b = e["best"]
        eff = (f"`{b['key']}`: {b['effect']:.4g}" if b else "-")
        span = (f"{b['low'][1]:.4g} at {b['low'][0]} -> {b['high'][1]:.4g} at {b['high'][0]}" if b else "-")
        lines.append(f"| `{e['metric']}` | {e['kind']} | {e['units']} | {e['min']:.4g} | {e['max']:.4g} | "
                     f"{eff} | {span} |")
    if unchanged:
        lines += ["", "Unchanged over the sweep: " + ", ".join(f"`{c}`" for c in unchanged) + "."]
    lines += ["", "## Eq. 15 per camera", ""]
    lines += _eq15_section(plan, ok)
    lines += ["", "## Points", ""]
    show = ["scene_range_db", "captured_gain_db_vs_gamma1", "gain_db_vs_gamma1", "gain_db_vs_gamma2",
            "snr_darkest_hdr", "clipped_fraction_hdr"]
    ratios = {_num(r["metrics"].get("spot_fill_ratio")) for r in ok.values()}
    if len(ratios) > 1:
        show.insert(0, "spot_fill_ratio")
    show += [c for c in plan.columns if c.startswith("banding_")][:3]
    head = ["point", *(f"`{_short(k)}`" for k in spec.keys), *show, "status"]
    lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for i in sorted(records)[:200]:
        r = records[i]
        row = [str(i), *(_label(r["values"][k]) for k in spec.keys),
               *(_fmt(r["metrics"].get(c)) for c in show), r["status"]]
        lines.append("| " + " | ".join(row) + " |")
    if len(records) > 200:
        lines.append(f"| ... {len(records) - 200} more in points.csv | |")
    if failed:
        lines += ["", "## Failed points", ""]
        lines += [f"- point {i} ({', '.join(f'{k} = {_label(v)}' for k, v in r['values'].items())}): "
                  f"`{r['error']}`" for i, r in sorted(failed.items())]
    lines += ["", "## Files", ""]
    lines += [f"- `{f}`" for f in files]
    lines += ["", f"Column units and meanings: `sweep.json` (`columns`) and the `#` lines of `points.csv`. "
              f"Regenerate with `bench-sim sweep {spec.path.name} --out DIR`.", ""]
    return "\n".join(lines)


def _eq15_section(plan: SweepPlan, ok: Mapping[int, Mapping[str, Any]]) -> list[str]:
    """One row per distinct camera: gain over Gamma2 against eq. 15, and the gain over Gamma1."""
    cams: dict[tuple[Any, ...], dict[str, Any]] = {}
    for i, r in sorted(ok.items()):
        m = r["metrics"]
        key = tuple(round(_num(m.get(c)), 9) for c in ("dr_db_gamma1", "dr_db_gamma2", "dr_db_hdr"))
        cams.setdefault(key, {"metrics": m, "points": []})["points"].append(i)
    if not cams:
        return ["No point finished."]
    keys = list(plan.spec.keys)
    out = [
        "Eq. 15 predicts the DR gain of Gamma_HDR over Gamma2 as `20 lg(mu2/mu1)`, a ratio of clip "
        "points; it counts as holding when the gain measured with the extrapolated saturation points "
        f"(where the linear response meets the plateau) is within {EQ15_TOLERANCE_DB} dB of it. The "
        "gain with EMVA 1288's saturation (the variance maximum) is given beside it; it scatters by a "
        "few tenths of a dB. The gain over Gamma1 is the informative one (the gain over Gamma2 is "
        "eq. 15 by construction wherever both stages clip on the output word).",
        "",
        "| camera (swept keys of its points) | DR Gamma1 / Gamma2 / HDR [dB] | gain vs Gamma2 [dB] "
        "| same, extrapolated [dB] | eq. 15 [dB] | holds | by construction | gain vs Gamma1 [dB] |",
        "|---|---|---:|---:|---:|---|---|---:|",
    ]
    for cam in cams.values():
        m = cam["metrics"]
        pts = cam["points"]
        where = "; ".join(f"`{_short(k)}` = {_distinct([ok[i]['values'][k] for i in pts])}" for k in keys)
        err = _num(m.get("eq15_error_db"))
        holds = abs(err) <= EQ15_TOLERANCE_DB if math.isfinite(err) else None
        out.append(
            f"| {where} | {_fmt(m.get('dr_db_gamma1'))} / {_fmt(m.get('dr_db_gamma2'))} / "
            f"{_fmt(m.get('dr_db_hdr'))} "
            f"| {_fmt(m.get('gain_db_vs_gamma2'))} | {_fmt(m.get('gain_db_vs_gamma2_extrapolated'))} "
            f"| {_fmt(m.get('eq15_db'))} | {_fmt(holds)} "
            f"| {_fmt(m.get('eq15_by_construction'))} | {_fmt(m.get('gain_db_vs_gamma1'))} |"
        )
    return out


def _distinct(values: Sequence[Any]) -> str:
    """The distinct values, in order (numbers ascending), as text."""
    uniq = list({_label(v): v for v in values}.values())
    if _numeric(uniq):
        uniq = sorted(uniq)
    return ", ".join(_label(v) for v in uniq)


def write_outputs(out: Path, plan: SweepPlan, records: Mapping[int, Mapping[str, Any]],
                  sessions: Sequence[Any] = (), plots: bool = True) -> list[str]:
    """Write ``points.csv``, ``sweep.nc``, ``plots/`` (unless ``plots`` is false) and
    ``report.md``; returns their names."""
    from bench_sim.io import atomic_path, write_text

    files = ["points.csv", "sweep.nc", "sweep.json"]
    write_points_csv(out, plan, records)
    ds = to_dataset(plan, records, sessions)
    with atomic_path(out / "sweep.nc") as tmp:
        ds.to_netcdf(tmp)
    meta = _csv_meta(plan)
    meta.pop("units", None)
    if plots and any(r["status"] == "ok" for r in records.values()):
        for key in plan.spec.keys:
            files.append(str(_plot_key(out, plan, ds, key, meta).relative_to(out)))
        if plan.spec.mode == "product" and len(plan.spec.keys) == 2:
            files.append(str(_plot_heatmaps(out, plan, ds, meta).relative_to(out)))
    files.append("report.md")
    write_text(out / "report.md", _report(plan, records, sessions, files))
    return files
