"""The sweep's camera columns on disk: a camera's measured dynamic range through the chain
(:func:`bench_sim.workflows.sweep.point.camera_dr`, ~1 s on every sweep before its first point)
kept per camera, so a sweep of a camera measured before (the same sweep again, another
parameter of the same camera) starts its points at once.

Where
    ``<cache folder>/camera_dr/``, beside the fast engine's light records
    (:mod:`bench_sim.render.record_store`: ``$BENCH_SIM_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/bench_sim``, else ``~/.cache/bench_sim``). Removing the folder clears it.
Switch and size
    The record store's: ``BENCH_SIM_RECORD_CACHE=off`` turns this store off too (the test suite
    runs with it off); at most ``BENCH_SIM_RECORD_CACHE_MIB`` MiB, least recently used files
    deleted beyond it (a file is a few KiB).
Files
    ``<sha256>.npz`` (one string member ``meta``, no pickles), the hash of the camera's key
    (:func:`bench_sim.workflows.sweep.point.camera_key`: sensor, timing, DTDI, the fused stages,
    the root seed and the number of levels) and :func:`versions` (bench_sim, NumPy, SciPy and
    numba versions, :data:`FORMAT`, and a fingerprint of every source file of the package, so an
    edited tree measures again). ``meta`` holds the key, the versions and the columns as JSON;
    JSON writes a float as its shortest repr, which reads back to the same float64 bits (NaN and
    the infinities included), so a column loaded from here is the one that was measured.
Failures
    The store never fails a run: a file that cannot be read (truncated, corrupt, another key or
    versions) is a miss and is deleted if possible; a write that fails is skipped. Writes are
    atomic (:func:`bench_sim.io.atomic.atomic_path`).
"""

from __future__ import annotations

import functools
import platform
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.render.record_store import (
    package_version,
    read_entry,
    source_fingerprint,
    store_on,
    write_entry,
)
from bench_sim.runtime.backend import cache_folder
from bench_sim.version import __version__

__all__ = ["FORMAT", "store_dir", "versions", "load", "save"]

#: Version of the file layout; raise it when the files or the columns' meaning change.
FORMAT = 1


def store_dir() -> Path | None:
    """The store's folder (``<cache folder>/camera_dr``), or ``None`` when the stores are off."""
    return cache_folder() / "camera_dr" if store_on() else None


@functools.cache
def versions() -> dict[str, str]:
    """What stored columns depend on besides their key: the bench_sim, Python, NumPy, SciPy and
    numba versions, :data:`FORMAT` and the fingerprint of the package's sources (all of them:
    the measurement runs through the sensor, DTDI, fusion, metrics and runtime layers).
    Computed once per process."""
    return {
        "bench_sim": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": package_version("scipy"),
        "numba": package_version("numba"),
        "format": str(FORMAT),
        "source": source_fingerprint((".",)),
    }


def _read(path: Path, meta: dict[str, Any]) -> dict[str, Any]:
    columns = meta["columns"]
    if not isinstance(columns, dict):
        raise ValueError("no columns")
    return columns


def load(key: str) -> dict[str, Any] | None:
    """The stored columns of ``key``, or ``None``: the store is off, has none, or the file
    cannot be read (then it is deleted). Never raises."""
    return read_entry(store_dir(), key, versions(), _read)


def save(key: str, columns: dict[str, Any]) -> None:
    """Store the columns of ``key``, then delete the least recently used files beyond the size
    bound. Nothing when the store is off; a write that fails is skipped (never raises)."""
    write_entry(store_dir(), key, versions(), {"columns": columns})
