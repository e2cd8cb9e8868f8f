"""``simulate``'s Zarr store, written block by block while the pass runs (flat memory).

:class:`ZarrPassSink` is the :class:`bench_sim.sensor.pass_lines.PassSink` of
:func:`bench_sim.pipeline.run_pass` that ``bench-sim simulate --format zarr`` streams into. It first
creates the whole store -- the dataset's schema exactly as :func:`bench_sim.pipeline.run_pass`'s
:class:`xarray.Dataset` would be written by ``simulate`` (:func:`bench_sim.pipeline.stored_dataset`:
dimensions, stored dtypes, chunks, units and long names, the coordinates, the config, seed and
version attributes, consolidated metadata) -- with no data, then receives every variable's completed
lines and writes each row of chunks (all stages, the chunk's lines, all columns) as soon as all its
lines are in, every chunk once, whole. The rows in flight (the lines of about ``max(stages)`` plus a
band of the truth, rounded out to the store's chunks) wait in raw
files beside the store, not in memory: memory holds one block of lines and, while a row is written,
one chunk's stages of it, whatever the number of lines. The store's bytes equal those of the
in-memory dataset written at the end (the same values into the same chunks).
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.io.interrupts import deferred_interrupts
from bench_sim.pipeline import (
    COORD_ATTRS,
    VARIABLES_BY_NAME,
    pass_attrs,
    pass_coords,
    pass_dtypes,
    store_chunks,
    variable_attrs,
)
from bench_sim.render.exposures import RenderSetup

if TYPE_CHECKING:
    import xarray as xr

__all__ = ["ZarrPassSink"]

#: folder beside the store that holds the rows of chunks in flight (removed when the pass ends)
_SPILL_DIR = ".simulate_rows"


def _template(
    cfg: BenchConfig, st: tuple[int, ...], seed: int, setup: RenderSetup, truth: bool
) -> xr.Dataset:
    """The pass's dataset with lazy (never computed) variables in Zarr's own chunks."""
    import dask.array as da
    import xarray as xr

    stage_dt, image_dt = pass_dtypes(cfg, st, truth=truth)
    lines, cols = cfg.lines, cfg.sensor.columns
    data: dict[str, Any] = {}
    for name in {**stage_dt, **image_dt}:
        var = VARIABLES_BY_NAME[name]
        shape = (len(st), lines, cols) if name in stage_dt else (lines, cols)
        dt = var.stored_dtype(cfg.dtdi.beta_bits)
        data[name] = (var.dims, da.empty(shape, dtype=dt, chunks=store_chunks(var.dims, shape)))
    order = [v.name for v in VARIABLES_BY_NAME.values() if v.name in data]
    ds = xr.Dataset({n: data[n] for n in order}, coords=pass_coords(cfg, st))
    for key, v in ds.data_vars.items():
        v.attrs.update(variable_attrs(cfg, str(key)))
    for coord, attrs in COORD_ATTRS.items():
        ds[coord].attrs.update(attrs)
    ds.attrs.update(pass_attrs(cfg, seed, setup, fused=bool(image_dt)))
    return ds


class ZarrPassSink:
    """Streams a pass into a new Zarr v3 store at ``path`` (see the module docstring).

    Parameters
    ----------
    path
        The store's folder (must not exist).
    cfg, st, seed, setup
        The pass: config, stages, root seed and render set-up (its engine, variant, frames).
    truth
        Whether the pass computes the truth variables.
    """

    def __init__(
        self, path: Path, cfg: BenchConfig, st: tuple[int, ...], seed: int, setup: RenderSetup, *,
        truth: bool,
    ) -> None:
        import zarr

        ds = _template(cfg, st, seed, setup, truth)
        # Zarr writes on its own thread: a write cut by Ctrl-C would go on there after the output
        # set's temporary folder is removed, and make its folders again; so no write is cut
        with warnings.catch_warnings(), deferred_interrupts():  # consolidated: a Zarr v3 extension
            warnings.filterwarnings("ignore", message="Consolidated metadata", category=UserWarning)
            ds.to_zarr(path, mode="w-", zarr_format=3, consolidated=True, compute=False)
        self.stages = {int(m): s for s, m in enumerate(st)}
        self.lines = cfg.lines
        self.arrays = {str(n): zarr.open_array(Path(path) / str(n), mode="r+") for n in ds.data_vars}
        #: rows of chunks in flight: spilled to raw files in this folder, one per variable and row
        self.spill = Path(path).parent / _SPILL_DIR
        self.spill.mkdir()
        #: name -> row of chunks -> lines filled per stage
        self.rows: dict[str, dict[int, np.ndarray]] = {n: {} for n in self.arrays}

    def write(self, name: str, stage: int | None, line0: int, block: np.ndarray) -> None:
        """Lines ``line0 ..`` of ``name`` (of ``stage``, or an image variable); a row of chunks is
        written once all its lines of every stage are in."""
        arr = self.arrays[name]
        stage_axis = stage is not None
        n_stages = arr.shape[0] if stage_axis else 1
        step = arr.chunks[1 if stage_axis else 0]
        s = self.stages[int(stage)] if stage is not None else 0
        j, end = int(line0), int(line0) + len(block)
        while j < end:
            row = j // step
            r0, r1 = row * step, min((row + 1) * step, self.lines)
            stop = min(end, r1)
            filled = self.rows[name].setdefault(row, np.zeros(n_stages, dtype=np.int64))
            part = np.ascontiguousarray(block[j - line0 : stop - line0], dtype=arr.dtype)
            fd = os.open(self._file(name, row), os.O_WRONLY | os.O_CREAT, 0o644)  # not O_APPEND: pwrite
            try:
                os.pwrite(fd, part.tobytes(), (s * (r1 - r0) + j - r0) * arr.shape[-1] * part.itemsize)
            finally:
                os.close(fd)
            filled[s] += stop - j
            if filled.min() == r1 - r0:
                self._write_row(name, row, r0, r1)
            j = stop

    def _file(self, name: str, row: int) -> Path:
        return self.spill / f"{name}.{row}"

    def _write_row(self, name: str, row: int, r0: int, r1: int) -> None:
        """Row ``row`` of chunks (lines ``r0 .. r1 - 1``) from its file into the store, a block of
        stages (one chunk's) at a time, then drop the file."""
        arr, path = self.arrays[name], self._file(name, row)
        per_stage = (r1 - r0) * arr.shape[-1]
        with deferred_interrupts():  # never cut (see __init__)
            self._write_chunks(arr, path, per_stage, r0, r1)
        path.unlink()
        del self.rows[name][row]

    @staticmethod
    def _write_chunks(arr: Any, path: Path, per_stage: int, r0: int, r1: int) -> None:
        if arr.ndim == 2:
            arr[r0:r1] = np.fromfile(path, dtype=arr.dtype).reshape(r1 - r0, -1)
        else:
            for s0 in range(0, arr.shape[0], arr.chunks[0]):
                s1 = min(s0 + arr.chunks[0], arr.shape[0])
                block = np.fromfile(path, dtype=arr.dtype, count=(s1 - s0) * per_stage,
                                    offset=s0 * per_stage * arr.dtype.itemsize)
                arr[s0:s1, r0:r1] = block.reshape(s1 - s0, r1 - r0, -1)

    def close(self) -> None:
        """Check that every row of chunks was written; remove the spill folder."""
        left = {n: sorted(rows) for n, rows in self.rows.items() if rows}
        if left:
            raise RuntimeError(f"simulate: Zarr rows of chunks never completed: {left}")
        self.spill.rmdir()
