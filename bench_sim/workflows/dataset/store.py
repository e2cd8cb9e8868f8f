"""The layout of a dataset folder: its skeleton (``dataset.json``, an empty ``data.zarr`` with
the whole schema, ``samples/``), the checks of ``--out`` before a run, the sizes, and the
manifest rebuilt from the samples' records.

:mod:`bench_sim.workflows.dataset.reader` names the files and reads them; this module writes the
skeleton and the manifest (the samples' arrays and records are written by
:mod:`bench_sim.workflows.dataset.run` as they complete).
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from bench_sim.config import config_sha256, config_to_toml_text
from bench_sim.errors import BenchSimError
from bench_sim.io import atomic_path, check_output_dir, umask, write_csv, write_json
from bench_sim.io.interrupts import deferred_interrupts
from bench_sim.io.ownership import entries, refuse_foreign, remove_listed
from bench_sim.io.strict_json import strict_dumps
from bench_sim.pipeline import (
    COORD_ATTRS,
    IMAGE_DIMS,
    STAGE_DIMS,
    constant_attrs,
    pass_variables,
    physical_coords,
    store_chunks,
    variable_attrs,
)
from bench_sim.version import __version__
from bench_sim.workflows.dataset.reader import (
    COMPLETION_RECORD,
    DATA_STORE,
    DATASET_FILES,
    DATASET_JSON,
    DATASET_KIND,
    MANIFEST_CSV,
    MANIFEST_META,
    MANIFEST_PARQUET,
    RECORDS_DIR,
    SAMPLE_COORDS,
    read_records,
)
from bench_sim.workflows.dataset.splits import SPLIT_RULE, split_map, split_sizes
from bench_sim.workflows.dataset.targets import strict_json
from bench_sim.workflows.output_meta import chain_provenance, provenance, store_attrs

if TYPE_CHECKING:
    import pandas as pd

    from bench_sim.workflows.dataset.spec import DatasetSpec

__all__ = [
    "FORMAT_VERSION",
    "bytes_per_sample",
    "estimate_bytes",
    "folder_state",
    "check_folder",
    "lay_out",
    "manifest_frame",
    "manifest_meta",
    "write_manifest",
]

#: Format of the dataset folder (``dataset.json``'s ``format``), raised on incompatible changes
FORMAT_VERSION = 2
#: Bytes of a sample's record and manifest rows, and of the card, thumbnails and metadata
RECORD_BYTES, FIXED_BYTES = 16 * 1024, 8 * 2**20


def bytes_per_sample(spec: DatasetSpec) -> int:
    """Uncompressed bytes of one sample's arrays: an upper bound of what it takes on disk."""
    lines, cols = spec.base.lines, spec.base.sensor.columns
    per = list(_schema(spec)["variables"].values())
    arrays = sum(np.dtype(v["dtype"]).itemsize * int(np.prod(v["shape"][1:])) for v in per)
    return arrays + 8 * 2 * (lines + cols)  # and its coordinates


def estimate_bytes(spec: DatasetSpec, samples: int | None = None) -> int:
    """Upper bound of the bytes a dataset (or ``samples`` of its samples) writes: uncompressed
    arrays, records and manifest rows, plus the card, thumbnails and metadata."""
    n = spec.samples if samples is None else int(samples)
    return n * (bytes_per_sample(spec) + RECORD_BYTES) + FIXED_BYTES


# --- the folder ----------------------------------------------------------------------------------


def folder_state(out: Path) -> str:
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
    """``dataset.json``'s ``schema``: every variable's dimensions, stored type, chunks, shape, units
    and long name (``simulate``'s schema with a ``sample`` dimension,
    :mod:`bench_sim.pipeline.store_schema`), and the coordinates of each sample."""
    lines, cols, n_st, n = spec.base.lines, spec.base.sensor.columns, len(spec.stages), spec.samples
    variables: dict[str, Any] = {}
    for v in pass_variables(truth=True, maps=True):
        if v.dims == IMAGE_DIMS and not spec.fused:
            continue
        dims = ("sample", *v.dims)
        shape = (n, n_st, lines, cols) if v.dims == STAGE_DIMS else (n, lines, cols)
        variables[v.name] = {
            "dims": list(dims), "dtype": v.stored_dtype(spec.word_bits).name,
            "chunks": list(store_chunks(dims, shape)), "shape": list(shape), "units": v.units,
            "long_name": v.doc,
        }
    coords = {name: {"dims": ["sample", dim], "dtype": "float64"} for name, dim in SAMPLE_COORDS.items()}
    return {"variables": variables, "sample_coordinates": coords, "store": DATA_STORE, "zarr_format": 3}


def _info(spec: DatasetSpec) -> dict[str, Any]:
    """The content of ``dataset.json``."""
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
        "mu1": int(spec.base.fusion.mu1),
        "mu2": int(spec.base.fusion.mu2),
        "spec_file": spec_file,
        "spec": spec.raw,
        "spec_sha256": spec.identity(),
        "randomize": {k: d.model_dump() for k, d in spec.randomize.items()},
        "images": spec.images,
        "splits": spec.splits,
        "split_rule": SPLIT_RULE,
        "split_samples": split_sizes(spec.samples, spec.splits),
        "scene": {k: sv.as_json() for k, sv in spec.scene.items()},
        "camera": spec.camera,
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
    import dask.array as da
    import xarray as xr

    info = _info(spec)
    schema = info["schema"]
    base = spec.base
    coords = {
        "sample": np.arange(spec.samples, dtype=np.int64),
        "stage": np.asarray(spec.stages, dtype=np.int64),
        "line": np.arange(base.lines, dtype=np.int64),
        "column": np.arange(base.sensor.columns, dtype=np.int64),
    }
    data = {
        name: (v["dims"], da.zeros(v["shape"], chunks=v["chunks"], dtype=v["dtype"]))
        for name, v in schema["variables"].items()
    }
    ds = xr.Dataset(data, coords=coords)
    for name in schema["variables"]:
        ds[name].attrs.update(variable_attrs(base, name))
    size = {"line": base.lines, "column": base.sensor.columns}
    for cname, (dim, _values, cattrs) in physical_coords(base).items():
        zeros = da.zeros((spec.samples, size[dim]), chunks=(1, size[dim]))
        ds.coords[cname] = (("sample", dim), zeros, cattrs)
    ds["sample"].attrs.update(units="1", long_name="sample index (spawn key of its random stream)")
    for cname, cattrs in COORD_ATTRS.items():
        ds[cname].attrs.update(cattrs)
    ds.attrs.update(
        title=f"bench_sim dataset {spec.name}",
        seed=spec.seed,
        version=__version__,
        spec_sha256=info["spec_sha256"],
        base_config=config_to_toml_text(base),
        base_config_sha256=config_sha256(base),
        beta_bits=int(base.dtdi.beta_bits),
        pedestal_dn=float(base.dtdi.pedestal_dn),
        complete_samples="see samples/*.json records (status complete) or the manifest",
        camera=spec.camera,
        Conventions="CF-1.10",
        **constant_attrs(base),
        **store_attrs(base),
    )
    if spec.fused:
        ds.attrs.update(mu1=int(base.fusion.mu1), mu2=int(base.fusion.mu2))
    encoding = {name: {"chunks": tuple(v["chunks"])} for name, v in schema["variables"].items()}
    with warnings.catch_warnings(), deferred_interrupts():  # consolidated: a Zarr v3 extension; never cut
        warnings.filterwarnings("ignore", message="Consolidated metadata", category=UserWarning)
        ds.to_zarr(folder / DATA_STORE, mode="w-", zarr_format=3, consolidated=True, compute=False,
                   encoding=encoding)
    (folder / RECORDS_DIR).mkdir()
    write_json(folder / DATASET_JSON, strict_json(info))


def lay_out(spec: DatasetSpec, out: Path) -> None:
    """Make the skeleton in a temporary folder beside ``out`` and rename it into place (replacing
    an empty folder or a dataset that may be replaced: of that, only the dataset's own entries,
    checked by :func:`check_folder`, are removed)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-{os.getpid()}-", dir=out.parent))
    try:
        _write_skeleton(spec, tmp)
        os.chmod(tmp, 0o777 & ~umask())
        old = None
        if out.exists():
            refuse_foreign(out, "--out", DATASET_FILES)  # once more, just before it goes
            owned = entries(out)
            old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-{os.getpid()}-", dir=out.parent))
            os.replace(out, old / "set")
        os.replace(tmp, out)
        if old is not None:
            if remove_listed(old / "set", owned):  # pragma: no cover - an entry added meanwhile
                os.replace(old / "set", out.with_name(f"{out.name}.kept-{os.getpid()}"))
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def check_folder(spec: DatasetSpec, out: Path, *, reuse: bool) -> str:
    """Decide what to do with ``out`` before anything runs: ``create`` (lay out a new dataset,
    replacing an empty folder or a replaceable dataset) or ``reuse`` (the same dataset)."""
    state = folder_state(out)
    if state == "file":
        raise BenchSimError(f"--out = {str(out)!r}: is a file, not a folder")
    if state == "other":
        raise BenchSimError(
            f"--out = {str(out)!r}: folder exists, is not empty and holds no bench_sim dataset (no "
            f"{DATASET_JSON} of ours): choose a new or empty folder"
        )
    if state in ("absent", "empty"):
        check_output_dir(out)
        return "create"
    refuse_foreign(out, "--out", DATASET_FILES)  # only a dataset's own entries are ever touched
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


#: the per-sample metrics of a fused dataset besides those per stage (:func:`metric_names`)
FUSED_METRICS = ("light_ratio_p01", "light_ratio_p99", "light_ratio_max_dev", "light_ratio_outside_fraction",
                 "recoverable_fraction")


def metric_names(spec: DatasetSpec) -> list[str]:
    """The summary metrics of a sample (the manifest's columns,
    :func:`bench_sim.workflows.dataset.run.sample_metrics`)."""
    names = ["scene_dr_db"]
    for m in spec.stages:
        names += [f"saturated_fraction_m{m}", f"snr_dark_m{m}", f"snr_bright_m{m}"]
    return names + (list(FUSED_METRICS) if spec.fused else [])


def manifest_frame(
    spec: DatasetSpec, records: dict[int, dict[str, Any]], values: Sequence[dict[str, Any]]
) -> pd.DataFrame:
    """One row per sample: ``sample``, ``seed``, ``split``, every randomised key and
    ``scene.<key>``, ``light_scale``, ``config_sha256``, the summary metrics, ``status``
    (``complete`` / ``failed`` / ``pending``), ``error``, ``wall_s``, ``worker``. ``values``: every
    sample's drawn values (pending samples list theirs)."""
    import pandas as pd

    names = metric_names(spec)
    splits = split_map(spec.seed, spec.samples, spec.splits)
    drawn_keys = [*spec.randomize, *(f"scene.{k}" for k in spec.scene)]
    rows = []
    for i in range(spec.samples):
        rec = records.get(i, {})
        drawn = rec.get("values") or values[i]
        metrics = rec.get("metrics") or {}
        row: dict[str, Any] = {"sample": i, "seed": spec.seed, "split": splits[i]}
        row.update({k: drawn.get(k) for k in drawn_keys})
        if spec.scene:
            row["light_scale"] = float(rec.get("scene", {}).get("light_scale", np.nan))
        row["config_sha256"] = rec.get("config_sha256", "")
        # a record's null (strict JSON for a NaN metric) is NaN again in the table
        row.update({k: float(np.nan if metrics.get(k) is None else metrics[k]) for k in names})
        row.update(
            status=rec.get("status", "pending"), error=rec.get("error") or "",
            wall_s=float(rec.get("wall_s", np.nan)), worker=rec.get("worker", ""),
        )
        rows.append(row)
    return pd.DataFrame(rows)


def write_manifest(
    out: Path, spec: DatasetSpec, meta: dict[str, Any], values: Sequence[dict[str, Any]]
) -> pd.DataFrame:
    """``manifest.parquet`` (provenance in the schema metadata, key ``bench_sim``), ``manifest.csv``
    (plain CSV: one header line, one row per sample; ``pandas.read_csv`` reads it as it is) and its
    sidecar ``manifest.csv.json`` (the provenance and the columns), rebuilt from the records."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    df = manifest_frame(spec, read_records(out), values)
    table = pa.Table.from_pandas(df, preserve_index=False)
    provenance = strict_dumps(meta, sort_keys=True, default=str).encode()
    table = table.replace_schema_metadata({**(table.schema.metadata or {}), b"bench_sim": provenance})
    with atomic_path(out / MANIFEST_PARQUET) as tmp:
        pq.write_table(table, tmp)
    rows = [[_csv_value(v) for v in r] for r in df.itertuples(index=False, name=None)]
    write_json(out / MANIFEST_META, strict_json({**meta, "columns": list(df.columns)}))
    write_csv(out / MANIFEST_CSV, list(df.columns), rows)
    return df


def _csv_value(v: Any) -> Any:
    if isinstance(v, np.generic):
        v = v.item()
    return v


def manifest_meta(spec: DatasetSpec) -> dict[str, Any]:
    """The provenance of the manifest, the card's thumbnails and the completion record."""
    chain = chain_provenance(spec.base)
    return {
        "version": __version__, "seed": spec.seed, "config_sha256": config_sha256(spec.base),
        "spec_sha256": spec.identity(), "dataset": spec.name, "truth_exact": chain["truth_exact"],
        **({"truth_not_exact": chain["truth_not_exact"]} if "truth_not_exact" in chain else {}),
    }


