"""Stacks of raw frames of an EMVA 1288 measurement in one ``.npz`` file: what ``bench-sim ptc
--area`` writes and ``bench-sim calibrate`` reads (a lab's images in the same form).

Arrays (``S`` lit levels, ``L`` images per level, ``M x N`` pixels; images in DN, any integer or
float dtype):

``exposure_s`` (S,)
    exposure time of each lit level [s], never decreasing;
``photons_per_pixel`` (S,) or ``relative_irradiance`` (S,), optional
    mean photons per pixel during the exposure (a photon calibration), or an irradiation in any
    unit (the response's abscissa; no quantum efficiency); neither: the exposure time is the
    abscissa (an exposure-time series at constant irradiance);
``flats`` (S, L, M, N)
    the lit images, ``L >= 2`` (two: an EMVA 1288 pair; more: a stack);
``darks`` (S, L, M, N), optional
    dark images at each lit level's exposure time;
``dark_exposure_s`` (D,) and ``dark_images`` (D, L, M, N), optional
    further dark stacks (a dark series at other exposure times);
``bits``, ``wavelength_nm`` (scalars), optional
    the ADC's bits, the light's wavelength [nm];
``metadata`` (a JSON string), optional
    provenance.

At least one of ``darks`` and ``dark_images`` is needed.
"""

from __future__ import annotations

import os
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.errors import BenchSimError
from bench_sim.io.atomic import atomic_path
from bench_sim.io.image_header import MAX_IMAGE_PIXELS
from bench_sim.io.strict_json import strict_dumps

__all__ = ["FRAME_ARRAYS", "write_frames_npz", "read_frames_npz"]

#: The arrays of a frames file and their dimensions
FRAME_ARRAYS = {
    "exposure_s": 1,
    "photons_per_pixel": 1,
    "relative_irradiance": 1,
    "flats": 4,
    "darks": 4,
    "dark_exposure_s": 1,
    "dark_images": 4,
    "bits": 0,
    "wavelength_nm": 0,
}


def write_frames_npz(
    path: str | os.PathLike[str], arrays: Mapping[str, Any], metadata: Mapping[str, Any] | None = None
) -> Path:
    """Write a frames file (module docstring), atomically; ``metadata`` as its JSON string."""
    unknown = set(arrays) - set(FRAME_ARRAYS)
    if unknown:
        raise BenchSimError(f"frames file: unknown arrays {sorted(unknown)}; allowed {sorted(FRAME_ARRAYS)}")
    data = {k: np.asarray(v) for k, v in arrays.items()}
    if metadata is not None:
        data["metadata"] = np.asarray(strict_dumps(dict(metadata)))
    p = Path(path)
    with atomic_path(p) as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **data)  # type: ignore[arg-type]
    return p


def _array(path: Path, data: Any, name: str) -> np.ndarray | None:
    if name not in data.files:
        return None
    arr = np.asarray(data[name])
    if arr.ndim != FRAME_ARRAYS[name]:
        raise BenchSimError(
            f"{path}: array {name!r} has {arr.ndim} dimensions, expected {FRAME_ARRAYS[name]}"
        )
    if arr.dtype.kind not in "fiu" or not np.all(np.isfinite(arr)):
        raise BenchSimError(f"{path}: array {name!r} must hold finite numbers")
    return arr


def _member_shapes(path: Path) -> dict[str, tuple[int, ...]]:
    """The shape of every array of an ``.npz`` from its ``.npy`` headers alone (no array read)."""
    shapes: dict[str, tuple[int, ...]] = {}
    with zipfile.ZipFile(path) as zf:
        for info in zf.infolist():
            if not info.filename.endswith(".npy"):
                continue
            with zf.open(info) as f:
                version = np.lib.format.read_magic(f)
                read = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                        else np.lib.format.read_array_header_2_0)
                shape, _, _ = read(f)
            shapes[info.filename[: -len(".npy")]] = tuple(int(n) for n in shape)
    return shapes


def _check_sizes(p: Path) -> None:
    """Refuse, from the arrays' headers and before any is read, empty images and a file whose
    arrays claim more than :data:`~bench_sim.io.image_header.MAX_IMAGE_PIXELS` values (a damaged
    or hostile file: its arrays would be allocated as the headers say)."""
    try:
        shapes = _member_shapes(p)
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        detail = " ".join(str(exc).split())[:120] or exc.__class__.__name__
        raise BenchSimError(f"{p}: not a readable .npz frames file ({detail})") from None
    for name, shape in shapes.items():
        if FRAME_ARRAYS.get(name) == 4 and len(shape) == 4 and 0 in shape[2:]:
            raise BenchSimError(f"{p}: array {name!r} holds empty images ({shape[3]} x {shape[2]} pixels)")
    total = sum(int(np.prod(s, dtype=object)) for s in shapes.values())
    if total > MAX_IMAGE_PIXELS:
        raise BenchSimError(
            f"{p}: its arrays' headers claim {total} values: more than {MAX_IMAGE_PIXELS} "
            "(a damaged or hostile file?)"
        )


def read_frames_npz(path: str | os.PathLike[str]) -> dict[str, np.ndarray]:
    """Read and check a frames file: its arrays by name (module docstring), shapes consistent.

    Raises
    ------
    BenchSimError
        Not a readable ``.npz``, empty images or more values than
        :data:`~bench_sim.io.image_header.MAX_IMAGE_PIXELS` by the arrays' headers (before any
        is read), a missing ``exposure_s`` or ``flats``, no dark images, an array of the wrong
        dimensions or length, images of another size, fewer than two per level.
    """
    p = Path(path)
    _check_sizes(p)
    try:
        data = np.load(p, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise BenchSimError(f"{p}: not a readable .npz frames file ({exc.__class__.__name__})") from None
    with data:
        out = {name: a for name in FRAME_ARRAYS if (a := _array(p, data, name)) is not None}
    for need in ("exposure_s", "flats"):
        if need not in out:
            raise BenchSimError(f"{p}: missing array {need!r}; a frames file needs exposure_s and flats")
    if "darks" not in out and "dark_images" not in out:
        raise BenchSimError(f"{p}: no dark images: give 'darks' (at each level's exposure) or 'dark_images'")
    s, lf, m, n = out["flats"].shape
    for name in ("exposure_s", "photons_per_pixel", "relative_irradiance"):
        if name in out and out[name].size != s:
            raise BenchSimError(f"{p}: {name!r} has {out[name].size} values for {s} lit levels")
    for name in ("darks", "dark_images"):
        if name in out and (out[name].shape[2:] != (m, n) or out[name].shape[1] < 2):
            raise BenchSimError(
                f"{p}: {name!r} of shape {out[name].shape}: needs >= 2 images of {m} x {n} pixels per level"
            )
    if "darks" in out and out["darks"].shape[0] != s:
        raise BenchSimError(f"{p}: 'darks' holds {out['darks'].shape[0]} levels for {s} lit levels")
    if "dark_images" in out and out.get("dark_exposure_s", np.empty(0)).size != out["dark_images"].shape[0]:
        raise BenchSimError(f"{p}: 'dark_images' needs 'dark_exposure_s', one time per stack")
    if lf < 2:
        raise BenchSimError(f"{p}: 'flats' holds {lf} image per level; EMVA 1288 needs at least 2")
    return out
