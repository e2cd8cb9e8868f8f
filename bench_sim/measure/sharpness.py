"""Sharpness of a pass: the ISO 12233 e-SFR along and across the track of every stage image and
of ``Gamma_HDR``, from the slanted edges of the target.

The edges are found in the truth reflectance of the pass (:func:`bench_sim.metrics.edge_rois.
slanted_edge_rois`, on the smallest stage's ``reflectance``), so they are where the image has
them whatever the magnification, sync error or phase. Each ROI's e-SFR
(:func:`bench_sim.metrics.sfr.edge_sfr`) is measured on the noisy stage words ``dn`` (what a
camera gives), flat-fielded as a bench engineer would: the stage's offset
(:func:`bench_sim.sensor.model.stage_offset_dn`) subtracted and the result divided by the light
the pixels received, ``photons / reflectance`` of the truth (the e-SFR assumes a uniformly lit
edge; the spot's fall-off across a ROI would otherwise tilt the step). ``gamma_hdr`` (offsets
already removed) is divided by the light of stage ``mu2``. ROIs with clipped pixels
(``clipped``, more than 0.1 %) or that the e-SFR refuses are left out. The SFRs of the ROIs of
one direction are resampled onto :data:`SFR_FREQUENCY_CYC_PX` and averaged; the MTF50 is that
mean curve's.

Directions (rows of an image = lines = along the track): the **along-track** SFR comes from the
near-horizontal edges (their normal runs along the lines), the **across-track** SFR from the
near-vertical ones. Frequencies are in cycles per pixel of the image: per line along the track
(one line period of motion, ``1 + timing.sync_error`` sensor pixels) and per column across it.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.errors import BenchSimError
from bench_sim.metrics.edge_rois import EdgeROI, slanted_edge_rois
from bench_sim.metrics.sfr import edge_sfr, mtf50
from bench_sim.pipeline import Read
from bench_sim.sensor.model import stage_offset_dn

if TYPE_CHECKING:
    import xarray as xr

__all__ = ["SFR_FREQUENCY_CYC_PX", "DIRECTIONS", "DirectionSFR", "StageImage", "direction_sfr",
           "has_slanted_edges", "image_sharpness", "stage_images", "read_stage_images", "mean_curve",
           "add_sharpness", "PassSharpness", "pass_sharpness",
           "sharpness_summary", "sharpness_curves"]

#: common frequency grid of the averaged SFRs [cycles/pixel], 0 .. 1 in steps of 1/50
SFR_FREQUENCY_CYC_PX = np.linspace(0.0, 1.0, 51)
#: direction -> the edge orientation that measures it
DIRECTIONS = {"along": "horizontal", "across": "vertical"}
_CLIPPED_MAX_FRACTION = 1e-3


@dataclass(frozen=True)
class StageImage:
    """One image of a pass ready for the e-SFR (:func:`stage_images`): ``name`` (``stage_010``,
    ``gamma_hdr``), ``stage`` (``m``; ``None`` for ``gamma_hdr``), the flat-fielded ``image``
    (float64) and where it ``clipped`` (bool)."""

    name: str
    stage: int | None
    image: np.ndarray
    clipped: np.ndarray


@dataclass(frozen=True)
class DirectionSFR:
    """The mean e-SFR of one image's edges of one orientation: ``sfr`` on
    :data:`SFR_FREQUENCY_CYC_PX` (NaN without edges), its MTF50 [cycles/px] and the edges used."""

    sfr: np.ndarray
    mtf50_cyc_px: float
    edges: int


def has_slanted_edges(cfg: BenchConfig) -> bool:
    """Whether the bench's target carries slanted edges (``target.layout = "slanted_edges"``)."""
    return cfg.target.layout == "slanted_edges"


def direction_sfr(
    image: np.ndarray, rois: Sequence[EdgeROI], orientation: str, clipped: np.ndarray | None = None
) -> DirectionSFR:
    """Mean e-SFR of ``image`` over the ``rois`` of one ``orientation`` (module docstring)."""
    curves = []
    for e in rois:
        if e.orientation != orientation:
            continue
        x0, y0, x1, y1 = e.roi
        if clipped is not None and clipped[y0:y1, x0:x1].mean() > _CLIPPED_MAX_FRACTION:
            continue
        try:
            r = edge_sfr(image, e.roi)
        except BenchSimError:
            continue
        if r.orientation != orientation:
            continue
        curves.append(r)
    return mean_curve([(r.frequency_cyc_px, r.sfr) for r in curves])


def mean_curve(curves: Sequence[tuple[np.ndarray, np.ndarray]]) -> DirectionSFR:
    """The SFRs ``(frequency [cycles/px], sfr)`` resampled onto :data:`SFR_FREQUENCY_CYC_PX`
    and averaged, with the mean's MTF50 (NaN curve without any)."""
    if not curves:
        return DirectionSFR(np.full(SFR_FREQUENCY_CYC_PX.size, np.nan), float("nan"), 0)
    grid = [np.interp(SFR_FREQUENCY_CYC_PX, f, s, right=np.nan) for f, s in curves]
    mean = np.mean(grid, axis=0)
    return DirectionSFR(mean, mtf50(SFR_FREQUENCY_CYC_PX, mean), len(grid))


def image_sharpness(
    image: np.ndarray, rois: Sequence[EdgeROI], clipped: np.ndarray | None = None
) -> dict[str, DirectionSFR]:
    """``{"along": ..., "across": ...}``: the mean e-SFR of an image in both directions."""
    img = np.asarray(image, dtype=np.float64)
    return {d: direction_sfr(img, rois, o, clipped) for d, o in DIRECTIONS.items()}


def _dataset_reader(ds: xr.Dataset) -> Read:
    return lambda name, m: ds[name].values if m is None else ds[name].sel(stage=m).values


def _hdr_clipped(read: Read, stages: Sequence[int]) -> np.ndarray:
    """Where ``gamma_hdr`` is clipped: where the stage it came from is."""
    src = read("gamma_hdr_source", None)
    out = np.zeros(src.shape, dtype=bool)
    for m in np.unique(src):
        if int(m) in stages:
            sel = src == m
            out[sel] = read("clipped", int(m))[sel]
    return out


def _light(read: Read, m: int) -> np.ndarray:
    """The light stage ``m``'s pixels received, ``photons / reflectance`` (1 where unknown)."""
    ph = read("photons", m)
    refl = read("reflectance", m).astype(np.float64)
    light = np.divide(ph, refl, out=np.ones(ph.shape), where=refl > 0)
    return np.where(light > 0, light, 1.0)


def stage_images(ds: xr.Dataset, cfg: BenchConfig) -> list[StageImage]:
    """Every stage image of the pass ``ds`` of the bench ``cfg`` flat-fielded (the module
    docstring: offset removed, divided by the light), then ``gamma_hdr`` when fused; without the
    truth (``photons``, ``reflectance``) the light is taken as uniform."""
    has = {str(n) for n in ds.data_vars}
    return read_stage_images(_dataset_reader(ds), [int(v) for v in ds.stage.values], has, cfg)


def read_stage_images(read: Read, stages: Sequence[int], has: set[str], cfg: BenchConfig) -> list[StageImage]:
    """:func:`stage_images` of a pass's variables ``has`` (names) read by ``read``."""
    truth = "photons" in has and "reflectance" in has
    out = []
    for m in stages:
        light = _light(read, m) if truth else 1.0
        img = (read("dn", m) - stage_offset_dn(cfg.sensor, cfg.dtdi, m)) / light
        clip = read("clipped", m) if "clipped" in has else np.zeros(img.shape, dtype=bool)
        out.append(StageImage(f"stage_{m:03d}", m, img, clip))
    if "gamma_hdr" in has:
        hdr = read("gamma_hdr", None)
        light = _light(read, cfg.fusion.mu2) if truth else 1.0
        clip = _hdr_clipped(read, stages) if "clipped" in has else np.zeros(hdr.shape, dtype=bool)
        out.append(StageImage("gamma_hdr", None, hdr / light, clip))
    return out


@dataclass(frozen=True)
class PassSharpness:
    """:func:`pass_sharpness`: the stages' mean e-SFRs per direction (``stages`` in order) and,
    when fused, ``gamma_hdr``'s (``None`` otherwise); ``rois`` the edges found."""

    stages: list[int]
    per_stage: list[dict[str, DirectionSFR]]
    hdr: dict[str, DirectionSFR] | None
    rois: list[EdgeROI]


def pass_sharpness(
    read: Read, stages: Sequence[int], has: set[str], cfg: BenchConfig
) -> PassSharpness | None:
    """The e-SFR of every stage and of ``gamma_hdr`` in both directions (module docstring) of a
    pass's variables ``has`` read by ``read`` (a dataset's, or a :class:`~bench_sim.pipeline.PassResult`'s
    :meth:`~bench_sim.pipeline.PassResult.read` without one); ``None`` when its reflectance (of the
    first stage) holds no whole dark square."""
    rois = slanted_edge_rois(read("reflectance", stages[0]))
    if not rois:
        return None
    images = read_stage_images(read, stages, has, cfg)
    per_stage = [image_sharpness(s.image, rois, s.clipped) for s in images if s.stage is not None]
    hdr = image_sharpness(images[-1].image, rois, images[-1].clipped) if "gamma_hdr" in has else None
    return PassSharpness(list(stages), per_stage, hdr, list(rois))


def add_sharpness(ds: xr.Dataset, cfg: BenchConfig) -> xr.Dataset:
    """``ds`` (a pass's dataset with its truth, of the bench ``cfg``) with the e-SFR of every stage and of
    ``gamma_hdr`` in both directions added (:func:`pass_sharpness`); unchanged when its
    reflectance holds no whole dark square.

    Added: the coordinate ``sfr_frequency`` [cycles/px] and, for ``D`` in ``along``, ``across``,
    ``sfr_D`` (stage, sfr_frequency) [1], ``mtf50_D`` (stage) [cycles/px] and, when fused,
    ``gamma_hdr_sfr_D`` (sfr_frequency) and ``gamma_hdr_mtf50_D`` (scalar); the attribute
    ``sfr_edges`` lists the edge ROIs found (JSON: x0, y0, x1, y1, orientation).
    """
    import xarray as xr

    stages = [int(v) for v in ds.stage.values]
    got = pass_sharpness(_dataset_reader(ds), stages, {str(n) for n in ds.data_vars}, cfg)
    if got is None:
        return ds
    new: dict[str, xr.DataArray] = {}
    for d in DIRECTIONS:
        side = "lines (along the track)" if d == "along" else "columns (across the track)"
        new[f"sfr_{d}"] = xr.DataArray(
            np.stack([s[d].sfr for s in got.per_stage]), dims=("stage", "sfr_frequency"),
            attrs={"units": "1", "long_name": f"ISO 12233 e-SFR along the {side}, mean over the edges"})
        new[f"mtf50_{d}"] = xr.DataArray(
            np.array([s[d].mtf50_cyc_px for s in got.per_stage]), dims=("stage",),
            attrs={"units": "cycles/px", "long_name": f"MTF50 along the {side}"})
    if got.hdr is not None:
        for d in DIRECTIONS:
            new[f"gamma_hdr_sfr_{d}"] = xr.DataArray(
                got.hdr[d].sfr, dims=("sfr_frequency",),
                attrs={"units": "1", "long_name": f"e-SFR {d} the track of gamma_hdr, mean over the edges"})
            new[f"gamma_hdr_mtf50_{d}"] = xr.DataArray(
                got.hdr[d].mtf50_cyc_px,
                attrs={"units": "cycles/px", "long_name": f"MTF50 {d} the track of gamma_hdr"})
    out = ds.assign_coords(sfr_frequency=("sfr_frequency", SFR_FREQUENCY_CYC_PX, {"units": "cycles/px"}))
    out = out.assign(new)
    out.attrs["sfr_edges"] = json.dumps([[*e.roi, e.orientation] for e in got.rois])
    return out


def sharpness_summary(ds: xr.Dataset) -> dict[str, object]:
    """The MTF50s of :func:`add_sharpness` as plain JSON values (``{}`` when ``ds`` has none):
    ``{"mtf50_along_cyc_px": {stage: value}, "mtf50_across_cyc_px": ..., "gamma_hdr_...": value}``,
    ``None`` for NaN."""
    if "mtf50_along" not in ds:
        return {}

    def num(v: object) -> float | None:
        f = float(v)  # type: ignore[arg-type]
        return None if np.isnan(f) else f

    out: dict[str, object] = {}
    for d in DIRECTIONS:
        values = zip(ds.stage.values, ds[f"mtf50_{d}"].values, strict=True)
        out[f"mtf50_{d}_cyc_px"] = {str(int(m)): num(v) for m, v in values}
        if f"gamma_hdr_mtf50_{d}" in ds:
            out[f"gamma_hdr_mtf50_{d}_cyc_px"] = num(ds[f"gamma_hdr_mtf50_{d}"].values)
    return out


def sharpness_curves(ds: xr.Dataset) -> list[list[object]]:
    """The mean e-SFR curves of :func:`add_sharpness` as rows ``stage, direction,
    frequency_cyc_px, sfr`` (``stage`` = ``gamma_hdr`` for the fused image; ``None`` for NaN);
    ``[]`` when ``ds`` has none."""
    if "sfr_along" not in ds:
        return []
    f = ds["sfr_frequency"].values
    rows: list[list[object]] = []
    curves = [(str(int(m)), d, ds[f"sfr_{d}"].sel(stage=m).values)
              for m in ds.stage.values for d in DIRECTIONS]
    curves += [("gamma_hdr", d, ds[f"gamma_hdr_sfr_{d}"].values)
               for d in DIRECTIONS if f"gamma_hdr_sfr_{d}" in ds]
    for label, d, sfr in curves:
        rows += [[label, d, float(x), None if np.isnan(y) else float(y)] for x, y in zip(f, sfr, strict=True)]
    return rows
