"""``bench-sim mtf SIMULATION``: the e-SFR of every stage a ``simulate`` output holds.

Input: the folder ``bench-sim simulate`` wrote, or its ``simulation.zarr``, ``simulation.nc`` or
(``--format tiff``) ``meta.json``. The bench's config and the pass's truth come with it. The
edges are found once, in the truth ``reflectance`` of the smallest stage
(:func:`bench_sim.metrics.edge_finder.find_edges`: any target, the noise-free image in the
image's own pixel grid), or given with ``--roi``; every stage image and ``gamma_hdr`` is
flat-fielded as :func:`bench_sim.measure.sharpness.stage_images` does and each edge measured on
it (:func:`bench_sim.metrics.sfr_table.read_edges`); clipped pixels are left out. Near-horizontal
edges give the SFR **along** the track (frequencies per output line), near-vertical ones
**across** it; the mean curve of each direction is that of
:func:`bench_sim.measure.sharpness.mean_curve`. cycles/mm are on the sensor (``sensor.pixel_pitch_m``
unless ``--pixel-pitch-um``).

Outputs (one set in ``--out``): ``edges.csv`` (stage, then the columns of
:data:`bench_sim.workflows.mtf.EDGE_COLUMNS`), ``sfr_edges.csv`` (every stage's every edge's
curve), ``sfr_stages.csv`` (the mean curve per stage and direction), ``stages.csv`` (MTF50,
MTF50P, the SFR at Nyquist and the edges used, per stage and direction), ``sfr.png``,
``rois.png`` and ``summary.json``.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from bench_sim.config import BenchConfig, config_from_dict
from bench_sim.errors import BenchSimError
from bench_sim.io import image_file_problem, output_set, read_json, write_json
from bench_sim.measure.sharpness import DIRECTIONS, SFR_FREQUENCY_CYC_PX, StageImage, mean_curve, stage_images
from bench_sim.metrics.edge_finder import find_edges
from bench_sim.metrics.sfr import check_roi_bounds
from bench_sim.metrics.sfr_readings import mtf50p, mtf_at
from bench_sim.metrics.sfr_table import EdgeReading, EdgeRefusal, read_edges
from bench_sim.version import __version__
from bench_sim.workflows import mtf_figures, mtf_tables

if TYPE_CHECKING:
    import xarray as xr

__all__ = ["is_simulation_output", "open_simulation", "run_simulation_mtf", "SIMULATION_FILES"]

#: the files ``bench-sim mtf`` writes for a simulate output
SIMULATION_FILES = ("edges.csv", "sfr_edges.csv", "sfr_stages.csv", "stages.csv", "sfr.png", "rois.png",
                    "summary.json")
_NAMES = ("simulation.zarr", "simulation.nc", "meta.json")


def _source(path: Path) -> Path | None:
    """The store or ``meta.json`` of a simulate output at ``path``, ``None`` if it is none."""
    if path.is_dir() and path.suffix != ".zarr":
        found = [path / n for n in _NAMES if (path / n).exists()]
        return found[0] if found else None
    if path.suffix == ".zarr" and path.is_dir() or path.suffix == ".nc" and path.is_file():
        return path
    if path.name == "meta.json" and path.is_file():
        return path
    return None


def is_simulation_output(path: Path) -> bool:
    """Whether ``path`` is a ``simulate`` output (module docstring) rather than an image file."""
    return _source(Path(path)) is not None


def _read_tiff(path: Path) -> np.ndarray:
    """One TIFF of a simulate output, its header checked first (a FIFO, an empty image or one
    claiming too many pixels is one line, :func:`bench_sim.io.image_file_problem`)."""
    import tifffile

    problem = image_file_problem(path)
    if problem is not None:
        raise BenchSimError(f"{path}: {problem}")
    return np.asarray(tifffile.imread(path))


def _tiff_dataset(meta_path: Path) -> tuple[xr.Dataset, dict[str, Any], str]:
    """The TIFF set of ``simulate --format tiff`` as a dataset, its config and the config's SHA-256."""
    import xarray as xr

    meta = read_json(meta_path)
    files = meta.get("files") if isinstance(meta, dict) else None
    if not isinstance(files, dict) or "config" not in meta:
        raise BenchSimError(f"{meta_path}: not the meta.json of a simulate output (no 'files' or 'config')")
    stages = sorted({int(f["stage"]) for f in files.values() if f.get("stage") is not None})
    data: dict[str, Any] = {}
    for var in ("dn", "photons", "reflectance", "clipped"):
        names = [n for m in stages for n, f in files.items() if f["variable"] == var and f["stage"] == m]
        if len(names) == len(stages) and stages:
            data[var] = (("stage", "line", "column"),
                         np.stack([_read_tiff(meta_path.parent / n) for n in names]))
    for n, f in files.items():
        if f.get("stage") is None and f["variable"] in ("gamma_hdr", "gamma_hdr_source"):
            data[f["variable"]] = (("line", "column"), _read_tiff(meta_path.parent / n))
    if "dn" not in data:
        raise BenchSimError(f"{meta_path}: lists no stage words (stage_MMM_dn.tiff)")
    if "clipped" in data:
        data["clipped"] = (data["clipped"][0], data["clipped"][1].astype(bool))
    return xr.Dataset(data, coords={"stage": stages}), meta["config"], str(meta.get("config_sha256", ""))


def open_simulation(path: Path) -> tuple[xr.Dataset, BenchConfig, str]:
    """A simulate output's dataset (loaded), its bench and the config's SHA-256."""
    import xarray as xr

    src = _source(Path(path))
    if src is None:
        raise BenchSimError(f"{path}: not a simulate output (no {', '.join(_NAMES)})")
    try:
        if src.name == "meta.json":
            ds, settings, sha = _tiff_dataset(src)
        else:
            ds = (xr.open_zarr(src) if src.suffix == ".zarr" else xr.open_dataset(src)).load()
            settings = tomllib.loads(str(ds.attrs.get("config", "")))
            sha = str(ds.attrs.get("config_sha256", ""))
    except BenchSimError:
        raise
    except Exception as exc:
        detail = " ".join(str(exc).split())[:120]
        raise BenchSimError(f"{src}: cannot read the simulate output ({detail})") from None
    if not settings:
        raise BenchSimError(f"{src}: the simulate output carries no config")
    return ds, config_from_dict(settings, source=f"{src} (its config)"), sha


def _edges(ds: xr.Dataset, rois: tuple[str, ...]) -> list[Any]:
    """The edges of the pass: the ROIs given, else those found in the truth reflectance (or, without
    it, in the smallest stage's words)."""
    plane = ds["reflectance"] if "reflectance" in ds else ds["dn"]
    ref = np.asarray(plane.isel(stage=0).values, dtype=np.float64)
    if rois:
        out = []
        for text in rois:
            try:
                box = tuple(int(v) for v in text.split(","))
            except ValueError:
                raise BenchSimError(f"--roi = {text!r}: expected four integers x0,y0,x1,y1") from None
            if len(box) != 4:
                raise BenchSimError(f"--roi = {text!r}: expected four integers x0,y0,x1,y1")
            x0, y0, x1, y1 = box
            out.append(check_roi_bounds((x0, y0, x1, y1), ref.shape[1], ref.shape[0], f"--roi = {text!r}"))
        return out
    return find_edges(ref)


def _direction(readings: list[EdgeReading], orientation: str) -> dict[str, Any]:
    """The mean curve of one direction's edges and its readings."""
    mean = mean_curve([(r.frequency_cyc_px, r.result.sfr) for r in readings
                       if r.result.orientation == orientation])
    return {"sfr": mean.sfr, "mtf50_cyc_px": mean.mtf50_cyc_px, "edges": mean.edges,
            "mtf50p_cyc_px": mtf50p(SFR_FREQUENCY_CYC_PX, mean.sfr) if mean.edges else float("nan"),
            "mtf_nyquist": mtf_at(SFR_FREQUENCY_CYC_PX, mean.sfr, 0.5) if mean.edges else float("nan")}


def _measure(images: list[StageImage], edges: list[Any], axis: str, pitch_m: float
             ) -> list[tuple[StageImage, list[EdgeReading], list[EdgeRefusal], dict[str, dict[str, Any]]]]:
    out = []
    for s in images:
        valid = np.isfinite(s.image)
        readings, refusals = read_edges(s.image, edges, axis=axis, valid=valid, clipped=s.clipped,
                                        pixel_pitch_m=pitch_m, where=f"{s.name}: ")
        out.append((s, readings, refusals, {d: _direction(readings, o) for d, o in DIRECTIONS.items()}))
    return out


def run_simulation_mtf(path: Path, *, out: Path, rois: tuple[str, ...] = (), channel: str | None = None,
                       mask: Path | None = None, axis: str = "normal", pixel_pitch_um: float | None = None
                       ) -> dict[str, Any]:
    """``bench-sim mtf SIMULATION`` (module docstring); returns the summary."""
    if channel is not None or mask is not None:
        raise BenchSimError(f"{path}: a simulate output has one channel and its own clip flags: "
                            "--channel and --mask apply to image files")
    ds, cfg, sha = open_simulation(path)
    edges = _edges(ds, rois)
    pitch_m = cfg.sensor.pixel_pitch_m if pixel_pitch_um is None else pixel_pitch_um * 1e-6
    results = _measure(stage_images(ds, cfg), edges, axis, pitch_m)
    if not any(r[1] for r in results):
        problems = "; ".join(f"edge {f.edge}: {f.problem}" for f in results[0][2][:3]) or "no edge found"
        raise BenchSimError(f"{path}: no usable slanted edge in any stage ({problems})")
    meta = {"command": "mtf", "version": __version__, "input": {"path": str(path), "config_sha256": sha},
            "bench": cfg.name, "pixel_pitch_m": pitch_m,
            "frequency_axis": "along the edge normal (ISO 12233:2017)" if axis == "normal" else
            "along the pixel rows (near-vertical edges) or columns (near-horizontal): f cos(angle)",
            "directions": "along the track: near-horizontal edges, cycles per output line; across: "
            "near-vertical edges, cycles per column",
            "rois": "given (--roi)" if rois else
            "found in the truth reflectance (bench_sim.metrics.edge_finder)",
            "method": "ISO 12233:2017 e-SFR (bench_sim.metrics.sfr), flat-fielded stage words"}
    summary = {**meta, "stages": mtf_tables.stage_records(results)}
    record = {"command": "mtf", "version": __version__, "input_config_sha256": sha}
    first = results[0]
    reflectance = ds["reflectance"].isel(stage=0).values if "reflectance" in ds else first[0].image
    with output_set(out, record) as tmp:
        mtf_tables.write_tables(tmp, results, meta)
        mtf_figures.stages_figure(tmp / "sfr.png", results, meta)
        mtf_figures.rois_figure(tmp / "rois.png", np.asarray(reflectance, dtype=np.float64),
                                np.ones(first[0].image.shape, dtype=bool), first[1], first[2], meta,
                                title=f"{len(first[1])} edges measured on {first[0].name} (green), "
                                f"{len(first[2])} refused (red)")
        write_json(tmp / "summary.json", summary)
    return summary
