"""The compiled sums of many fusions (``bench_sim.metrics.fusion_sums``) against the numpy functions
they stand for: eq. 11 (``fuse_dtdi_hdr_eq11``) and the clip-aware rule
(``fuse_stages_highest_unsaturated``, two and three stages) of the same words, their relative
error against the truth per region, the pixels from a clipped stage, and the darkest region's
signal and variance. Synthetic stage words with ties at eq. 11's threshold and at the saturation
levels, truth below 1 DN, stages without light and words at the word's top."""

from __future__ import annotations

import numpy as np
import pytest

from bench_sim.fusion.multistage import fuse_stages_highest_unsaturated
from bench_sim.fusion.paper import fuse_dtdi_hdr_eq11
from bench_sim.metrics.fusion_sums import FIELDS, REGIONS, RULE_EQ11, RULE_SAT, fusion_sums
from bench_sim.metrics.fusion_truth import (
    LIGHT_RATIO_TOLERANCE,
    clip_flags,
    clip_regions,
    from_clipped_stage,
    relative_error,
    tdi_light_ratio,
)

BETA = 12
TOP = 2**BETA - 1
STAGES = np.array([2, 5, 9, 16])
OFFSETS = np.array([64.0, 64.0 + 2 * 0.7, 64.0 + 9 * 0.7, 64.0 + 16 * 0.7])


def _data(seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    n_st, n = STAGES.size, 4000
    per_read = rng.uniform(0.0, 400.0, n)
    truth = STAGES[:, None] * per_read[None, :] * rng.uniform(0.9, 1.1, (n_st, n))
    truth[:, :50] = rng.uniform(0.0, 1.0, (n_st, 50))  # below 1 DN: no relative error
    words = np.clip(np.rint(truth + OFFSETS[:, None] + rng.normal(0, 3, (n_st, n))), 0, TOP)
    words[-1, 100:300] = TOP  # the top stage at the word's top
    # ties: eq. 11's threshold of the pair (2, 16) exactly, s_2 * 16 == (4096 - o_16) * 2
    words[0, 300:320] = (4096 - OFFSETS[-1]) * 2 / 16 + OFFSETS[0]
    signal = words - OFFSETS[:, None]
    photons = truth * 3.0
    photons[:, 320:340] = 0.0  # no light: the light ratio is undefined
    spot = rng.random((n_st, n)) < 0.4
    fill = ~spot & (rng.random((n_st, n)) < 0.8)
    return {
        "words": words, "signal": signal, "truth": truth, "clipped": rng.random((n_st, n)) < 0.1,
        "clear": rng.random((n_st, n)) < 0.85, "photons": photons, "spot": spot, "fill": fill,
        "dark": np.sort(rng.choice(n, 200, replace=False)), "dark_var": rng.uniform(1.0, 50.0, (n_st, 200)),
    }


def _reference(
    d: dict[str, np.ndarray], combo: tuple[int, ...], rule: str, sat: np.ndarray
) -> dict[str, float]:
    """The sums of one candidate (row indices ``combo``, top last) with the numpy functions."""
    ms = [int(STAGES[i]) for i in combo]
    at = list(zip(ms, combo, strict=True))
    if rule == "eq11":
        a, b = combo
        fused = fuse_dtdi_hdr_eq11(d["words"][a], d["words"][b], mu1=ms[0], mu2=ms[1], beta=BETA,
                                   pedestal_dn=(float(OFFSETS[a]), float(OFFSETS[b])))
    else:
        levels = {m: float(sat[i]) for m, i in at}
        fused = fuse_stages_highest_unsaturated({m: d["signal"][i] for m, i in at}, beta=BETA,
                                                criterion="clip", saturation_dn=levels)
    top = combo[-1]
    err = relative_error(fused.hdr, d["truth"][top])
    ratio = tdi_light_ratio(d["photons"][combo[0]], d["photons"][top], ms[0], ms[-1])
    clears = [d["clear"][i] for i in combo]
    if len(combo) == 2:
        clipr = clip_regions(clip_flags(*clears))
    else:
        some, every = np.logical_or.reduce(clears), np.logical_and.reduce(clears)
        clipr = {"clipped": some & ~every, "recoverable": some, "lost": ~some}
    regions = {"whole": np.ones(err.shape, bool), "spot": d["spot"][top], "fill": d["fill"][top],
               "spot_edge": np.isfinite(ratio) & (np.abs(ratio - 1.0) > LIGHT_RATIO_TOLERANCE), **clipr}
    out: dict[str, float] = {}
    for r in REGIONS:
        e = err[regions[r] & np.isfinite(err)]
        out.update({f"{r}_n": e.size, f"{r}_sum": e.sum(), f"{r}_sumsq": (e * e).sum()})
    src = fused.source
    out["from_clipped"] = from_clipped_stage(src, {m: d["clipped"][i] for m, i in at}).sum()
    out["from_low"] = np.sum(src == ms[0])
    out["from_mid"] = np.sum(src == ms[1]) if len(combo) == 3 else 0
    px = d["dark"]
    k = dict(at)
    sig = np.array([d["truth"][k[int(s)], p] * (ms[-1] / int(s) if s != ms[-1] else 1.0)
                    for s, p in zip(src[px], px, strict=True)])
    var = np.array([d["dark_var"][k[int(s)], j] * ((ms[-1] / int(s)) ** 2 if s != ms[-1] else 1.0)
                    for j, s in enumerate(src[px])])
    out.update(dark_signal=sig.sum(), dark_var=var.sum(), dark_n=px.size)
    return out


@pytest.mark.physics
@pytest.mark.parametrize("seed", [0, 1])
def test_sums_equal_the_numpy_functions_for_pairs_and_triples(seed: int) -> None:
    d = _data(seed)
    sat = np.stack([TOP - OFFSETS, TOP - OFFSETS - 25.0])  # clip, and a margin below it
    rules = ("eq11", "clip", "clip_margin")
    codes = np.array([RULE_EQ11, RULE_SAT, RULE_SAT])
    sat_rules = np.stack([np.zeros(STAGES.size), sat[0], sat[1]])
    top = STAGES.size - 1
    combos = [(0, top), (1, top), (2, top), (0, 1, top), (0, 2, top)]
    got = fusion_sums(
        signal=d["signal"], truth=d["truth"], valid=d["truth"] >= 1.0, clipped=d["clipped"], clear=d["clear"],
        photons_per_row=d["photons"] / STAGES[:, None].astype(np.float64), spot=d["spot"], fill=d["fill"],
        dark_pixels=d["dark"], dark_var=d["dark_var"], stages=STAGES.astype(np.float64), top=top,
        lows=np.array([c[0] for c in combos]), mids=np.array([c[1] if len(c) == 3 else -1 for c in combos]),
        codes=codes, saturation=sat_rules, phi_minus_offset_top=2.0**BETA - OFFSETS[top],
        tolerance=LIGHT_RATIO_TOLERANCE,
    )
    checked = 0
    for j, combo in enumerate(combos):
        for r, rule in enumerate(rules):
            if rule == "eq11" and len(combo) == 3:
                assert not got[j, r].any()  # eq. 11 fuses two stages only: left at 0
                continue
            ref = _reference(d, combo, rule, sat[0] if rule == "clip" else sat[1])
            for f, v in zip(FIELDS, got[j, r], strict=True):
                assert v == pytest.approx(ref[f], rel=1e-12, abs=1e-9), (combo, rule, f)
            checked += 1
    assert checked == 13
    # the ties went both ways somewhere: eq. 11 kept stage 16 at its threshold exactly
    assert got[0, 0, FIELDS.index("from_low")] < d["signal"].shape[1]
