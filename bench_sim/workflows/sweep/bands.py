"""Flicker banding per image of a sweep point, with the closed form beside it: ``points_images.csv``.

For every flickering, emitting light of a point and every image (each stage the spec lists in
``stages``, the fused pair, and ``gamma_hdr``) one row of the long table ``points_images.csv``
(point x image x light):

=========================== =========================================================================
``point``, ``image``, ``stage``  the point; ``stage_MMM`` or ``gamma_hdr`` (``stage``: ``m``, or ``mu2``)
``light``, ``flicker_hz``   the light and its frequency [Hz]
``cycles_per_line``         its frequency along the track, folded into ``0 .. 0.5``
``amplitude``, ``phase_rad``  measured: :func:`bench_sim.metrics.banding.flat_banding` (no floor
                            from the target: only pixels whose target is flat around them, each
                            column fitted on its own, the columns' phasors weighted by their share
                            of the line profile) of the stage's noise-free truth ``photons``, or of
                            the fused image (``gamma_hdr``; its saturated pixels left out), both
                            against the stage's truth ``reflectance``
``amplitude_sd``            the measured amplitude's standard error from the fits' residuals:
                            on ``gamma_hdr`` (noisy) a null reads below ``4 amplitude_sd`` but
                            for a chance of 3e-4; on the noise-free truth the residuals are
                            rounding (a null reads ~1e-9) and a waveform's harmonics
``predicted_amplitude``, ``predicted_phase_rad``  :func:`~bench_sim.metrics.flicker_theory.predicted_banding`
                            (``gamma_hdr``: the stages' phasors weighted by the share of the profile
                            each source stage makes, its ``mu1`` part scaled by ``mu2 / mu1``)
``alone``                   the light is the only emitting light of the point; otherwise the
                            measured amplitude is the prediction times the light's share of the
                            illumination (the prediction is for the light alone)
=========================== =========================================================================
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.io import write_csv
from bench_sim.metrics.banding import FlatBanding, flat_banding
from bench_sim.metrics.flicker_theory import predicted_banding
from bench_sim.pipeline import Read
from bench_sim.rig.geometry import rig_geometry
from bench_sim.rig.lights import flicker_fundamental

__all__ = [
    "IMAGES_CSV", "IMAGE_COLUMNS", "banding_rows", "flat_half_lines", "stage_banding", "write_points_images",
]

IMAGES_CSV = "points_images.csv"
#: columns of ``points_images.csv`` -> units
IMAGE_COLUMNS: dict[str, str] = {
    "point": "1", "image": "1", "stage": "1", "light": "1", "flicker_hz": "Hz", "cycles_per_line": "1",
    "amplitude": "1", "phase_rad": "rad", "amplitude_sd": "1", "predicted_amplitude": "1",
    "predicted_phase_rad": "rad", "alone": "1",
}
#: waveform -> phase of its fundamental relative to ``flicker_phase_rad`` [rad]
_FUNDAMENTAL_PHASE = {"sine": 0.0, "rectified_sine": -0.5 * math.pi}


def flat_half_lines(cfg: BenchConfig, stage: int) -> int:
    """The flatness window's half height [lines] for stage ``m``: the pixel and its smear (1)
    plus the walk of its ``m`` row footprints under the sync error ``e``, ``ceil(|e| (m - 1))``."""
    return 1 + math.ceil(abs(float(cfg.timing.sync_error)) * (int(stage) - 1) - 1e-9)


def stage_banding(cfg: BenchConfig, read: Read, stage: int, cycles_per_line: float) -> FlatBanding:
    """The banding of stage ``m``'s noise-free truth ``photons`` against its ``reflectance``
    (:func:`bench_sim.metrics.banding.flat_banding`): the estimator without the target's floor.
    ``read``: the pass's variables (:meth:`bench_sim.pipeline.PassResult.read`)."""
    return flat_banding(
        read("photons", stage), read("reflectance", stage), cycles_per_line,
        half_lines=flat_half_lines(cfg, stage),
    )


def _prediction(cfg: BenchConfig, name: str, m: int) -> tuple[float, complex]:
    """``(nu, A e^{i psi})`` of stage ``m`` for light ``name`` alone."""
    light = cfg.lights.get(name)
    geom = rig_geometry(cfg)
    nu, amp, phase = predicted_banding(
        flicker_fundamental(light.flicker_waveform, light.flicker_depth), light.flicker_hz,
        light.flicker_phase_rad + _FUNDAMENTAL_PHASE[light.flicker_waveform], geom.line_period_s,
        geom.t_int_s, m,
    )
    return nu, amp * cmath.exp(1j * phase)


def _hdr_prediction(cfg: BenchConfig, name: str, read: Read, fused: Any) -> complex:
    """The fused image's phasor: ``sum_s q_s P_s`` over the source stages, ``q_s`` the share of
    the profile's mean made by the pixels taken from stage ``s``."""
    mu1, mu2 = cfg.fusion.mu1, cfg.fusion.mu2
    refl = np.asarray(read("reflectance", mu2), dtype=np.float64)
    hdr = np.asarray(fused.hdr, dtype=np.float64)
    part = np.divide(hdr, refl, out=np.zeros(hdr.shape), where=refl > 0)
    total = float(part.sum())
    if total <= 0:
        return complex(float("nan"), 0.0)
    q1 = float(part[np.asarray(fused.source) == mu1].sum()) / total
    return q1 * _prediction(cfg, name, mu1)[1] + (1.0 - q1) * _prediction(cfg, name, mu2)[1]


def banding_rows(
    point: int, cfg: BenchConfig, stages: Sequence[int], read: Read, fused: Any
) -> list[dict[str, Any]]:
    """The rows of ``points_images.csv`` of one point (module docstring). ``read``: the pass's
    variables with its truth (:meth:`bench_sim.pipeline.PassResult.read`); ``fused``: its eq. 11 fusion
    (:class:`~bench_sim.fusion.common.FusionResult`)."""
    rows: list[dict[str, Any]] = []
    emitting = [n for n, light in cfg.lights.items() if light.emits]
    for name in emitting:
        light = cfg.lights.get(name)
        if not light.flickers:
            continue
        base = {"point": point, "light": name, "flicker_hz": float(light.flicker_hz),
                "alone": len(emitting) == 1}
        for m in stages:
            nu, pred = _prediction(cfg, name, m)
            fb = stage_banding(cfg, read, m, nu)
            rows.append({**base, "image": f"stage_{m:03d}", "stage": m, "cycles_per_line": nu,
                         "amplitude": fb.amplitude, "phase_rad": fb.phase_rad, "amplitude_sd": fb.sd,
                         "predicted_amplitude": abs(pred), "predicted_phase_rad": cmath.phase(pred)})
        mu2 = cfg.fusion.mu2
        nu = _prediction(cfg, name, mu2)[0]
        hdr = np.where(np.asarray(fused.saturated), np.nan, np.asarray(fused.hdr, dtype=np.float64))
        fb = flat_banding(hdr, read("reflectance", mu2), nu, half_lines=flat_half_lines(cfg, mu2))
        pred = _hdr_prediction(cfg, name, read, fused)
        rows.append({**base, "image": "gamma_hdr", "stage": mu2, "cycles_per_line": nu,
                     "amplitude": fb.amplitude, "phase_rad": fb.phase_rad, "amplitude_sd": fb.sd,
                     "predicted_amplitude": abs(pred), "predicted_phase_rad": cmath.phase(pred)})
    return rows


def _cell(v: Any) -> Any:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    return v


def write_points_images(out: Path, records: Mapping[int, Mapping[str, Any]]) -> Path:
    """(Re)write ``points_images.csv`` (plain CSV, one header line) from the point records."""
    rows = [
        [_cell(row.get(c)) for c in IMAGE_COLUMNS]
        for i in sorted(records)
        for row in (records[i].get("metrics") or {}).get("banding_images", [])
    ]
    return write_csv(out / IMAGES_CSV, list(IMAGE_COLUMNS), rows)
