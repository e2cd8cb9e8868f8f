"""The one-screen summary ``bench-sim simulate`` prints at the end: what was written and how big,
the bench, seed and stages, the clipped fraction of every stage, the time, and how to open it.

It is read back from the output set itself (the files and their metadata), so it says what is on
disk, whatever wrote it.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.io import format_bytes

__all__ = ["folder_sizes", "clipped_fractions", "simulate_summary"]

#: how each format is opened (Python), shown at the end of the summary
OPEN_HINT = {
    "zarr": 'xarray.open_zarr("{path}")',
    "netcdf": 'xarray.open_dataset("{path}")',
    "tiff": "tifffile.imread(...) per file; {path} lists them with their units",
}
FORMAT_FILES = {"zarr": "simulation.zarr", "netcdf": "simulation.nc", "tiff": "meta.json"}


def folder_sizes(out: Path) -> list[tuple[str, int]]:
    """``(name, bytes)`` of every visible entry of ``out`` (a folder's size is its files' sum)."""
    sizes = []
    for p in sorted(out.iterdir()):
        if p.name.startswith("."):
            continue
        size = sum(f.stat().st_size for f in p.rglob("*") if f.is_file()) if p.is_dir() else p.stat().st_size
        sizes.append((p.name, size))
    return sizes


def clipped_fractions(out: Path, fmt: str) -> tuple[dict[int, float], dict[str, Any]]:
    """The fraction of clipped pixels of every stage (``clipped``: a read hit full well or the
    ADC top, or the word its top) and the run's metadata, read from the output set ``out``."""
    if fmt == "tiff":
        import tifffile

        meta = json.loads((out / "meta.json").read_text())
        fractions = {}
        for m in meta.get("stages", []):
            path = out / f"stage_{int(m):03d}_clipped.tiff"
            if path.is_file():
                img = tifffile.imread(path)
                fractions[int(m)] = float(np.mean(img > 0))
                meta.setdefault("dims", {"line": img.shape[0], "column": img.shape[1]})
        return fractions, meta
    import xarray as xr

    path = out / FORMAT_FILES[fmt]
    ds = xr.open_zarr(path) if fmt == "zarr" else xr.open_dataset(path)
    try:
        clipped = ds["clipped"].astype(bool).mean(dim=("line", "column")).values
        fractions = {int(m): float(f) for m, f in zip(ds["stage"].values, clipped, strict=True)}
        meta = dict(ds.attrs)
        meta.setdefault("dims", dict(ds.sizes))
    finally:
        ds.close()
    return fractions, meta


def _bench_name(meta: dict[str, Any]) -> str:
    cfg = meta.get("config")
    if isinstance(cfg, dict):
        return str(cfg.get("name", "?"))
    if isinstance(cfg, str):  # the resolved config as TOML text
        for line in cfg.splitlines():
            if line.startswith("name = "):
                return line.split("=", 1)[1].strip().strip('"')
    return "?"


def simulate_summary(out: Path, fmt: str, wall_s: float) -> str:
    """The summary of the simulation written to ``out`` in format ``fmt``, ``wall_s`` [s] after
    the command started: at most a dozen lines."""
    out = Path(out)
    fractions, meta = clipped_fractions(out, fmt)
    sizes = folder_sizes(out)
    total = sum(s for _, s in sizes)
    dims = meta.get("dims") or {}
    shape = ""
    if isinstance(dims, dict):
        shape = f"{dims.get('line', '?')} lines x {dims.get('column', '?')} columns"
    stages = ", ".join(str(m) for m in fractions) or "?"
    engine = f"engine {meta.get('engine', '?')} ({meta.get('variant', '?')})"
    lines = [
        f"simulate: bench {_bench_name(meta)!r}, seed {meta.get('seed', '?')}, stages {stages}"
        + (f", {shape}" if shape else "") + f"; {engine}; {wall_s:.1f} s",
        f"wrote {out}/ ({format_bytes(total)}):",
    ]
    shown = sizes if len(sizes) <= 6 else sizes[:5]
    lines += [f"  {name:<32} {format_bytes(size):>10}" for name, size in shown]
    if len(sizes) > len(shown):
        rest = sizes[len(shown):]
        lines.append(f"  ... {len(rest)} more files, {format_bytes(sum(s for _, s in rest))}")
    worst = max(fractions.values(), default=0.0)
    clip = "   ".join(f"stage {m}: {100 * f:.2f} %" for m, f in fractions.items())
    lines.append(f"clipped (full well, ADC or word top): {clip}" if fractions else "clipped: (not stored)")
    if worst > 0.5:
        lines.append(
            "more than half of a stage is clipped: lower the lights or the stage, or widen dtdi.beta_bits"
        )
    lines.append("open it: " + OPEN_HINT[fmt].format(path=out / FORMAT_FILES[fmt]))
    return "\n".join(lines)
