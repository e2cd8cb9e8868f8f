"""``bench-sim calibrate``: a digital twin of a real camera from its photon-transfer data or its
EMVA 1288 results, and what it gives in DTDI.

``bench-sim calibrate INPUT --out DIR [--stages mu1,mu2] [--config BASE] [--seed S]`` runs
:func:`calibrate`:

1. read the input (:mod:`bench_sim.workflows.calibrate_inputs`: a photon-transfer table, EMVA
   1288 results as TOML or the ``emva1288`` package's XML, or a descriptor with its images);
2. fit the EMVA 1288 quantities with standard errors (:func:`bench_sim.measure.calibration.fit_camera`)
   or take the published results as they are;
3. turn them into a ``[sensor]`` section (:func:`sensor_section`) on the base config (its
   geometry, timing and DTDI word are kept);
4. predict the dynamic range of stages ``mu1``, ``mu2`` and of ``Gamma_HDR``: in closed form
   (the clip point, :func:`bench_sim.sensor.model.stage_dr_model_db`, and EMVA 1288's variance
   maximum, :func:`bench_sim.sensor.saturation.stage_variance_maximum_photons`) and measured
   through the chain as ``reproduce`` does (:func:`bench_sim.measure.chain_dr.measure_chain_dynamic_range`);
5. write, as one output set: ``sensor.toml`` (the ``[sensor]`` section: paste it, or name the
   file as ``base``), ``calibration.json`` (everything, with provenance), ``calibration.csv``
   (quantity, value, standard error, unit), ``report.md``, ``ptc.png`` (model over data) and
   ``residuals.png`` (table inputs).

How the sensor section is made
------------------------------
``conversion_gain_dn_per_e = K``, ``quantum_efficiency = eta``; ``read_noise_e`` is the dark
noise at zero exposure (several exposure times) or ``sqrt(sigma_d^2 - I_d t)`` (one); the dark
current is the fitted one (several exposure times), the published one, or 0 (then the whole
dark noise is read noise, exact at the measured exposure time); ``black_offset_dn`` is the dark
level less the dark signal; ``adc_bits`` the camera's; ``full_well_e`` is the clip whose
variance maximum lies at the measured saturation capacity
(:func:`bench_sim.sensor.saturation.full_well_for_saturation`), so that the model saturates where
the camera does in EMVA 1288's sense. DSNU and PRNU come from the descriptor's spatial stacks or
the published results (``dsnu_e_s = DSNU / t_exp``, the column offsets set to 0); what the input
does not give is kept from the base config and listed as such in the report.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from bench_sim.config import DEFAULT_CONFIG_PATH, BenchConfig, load_config, with_overrides
from bench_sim.errors import BenchSimError
from bench_sim.io import check_output_dir, output_set, write_csv, write_figure_png, write_json, write_text
from bench_sim.measure.calibration import CameraFit, fit_camera
from bench_sim.measure.chain_dr import measure_chain_dynamic_range
from bench_sim.measure.uniform_field import measurement_pedestal_dn
from bench_sim.sensor.model import stage_dr_model_db, stage_saturation_photons, stage_snr1_photons
from bench_sim.sensor.saturation import full_well_for_saturation, stage_variance_maximum_photons
from bench_sim.workflows.calibrate_inputs import CalibrationInput, read_input
from bench_sim.workflows.calibrate_report import figures, report_markdown, results_rows
from bench_sim.workflows.output_meta import provenance
from bench_sim.workflows.preflight import check_seed
from bench_sim.workflows.reproduce.report import AGREE_DB

__all__ = ["calibrate", "sensor_section", "predict_dr", "parse_stage_pair", "SENSOR_KEYS", "INPUT_HELP"]

#: The keys of ``[sensor]`` a calibration sets (the rest come from the base config).
SENSOR_KEYS = (
    "conversion_gain_dn_per_e", "quantum_efficiency", "wavelength_m", "read_noise_e", "dark_current_e_s",
    "black_offset_dn", "adc_bits", "full_well_e", "dsnu_e_s", "prnu", "column_offset_dn",
)
#: ``bench-sim calibrate INPUT``'s help.
INPUT_HELP = (
    "photon-transfer table (.csv), EMVA 1288 results (.toml, or the emva1288 package's .xml), or an "
    "EMVA 1288 descriptor with its images (.txt or its folder)"
)
#: Columns of the whole-chain DR measurement (as ``reproduce``).
CHAIN_COLUMNS = 64


def parse_stage_pair(text: str | None, cfg: BenchConfig) -> tuple[int, int]:
    """``--stages mu1,mu2`` (default: the config's ``fusion.mu1``, ``fusion.mu2``)."""
    if text is None:
        return cfg.fusion.mu1, cfg.fusion.mu2
    parts = [p.strip() for p in str(text).split(",")]
    try:
        mu1, mu2 = (int(p) for p in parts)
    except ValueError as exc:
        raise BenchSimError(f"--stages = {text!r}: expected two stages 'mu1,mu2', e.g. 10,80") from exc
    if not 1 <= mu1 < mu2 <= cfg.sensor.rows:
        raise BenchSimError(f"--stages = {text!r}: need 1 <= mu1 < mu2 <= sensor.rows = {cfg.sensor.rows}")
    return mu1, mu2


def _bits_for(k: float, full_well_e: float, black_dn: float) -> int:
    """Smallest ADC (>= 8 bits) whose top holds the full well above the black offset."""
    return max(8, math.ceil(math.log2(k * full_well_e + black_dn + 2.0)))


def _from_fit(inp: CalibrationInput, f: CameraFit) -> tuple[dict[str, Any], list[str]]:
    tab = inp.table
    assert tab is not None
    multi = tab.dark_exposure_s.size >= 3
    idark = f.dark_current_e_s if multi and f.dark_current_e_s > 0 else 0.0
    t = f.exposure_s
    kept: list[str] = []
    sec: dict[str, Any] = {
        "conversion_gain_dn_per_e": f.k_dn_per_e,
        "quantum_efficiency": f.quantum_efficiency,
        "read_noise_e": f.dark_noise_e,  # at 0 s (several exposure times), or all of it (idark = 0)
        "dark_current_e_s": idark,
        # the dark level less the dark signal (several exposure times: the intercept at 0 s)
        "black_offset_dn": max(f.dark_offset_dn - (0.0 if multi else f.k_dn_per_e * idark * t), 0.0),
        "adc_bits": f.bits,
        "full_well_e": full_well_for_saturation(f.saturation_capacity_e, idark * t),
    }
    if tab.wavelength_nm is not None:
        sec["wavelength_m"] = tab.wavelength_nm * 1e-9
    t_sp = inp.spatial.get("exposure_s", t)
    if inp.spatial and t_sp > 0:
        sec.update(dsnu_e_s=inp.spatial["dsnu_dn"] / f.k_dn_per_e / t_sp, prnu=inp.spatial["prnu"],
                   column_offset_dn=0.0)
    else:
        kept += ["dsnu_e_s", "prnu", "column_offset_dn"]
    if tab.wavelength_nm is None:
        kept.append("wavelength_m")
    return sec, kept


def _from_results(inp: CalibrationInput, base: BenchConfig) -> tuple[dict[str, Any], list[str]]:
    r = inp.results
    t = r.get("exposure_s", base.timing.t_int_s)
    idark = r.get("dark_current_e_per_s", 0.0)
    k = r["K_dn_per_e"]
    fw = full_well_for_saturation(r["saturation_capacity_e"], idark * t)
    black = base.sensor.black_offset_dn
    sec: dict[str, Any] = {
        "conversion_gain_dn_per_e": k,
        "read_noise_e": math.sqrt(max(r["dark_noise_e"] ** 2 - idark * t, 0.0)),
        "dark_current_e_s": idark,
        "full_well_e": fw,
        "adc_bits": int(r["bits"]) if "bits" in r else _bits_for(k, fw, black),
    }
    kept = ["black_offset_dn"]
    for key, src, scale in (("quantum_efficiency", "qe", 1.0), ("prnu", "prnu_percent", 0.01)):
        if src in r:
            sec[key] = r[src] * scale
        else:
            kept.append(key)
    if "wavelength_nm" in r:
        sec["wavelength_m"] = r["wavelength_nm"] * 1e-9
    else:
        kept.append("wavelength_m")
    if "dsnu_e" in r and t > 0:
        sec.update(dsnu_e_s=r["dsnu_e"] / t, column_offset_dn=0.0)
    else:
        kept += ["dsnu_e_s", "column_offset_dn"]
    return sec, kept


def sensor_section(
    inp: CalibrationInput, base: BenchConfig, fit: CameraFit | None = None
) -> tuple[dict[str, Any], list[str]]:
    """The ``[sensor]`` keys a calibration sets and the keys kept from ``base`` (see module doc).

    Raises
    ------
    BenchSimError
        A quantum efficiency above 1 (a photon calibration off by a factor), or a section the
        config refuses.
    """
    sec, kept = _from_fit(inp, fit) if fit is not None else _from_results(inp, base)
    qe = sec.get("quantum_efficiency")
    if qe is not None and not 0 < qe <= 1:
        raise BenchSimError(
            f"{inp.path}: fitted quantum efficiency {qe:.4g} outside 0..1: check photons_per_pixel "
            "(mean photons per pixel during the exposure)"
        )
    return sec, kept


def predict_dr(
    cfg: BenchConfig, mu1: int, mu2: int, seed: int, *, lines: int = 32, n_levels: int = 40
) -> dict[str, Any]:
    """Predicted DR [dB] of ``Gamma1`` (stage ``mu1``), ``Gamma2`` (``mu2``) and ``Gamma_HDR``.

    ``closed_form_clip``: saturation at the clip point, SNR = 1 of the linear model
    (:func:`bench_sim.sensor.model.stage_dr_model_db`); ``closed_form_emva``: saturation at the
    model's variance maximum (EMVA 1288's definition, what the chain measures);
    ``chain``/``chain_extrapolated``: measured through the sensor, DTDI and eq. 11 fusion
    (:func:`bench_sim.measure.chain_dr.measure_chain_dynamic_range`, as ``reproduce``);
    ``agree``: ``|closed_form_emva - chain| <= AGREE_DB`` (``reproduce``'s stated scatter).
    """
    t, s = cfg.timing.t_int_s, cfg.sensor
    ped = measurement_pedestal_dn(cfg, (mu1, mu2))
    beta, sub = cfg.dtdi.beta_bits, cfg.dtdi.subtract_black
    vmax = {
        m: stage_variance_maximum_photons(s, t, m, beta_bits=beta, subtract_black=sub, pedestal_dn=ped)
        for m in (mu1, mu2)
    }
    clip = {
        m: stage_saturation_photons(s, t, m, beta_bits=beta, subtract_black=sub, pedestal_dn=ped)
        for m in (mu1, mu2)
    }
    snr1 = {m: stage_snr1_photons(s, t, m) for m in (mu1, mu2)}
    emva = {
        "gamma1": 20 * math.log10(vmax[mu1] / snr1[mu1]),
        "gamma2": 20 * math.log10(vmax[mu2] / snr1[mu2]),
        "gamma_hdr": 20 * math.log10(vmax[mu1] / snr1[mu2]),
    }
    closed = {
        "gamma1": stage_dr_model_db(cfg, mu1, ped),
        "gamma2": stage_dr_model_db(cfg, mu2, ped),
        "gamma_hdr": 20 * math.log10(clip[mu1] / snr1[mu2]),
    }
    chain = measure_chain_dynamic_range(
        cfg, seed, mu1=mu1, mu2=mu2, lines=lines, columns=min(CHAIN_COLUMNS, s.columns), n_levels=n_levels
    )
    out: dict[str, Any] = {"mu1": mu1, "mu2": mu2, "pedestal_dn": ped, "agree_db": AGREE_DB, "images": {}}
    for name in ("gamma1", "gamma2", "gamma_hdr"):
        img = chain.images[name]
        out["images"][name] = {
            "closed_form_clip_db": closed[name], "closed_form_emva_db": emva[name], "chain_db": img.dr_db,
            "chain_extrapolated_db": img.dr_db_extrapolated,
            "agree": abs(emva[name] - img.dr_db) <= AGREE_DB,
        }
    out["saturation_photons_per_frame"] = {
        str(m): {"variance_maximum": vmax[m], "clip": clip[m]} for m in vmax
    }
    out["snr1_photons_per_frame"] = {str(m): v for m, v in snr1.items()}
    return out


def _model_check(cfg: BenchConfig, t_exp: float) -> dict[str, float]:
    """What the calibrated sensor predicts for a single read at the measured exposure: the
    EMVA saturation capacity (variance maximum) [e-] and the dark noise [e-]."""
    s = cfg.sensor
    p = stage_variance_maximum_photons(s, t_exp, 1, beta_bits=32, subtract_black=True, pedestal_dn=0.0)
    dark = math.sqrt(s.read_noise_e**2 + s.dark_current_e_s * t_exp)
    return {"saturation_capacity_e": s.quantum_efficiency * p, "dark_noise_e": dark, "exposure_s": t_exp}


def _sensor_toml(sec: dict[str, Any], kept: list[str], meta: dict[str, Any], inp: CalibrationInput) -> str:
    units = {
        "conversion_gain_dn_per_e": "K [DN/e-]", "quantum_efficiency": "eta at wavelength_m",
        "wavelength_m": "[m]", "read_noise_e": "[e-]", "dark_current_e_s": "[e-/s]",
        "black_offset_dn": "[DN]",
        "adc_bits": "[bits]", "full_well_e": "clip [e-] of the measured EMVA saturation capacity",
        "dsnu_e_s": "[e-/s]", "prnu": "[fraction]", "column_offset_dn": "[DN]",
    }
    lines = [
        f"# bench_sim sensor calibrated by 'bench-sim calibrate' from {inp.path.name} ({inp.kind})",
        f"# bench_sim {meta['version']}; paste the [sensor] section into a config, or name this file as base",
        f"# kept from the base config (not in the input): {', '.join(kept) or 'none'}",
        *(f"# {k}: {v}" for k, v in inp.text.items()),
        "[sensor]",
    ]
    for key in SENSOR_KEYS:
        if key in sec:
            v = sec[key]
            lines.append(f"{key} = {int(v) if key == 'adc_bits' else repr(float(v))}  # {units[key]}")
    return "\n".join(lines) + "\n"


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
        Photon-transfer table (``.csv``), EMVA 1288 results (``.toml``, ``.xml``) or an EMVA
        1288 descriptor (``.txt`` or its folder).
    out
        Output folder (written as one set).
    stages
        ``"mu1,mu2"`` or ``(mu1, mu2)``; default the base config's fusion stages.
    config
        Base config (geometry, timing, DTDI word); default the paper rig.
    seed
        Seed of the whole-chain DR measurement.
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
        non-monotonic exposure, too few levels in the linear range, no saturation reached), a
        bad ``--stages``, a config that refuses the calibrated sensor, a bad output folder.
    """
    seed = check_seed(seed)
    base = load_config(config if config is not None else DEFAULT_CONFIG_PATH)
    mu1, mu2 = stages if isinstance(stages, tuple) else parse_stage_pair(stages, base)
    parse_stage_pair(f"{mu1},{mu2}", base)
    inp = read_input(input_path)
    fit = fit_camera(inp.table) if inp.table is not None else None
    sec, kept = sensor_section(inp, base, fit)
    over = {"sensor": sec, "fusion": {"mu1": mu1, "mu2": mu2}}
    cfg = with_overrides(base, over, source=f"calibrated from {inp.path}")
    out_path = check_output_dir(out)
    dr = predict_dr(cfg, mu1, mu2, int(seed)) if chain else None
    t_exp = fit.exposure_s if fit is not None else inp.results.get("exposure_s", base.timing.t_int_s)
    meta = provenance(cfg, int(seed), input=str(inp.path), input_kind=inp.kind)
    result: dict[str, Any] = {
        **meta, "command": "calibrate", "stages": [mu1, mu2], "sensor": sec, "kept_from_base": kept,
        "fit": fit.summary() if fit is not None else None, "published": inp.results or None,
        "spatial": inp.spatial or None, "model_check": _model_check(cfg, t_exp), "dynamic_range": dr,
    }
    figs = figures(inp, fit, cfg) if fit is not None else {}
    record = {"command": "calibrate", **{k: meta[k] for k in ("version", "seed", "config_sha256")}}
    img_meta = {k: v for k, v in meta.items() if k not in ("config", "versions")}
    with output_set(out_path, record) as tmp:
        write_text(tmp / "sensor.toml", _sensor_toml(sec, kept, meta, inp))
        write_csv(tmp / "calibration.csv", ["quantity", "value", "standard_error", "unit"],
                  results_rows(fit, inp.results, sec), img_meta)
        for name, fig in figs.items():
            write_figure_png(tmp / name, fig, img_meta)
        result["files"] = ["sensor.toml", "calibration.csv", "calibration.json", "report.md", *figs]
        write_text(tmp / "report.md", report_markdown(result, list(figs)))
        write_json(tmp / "calibration.json", result)
    return result
