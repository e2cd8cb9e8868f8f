"""The fast engine's row kernels on disk, beside its light records
(:mod:`bench_sim.render.record_store`): a new process (a Dask worker, a second run) that finds
the kernels of its records and run texture grid loads them instead of deriving them again from
the records (~0.5 s of one core per process at ``--quick`` size).

Where
    ``<cache folder>/kernels/`` (the record store's cache folder). Removing it clears it.
Switch and size
    The record store's: ``BENCH_SIM_RECORD_CACHE=off`` turns this store off too (the test suite
    runs with it off); at most ``BENCH_SIM_RECORD_CACHE_MIB`` MiB in this folder, least
    recently used files deleted beyond it.
Files
    ``<sha256>.npz`` (uncompressed, no pickles), the hash of the kernels' key (the records' key
    and the grid's: :meth:`bench_sim.render.engines.FastEngine.kernel_key`) and
    :func:`versions` (the record store's, NumPy's version and a fingerprint of the engine's
    source). Members: ``meta`` (the key, the versions and the number of rows as JSON),
    ``bases`` (rows, 2) int64 (each row's first texel row and column), ``shapes`` (rows, 4)
    int64 (each row's weights' shape) and ``weights``, every row's float32 weights as they were
    derived, one after the other (so each row's are the same dtype, shape and bytes). One flat
    member, read with one copy: a member per row took ~0.15 s to read at ``--quick`` size (the
    zip directory, a header per member), in every worker process.
Failures
    The store never fails a run: a file that cannot be read (truncated, corrupt, another key or
    versions, inconsistent members) is a miss and is deleted if possible; a write that fails is
    skipped. Writes are atomic (:func:`bench_sim.io.atomic.atomic_path`).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.render import record_store
from bench_sim.runtime.backend import cache_folder

__all__ = ["FORMAT", "RowKernels", "store_dir", "versions", "load", "save"]

#: Version of the file layout; raise it when the files or the kernels' meaning change.
FORMAT = 2
#: Kernels of a sensor's rows: ``(base_y, base_x, weights)`` per row.
RowKernels = list[tuple[int, int, np.ndarray]]


def store_dir() -> Path | None:
    """The store's folder (``<cache folder>/kernels``), or ``None`` when the stores are off."""
    return cache_folder() / "kernels" if record_store.store_on() else None


@functools.cache
def versions() -> dict[str, str]:
    """What stored kernels depend on besides their key: the record store's
    :func:`~bench_sim.render.record_store.versions`, NumPy's version, :data:`FORMAT` and the
    fingerprint of the engine that derives them. Computed once per process."""
    return {
        **record_store.versions(),
        "numpy": np.__version__,
        "kernels_format": str(FORMAT),
        "engine": record_store.source_fingerprint(("render/engines.py",)),
    }


def _read(path: Path, meta: dict[str, Any]) -> RowKernels:
    rows = int(meta["rows"])
    arrays = record_store.mapped_arrays(path, ("bases", "shapes", "weights"))
    bases, shapes, flat = arrays["bases"], arrays["shapes"], arrays["weights"]
    if (bases.shape != (rows, 2) or shapes.shape != (rows, 4) or bases.dtype != np.int64
            or shapes.dtype != np.int64 or flat.dtype != np.float32 or flat.ndim != 1 or np.any(shapes < 0)):
        raise ValueError("inconsistent members")
    ends = np.cumsum(np.prod(shapes, axis=1))
    if rows and int(ends[-1]) != flat.size:
        raise ValueError("inconsistent weights")
    weights = np.array(flat)  # one copy out of the map: writeable arrays, as derived
    starts = np.concatenate([[0], ends[:-1]]) if rows else ends
    return [(int(bases[i, 0]), int(bases[i, 1]), weights[starts[i]:ends[i]].reshape(tuple(shapes[i])))
            for i in range(rows)]


def load(key: str) -> RowKernels | None:
    """The stored kernels of ``key``, or ``None``: the store is off, has none, or the file
    cannot be read (then it is deleted). Never raises."""
    return record_store.read_entry(store_dir(), key, versions(), _read)


def save(key: str, kernels: Sequence[tuple[int, int, np.ndarray]]) -> None:
    """Store the kernels of ``key``, then delete the least recently used files beyond the size
    bound. Nothing when the store is off; a write that fails is skipped (never raises)."""

    def arrays() -> dict[str, np.ndarray]:
        bases = np.array([[by, bx] for by, bx, _ in kernels], dtype=np.int64).reshape(len(kernels), 2)
        shapes = np.array([w.shape for _, _, w in kernels], dtype=np.int64).reshape(len(kernels), 4)
        flat = [np.ascontiguousarray(w, dtype=np.float32).ravel() for _, _, w in kernels]
        return {"bases": bases, "shapes": shapes,
                "weights": np.concatenate(flat) if flat else np.zeros(0, np.float32)}

    record_store.write_entry(store_dir(), key, versions(), {"rows": len(kernels)}, arrays)
