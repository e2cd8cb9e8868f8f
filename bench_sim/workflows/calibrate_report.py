"""The report of ``bench-sim calibrate``: the results table (value, standard error, unit), the
figures (the twin's exact curves over the data, past saturation too; the fit residuals; the DSNU
and PRNU histograms of an image input) and ``report.md``, where every number is said in words
(:mod:`bench_sim.workflows.calibrate`); the sentences about the fit, the twin and the DTDI
prediction are :mod:`bench_sim.workflows.calibrate_words`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bench_sim.io import markdown_table
from bench_sim.metrics.emva_fit import CameraFit
from bench_sim.metrics.frame_series import FrameAnalysis
from bench_sim.metrics.ptc_table import PtcTable
from bench_sim.workflows.calibrate_words import dr_lines, fit_lines, frames_lines, num, twin_lines

__all__ = ["results_rows", "figures", "defects_figure", "report_markdown", "FIT_QUANTITIES"]

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
    ("saturation signal mu_y.sat - mu_y.dark", "saturation_signal_dn", None, "DN"),
    ("plateau signal", "plateau_dn", None, "DN"),
    ("plateau variance", "plateau_var_dn2", None, "DN^2"),
    ("sensitivity threshold mu_p.min", "photons_min", None, "photons"),
    ("dynamic range", "dynamic_range_db", None, "dB"),
    ("SNR max", "snr_max", None, "1"),
    ("linearity error LE", "linearity_error_percent", "linearity_error_se_percent", "%"),
    ("chi2_red of the K fit", "chi2_red_k", None, "1"),
    ("chi2_red of the R fit", "chi2_red_r", None, "1"),
)
_PUBLISHED_UNITS = {
    "K_dn_per_e": "DN/e-",
    "qe": "1",
    "wavelength_nm": "nm",
    "dark_noise_e": "e-",
    "saturation_capacity_e": "e-",
    "dark_current_e_per_s": "e-/s",
    "dsnu_e": "e-",
    "prnu_percent": "%",
    "bits": "bits",
    "exposure_s": "s",
}


def results_rows(
    fit: CameraFit | None, published: dict[str, float], sensor: dict[str, Any]
) -> list[list[Any]]:
    """``calibration.csv``'s rows: the fitted (or published) quantities, then the sensor keys and
    the effects' parameters."""
    rows: list[list[Any]] = []
    if fit is not None:
        for label, attr, se, unit in FIT_QUANTITIES:
            v = float(getattr(fit, attr))
            e = float(getattr(fit, se)) if se else math.nan
            rows.append([label, v, "" if math.isnan(e) else e, unit])
    for key, v in published.items():
        rows.append([key, float(v), "", _PUBLISHED_UNITS.get(key, "")])
    for key, v in sensor.items():
        if key != "effects":
            rows.append([f"sensor.{key}", float(v), "", "model"])
    for name, entry in sensor.get("effects", {}).items():
        for key, v in entry.items():
            if not isinstance(v, str):
                rows.append([f"sensor.effects.{name}.{key}", float(v), "", "model"])
    return rows


def _abscissa(tab: PtcTable) -> tuple[np.ndarray, str]:
    if tab.irradiance is None:
        return np.maximum(tab.signal_dn, 1e-3), r"$\mu_y - \mu_{y.dark}$ [DN]"
    label = {
        "photons": r"$\mu_p$ [photons/pixel]",
        "relative_irradiance": "relative irradiance",
        "exposure": "exposure time [s]",
    }[tab.irradiance_kind]
    return tab.irradiance, label


def _ptc_figure(tab: PtcTable, fit: CameraFit, curve: dict[str, list[float]]) -> Any:
    import matplotlib.pyplot as plt

    x, xlabel = _abscissa(tab)
    sig, var = tab.signal_dn, tab.var_dn2
    msig, mvar = np.asarray(curve["signal_dn"]), np.asarray(curve["var_dn2"])
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.5))
    ax = axes[0]
    ax.loglog(x, np.maximum(sig, 1e-3), "o", ms=3, label="data")
    ax.loglog(x, np.maximum(msig, 1e-3), "-", lw=1, label="twin (exact, its chain)")
    ax.set(xlabel=xlabel, ylabel=r"$\mu_y - \mu_{y.dark}$ [DN]", title="Response")
    ax = axes[1]
    ax.loglog(x, np.maximum(var, 1e-3), "o", ms=3, label="data")
    ax.loglog(x[fit.linear], var[fit.linear], "o", ms=5, mfc="none", label="linear range (K fit)")
    ax.loglog(x, np.maximum(mvar, 1e-3), "-", lw=1, label="twin")
    ax.axvline(x[fit.saturation_index], color="k", lw=0.6, ls="--", label="saturation (variance max)")
    ax.set(
        xlabel=xlabel, ylabel=r"$\sigma_y^2$ [DN$^2$]", title=f"Photon transfer (clips on: {fit.clips_on})"
    )
    ax = axes[2]
    ok = np.isfinite(fit.snr) & (fit.snr > 0)
    ax.loglog(x[ok], fit.snr[ok], "o", ms=3, label="data")
    with np.errstate(divide="ignore"):
        msnr = np.where(mvar > 0, np.maximum(msig, 1e-9) / np.sqrt(np.maximum(mvar, 1e-300)), np.inf)
    fin = np.isfinite(msnr)
    ax.loglog(x[fin], msnr[fin], "-", lw=1, label="twin (variance 0 past the ADC clip: SNR infinite)")
    ax.axhline(1.0, color="k", lw=0.5)
    ax.set(xlabel=xlabel, ylabel="SNR", title="SNR")
    for a in axes:
        a.grid(True, which="both", lw=0.3)
        a.legend(fontsize=7)
    fig.tight_layout()
    return fig


def _residual_figure(tab: PtcTable, fit: CameraFit) -> Any:
    import matplotlib.pyplot as plt

    lin = fit.linear
    fig, ax = plt.subplots(figsize=(7, 4))
    x = tab.signal_dn[lin]
    ax.plot(x, fit.k_fit.residuals / tab.var_dn2[lin], "o", ms=4, label=r"K fit: residual / $\sigma_y^2$")
    if fit.linearity is not None:
        dev = fit.linearity.deviation_percent / 100.0
        ax.plot(
            tab.signal_dn[fit.linearity.in_range],
            dev[fit.linearity.in_range],
            "s",
            ms=4,
            label="linearity: relative deviation from the LE line",
        )
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set(xlabel=r"$\mu_y - \mu_{y.dark}$ [DN]", ylabel="relative residual", title="Residuals")
    ax.grid(True, lw=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def defects_figure(frames: FrameAnalysis) -> Any:
    """The DSNU and PRNU histograms of an image series with the outlier thresholds (R4 section 8)."""
    import matplotlib.pyplot as plt

    hists = frames.defects.histograms
    fig, axes = plt.subplots(1, len(hists), figsize=(6 * len(hists), 4), squeeze=False)
    titles = {
        "dsnu_e_s": ("DSNU image: dark current [e-/s]", "dark current [e-/s]"),
        "prnu_relative": ("PRNU image: relative response", "response / median"),
    }
    for ax, (name, h) in zip(axes[0], hists.items(), strict=True):
        edges, counts = np.asarray(h["edges"]), np.asarray(h["counts"])
        ax.stairs(np.maximum(counts, 0.5), edges)
        for key in ("threshold_low", "threshold_high"):
            ax.axvline(h[key], color="r", lw=0.6, ls="--")
        ax.set_yscale("log")
        ax.set(title=titles[name][0], xlabel=titles[name][1], ylabel="pixels")
        ax.grid(True, lw=0.3)
    fig.tight_layout()
    return fig


def figures(
    tab: PtcTable, fit: CameraFit, curve: dict[str, list[float]], frames: FrameAnalysis | None
) -> dict[str, Any]:
    """``ptc.png`` (signal, variance and SNR: data and the twin's exact curves, past saturation),
    ``residuals.png`` (the K fit's relative residuals, the deviations from the LE line) and, for
    images, ``defects.png`` (the DSNU and PRNU histograms with the outlier thresholds)."""
    import matplotlib

    matplotlib.use("Agg")
    out = {"ptc.png": _ptc_figure(tab, fit, curve), "residuals.png": _residual_figure(tab, fit)}
    if frames is not None and frames.defects.histograms:
        out["defects.png"] = defects_figure(frames)
    return out


def report_markdown(result: dict[str, Any], figs: list[str]) -> str:
    """``report.md`` from ``calibration.json``'s dict."""
    lines = [
        "# Camera calibration (EMVA 1288) and its DTDI dynamic range",
        "",
        f"Input: `{result['input']}` ({result['input_kind']}); bench_sim {result['version']}, "
        f"seed {result['seed']}, config sha256 `{result['config_sha256'][:12]}`.",
        "",
    ]
    fit = result["fit"]
    if fit is not None:
        lines += ["## Fit (weighted least squares, EMVA 1288 Release 4)", ""]
        rows = [[label, num(fit[a]), num(fit[s]) if s else "-", u] for label, a, s, u in FIT_QUANTITIES]
        lines += [
            *markdown_table(["quantity", "value", "standard error", "unit"], rows),
            "",
            *fit_lines(fit),
            "",
        ]
    if result.get("frames"):
        lines += [
            "## From the images: defect pixels, non-uniformity, row noise",
            "",
            *frames_lines(result["frames"]),
            "",
        ]
    if result["published"]:
        lines += ["## Published EMVA 1288 results", ""]
        lines += [
            *markdown_table(["quantity", "value"], [[k, num(v)] for k, v in result["published"].items()]),
            "",
        ]
    lines += ["## The twin (`sensor.toml`)", "", *twin_lines(result), ""]
    lines += [
        f"## Predicted DTDI dynamic range (stages {result['stages'][0]}, {result['stages'][1]})",
        "",
        *dr_lines(result["dynamic_range"]),
        "",
    ]
    if figs:
        lines += ["## Figures", "", *(f"![{f}]({f})" for f in figs), ""]
    return "\n".join(lines)
