"""``bench-sim dataset``: synthetic validation datasets with exact ground truth, sample by sample
on Dask, resumable.

A spec (:mod:`bench_sim.workflows.dataset.spec`) names a bench, a number of samples, a root
seed, the stages to store, the output size and the config keys to randomise. Sample ``i`` is one
:func:`bench_sim.workflows.simulate.run_pass` of its own bench (parameters drawn from its own
stream), with its own simulation stream: its content depends only on (spec, seed, ``i``), never
on the number of workers or the order in which samples finish.

Steps of :func:`run_dataset`:

1. **Check** (before anything is written): the spec and every sample's bench and image file,
   the output folder (new, empty, a complete dataset to replace, or, with ``--resume`` /
   ``--only``, the same dataset), and the size of what is left to write against the free disk
   space (:func:`estimate_bytes`). Each refusal is one line.
2. **Lay out** ``DIR`` (:mod:`bench_sim.workflows.dataset.reader` lists the files): ``dataset.json`` and an
   empty ``data.zarr`` with the full schema are made in a temporary folder and renamed into
   place.
3. **Run** the samples on the execution layer (:mod:`bench_sim.runtime.execution`: a
   ``LocalCluster`` or ``--scheduler``). Workers return arrays; this process writes each
   sample's chunks into ``data.zarr`` as it completes and only then its record
   ``samples/NNNNNNNN.json`` (status ``complete``). A killed run leaves at worst a sample whose
   chunks are written but whose record is not: it counts as not done, and ``--resume`` redoes
   it. A failed sample gets a ``failed`` record with its one-line error and is retried by
   ``--resume``.
4. **Summarise**: the manifest (rebuilt from the records, also every 10 s during the run),
   the dataset card and its thumbnail sheet, and, when every sample is complete, the completion
   record, written last.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.errors import BenchSimError
from bench_sim.workflows.dataset.reader import (
    COMPLETION_RECORD,
    DATA_STORE,
    DATASET_JSON,
    DATASET_KIND,
    FUSED_VARIABLES,
    MANIFEST_CSV,
    MANIFEST_PARQUET,
    RECORDS_DIR,
    STAGE_VARIABLES,
    read_records,
    record_path,
)

if TYPE_CHECKING:
    import pandas as pd
    import xarray as xr

    from bench_sim.workflows.dataset.spec import DatasetSpec

__all__ = [
    "SampleTask",
    "SampleOutput",
    "DatasetRun",
    "make_sample",
    "sample_metrics",
    "bytes_per_sample",
    "estimate_bytes",
    "run_dataset",
    "manifest_frame",
]

#: Format of the dataset folder (``dataset.json``'s ``format``), raised on incompatible changes
FORMAT_VERSION = 1
#: Seconds between manifest rewrites during a run
MANIFEST_EVERY_S = 10.0
#: Bytes of a sample's record and manifest rows, and of the card, thumbnails and metadata
RECORD_BYTES, FIXED_BYTES = 16 * 1024, 8 * 2**20


@dataclass(frozen=True)
class SampleTask:
    """What a worker needs to make one sample."""

    index: int
    config: BenchConfig
    stages: tuple[int, ...]
    stream: np.random.SeedSequence


@dataclass
class SampleOutput:
    """What a worker returns for one sample.

    Attributes
    ----------
    arrays
        Variable -> array: ``(stage, line, column)`` for :data:`~bench_sim.workflows.dataset.reader.STAGE_VARIABLES`,
        ``(line, column)`` for :data:`~bench_sim.workflows.dataset.reader.FUSED_VARIABLES`.
    metrics
        :func:`sample_metrics`.
    info
        ``config_sha256``, ``engine``, ``variant``, ``t_int_s``, ``frames`` and the pass's
        timings per step [s].
    """

    index: int
    arrays: dict[str, np.ndarray]
    metrics: dict[str, float]
    info: dict[str, Any]


def sample_metrics(ds: xr.Dataset, cfg: BenchConfig) -> dict[str, float]:
    """Summary metrics of one simulation (the manifest's columns).

    ``scene_dr_db`` (:func:`~bench_sim.metrics.truth.scene_dynamic_range_db` of the photons of
    the lowest stored stage) and, per stored stage ``m``: ``saturated_fraction_m{m}``,
    ``snr_dark_m{m}`` and ``snr_bright_m{m}`` (:func:`~bench_sim.metrics.truth.truth_snr` over the
    darkest and brightest tenth of the scene, clipped pixels left out, above the stage's dark
    level :func:`~bench_sim.sensor.model.stage_mean_var_dn` at 0 photons).
    """
    from bench_sim.metrics.truth import region_masks, saturated_fraction, scene_dynamic_range_db, truth_snr
    from bench_sim.sensor.model import stage_mean_var_dn

    photons0 = np.asarray(ds.photons.values[0])
    dark, bright = region_masks(photons0)
    out = {"scene_dr_db": scene_dynamic_range_db(photons0)}
    t_int, ped = float(ds.attrs["t_int_s"]), float(ds.attrs["pedestal_dn"])
    for s, m in enumerate(int(v) for v in ds.stage.values):
        dn, mean, clipped = ds.dn.values[s], ds.mean_dn.values[s], ds.clipped.values[s]
        dark_level = float(stage_mean_var_dn(
            0.0, cfg.sensor, t_int, m, subtract_black=cfg.dtdi.subtract_black, pedestal_dn=ped
        )[0])
        out[f"saturated_fraction_m{m}"] = saturated_fraction(clipped)
        out[f"snr_dark_m{m}"] = truth_snr(dn, mean, dark_level, dark & ~clipped)
        out[f"snr_bright_m{m}"] = truth_snr(dn, mean, dark_level, bright & ~clipped)
    return out


def make_sample(task: SampleTask) -> SampleOutput:
    """Make one sample (runs in a worker): one pass with truth, its arrays and metrics."""
    from bench_sim.config import config_sha256
    from bench_sim.workflows.simulate import run_pass

    res = run_pass(task.config, task.stages, np.random.default_rng(task.stream), truth=True)
    ds = res.dataset
    arrays = {v: np.asarray(ds[v].values) for v in (*STAGE_VARIABLES, *FUSED_VARIABLES) if v in ds}
    info = {
        "config_sha256": config_sha256(task.config),
        **{k: ds.attrs[k] for k in ("engine", "variant", "t_int_s", "frames")},
        "timings_s": {k: round(float(v), 4) for k, v in res.timings_s.items()},
    }
    return SampleOutput(task.index, arrays, sample_metrics(ds, task.config), info)


def bytes_per_sample(stages: int, lines: int, columns: int, fused: bool) -> int:
    """Uncompressed bytes of one sample's arrays: an upper bound of what it takes on disk."""
    per_pixel = sum(np.dtype(d).itemsize for d in STAGE_VARIABLES.values()) * stages
    if fused:
        per_pixel += sum(np.dtype(d).itemsize for d in FUSED_VARIABLES.values())
    return per_pixel * lines * columns


def estimate_bytes(spec: DatasetSpec, samples: int | None = None) -> int:
    """Upper bound of the bytes a dataset (or ``samples`` of its samples) writes: uncompressed
    arrays, records and manifest rows, plus the card, thumbnails and metadata."""
    n = spec.samples if samples is None else int(samples)
    per = bytes_per_sample(len(spec.stages), spec.base.lines, spec.base.sensor.columns, spec.fused)
    return n * (per + RECORD_BYTES) + FIXED_BYTES


# --- the folder ----------------------------------------------------------------------------------


def _folder_state(out: Path) -> str:
    """``absent``, ``empty``, ``dataset`` (holds a bench_sim dataset.json), ``file`` or ``other``."""
    if not out.exists():
        return "absent"
    if not out.is_dir():
        return "file"
    if not any(out.iterdir()):
        return "empty"
    try:
        if json.loads((out / DATASET_JSON).read_text()).get("kind") == DATASET_KIND:
            return "dataset"
    except (OSError, ValueError, AttributeError):
        pass
    return "other"


def _schema(spec: DatasetSpec) -> dict[str, Any]:
    from bench_sim.workflows.simulate import VARIABLES

    lines, cols, n_st = spec.base.lines, spec.base.sensor.columns, len(spec.stages)
    variables: dict[str, Any] = {}
    for name, dtype in STAGE_VARIABLES.items():
        variables[name] = {
            "dims": ["sample", "stage", "line", "column"], "dtype": dtype, "chunks": [1, 1, lines, cols],
            "shape": [spec.samples, n_st, lines, cols],
            "units": VARIABLES[name][0], "long_name": VARIABLES[name][1],
        }
    if spec.fused:
        for name, dtype in FUSED_VARIABLES.items():
            variables[name] = {
                "dims": ["sample", "line", "column"], "dtype": dtype, "chunks": [1, lines, cols],
                "shape": [spec.samples, lines, cols],
                "units": VARIABLES[name][0], "long_name": VARIABLES[name][1],
            }
    return {"variables": variables, "store": DATA_STORE, "zarr_format": 3}


def _info(spec: DatasetSpec) -> dict[str, Any]:
    """The content of ``dataset.json``."""
    from bench_sim.runtime.provenance import provenance

    try:
        spec_file = os.path.relpath(spec.path)
    except ValueError:  # pragma: no cover - another drive
        spec_file = str(spec.path)
    if spec_file.startswith(".."):
        spec_file = spec.path.name
    return {
        "kind": DATASET_KIND,
        "format": FORMAT_VERSION,
        "name": spec.name,
        "description": spec.description,
        "samples": spec.samples,
        "seed": spec.seed,
        "stages": list(spec.stages),
        "lines": spec.base.lines,
        "columns": spec.base.sensor.columns,
        "fused": spec.fused,
        "spec_file": spec_file,
        "spec": spec.raw,
        "spec_sha256": spec.identity(),
        "randomize": {k: d.model_dump() for k, d in spec.randomize.items()},
        "images": spec.images,
        "streams": (
            "sample i owns numpy.random.SeedSequence(seed, spawn_key=(i,)) = SeedSequence(seed).spawn(n)[i]; "
            "its child 0 draws the randomised values (keys in sorted order), its child 1 drives the "
            "simulation (render seed, target, fixed pattern, temporal noise)"
        ),
        "base": provenance(spec.base, spec.seed, kind="dataset base bench"),
        "schema": _schema(spec),
    }


def _write_skeleton(spec: DatasetSpec, folder: Path) -> None:
    """``dataset.json``, an empty ``data.zarr`` with the whole schema and ``samples/``."""
    import warnings

    import dask.array as da
    import xarray as xr

    from bench_sim.config import config_sha256, config_to_toml_text
    from bench_sim.io import write_json
    from bench_sim.version import __version__

    info = _info(spec)
    schema = info["schema"]["variables"]
    coords = {
        "sample": np.arange(spec.samples, dtype=np.int64),
        "stage": np.asarray(spec.stages, dtype=np.int64),
        "line": np.arange(spec.base.lines, dtype=np.int64),
        "column": np.arange(spec.base.sensor.columns, dtype=np.int64),
    }
    data = {
        name: (v["dims"], da.zeros(v["shape"], chunks=v["chunks"], dtype=v["dtype"]))
        for name, v in schema.items()
    }
    ds = xr.Dataset(data, coords=coords)
    for name, v in schema.items():
        ds[name].attrs.update(units=v["units"], long_name=v["long_name"])
    ds["sample"].attrs.update(units="1", long_name="sample index (spawn key of its random stream)")
    ds["stage"].attrs.update(units="1", long_name="DTDI stage m (rows summed)")
    ds["line"].attrs.update(units="1", long_name="scene line (material at line * delta along the track)")
    ds["column"].attrs.update(units="1", long_name="sensor column")
    ds.attrs.update(
        title=f"bench_sim dataset {spec.name}",
        seed=spec.seed,
        version=__version__,
        spec_sha256=info["spec_sha256"],
        base_config=config_to_toml_text(spec.base),
        base_config_sha256=config_sha256(spec.base),
        beta_bits=int(spec.base.dtdi.beta_bits),
        pedestal_dn=float(spec.base.dtdi.pedestal_dn),
        complete_samples="see samples/*.json records (status complete) or the manifest",
    )
    if spec.fused:
        ds.attrs.update(mu1=int(spec.base.fusion.mu1), mu2=int(spec.base.fusion.mu2))
    encoding = {name: {"chunks": tuple(v["chunks"])} for name, v in schema.items()}
    with warnings.catch_warnings():  # consolidated metadata is a Zarr v3 extension
        warnings.filterwarnings("ignore", message="Consolidated metadata", category=UserWarning)
        ds.to_zarr(folder / DATA_STORE, mode="w-", zarr_format=3, consolidated=True, compute=False,
                   encoding=encoding)
    (folder / RECORDS_DIR).mkdir()
    write_json(folder / DATASET_JSON, info)


def _lay_out(spec: DatasetSpec, out: Path) -> None:
    """Make the skeleton in a temporary folder beside ``out`` and rename it into place (replacing
    an empty folder or a dataset that may be replaced)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-{os.getpid()}-", dir=out.parent))
    try:
        _write_skeleton(spec, tmp)
        os.chmod(tmp, 0o777 & ~_umask())
        old = None
        if out.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-{os.getpid()}-", dir=out.parent))
            os.replace(out, old / "set")
        os.replace(tmp, out)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _check_folder(spec: DatasetSpec, out: Path, *, reuse: bool) -> str:
    """Decide what to do with ``out`` before anything runs: ``create`` (lay out a new dataset,
    replacing an empty folder or a replaceable dataset) or ``reuse`` (the same dataset)."""
    from bench_sim.io import check_output_dir
    from bench_sim.version import __version__

    state = _folder_state(out)
    if state == "file":
        raise BenchSimError(f"--out = {str(out)!r}: is a file, not a folder")
    if state == "other":
        raise BenchSimError(
            f"--out = {str(out)!r}: folder exists, is not empty and holds no bench_sim dataset: choose "
            "a new or empty folder"
        )
    if state in ("absent", "empty"):
        check_output_dir(out)
        return "create"
    info = json.loads((out / DATASET_JSON).read_text())
    records = read_records(out)
    has_data = (out / DATA_STORE).is_dir()
    done = sum(1 for r in records.values() if r.get("status") == "complete")
    if not reuse:
        if (out / COMPLETION_RECORD).is_file() or not records or not has_data:
            return "create"  # a complete dataset, or one with no sample yet, is replaced
        raise BenchSimError(
            f"--out = {str(out)!r}: holds an incomplete dataset ({done} of {info.get('samples')} samples "
            "complete): --resume completes it; delete the folder to start again"
        )
    if not has_data:
        return "create"  # a card without its data (e.g. a committed example): make the data
    if info.get("spec_sha256") != spec.identity():
        raise BenchSimError(
            f"--out = {str(out)!r}: holds a dataset made from another spec (spec, base bench or image "
            "files changed): use a new folder, or run without --resume to replace a complete one"
        )
    made_with = info.get("base", {}).get("version")
    if made_with != __version__:
        raise BenchSimError(
            f"--out = {str(out)!r}: made with bench_sim {made_with}, this is {__version__}: samples would "
            "not match; use a new folder"
        )
    return "reuse"


# --- manifest ------------------------------------------------------------------------------------


def manifest_frame(
    spec: DatasetSpec, records: dict[int, dict[str, Any]], values: Sequence[dict[str, Any]]
) -> pd.DataFrame:
    """One row per sample: ``sample``, ``seed``, every randomised key, ``config_sha256``, the
    summary metrics, ``status`` (``complete`` / ``failed`` / ``pending``), ``error``, ``wall_s``,
    ``worker``. ``values``: every sample's drawn values (pending samples list theirs)."""
    import pandas as pd

    metric_names: list[str] = ["scene_dr_db"]
    for m in spec.stages:
        metric_names += [f"saturated_fraction_m{m}", f"snr_dark_m{m}", f"snr_bright_m{m}"]
    rows = []
    for i in range(spec.samples):
        rec = records.get(i, {})
        drawn = rec.get("values") or values[i]
        metrics = rec.get("metrics") or {}
        row: dict[str, Any] = {"sample": i, "seed": spec.seed}
        row.update({k: drawn.get(k) for k in spec.randomize})
        row["config_sha256"] = rec.get("config_sha256", "")
        row.update({k: float(metrics.get(k, np.nan)) for k in metric_names})
        row.update(
            status=rec.get("status", "pending"), error=rec.get("error") or "",
            wall_s=float(rec.get("wall_s", np.nan)), worker=rec.get("worker", ""),
        )
        rows.append(row)
    return pd.DataFrame(rows)


def _write_manifest(
    out: Path, spec: DatasetSpec, meta: dict[str, Any], values: Sequence[dict[str, Any]]
) -> pd.DataFrame:
    """``manifest.parquet`` (provenance in the schema metadata, key ``bench_sim``) and
    ``manifest.csv`` (provenance as ``#`` lines), both rebuilt from the records."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from bench_sim.io import atomic_path, write_csv

    df = manifest_frame(spec, read_records(out), values)
    table = pa.Table.from_pandas(df, preserve_index=False)
    provenance = json.dumps(meta, sort_keys=True, default=str).encode()
    table = table.replace_schema_metadata({**(table.schema.metadata or {}), b"bench_sim": provenance})
    with atomic_path(out / MANIFEST_PARQUET) as tmp:
        pq.write_table(table, tmp)
    rows = [[_csv_value(v) for v in r] for r in df.itertuples(index=False, name=None)]
    write_csv(out / MANIFEST_CSV, list(df.columns), rows, metadata=meta)
    return df


def _csv_value(v: Any) -> Any:
    if isinstance(v, np.generic):
        v = v.item()
    return v


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
    from bench_sim.io import check_free_space, format_bytes, write_json
    from bench_sim.runtime.execution import open_client, run_tasks
    from bench_sim.workflows.dataset.card import write_card
    from bench_sim.workflows.dataset.spec import check_sample_configs, load_spec, sample_streams
    from bench_sim.workflows.preflight import preflight_tasks

    t_start = time.perf_counter()
    if workers is not None and scheduler is not None:
        raise BenchSimError("--workers and --scheduler: give one (a scheduler brings its own workers)")
    if workers is not None and workers < 0:
        raise BenchSimError(f"--workers = {workers}: must be >= 0 (0 runs in this process)")
    if resume and only:
        raise BenchSimError("--resume and --only: give one (--only remakes just the samples named)")
    spec = load_spec(spec_path)
    only_idx = _parse_only(only, spec.samples)
    out = Path(out).expanduser().resolve()
    action = _check_folder(spec, out, reuse=resume or only_idx is not None)
    done_before = set() if action == "create" else {
        i for i, r in read_records(out).items() if r.get("status") == "complete"
    }
    todo = only_idx if only_idx is not None else [i for i in range(spec.samples) if i not in done_before]
    per = bytes_per_sample(len(spec.stages), spec.base.lines, spec.base.sensor.columns, spec.fused)
    check_free_space(
        out, estimate_bytes(spec, len(todo)),
        detail=f"{len(todo)} samples x {format_bytes(per)} uncompressed + records and card",
    )
    values = [spec.draw(i) for i in range(spec.samples)]
    planned = check_sample_configs(spec, {i: values[i] for i in todo})
    preflight_tasks(  # memory of the samples running at once here, the backend (disk: above)
        "dataset", [(planned[i], spec.stages) for i in todo], out=out, workers=workers,
        scheduler=scheduler, disk_bytes={}, hint="lower --workers, lines or columns",
    )
    run = DatasetRun(out=out, samples=spec.samples)

    # the execution layer first: a scheduler that cannot be reached (or a cluster that cannot
    # start) is refused before anything is laid out at --out
    with open_client(workers=workers, scheduler=scheduler) if todo else contextlib.nullcontext() as client:
        if action == "create":
            _lay_out(spec, out)
        meta = _manifest_meta(spec)
        (out / COMPLETION_RECORD).unlink(missing_ok=True)  # rewritten last if the dataset completes
        if not todo:
            run.complete = len(done_before)
        else:
            tasks = [
                SampleTask(i, planned[i], spec.stages, sample_streams(spec.seed, i)[1]) for i in todo
            ]
            writer = _SampleWriter(out, spec, values, meta)
            bar = _progress(progress, len(todo), spec.samples - len(todo))
            try:
                run_tasks(make_sample, tasks, client=client, indices=todo, keep_values=False,
                          on_result=lambda o: (writer.write(o), bar(o)))
            except BaseException:
                _write_manifest(out, spec, meta, values)  # what is on disk now (Ctrl-C, lost scheduler)
                raise
            finally:
                bar(None)
            run.ran, run.failed = writer.ran, writer.failed
            run.complete = sum(1 for r in read_records(out).values() if r.get("status") == "complete")
    df = _write_manifest(out, spec, meta, values)
    write_card(out, spec, df, command=command, provenance=meta)
    if run.complete == spec.samples:
        write_json(out / COMPLETION_RECORD, {
            "command": "dataset", "version": meta["version"], "seed": spec.seed,
            "spec_sha256": meta["spec_sha256"], "samples": spec.samples,
        })
    run.wall_s = time.perf_counter() - t_start
    return run


def _manifest_meta(spec: DatasetSpec) -> dict[str, Any]:
    from bench_sim.config import config_sha256
    from bench_sim.version import __version__

    return {
        "version": __version__, "seed": spec.seed, "config_sha256": config_sha256(spec.base),
        "spec_sha256": spec.identity(), "dataset": spec.name,
    }


class _SampleWriter:
    """Writes each outcome as it arrives: arrays into ``data.zarr``, then the record; the
    manifest every :data:`MANIFEST_EVERY_S` seconds."""

    def __init__(self, out: Path, spec: DatasetSpec, values: Sequence[dict[str, Any]], meta: dict[str, Any]):
        import zarr

        self.out, self.spec, self.values, self.meta = out, spec, values, meta
        self.group = zarr.open_group(str(out / DATA_STORE), mode="r+", use_consolidated=False)
        self.ran: list[int] = []
        self.failed: dict[int, str] = {}
        self._last_manifest = time.monotonic()

    def write(self, outcome: Any) -> None:
        from bench_sim.io import write_json

        i = int(outcome.index)
        path = record_path(self.out, i)
        path.unlink(missing_ok=True)  # --only on a complete sample: not complete while rewritten
        rec: dict[str, Any] = {
            "sample": i, "seed": self.spec.seed, "values": self.values[i],
            "wall_s": round(float(outcome.wall_s), 4), "worker": str(outcome.worker),
        }
        if outcome.ok:
            value: SampleOutput = outcome.value
            for name, arr in value.arrays.items():
                self.group[name][i] = np.asarray(arr, dtype=self.group[name].dtype)
            rec.update(status="complete", metrics=value.metrics, **value.info)
        else:
            rec.update(status="failed", error=outcome.error)
            self.failed[i] = str(outcome.error)
        write_json(path, rec)  # after the arrays: a record says they are on disk
        self.ran.append(i)
        if time.monotonic() - self._last_manifest > MANIFEST_EVERY_S:
            _write_manifest(self.out, self.spec, self.meta, self.values)
            self._last_manifest = time.monotonic()


def _progress(enabled: bool, total: int, skipped: int) -> Callable[[Any], None]:
    """A callback advancing a rich progress bar per outcome (``None`` closes it)."""
    if not enabled:
        return lambda outcome: None
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    bar = Progress(
        TextColumn("[bold]dataset"), BarColumn(), TextColumn("{task.completed}/{task.total} samples"),
        TextColumn("{task.fields[note]}"), TimeElapsedColumn(), TimeRemainingColumn(), transient=False,
        console=None,
    )
    note = f"({skipped} already complete)" if skipped else ""
    task = bar.add_task("samples", total=total, note=note)
    bar.start()
    failed = [0]

    def step(outcome: Any) -> None:
        if outcome is None:
            bar.stop()
            return
        if not outcome.ok:
            failed[0] += 1
            bar.update(task, note=f"{failed[0]} failed")
        bar.update(task, advance=1)

    return step


def main_summary(run: DatasetRun) -> str:
    """One line about a finished run, for the command's output."""
    failed = f", {len(run.failed)} failed (see manifest.csv; --resume retries them)" if run.failed else ""
    state = "complete" if run.done else "incomplete"
    return (
        f"dataset {run.out}: {run.complete} of {run.samples} samples complete ({state}); "
        f"{len(run.ran)} made in {run.wall_s:.1f} s{failed}"
    )

