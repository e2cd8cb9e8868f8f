"""``bench_sim.simulate`` / ``bench-sim simulate``: any bench to its DTDI stage images, with the
exact ground truth behind every pixel, in one streaming pass.

The pass itself (frames -> sensor -> DTDI -> stage images and truth) is
:func:`bench_sim.pipeline.run_pass`; its variables (``dn``, ``mean_dn``, ``photons``,
``reflectance``, ``clipped``, ``gamma_hdr``, ``gamma_hdr_source``: dimensions, dtypes, units) are the table
:data:`bench_sim.pipeline.PASS_VARIABLES`. This module resolves the config, checks the inputs
before any rendering (:func:`check_inputs`), runs the pass with the run's seed (one generator,
drawn in a fixed order: the same config and seed give identical data with any number of threads)
and writes the :class:`xarray.Dataset` as Zarr, NetCDF or TIFF (:func:`write_simulation`).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from bench_sim.config import BenchConfig, load_config, warn_config, with_overrides
from bench_sim.errors import BenchSimError
from bench_sim.io import output_set, write_csv, write_json
from bench_sim.io.interrupts import deferred_interrupts
from bench_sim.io.strict_json import strict_dumps
from bench_sim.measure.sharpness import add_sharpness, has_slanted_edges, sharpness_curves, sharpness_summary
from bench_sim.pipeline import (
    IMAGE_DIMS,
    PASS_VARIABLES,
    STAGE_DIMS,
    PassResult,
    Variable,
    pass_variables,
    run_pass,
    stored_dataset,
)
from bench_sim.render.exposures import RenderSetup
from bench_sim.sensor.dtdi import check_stages, frames_needed
from bench_sim.sensor.pass_lines import PassSink
from bench_sim.workflows.estimates import estimate_simulate
from bench_sim.workflows.output_meta import provenance
from bench_sim.workflows.preflight import check_seed, preflight
from bench_sim.workflows.simulate_store import ZarrPassSink

if TYPE_CHECKING:
    import xarray as xr

__all__ = ["simulate", "run_pass", "PassResult", "resolve_config", "check_stages", "VARIABLES"]

#: name -> (units, long_name) of every variable of the dataset (from
#: :data:`bench_sim.pipeline.PASS_VARIABLES`)
VARIABLES: dict[str, tuple[str, str]] = {v.name: (v.units, v.doc) for v in PASS_VARIABLES}


def resolve_config(config: BenchConfig | str | Path | Mapping[str, Any] | None) -> BenchConfig:
    """A :class:`BenchConfig` from a config, a TOML path, or a dict of overrides on the default
    rig (``None``: the default rig)."""
    if config is None:
        return load_config()
    if isinstance(config, BenchConfig):
        return config
    if isinstance(config, str | Path):
        return load_config(config)
    if isinstance(config, Mapping):
        cfg = with_overrides(load_config(), dict(config), source="simulate(config=...)")
        warn_config(cfg, "simulate(config=...)")
        return cfg
    raise BenchSimError(
        f"config = {type(config).__name__}: expected a BenchConfig, a TOML path or a dict of overrides"
    )


def simulate(
    config: BenchConfig | str | Path | Mapping[str, Any] | None,
    *,
    stages: Iterable[int] | str,
    seed: int = 0,
    progress: bool = False,
) -> xr.Dataset:
    """Simulate a bench to every requested stage image with its exact ground truth.

    Parameters
    ----------
    config
        A :class:`~bench_sim.config.BenchConfig`, a TOML path, or a dict of overrides on the
        default rig (e.g. ``{"timing": {"sync_error": 0.05}}``).
    stages
        Stages ``m`` (each once, in ``1 .. sensor.rows``) or ``"all"``.
    seed
        Root seed of the run's one generator (an integer >= 0).
    progress
        Show a progress bar over the frames.

    Returns
    -------
    xarray.Dataset
        Dimensions ``stage``, ``line``, ``column``; variables ``dn``, ``mean_dn``, ``photons``,
        ``reflectance``, ``clipped`` and, when ``fusion.mu1`` and ``fusion.mu2`` are among the
        stages, ``gamma_hdr`` and ``gamma_hdr_source`` and, from the truth, the maps
        ``gamma_hdr_error`` and ``tdi_light_ratio`` (see the module docstring). With a
        ``slanted_edges`` target also the ISO 12233 e-SFR along and across the track of every
        stage and of ``gamma_hdr``: ``sfr_along``, ``sfr_across`` (stage, sfr_frequency),
        ``mtf50_along``, ``mtf50_across`` (stage) [cycles/px], ``gamma_hdr_sfr_*`` and
        ``gamma_hdr_mtf50_*`` (:func:`bench_sim.measure.sharpness.add_sharpness`).
    """
    cfg = resolve_config(config)
    st = check_stages(stages, cfg.sensor.rows)
    seed = check_seed(seed, "seed")
    check_inputs(cfg, st)
    return _with_sharpness(_run(cfg, st, int(seed), progress).dataset, cfg)


def _run(
    cfg: BenchConfig, st: tuple[int, ...], seed: int, progress: bool,
    sink: Callable[[RenderSetup], PassSink] | None = None,
) -> PassResult:
    """:func:`run_pass` of the run, with a progress bar over the frames when ``progress``."""
    if not progress:
        return run_pass(cfg, st, seed, sink=sink)
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    with Progress(
        TextColumn("[bold]simulate"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total} frames"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
    ) as bar:
        task = bar.add_task("pass", total=frames_needed(cfg.lines, st))
        return run_pass(cfg, st, seed, on_frames=lambda n: bar.update(task, advance=n), sink=sink)


def _with_sharpness(ds: xr.Dataset, cfg: BenchConfig) -> xr.Dataset:
    """The pass's dataset with the e-SFR of every stage and of ``gamma_hdr`` along and across the
    track when the target has slanted edges (:func:`bench_sim.measure.sharpness.add_sharpness`)."""
    return add_sharpness(ds, cfg) if has_slanted_edges(cfg) else ds


def check_inputs(
    cfg: BenchConfig, stages: Iterable[int] | None = None, out: Path | None = None, fmt: str = "zarr"
) -> None:
    """Check everything a pass needs besides the config itself before any rendering: the target
    image file and, given the ``stages``, the output folder (if any), the memory and disk of the
    run and the backend (:func:`bench_sim.workflows.preflight.preflight`); raises
    :class:`BenchSimError` (one line)."""
    if stages is None:  # the inputs alone
        preflight(cfg, out=None, estimate=None, render=False)
        return
    preflight(cfg, out=out, estimate=estimate_simulate(cfg, stages, fmt))


# --- the command: bench-sim simulate ------------------------------------------------------------

#: ``--format`` values and the file each writes into ``--out``
FORMATS = {"zarr": "simulation.zarr", "netcdf": "simulation.nc", "tiff": "meta.json"}
#: the TIFF set's table of the mean e-SFR curves per stage (a slanted-edge target)
SFR_CURVES_FILE = "sfr_curves.csv"


def parse_stages_arg(text: str, rows: int) -> tuple[int, ...]:
    """``--stages``: ``"all"``, or comma-separated stages and inclusive ranges
    ``start:stop[:step]`` (``"10,80"``, ``"5:100:5"``), each stage once, in ``1..rows``
    (:func:`check_stages`). Returns them sorted; one-line :class:`BenchSimError` otherwise."""
    if text.strip() == "all":
        return check_stages("all", rows, "--stages")
    stages: list[int] = []
    try:
        for part in (p.strip() for p in text.split(",")):
            bits = [int(b) for b in part.split(":")]
            if len(bits) == 1:
                stages.append(bits[0])
            elif len(bits) in (2, 3) and (len(bits) == 2 or bits[2] >= 1):
                stages.extend(range(bits[0], bits[1] + 1, bits[2] if len(bits) == 3 else 1))
            else:
                raise ValueError
    except ValueError:
        raise BenchSimError(
            f"--stages = {text!r}: expected 'all', integers like '10,80' or ranges like '5:100:5'"
        ) from None
    return check_stages(stages, rows, "--stages", given=repr(text))


def tiff_dtype(var: Variable) -> np.dtype:
    """The 32-bit TIFF sample type of a variable: ``uint32`` for integer and boolean variables,
    ``float32`` for the others."""
    return np.dtype(np.uint32 if var.stored_dtype(None).kind in "uib" else np.float32)


def write_simulation(ds: xr.Dataset, folder: Path, fmt: str, meta: Mapping[str, Any]) -> list[str]:
    """Write a simulation into ``folder`` as ``fmt`` (see :data:`FORMATS`); returns the names.

    ``zarr``: ``simulation.zarr`` (Zarr v3, consolidated metadata: ``xarray.open_zarr`` opens it);
    ``netcdf``: ``simulation.nc``; both in the one file schema of ``simulate`` and the data sets
    (:func:`bench_sim.pipeline.stored_dataset`: words in the smallest unsigned type, the truth in
    float32, chunks of whole stages); ``tiff``: one 32-bit TIFF per stage and variable,
    ``stage_MMM_VARIABLE.tiff`` (integer and boolean variables uint32, the others float32), ``gamma_hdr.tiff``
    and ``gamma_hdr_source.tiff`` when fused, each with its units and the provenance as JSON in the
    ImageDescription tag, plus ``meta.json`` (provenance, units, file list and, with slanted
    edges, the MTF50s of :func:`bench_sim.measure.sharpness.sharpness_summary`) and, with slanted
    edges, ``sfr_curves.csv`` (the mean e-SFR curve of every stage and direction,
    :func:`bench_sim.measure.sharpness.sharpness_curves`).
    """
    if fmt in ("zarr", "netcdf"):
        ds = stored_dataset(ds, int(ds.attrs["beta_bits"]))
    # never cut by Ctrl-C (held, then delivered): Zarr writes on its own thread, and the locks of
    # xarray and HDF5 an interruption leaves held would deadlock the store's close
    if fmt == "zarr":
        with warnings.catch_warnings(), deferred_interrupts():  # consolidated: a Zarr v3 extension
            warnings.filterwarnings("ignore", message="Consolidated metadata", category=UserWarning)
            ds.to_zarr(folder / FORMATS["zarr"], mode="w-", zarr_format=3, consolidated=True)
        return [FORMATS["zarr"]]
    if fmt == "netcdf":
        with deferred_interrupts():
            ds.to_netcdf(folder / FORMATS["netcdf"])
        return [FORMATS["netcdf"]]
    if fmt != "tiff":
        raise BenchSimError(f"--format = {fmt!r}: allowed {', '.join(FORMATS)}")
    import tifffile

    files: dict[str, dict[str, Any]] = {}

    def put(name: str, arr: np.ndarray, var: Variable, stage: int | None) -> None:
        info = {"variable": var.name, "stage": stage, "units": var.units, "long_name": var.doc}
        desc = strict_dumps({**meta, **info}, sort_keys=True, default=str)
        dtype = tiff_dtype(var)
        tifffile.imwrite(folder / name, np.asarray(arr).astype(dtype), description=desc, metadata=None)
        files[name] = {**info, "dtype": np.dtype(dtype).name}

    for m in ds.stage.values:
        for var in pass_variables(STAGE_DIMS):
            if var.name in ds:
                put(f"stage_{int(m):03d}_{var.name}.tiff", ds[var.name].sel(stage=m).values, var, int(m))
    for var in pass_variables(IMAGE_DIMS, maps=True):
        if var.name in ds:
            put(f"{var.name}.tiff", ds[var.name].values, var, None)
    sharp = sharpness_summary(ds)  # the MTF50s of a slanted-edge target (none otherwise)
    curves = sharpness_curves(ds)
    if curves:  # and their mean e-SFR curves
        write_csv(folder / SFR_CURVES_FILE, ["stage", "direction", "frequency_cyc_px", "sfr"], curves,
                  {**meta, "directions": "along the track: near-horizontal edges (cycles/line); across: "
                   "near-vertical edges (cycles/column); frequencies along the edge normal"})
    write_json(folder / "meta.json", {**meta, "files": files, "dims": ["line", "column"], **sharp})
    return [*files, *([SFR_CURVES_FILE] if curves else []), "meta.json"]


def run_simulate(
    config: Path | None, *, stages: str, seed: int, out: Path, fmt: str = "zarr", progress: bool = True
) -> Path:
    """``bench-sim simulate``: check every input, simulate, write the output set into ``out``.

    Bad stages, formats, image files or output folders are reported (one line, exit 2) before
    any rendering; nothing is written unless the whole set is complete. ``zarr`` (but for a
    slanted-edge target, whose e-SFR needs the whole images) streams the stages into the store
    as the pass completes them (:mod:`bench_sim.workflows.simulate_store`): memory stays flat in
    the number of lines, and the store's bytes are those of the dataset written at the end.
    """
    if fmt not in FORMATS:
        raise BenchSimError(f"--format = {fmt!r}: allowed {', '.join(FORMATS)}")
    check_seed(seed)
    cfg = load_config(config)
    st = parse_stages_arg(stages, cfg.sensor.rows)
    check_inputs(cfg, st, out, fmt)
    meta = provenance(cfg, seed, kind="simulation", stages=list(st))
    record = {"command": "simulate", "version": meta["version"], "seed": int(seed),
              "config_sha256": meta["config_sha256"], "format": fmt, "stages": list(st)}
    if fmt == "zarr" and not has_slanted_edges(cfg):  # streamed: stages written as they complete
        with output_set(out, record) as tmp:
            sinks: list[ZarrPassSink] = []

            def sink(setup: RenderSetup) -> ZarrPassSink:
                sinks.append(ZarrPassSink(tmp / FORMATS["zarr"], cfg, st, int(seed), setup, truth=True))
                return sinks[-1]

            _run(cfg, st, int(seed), progress, sink)
            sinks[0].close()
        return Path(out)
    ds = simulate(cfg, stages=st, seed=seed, progress=progress)
    meta.update(engine=ds.attrs["engine"], variant=ds.attrs["variant"])
    with output_set(out, record) as tmp:
        write_simulation(ds, tmp, fmt, meta)
    return Path(out)
