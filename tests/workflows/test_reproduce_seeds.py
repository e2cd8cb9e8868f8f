"""``reproduce --seeds N`` (:mod:`bench_sim.workflows.reproduce.seeds`): the headline numbers of
``metrics.json`` and their mean +- sample standard deviation over seeds."""

from __future__ import annotations

import numpy as np
import pytest

from bench_sim.workflows.reproduce.seeds import HEADLINES, headline_numbers, seed_spread, spread_section


def _metrics(x: float) -> dict:
    return {
        "dr_db": {"gamma1": 60 + x, "gamma2": 52 - x, "gamma_hdr": 70 + 2 * x},
        "delta_dr_db_vs_gamma1": 9 + x, "delta_dr_db_vs_gamma2": 18.0,
        "darkest_patch": {"snr": {"gamma1": 1.5, "gamma2": 4 + x, "gamma_hdr": 4 + x}},
        "fusion_truth": {"rules": {"eq11": {
            "error": {"whole": {"rms": 0.07}, "spot_edge": {"bias": -0.1 * x}}, "from_clipped_fraction": 0.01,
        }}},
    }


def test_headlines_are_read_from_metrics_and_spread_is_mean_and_sample_sd():
    xs = [0.0, 0.3, -0.2, 0.5, 0.1]
    runs = [headline_numbers(_metrics(x)) for x in xs]
    assert runs[1]["dr_db_gamma1"] == 60.3 and runs[1]["snr_darkest_gamma2"] == 4.3
    assert runs[0]["truth_rms_clip"] is None  # absent in these metrics: left out, not 0
    spread = seed_spread(runs)
    assert set(spread) == set(HEADLINES)
    g = spread["gain_db_vs_gamma1"]
    assert g["mean"] == pytest.approx(np.mean(9 + np.array(xs)))
    assert g["sd"] == pytest.approx(np.std(9 + np.array(xs), ddof=1)) and g["n"] == 5
    assert spread["gain_db_vs_gamma2"]["sd"] == 0.0
    assert spread["truth_rms_clip"]["n"] == 0
    text = "\n".join(spread_section(spread, list(range(3, 8))))
    assert "Spread over 5 seeds (3..7)" in text and f"{g['mean']:.4g} +- {g['sd']:.2g}" in text
    assert "clip-aware" not in text  # no row for a number no seed measured
