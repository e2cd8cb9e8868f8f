"""The report of ``bench-sim calibrate``: the results table (value, standard error, unit), the
photon-transfer figures (the calibrated model over the data, the fit residuals) and
``report.md`` (:mod:`bench_sim.workflows.calibrate`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.io import markdown_table
from bench_sim.measure.calibration import CameraFit
from bench_sim.sensor.model import stage_mean_var_dn
from bench_sim.sensor.saturation import stage_variance_dn2_clipped
from bench_sim.workflows.calibrate_inputs import CalibrationInput

__all__ = ["results_rows", "figures", "report_markdown", "FIT_QUANTITIES"]

#: (label, value attribute, standard-error attribute or None, unit) of the table and the report
FIT_QUANTITIES: tuple[tuple[str, str, str | None, str], ...] = (
    ("K", "k_dn_per_e", "k_se", "DN/e-"),
    ("responsivity R", "responsivity_dn_per_photon", "responsivity_se", "DN/photon"),
    ("quantum efficiency", "quantum_efficiency", "quantum_efficiency_se", "1"),
    ("dark variance sigma_y.dark^2", "dark_var_dn2", "dark_var_se", "DN^2"),
    ("dark noise sigma_d", "dark_noise_e", "dark_noise_e_se", "e-"),
    ("dark offset", "dark_offset_dn", None, "DN"),
    ("dark current (mean)", "dark_current_e_s", "dark_current_e_s_se", "e-/s"),
    ("dark current (variance)", "dark_current_from_variance_e_s", None, "e-/s"),
    ("saturation photons mu_p.sat", "photons_sat", None, "photons"),
    ("saturation capacity mu_e.sat", "saturation_capacity_e", "saturation_capacity_e_se", "e-"),
    ("plateau signal", "plateau_dn", None, "DN"),
    ("sensitivity threshold mu_p.min", "photons_min", None, "photons"),
    ("dynamic range", "dynamic_range_db", None, "dB"),
    ("SNR max", "snr_max", None, "1"),
    ("chi2_red of the K fit", "chi2_red_k", None, "1"),
    ("chi2_red of the R fit", "chi2_red_r", None, "1"),
)
_PUBLISHED_UNITS = {
    "K_dn_per_e": "DN/e-", "qe": "1", "wavelength_nm": "nm", "dark_noise_e": "e-",
    "saturation_capacity_e": "e-", "dark_current_e_per_s": "e-/s", "dsnu_e": "e-", "prnu_percent": "%",
    "bits": "bits", "exposure_s": "s",
}


def results_rows(
    fit: CameraFit | None, published: dict[str, float], sensor: dict[str, Any]
) -> list[list[Any]]:
    """``calibration.csv``'s rows: the fitted (or published) quantities, then the sensor keys."""
    rows: list[list[Any]] = []
    if fit is not None:
        for label, attr, se, unit in FIT_QUANTITIES:
            v = float(getattr(fit, attr))
            e = float(getattr(fit, se)) if se else math.nan
            rows.append([label, v, "" if math.isnan(e) else e, unit])
    for key, v in published.items():
        rows.append([key, float(v), "", _PUBLISHED_UNITS.get(key, "")])
    for key, v in sensor.items():
        rows.append([f"sensor.{key}", float(v), "", "model"])
    return rows


def _model_curves(inp: CalibrationInput, cfg: BenchConfig) -> tuple[np.ndarray, np.ndarray]:
    """The calibrated model's mean signal [DN] and temporal variance [DN^2] of a single read at
    every lit level of the table (each at its exposure time)."""
    tab = inp.table
    assert tab is not None
    s = cfg.sensor
    sig, var = np.empty(tab.photons.size), np.empty(tab.photons.size)
    for i, (p, t) in enumerate(zip(tab.photons, tab.exposure_s, strict=True)):
        mean, _ = stage_mean_var_dn(p, s, float(t), 1)
        dark, _ = stage_mean_var_dn(0.0, s, float(t), 1)
        top = s.pixel_saturation_dn - float(dark)  # the mean cannot pass the clip
        sig[i] = min(float(mean - dark), top, s.conversion_gain_dn_per_e * s.full_well_e)
        var[i] = float(stage_variance_dn2_clipped(p, s, float(t), 1, beta_bits=32, pedestal_dn=0.0))
    return sig, var


def figures(inp: CalibrationInput, fit: CameraFit, cfg: BenchConfig) -> dict[str, Any]:
    """``ptc.png`` (signal, variance and SNR versus photons: data and calibrated model) and
    ``residuals.png`` (relative residuals of the K and R fits in the linear range)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tab = inp.table
    assert tab is not None
    p = tab.photons
    sig = tab.mean_dn - tab.dark_mean_dn
    msig, mvar = _model_curves(inp, cfg)
    lin = fit.linear
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.5))
    ax = axes[0]
    ax.loglog(p, np.maximum(sig, 1e-3), "o", ms=3, label="data")
    ax.loglog(p, np.maximum(msig, 1e-3), "-", lw=1, label="calibrated model")
    ax.set(xlabel=r"$\mu_p$ [photons/pixel]", ylabel=r"$\mu_y - \mu_{y.dark}$ [DN]", title="Response")
    ax = axes[1]
    ax.loglog(p, np.maximum(tab.var_dn2, 1e-3), "o", ms=3, label="data")
    ax.loglog(p[lin], tab.var_dn2[lin], "o", ms=5, mfc="none", label="linear range (fit)")
    ax.loglog(p, np.maximum(mvar, 1e-3), "-", lw=1, label="calibrated model")
    ax.axvline(fit.photons_sat, color="k", lw=0.6, ls="--", label="saturation (variance max)")
    ax.set(xlabel=r"$\mu_p$ [photons/pixel]", ylabel=r"$\sigma_y^2$ [DN$^2$]", title="Photon transfer")
    ax = axes[2]
    ok = np.isfinite(fit.snr) & (fit.snr > 0)
    ax.loglog(p[ok], fit.snr[ok], "o", ms=3, label="data")
    msnr = np.maximum(msig, 1e-9) / np.sqrt(np.maximum(mvar, 1e-12))
    ax.loglog(p, msnr, "-", lw=1, label="calibrated model")
    ax.axhline(1.0, color="k", lw=0.5)
    ax.set(xlabel=r"$\mu_p$ [photons/pixel]", ylabel="SNR", title="SNR")
    for a in axes:
        a.grid(True, which="both", lw=0.3)
        a.legend(fontsize=7)
    fig.tight_layout()
    out = {"ptc.png": fig}
    fig2, ax2 = plt.subplots(figsize=(7, 4))
    x = sig[lin]
    ax2.plot(x, fit.k_fit.residuals / tab.var_dn2[lin], "o", ms=4, label=r"K fit: residual / $\sigma_y^2$")
    ax2.plot(x, fit.r_fit.residuals / np.maximum(x, 1e-9), "s", ms=4, label=r"R fit: residual / signal")
    ax2.axhline(0.0, color="k", lw=0.5)
    ax2.set(xlabel=r"$\mu_y - \mu_{y.dark}$ [DN]", ylabel="relative residual",
            title="Residuals of the weighted fits (linear range)")
    ax2.grid(True, lw=0.3)
    ax2.legend(fontsize=8)
    fig2.tight_layout()
    out["residuals.png"] = fig2
    return out


def _num(v: Any) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return f"{v:.5g}" if isinstance(v, float) else str(v)


def _dr_lines(dr: dict[str, Any] | None) -> list[str]:
    if dr is None:
        return ["Not computed (chain measurement switched off)."]
    names = {"gamma1": f"Gamma1 (stage {dr['mu1']})", "gamma2": f"Gamma2 (stage {dr['mu2']})",
             "gamma_hdr": "Gamma_HDR (eq. 11)"}
    rows = [
        [names[k], _num(v["closed_form_clip_db"]), _num(v["closed_form_emva_db"]), _num(v["chain_db"]),
         _num(v["chain_extrapolated_db"]), "yes" if v["agree"] else "**no**"]
        for k, v in dr["images"].items()
    ]
    head = ["image", "closed form, clip [dB]", "closed form, EMVA [dB]", "chain, EMVA [dB]",
            "chain, clip [dB]", f"EMVA agrees within {dr['agree_db']} dB"]
    return [
        *markdown_table(head, rows),
        "",
        "EMVA: saturation at the maximum of the temporal variance (EMVA 1288; what `reproduce` "
        "measures); clip: where the linear response meets the clipped plateau. Photons per pixel "
        f"per frame; measurement pedestal {dr['pedestal_dn']} DN.",
    ]


def report_markdown(result: dict[str, Any], figs: list[str]) -> str:
    """``report.md`` from ``calibration.json``'s dict."""
    lines = [
        "# Camera calibration (EMVA 1288) and its DTDI dynamic range", "",
        f"Input: `{result['input']}` ({result['input_kind']}); bench_sim {result['version']}, "
        f"seed {result['seed']}, config sha256 `{result['config_sha256'][:12]}`.", "",
    ]
    fit = result["fit"]
    if fit is not None:
        lines += ["## Fit (weighted least squares, EMVA 1288 Release 4)", ""]
        rows = [[label, _num(fit[a]), _num(fit[s]) if s else "-", u] for label, a, s, u in FIT_QUANTITIES]
        lines += [*markdown_table(["quantity", "value", "standard error", "unit"], rows), ""]
        lines += [
            f"Exposure time {fit['exposure_s']:.6g} s; ADC {fit['bits']} bits"
            f"{' (inferred from the largest mean)' if fit['bits_inferred'] else ''}; saturation at level "
            f"{fit['saturation_index'] + 1} of the lit levels."
            + (" Dark noise at the quantisation limit (0.24 DN^2): an upper bound."
               if fit["dark_noise_quantization_limited"] else ""), "",
        ]
    if result["published"]:
        lines += ["## Published EMVA 1288 results", ""]
        pub = [[k, _num(v)] for k, v in result["published"].items()]
        lines += [*markdown_table(["quantity", "value"], pub), ""]
    mc = result["model_check"]
    sensor = [[f"`{k}`", _num(float(v))] for k, v in result["sensor"].items()]
    lines += [
        "## Calibrated sensor (`sensor.toml`)", "",
        *markdown_table(["key", "value"], sensor), "",
        f"Kept from the base config: {', '.join(result['kept_from_base']) or 'nothing'}.", "",
        f"Check: the calibrated model gives a saturation capacity of {mc['saturation_capacity_e']:.5g} e- "
        f"(variance maximum of one read) and a dark noise of {mc['dark_noise_e']:.4g} e- at "
        f"{mc['exposure_s']:.6g} s.", "",
        f"## Predicted DTDI dynamic range (stages {result['stages'][0]}, {result['stages'][1]})", "",
        *_dr_lines(result["dynamic_range"]), "",
    ]
    if figs:
        lines += ["## Figures", "", *(f"![{f}]({f})" for f in figs), ""]
    return "\n".join(lines)
