"""Reading a synthetic validation dataset made by ``bench-sim dataset``.

- :func:`open` ``(DIR)`` -> :class:`xarray.Dataset` (lazy, Dask-backed): the arrays with
  dimensions ``sample``, ``stage``, ``line``, ``column`` and the manifest's columns (the
  randomised values, the summary metrics) as coordinates along ``sample``.
- :func:`iter_samples` ``(DIR)`` -> one :class:`Sample` at a time: numpy arrays and the
  sample's parameters and metrics, without xarray.
- For training: ``bench_sim.dataset.iter_batches`` / ``torch_dataset`` by split
  (:mod:`bench_sim.workflows.dataset.loaders`).

Layout of ``DIR`` (the writer is :mod:`bench_sim.workflows.dataset.run`):

=========================== =====================================================================
``data.zarr``               Zarr v3, the schema of ``simulate``'s store with a ``sample``
                            dimension (:mod:`bench_sim.pipeline.store_schema`): the pass's
                            stage variables (``sample, stage, line, column``) and, when two
                            stages are fused, its image variables (``sample, line, column``):
                            ``gamma_hdr``, the true HDR target ``true_hdr_dn``, ...; words in
                            the smallest unsigned type, truth in float32; ``units``,
                            ``long_name``, ``pedestal_included`` on every array; physical
                            coordinates per sample (:data:`SAMPLE_COORDS`)
``samples/NNNNNNNN.json``   one record per finished sample, written after its arrays are on
                            disk: status (``complete`` / ``failed``), values, metrics, time
                            (the journal of :mod:`bench_sim.runtime.journal`)
``manifest.parquet``/``.csv`` one row per sample (complete, failed or pending); plain CSV,
                            its provenance in ``manifest.csv.json``
``dataset.json``            the spec, provenance (version, config hashes), the schema
``README.md``               the dataset card; ``thumbnails.png`` its thumbnail sheet
``.bench-sim-output.json``  the completion record, written last, when every sample is complete
=========================== =====================================================================

A dataset is written sample by sample, so ``DIR`` can hold an incomplete one (a run that was
stopped, or is still going): only samples with a ``complete`` record are valid. :func:`open` and
:func:`iter_samples` refuse an incomplete dataset unless asked for its complete samples
(``incomplete=True``). This module imports nothing heavy at import time.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from bench_sim.errors import BenchSimError
from bench_sim.io import OUTPUT_MARKER
from bench_sim.pipeline import IMAGE_DIMS, STAGE_DIMS, VARIABLES_BY_NAME, pass_variables
from bench_sim.runtime.journal import Journal
from bench_sim.workflows.dataset.splits import DEFAULT_SPLITS, split_map

if TYPE_CHECKING:
    import xarray as xr

__all__ = [
    "open",
    "iter_samples",
    "read_sample_array",
    "Sample",
    "DATA_STORE",
    "DATASET_JSON",
    "RECORDS_DIR",
    "MANIFEST_PARQUET",
    "MANIFEST_CSV",
    "MANIFEST_META",
    "CARD",
    "THUMBNAILS",
    "COMPLETION_RECORD",
    "DATASET_KIND",
    "DATASET_FILES",
    "STAGE_VARIABLES",
    "FUSED_VARIABLES",
    "SAMPLE_COORDS",
    "variable_meta",
    "journal",
    "record_path",
    "read_info",
    "read_records",
    "complete_samples",
    "is_complete",
]

DATA_STORE = "data.zarr"
DATASET_JSON = "dataset.json"
RECORDS_DIR = "samples"
MANIFEST_PARQUET = "manifest.parquet"
MANIFEST_CSV = "manifest.csv"
#: the manifest's sidecar: its provenance and columns
MANIFEST_META = "manifest.csv.json"
CARD = "README.md"
THUMBNAILS = "thumbnails.png"
#: written last, when every sample is complete (the output-set marker of :mod:`bench_sim.io`)
COMPLETION_RECORD = OUTPUT_MARKER
#: ``kind`` of ``dataset.json``: how a folder is recognised as a bench_sim dataset
DATASET_KIND = "bench_sim dataset"
#: Everything a dataset folder may hold (patterns of :mod:`bench_sim.io.ownership`): a folder
#: holding anything else is never replaced or written into
DATASET_FILES = (
    DATASET_JSON, f"{DATA_STORE}/**", f"{RECORDS_DIR}/[0-9]*.json", MANIFEST_PARQUET, MANIFEST_CSV,
    MANIFEST_META, CARD, THUMBNAILS,
)



#: variables with dimensions (sample, stage, line, column): the pass's stage variables
#: (:data:`bench_sim.pipeline.PASS_VARIABLES`)
STAGE_VARIABLES: tuple[str, ...] = tuple(v.name for v in pass_variables(STAGE_DIMS))
#: variables with dimensions (sample, line, column), present when two stages are fused: the pass's
#: image variables, its maps included (the same variables as ``simulate``'s)
FUSED_VARIABLES: tuple[str, ...] = tuple(v.name for v in pass_variables(IMAGE_DIMS, maps=True))
#: coordinates of their own per sample (where its window sits, its line period)
SAMPLE_COORDS: dict[str, str] = {"along_track_mm": "line", "time_s": "line", "across_track_mm": "column"}


def variable_meta(name: str) -> tuple[str, str]:
    """(units, long name) of a dataset variable."""
    return VARIABLES_BY_NAME[name].units, VARIABLES_BY_NAME[name].doc


def journal(folder: str | Path) -> Journal:
    """The journal of a dataset folder: ``samples/NNNNNNNN.json``, indexed by the record's ``sample``."""
    return Journal(Path(folder) / RECORDS_DIR, key="sample", digits=8)


def record_path(folder: str | Path, index: int) -> Path:
    """The completion record of sample ``index``."""
    return journal(folder).path(index)


def read_info(folder: str | Path) -> dict[str, Any]:
    """``dataset.json`` of a dataset folder (one-line error if it is not one)."""
    path = Path(folder) / DATASET_JSON
    try:
        info = json.loads(path.read_text())
    except FileNotFoundError:
        raise BenchSimError(f"{str(folder)!r}: not a bench_sim dataset (no {DATASET_JSON})") from None
    except (OSError, ValueError) as exc:
        raise BenchSimError(f"{str(path)!r}: unreadable ({exc})") from None
    if info.get("kind") != DATASET_KIND:
        raise BenchSimError(f"{str(path)!r}: not a bench_sim dataset description")
    return info


def read_records(folder: str | Path) -> dict[int, dict[str, Any]]:
    """Sample index -> its record, for every readable record (complete or failed); an
    unreadable one counts as not done (:mod:`bench_sim.runtime.journal`)."""
    return journal(folder).read()


def complete_samples(folder: str | Path) -> list[int]:
    """Indices of the samples whose record says ``complete``, sorted."""
    return sorted(i for i, r in read_records(folder).items() if r.get("status") == "complete")


def is_complete(folder: str | Path) -> bool:
    """Whether the dataset's completion record exists (every sample complete)."""
    return (Path(folder) / COMPLETION_RECORD).is_file()


def _selection(
    folder: Path, incomplete: bool, only: Sequence[int] | None
) -> tuple[dict[str, Any], list[int]]:
    info = read_info(folder)
    n = int(info["samples"])
    done = complete_samples(folder)
    if not incomplete and len(done) < n:
        raise BenchSimError(
            f"{str(folder)!r}: incomplete dataset ({len(done)} of {n} samples complete): complete it with "
            "bench-sim dataset SPEC --out DIR --resume, or read its complete samples with incomplete=True"
        )
    if only is not None:
        bad = [i for i in only if i not in set(done)]
        if bad:
            raise BenchSimError(f"sample {bad[0]}: not a complete sample of {str(folder)!r}")
        done = [int(i) for i in only]
    return info, done


def open(folder: str | Path, *, incomplete: bool = False) -> xr.Dataset:
    """Open a dataset lazily as an :class:`xarray.Dataset`.

    Parameters
    ----------
    folder
        The dataset folder (``bench-sim dataset ... --out DIR``).
    incomplete
        Open a dataset that is not complete, keeping its complete samples only. Without it an
        incomplete dataset is refused (one line).

    Returns
    -------
    xarray.Dataset
        ``data.zarr`` (Dask arrays: nothing is read until used), restricted to the complete
        samples, with the manifest's columns (``seed``, every randomised key, ``config_sha256``,
        the summary metrics, ``wall_s``) as coordinates along ``sample``.
    """
    import xarray as xr

    folder = Path(folder)
    info, done = _selection(folder, incomplete, None)
    ds = xr.open_zarr(folder / DATA_STORE, consolidated=True)
    ds = ds.sel(sample=done)
    records = read_records(folder)
    table = [
        {**r.get("values", {}), "config_sha256": r.get("config_sha256"),
         **{k: np.nan if v is None else v for k, v in r.get("metrics", {}).items()},
         "wall_s": r.get("wall_s")}
        for r in (records[i] for i in done)
    ]
    for key in dict.fromkeys(k for row in table for k in row):
        ds.coords[key] = ("sample", np.asarray([row.get(key) for row in table]))
    splits = info.get("splits") or DEFAULT_SPLITS
    of = split_map(int(info["seed"]), int(info["samples"]), splits)
    ds.coords["split"] = ("sample", np.asarray([of[i] for i in done]))
    return ds


@dataclass
class Sample:
    """One sample of a dataset.

    Attributes
    ----------
    index
        The sample's index (its position in the dataset, its stream's spawn key).
    stages
        The stored stages, in the order of the first axis of the stage arrays.
    arrays
        Variable -> numpy array: ``(stage, line, column)`` for ``dn``, ``mean_dn``, ``photons``,
        ``reflectance``, ``clipped``; ``(line, column)`` for ``gamma_hdr``, ``gamma_hdr_source``.
    values
        The randomised config values (dotted keys; image paths relative to the spec).
    metrics
        The summary metrics of the manifest.
    units
        Variable -> units.
    """

    index: int
    stages: tuple[int, ...]
    arrays: dict[str, np.ndarray]
    values: dict[str, Any]
    metrics: dict[str, float]
    units: dict[str, str] = field(default_factory=dict)


def iter_samples(
    folder: str | Path,
    *,
    variables: Sequence[str] | None = None,
    only: Sequence[int] | None = None,
    incomplete: bool = False,
) -> Iterator[Sample]:
    """Yield the samples of a dataset one at a time as numpy arrays (no xarray needed).

    Parameters
    ----------
    folder
        The dataset folder.
    variables
        Variables to read (default: all).
    only
        Sample indices to read (default: every complete sample, in order).
    incomplete
        Allow an incomplete dataset (its complete samples are yielded).
    """
    import zarr

    folder = Path(folder)
    info, done = _selection(folder, incomplete, only)
    schema = info["schema"]["variables"]
    names = list(schema) if variables is None else list(variables)
    unknown = [v for v in names if v not in schema]
    if unknown:
        raise BenchSimError(
            f"variables = {names}: {unknown[0]!r} is not in the dataset ({', '.join(schema)})"
        )
    group: Any = zarr.open_group(str(folder / DATA_STORE), mode="r")  # of arrays, by name
    records = read_records(folder)
    stages = tuple(int(m) for m in info["stages"])
    units = {v: schema[v]["units"] for v in names}
    for i in done:
        rec = records[i]
        arrays = {v: read_sample_array(group, folder, v, i) for v in names}
        yield Sample(i, stages, arrays, dict(rec.get("values", {})), dict(rec.get("metrics", {})), units)


def _damaged(folder: Path, arr: Any, name: str, index: int, exc: Exception) -> str:
    """The one line of a sample's chunk that cannot be read: sample, variable, file, remedy."""
    where = folder / DATA_STORE / name
    try:  # the file of the sample's (first) chunk, e.g. data.zarr/gamma_hdr/c/3/0/0
        coords = (index // arr.chunks[0], *(0 for _ in arr.chunks[1:]))
        where = where / arr.metadata.chunk_key_encoding.encode_chunk_key(coords)
    except (AttributeError, TypeError, IndexError):  # a store of another layout: its folder
        pass
    detail = " ".join(str(exc).split())[:160] or type(exc).__name__
    return (
        f"sample {index}, variable {name!r}: cannot read {where} ({type(exc).__name__}: {detail}): a "
        f"damaged file; remake the sample with 'bench-sim dataset SPEC --out {folder} --only {index}'"
    )


def read_sample_array(group: Any, folder: Path, name: str, index: int) -> np.ndarray:
    """Variable ``name`` of sample ``index`` from the dataset's open Zarr ``group``; a chunk
    that cannot be read (a damaged file) is one :class:`~bench_sim.errors.BenchSimError` line
    naming the sample, the variable, the chunk's file and how to remake it."""
    try:
        return np.asarray(group[name][int(index)])
    except Exception as exc:  # zarr and its codecs raise many kinds for a damaged chunk
        raise BenchSimError(_damaged(folder, group[name], name, int(index), exc)) from None
