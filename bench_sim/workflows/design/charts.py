"""The plots of a design (``DIR/plots/``).

``pareto.png``
    Every candidate's closed-form DR against its RMS error against the true HDR target, coloured
    by the share of its pixels taken from a clipped stage; the Pareto front ringed, the
    recommended design, the runner-up and the configured pair marked.
``heatmaps.png``
    Each reported objective (a row) over the stage pairs (``mu1`` across, ``mu2`` up), one panel
    per rule, at the recommended design's point and word (the first point and the pass's word
    when none is feasible).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.io import write_figure_png
from bench_sim.workflows.design.objectives import OBJECTIVES, Choice
from bench_sim.workflows.design.table import DesignTable

__all__ = ["plot_pareto", "plot_heatmaps", "DPI"]

#: resolution of the plots [dots per inch]
DPI = 90


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_pareto(out: Path, table: DesignTable, choice: Choice, meta: Mapping[str, Any]) -> str:
    """``plots/pareto.png`` (module docstring); returns its name."""
    plt = _pyplot()
    c = table.columns
    x = np.asarray(c["truth_rms"], dtype=np.float64)
    y = np.asarray(c["dr_db"], dtype=np.float64)
    share = np.asarray(c["clipped_share"], dtype=np.float64)
    fig, ax = plt.subplots(figsize=(7.0, 4.6), dpi=DPI)
    ok = np.isfinite(x) & np.isfinite(y) & (x > 0)
    sc = ax.scatter(
        x[ok],
        y[ok],
        c=share[ok],
        s=6,
        cmap="viridis",
        vmin=0.0,
        vmax=max(float(np.nanmax(share)) if share.size else 0.0, 1e-6),
        alpha=0.7,
        linewidths=0,
    )
    front = ok & choice.front
    ax.scatter(
        x[front],
        y[front],
        s=40,
        facecolors="none",
        edgecolors="k",
        linewidths=0.8,
        label="Pareto front (DR, truth RMS, clipped share)",
    )
    marks = (  # the recommended design last, on top (a runner-up that ties with it sits below)
        ("configured pair", choice.reference, "s", "C0", 120),
        ("runner-up", choice.runner_up, "D", "C1", 120),
        ("recommended", choice.recommended, "*", "C3", 200),
    )
    for label, i, marker, color, size in marks:
        if i is not None and ok[i]:
            ax.scatter(
                [x[i]],
                [y[i]],
                marker=marker,
                s=size,
                color=color,
                edgecolors="k",
                label=f"{label}: {c['stages'][i]} {c['rule'][i]} {c['beta_bits'][i]}-bit",
            )
    if ok.any():
        ax.set_xscale("log")
    ax.set_xlabel("RMS relative error against the true HDR target (whole image)")
    ax.set_ylabel("DR of Gamma_HDR, closed form [dB]")
    fig.colorbar(sc, ax=ax, label="share of pixels from a clipped stage")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7, loc="lower right")
    ax.set_title(f"{len(table)} candidates: DR against truth error", fontsize=10)
    fig.tight_layout()
    write_figure_png(out / "plots" / "pareto.png", fig, dict(meta, figure="Pareto front"), dpi=DPI)
    return "plots/pareto.png"


def _grid(table: DesignTable, sel: np.ndarray, objective: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The objective over (mu1, mu2) of the selected pairs: stages across, stages up, values."""
    c = table.columns
    lows = np.unique(c["mu1"][sel])
    highs = np.unique(c["mu2"][sel])
    grid = np.full((highs.size, lows.size), np.nan)
    li = {int(m): k for k, m in enumerate(lows)}
    hi = {int(m): k for k, m in enumerate(highs)}
    for i in np.flatnonzero(sel):
        grid[hi[int(c["mu2"][i])], li[int(c["mu1"][i])]] = float(c[objective][i])
    return lows, highs, grid


def _edges(stages: np.ndarray) -> np.ndarray:
    """Cell edges around the stages: half-way between neighbours, half a step beyond the ends."""
    m = np.asarray(stages, dtype=np.float64)
    if m.size == 1:
        return np.array([m[0] - 0.5, m[0] + 0.5])
    mid = (m[1:] + m[:-1]) / 2
    return np.concatenate([[m[0] - (mid[0] - m[0])], mid, [m[-1] + (m[-1] - mid[-1])]])


def _heat_panel(ax: Any, fig: Any, table: DesignTable, sel: np.ndarray, obj: str, title: str) -> None:
    """One heat map: ``obj`` over (mu1, mu2) of the selected pairs."""
    o = OBJECTIVES[obj]
    lows, highs, grid = _grid(table, sel, obj)
    im = ax.pcolormesh(_edges(lows), _edges(highs), np.ma.masked_invalid(grid), cmap="viridis")
    fig.colorbar(im, ax=ax, label=f"[{o.units}]")
    better = {"max": "higher", "min": "lower", "zero": "nearer 0"}[o.direction]
    ax.set_title(f"{obj}: {title} ({better} is better)", fontsize=7)
    ax.set_xlabel("mu1 (low stage)", fontsize=7)
    ax.set_ylabel("mu2 (high stage)", fontsize=7)
    ax.tick_params(labelsize=6)


def plot_heatmaps(out: Path, table: DesignTable, choice: Choice, objectives: Sequence[str],
                  meta: Mapping[str, Any]) -> list[str]:
    """``plots/heatmaps.png``: a heat map per objective (rows) and rule (columns) over the stage
    pairs (module docstring); returns its name (none without pairs)."""
    plt = _pyplot()
    c = table.columns
    best = choice.recommended
    point = int(c["point"][best]) if best is not None else int(c["point"][0])
    beta = int(c["beta_bits"][best]) if best is not None else int(np.max(c["beta_bits"]))
    base = (c["point"] == point) & (c["beta_bits"] == beta) & (c["mu_mid"] == 0)
    rules = [r for r in dict.fromkeys(str(r) for r in c["rule"]) if (base & (c["rule"] == r)).any()]
    if not rules or not objectives:
        return []
    size = (3.3 * len(rules) + 0.6, 2.7 * len(objectives))
    fig, axes = plt.subplots(len(objectives), len(rules), figsize=size, dpi=DPI, squeeze=False,
                             layout="constrained")
    for row, obj in zip(axes, objectives, strict=True):
        for ax, rule in zip(row, rules, strict=True):
            _heat_panel(ax, fig, table, base & (c["rule"] == rule), obj, f"{rule}, {beta}-bit")
            if best is not None and str(c["rule"][best]) == rule and not c["mu_mid"][best]:
                ax.plot([c["mu1"][best]], [c["mu2"][best]], "r*", ms=8)
    fig.suptitle(f"Objectives over the stage pairs (point {point}; red star: the recommended design)",
                 fontsize=9)
    write_figure_png(out / "plots" / "heatmaps.png", fig, dict(meta, figure="heat maps per objective"),
                     dpi=DPI)
    return ["plots/heatmaps.png"]
