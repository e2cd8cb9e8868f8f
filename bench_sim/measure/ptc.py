"""Photon-transfer measurement (EMVA 1288 R4) of DTDI stages, through the real sensor + DTDI code.

The measurement in three steps: :func:`plan_ptc` (validate, place the levels) ->
:func:`measure_ptc` (expose) -> :func:`analyse_ptc` (EMVA 1288 analysis). The command
``bench-sim ptc`` (:func:`bench_sim.workflows.ptc_job.run_ptc`) runs them and writes the files.

Measurement
-----------
The uniform-field runner (:mod:`bench_sim.measure.uniform_field`) exposes a uniform field
of ``mu_p`` photons per pixel per frame through the EMVA 1288 pixel model and the streaming DTDI
accumulator, with the config's sensor, timing and DTDI settings. One pass of
``K = 2 L + max(stages) - 1`` frames over the top-left ``max(stages)`` rows x ``C`` columns gives,
for every requested stage, an image pair of ``L`` lines each. The default image is ``L = 64``
lines x ``C = 256`` columns (or the sensor's width if smaller).

Levels (mean photons per pixel per frame): a dark level, ``log_levels`` log-spaced levels from
well below SNR = 1 of the highest stage to 1.5 x the saturation of the lowest stage, plus
``dense_levels`` levels from 0.90 to 1.02 x the predicted saturation of every requested stage
(:mod:`bench_sim.sensor.model`; it only places the levels, the analysis uses the images).
Every stage sees every level. For stage ``m`` the descriptor's photon count is the mean number
of photons per pixel summed over the ``m`` frames that make the stage value (``m * mu_p``) and
its exposure time is ``m * t_int``.

Spatial stacks (DSNU, PRNU): ``spatial_images`` (16) images in the dark and at 50 % of each
stage's predicted saturation. In a DTDI stage every line sums the same ``m`` pixels of its
column, so the fixed pattern is a column pattern; the expected values are
:func:`bench_sim.sensor.model.stage_dsnu_dn` and :func:`bench_sim.sensor.model.stage_prnu`.

Pedestal: the one rule of the uniform-field runner
(:func:`bench_sim.measure.uniform_field.measurement_pedestal_dn`): the configured
``dtdi.pedestal_dn`` (64 DN by default), raised where needed to keep every measured stage's
dark value 5 sigma above 0 DN. It lowers the usable range of the word by the offset (reported).

References
----------
EMVA Standard 1288, Release 4.0 Linear (2021): sections 2 (model), 6 (photon transfer),
8 (spatial nonuniformity); the descriptor file format of the EMVA 1288 reference software.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.errors import BenchSimError
from bench_sim.measure.uniform_field import (
    expose_uniform,
    measurement_offsets_dn,
    measurement_pedestal_dn,
)
from bench_sim.metrics.emva1288 import (
    PhotonTransferResult,
    analyse_photon_transfer,
    dynamic_range_from_series,
    mean_var_from_pair,
    snr_curve,
    spatial_nonuniformity,
)
from bench_sim.sensor.dtdi import validate_stages
from bench_sim.sensor.emva import draw_fixed_pattern
from bench_sim.sensor.model import (
    QUANTIZATION_VAR_DN2,
    dark_noise_e,
    stage_dsnu_dn,
    stage_mean_var_dn,
    stage_prnu,
    stage_saturation_photons,
    stage_snr1_photons,
)

__all__ = [
    "PtcPlan",
    "PtcImages",
    "StageResult",
    "plan_ptc",
    "measure_ptc",
    "analyse_ptc",
    "stage_quantization_var_dn2",
    "DEFAULT_LINES",
    "DEFAULT_COLUMNS",
    "DEFAULT_LOG_LEVELS",
    "DEFAULT_DENSE_LEVELS",
    "DEFAULT_SPATIAL_IMAGES",
]

DEFAULT_LINES = 64
DEFAULT_COLUMNS = 256
DEFAULT_LOG_LEVELS = 32
DEFAULT_DENSE_LEVELS = 13
DEFAULT_SPATIAL_IMAGES = 16
#: Dense levels near each stage's predicted saturation, as fractions of it (the variance peaks
#: a few per cent below the clip; 13 levels give 1 % steps).
DENSE_FROM, DENSE_TO = 0.90, 1.02
#: EMVA 1288 image files hold 16-bit images: the measurement refuses a wider word.
MAX_FILE_BITS = 16


@dataclass(frozen=True)
class PtcPlan:
    """What :func:`measure_ptc` exposes.

    Attributes
    ----------
    stages
        Stages measured (sorted).
    lines, columns
        Image size ``L x C``.
    levels
        Lit levels [mean photons per pixel per frame], increasing (the dark level is extra).
    pedestal_dn
        Word pedestal of the measurement [DN].
    offsets_dn
        Offset every stage's image carries (pedestal, plus ``m b`` with ``subtract_black`` off).
    spatial_images
        Images per spatial stack.
    spatial_photons
        Stage -> level of its bright spatial stack [photons per pixel per frame].
    """

    stages: tuple[int, ...]
    lines: int
    columns: int
    levels: np.ndarray
    pedestal_dn: int
    offsets_dn: dict[int, float]
    spatial_images: int
    spatial_photons: dict[int, float]

    @property
    def all_levels(self) -> np.ndarray:
        """The dark level 0 followed by :attr:`levels`."""
        return np.concatenate([[0.0], self.levels])


@dataclass(frozen=True)
class PtcImages:
    """The stage words exposed for a plan (``uint32``).

    ``pairs[m]``: (levels + 1, 2, L, C), level 0 dark; ``spatial_dark[m]``, ``spatial_bright[m]``:
    (n, L, C).
    """

    pairs: dict[int, np.ndarray]
    spatial_dark: dict[int, np.ndarray]
    spatial_bright: dict[int, np.ndarray]


@dataclass(frozen=True)
class StageResult:
    """EMVA 1288 results of one stage and what the config predicts for them."""

    stage: int
    exposure_ns: float
    pedestal_dn: int
    offset_dn: float
    measured: PhotonTransferResult
    dr_db_by_saturation_method: dict[str, float]
    spatial: dict[str, float]
    expected: dict[str, float]
    dark_mean_dn: float
    dark_var_dn2: float
    photons_per_frame: np.ndarray = field(repr=False)
    mean_dn: np.ndarray = field(repr=False)
    var_dn2: np.ndarray = field(repr=False)
    snr: np.ndarray = field(repr=False)
    snr_model: np.ndarray = field(repr=False)

    @property
    def relative_error(self) -> dict[str, float | None]:
        """Measured / expected - 1 for K, QE, dark noise (e-, DN), DSNU and PRNU."""
        meas = {
            "K": self.measured.k_dn_per_e,
            "quantum_efficiency": self.measured.quantum_efficiency,
            "dark_temporal_noise_e": self.measured.dark_temporal_noise_e,
            "dark_temporal_noise_dn": self.measured.dark_temporal_noise_dn,
            "dsnu_e": self.spatial["dsnu_e"],
            "prnu": self.spatial["prnu"],
        }
        exp = {**self.expected, "K": self.expected["K_dn_per_e"]}
        return {k: (v / exp[k] - 1.0 if exp[k] > 0 else None) for k, v in meas.items()}

    def as_dict(self) -> dict[str, Any]:
        m = self.stage
        signal = self.mean_dn - self.dark_mean_dn
        return {
            "stage": m,
            "exposure_ns": self.exposure_ns,
            "pedestal_dn": self.pedestal_dn,
            "offset_dn": self.offset_dn,
            "measured": self.measured.summary(),
            "dynamic_range_db_by_saturation_method": dict(self.dr_db_by_saturation_method),
            "spatial": dict(self.spatial),
            "per_frame": {
                "photons_sat": self.measured.photons_sat / m,
                "photons_min": self.measured.photons_min / m,
                "photons_min_model": self.measured.photons_min_model / m,
            },
            "expected": dict(self.expected),
            "relative_error": self.relative_error,
            "dark": {"mean_dn": self.dark_mean_dn, "var_dn2": self.dark_var_dn2},
            "series": {
                "photons_per_frame": self.photons_per_frame.tolist(),
                "photons": (m * self.photons_per_frame).tolist(),
                "mean_dn": self.mean_dn.tolist(),
                "var_dn2": self.var_dn2.tolist(),
                "signal_dn": signal.tolist(),
                "snr": [float(x) if np.isfinite(x) else None for x in self.snr],
                "snr_model": self.snr_model.tolist(),
            },
        }


def _saturation(cfg: BenchConfig, stage: int, pedestal_dn: float) -> float:
    return stage_saturation_photons(
        cfg.sensor, cfg.timing.t_int_s, stage, beta_bits=cfg.dtdi.beta_bits,
        subtract_black=cfg.dtdi.subtract_black, pedestal_dn=pedestal_dn,
    )


def _plan_levels(
    cfg: BenchConfig, stages: tuple[int, ...], pedestal_dn: float, log_levels: int, dense_levels: int
) -> np.ndarray:
    """``log_levels`` log-spaced levels from 0.25 x the SNR = 1 level of the highest stage to
    1.5 x the saturation of the lowest stage, and ``dense_levels`` from 0.90 to 1.02 x each
    stage's predicted saturation; levels closer than 0.5 % are merged."""
    p_sat = {m: _saturation(cfg, m, pedestal_dn) for m in stages}
    p_lo = 0.25 * min(stage_snr1_photons(cfg.sensor, cfg.timing.t_int_s, m) for m in stages)
    grid = [np.geomspace(p_lo, 1.5 * max(p_sat.values()), log_levels)]
    grid += [p_sat[m] * np.linspace(DENSE_FROM, DENSE_TO, dense_levels) for m in stages]
    levels = np.unique(np.concatenate(grid))
    keep = [float(levels[0])]
    for v in levels[1:]:
        if v > keep[-1] * 1.005:
            keep.append(float(v))
    return np.asarray(keep)


def plan_ptc(
    cfg: BenchConfig,
    stages: list[int] | tuple[int, ...],
    *,
    lines: int = DEFAULT_LINES,
    columns: int | None = None,
    log_levels: int = DEFAULT_LOG_LEVELS,
    dense_levels: int = DEFAULT_DENSE_LEVELS,
    spatial_images: int = DEFAULT_SPATIAL_IMAGES,
) -> PtcPlan:
    """Validate the arguments and place the levels. Raises :class:`BenchSimError` (one line)."""
    st = validate_stages(stages, cfg.sensor.rows)
    if cfg.dtdi.beta_bits > MAX_FILE_BITS:
        raise BenchSimError(
            f"dtdi.beta_bits = {cfg.dtdi.beta_bits}: EMVA 1288 image files are 16-bit, so the "
            f"photon-transfer export needs beta_bits <= {MAX_FILE_BITS}"
        )
    if not 4 <= int(lines) <= 4096:
        raise BenchSimError(f"lines = {lines!r}: image height must lie in 4..4096")
    cols = min(DEFAULT_COLUMNS, cfg.sensor.columns) if columns is None else int(columns)
    if not 4 <= cols <= cfg.sensor.columns:
        raise BenchSimError(f"columns = {columns!r}: image width must lie in 4..{cfg.sensor.columns}")
    if log_levels < 30:
        raise BenchSimError(f"log_levels = {log_levels!r}: EMVA 1288 needs at least 30 levels")
    if dense_levels < 3:
        raise BenchSimError(f"dense_levels = {dense_levels!r}: need at least 3 near saturation")
    if spatial_images < 3:
        raise BenchSimError(f"spatial_images = {spatial_images!r}: EMVA spatial stacks need >= 3")
    ped = measurement_pedestal_dn(cfg, st)
    return PtcPlan(
        stages=st,
        lines=int(lines),
        columns=cols,
        levels=_plan_levels(cfg, st, ped, log_levels, dense_levels),
        pedestal_dn=ped,
        offsets_dn=measurement_offsets_dn(cfg, st, ped),
        spatial_images=int(spatial_images),
        spatial_photons={m: 0.5 * _saturation(cfg, m, ped) for m in st},
    )


def measure_ptc(cfg: BenchConfig, plan: PtcPlan, seed: int) -> PtcImages:
    """Expose the plan: one fixed pattern, then the levels in order, from one generator."""
    rng = np.random.default_rng(seed)
    fixed = draw_fixed_pattern(cfg.sensor, rng).window(plan.stages[-1], plan.columns)
    kw: dict[str, Any] = {
        "fixed": fixed, "lines": plan.lines, "columns": plan.columns, "pedestal_dn": plan.pedestal_dn
    }
    pairs: dict[int, list[np.ndarray]] = {m: [] for m in plan.stages}
    for p in plan.all_levels:  # a pair per level, every stage from the same pass
        for m, stack in expose_uniform(cfg, plan.stages, float(p), rng, images=2, **kw).items():
            pairs[m].append(stack)
    n = plan.spatial_images
    spatial_dark = expose_uniform(cfg, plan.stages, 0.0, rng, images=n, **kw)
    spatial_bright = {
        m: expose_uniform(cfg, (m,), plan.spatial_photons[m], rng, images=n, **kw)[m] for m in plan.stages
    }
    return PtcImages(
        pairs={m: np.stack(v) for m, v in pairs.items()},
        spatial_dark=spatial_dark,
        spatial_bright=spatial_bright,
    )


def stage_quantization_var_dn2(cfg: BenchConfig, stage: int) -> float:
    """The rounding's variance in stage ``m``'s word [DN^2]: ``m`` pixel ADC roundings (``m / 12``),
    or one of the output word (``1 / 12``) without pixel quantisation."""
    return stage * QUANTIZATION_VAR_DN2 if cfg.sensor.quantization else QUANTIZATION_VAR_DN2


def analyse_ptc(cfg: BenchConfig, plan: PtcPlan, images: PtcImages) -> dict[int, StageResult]:
    """EMVA 1288 analysis of every stage, with the model's expectations from the config."""
    s, t = cfg.sensor, cfg.timing.t_int_s
    out: dict[int, StageResult] = {}
    for m in plan.stages:
        q_var = stage_quantization_var_dn2(cfg, m)
        mv = np.array([mean_var_from_pair(a, b) for a, b in images.pairs[m]])
        dark_mean, dark_var = float(mv[0, 0]), float(mv[0, 1])
        mean, var = mv[1:, 0], mv[1:, 1]
        photons = m * plan.levels
        res = analyse_photon_transfer(
            photons, mean, var, dark_mean, dark_var, quantization_var_dn2=q_var,
            pixels=plan.lines * plan.columns, bits=cfg.dtdi.beta_bits, exposure_s=m * t,
        )
        std = np.sqrt(np.maximum(var, 0.0))
        by_method = {
            meth: dynamic_range_from_series(
                np.concatenate([[0.0], photons]), np.concatenate([[dark_mean], mean]),
                np.concatenate([[np.sqrt(max(dark_var, 0.0))], std]), dark_signal=dark_mean,
                saturation=meth, responsivity=res.responsivity_dn_per_photon,
            ).dr_db
            for meth in ("max_variance", "interpolated", "extrapolated")
        }
        spatial = spatial_nonuniformity(images.spatial_bright[m], images.spatial_dark[m], res.k_dn_per_e)
        mean_model, var_model = stage_mean_var_dn(plan.levels, s, t, m)
        dark_model, dark_var_model = stage_mean_var_dn(0.0, s, t, m)
        k = s.conversion_gain_dn_per_e
        expected = {
            "K_dn_per_e": k,
            "quantum_efficiency": s.quantum_efficiency,
            "dark_temporal_noise_e": float(np.sqrt(m)) * dark_noise_e(s, t),
            "dark_temporal_noise_dn": float(np.sqrt(dark_var_model)),
            "saturation_photons_per_frame": _saturation(cfg, m, plan.pedestal_dn),
            "dsnu_e": stage_dsnu_dn(s, t, m) / k,
            "prnu": stage_prnu(s, m),
        }
        out[m] = StageResult(
            stage=m,
            exposure_ns=m * t * 1e9,
            pedestal_dn=plan.pedestal_dn,
            offset_dn=plan.offsets_dn[m],
            measured=res,
            dr_db_by_saturation_method=by_method,
            spatial={**spatial, "photons_per_frame": plan.spatial_photons[m], "images": plan.spatial_images},
            expected=expected,
            dark_mean_dn=dark_mean,
            dark_var_dn2=dark_var,
            photons_per_frame=plan.levels,
            mean_dn=mean,
            var_dn2=var,
            snr=snr_curve(mean - dark_mean, std),
            snr_model=(mean_model - dark_model) / np.sqrt(var_model),
        )
    return out
