"""``bench_sim.simulate`` / ``bench-sim simulate``: any bench to its DTDI stage images, with the
exact ground truth behind every pixel, in one streaming pass.

One pass renders the frames ``0 .. L + max(stages) - 2`` (``L = config.lines``), exposes the
rows ``0 .. max(stages) - 1`` of the sensor (EMVA 1288 model, :mod:`bench_sim.sensor.emva`),
accumulates every requested stage (paper eq. 1-2, 4) and, from the same frames and the same
physical sensor, the truth (:mod:`bench_sim.sensor.stage_truth`). The result is an
:class:`xarray.Dataset` with dimensions ``stage``, ``line``, ``column``:

=============== ======================================================================
``dn``          stage words (``0 .. 2**beta - 1``; uint16 up to beta = 16, else uint32)
``mean_dn``     exact expectation of ``dn`` before the word clips (fixed patterns in)
``photons``     mean photons collected by the stage pixel (its ``m`` rows, smear in)
``reflectance`` target reflectance integrated by the pixel's ``m`` footprints
``clipped``     a read hit full well or the ADC top, or the word hit ``2**beta - 1``
``hdr``         eq. 11 fusion of stages ``fusion.mu1``, ``fusion.mu2`` (when both requested)
``hdr_source``  the stage each ``hdr`` pixel came from
=============== ======================================================================

Attributes carry the resolved config as TOML text, its SHA-256, the seed, the version, the
engine and the Mitsuba variant. Random numbers come from one generator seeded with ``seed``,
drawn in a fixed order (render seed, fixed pattern, then the seed of the temporal noise, from
which every chunk of frames spawns its own stream), so the same config and seed give identical
data with any number of threads; ``reproduce`` runs its pass through :func:`run_pass` with its
own generator. Rendering runs a chunk ahead in its own thread and the chunks of frames are
exposed on the thread pool (:mod:`bench_sim.runtime.parallel`) while the stages accumulate in order.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.errors import BenchSimError

if TYPE_CHECKING:
    import xarray as xr

    from bench_sim.render.exposures import RenderSetup

__all__ = ["simulate", "run_pass", "PassResult", "resolve_config", "check_stages", "VARIABLES"]

#: Frames exposed per vectorised sensor call (the temporal noise depends on it: fixed).
SENSOR_CHUNK_FRAMES = 16
#: Frames rendered per engine call (a multiple of the sensor chunk).
RENDER_CHUNK_FRAMES = 64
#: Output lines per band of the reflectance truth.
TRUTH_BAND_LINES = 256

#: name -> (units, long_name) of every variable of the dataset
VARIABLES: dict[str, tuple[str, str]] = {
    "dn": ("DN", "DTDI stage word (paper eq. 1-2, 4)"),
    "mean_dn": ("DN", "expectation of the stage word before the word clips"),
    "photons": ("photons", "mean photons collected by the stage pixel (sum over its m rows)"),
    "reflectance": ("1", "target reflectance integrated by the stage pixel's footprints"),
    "clipped": ("1", "a read hit full well or the ADC top, or the word hit 2**beta - 1"),
    "hdr": ("DN", "Gamma_HDR, paper eq. 11, in stage-mu2 units, pedestal removed"),
    "hdr_source": ("1", "stage each Gamma_HDR pixel came from"),
}


def resolve_config(config: BenchConfig | str | Path | Mapping[str, Any] | None) -> BenchConfig:
    """A :class:`BenchConfig` from a config, a TOML path, or a dict of overrides on the default
    rig (``None``: the default rig)."""
    from bench_sim.config import load_config, warn_config, with_overrides

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


def check_stages(
    stages: Iterable[int] | str, rows: int, what: str = "stages", given: str | None = None
) -> tuple[int, ...]:
    """Validate requested stages: integers in ``1 .. rows``, no duplicates; ``"all"`` means
    ``1 .. rows``. Returns them sorted; raises :class:`BenchSimError` (one line) otherwise,
    quoting ``given`` (what the user wrote, e.g. the ``--stages`` text) or the stages."""
    if isinstance(stages, str):
        if stages.strip() == "all":
            return tuple(range(1, rows + 1))
        raise BenchSimError(f"{what} = {stages!r}: expected a list of stages or 'all'")
    try:
        items = list(stages)
    except TypeError:
        raise BenchSimError(f"{what} = {stages!r}: expected a list of stages or 'all'") from None
    shown = given if given is not None else repr(items)
    if not items:
        raise BenchSimError(f"{what}: at least one stage is needed")
    out = []
    for m in items:
        if isinstance(m, bool) or not isinstance(m, int | np.integer):
            raise BenchSimError(f"{what} = {shown}: {m!r} is not an integer stage")
        out.append(int(m))
    dup = sorted({m for m in out if out.count(m) > 1})
    if dup:
        raise BenchSimError(f"{what} = {shown}: stage {dup[0]} is given twice (each stage once)")
    bad = [m for m in out if not 1 <= m <= rows]
    if bad:
        raise BenchSimError(f"{what} = {shown}: stage {bad[0]} outside 1..{rows} (sensor.rows = {rows})")
    return tuple(sorted(out))


@dataclass
class PassResult:
    """What :func:`run_pass` returns.

    Attributes
    ----------
    dataset
        The simulation (see the module docstring); without ``mean_dn``, ``photons``,
        ``reflectance`` and ``clipped`` when run with ``truth=False``. Built when first read
        (a caller that only needs ``stage_dn`` does not import xarray).
    stage_dn
        Stage ``m`` -> (lines, N) stage words, ``uint16`` for ``beta <= 16`` (the default 12),
        else ``uint32`` (:func:`bench_sim.sensor.model.word_dtype`; the arrays behind
        ``dataset.dn``).
    setup
        The render set-up (geometry, target grid and panel, engine info, backend).
    truth
        Whether the pass computed the truth (``dataset`` then has ``mean_dn``, ``photons``,
        ``reflectance``, ``clipped``); reading it does not build the dataset.
    timings_s
        Seconds per step: ``render_setup``; ``render_frames``, ``sensor_dtdi``, ``truth``
        (busy time of each; rendering runs ahead in its own thread and the chunks are exposed
        on the thread pool, so they overlap); ``pass_wall``, the wall time of the streaming
        pass they share.
    """

    stage_dn: dict[int, np.ndarray]
    setup: RenderSetup
    timings_s: dict[str, float] = field(default_factory=dict)
    make_dataset: Callable[[], xr.Dataset] | None = field(default=None, repr=False)
    truth: bool = False

    @functools.cached_property
    def dataset(self) -> xr.Dataset:
        if self.make_dataset is None:
            raise BenchSimError("PassResult: no dataset")
        return self.make_dataset()


def _pedestal_dn(cfg: BenchConfig) -> float:
    return float(getattr(cfg.dtdi, "pedestal_dn", 0.0))


def run_pass(
    cfg: BenchConfig,
    stages: Iterable[int],
    seed: int | np.random.SeedSequence | np.random.Generator,
    *,
    truth: bool = True,
    on_frames: Callable[[int], None] | None = None,
) -> PassResult:
    """Run one simulation pass: render, expose, accumulate stages and truth, fuse.

    The building block of :func:`simulate`, ``reproduce``, sweeps and data sets.

    Parameters
    ----------
    cfg
        The bench; ``cfg.lines`` output lines of ``cfg.sensor.columns`` columns.
    stages
        Stages to output, each in ``1 .. sensor.rows`` (validated by :func:`check_stages`).
    seed
        Root seed, a ``SeedSequence`` (a sample's or sweep point's stream) or a generator to
        draw from, consumed in this order: one integer for the renderer (reference engine),
        the sensor's fixed pattern, then one ``SeedSequence`` of the temporal noise, from which
        chunk ``c`` of :data:`SENSOR_CHUNK_FRAMES` frames (rows ``0 .. max(stages) - 1``) gets
        its own generator (:func:`bench_sim.runtime.parallel.chunk_generator`): the result does not
        depend on the number of threads (``BENCH_SIM_THREADS``).
    truth
        Also compute ``mean_dn``, ``photons``, ``reflectance`` and ``clipped``.
    on_frames
        Called with the number of frames after every rendered chunk (progress bars).
    """
    from bench_sim.config import config_sha256, config_to_toml_text
    from bench_sim.render.exposures import iter_photon_frames, prepare
    from bench_sim.runtime.parallel import prefetch, seed_sequence
    from bench_sim.sensor.dtdi import DTDIAccumulator, frames_needed, full_scale_dn
    from bench_sim.sensor.emva import draw_fixed_pattern
    from bench_sim.sensor.model import word_dtype
    from bench_sim.sensor.stage_truth import (
        StageSums,
        reflectance_rows,
        row_footprints,
        stage_dark_offset_dn,
        stage_mean_dn,
        stage_reflectance,
    )
    from bench_sim.sensor.stream import iter_exposed
    from bench_sim.version import __version__

    st = check_stages(stages, cfg.sensor.rows)
    rng = np.random.default_rng(seed)  # a Generator is used as is
    lines, n_cols = cfg.lines, cfg.sensor.columns
    n_rows = st[-1]
    frames = frames_needed(lines, st)
    beta, ped = cfg.dtdi.beta_bits, _pedestal_dn(cfg)
    clip_word = full_scale_dn(beta) - 1
    timings = {"render_setup": 0.0, "render_frames": 0.0, "sensor_dtdi": 0.0, "truth": 0.0, "pass_wall": 0.0}

    t0 = time.perf_counter()
    setup = prepare(cfg, frames, rng)
    timings["render_setup"] = time.perf_counter() - t0
    t_int = setup.geom.t_int_s
    fixed = draw_fixed_pattern(cfg.sensor, rng)
    noise = seed_sequence(rng)
    fp = fixed if n_rows == cfg.sensor.rows else fixed.window(n_rows, n_cols)
    acc = DTDIAccumulator(
        n_cols, st, beta, cfg.sensor.black_offset_dn, cfg.dtdi.subtract_black, pedestal_dn=ped
    )
    dn_all = np.empty((len(st), lines, n_cols), dtype=word_dtype(beta))
    dn = {m: dn_all[s] for s, m in enumerate(st)}
    done = dict.fromkeys(st, 0)
    if truth:
        t0 = time.perf_counter()
        shape = (len(st), lines, n_cols)
        photons = np.empty(shape, dtype=np.float64)
        mean_dn = np.empty(shape, dtype=np.float64)
        clipped = np.empty(shape, dtype=bool)
        reflectance = np.empty(shape, dtype=np.float32)
        sums = StageSums(n_cols, st, 3)
        truth_done = dict.fromkeys(st, 0)
        refl_done = 0
        offsets = {
            m: stage_dark_offset_dn(
                cfg.sensor, fp, t_int, m, subtract_black=cfg.dtdi.subtract_black, pedestal_dn=ped
            )
            for m in st
        }
        footprints = row_footprints(cfg, setup.geom, setup.grid, n_rows)
        gain = fp.prnu_gain
        timings["truth"] += time.perf_counter() - t0

    def reflectance_band(upto: int) -> int:
        start = refl_done
        while start < upto:
            stop = min(start + TRUTH_BAND_LINES, upto)
            q = setup.grid.q
            r0, r1 = reflectance_rows(footprints, q, st[-1], start, stop)
            band = setup.grid.rows(r0, r1)
            for s, m in enumerate(st):
                reflectance[s, start:stop] = stage_reflectance(band, q, footprints, m, start, stop, row0=r0)
            start = stop
        return start

    def rendered() -> Iterator[np.ndarray]:
        # runs ahead in its own thread (prefetch): the next chunk renders while this one is exposed
        frames_iter = iter_photon_frames(setup, chunk=RENDER_CHUNK_FRAMES)
        while True:
            t0 = time.perf_counter()
            chunk = next(frames_iter, None)
            timings["render_frames"] += time.perf_counter() - t0
            if chunk is None:
                return
            yield chunk

    def pieces() -> Iterator[np.ndarray]:
        for chunk in prefetch(rendered()):
            for c0 in range(0, chunk.shape[0], SENSOR_CHUNK_FRAMES):
                yield chunk[c0 : c0 + SENSOR_CHUNK_FRAMES, :n_rows]

    t_pass = time.perf_counter()
    for got in iter_exposed(pieces(), cfg.sensor, fp, t_int, noise, saturated=truth):
        t0 = time.perf_counter()
        for m, block in acc.push_many(got.dn).items():
            take = block[: max(lines - done[m], 0)]
            dn[m][done[m] : done[m] + len(take)] = take
            done[m] += len(take)
        t1 = time.perf_counter()
        timings["sensor_dtdi"] += got.seconds + t1 - t0
        if truth:
            ph = got.photons
            stack = np.empty((ph.shape[0], n_rows, 3, n_cols), dtype=np.float64)
            stack[:, :, 0] = ph
            np.multiply(ph, gain, out=stack[:, :, 1])
            stack[:, :, 2] = got.saturated
            for frame in stack:
                for m, line in sums.push(frame).items():
                    s, j = st.index(m), truth_done[m]
                    if j < lines:
                        photons[s, j] = line[0]
                        mean_dn[s, j] = stage_mean_dn(line[1], cfg.sensor, offsets[m])
                        clipped[s, j] = line[2] > 0
                        truth_done[m] = j + 1
            complete = min(truth_done.values())
            if complete - refl_done >= TRUTH_BAND_LINES or complete == lines:
                refl_done = reflectance_band(complete)
            timings["truth"] += time.perf_counter() - t1
        if on_frames is not None:
            on_frames(got.photons.shape[0])
    timings["pass_wall"] = time.perf_counter() - t_pass
    if min(done.values()) < lines:
        raise BenchSimError(f"simulate: the pass gave only {min(done.values())} of {lines} lines")

    if truth:
        t0 = time.perf_counter()
        clipped |= dn_all >= clip_word
        timings["truth"] += time.perf_counter() - t0

    def make_dataset() -> xr.Dataset:
        import xarray as xr

        coords = {
            "stage": np.asarray(st, dtype=np.int64), "line": np.arange(lines), "column": np.arange(n_cols)
        }
        dims = ("stage", "line", "column")
        data: dict[str, Any] = {"dn": (dims, dn_all)}
        if truth:
            data.update(mean_dn=(dims, mean_dn), photons=(dims, photons), reflectance=(dims, reflectance),
                        clipped=(dims, clipped))
        mu1, mu2 = cfg.fusion.mu1, cfg.fusion.mu2
        if mu1 in st and mu2 in st:
            from bench_sim.fusion.paper import fuse_dtdi_hdr_eq11

            kw = {"pedestal_dn": ped} if ped else {}
            fused = fuse_dtdi_hdr_eq11(dn[mu1], dn[mu2], mu1=mu1, mu2=mu2, beta=beta, **kw)
            data["hdr"] = (("line", "column"), fused.hdr.astype(np.float32))
            data["hdr_source"] = (("line", "column"), fused.source.astype(np.int16))
        ds = xr.Dataset(data, coords=coords)
        for name, var in ds.data_vars.items():
            units, long_name = VARIABLES[name]
            var.attrs.update(units=units, long_name=long_name)
        ds["line"].attrs.update(units="1", long_name="scene line (material at line * delta along the track)")
        ds["column"].attrs.update(units="1", long_name="sensor column")
        ds["stage"].attrs.update(units="1", long_name="DTDI stage m (rows summed)")
        ds.attrs.update(
            title=f"bench_sim simulation of {cfg.name}",
            config=config_to_toml_text(cfg),
            config_sha256=config_sha256(cfg),
            seed=int(seed) if isinstance(seed, int | np.integer) else -1,
            version=__version__,
            engine=str(setup.info["engine"]),
            variant=str(setup.info["variant"]),
            beta_bits=int(beta),
            pedestal_dn=ped,
            t_int_s=float(t_int),
            frames=int(frames),
        )
        if isinstance(seed, np.random.SeedSequence):
            ds.attrs.update(seed_entropy=str(seed.entropy), seed_spawn_key=str(list(seed.spawn_key)))
        if mu1 in st and mu2 in st:
            ds.attrs.update(mu1=int(mu1), mu2=int(mu2))
        return ds

    return PassResult(dn, setup, timings, make_dataset, truth=truth)


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
        stages, ``hdr`` and ``hdr_source`` (see the module docstring).
    """
    cfg = resolve_config(config)
    st = check_stages(stages, cfg.sensor.rows)
    from bench_sim.workflows.preflight import check_seed

    seed = check_seed(seed, "seed")
    check_inputs(cfg, st)
    if not progress:
        return run_pass(cfg, st, int(seed)).dataset
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    from bench_sim.sensor.dtdi import frames_needed

    with Progress(
        TextColumn("[bold]simulate"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total} frames"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
    ) as bar:
        task = bar.add_task("pass", total=frames_needed(cfg.lines, st))
        return run_pass(cfg, st, int(seed), on_frames=lambda n: bar.update(task, advance=n)).dataset


def check_inputs(
    cfg: BenchConfig, stages: Iterable[int] | None = None, out: Path | None = None, fmt: str = "zarr"
) -> None:
    """Check everything a pass needs besides the config itself before any rendering: the target
    image file and, given the ``stages``, the output folder (if any), the memory and disk of the
    run and the backend (:func:`bench_sim.workflows.preflight.preflight`); raises
    :class:`BenchSimError` (one line)."""
    from bench_sim.runtime.resources import estimate_simulate
    from bench_sim.workflows.preflight import preflight

    if stages is None:  # the inputs alone
        preflight(cfg, out=None, estimate=None, render=False)
        return
    preflight(cfg, out=out, estimate=estimate_simulate(cfg, stages, fmt))


# --- the command: bench-sim simulate ------------------------------------------------------------

#: ``--format`` values and the file each writes into ``--out``
FORMATS = {"zarr": "simulation.zarr", "netcdf": "simulation.nc", "tiff": "meta.json"}


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


def write_simulation(ds: xr.Dataset, folder: Path, fmt: str, meta: Mapping[str, Any]) -> list[str]:
    """Write a simulation into ``folder`` as ``fmt`` (see :data:`FORMATS`); returns the names.

    ``zarr``: ``simulation.zarr`` (Zarr v3, consolidated metadata: ``xarray.open_zarr`` opens it);
    ``netcdf``: ``simulation.nc``; ``tiff``: one 32-bit TIFF per stage and variable,
    ``stage_MMM_VARIABLE.tiff`` (``dn`` and ``clipped`` uint32, the others float32), ``hdr.tiff``
    and ``hdr_source.tiff`` when fused, each with its units and the provenance as JSON in the
    ImageDescription tag, plus ``meta.json`` (provenance, units, file list).
    """
    import json
    import warnings

    from bench_sim.io import write_json

    if fmt == "zarr":
        with warnings.catch_warnings():  # consolidated metadata is a Zarr v3 extension
            warnings.filterwarnings("ignore", message="Consolidated metadata", category=UserWarning)
            ds.to_zarr(folder / FORMATS["zarr"], mode="w-", zarr_format=3, consolidated=True)
        return [FORMATS["zarr"]]
    if fmt == "netcdf":
        ds.to_netcdf(folder / FORMATS["netcdf"])
        return [FORMATS["netcdf"]]
    if fmt != "tiff":
        raise BenchSimError(f"--format = {fmt!r}: allowed {', '.join(FORMATS)}")
    import tifffile

    files: dict[str, dict[str, Any]] = {}

    def put(name: str, arr: np.ndarray, var: str, stage: int | None) -> None:
        units, long_name = VARIABLES[var]
        info = {"variable": var, "stage": stage, "units": units, "long_name": long_name}
        desc = json.dumps({**meta, **info}, sort_keys=True, default=str)
        dtype = np.uint32 if var in ("dn", "clipped", "hdr_source") else np.float32
        tifffile.imwrite(folder / name, np.asarray(arr).astype(dtype), description=desc, metadata=None)
        files[name] = {**info, "dtype": np.dtype(dtype).name}

    for m in ds.stage.values:
        for var in ("dn", "mean_dn", "photons", "reflectance", "clipped"):
            if var in ds:
                put(f"stage_{int(m):03d}_{var}.tiff", ds[var].sel(stage=m).values, var, int(m))
    for var in ("hdr", "hdr_source"):
        if var in ds:
            put(f"{var}.tiff", ds[var].values, var, None)
    write_json(folder / "meta.json", {**meta, "files": files, "dims": ["line", "column"]})
    return [*files, "meta.json"]


def run_simulate(
    config: Path | None, *, stages: str, seed: int, out: Path, fmt: str = "zarr", progress: bool = True
) -> Path:
    """``bench-sim simulate``: check every input, simulate, write the output set into ``out``.

    Bad stages, formats, image files or output folders are reported (one line, exit 2) before
    any rendering; nothing is written unless the whole set is complete.
    """
    from bench_sim.config import load_config
    from bench_sim.io import output_set
    from bench_sim.runtime.provenance import provenance
    from bench_sim.workflows.preflight import check_seed

    if fmt not in FORMATS:
        raise BenchSimError(f"--format = {fmt!r}: allowed {', '.join(FORMATS)}")
    check_seed(seed)
    cfg = load_config(config)
    st = parse_stages_arg(stages, cfg.sensor.rows)
    check_inputs(cfg, st, out, fmt)
    ds = simulate(cfg, stages=st, seed=seed, progress=progress)
    meta = provenance(
        cfg, seed, kind="simulation", stages=list(st), engine=ds.attrs["engine"], variant=ds.attrs["variant"]
    )
    record = {"command": "simulate", "version": meta["version"], "seed": int(seed),
              "config_sha256": meta["config_sha256"], "format": fmt, "stages": list(st)}
    with output_set(out, record) as tmp:
        write_simulation(ds, tmp, fmt, meta)
    return Path(out)
