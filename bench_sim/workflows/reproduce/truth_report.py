"""The report's section on Gamma_HDR against its exact truth (every sentence from the numbers of
:class:`bench_sim.workflows.reproduce.result.TruthResult`)."""

from __future__ import annotations

from typing import Any

from bench_sim.io import markdown_table
from bench_sim.measure.fusion_scores import RULES
from bench_sim.workflows.reproduce.truth_figures import ERROR_FIGURE, LIGHT_RATIO_FIGURE
from bench_sim.workflows.reproduce.wording import pct

__all__ = ["truth_section", "clipped_source_sentence", "truth_winner"]

_REGIONS = {"whole": "whole image", "spot": "under the spot", "fill": "under the fill",
            "spot_edge": "where r leaves 1 +- tol (spot edge; target edges along the track)"}


def _pct(x: float | None, sign: bool = True) -> str:
    return pct(x, 2, sign)


def clipped_source_sentence(t: dict[str, Any], mu2: int) -> str:
    """How many of eq. 11's Gamma_HDR pixels come from a stage clipped there (never "0 %" unless
    so): by the truth's clip flags (pixel, ADC or word, either stage) and by the words at their top."""
    e = t["rules"]["eq11"]
    n, frac, top = e["from_clipped_pixels"], e["from_clipped_fraction"], e["from_word_top_fraction"]
    if n == 0:
        return "No Gamma_HDR pixel is taken from a clipped stage (the truth's clip flags of both stages)."
    return (
        f"{pct(frac, 2)} of Gamma_HDR's pixels ({n}) are taken from a stage that clipped there (the "
        f"truth's clip flags: pixel, ADC or word, stage {mu2} or the other); {pct(top, 2)} from a stage "
        "word at its top, a count anyone can redo from gamma1.tiff and gamma2.tiff. Eq. 11 keeps "
        f"Gamma2 wherever Gamma1 predicts it inside the word, where stage {mu2} may already have "
        "clipped, and takes the scaled Gamma1 elsewhere, clipped or not."
    )


def truth_winner(t: dict[str, Any]) -> tuple[str, str]:
    """``(rule, region)``: the rule with the lower RMS relative error over the whole image (ties:
    eq. 11) and the region where eq. 11 errs most."""
    rms = {k: v["error"]["whole"]["rms"] for k, v in t["rules"].items()}
    best = min(rms, key=lambda k: (float("inf") if rms[k] is None else rms[k], k != "eq11"))
    worst = max(
        (k for k, v in t["rules"]["eq11"]["error"].items() if v["rms"] is not None),
        key=lambda k: t["rules"]["eq11"]["error"][k]["rms"],
    )
    return best, worst


def truth_section(t: dict[str, Any], mu1: int, mu2: int) -> list[str]:
    """``## Gamma_HDR against its exact truth``: where and why eq. 11 is wrong, with numbers."""
    lr = t["light_ratio"]
    tol = lr["tolerance"]
    rules = t["rules"]
    rows = []
    for region, label in _REGIONS.items():
        rows.append([label, *(
            f"{_pct(rules[k]['error'][region]['bias'])} / {_pct(rules[k]['error'][region]['rms'], False)}"
            for k in rules
        ), str(t["region_pixels"][region])])
    clipped = (pct(rules[k]["from_clipped_fraction"], 2) for k in rules)
    rows.append(["from a clipped stage", *clipped, ""])
    best, worst = truth_winner(t)
    winner = RULES[best]
    edge = rules["eq11"]["error"]["spot_edge"]
    why = (
        f"The light per row changes over the TDI window: r, the mean light per row over the {mu2} rows "
        f"of stage {mu2} against that over the {mu1} rows of stage {mu1}, leaves 1 +- {tol:g} on "
        f"{pct(lr['outside_fraction'], 2)} of the pixels (1st-99th percentile "
        f"{lr['p01']:.3f}-{lr['p99']:.3f}, "
        f"largest |r - 1| = {lr['max_abs_dev']:.2f}). Eq. 11 assumes Gamma2 = (mu2/mu1) Gamma1, i.e. "
        "r = 1; where r != 1 the branch from Gamma1 is off by 1/r, and Gamma2 may clip where Gamma1 "
        "says it does not."
    )
    if edge["bias"] is not None:
        why += (f" Along the spot edge eq. 11's Gamma_HDR is {_pct(edge['bias'])} off the truth on "
                f"average (RMS {_pct(edge['rms'], False)}).")
    return [
        "## Gamma_HDR against its exact truth",
        "",
        f"The truth is the exact expected stage-{mu2} signal without any clip (the pass's `linear_dn` "
        f"less the stage offset); both rules fuse the same stages {mu1} and {mu2} of the same pass. "
        "Relative errors (Gamma_HDR - truth) / truth, bias / RMS per region; they include the temporal "
        "noise of each pixel:",
        "",
        *markdown_table(["region", *(RULES[k] for k in rules), "pixels"], rows),
        "",
        clipped_source_sentence(t, mu2),
        "",
        why,
        "",
        f"By the truth, **{winner}** has the lowest RMS error over the whole image ("
        + ", ".join(f"{RULES[k]} {_pct(v['error']['whole']['rms'], False)}" for k, v in rules.items())
        + f"); eq. 11 is the paper's rule. Eq. 11 errs most in the region '{_REGIONS[worst]}'. "
        "What helps: flatter illumination along the track (r -> 1), a stage pair with a shorter window "
        "(smaller mu2), or a rule that never takes a clipped stage.",
        "",
        f"![relative error against truth]({ERROR_FIGURE})",
        "",
        f"![TDI window light ratio]({LIGHT_RATIO_FIGURE})",
        "",
    ]
