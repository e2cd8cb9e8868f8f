"""``bench-sim dataset``: synthetic validation datasets with exact ground truth, sample by sample
on Dask, resumable.

A spec (:mod:`bench_sim.workflows.dataset.spec`) names a bench, a number of samples, a root
seed, the stages to store, the output size and the config keys to randomise. Sample ``i`` is one
:func:`bench_sim.pipeline.run_pass` of its own bench (parameters drawn from its own
stream), with its own simulation stream: its content depends only on (spec, seed, ``i``), never
on the number of workers or the order in which samples finish.

Steps of :func:`run_dataset`:

1. **Check** (before anything is written): the spec and every sample's bench and image file,
   the output folder (new, empty, a complete dataset to replace, or, with ``--resume`` /
   ``--only``, the same dataset), and the size of what is left to write against the free disk
   space (:func:`estimate_bytes`). Each refusal is one line.
2. **Lay out** ``DIR`` (:mod:`bench_sim.workflows.dataset.reader` lists the files): ``dataset.json`` and an
   empty ``data.zarr`` with the full schema are made in a temporary folder and renamed into
   place (:class:`~bench_sim.workflows.dataset.writer.DatasetFolder`). On a cluster this is done
   once the samples are submitted, while the first ones are made; nothing is written before it.
3. **Run** the samples on the execution layer (:mod:`bench_sim.runtime.execution`: a
   ``LocalCluster`` or ``--scheduler``). Workers return arrays; this process writes each
   sample's chunks into ``data.zarr`` as it completes and only then its record
   ``samples/NNNNNNNN.json`` (status ``complete``). A killed run leaves at worst a sample whose
   chunks are written but whose record is not: it counts as not done, and ``--resume`` redoes
   it. A failed sample gets a ``failed`` record with its one-line error and is retried by
   ``--resume``. The fast engine's light records are made once per distinct scene for the
   whole run (a task of their own, :func:`bench_sim.render.exposures.fast_records`) and handed
   to every sample that needs them: the drawn powers, sync error and target change no record,
   so a data set like the example renders its records once, not once per worker.
4. **Summarise**: the manifest (rebuilt from the records, also every 10 s during the run),
   the dataset card and its thumbnail sheet, and, when every sample is complete, the completion
   record, written last.
"""

from __future__ import annotations

import contextlib
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig, config_sha256
from bench_sim.errors import BenchSimError, note_kept
from bench_sim.io import check_free_space, format_bytes, write_json
from bench_sim.io.folder_lock import folder_lock
from bench_sim.io.ownership import entries
from bench_sim.metrics.fusion_truth import LIGHT_RATIO_TOLERANCE
from bench_sim.metrics.truth import region_masks, saturated_fraction, scene_dynamic_range_db, truth_snr
from bench_sim.pipeline import PassResult, physical_coords, run_pass
from bench_sim.render.exposures import fast_records, records_group
from bench_sim.render.records import LightRecords, install_records
from bench_sim.runtime.execution import Shared, open_client, release_client, run_tasks
from bench_sim.runtime.preload import FIGURES, import_modules
from bench_sim.runtime.progress import progress_bar
from bench_sim.sensor.model import stage_mean_var_dn
from bench_sim.workflows.dataset.card import write_card
from bench_sim.workflows.dataset.reader import (
    COMPLETION_RECORD,
    FUSED_VARIABLES,
    STAGE_VARIABLES,
    read_records,
)
from bench_sim.workflows.dataset.sample_scene import SampleScene, peak_signal_fraction, scale_lights
from bench_sim.workflows.dataset.spec import DatasetSpec, check_sample_configs, load_spec, sample_streams
from bench_sim.workflows.dataset.store import (
    bytes_per_sample,
    check_folder,
    estimate_bytes,
    manifest_frame,
    manifest_meta,
    write_manifest,
)
from bench_sim.workflows.dataset.targets import fixed_camera, recorded_values
from bench_sim.workflows.dataset.writer import DatasetFolder, SampleWriter
from bench_sim.workflows.preflight import preflight_tasks

__all__ = [
    "SampleTask",
    "SampleOutput",
    "DatasetRun",
    "make_sample",
    "sample_inputs",
    "sample_metrics",
    "bytes_per_sample",
    "estimate_bytes",
    "run_dataset",
    "manifest_frame",
]

#: what the samples, the manifest and the card are written with (imported while samples run)
WRITE_MODULES = ("xarray", "zarr", "pyarrow", *FIGURES)


@dataclass(frozen=True)
class SampleTask:
    """What a worker needs to make one sample."""

    index: int
    config: BenchConfig
    stages: tuple[int, ...]
    stream: np.random.SeedSequence
    camera_seed: int | None = None  # camera = "fixed": the dataset's root seed (targets.fixed_camera)
    scene: dict[str, float] = field(default_factory=dict)  # its [scene] values (dataset.sample_scene)


@dataclass
class SampleOutput:
    """What a worker returns for one sample.

    Attributes
    ----------
    arrays
        Variable -> array: ``(stage, line, column)`` for
        :data:`~bench_sim.workflows.dataset.reader.STAGE_VARIABLES`, ``(line, column)`` for
        :data:`~bench_sim.workflows.dataset.reader.FUSED_VARIABLES`, and the sample's own
        coordinates (:data:`~bench_sim.workflows.dataset.reader.SAMPLE_COORDS`).
    metrics
        :func:`sample_metrics`.
    info
        ``config_sha256``, ``engine``, ``variant``, ``t_int_s``, ``frames``, the pass's
        timings per step [s] and, with a ``[scene]``, ``scene`` (its values and light scale).
    """

    index: int
    arrays: dict[str, np.ndarray]
    metrics: dict[str, float]
    info: dict[str, Any]


def sample_metrics(sim: PassResult, cfg: BenchConfig) -> dict[str, float]:
    """Summary metrics of one simulation ``sim`` (the manifest's columns), from its arrays and
    attributes (:meth:`~bench_sim.pipeline.PassResult.read`, :attr:`~bench_sim.pipeline.PassResult.attrs`:
    no dataset is built, xarray is not imported).

    ``scene_dr_db`` (:func:`~bench_sim.metrics.truth.scene_dynamic_range_db` of the photons of
    the lowest stored stage) and, per stored stage ``m``: ``saturated_fraction_m{m}``,
    ``snr_dark_m{m}`` and ``snr_bright_m{m}`` (:func:`~bench_sim.metrics.truth.truth_snr` over the
    darkest and brightest tenth of the scene, clipped pixels left out, above the stage's dark
    level :func:`~bench_sim.sensor.model.stage_mean_var_dn` at 0 photons); when fused, the TDI
    window's light ratio ``r`` (``tdi_light_ratio``): ``light_ratio_p01``, ``light_ratio_p99``,
    ``light_ratio_max_dev`` (largest ``|r - 1|``), ``light_ratio_outside_fraction`` (pixels with
    ``|r - 1|`` above :data:`~bench_sim.metrics.fusion_truth.LIGHT_RATIO_TOLERANCE`: 0 where eq. 11's
    assumption holds everywhere), and ``recoverable_fraction`` (``hdr_recoverable``).
    """
    read = sim.read
    photons0 = np.asarray(read("photons", sim.stages[0]))
    dark, bright = region_masks(photons0)
    out = {"scene_dr_db": scene_dynamic_range_db(photons0)}
    t_int, ped = float(sim.attrs["t_int_s"]), float(sim.attrs["pedestal_dn"])
    for m in sim.stages:
        dn, mean, clipped = read("dn", m), read("mean_dn", m), read("clipped", m)
        dark_level = float(stage_mean_var_dn(
            0.0, cfg.sensor, t_int, m, subtract_black=cfg.dtdi.subtract_black, pedestal_dn=ped
        )[0])
        out[f"saturated_fraction_m{m}"] = saturated_fraction(clipped)
        out[f"snr_dark_m{m}"] = truth_snr(dn, mean, dark_level, dark & ~clipped)
        out[f"snr_bright_m{m}"] = truth_snr(dn, mean, dark_level, bright & ~clipped)
    if "tdi_light_ratio" in sim.variables:
        r = np.asarray(read("tdi_light_ratio", None), dtype=np.float64)
        r = r[np.isfinite(r)]
        dev = np.abs(r - 1.0)
        p01, p99 = np.percentile(r, [1.0, 99.0]) if r.size else (np.nan, np.nan)
        out.update(
            light_ratio_p01=float(p01), light_ratio_p99=float(p99),
            light_ratio_max_dev=float(dev.max()) if r.size else float("nan"),
            light_ratio_outside_fraction=float(np.mean(dev > LIGHT_RATIO_TOLERANCE)) if r.size else 0.0,
            recoverable_fraction=float(np.mean(read("hdr_recoverable", None))),
        )
    return out


def sample_inputs(tasks: Sequence[SampleTask]) -> list[tuple[Shared, ...]]:
    """The shared inputs of each sample: the light records of its scene (none for the reference
    engine), one :class:`~bench_sim.runtime.execution.Shared` per distinct scene."""
    out: list[tuple[Shared, ...]] = []
    for t in tasks:
        group = records_group(t.config)
        out.append(() if group is None else (Shared("records:" + group, fast_records, t.config),))
    return out


def make_sample(task: SampleTask, records: LightRecords | None = None) -> SampleOutput:
    """Make one sample (runs in a worker): one pass with truth, its arrays and metrics (read
    off the pass's arrays: the worker never imports xarray).

    ``records``: the light records of its scene made by another task (:func:`sample_inputs`),
    put in this process's cache for the pass; without them the pass finds them in the cache or
    renders them. With ``scene.peak_of_mu2_clip`` the lights are scaled first
    (:func:`~bench_sim.workflows.dataset.sample_scene.peak_signal_fraction`)."""
    if records is not None:
        install_records(records)
    cfg, scale = task.config, 1.0
    peak = task.scene.get("peak_of_mu2_clip")
    if peak is not None:
        now = peak_signal_fraction(cfg, task.stages, task.stream)
        if not now > 0:
            raise BenchSimError(f"scene.peak_of_mu2_clip: sample {task.index} sees no light to scale")
        scale = float(peak) / now
        cfg = scale_lights(cfg, scale)
    camera = None if task.camera_seed is None else fixed_camera(cfg, task.camera_seed)
    res = run_pass(cfg, task.stages, np.random.default_rng(task.stream), truth=True, fixed_pattern=camera)
    arrays = {v: res.values(v) for v in (*STAGE_VARIABLES, *FUSED_VARIABLES) if v in res.variables}
    across = task.scene.get("window_across_mm", 0.0) * 1e-3
    arrays.update({k: values for k, (_d, values, _a) in physical_coords(cfg, across_m=across).items()})
    info: dict[str, Any] = {
        "config_sha256": config_sha256(cfg),
        **{k: res.attrs[k] for k in ("engine", "variant", "t_int_s", "frames")},
        "timings_s": {k: round(float(v), 4) for k, v in res.timings_s.items()},
    }
    if task.scene:
        info["scene"] = SampleScene(dict(task.scene), scale).as_record()
    return SampleOutput(task.index, arrays, sample_metrics(res, cfg), info)


# --- the run -------------------------------------------------------------------------------------


@dataclass
class DatasetRun:
    """What :func:`run_dataset` did.

    Attributes
    ----------
    out
        The dataset folder.
    samples
        Samples in the dataset.
    ran
        Samples run this time (``complete`` or ``failed``).
    complete
        Samples complete in the folder now.
    failed
        Index -> one-line error of the samples that failed this time.
    wall_s
        Wall time of the run [s].
    """

    out: Path
    samples: int
    ran: list[int] = field(default_factory=list)
    complete: int = 0
    failed: dict[int, str] = field(default_factory=dict)
    wall_s: float = 0.0

    @property
    def done(self) -> bool:
        return self.complete == self.samples


@dataclass(frozen=True)
class _Plan:
    """A checked run: the spec, the folder, what to do with it, the samples to make."""

    spec: DatasetSpec
    out: Path
    action: str
    done_before: set[int]
    todo: list[int]
    values: list[dict[str, Any]]
    planned: dict[int, BenchConfig]


def _parse_only(only: Sequence[int] | None, samples: int) -> list[int] | None:
    if only is None:
        return None
    out = sorted({int(i) for i in only})
    if not out:
        return None
    bad = [i for i in out if not 0 <= i < samples]
    if bad:
        raise BenchSimError(f"--only = {bad[0]}: outside 0..{samples - 1} (samples = {samples})")
    return out


def _check_options(
    workers: int | None, scheduler: str | None, resume: bool, only: Sequence[int] | None
) -> None:
    if workers is not None and scheduler is not None:
        raise BenchSimError("--workers and --scheduler: give one (a scheduler brings its own workers)")
    if workers is not None and workers < 0:
        raise BenchSimError(f"--workers = {workers}: must be >= 0 (0 runs in this process)")
    if resume and only:
        raise BenchSimError("--resume and --only: give one (--only remakes just the samples named)")


def _own_complete(out: Path, spec: DatasetSpec) -> set[int]:
    """The complete samples of ``out`` whose record names this spec and seed; the others (another
    spec's or seed's, or a record without them) are recomputed, with one warning counting them."""
    own, foreign = set(), 0
    for i, rec in read_records(out).items():
        if rec.get("spec_sha256") != spec.identity() or rec.get("seed") != spec.seed:
            foreign += 1
        elif rec.get("status") == "complete":
            own.add(i)
    if foreign:
        warnings.warn(f"bench_sim: {out}: {foreign} sample records of another spec or seed: recomputed",
                      RuntimeWarning, stacklevel=3)
    return own


def _plan(
    spec_path: str | Path, out: str | Path, workers: int | None, scheduler: str | None, resume: bool,
    only: Sequence[int] | None,
) -> _Plan:
    """Every check before anything is written: the spec, the folder, the disk, every sample's
    bench, memory and backend (one line on the first problem)."""
    spec = load_spec(spec_path)
    only_idx = _parse_only(only, spec.samples)
    out = Path(out).expanduser().resolve()
    action = check_folder(spec, out, reuse=resume or only_idx is not None)
    done_before = set() if action == "create" else _own_complete(out, spec)
    todo = only_idx if only_idx is not None else [i for i in range(spec.samples) if i not in done_before]
    per = bytes_per_sample(spec)
    check_free_space(
        out, estimate_bytes(spec, len(todo)),
        detail=f"{len(todo)} samples x {format_bytes(per)} uncompressed + records and card",
    )
    # target.image drawn for a sample whose layout uses none: null in its config and record
    values = [recorded_values(spec.draw(i), spec.base.target.layout) for i in range(spec.samples)]
    planned = check_sample_configs(spec, {i: values[i] for i in todo})
    preflight_tasks(  # memory of the samples running at once here, the backend (disk: above)
        "dataset", [(planned[i], spec.stages) for i in todo], out=out, workers=workers,
        scheduler=scheduler, disk_bytes={}, hint="lower --workers, lines or columns",
    )
    return _Plan(spec, out, action, done_before, todo, values, planned)


def _scene_values(values: dict[str, Any]) -> dict[str, float]:
    """A sample's ``[scene]`` values from its drawn values (``scene.<key>``)."""
    return {k.removeprefix("scene."): float(v) for k, v in values.items() if k.startswith("scene.")}


def _run_samples(
    plan: _Plan, client: Any, meta: dict[str, Any], progress: bool, folder: DatasetFolder
) -> SampleWriter:
    """Make the samples to do, writing each as it completes; on a cluster the folder is made ready
    and :data:`WRITE_MODULES` imported while the first samples are made (in this process: the
    folder first). The manifest of what is on disk is written if the run stops (Ctrl-C, a lost
    scheduler)."""
    spec, todo = plan.spec, plan.todo
    camera_seed = spec.seed if spec.camera == "fixed" else None
    tasks = [SampleTask(i, plan.planned[i], spec.stages, sample_streams(spec.seed, i)[1], camera_seed,
                        _scene_values(plan.values[i])) for i in todo]
    skipped = spec.samples - len(todo)
    note = f"({skipped} already complete)" if skipped else ""
    with progress_bar("dataset", len(todo), "samples", enabled=progress, note=note) as bar:
        writer = SampleWriter(plan.out, spec, plan.values, meta, bar)

        def meanwhile() -> None:
            folder.prepare()
            import_modules(WRITE_MODULES)

        if client is None:
            folder.prepare()
        try:
            run_tasks(make_sample, tasks, client=client, indices=todo, keep_values=False,
                      on_result=writer.write, shared=sample_inputs(tasks), meanwhile=meanwhile)
        except BaseException:
            if folder.ready:
                write_manifest(plan.out, spec, meta, plan.values)  # what is on disk now
            raise
    return writer


def run_dataset(
    spec_path: str | Path,
    out: str | Path,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    resume: bool = False,
    only: Sequence[int] | None = None,
    progress: bool = False,
    command: str | None = None,
) -> DatasetRun:
    """Make (or complete) the dataset of ``spec_path`` in ``out``; see the module docstring.

    Parameters
    ----------
    spec_path
        The dataset spec (TOML).
    out
        The dataset folder: new or empty; a complete dataset (or one without any sample yet),
        replaced; with ``resume`` or ``only``, the same dataset, reused.
    workers, scheduler
        Where the samples run (:func:`bench_sim.runtime.execution.open_client`: ``workers``
        processes of a local cluster, ``0`` for this process, or a scheduler's address).
    resume
        Skip the complete samples, redo the others (failed, half-written, not started).
    only
        Make just these samples (in a new folder, or again in the same dataset), identically.
    progress
        Show a progress bar.
    command
        The command line, for the dataset card.
    """
    t_start = time.perf_counter()
    _check_options(workers, scheduler, resume, only)
    # one writer per folder: held from before the folder is read until its last file is written
    with folder_lock(Path(out).expanduser().resolve(), "dataset"):
        run = _plan_and_run(spec_path, out, workers, scheduler, resume, only, progress, command)
    run.wall_s = time.perf_counter() - t_start
    return run


def _plan_and_run(
    spec_path: str | Path, out: str | Path, workers: int | None, scheduler: str | None, resume: bool,
    only: Sequence[int] | None, progress: bool, command: str | None,
) -> DatasetRun:
    """:func:`run_dataset` under the folder's lock."""
    plan = _plan(spec_path, out, workers, scheduler, resume, only)
    spec, out = plan.spec, plan.out
    run = DatasetRun(out=out, samples=spec.samples)
    # the execution layer first (refused before anything is laid out at --out if it cannot start)
    cluster = open_client(workers=workers, scheduler=scheduler) if plan.todo else contextlib.nullcontext()
    folder = DatasetFolder(spec, out, plan.action)  # made ready while the first samples run
    try:
        with cluster as client:
            meta = manifest_meta(spec)
            if not plan.todo:
                folder.prepare()
                run.complete = len(plan.done_before)
            else:
                writer = _run_samples(plan, client, meta, progress, folder)
                run.ran, run.failed = writer.ran, writer.failed
                run.complete = sum(1 for r in read_records(out).values() if r.get("status") == "complete")
            release_client(client)  # the cluster closes while the manifest and card are written
            df = write_manifest(out, spec, meta, plan.values)
            write_card(out, spec, df, command=command, provenance=meta)
        if run.complete == spec.samples:
            write_json(out / COMPLETION_RECORD, {
                "command": "dataset", "version": meta["version"], "seed": spec.seed,
                "spec_sha256": meta["spec_sha256"], "samples": spec.samples, "files": entries(out),
            })
    except BaseException as exc:
        if folder.ready:  # while the samples run, the cluster closes or the manifest and card are written
            done = sum(1 for r in read_records(out).values() if r.get("status") == "complete")
            note_kept(exc, f"{done} of {spec.samples} samples complete are kept in {out}; finish with "
                           f"'bench-sim dataset {spec_path} --out {out} --resume'")
        raise
    return run


def main_summary(run: DatasetRun) -> str:
    """One line about a finished run, for the command's output."""
    failed = f", {len(run.failed)} failed (see manifest.csv; --resume retries them)" if run.failed else ""
    state = "complete" if run.done else "incomplete"
    return (
        f"dataset {run.out}: {run.complete} of {run.samples} samples complete ({state}); "
        f"{len(run.ran)} made in {run.wall_s:.1f} s{failed}"
    )
