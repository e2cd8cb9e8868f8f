"""The outputs of a sweep: ``points.csv``, ``sweep.nc``, ``plots/`` and ``report.md``.

``points.csv`` and ``sweep.nc``
    The point records as a table and as an :class:`xarray.Dataset`
    (:mod:`bench_sim.workflows.sweep.points` describes both).
``plots/``
    ``<key>.png``: every metric group against each swept key; ``heatmaps.png`` (the main
    metrics over the grid) for two-parameter products (:mod:`bench_sim.workflows.sweep.plots`).
``report.md``
    What was swept, which metrics are camera properties and which are scene-referred, what
    changed most (the range of each metric's mean over each key), eq. 15 per camera, failures.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.config import config_sha256
from bench_sim.io import atomic_path, markdown_table, write_text
from bench_sim.io.interrupts import deferred_interrupts
from bench_sim.version import __version__
from bench_sim.workflows.sweep.bands import write_points_images
from bench_sim.workflows.sweep.plan import IMAGES, SweepPlan, column_docs
from bench_sim.workflows.sweep.plots import PLOT_GROUPS, plot_heatmaps, plot_key
from bench_sim.workflows.sweep.points import (
    TEXT_COLUMNS,
    all_numeric,
    as_number,
    csv_meta,
    key_units,
    points_table,
    short_key,
    to_dataset,
    value_label,
    write_points_csv,
)

__all__ = ["write_points_csv", "write_outputs", "points_table", "to_dataset", "PLOT_GROUPS"]

#: |gain over Gamma2 (extrapolated saturation points) - eq. 15| below which eq. 15 counts as
#: holding [dB]
EQ15_TOLERANCE_DB = 0.5


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
    main effect), over the points that finished. In the order of the points (not of their
    completion), so that ties resolve alike in every run."""
    ok = {i: records[i] for i in sorted(records) if records[i]["status"] == "ok"}
    out = []
    for col, (units, kind, _meaning) in column_docs(plan).items():
        vals = {i: as_number(r["metrics"].get(col)) for i, r in ok.items()}
        finite = [v for v in vals.values() if math.isfinite(v)]
        if len(finite) < 2 or col in TEXT_COLUMNS:
            continue
        best: dict[str, Any] | None = None
        for key in plan.spec.keys:
            groups: dict[str, list[float]] = {}
            for i, r in ok.items():
                p = plan.spec.points[i]
                if plan.spec.mode == "sequential" and p.varied != key:
                    continue
                v = vals[i]
                if math.isfinite(v):
                    groups.setdefault(value_label(r["values"][key]), []).append(v)
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


def _head(
    plan: SweepPlan, ok: Mapping[int, Any], failed: Mapping[int, Any], sessions: Sequence[Any]
) -> list[str]:
    """Title, spec, counts of the points and renders, and what was swept."""
    spec = plan.spec
    renders = sum(int(r["metrics"].get("mitsuba_renders") or 0) for r in ok.values())
    lines = [f"# Sweep `{spec.name}`", ""]
    if spec.description:
        lines += [spec.description.strip(), ""]
    lines += [
        f"Spec `{spec.path.name}` (SHA-256 `{plan.sha256[:16]}`), mode **{spec.mode}**, "
        f"noise **{spec.noise}**, "
        f"root seed {spec.seed}{', --quick preset' if spec.quick else ''}; base config `{spec.base.name}` "
        f"(SHA-256 `{config_sha256(spec.base)[:16]}`), bench_sim {__version__}.",
        "",
        f"**{len(spec.points)} points**: {len(ok)} ok, {len(failed)} failed; "
        f"{renders} Mitsuba renders in all "
        f"({renders / max(len(ok), 1):.2g} per point: a light-power or flicker sweep on the fast engine "
        "renders each light once per distinct scene for the whole run and forms every frame as a "
        "weighted sum). "
        f"Runs: {len(sessions)} ({sum(1 for s in sessions if s.get('resumed'))} resumed).",
        "",
        "## What was swept",
        "",
        "| key | values |",
        "|---|---|",
    ]
    lines += [
        f"| `{k}` [{key_units(k)}] | {', '.join(value_label(v) for v in spec.values[k])} |" for k in spec.keys
    ]
    return lines


def _effects_section(plan: SweepPlan, records: Mapping[int, Mapping[str, Any]]) -> list[str]:
    """Which metrics are camera properties and which scene-referred; what changed most."""
    docs = column_docs(plan)
    lines = [
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
    return lines


def _points_section(
    plan: SweepPlan, records: Mapping[int, Mapping[str, Any]], ok: Mapping[int, Mapping[str, Any]]
) -> list[str]:
    """The main metrics of the first 200 points."""
    spec = plan.spec
    lines = ["", "## Points", ""]
    show = ["scene_range_db", "captured_gain_db_vs_gamma1", "gain_db_vs_gamma1", "gain_db_vs_gamma2",
            "snr_darkest_gamma_hdr", "clipped_fraction_gamma_hdr"]
    ratios = {as_number(r["metrics"].get("spot_fill_ratio")) for r in ok.values()}
    if len(ratios) > 1:
        show.insert(0, "spot_fill_ratio")
    show += [c for c in plan.columns if c.startswith("banding_")][:3]
    head = ["point", *(f"`{short_key(k)}`" for k in spec.keys), *show, "status"]
    rows = [
        [str(i), *(value_label(records[i]["values"][k]) for k in spec.keys),
         *(_fmt(records[i]["metrics"].get(c)) for c in show), records[i]["status"]]
        for i in sorted(records)[:200]
    ]
    lines += markdown_table(head, rows)
    if len(records) > 200:
        lines.append(f"| ... {len(records) - 200} more in points.csv | |")
    return lines


def _report(plan: SweepPlan, records: Mapping[int, Mapping[str, Any]], sessions: Sequence[Any],
            files: Sequence[str]) -> str:
    """The text of ``report.md`` (the points in their order, whatever order they finished in)."""
    spec = plan.spec
    records = dict(sorted(records.items()))
    ok = {i: r for i, r in records.items() if r["status"] == "ok"}
    failed = {i: r for i, r in records.items() if r["status"] != "ok"}
    lines = _head(plan, ok, failed, sessions)
    lines += _effects_section(plan, records)
    lines += ["", "## Eq. 15 per camera", ""]
    lines += _eq15_section(plan, ok)
    lines += _points_section(plan, records, ok)
    if failed:
        lines += ["", "## Failed points", ""]
        lines += [f"- point {i} ({', '.join(f'{k} = {value_label(v)}' for k, v in r['values'].items())}): "
                  f"`{r['error']}`" for i, r in sorted(failed.items())]
    lines += ["", "## Files", ""]
    lines += [f"- `{f}`" for f in files]
    lines += ["", f"Column units and meanings: `sweep.json` (`columns`) and `points.csv.json`. "
              f"Regenerate with `bench-sim sweep {spec.path.name} --out DIR`.", ""]
    return "\n".join(lines)


def _eq15_section(plan: SweepPlan, ok: Mapping[int, Mapping[str, Any]]) -> list[str]:
    """One row per distinct camera: gain over Gamma2 against eq. 15, and the gain over Gamma1."""
    cams: dict[tuple[Any, ...], dict[str, Any]] = {}
    for i, r in sorted(ok.items()):
        m = r["metrics"]
        key = tuple(round(as_number(m.get(f"dr_db_{name}")), 9) for name in IMAGES)
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
        where = "; ".join(f"`{short_key(k)}` = {_distinct([ok[i]['values'][k] for i in pts])}" for k in keys)
        err = as_number(m.get("eq15_error_db"))
        holds = abs(err) <= EQ15_TOLERANCE_DB if math.isfinite(err) else None
        out.append(
            f"| {where} | {_fmt(m.get('dr_db_gamma1'))} / {_fmt(m.get('dr_db_gamma2'))} / "
            f"{_fmt(m.get('dr_db_gamma_hdr'))} "
            f"| {_fmt(m.get('gain_db_vs_gamma2'))} | {_fmt(m.get('gain_db_vs_gamma2_extrapolated'))} "
            f"| {_fmt(m.get('eq15_db'))} | {_fmt(holds)} "
            f"| {_fmt(m.get('eq15_by_construction'))} | {_fmt(m.get('gain_db_vs_gamma1'))} |"
        )
    return out


def _distinct(values: Sequence[Any]) -> str:
    """The distinct values, in order (numbers ascending), as text."""
    uniq = list({value_label(v): v for v in values}.values())
    if all_numeric(uniq):
        uniq = sorted(uniq)
    return ", ".join(value_label(v) for v in uniq)


def write_outputs(out: Path, plan: SweepPlan, records: Mapping[int, Mapping[str, Any]],
                  sessions: Sequence[Any] = (), plots: bool = True) -> list[str]:
    """Write ``points.csv``, ``sweep.nc``, ``plots/`` (unless ``plots`` is false) and
    ``report.md``; returns their names."""
    files = ["points.csv", "points.csv.json", "sweep.nc", "sweep.json"]
    write_points_csv(out, plan, records)
    if any((r.get("metrics") or {}).get("banding_images") for r in records.values()):
        files.append(str(write_points_images(out, records).relative_to(out)))  # banding per image
    if plan.spec.keep_images:
        files.append("images/ (one point_NNNNNN.zarr per point: its stage images, truth and Gamma_HDR)")
    ds = to_dataset(plan, records, sessions)
    # never cut by Ctrl-C: xarray's and HDF5's locks an interruption leaves held would deadlock
    # the store's own close (a hang found by scripts/ctrl_c_stress.py), and HDF5 can swallow it
    with deferred_interrupts(), atomic_path(out / "sweep.nc") as tmp:
        ds.to_netcdf(tmp)
    meta = csv_meta(plan)
    meta.pop("units", None)
    if plots and any(r["status"] == "ok" for r in records.values()):
        for key in plan.spec.keys:
            files.append(str(plot_key(out, plan, ds, key, meta).relative_to(out)))
        if plan.spec.mode == "product" and len(plan.spec.keys) == 2:
            files.append(str(plot_heatmaps(out, plan, ds, meta).relative_to(out)))
    files.append("report.md")
    write_text(out / "report.md", _report(plan, records, sessions, files))
    return files
