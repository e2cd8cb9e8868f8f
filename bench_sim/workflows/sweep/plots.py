"""The plots of a sweep (``DIR/plots/``): every metric group against each swept key
(``<key>.png``) and, for a two-parameter product, the main metrics as heat maps over the grid
(``heatmaps.png``). They are drawn from ``sweep.nc``'s dataset
(:func:`bench_sim.workflows.sweep.points.to_dataset`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from bench_sim.io import write_figure_png
from bench_sim.workflows.sweep.plan import SweepPlan, column_docs
from bench_sim.workflows.sweep.points import all_numeric, key_units, short_key, value_label

__all__ = ["PLOT_GROUPS", "HEATMAPS", "DPI", "plot_key", "plot_heatmaps"]

#: Figure panels: title -> (units, metric columns). Banding columns form one more panel.
PLOT_GROUPS: dict[str, tuple[str, tuple[str, ...]]] = {
    "measured DR (camera)": ("dB", ("dr_db_gamma1", "dr_db_gamma2", "dr_db_gamma_hdr")),
    "DR gain of Gamma_HDR (camera)": ("dB", ("gain_db_vs_gamma1", "gain_db_vs_gamma2", "eq15_db")),
    "gain over Gamma1: camera DR and wedge captured": (
        "dB", ("gain_db_vs_gamma1", "captured_gain_db_vs_gamma1")
    ),
    "wedge range captured (scene)": (
        "dB",
        ("scene_range_db", "captured_range_db_gamma1", "captured_range_db_gamma2",
         "captured_range_db_gamma_hdr"),
    ),
    "clipped fraction (scene)": ("1", ("clipped_fraction_gamma1", "clipped_fraction_gamma2",
                                       "clipped_fraction_gamma_hdr")),
    "SNR of the darkest step (scene)": ("1", ("snr_darkest_gamma1", "snr_darkest_gamma2",
                                              "snr_darkest_gamma_hdr")),
    "SNR of the brightest step (scene)": ("1", ("snr_brightest_gamma1", "snr_brightest_gamma2",
                                                "snr_brightest_gamma_hdr")),
    "omega, eq. 17 (scene)": ("1", ("omega_gamma1", "omega_gamma2", "omega_gamma_hdr")),
}
#: Metrics drawn as heat maps of a two-parameter product.
HEATMAPS = (
    "gain_db_vs_gamma1", "gain_db_vs_gamma2", "dr_db_gamma_hdr", "captured_gain_db_vs_gamma1",
    "scene_range_db", "snr_darkest_gamma_hdr", "clipped_fraction_gamma_hdr",
)
#: Resolution of the plots [dots per inch]
DPI = 90
#: Line styles and markers of the other keys' value combinations (product mode)
STYLES = ("-", "--", ":", "-.")
MARKERS = ("o", "s", "^", "D", "v", "P")
#: More combinations of the other keys than this: their mean and range are drawn
MAX_COMBOS = 6


class _KeyData(NamedTuple):
    """What one key's figure draws: positions along the key, tick labels (categorical keys),
    log axis, the combinations of the other keys' values, the other keys, the data (transposed
    to the key first in product mode, else the points that vary it) and the points' order."""

    x: np.ndarray
    ticks: list[str] | None
    log: bool
    combos: list[tuple[int, ...]]
    others: list[str]
    data: Any
    order: np.ndarray | None


def _groups(plan: SweepPlan) -> dict[str, tuple[str, tuple[str, ...]]]:
    groups = dict(PLOT_GROUPS)
    banding = tuple(c for c in plan.columns if c.startswith("banding_"))
    if banding:
        groups["flicker banding per stage (scene)"] = ("1", banding)
    return groups


def _xaxis(values: Sequence[Any]) -> tuple[np.ndarray, list[str] | None, bool]:
    """Positions, tick labels (categorical keys) and whether to use a log axis."""
    if all_numeric(values):
        x = np.asarray(values, dtype=np.float64)
        pos = x[x > 0]
        log = pos.size == x.size and x.size > 2 and pos.max() / pos.min() >= 20
        return x, None, bool(log)
    return np.arange(len(values), dtype=np.float64), [value_label(v) for v in values], False


def _key_data(plan: SweepPlan, ds: Any, key: str) -> _KeyData:
    spec = plan.spec
    if spec.mode == "product":
        others = [k for k in spec.keys if k != key]
        combos: list[tuple[int, ...]] = [()]
        if others:
            combos = list(np.ndindex(*[len(spec.values[k]) for k in others]))
        x, ticks, log = _xaxis(spec.values[key])
        return _KeyData(x, ticks, log, combos, others, ds.transpose(key, *others), None)
    sel = ds.where(ds["varied"] == key, drop=True) if spec.mode == "sequential" else ds
    vals = list(sel[key].values)
    order = np.argsort(np.asarray(vals)) if all_numeric(vals) else np.arange(len(vals))
    x, ticks, log = _xaxis([vals[i] for i in order])
    return _KeyData(x, ticks, log, [()], [], sel, order)


def _draw_panel(ax: Any, mode: str, kd: _KeyData, cols: Sequence[str], colors: Sequence[str]) -> list[Any]:
    """One panel's curves: colour is the metric; in product mode line style and marker are the
    other keys' values (their mean and range over more than :data:`MAX_COMBOS`). Returns the
    legend handles of the metrics."""
    from matplotlib.lines import Line2D

    x, many = kd.x, len(kd.combos) > MAX_COMBOS
    handles = []
    for ci, col in enumerate(cols):
        if col not in kd.data:
            continue
        color = colors[ci % len(colors)]
        handles.append(Line2D([], [], color=color, marker="o", ms=4, label=short_key(col)))
        if mode != "product":
            y = np.asarray(kd.data[col].values, dtype=np.float64)[kd.order]
            ax.plot(x, y, marker="o", ms=4, ls="-" if mode == "sequential" else "none", color=color)
            continue
        arr = np.asarray(kd.data[col].values, dtype=np.float64).reshape(len(x), -1)
        if many:
            ax.fill_between(x, np.nanmin(arr, axis=1), np.nanmax(arr, axis=1), color=color, alpha=0.2)
            ax.plot(x, np.nanmean(arr, axis=1), marker="o", ms=4, color=color)
        else:
            for j in range(len(kd.combos)):
                ax.plot(x, arr[:, j], ls=STYLES[j % len(STYLES)], marker=MARKERS[j % len(MARKERS)],
                        color=color, ms=4, lw=1.2)
    return handles


def _style_panel(ax: Any, kd: _KeyData, key: str, title: str, units: str, handles: list[Any]) -> None:
    """Axes, scales (log where the values span 20x), labels, grid and legend of one panel."""
    x = kd.x
    if kd.ticks is not None:
        ax.set_xticks(x, kd.ticks, rotation=30, fontsize=7)
    elif not kd.log and len(np.unique(x)) <= 8:
        ax.set_xticks(np.unique(x), [value_label(float(v)) for v in np.unique(x)])
    if kd.log:
        ax.set_xscale("log")
    if title.startswith(("omega", "SNR")):
        shown = [v for ln in ax.get_lines() for v in np.asarray(ln.get_ydata(), dtype=float)]
        pos = [v for v in shown if np.isfinite(v) and v > 0]
        if pos and max(pos) / min(pos) >= 20:
            ax.set_yscale("log")
    ax.set_title(title, fontsize=9)
    ax.set_xlabel(f"{key} [{key_units(key)}]", fontsize=8)
    ax.set_ylabel(f"[{units}]", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.grid(alpha=0.3)
    ax.legend(handles=handles, fontsize=6)


def _combo_legend(fig: Any, spare: list[Any], plan: SweepPlan, kd: _KeyData) -> None:
    """The legend of the other keys' values (product mode): in a spare panel, else below."""
    from matplotlib.lines import Line2D

    spec = plan.spec
    over = ", ".join(map(short_key, kd.others))
    if len(kd.combos) > MAX_COMBOS:
        keys = [Line2D([], [], color="0.4", label=f"mean and range over {over}")]
    else:
        keys = [
            Line2D([], [], color="0.4", ls=STYLES[j % len(STYLES)], marker=MARKERS[j % len(MARKERS)],
                   ms=4, label=", ".join(f"{short_key(o)} = {value_label(spec.values[o][c])}"
                                         for o, c in zip(kd.others, combo, strict=True)))
            for j, combo in enumerate(kd.combos)
        ]
    if spare:
        spare[0].legend(handles=keys, loc="center", fontsize=7, title=f"line style: {over}",
                        title_fontsize=7)
    else:
        fig.legend(handles=keys, loc="lower center", fontsize=7, ncol=min(len(keys), 6))
        fig.subplots_adjust(bottom=0.12)


def plot_key(out: Path, plan: SweepPlan, ds: Any, key: str, meta: Mapping[str, Any]) -> Path:
    """``plots/<key>.png``: every metric group against ``key`` (``meta``: the PNG's provenance)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    spec = plan.spec
    groups = _groups(plan)
    ncol = 3
    nrow = math.ceil(len(groups) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.6 * ncol, 3.3 * nrow), squeeze=False)
    fig.subplots_adjust(left=0.06, right=0.98, bottom=0.07, top=0.93, wspace=0.28, hspace=0.42)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    kd = _key_data(plan, ds, key)
    for ax, (title, (units, cols)) in zip(axes.flat, groups.items(), strict=False):
        handles = _draw_panel(ax, spec.mode, kd, cols, colors)
        _style_panel(ax, kd, key, title, units, handles)
    spare = list(axes.flat)[len(groups):]
    for ax in spare:
        ax.set_axis_off()
    if spec.mode == "product" and kd.others:
        _combo_legend(fig, spare, plan, kd)
    fig.suptitle(f"sweep {spec.name}: metrics against {key}", fontsize=10)
    return write_figure_png(out / "plots" / f"{_safe(key)}.png", fig, meta, dpi=DPI)


def plot_heatmaps(out: Path, plan: SweepPlan, ds: Any, meta: Mapping[str, Any]) -> Path:
    """One panel per :data:`HEATMAPS` metric over the grid of a two-key product."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    spec = plan.spec
    ky, kx = spec.keys
    docs = column_docs(plan)
    ncol = 3
    nrow = math.ceil(len(HEATMAPS) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.8 * ncol, 3.4 * nrow), squeeze=False)
    fig.subplots_adjust(left=0.08, right=0.97, bottom=0.09, top=0.92, wspace=0.45, hspace=0.55)
    for ax, col in zip(axes.flat, HEATMAPS, strict=False):
        arr = np.asarray(ds[col].transpose(ky, kx).values, dtype=np.float64)
        im = ax.imshow(arr, origin="lower", aspect="auto", cmap="viridis")
        finite = arr[np.isfinite(arr)]
        lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
        ax.set_xticks(range(len(spec.values[kx])), [value_label(v) for v in spec.values[kx]], fontsize=7)
        ax.set_yticks(range(len(spec.values[ky])), [value_label(v) for v in spec.values[ky]], fontsize=7)
        ax.set_xlabel(f"{short_key(kx)} [{key_units(kx)}]", fontsize=8)
        ax.set_ylabel(f"{short_key(ky)} [{key_units(ky)}]", fontsize=8)
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


def _safe(key: str) -> str:
    return key.replace(".", "_").replace("/", "_")
