"""``bench-sim calibrate``: a digital twin of a real camera from its photon-transfer data, its raw
images or its EMVA 1288 results, and what it gives in DTDI.

``bench-sim calibrate INPUT --out DIR [--stages mu1,mu2] [--config BASE] [--seed S]`` runs
:func:`calibrate`:

1. read the input (:mod:`bench_sim.workflows.calibrate_inputs`: a photon-transfer table, raw
   images as a frames ``.npz`` or a folder with ``frames.csv``, EMVA 1288 results as TOML or the
   ``emva1288`` package's XML, or a descriptor with its images);
2. fit the EMVA 1288 quantities with standard errors, with the one estimator ``ptc`` uses too
   (:func:`bench_sim.metrics.emva_fit.fit_camera`; images through
   :func:`bench_sim.metrics.frame_series.analyse_frames`: defect pixels, the two DSNUs, PRNU, row
   noise), or take the published results as they are;
3. turn them into the twin (:mod:`bench_sim.workflows.calibrate_twin`): a ``[sensor]`` section
   on the base config (its geometry, timing and DTDI word are kept), with the effects and their
   files that make the twin follow the camera's response, defects and offsets;
4. predict the dynamic range of stages ``mu1``, ``mu2`` and of ``Gamma_HDR`` with what clips each
   (:func:`bench_sim.workflows.calibrate_dr.predict_dr`);
5. write, as one output set: ``sensor.toml`` (the ``[sensor]`` section: paste it, or name the
   file as ``base``), the effects' files (``response.csv``, ``defect_map.csv``), ``defects.csv``,
   ``calibration.json`` (everything, with provenance), ``calibration.csv`` (quantity, value,
   standard error, unit), ``report.md``, ``ptc.png`` (model over data), ``residuals.png`` and
   ``defects.png`` (image inputs: the DSNU and PRNU histograms).
"""

from __future__ import annotations

import json
import math
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.config import DEFAULT_CONFIG_PATH, BenchConfig, load_config, with_overrides
from bench_sim.io import check_output_dir, output_set, write_csv, write_figure_png, write_json, write_text
from bench_sim.metrics.emva_fit import CameraFit, fit_camera
from bench_sim.metrics.frame_series import FrameAnalysis, analyse_frames
from bench_sim.metrics.ptc_table import PtcTable
from bench_sim.sensor.fixed_pattern import draw_fixed_pattern
from bench_sim.sensor.response_curve import chain_response_curve
from bench_sim.sensor.saturation import stage_variance_maximum_photons
from bench_sim.workflows.calibrate_dr import parse_stage_pair, predict_dr
from bench_sim.workflows.calibrate_inputs import CalibrationInput, read_input
from bench_sim.workflows.calibrate_report import figures, report_markdown, results_rows
from bench_sim.workflows.calibrate_twin import Twin, twin_from_fit, twin_from_results
from bench_sim.workflows.output_meta import provenance
from bench_sim.workflows.preflight import check_seed

__all__ = ["calibrate", "SENSOR_KEYS", "INPUT_HELP"]

#: The keys of ``[sensor]`` a calibration sets (the rest come from the base config).
SENSOR_KEYS = (
    "conversion_gain_dn_per_e",
    "quantum_efficiency",
    "wavelength_m",
    "read_noise_e",
    "dark_current_e_s",
    "black_offset_dn",
    "adc_bits",
    "full_well_e",
    "dsnu_e_s",
    "prnu",
    "column_offset_dn",
)
#: ``bench-sim calibrate INPUT``'s help.
INPUT_HELP = (
    "photon-transfer table (.csv), raw images (a frames .npz, or a folder with frames.csv), EMVA 1288 "
    "results (.toml, or the emva1288 package's .xml), or an EMVA 1288 descriptor with its images (.txt or "
    "its folder)"
)
#: The twin's own pixels the model curve averages over (rows, columns)
_CURVE_WINDOW = (16, 32)


def _fit(inp: CalibrationInput) -> tuple[CameraFit | None, FrameAnalysis | None, PtcTable | None]:
    if inp.frames is not None:
        an = analyse_frames(inp.frames)
        return an.fit, an, an.table
    if inp.table is not None:
        return fit_camera(inp.table, quantization_var_dn2=inp.quantization_var_dn2), None, inp.table
    return None, None, None


def _model_check(cfg: BenchConfig, t_exp: float) -> dict[str, float]:
    """What the calibrated sensor predicts for a single read at the measured exposure: the
    EMVA saturation capacity (variance maximum) [e-] and the dark noise [e-]."""
    s = cfg.sensor
    p = stage_variance_maximum_photons(s, t_exp, 1, beta_bits=32, subtract_black=True, pedestal_dn=0.0)
    dark = math.sqrt(s.read_noise_e**2 + s.dark_current_e_s * t_exp)
    return {"saturation_capacity_e": s.quantum_efficiency * p, "dark_noise_e": dark, "exposure_s": t_exp}


def model_curve(cfg: BenchConfig, fit: CameraFit, tab: PtcTable, seed: int) -> dict[str, list[float]]:
    """The twin's exact mean signal [DN] and temporal variance [DN^2] at every lit level of the
    data (each read through its chain, :func:`bench_sim.sensor.response_curve.chain_response_curve`,
    averaged over a window of its pixels less the defects): the levels' linear electrons from the
    fit, over the twin's QE."""
    s = cfg.sensor
    if tab.irradiance is not None and fit.response is not None and fit.linearized:
        e = fit.response.slope * tab.irradiance / fit.k_dn_per_e
    elif tab.irradiance is not None and math.isfinite(fit.responsivity_dn_per_photon):
        e = fit.responsivity_dn_per_photon * tab.irradiance / fit.k_dn_per_e
    elif tab.irradiance is not None:
        slope = float(
            np.sum(tab.signal_dn[fit.linear] * tab.irradiance[fit.linear])
            / np.sum(tab.irradiance[fit.linear] ** 2)
        )
        e = slope * tab.irradiance / fit.k_dn_per_e
    else:
        e = np.maximum(tab.signal_dn, 0.0) / fit.k_dn_per_e
    fixed = draw_fixed_pattern(s, np.random.default_rng(seed)).window(*_CURVE_WINDOW)
    law_mask = np.ones(fixed.shape, dtype=bool)
    for _, state in fixed.effects:
        if "code" in state:
            law_mask &= np.asarray(state["code"]) == 0
    sig, var = chain_response_curve(s, fixed, e / s.quantum_efficiency, tab.exposure_s, mask=law_mask)
    return {
        "signal_dn": sig.tolist(),
        "var_dn2": var.tolist(),
        "data_signal_dn": tab.signal_dn.tolist(),
        "data_var_dn2": tab.var_dn2.tolist(),
        "exposure_s": tab.exposure_s.tolist(),
    }


def _sensor_toml(twin: Twin, meta: dict[str, Any], inp: CalibrationInput) -> str:
    units = {
        "conversion_gain_dn_per_e": "K [DN/e-]",
        "quantum_efficiency": "eta at wavelength_m",
        "wavelength_m": "[m]",
        "read_noise_e": "[e-]",
        "dark_current_e_s": "[e-/s]",
        "black_offset_dn": "[DN]",
        "adc_bits": "[bits]",
        "full_well_e": "clip [e-] (report.md: where the camera clips)",
        "dsnu_e_s": "dark current non-uniformity [e-/s]",
        "prnu": "[fraction]",
        "column_offset_dn": "[DN]",
    }
    lines = [
        f"# bench_sim sensor calibrated by 'bench-sim calibrate' from {inp.path.name} ({inp.kind})",
        f"# bench_sim {meta['version']}; paste the [sensor] section into a config, or name this file as base",
        f"# kept from the base config (not in the input): {', '.join(twin.kept) or 'none'}",
        *(f"# unknown (not in the input): {u}" for u in twin.unknown),
        *(f"# {k}: {v}" for k, v in inp.text.items()),
        "[sensor]",
    ]
    for key in SENSOR_KEYS:
        if key in twin.sensor:
            v = twin.sensor[key]
            lines.append(f"{key} = {int(v) if key == 'adc_bits' else repr(float(v))}  # {units[key]}")
    for name, entry in twin.sensor.get("effects", {}).items():
        lines += ["", f"[sensor.effects.{name}]"]
        for key, v in entry.items():
            lines.append(f"{key} = {json.dumps(v)}" if isinstance(v, str) else f"{key} = {float(v)!r}")
    return "\n".join(lines) + "\n"


def _with_files(twin: Twin, folder: Path) -> dict[str, Any]:
    """The twin's sensor section with its effects' files written to ``folder`` (absolute paths)."""
    sec = {k: v for k, v in twin.sensor.items() if k != "effects"}
    effects = {}
    for name, entry in twin.sensor.get("effects", {}).items():
        entry = dict(entry)
        for key in ("table", "map_file"):
            if key in entry:
                (folder / entry[key]).write_text(twin.files[entry[key]])
                entry[key] = str(folder / entry[key])
        effects[name] = entry
    if effects:
        sec["effects"] = effects
    return sec


def _write(
    out_path: Path, result: dict[str, Any], meta: dict[str, Any], twin: Twin, inp: CalibrationInput,
    fit: CameraFit | None, figs: dict[str, Any],
) -> None:
    """Every file of the calibration as one output set (module docstring)."""
    record = {"command": "calibrate", **{k: meta[k] for k in ("version", "seed", "config_sha256")}}
    img_meta = {k: v for k, v in meta.items() if k not in ("config", "versions")}
    with output_set(out_path, record) as tmp:
        write_text(tmp / "sensor.toml", _sensor_toml(twin, meta, inp))
        for name, text in twin.files.items():
            write_text(tmp / name, text)
        write_csv(tmp / "calibration.csv", ["quantity", "value", "standard_error", "unit"],
                  results_rows(fit, inp.results, twin.sensor), img_meta)
        for name, fig in figs.items():
            write_figure_png(tmp / name, fig, img_meta)
        result["files"] = ["sensor.toml", *twin.files, "calibration.csv", "calibration.json", "report.md",
                           *figs]
        write_text(tmp / "report.md", report_markdown(result, list(figs)))
        write_json(tmp / "calibration.json", result)


def calibrate(
    input_path: str | Path,
    out: str | Path,
    *,
    stages: str | tuple[int, int] | None = None,
    config: str | Path | None = None,
    seed: int = 0,
    chain: bool = True,
) -> dict[str, Any]:
    """Calibrate the sensor model to a camera and predict its DTDI dynamic range (module doc).

    Parameters
    ----------
    input_path
        Photon-transfer table (``.csv``), raw images (``.npz``, or a folder with ``frames.csv``),
        EMVA 1288 results (``.toml``, ``.xml``) or an EMVA 1288 descriptor (``.txt`` or its folder).
    out
        Output folder (written as one set).
    stages
        ``"mu1,mu2"`` or ``(mu1, mu2)``; default the base config's fusion stages.
    config
        Base config (geometry, timing, DTDI word); default the paper rig.
    seed
        Seed of the whole-chain DR measurement and of the twin's model curve.
    chain
        Measure the DR through the chain as well (a few seconds); off: closed forms only.

    Returns
    -------
    dict
        The content of ``calibration.json``.

    Raises
    ------
    BenchSimError
        One line, before anything is written: a bad input (missing columns, negative variance,
        non-monotonic exposure, too few levels in the linear range, images of unequal size), a
        bad ``--stages``, a config that refuses the calibrated sensor, a bad output folder.
    """
    seed = check_seed(seed)
    base = load_config(config if config is not None else DEFAULT_CONFIG_PATH)
    mu1, mu2 = stages if isinstance(stages, tuple) else parse_stage_pair(stages, base)
    parse_stage_pair(f"{mu1},{mu2}", base)
    out_path = check_output_dir(out)  # before the images are read and analysed
    inp = read_input(input_path)
    fit, frames, tab = _fit(inp)
    twin = twin_from_fit(inp, fit, base, frames) if fit is not None else twin_from_results(inp, base)
    with tempfile.TemporaryDirectory(prefix="bench_sim_twin_") as folder:
        sec = _with_files(twin, Path(folder))
        cfg = with_overrides(
            base, {"sensor": sec, "fusion": {"mu1": mu1, "mu2": mu2}}, source=f"calibrated from {inp.path}"
        )
        dr = predict_dr(cfg, mu1, mu2, int(seed), chain=chain)
        curve = model_curve(cfg, fit, tab, int(seed)) if fit is not None and tab is not None else None
    t_exp = fit.exposure_s if fit is not None else inp.results.get("exposure_s", base.timing.t_int_s)
    meta = provenance(cfg, int(seed), input=str(inp.path), input_kind=inp.kind)
    result: dict[str, Any] = {
        **meta, "command": "calibrate", "stages": [mu1, mu2], "sensor": twin.sensor,
        "kept_from_base": twin.kept, "unknown": twin.unknown, "notes": twin.notes,
        "fit": fit.summary() if fit is not None else None,
        "frames": None if frames is None else frames.summary(), "published": inp.results or None,
        "spatial": inp.spatial or None, "model_check": _model_check(cfg, t_exp), "model_curve": curve,
        "dynamic_range": dr,
    }
    figs = figures(tab, fit, curve, frames) if fit is not None and tab is not None and curve else {}
    _write(out_path, result, meta, twin, inp, fit, figs)
    return result
