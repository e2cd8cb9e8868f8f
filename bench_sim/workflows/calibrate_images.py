"""The image inputs of ``bench-sim calibrate``: a lab's raw frames, as one ``.npz`` file of stacks
(:mod:`bench_sim.io.frame_stacks`, what ``bench-sim ptc --area`` writes) or as a folder of image
files with a manifest, read into a :class:`~bench_sim.metrics.frame_series.FrameSeries`.

The folder form: ``frames.csv``, one row per image file (TIFF, PNG or NPY, relative to the
folder), columns ``file``, ``kind`` (``flat`` or ``dark``), ``exposure_s`` and optionally
``photons_per_pixel`` or ``relative_irradiance`` (flats), ``bits`` and ``wavelength_nm`` (one
value each). Flats of one exposure time and irradiation are one level (at least two images);
darks of one exposure time are one dark stack.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from bench_sim.errors import BenchSimError
from bench_sim.io import ImageReadError, image_file_problem, read_frames_npz, read_image
from bench_sim.metrics.frame_series import FrameSeries, LitLevel

__all__ = ["MANIFEST", "read_frames_file", "read_frames_folder"]

#: The manifest of a folder of images
MANIFEST = "frames.csv"
_KINDS = {"flat": "flat", "light": "flat", "bright": "flat", "dark": "dark"}


def _kind_of(names: set[str]) -> str:
    if "photons_per_pixel" in names:
        return "photons"
    if "relative_irradiance" in names:
        return "relative_irradiance"
    return "exposure"


def read_frames_file(path: Path) -> FrameSeries:
    """A frames ``.npz`` (:mod:`bench_sim.io.frame_stacks`) as a series."""
    arr = read_frames_npz(path)
    kind = _kind_of(set(arr))
    x = arr.get("photons_per_pixel", arr.get("relative_irradiance"))
    t = arr["exposure_s"].astype(np.float64)
    lit = tuple(
        LitLevel(float(t[i]), None if x is None else float(x[i]), arr["flats"][i]) for i in range(t.size)
    )
    dark: list[tuple[float, np.ndarray]] = []
    if "darks" in arr:
        dark += [(float(t[i]), arr["darks"][i]) for i in range(t.size)]
    if "dark_images" in arr:
        dark += [(float(te), st) for te, st in zip(arr["dark_exposure_s"], arr["dark_images"], strict=True)]
    bits = int(arr["bits"]) if "bits" in arr else None
    wl = float(arr["wavelength_nm"]) if "wavelength_nm" in arr else None
    return FrameSeries(
        lit=lit, dark=tuple(dark), irradiance_kind=kind, bits=bits, wavelength_nm=wl, source=str(path)
    )


def _number(path: Path, row: int, name: str, text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise BenchSimError(f"{path}: row {row}: {name} = {text!r} is not a number") from None
    if not math.isfinite(v) or v < 0:
        raise BenchSimError(f"{path}: row {row}: {name} = {text!r} must be a finite number >= 0")
    return v


def _read(folder: Path, name: str) -> np.ndarray:
    try:
        return read_image(folder / name)
    except ImageReadError as exc:
        raise BenchSimError(str(exc)) from None


def _one_value(path: Path, rows: list[dict[str, str]], name: str) -> float | None:
    vals = {r[name].strip() for r in rows if r.get(name, "").strip()}
    if not vals:
        return None
    if len(vals) > 1:
        raise BenchSimError(f"{path}: column {name}: expected one value, got {sorted(vals)}")
    return _number(path, 1, name, vals.pop())


def read_frames_folder(folder: Path) -> FrameSeries:
    """A folder of images with its ``frames.csv`` manifest (module docstring) as a series."""
    path = folder / MANIFEST
    try:
        rows = list(
            csv.DictReader(
                ln
                for ln in path.read_text(encoding="utf-8").splitlines()
                if ln.strip() and not ln.lstrip().startswith("#")
            )
        )
    except (OSError, UnicodeDecodeError) as exc:
        raise BenchSimError(f"{path}: cannot read the manifest ({exc.__class__.__name__})") from None
    names = set(rows[0]) if rows else set()
    missing = [c for c in ("file", "kind", "exposure_s") if c not in names]
    if missing:
        raise BenchSimError(
            f"{path}: missing column(s) {', '.join(missing)}; required: file, kind, exposure_s"
        )
    for r in rows:  # every file's header before any image is decoded
        problem = image_file_problem(folder / r["file"].strip())
        if problem is not None:
            raise BenchSimError(f"{folder / r['file'].strip()}: {problem}")
    xname = next((c for c in ("photons_per_pixel", "relative_irradiance") if c in names), None)
    flats: dict[tuple[float, float | None], list[np.ndarray]] = {}
    darks: dict[float, list[np.ndarray]] = {}
    for i, r in enumerate(rows, 1):
        kind = _KINDS.get(r["kind"].strip().lower())
        if kind is None:
            raise BenchSimError(f"{path}: row {i}: kind = {r['kind']!r}; allowed: flat, dark")
        t = _number(path, i, "exposure_s", r["exposure_s"])
        img = _read(folder, r["file"].strip())
        if kind == "dark":
            darks.setdefault(t, []).append(img)
        else:
            x = _number(path, i, xname, r[xname]) if xname else None
            flats.setdefault((t, x), []).append(img)
    lit = tuple(
        LitLevel(t, x, np.stack(v))
        for (t, x), v in sorted(
            flats.items(), key=lambda kv: (kv[0][1] if kv[0][1] is not None else 0.0, kv[0][0])
        )
    )
    bits = _one_value(path, rows, "bits")
    return FrameSeries(
        lit=lit,
        dark=tuple((t, np.stack(v)) for t, v in sorted(darks.items())),
        irradiance_kind=_kind_of(names),
        bits=None if bits is None else int(bits),
        wavelength_nm=_one_value(path, rows, "wavelength_nm"),
        source=str(path),
    )
