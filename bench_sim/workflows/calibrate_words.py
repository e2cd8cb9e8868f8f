"""The sentences of ``calibrate``'s report: every number of ``report.md`` said in words with what
it is, where it comes from and how sure it is (:mod:`bench_sim.workflows.calibrate_report`).

* the fit (:func:`fit_lines`): the exposure times behind it, a misfit of the linear model in
  words with its size (and the rule that widens the errors), the linearity error, where the camera
  clips, what the table does not give;
* an image input (:func:`frames_lines`): defect pixels, the two DSNUs, PRNU, the row noise;
* the twin (:func:`twin_lines`) and the DTDI prediction (:func:`dr_lines`): what clips each image,
  the output word's cap and the width that removes it, the measurement pedestal.
"""

from __future__ import annotations

import math
from typing import Any

from bench_sim.io import markdown_table
from bench_sim.metrics.weighted_fit import MISFIT_QUANTILE

__all__ = ["num", "fit_lines", "frames_lines", "twin_lines", "dr_lines", "CLIP_WORDS"]

#: What each clip means, in words
CLIP_WORDS = {
    "adc": "the ADC (the values pile up at its top code: the plateau's variance collapses to ~0)",
    "full_well": "the pixel's full well (the read noise after the clip stays: the plateau's variance is the "
    "dark variance)",
    "both": "both the full well and the ADC (the plateau's variance lies between 0 and the dark variance)",
    "unknown": "not known (the data end at the variance maximum)",
    "word": "the output word (the stage sum reaches 2**beta - 1 before its pixels or the ADC clip)",
}


def num(v: Any) -> str:
    """A value for a table: 5 significant digits, ``-`` for none."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return f"{v:.5g}" if isinstance(v, float) else str(v)


def _exposure_line(fit: dict[str, Any]) -> str:
    lo, hi, med = fit["exposure_min_s"], fit["exposure_max_s"], fit["exposure_s"]
    if math.isclose(lo, hi, rel_tol=1e-9):
        return f"Every level was taken at {med:.6g} s: the dark noise and the saturation are at that time."
    return (
        f"Exposure times of the lit levels: {lo:.6g} to {hi:.6g} s (median {med:.6g} s, the twin's reference "
        "exposure); the dark noise is the dark variance's intercept at 0 s, the dark current the slope of "
        "the dark mean over the exposure times."
    )


def _misfit_line(fit: dict[str, Any]) -> str:
    red = fit["chi2_red_k"]
    if fit["k_misfit"]:
        scale = math.sqrt(red)
        return (
            "**The linear photon-transfer model does not fit the data within their errors**: chi2_red = "
            f"{red:.3g} "
            f"(above its {MISFIT_QUANTILE:.0%} quantile), so the points scatter about the line by "
            f"{scale:.3g} times "
            "the error their pixel count gives. The standard errors of the table are widened by "
            f"sqrt(chi2_red) = {scale:.3g} (Birge's rule); K's statistical error alone is "
            f"{fit['k_se_statistical']:.3g}."
        )
    if math.isfinite(red):
        return f"The photon-transfer line fits the data within their errors (chi2_red = {red:.3g})."
    return ""


def fit_lines(fit: dict[str, Any]) -> list[str]:
    """The fit in words."""
    out = [_exposure_line(fit), "", _misfit_line(fit), ""]
    bits = f"ADC {fit['bits']} bits" + (" (inferred from the largest mean)" if fit["bits_inferred"] else "")
    out.append(
        f"{bits}; saturation (variance maximum) at lit level {fit['saturation_index'] + 1}"
        + (
            ", the last level: **the saturation capacity is a lower bound**."
            if fit["saturation_lower_bound"]
            else "."
        )
    )
    out += [
        "",
        f"The camera clips on {CLIP_WORDS[fit['clips_on']]}"
        + (
            f"; plateau variance {fit['plateau_var_dn2']:.3g} DN^2."
            if math.isfinite(fit["plateau_var_dn2"])
            else "."
        ),
    ]
    if math.isfinite(fit["linearity_error_percent"]):
        out += [
            "",
            f"Linearity error LE = {fit['linearity_error_percent']:.3g} +- "
            f"{fit['linearity_error_se_percent']:.2g} % "
            "(EMVA 1288 R4: half the spread of the relative deviations from the weighted line over 5-95 % of "
            "the saturation signal)."
            + (
                f" The response is non-linear: a degree-{fit['response_degree']} polynomial fits it, and "
                f"K, QE and "
                "the saturation capacity are those of the linearised data."
                if fit["linearized"]
                else ""
            ),
        ]
    if not fit["qe_known"]:
        out += [
            "",
            "**Quantum efficiency and responsivity: unknown** (the table has no photon calibration); "
            "K, the dark noise and the saturation are given in DN and e-.",
        ]
    if fit["dark_noise_quantization_limited"]:
        out += ["", "Dark noise at the quantisation limit (0.24 DN^2): an upper bound."]
    return out


def _rms(d: dict[str, Any], part: str, unit: str) -> str:
    return f"{d[f'{part}{unit}']:.4g} +- {d[f'{part}_se{unit}']:.2g}"


def frames_lines(fr: dict[str, Any]) -> list[str]:
    """An image input's defects, non-uniformities and row noise in words."""
    d = fr["defects"]
    counts = ", ".join(f"{v} {k}" for k, v in d["counts"].items()) or "none"
    th = d["thresholds"]
    out = [
        f"Defect pixels (EMVA 1288 R4: outliers of the DSNU image, the PRNU image and the dark temporal "
        f"variance, beyond {th['sigmas']:.3g} robust standard deviations, {th['false_alarms_per_image']:g} "
        f"false "
        f"detections expected per image; hot from {th['hot_dark_current_e_s']:g} e-/s of excess dark "
        f"current): "
        f"{counts}; kept out of every mean, variance, DSNU, PRNU and the dark-current fit "
        f"({fr['good_pixels']} pixels used). Their map: `defects.csv`; histograms: `defects.png`.",
        "",
    ]
    sp = fr["spatial"]
    out.append(
        f"DSNU at {sp['exposure_s']:.6g} s: {_rms(sp['dsnu_e'], 'total', '_e')} e- (column "
        f"{_rms(sp['dsnu_e'], 'column', '_e')}, row {_rms(sp['dsnu_e'], 'row', '_e')}, pixel "
        f"{_rms(sp['dsnu_e'], 'pixel', '_e')}); PRNU {100 * sp['prnu']['total']:.3g} % at "
        f"{sp['prnu_level_signal_dn']:.5g} DN."
    )
    split = fr["dsnu_split"]
    if split is not None:
        out += [
            "",
            f"DSNU split over {len(split['exposures_s'])} dark exposure times (a line per pixel): the offset "
            f"pattern at 0 s {_rms(split['dsnu0_e'], 'total', '_e')} e- (pixel part "
            f"{_rms(split['dsnu0_e'], 'pixel', '_e')}, column part "
            f"{_rms(split['dsnu0_e'], 'column', '_e')}), the "
            f"dark current {split['dark_current_mean_e_s']:.4g} e-/s with a non-uniformity of "
            f"{_rms(split['dark_current_nu_e_s'], 'total', '_e_s')} e-/s.",
        ]
    rn = fr["row_noise"]
    if rn is not None:
        out += [
            "",
            f"Temporal row noise (variance of a row's mean beyond the pixels' own): {rn['var_dn2']:.3g} +- "
            f"{rn['var_se_dn2']:.2g} DN^2 per read.",
        ]
    return out


def twin_lines(result: dict[str, Any]) -> list[str]:
    """The twin's keys and what they rest on."""
    sensor = [[f"`{k}`", num(float(v))] for k, v in result["sensor"].items() if k != "effects"]
    effects = [
        f"- `[sensor.effects.{n}]`: "
        + ", ".join(f"{k} = {num(v) if not isinstance(v, str) else v}" for k, v in e.items())
        for n, e in result["sensor"].get("effects", {}).items()
    ]
    mc = result["model_check"]
    out = [*markdown_table(["key", "value"], sensor), ""]
    if effects:
        out += ["Effects (the twin follows the camera beyond the linear model):", "", *effects, ""]
    out += [f"Kept from the base config: {', '.join(result['kept_from_base']) or 'nothing'}.", ""]
    if result["unknown"]:
        out += [f"Unknown (not in the input, not invented): {'; '.join(result['unknown'])}.", ""]
    out += [*result["notes"], ""] if result["notes"] else []
    out.append(
        f"Check: the twin's own saturation capacity is {mc['saturation_capacity_e']:.5g} e- (variance "
        f"maximum "
        f"of one read, linear model) and its dark noise {mc['dark_noise_e']:.4g} e- at "
        f"{mc['exposure_s']:.6g} s."
    )
    return out


def _cap_lines(dr: dict[str, Any]) -> list[str]:
    out = []
    for cap in dr["word_caps"]:
        wider = (
            f"a word of {cap['word_bits_without_cap']} bits removes the cap"
            if cap["word_bits_without_cap"]
            else "no word up to 32 bits removes it"
        )
        below = (
            f", **below the camera's single-frame {cap['single_frame_dr_db']:.3g} dB**"
            if cap["below_single_frame"]
            else ""
        )
        out.append(
            f"**Warning**: the {cap['beta_bits']}-bit output word caps stage {cap['stage']}: it clips on the "
            f"word at {cap['dr_db']:.3g} dB{below}; {wider} (`dtdi.beta_bits`)."
        )
    return out


def dr_lines(dr: dict[str, Any]) -> list[str]:
    """The DTDI prediction: per image its DR and what clips it, the word's caps, the pedestal."""
    names = {
        "gamma1": f"Gamma1 (stage {dr['mu1']})",
        "gamma2": f"Gamma2 (stage {dr['mu2']})",
        "gamma_hdr": "Gamma_HDR (eq. 11)",
    }
    rows = [
        [
            names[k],
            _clip_word(v["clips_on"]),
            num(v["closed_form_clip_db"]),
            num(v["closed_form_emva_db"]),
            num(v["chain_db"]),
            num(v["chain_extrapolated_db"]),
            "-" if v["agree"] is None else ("yes" if v["agree"] else "**no**"),
        ]
        for k, v in dr["images"].items()
    ]
    head = [
        "image",
        "clips on",
        "closed form, clip [dB]",
        "closed form, EMVA [dB]",
        "chain, EMVA [dB]",
        "chain, clip [dB]",
        f"EMVA agrees within {dr['agree_db']} dB",
    ]
    ped = dr["pedestal_dn"]
    ped_words = (
        f"the configured `dtdi.pedestal_dn` ({dr['configured_pedestal_dn']} DN)"
        if ped == dr["configured_pedestal_dn"]
        else f"`dtdi.pedestal_dn` = {dr['configured_pedestal_dn']} DN raised to {ped} DN to keep stage "
        f"{dr['mu2']}'s dark value 5 standard deviations above 0 DN"
    )
    return [
        *markdown_table(head, rows),
        "",
        *_cap_lines(dr),
        "" if dr["word_caps"] else "",
        f"The camera's single-frame DR (one read, no output word): {dr['single_frame_dr_db']:.4g} dB. The "
        f"output "
        f"word: {dr['beta_bits']} bits (the base config's `dtdi.beta_bits`). Gamma_HDR saturates where "
        f"Gamma1 does.",
        "",
        "EMVA: saturation at the maximum of the temporal variance (EMVA 1288; what `reproduce` measures); "
        "clip: "
        "where the linear response meets the clipped plateau. Photons per pixel per frame. The chain "
        "measurement's "
        f"word pedestal is {ped_words} (`bench_sim.measure.uniform_field.measurement_pedestal_dn`).",
    ]


def _clip_word(kind: str) -> str:
    return {
        "adc": "ADC",
        "full_well": "pixel (full well)",
        "word": "output word",
        "both": "pixel and ADC",
    }.get(kind, kind)
