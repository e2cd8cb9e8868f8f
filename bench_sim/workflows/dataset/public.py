"""``bench_sim.dataset``: reading a generated dataset, and loading it for training.

- :func:`open`, :func:`iter_samples`, :class:`Sample` and the file names:
  :mod:`bench_sim.workflows.dataset.reader`;
- :func:`iter_batches`, :func:`torch_dataset`, :class:`SplitSamples`, :func:`split_samples`:
  :mod:`bench_sim.workflows.dataset.loaders` (splits: :mod:`bench_sim.workflows.dataset.splits`).
"""

from __future__ import annotations

from bench_sim.workflows.dataset.loaders import SplitSamples, iter_batches, split_samples, torch_dataset
from bench_sim.workflows.dataset.reader import (
    CARD,
    COMPLETION_RECORD,
    DATA_STORE,
    DATASET_JSON,
    DATASET_KIND,
    FUSED_VARIABLES,
    MANIFEST_CSV,
    MANIFEST_PARQUET,
    RECORDS_DIR,
    STAGE_VARIABLES,
    THUMBNAILS,
    Sample,
    complete_samples,
    is_complete,
    iter_samples,
    journal,
    open,
    read_info,
    read_records,
    record_path,
    variable_meta,
)
from bench_sim.workflows.dataset.splits import split_of

__all__ = [
    "open", "iter_samples", "Sample", "iter_batches", "torch_dataset", "SplitSamples", "split_samples",
    "split_of", "DATA_STORE", "DATASET_JSON", "RECORDS_DIR", "MANIFEST_PARQUET", "MANIFEST_CSV", "CARD",
    "THUMBNAILS", "COMPLETION_RECORD", "DATASET_KIND", "STAGE_VARIABLES", "FUSED_VARIABLES",
    "variable_meta", "journal", "record_path", "read_info", "read_records", "complete_samples",
    "is_complete",
]
