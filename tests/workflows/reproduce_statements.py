"""Checks of ``report.md``'s statements against the numbers they are about.

Each check parses a sentence of the report (regular expressions on the text, not the report
writer's own formatting code) and compares what it says with ``metrics.json``'s dict ``m``: which
input is "the better input", every percentage ("0%" only where the number is exactly 0), which
stage clips on what, the verdicts of the paper's claims, the rankings, and the labels of every SNR
(spatial or temporal) and of the ratio of the read-noise floors. :func:`check_report` returns the names of the
checks that found their sentence (so that a test can require the statements to be there) and raises
``AssertionError`` naming the first false one.
"""

from __future__ import annotations

import math
import re
from typing import Any

NAMES = {"Gamma1": "gamma1", "Gamma2": "gamma2", "Gamma_HDR": "gamma_hdr"}
NUM = r"[-+]?\d[\d,]*(?:\.\d+)?(?:e[-+]?\d+)?"
PCT = r"(?:[<>]?[-+]?\d+(?:\.\d+)?%)"
AGREE_DB = 0.5
SNR_IN_NOISE, SNR_ROSE = 2.0, 3.0  # the paper's claims: "in the noise" below 2, Rose criterion 3


def num(text: str) -> float:
    return float(text.replace(",", ""))


def frac_ok(token: str, x: float | None) -> bool:
    """Whether a percentage token states the fraction ``x`` honestly: "0%" only for exactly 0,
    "100%" only for exactly 1, otherwise the value within half its last decimal."""
    if x is None:
        return token == "n/a"
    if token.startswith("<"):
        return 0 < abs(x) < 1e-8
    if token.startswith(">"):
        return 1 - 1e-8 < x < 1
    value = float(token.rstrip("%"))
    if value == 0 or abs(value) == 100:
        return 100 * x == value
    decimals = len(token.rstrip("%").split(".")[1]) if "." in token else 0
    return abs(100 * x - value) <= 0.5 * 10.0**-decimals + 1e-9


def _close(text: str, x: float, decimals: int) -> bool:
    return abs(num(text) - x) <= 0.5 * 10.0**-decimals + 1e-9


def _better(dr: dict[str, float]) -> str:
    return "gamma1" if dr["gamma1"] >= dr["gamma2"] else "gamma2"


def _clip_word(flag: bool, beta: int) -> str:
    return f"the {beta}-bit output word" if flag else "the pixel (full well / ADC top)"


def check_dr(text: str, m: dict[str, Any]) -> list[str]:
    """The DR section: the better input and the gains over it, the clip causes, eq. 15, the
    ends of Gamma_HDR, the read-noise floors' ratio and the switch."""
    found = []
    dr, model = m["dr_db"], m["dr_details"]["model_dr_db"]
    g = re.search(rf"Gain over the better input \(by measured DR\), (Gamma[12]): ({NUM}) dB\*\* \(sensor "
                  rf"model: ({NUM}) dB; DR Gamma1 ({NUM}) dB, Gamma2 ({NUM}) dB\)", text)
    assert g, "no gain over the better input"
    better = NAMES[g[1]]
    assert better == _better(dr), f"{g[1]} called the better input with DRs {dr}"
    assert _close(g[2], dr["gamma_hdr"] - dr[better], 2)
    assert _close(g[3], model["gamma_hdr"] - model[better], 2)
    assert _close(g[4], dr["gamma1"], 2) and _close(g[5], dr["gamma2"], 2)
    found.append("better_input")
    for name in re.findall(r"the gain over the better input \((Gamma[12])\) above is the informative", text):
        assert NAMES[name] == better
    g1 = re.search(rf"\. Gain over Gamma1: ({NUM}) dB\.", text)
    assert (g1 is not None) == (better == "gamma2")
    if g1:
        assert _close(g1[1], dr["gamma_hdr"] - dr["gamma1"], 2)
    g2 = re.search(rf"Gain over Gamma2: ({NUM}) dB \(({NUM}) dB with the extrapolated saturation points\), "
                   rf"against eq\. 15's 20 lg\((\d+)/(\d+)\) = ({NUM}) dB \((agrees|\*\*differs\*\*|"
                   r"\*\*does not agree\*\*)", text)
    assert g2, "no gain over Gamma2"
    ext = m["dr_db_extrapolated"]
    assert _close(g2[1], dr["gamma_hdr"] - dr["gamma2"], 2)
    assert _close(g2[2], ext["gamma_hdr"] - ext["gamma2"], 2)
    eq15 = 20 * math.log10(m["mu2"] / m["mu1"])
    assert (int(g2[3]), int(g2[4])) == (m["mu2"], m["mu1"]) and _close(g2[5], eq15, 2)
    assert (g2[6] == "agrees") == (abs(ext["gamma_hdr"] - ext["gamma2"] - eq15) <= AGREE_DB)
    found.append("gain_over_gamma2")
    clips, beta = m["stage_clips_on_word"], m["beta"]
    both = re.search(r"Here both stages clip on the (\d+)-bit word", text)
    assert (both is not None) == ("*by construction*" in text)
    if both:
        assert clips["gamma1"] and clips["gamma2"] and int(both[1]) == beta
    each = re.search(r"here stage (\d+) clips on (.+?) and stage (\d+) on (.+?), so", text)
    if each:
        assert int(each[1]) == m["mu1"] and int(each[3]) == m["mu2"]
        assert each[2] == _clip_word(clips["gamma1"], beta) and each[4] == _clip_word(clips["gamma2"], beta)
    assert both or each
    row = re.search(r"\| the stage clips on \| (.+?) \| (.+?) \|", text)
    assert row and row[1] == _clip_word(clips["gamma1"], beta) and row[2] == _clip_word(clips["gamma2"], beta)
    found.append("clip_causes")
    return found + check_ends(text, m) + check_switch(text, m)


def check_ends(text: str, m: dict[str, Any]) -> list[str]:
    """Gamma_HDR's saturation and SNR = 1 points against its inputs', the noise floor's drop."""
    img = m["dr_details"]["images"]
    e = re.search(rf"Gamma_HDR saturates at ({NUM}) photons per pixel per frame \((Gamma1's saturation end|"
                  rf"not Gamma1's ({NUM}))\) and reaches SNR = 1 at ({NUM}) \((stage (\d+)'s dark end|not "
                  rf"stage (\d+)'s ({NUM}))\); its noise floor lies ({NUM}) dB (below|above) Gamma1's "
                  rf"\(({NUM})\), a temporal SNR gain of ({NUM}) at the noise floor", text)
    if e is None:
        return []
    sat = {k: img[k]["photons_sat"] for k in NAMES.values()}
    low = {k: img[k]["photons_min"] for k in NAMES.values()}

    def rel(text_value: str, x: float) -> bool:
        return abs(num(text_value) / x - 1) < 1e-3

    assert rel(e[1], sat["gamma_hdr"]) and rel(e[4], low["gamma_hdr"]) and rel(e[11], low["gamma1"])
    same_sat = abs(20 * math.log10(sat["gamma_hdr"] / sat["gamma1"])) <= AGREE_DB
    assert (e[2] == "Gamma1's saturation end") == same_sat
    assert (e[5].endswith("dark end")) == (abs(20 * math.log10(low["gamma_hdr"] / low["gamma2"])) <= AGREE_DB)
    drop = 20 * math.log10(low["gamma1"] / low["gamma_hdr"])
    assert _close(e[9], abs(drop), 2) and (e[10] == "below") == (drop >= 0)
    assert _close(e[12], low["gamma1"] / low["gamma_hdr"], 2)
    return ["hdr_ends"]


def check_switch(text: str, m: dict[str, Any]) -> list[str]:
    sw = m["fusion_switch"]
    s = re.search(rf"the (\w+) SNR of Gamma_HDR (drops|rises) from ({NUM}) \(Gamma2, at ({NUM}) photons\) "
                  rf"to ({NUM}) \(scaled Gamma1", text)
    if not (math.isfinite(sw["snr_below"]) and math.isfinite(sw["snr_above"])):
        assert s is None
        return []
    assert s and s[1] == "temporal"  # the photon-transfer series: temporal noise
    assert (s[2] == "drops") == (sw["snr_above"] < sw["snr_below"])
    assert _close(s[3], sw["snr_below"], 1) and _close(s[5], sw["snr_above"], 1)
    return ["fusion_switch"]


def check_fractions(text: str, m: dict[str, Any]) -> list[str]:
    """Fig. 3's and Fig. 4's fractions at the word's top, the pedestal note, the pixels taken
    from a clipped Gamma2."""
    sat, beta = m["saturated_fraction"], m["beta"]
    f3 = re.search(rf"Gamma2 \(m = (\d+)\) stores ({PCT}) of its pixels at the top of the (\d+)-bit word, "
                   rf"Gamma1 \(m = (\d+)\) ({PCT})\.", text)
    assert f3 and int(f3[1]) == m["mu2"] and int(f3[4]) == m["mu1"] and int(f3[3]) == beta
    assert frac_ok(f3[2], sat["gamma2"]) and frac_ok(f3[5], sat["gamma1"]), (f3[0], sat)
    top = re.search(rf"Pixels at the top of the (\d+)-bit word: Gamma1 ({PCT}), Gamma2 ({PCT}), "
                    rf"Gamma_HDR ({PCT})", text)
    assert top and int(top[1]) == beta
    for k, tok in zip(("gamma1", "gamma2", "gamma_hdr"), top.groups()[1:], strict=True):
        assert frac_ok(tok, sat[k]), (top[0], sat)
    eq11 = m["fusion_truth"]["rules"]["eq11"]
    none = "No Gamma_HDR pixel is taken from a clipped stage" in text
    # the truth's count is of pixels from either stage clipped there (fusion_scores): never "Gamma2"
    assert "from a clipped Gamma2" not in text
    some = re.findall(rf"({PCT}) of Gamma_HDR's pixels \((\d+)\) are taken from a stage that clipped "
                      r"there \(the truth's clip flags: pixel, ADC or word, stage \d+ or the other\); "
                      rf"({PCT}) from a stage word at its top", text)
    assert none == (eq11["from_clipped_pixels"] == 0) and bool(some) != none
    for frac, n, word in some:
        assert int(n) == eq11["from_clipped_pixels"]
        assert frac_ok(frac, eq11["from_clipped_fraction"]) and frac_ok(word, eq11["from_word_top_fraction"])
    anywhere = re.search(rf"Clipped anywhere \(pixel, ADC or word; the truth's clip flags\): Gamma1 ({PCT}), "
                         rf"Gamma2 ({PCT}), Gamma_HDR ({PCT})\.", text)
    assert (anywhere is not None) == bool(m.get("clipped_fraction"))
    if anywhere:
        for k, tok in zip(("gamma1", "gamma2", "gamma_hdr"), anywhere.groups(), strict=True):
            assert frac_ok(tok, m["clipped_fraction"][k])
    zero = m["darkest_patch"]["word_zero_fraction"]
    clean = "no pixel of the darkest patch is stored as 0 DN" in text
    assert clean == (max(zero.values()) == 0)
    if not clean:
        z = re.search(rf"({PCT}) of the darkest patch's pixels are still stored as 0 DN", text)
        assert z and frac_ok(z[1], max(zero.values()))
    return ["fig3_fractions", "word_top", "from_clipped_gamma2", "pedestal"]


def _row(text: str, claim: str) -> tuple[str, bool]:
    r = re.search(rf"^\| {re.escape(claim)}[^|]* \| (.+?) \| (yes|\*\*no\*\*) \|$", text, re.M)
    assert r, f"no row {claim!r}"
    return r[1], r[2] == "yes"


def check_fig4_table(text: str, m: dict[str, Any]) -> list[str]:
    """The paper's qualitative claims: each measured cell against the numbers, each verdict
    recomputed from them, the SNRs labelled spatial, the read-noise floors' ratio named."""
    dark, bright = m["darkest_patch"], m["brightest_patch"]
    cell, holds = _row(text, f"stage {m['mu2']} saturates the brightly lit region")
    c = re.match(rf"({PCT}) of the (\d+)% patch at the word's top \(the brightest wedge step as lit\)$", cell)
    assert c and frac_ok(c[1], bright["gamma2_saturated_fraction"])
    assert holds == (bright["gamma2_saturated_fraction"] > 0.99)
    cell, holds = _row(text, f"stage {m['mu1']} leaves the darkest patches in the noise")
    c = re.match(rf"spatial SNR ({NUM}) on the (\d+)% patch \(the darkest wedge step as lit\)", cell)
    assert c and _close(c[1], dark["snr"]["gamma1"], 2)
    assert holds == (dark["snr"]["gamma1"] < SNR_IN_NOISE)
    cell, holds = _row(text, "Gamma_HDR keeps the bright detail")
    c = re.match(
        rf"({PCT}) at the word's top, ({PCT}) from a Gamma2 at the word's top .*; "
        rf"stage (\d+) at ({PCT}) of Phi_FS",
        cell,
    )
    hdr_sat = bright["gamma_hdr_saturated_fraction"]
    from_clip = bright["gamma_hdr_from_clipped_gamma2_fraction"]
    assert c and frac_ok(c[1], hdr_sat) and frac_ok(c[2], from_clip)
    assert frac_ok(c[4], bright["gamma1_fraction_of_phi_fs"])
    # with the truth, an SNR cleared to None: at least half of the patch clipped (on the pixels)
    half_clipped = "fusion_truth" in m and bright["snr"].get("gamma_hdr") is None
    assert holds == (hdr_sat == 0 and from_clip == 0 and not half_clipped)
    assert ("at least half of Gamma_HDR's pixels there are clipped" in cell) == half_clipped
    cell, holds = _row(text, "Gamma_HDR lifts the dark detail")
    c = re.match(rf"spatial SNR ({NUM}) \(x({NUM}) over Gamma1's; (.+?)\)", cell)
    s1, sh = dark["snr"]["gamma1"], dark["snr"]["gamma_hdr"]
    assert c and _close(c[1], sh, 2) and _close(c[2], sh / s1, 2)
    assert holds == (sh >= SNR_ROSE and sh >= 1.8 * s1)
    t = dark.get("temporal_snr")  # once the run measures it (from the truth)
    tc = re.search(rf"; temporal SNR ({NUM}) \(x({NUM}) over Gamma1's; ratio of the two stages' read-", cell)
    assert (tc is not None) == bool(t)
    if tc and t:
        assert _close(tc[1], t["gamma_hdr"], 2) and _close(tc[2], t["gamma_hdr"] / t["gamma1"], 2)
    return ["fig4_table"]


def check_labels(text: str, m: dict[str, Any]) -> list[str]:
    """Every SNR labelled spatial or temporal (or the SNR = 1 point of the temporal DR);
    ``sqrt(mu2/mu1)`` named, wherever it appears, as the ratio of the two stages' read-noise floors
    and never as a limit or bound of a measured gain (issue 34: the report's own gain over Gamma1
    exceeds it)."""
    for line in text.splitlines():
        for hit in re.finditer(r"SNR", line):
            before, after = line[: hit.start()], line[hit.end():]
            labelled = before.endswith(("spatial ", "temporal "))
            labelled = labelled or after.startswith((" = 1", " versus", " vs"))
            assert labelled, f"unlabelled SNR: {line[max(0, hit.start() - 60): hit.end() + 30]!r}"
    ratio = f"sqrt({m['mu2']}/{m['mu1']}) = {math.sqrt(m['mu2'] / m['mu1']):.2f}"
    assert ratio in text
    named = re.findall(r"ratio of the two stages' read-noise floors (?:is )?" + re.escape(ratio), text)
    assert text.count(ratio) == len(named), "sqrt(mu2/mu1) not named as the read-noise floors' ratio"

    assert "read-noise limit" not in text and not re.search(r"bounds? (a|the|that) .*gain", text)
    assert not re.search(r"(?<![\d.])0\.0+ ?%|100\.0+ ?%", text), "a fraction printed as 0.0% or 100.0%"
    return ["snr_labels"]


def check_table1(text: str, m: dict[str, Any]) -> list[str]:
    """Eq. 18 (paper and simulation), the omega comparisons and the DR ranking."""
    om, op, dr = m["omega"], m["omega_paper"], m["dr_db"]
    paper18 = op["gamma_hdr"] < min(op["gamma1"], op["gamma2"])
    assert f"Table 1 {'agrees with' if paper18 else 'contradicts'} eq. 18." in text
    holds = om["gamma_hdr"] < min(om["gamma1"], om["gamma2"])
    assert m["eq18_holds"] == holds
    s = re.search(r"In the simulation eq\. 18 (holds|does not hold) \(omega: .+?\): omega\(HDR\) (<|>=) "
                  rf"omega\(Gamma2\), (whose ({PCT}) saturated pixels pile into its top bin|"
                  r"which has no saturated pixels); omega\(HDR\) (<|>=) omega\(Gamma1\)", text)
    assert s and (s[1] == "holds") == holds
    assert (s[2] == "<") == (om["gamma_hdr"] < om["gamma2"])
    assert (s[5] == "<") == (om["gamma_hdr"] < om["gamma1"])
    sat2 = m["saturated_fraction"]["gamma2"]
    assert (s[4] is None) == (sat2 == 0) and (s[4] is None or frac_ok(s[4], sat2))
    rank = re.search(r"ranks the images (\S+) > (\S+) > (\S+?)\.", text)
    assert rank and [NAMES[x] for x in rank.groups()] == sorted(dr, key=dr.__getitem__, reverse=True)
    eq15 = 20 * math.log10(m["mu2"] / m["mu1"])
    e = re.search(r"\*\*26\.02 dB (is|is not) eq\. 15 for (\d+)/(\d+)\.\*\*", text)
    assert e and (e[1] == "is") == (abs(eq15 - 26.02) <= AGREE_DB)
    g2x = m["delta_dr_db_vs_gamma2_extrapolated"]
    assert ("in line with eq. 15's" in text) == (abs(g2x - eq15) <= AGREE_DB)
    assert ("and in line with 26.02 dB" in text) == (abs(g2x - 26.02) <= AGREE_DB)
    return ["table1", "inconsistencies"]


def check_truth(text: str, m: dict[str, Any]) -> list[str]:
    """The truth section: the light ratio's fraction outside the tolerance, the winner by RMS,
    the region where eq. 11 errs most, the clipped fractions per rule."""
    t = m.get("fusion_truth")
    if not t:
        return []
    lr = t["light_ratio"]
    o = re.search(rf"leaves 1 \+- ({NUM}) on ({PCT}) of the pixels", text)
    assert o and float(o[1]) == lr["tolerance"] and frac_ok(o[2], lr["outside_fraction"])
    rules = t["rules"]
    labels = {v["label"]: k for k, v in rules.items()} if all("label" in v for v in rules.values()) else {}
    w = re.search(r"By the truth, \*\*(.+?)\*\* has the lowest RMS error", text)
    rms = {k: v["error"]["whole"]["rms"] for k, v in rules.items()}
    assert w
    if labels and w[1] in labels:
        assert rms[labels[w[1]]] == min(rms.values())
    errs = {k: v["rms"] for k, v in rules["eq11"]["error"].items() if v["rms"] is not None}
    region = re.search(r"Eq\. 11 errs most in the region '(.+?)'", text)
    assert region
    worst = max(errs, key=errs.__getitem__)
    assert region[1].startswith({"whole": "whole", "spot": "under the spot", "fill": "under the fill",
                                 "spot_edge": "where r leaves"}[worst])
    row = re.search(r"^\| from a clipped stage \| (.+?) \|  \|$", text, re.M)
    assert row
    for tok, k in zip(row[1].split(" | "), rules, strict=True):
        assert frac_ok(tok, rules[k]["from_clipped_fraction"])
    edge = rules["eq11"]["error"]["spot_edge"]
    if edge["bias"] is not None:
        e = re.search(rf"on average \(RMS ({PCT})\)", text)
        assert e and frac_ok(e[1], edge["rms"]) and not e[1].startswith(("+", "-"))
    return ["truth"]


def check_report(text: str, m: dict[str, Any]) -> list[str]:
    """Every check above on one report; returns the names of the statements found."""
    return [
        *check_dr(text, m), *check_fractions(text, m), *check_fig4_table(text, m),
        *check_labels(text, m), *check_table1(text, m), *check_truth(text, m),
    ]
