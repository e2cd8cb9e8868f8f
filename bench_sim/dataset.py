"""``bench_sim.dataset``: reading a generated dataset, loading it for training, scoring a fusion.

A module (``from bench_sim.dataset import iter_batches`` works) that re-exports the public names
of the ``dataset`` workflow:

- :func:`open`, :func:`iter_samples`, :class:`Sample` and the file names:
  :mod:`bench_sim.workflows.dataset.reader`;
- :func:`iter_batches`, :func:`torch_dataset`, :class:`SplitSamples`, :func:`split_samples`:
  :mod:`bench_sim.workflows.dataset.loaders` (splits: :mod:`bench_sim.workflows.dataset.splits`);
- :func:`score_fusion`, :class:`FusionScore`: any fusion against the true HDR target over a split
  (:mod:`bench_sim.workflows.dataset.scoring`).
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
    MANIFEST_META,
    MANIFEST_PARQUET,
    RECORDS_DIR,
    SAMPLE_COORDS,
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
from bench_sim.workflows.dataset.scoring import REGIONS, FusionScore, score_fusion
from bench_sim.workflows.dataset.splits import split_indices, split_of, split_sizes

__all__ = [
    "open", "iter_samples", "Sample", "iter_batches", "torch_dataset", "SplitSamples", "split_samples",
    "score_fusion", "FusionScore", "REGIONS", "split_of", "split_indices", "split_sizes", "DATA_STORE",
    "DATASET_JSON", "RECORDS_DIR", "MANIFEST_PARQUET", "MANIFEST_CSV", "MANIFEST_META", "CARD", "THUMBNAILS",
    "COMPLETION_RECORD", "DATASET_KIND", "STAGE_VARIABLES", "FUSED_VARIABLES", "SAMPLE_COORDS",
    "variable_meta", "journal", "record_path", "read_info", "read_records", "complete_samples", "is_complete",
]
