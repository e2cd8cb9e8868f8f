"""EMVA 1288 R4 of the area sensor itself: raw frames of a window of the physical sensor through
its whole chain of effects, analysed as a lab analyses a camera, against the chain's closed forms.

``bench-sim ptc --area`` (:func:`bench_sim.workflows.ptc_job.run_area_ptc`) runs
:func:`plan_area` -> :func:`measure_area` -> :func:`analyse_area`. A DTDI stage image cannot
show what this shows: every line of a stage sums the same pixels of its column, so its fixed
pattern is a column pattern (no pixel positions, no row noise).

Measurement
-----------
One physical sensor (:func:`bench_sim.sensor.emva.draw_fixed_pattern`, its top-left ``rows x
columns`` window); raw frames from :func:`bench_sim.sensor.emva.expose`, every effect of the
chain included:

* an illumination series at the config's integration time ``t_int``: ``levels`` uniform fields
  equally spaced from 2 % to 120 % of the pixel's saturation (EMVA 1288's equal steps, past the
  clip), ``images`` frames each;
* a dark series: ``dark_images`` dark frames at each of ``dark_exposures`` exposure times from
  ``t_int`` to ``t_long`` (:func:`dark_series_long_s`: long enough that the dark current's
  non-uniformity stands three read noises above the reads, short enough that the mean dark signal
  stays below a quarter of saturation), so that the offset pattern at 0 s and the dark current's
  non-uniformity come apart, the defect pixels show, and the row noise is measured.

Random streams: one ``SeedSequence`` of the seed, spawned into one child for the fixed pattern and
one per level and dark exposure, so every level's frames are independent of the others.

Analysis: :func:`bench_sim.metrics.frame_series.analyse_frames` (the estimator ``calibrate``
runs on a lab's images). Prediction: :func:`bench_sim.sensor.emva_terms.sensor_emva_terms` of the
window (every effect's ``emva()`` and the default chain's drawn maps; the LE of the chain's exact
mean response on the same levels). :func:`compare_area` puts each measured quantity beside its
prediction with the estimator's stated standard error.

References
----------
EMVA Standard 1288, Release 4.0 Linear (2021), sections 6 (photon transfer, linearity) and 8
(non-uniformity, defect pixels).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.errors import BenchSimError
from bench_sim.metrics.frame_series import FrameAnalysis, FrameSeries, LitLevel, analyse_frames
from bench_sim.sensor.effects.base import EmvaTerm
from bench_sim.sensor.effects.defects import KINDS
from bench_sim.sensor.emva import FixedPattern, draw_fixed_pattern, expose
from bench_sim.sensor.emva_terms import sensor_emva_terms
from bench_sim.sensor.model import QUANTIZATION_VAR_DN2

__all__ = [
    "AreaPlan",
    "AreaFrames",
    "plan_area",
    "measure_area",
    "analyse_area",
    "compare_area",
    "dark_series_long_s",
]

#: The illumination series, as fractions of the pixel's saturation
LEVELS_FROM, LEVELS_TO = 0.02, 1.2


@dataclass(frozen=True)
class AreaPlan:
    """What :func:`measure_area` exposes: the window (``rows`` x ``columns``), the lit levels
    (mean photons per pixel per frame at ``t_int_s``) with ``images`` frames each, the dark
    exposure times [s] with ``dark_images`` frames each."""

    rows: int
    columns: int
    t_int_s: float
    photons: np.ndarray = field(repr=False)
    images: int
    dark_exposure_s: np.ndarray = field(repr=False)
    dark_images: int


@dataclass(frozen=True)
class AreaFrames:
    """The frames of a plan: ``flats`` (levels, images, M, N) and ``darks`` (exposures, images,
    M, N) [DN], and the physical sensor's window ``fixed``."""

    flats: np.ndarray = field(repr=False)
    darks: np.ndarray = field(repr=False)
    fixed: FixedPattern = field(repr=False)


def dark_series_long_s(cfg: BenchConfig) -> float:
    """The dark series' longest exposure [s] (module docstring), at least ``10 t_int``."""
    s, t = cfg.sensor, cfg.timing.t_int_s
    noise_e = math.sqrt(
        (s.read_noise_e if s.read_noise else 0.0) ** 2 + QUANTIZATION_VAR_DN2 / s.conversion_gain_dn_per_e**2
    )
    t_nu = 3.0 * noise_e / max(s.dsnu_e_s, 1e-9)
    t_sat = 0.25 * s.pixel_saturation_electrons / max(s.dark_current_e_s + 5.0 * s.dsnu_e_s, 1e-9)
    return max(min(t_nu, t_sat), 10.0 * t)


def plan_area(
    cfg: BenchConfig,
    *,
    rows: int = 64,
    columns: int = 128,
    levels: int = 40,
    images: int = 2,
    dark_exposures: int = 8,
    dark_images: int = 8,
) -> AreaPlan:
    """Validate and place the levels (module docstring). Raises :class:`BenchSimError`."""
    s = cfg.sensor
    if not (2 <= rows <= s.rows and 2 <= columns <= s.columns):
        raise BenchSimError(f"area window {rows} x {columns}: must lie in 2..{s.rows} x 2..{s.columns}")
    if levels < 30 or images < 2 or dark_exposures < 3 or dark_images < 2:
        raise BenchSimError(
            f"area plan: levels = {levels}, images = {images}, dark_exposures = {dark_exposures}, "
            f"dark_images = {dark_images}: EMVA 1288 needs >= 30 levels, >= 2 images each, and a dark "
            "series of >= 3 exposure times"
        )
    sat_photons = s.pixel_saturation_electrons / s.quantum_efficiency
    t = cfg.timing.t_int_s
    return AreaPlan(
        rows=rows,
        columns=columns,
        t_int_s=t,
        photons=np.linspace(LEVELS_FROM, LEVELS_TO, levels) * sat_photons,
        images=images,
        dark_exposure_s=np.linspace(t, dark_series_long_s(cfg), dark_exposures),
        dark_images=dark_images,
    )


def measure_area(cfg: BenchConfig, plan: AreaPlan, seed: int) -> AreaFrames:
    """Expose the plan through the sensor's chain (module docstring)."""
    n_lit, n_dark = plan.photons.size, plan.dark_exposure_s.size
    streams = np.random.SeedSequence(int(seed)).spawn(1 + n_lit + n_dark)
    fixed = draw_fixed_pattern(cfg.sensor, np.random.default_rng(streams[0])).window(plan.rows, plan.columns)
    shape = (plan.rows, plan.columns)
    flats = np.empty((n_lit, plan.images, *shape), dtype=np.uint16 if cfg.sensor.quantization else np.float64)
    darks = np.empty((n_dark, plan.dark_images, *shape), dtype=flats.dtype)
    for i, p in enumerate(plan.photons):
        frames = np.full((plan.images, *shape), float(p))
        flats[i] = expose(frames, cfg.sensor, fixed, plan.t_int_s, np.random.default_rng(streams[1 + i]))
    for j, t in enumerate(plan.dark_exposure_s):
        frames = np.zeros((plan.dark_images, *shape))
        darks[j] = expose(frames, cfg.sensor, fixed, float(t), np.random.default_rng(streams[1 + n_lit + j]))
    return AreaFrames(flats=flats, darks=darks, fixed=fixed)


def area_series(cfg: BenchConfig, plan: AreaPlan, frames: AreaFrames) -> FrameSeries:
    """The frames as the series :func:`~bench_sim.metrics.frame_series.analyse_frames` reads."""
    lit = tuple(LitLevel(plan.t_int_s, float(p), frames.flats[i]) for i, p in enumerate(plan.photons))
    dark = tuple((float(t), frames.darks[j]) for j, t in enumerate(plan.dark_exposure_s))
    return FrameSeries(
        lit=lit,
        dark=dark,
        irradiance_kind="photons",
        bits=cfg.sensor.adc_bits,
        wavelength_nm=cfg.sensor.wavelength_m * 1e9,
        source="ptc --area",
    )


def analyse_area(
    cfg: BenchConfig, plan: AreaPlan, frames: AreaFrames
) -> tuple[FrameAnalysis, dict[str, EmvaTerm]]:
    """The measurement (:func:`~bench_sim.metrics.frame_series.analyse_frames`) and the closed
    forms of the same window on the same levels (:func:`~bench_sim.sensor.emva_terms.sensor_emva_terms`)."""
    measured = analyse_frames(area_series(cfg, plan, frames))
    predicted = sensor_emva_terms(cfg.sensor, frames.fixed, plan.t_int_s, photons=plan.photons)
    return measured, predicted


def _row(name: str, value: float, se: float, predicted: float, unit: str) -> dict[str, Any]:
    z = (value - predicted) / se if se > 0 and math.isfinite(se) else math.nan
    return {
        "quantity": name,
        "measured": value,
        "standard_error": se,
        "predicted": predicted,
        "unit": unit,
        "z": z,
    }


def compare_area(measured: FrameAnalysis, predicted: dict[str, EmvaTerm]) -> dict[str, Any]:
    """Each quantity measured beside its closed form, with the estimator's standard error and the
    z-score; the defect pixels by kind (counts and whether the positions agree)."""

    def pred(name: str) -> float:
        return predicted[name].value if name in predicted else 0.0

    f, split = measured.fit, measured.dsnu_split
    rows = [
        _row(
            "linearity_error_percent",
            f.linearity_error_percent,
            f.linearity_error_se_percent,
            pred("linearity_error_percent"),
            "%",
        ),
        _row("K_dn_per_e", f.k_dn_per_e, f.k_se, pred("K_dn_per_e"), "DN/e-"),
        _row(
            "quantum_efficiency",
            f.quantum_efficiency,
            f.quantum_efficiency_se,
            pred("quantum_efficiency"),
            "1",
        ),
    ]
    if split is not None:
        d0, nu = split["dsnu0_e"], split["dark_current_nu_e_s"]
        rows += [
            _row("dsnu0_e (pixel part)", d0["pixel_e"], d0["pixel_se_e"], pred("dsnu0_e"), "e-"),
            _row("dsnu0_column_e", d0["column_e"], d0["column_se_e"], pred("dsnu0_column_e"), "e-"),
            _row(
                "dark_current_nu_e_s",
                nu["total_e_s"],
                nu["total_se_e_s"],
                pred("dark_current_nu_e_s"),
                "e-/s",
            ),
        ]
    if measured.row_noise is not None:
        rn = measured.row_noise
        rows.append(_row("row_noise_var_dn2", rn.var_dn2, rn.var_se_dn2, pred("row_noise_var_dn2"), "DN^2"))
    defects = {}
    for kind in KINDS:
        want = predicted.get(f"{kind}_pixels")
        found = measured.defects.positions(kind)
        defects[kind] = {
            "measured": len(found),
            "predicted": None if want is None else int(want.value),
            "positions_agree": None if want is None else sorted(found) == sorted(want.positions),
        }
    return {"quantities": rows, "defect_pixels": defects}
