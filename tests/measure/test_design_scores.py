"""Every candidate of one all-stage pass scored against its truth (``bench_sim.measure.design_scores``):
the narrower words from the widest are those of a pass at that word, and the closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench_sim.config import load_config, with_overrides
from bench_sim.measure.design_scores import CandidateSpace, score_candidates, word_config
from bench_sim.pipeline import run_pass
from bench_sim.sensor.model import hdr_dr_model_db, stage_dr_model_db, stage_saturation_photons

#: a 24-row sensor on the paper rig, the spot's edge and the wedge in view, stage 16 clipping
TINY = {"lines": 48, "sensor": {"rows": 24, "columns": 48}, "render": {"spp": 4},
        "target": {"panel_lines": 48, "panel_columns": 48}, "fusion": {"mu1": 2, "mu2": 16}}
PAIRS = ((2, 16), (3, 24), (5, 20), (1, 2))
TRIPLES = ((2, 8, 20),)


@pytest.fixture(scope="module")
def passes() -> dict[int, object]:
    """The same bench and seed at a 12-bit and a 10-bit word: every stage, with the truth."""
    base = with_overrides(load_config(None), TINY)
    return {b: run_pass(word_config(base, b), range(1, 25), 5, truth=True) for b in (12, 10)}


@pytest.mark.physics
def test_the_narrower_word_is_the_wider_clipped_and_so_is_its_clipped_flag(passes: dict) -> None:
    """The word is ``clip(rint(sum + P), 0, 2**beta - 1)``: the 10-bit word is the 12-bit one clipped
    at 1023, exactly, and the truth's ``clipped`` adds where it reaches that top."""
    wide, narrow = passes[12].dataset, passes[10].dataset
    dn12, dn10 = wide["dn"].values, narrow["dn"].values
    assert (dn12 >= 1023).any() and (dn12 > 1023).any()  # the narrower word clips somewhere new
    np.testing.assert_array_equal(np.minimum(dn12, 1023), dn10)
    np.testing.assert_array_equal(wide["clipped"].values | (dn12 >= 1023), narrow["clipped"].values)
    np.testing.assert_array_equal(wide["linear_dn"].values, narrow["linear_dn"].values)


@pytest.mark.physics
def test_scores_of_a_narrower_word_from_the_widest_pass_equal_a_pass_at_it(passes: dict) -> None:
    """A 10-bit candidate scored from the 12-bit pass equals the same candidate of a 10-bit pass:
    exactly where the words decide (the error, the clipped share, the regions of light), and where
    the clearance of the narrower word's clip is the normal law's within a few pixels."""
    cfg12, cfg10 = (word_config(with_overrides(load_config(None), TINY), b) for b in (12, 10))
    rules = ("eq11", "clip")
    both = score_candidates(cfg12, passes[12].dataset, CandidateSpace(PAIRS, TRIPLES, rules, (10, 12)))
    alone = score_candidates(cfg10, passes[10].dataset, CandidateSpace(PAIRS, TRIPLES, rules, (10,)))
    rows10 = both.columns["beta_bits"] == 10
    assert rows10.sum() == len(alone) == 2 * len(PAIRS) + len(TRIPLES)
    light = [f"truth_{s}_{r}" for s in ("rms", "bias") for r in ("spot", "fill", "spot_edge")]
    exact = ["truth_rms", "truth_bias", "clipped_share", "low_share", "snr_dark", "dr_db", "dr_cap_db",
             *light, "pixels_whole"]
    for col in ["mu1", "mu_mid", "mu2", "rule", *exact]:
        np.testing.assert_array_equal(both.columns[col][rows10], alone.columns[col], err_msg=col)
    pixels = 48 * 48
    for col in ("pixels_clipped", "pixels_recoverable", "pixels_lost"):
        assert np.abs(both.columns[col][rows10] - alone.columns[col]).max() <= 0.01 * pixels, col
    assert np.any(both.columns["clipped_share"][rows10] != both.columns["clipped_share"][~rows10])


@pytest.mark.physics
def test_closed_forms_of_the_candidates(passes: dict) -> None:
    """``dr_db`` is the lowest stage's clip over the highest stage's SNR = 1 point; the word's
    cap is zero where the lowest stage clips on the pixel and the DR of a word that never clips
    less it elsewhere; eq. 15's gain over stage mu2 where both clip on the same word."""
    cfg = word_config(with_overrides(load_config(None), TINY), 12)
    got = score_candidates(cfg, passes[12].dataset, CandidateSpace(PAIRS, (), ("eq11",), (12,))).columns
    for i in range(len(got["mu1"])):
        a, b = int(got["mu1"][i]), int(got["mu2"][i])
        assert got["dr_db"][i] == pytest.approx(hdr_dr_model_db(cfg, a, b), abs=1e-12)
        s, t = cfg.sensor, cfg.timing.t_int_s
        sat_word = stage_saturation_photons(s, t, a, beta_bits=12, pedestal_dn=64)
        sat_pixel = stage_saturation_photons(s, t, a, beta_bits=None, pedestal_dn=64)
        assert got["dr_cap_db"][i] == pytest.approx(20 * math.log10(sat_pixel / sat_word), abs=1e-9)
    # (5, 20): both stages clip on the 12-bit word (from stage 5 up on this sensor), so the fused
    # DR exceeds stage 20's by eq. 15, 20 lg(20/5) (but for the dark electrons, 3e-5 dB here), and
    # the word caps it; stage 2 clips on its pixel
    i = int(np.flatnonzero((got["mu1"] == 5) & (got["mu2"] == 20))[0])
    assert got["dr_db"][i] - stage_dr_model_db(cfg, 20) == pytest.approx(20 * math.log10(4), abs=1e-4)
    assert got["dr_cap_db"][i] > 0
    assert got["dr_cap_db"][got["mu1"] == 2] == pytest.approx(0.0, abs=1e-12)
