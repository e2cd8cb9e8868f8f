"""Measured dynamic range of ``Gamma1``, ``Gamma2`` and ``Gamma_HDR`` through the whole chain.

A photon-transfer series (EMVA 1288 style): a uniform field of ``mu_p`` photons per pixel per
frame, at many levels from dark to beyond the saturation of ``Gamma1``, goes through the sensor
model (:func:`bench_sim.sensor.emva.expose`, one fixed pattern for the whole series), the
streaming DTDI accumulator (:func:`bench_sim.sensor.pipeline.sensor_dtdi_pass`, frames in
chunks) and the paper's fusion (:func:`bench_sim.fusion.paper.fuse_dtdi_hdr_eq11`). Per level
and image, the mean and the temporal variance come from two images of the same uniform scene
(:func:`bench_sim.metrics.emva1288.mean_var_from_pair`), and the dynamic range
``20 lg(mu_p.sat / mu_p.min)`` from :func:`bench_sim.metrics.emva1288.dynamic_range_from_series`
(``mu_p.min``: SNR = 1 on the measured SNR curve; ``mu_p.sat``: see ``saturation`` below). The
photon unit is mean photons per pixel per *frame* for all three images, so their DRs compare
directly.

Two images per level from one pass: one DTDI pass of ``2 * lines`` scene lines is split into
lines ``0 .. lines-1`` and ``lines .. 2*lines-1``. Every raw read (frame ``k``, row ``i``)
belongs to exactly one scene line (``j = k - i``) and every line of a column sums the same
physical pixels, so the two halves are temporally independent images with the same fixed
pattern - an EMVA 1288 image pair - for ``2L + mu2 - 1`` frames instead of ``2 (L + mu2 - 1)``.

Offset (pedestal): with the black offset subtracted, the dark stage signal sits at 0 DN and the
word would clip half its noise (and the ``m``-fold column offsets) away; EMVA 1288 needs an
unclipped dark signal. Both stage words therefore get the same total offset ``P``
(:func:`ptc_offset_dn`: ``ceil(6 sigma)`` of the top stage's dark spread; with
``subtract_black = false`` at least ``mu2 * black`` and made equal for both stages by the DTDI
pedestal), and the fusion removes it again (``pedestal_dn`` of :func:`fuse_dtdi_hdr_eq11`, which
keeps eq. 11 with the word's signal range ``Phi_FS - P``). All images lose the same ``P`` DN of
range, so the differences between them are unaffected; their absolute DRs are lower than
without it by ``20 lg(Phi_FS / (Phi_FS - P))`` where the word limits (about 0.15 dB for 72 DN in
12 bits).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from bench_sim.config import DTDIConfig, SensorConfig
from bench_sim.errors import BenchSimError
from bench_sim.fusion.paper import fuse_dtdi_hdr_eq11
from bench_sim.metrics.dynamic_range import dr_increase_eq15_db
from bench_sim.metrics.emva1288 import (
    SaturationMethod,
    dynamic_range_from_series,
    mean_var_from_pair,
)
from bench_sim.metrics.snr import snr_versus_signal
from bench_sim.sensor.emva import FixedPattern, draw_fixed_pattern
from bench_sim.sensor.model import stage_dark_std_dn, stage_saturation_photons, stage_snr1_photons
from bench_sim.sensor.pipeline import sensor_dtdi_pass

__all__ = [
    "IMAGES",
    "ptc_offset_dn",
    "default_levels",
    "photon_transfer_series",
    "measure_dynamic_range",
]

#: The three images of the paper, in the order they are reported.
IMAGES: tuple[str, ...] = ("gamma1", "gamma2", "hdr")


def ptc_offset_dn(sensor: SensorConfig, dtdi: DTDIConfig, t_int_s: float, stage: int) -> float:
    """Total offset [DN] both stage words carry in the series (at least 1 DN).

    ``ceil(6 sigma)`` with ``sigma^2 = m^2 col^2 + m (K^2 (sigma_r^2 + mu_d) + 1/12) + m (K dsnu t)^2``
    [DN^2] for the top stage ``m`` (the column amplifier offset ``col`` adds coherently over the
    ``m`` rows of a column, temporal noise and DSNU of the ``m`` pixels incoherently); with
    ``dtdi.subtract_black`` off, at least the accumulated black offset ``m * black`` of the top
    stage.
    """
    need = math.ceil(6.0 * stage_dark_std_dn(sensor, t_int_s, stage))
    if not dtdi.subtract_black:
        need = max(need, math.ceil(stage * sensor.black_offset_dn))
    return float(max(need, 1))


def default_levels(
    sensor: SensorConfig,
    beta_bits: int,
    t_int_s: float,
    mu1: int,
    mu2: int,
    n_levels: int = 40,
    offset_dn: float = 0.0,
) -> np.ndarray:
    """Photon levels of the series: 0 (dark) and ``n_levels`` geometric levels [photons/pixel/frame].

    From a quarter of the predicted SNR = 1 point of stage ``mu2``
    (:func:`bench_sim.sensor.model.stage_snr1_photons`) to twice the predicted saturation of
    stage ``mu1`` (:func:`bench_sim.sensor.model.stage_saturation_photons`, the word with the
    offset or the pixel). The prediction only places the levels.
    """
    p_lo = 0.25 * stage_snr1_photons(sensor, t_int_s, mu2)
    p_hi = 2.0 * stage_saturation_photons(
        sensor, t_int_s, mu1, beta_bits=beta_bits, pedestal_dn=offset_dn
    )
    return np.concatenate([[0.0], np.geomspace(p_lo, p_hi, n_levels)])


def photon_transfer_series(
    sensor: SensorConfig,
    dtdi: DTDIConfig,
    t_int_s: float,
    mu1: int,
    mu2: int,
    rng: np.random.Generator,
    levels: Sequence[float] | np.ndarray,
    *,
    lines: int = 32,
    columns: int = 64,
    offset_dn: float | None = None,
    fixed: FixedPattern | None = None,
) -> dict[str, Any]:
    """Run a uniform-field photon-transfer series through sensor, DTDI and eq. 11 fusion.

    Parameters
    ----------
    sensor, dtdi
        Pixel model and DTDI settings (``beta_bits``, ``subtract_black``).
    t_int_s
        Integration time of one frame [s].
    mu1, mu2
        Stages fused (``1 <= mu1 < mu2 <= sensor.rows``).
    rng
        The run's random generator (fixed pattern first, unless ``fixed`` is given).
    levels
        Mean photons per pixel per frame, strictly increasing, >= 0.
    lines, columns
        Size of each of the two images per level (``lines`` x ``columns``).
    offset_dn
        Total offset of both stage words [DN]; default :func:`ptc_offset_dn`. With
        ``subtract_black`` off it must be at least ``mu2 * black_offset_dn``.
    fixed
        The sensor's fixed pattern (default: drawn from ``rng`` for the whole sensor).

    Returns
    -------
    dict
        ``photons`` (levels), ``offset_dn``, and per image name in :data:`IMAGES` a dict with
        ``mean_dn`` and ``temporal_var_dn2`` arrays (offset removed; ``hdr`` in stage-``mu2``
        units).
    """
    if not (isinstance(lines, int) and lines >= 1 and isinstance(columns, int) and columns >= 1):
        raise BenchSimError(f"lines = {lines!r}, columns = {columns!r}: need integers >= 1")
    if lines * columns < 2:
        raise BenchSimError("lines x columns: an image needs at least 2 pixels")
    if columns > sensor.columns or mu2 > sensor.rows:
        raise BenchSimError(
            f"columns = {columns}, mu2 = {mu2}: must fit the sensor's {sensor.rows} rows x "
            f"{sensor.columns} columns"
        )
    if not 1 <= mu1 < mu2:
        raise BenchSimError(f"mu1 = {mu1}, mu2 = {mu2}: need 1 <= mu1 < mu2")
    p = np.asarray(levels, dtype=np.float64)
    if p.ndim != 1 or p.size < 1 or not np.all(np.diff(p) > 0) or p[0] < 0:
        raise BenchSimError("levels: need strictly increasing photon levels >= 0")
    beta = dtdi.beta_bits
    off = ptc_offset_dn(sensor, dtdi, t_int_s, mu2) if offset_dn is None else float(offset_dn)
    black = 0.0 if dtdi.subtract_black else sensor.black_offset_dn
    pedestals = {m: off - m * black for m in (mu1, mu2)}
    if min(pedestals.values()) < 0:
        raise BenchSimError(
            f"offset_dn = {off:g}: below the accumulated black offset {mu2} x {black:g} DN of "
            f"stage {mu2} (dtdi.subtract_black is off)"
        )
    if not off < 0.5 * (2**beta - 1):
        raise BenchSimError(
            f"offset_dn = {off:g}: must be below half the {beta}-bit word ({0.5 * (2**beta - 1):g} DN); "
            "use a wider word (dtdi.beta_bits), subtract the black offset, or a quieter sensor"
        )
    if fixed is None:
        fixed = draw_fixed_pattern(sensor, rng)
    n_frames = 2 * lines + mu2 - 1
    stats = {name: np.zeros((p.size, 2)) for name in IMAGES}
    for li, level in enumerate(p):
        photons = np.full((n_frames, mu2, columns), level)
        st = sensor_dtdi_pass(
            photons, sensor, dtdi, t_int_s, (mu1, mu2), rng,
            fixed=fixed, lines=2 * lines, pedestal_dn=pedestals,
        )
        fused = fuse_dtdi_hdr_eq11(st[mu1], st[mu2], mu1=mu1, mu2=mu2, beta=beta, pedestal_dn=off)
        images = {
            "gamma1": st[mu1].astype(np.float64) - off,
            "gamma2": st[mu2].astype(np.float64) - off,
            "hdr": fused.hdr,
        }
        for name, img in images.items():
            stats[name][li] = mean_var_from_pair(img[:lines], img[lines:])
    out: dict[str, Any] = {"photons": p, "offset_dn": off}
    for name in IMAGES:
        out[name] = {"mean_dn": stats[name][:, 0], "temporal_var_dn2": stats[name][:, 1]}
    return out


def _merge_series(a: dict[str, Any], b: dict[str, Any]) -> dict[str, Any]:
    p = np.concatenate([a["photons"], b["photons"]])
    order = np.argsort(p, kind="stable")
    keep = np.concatenate([[True], np.diff(p[order]) > 0])
    idx = order[keep]
    out: dict[str, Any] = {"photons": p[idx], "offset_dn": a["offset_dn"]}
    for name in IMAGES:
        out[name] = {
            key: np.concatenate([a[name][key], b[name][key]])[idx]
            for key in ("mean_dn", "temporal_var_dn2")
        }
    return out


def measure_dynamic_range(
    sensor: SensorConfig,
    dtdi: DTDIConfig,
    t_int_s: float,
    mu1: int,
    mu2: int,
    rng: np.random.Generator,
    *,
    levels: Sequence[float] | np.ndarray | None = None,
    n_levels: int = 40,
    lines: int = 32,
    columns: int = 64,
    offset_dn: float | None = None,
    saturation: SaturationMethod = "extrapolated",
    refine_rounds: int = 2,
    refine_points: int = 8,
) -> dict[str, Any]:
    """Measured DR (EMVA 1288 style) of ``Gamma1``, ``Gamma2``, ``Gamma_HDR`` and the HDR's gains.

    Parameters
    ----------
    sensor, dtdi
        Pixel model and DTDI settings.
    t_int_s
        Integration time of one frame [s].
    mu1, mu2
        Stages fused with eq. 11.
    rng
        The run's random generator (fixed pattern, then temporal noise).
    levels
        Photon levels [photons/pixel/frame], strictly increasing (a dark level 0 is added if
        missing); default :func:`default_levels` with ``n_levels`` lit levels.
    n_levels
        Lit levels of the default grid.
    lines, columns
        Image size per level (two images each).
    offset_dn
        Offset of both stage words [DN]; default :func:`ptc_offset_dn`.
    saturation
        Definition of ``mu_p.sat`` for the headline numbers
        (:func:`bench_sim.metrics.emva1288.saturation_point`): ``"extrapolated"`` (default: where
        the linear response meets the clipped plateau; independent of the level grid),
        ``"interpolated"`` (EMVA's variance maximum, parabola between levels) or
        ``"max_variance"`` (the grid level of the variance maximum). ``"interpolated"`` is always
        reported too (``dr_db_variance_max``; with ``"extrapolated"`` it comes from the unrefined
        grid, so it is only as good as the level spacing, ``level_step_db_max``).
    refine_rounds, refine_points
        For the two variance-maximum definitions: rounds of ``refine_points`` extra levels
        between the neighbours of each image's variance maximum.

    Returns
    -------
    dict
        ``dr_db`` {image: dB}; ``delta_db_vs_gamma1`` and ``delta_db_vs_gamma2`` (HDR minus
        each); ``eq15_db`` (``20 lg(mu2/mu1)``); per image in ``images``: ``photons_min``,
        ``photons_sat``, ``signal_sat_dn``, ``dr_db``, ``dr_db_variance_max``, and the series
        ``mean_dn``, ``temporal_std_dn``, ``snr`` (dark-subtracted mean over temporal std);
        ``photons`` (the levels) and the settings used.
    """
    if saturation not in ("extrapolated", "interpolated", "max_variance"):
        raise BenchSimError(
            f"saturation = {saturation!r}: allowed 'extrapolated', 'interpolated', 'max_variance'"
        )
    off = ptc_offset_dn(sensor, dtdi, t_int_s, mu2) if offset_dn is None else float(offset_dn)
    if levels is None:
        levels = default_levels(sensor, dtdi.beta_bits, t_int_s, mu1, mu2, n_levels, off)
    levels = np.union1d([0.0], np.asarray(levels, dtype=np.float64))  # the dark level is needed
    fixed = draw_fixed_pattern(sensor, rng)
    kwargs: dict[str, Any] = {"lines": lines, "columns": columns, "offset_dn": off, "fixed": fixed}
    series = photon_transfer_series(sensor, dtdi, t_int_s, mu1, mu2, rng, levels, **kwargs)
    if saturation != "extrapolated":
        for _ in range(refine_rounds):
            p = series["photons"]
            extra: list[np.ndarray] = []
            for name in IMAGES:
                i = int(np.argmax(series[name]["temporal_var_dn2"]))
                lo, hi = p[max(i - 1, 0)], p[min(i + 1, p.size - 1)]
                if hi > lo:
                    extra.append(np.linspace(lo, hi, refine_points + 2)[1:-1])
            new = np.setdiff1d(np.unique(np.concatenate(extra)), p) if extra else np.array([])
            if new.size:
                more = photon_transfer_series(sensor, dtdi, t_int_s, mu1, mu2, rng, new, **kwargs)
                series = _merge_series(series, more)
    p = series["photons"]
    per_image: dict[str, Any] = {}
    for name in IMAGES:
        mean = series[name]["mean_dn"]
        std = np.sqrt(np.maximum(series[name]["temporal_var_dn2"], 0.0))
        dark = float(mean[0])
        main = dynamic_range_from_series(p, mean, std, dark_signal=dark, saturation=saturation)
        vmax = dynamic_range_from_series(p, mean, std, dark_signal=dark, saturation="interpolated")
        per_image[name] = {
            "dr_db": main.dr_db,
            "photons_min": main.photons_min,
            "photons_sat": main.photons_sat,
            "signal_sat_dn": main.signal_sat,
            "dr_db_variance_max": vmax.dr_db,
            "photons_sat_variance_max": vmax.photons_sat,
            "mean_dn": mean.tolist(),
            "temporal_std_dn": std.tolist(),
            "snr": snr_versus_signal(mean, std, dark)[1].tolist(),
        }
    dr = {name: per_image[name]["dr_db"] for name in IMAGES}
    steps = np.diff(np.log10(p[p > 0]))
    return {
        "mu1": mu1,
        "mu2": mu2,
        "beta_bits": dtdi.beta_bits,
        "adc_bits": sensor.adc_bits,
        "t_int_s": t_int_s,
        "lines": lines,
        "columns": columns,
        "offset_dn": off,
        "saturation": saturation,
        "photon_unit": "mean photons per pixel per frame",
        "level_step_db_max": float(20.0 * steps.max()) if steps.size else float("nan"),
        "photons": p.tolist(),
        "images": per_image,
        "dr_db": dr,
        "delta_db_vs_gamma1": dr["hdr"] - dr["gamma1"],
        "delta_db_vs_gamma2": dr["hdr"] - dr["gamma2"],
        "delta_db_vs_gamma2_variance_max": per_image["hdr"]["dr_db_variance_max"]
        - per_image["gamma2"]["dr_db_variance_max"],
        "eq15_db": dr_increase_eq15_db(mu1, mu2),
    }
