"""The on-disk store of the run texture's blocks: the target rasterised on a run's grid and, through
a lens, blurred (:mod:`bench_sim.render.texture`, :mod:`bench_sim.render.lens_blur`), one file
per block of :data:`bench_sim.render.texture.BLOCK_ROWS` rows, shared by the processes of this
machine, so a later run over the same grid (the same command again, every point of a sweep that
changes the lights, the sensor, DTDI or fusion, on any Dask worker) reads the blocks instead of
rasterising and blurring them again (3-4 s of CPU for the default ``reproduce``).

Where
    ``<cache folder>/textures/`` beside the light records' folder
    (:mod:`bench_sim.render.record_store`); ``rm -rf`` clears it.
Switch and size
    The light records' own: ``BENCH_SIM_RECORD_CACHE=off`` turns both stores off (the test suite
    runs so); ``BENCH_SIM_RECORD_CACHE_MIB`` bounds this folder too (the least recently used
    files deleted after each write).
Files
    ``<sha256>.npz`` (uncompressed): the hash of the block's key (everything the block depends
    on: the target, the grid, the lens, the block's index; :attr:`bench_sim.render.texture.
    RunTexture.store_key`) and :func:`versions` (bench_sim, numpy and scipy versions,
    :data:`FORMAT` and a fingerprint of the sources that make the blocks). A file holds the block
    ``values`` (float32, as made: the same bytes) and ``meta`` (the key and the versions as JSON),
    checked on load with the block's shape. A block loaded is a read-only memory map of its file
    (:func:`bench_sim.render.record_store.mapped_arrays`: no copy, no checksum of the zip member).
Failures
    Never fails a run: a file that cannot be read is a miss (and is deleted), a write that fails
    is skipped; files are written under a temporary name and renamed into place.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.render import record_store
from bench_sim.runtime.backend import cache_folder
from bench_sim.version import __version__

__all__ = ["FORMAT", "store_dir", "versions", "load", "save"]

#: Version of the file layout; raise it when the files or the blocks' meaning change.
FORMAT = 1
#: The sources that make a block (relative to the package).
_SOURCES = ("render/texture.py", "render/lens_blur.py", "rig")


def store_dir() -> Path | None:
    """The store's folder (``<cache folder>/textures``), or ``None`` when the stores are off."""
    return cache_folder() / "textures" if record_store.store_on() else None


@functools.cache
def versions() -> dict[str, str]:
    """What a stored block depends on besides its key (computed once per process)."""
    return {
        "bench_sim": __version__,
        "numpy": np.__version__,
        "scipy": record_store.package_version("scipy"),
        "format": str(FORMAT),
        "source": record_store.source_fingerprint(_SOURCES),
    }


def _read(path: Path, meta: dict[str, Any], shape: tuple[int, int]) -> np.ndarray:
    values = record_store.mapped_arrays(path, ("values",))["values"]  # a map of the file, no copy
    if set(meta) != {"key", "versions"} or values.dtype != np.float32 or values.shape != shape:
        raise ValueError("another block")
    return values


def load(key: str, shape: tuple[int, int]) -> np.ndarray | None:
    """The stored block of ``key`` (float32 of ``shape``), or ``None``: the store is off, has no
    such block, or its file cannot be read (then it is deleted). Never raises."""
    return record_store.read_entry(store_dir(), key, versions(), lambda path, meta: _read(path, meta, shape))


def save(key: str, values: np.ndarray) -> None:
    """Store the block ``values`` of ``key``, then delete the least recently used files beyond the
    size bound. Does nothing when the store is off; a write that fails is skipped."""
    record_store.write_entry(store_dir(), key, versions(), {}, lambda: {"values": values})
