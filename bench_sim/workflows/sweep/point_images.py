"""``keep_images = true`` in a sweep spec: each point's images in ``DIR/images/point_NNNNNN.zarr``.

The store is the point's pass as :func:`bench_sim.pipeline.run_pass` makes it (Zarr v3, read
with ``xarray.open_zarr``): the stage words ``dn`` of every stage the pass accumulated (the fused
pair, the spec's ``stages``, stage 1 when a light flickers), their truth (``mean_dn``,
``photons``, ``reflectance``, ``clipped``) and ``gamma_hdr`` / ``gamma_hdr_source``, with
``units`` and ``long_name`` on every variable and the point's resolved config, seed and version
as attributes (plus ``point``). The worker writes it into a temporary store beside it and
renames it into place, so a store that exists is whole; the sweep folder must be on a file
system the workers share (a local cluster, or a scheduler whose workers mount it).
"""

from __future__ import annotations

import os
import shutil
import warnings
from pathlib import Path
from typing import Any

from bench_sim.io.interrupts import deferred_interrupts

__all__ = ["IMAGES_DIR", "point_store", "write_point_images"]

#: folder of the point stores in the sweep folder
IMAGES_DIR = "images"


def point_store(images_dir: str | Path, index: int) -> Path:
    """The store of point ``index``."""
    return Path(images_dir) / f"point_{int(index):06d}.zarr"


def write_point_images(images_dir: str | Path, index: int, ds: Any) -> Path:
    """Write a point's pass dataset ``ds`` as its Zarr store (atomically: module docstring)."""
    final = point_store(images_dir, index)
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = final.with_name(f".{final.name}.partial-{os.getpid()}")
    shutil.rmtree(tmp, ignore_errors=True)
    out = ds.copy()
    out.attrs["point"] = int(index)
    try:
        # never cut by Ctrl-C: Zarr writes on its own thread (it would go on after tmp is removed)
        with warnings.catch_warnings(), deferred_interrupts():  # consolidated: a Zarr v3 extension
            warnings.filterwarnings("ignore", message="Consolidated metadata", category=UserWarning)
            out.to_zarr(tmp, mode="w", zarr_format=3, consolidated=True)
        shutil.rmtree(final, ignore_errors=True)
        os.replace(tmp, final)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return final
