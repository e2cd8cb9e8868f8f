"""A chain of every effect at once: the same words and truth with 1 and 2 threads, its exact truth
when composed (statistical test), and ``enabled = false`` leaving an effect out."""

from __future__ import annotations

import numpy as np
import pytest

from bench_sim.pipeline import run_pass
from bench_sim.sensor.effects.chain import sensor_chain
from tests.sensor.effects.chain_stats import assert_truth, clip_cfg, draw, flat_cfg

pytestmark = pytest.mark.physics

#: every built-in effect with an exact truth, in signal order
EXACT = {
    "knee": {"kind": "nonlinearity", "compression": 0.05, "knee_e": 6000.0},
    "pixels": {"kind": "defects", "hot_rate": 0.02, "hot_dark_current_e_s": 2e5, "warm_rate": 0.03,
               "cold_rate": 0.02, "cold_gain": 0.5, "stuck_rate": 0.01, "stuck_value_dn": 250,
               "rts_rate": 0.05, "rts_amplitude_dn": 12.0},
    "dsnu0": {"kind": "offset_pattern", "rms_e": 20.0},
    "rows": {"kind": "row_noise", "rms_dn": 2.0},
}

NOISE = "def noise(y, *, rng, rms_dn):\n    return y + rms_dn * rng.standard_normal(y.shape)\n"


def test_every_effect_draws_the_same_with_one_and_two_threads(tmp_path, monkeypatch):
    """Words and truth of a 60-line pass (stages 1, 8 and 80: 139 frames, several chunks of
    frames) with every effect and a plug-in drawing from its rng: identical with
    ``BENCH_SIM_THREADS`` 1 and 2."""
    (tmp_path / "noise.py").write_text(NOISE)
    effects = {**EXACT, "flicker": {"kind": "plugin", "function": f"{tmp_path / 'noise.py'}:noise",
                                    "point": "analog", "args": {"rms_dn": 1.5}}}
    cfg = flat_cfg(effects, 150.0, columns=12, lines=60)
    got = []
    for threads in ("1", "2"):
        monkeypatch.setenv("BENCH_SIM_THREADS", threads)
        got.append(run_pass(cfg, [1, 8, 80], 11).dataset)
    one, two = got
    for name in ("dn", "mean_dn", "linear_dn", "noise_std_dn", "clipped"):
        assert np.array_equal(one[name].values, two[name].values), name
    plain = run_pass(flat_cfg({}, 150.0, columns=12, lines=60), [1, 8, 80], 11).dataset
    assert not np.array_equal(one.dn.values, plain.dn.values)  # the effects act


@pytest.mark.parametrize(("clip", "stage"), [
    ("none", 1), ("full well", 1), ("none", 80), pytest.param("full well", 80, marks=pytest.mark.slow),
])
def test_the_composed_chain_follows_the_truth(clip, stage):
    """All four built-in effects at once (16 seeds on one sensor; chain_stats)."""
    d = draw(clip_cfg(EXACT, clip, stage), [stage])[stage]
    assert_truth(d, clip)


def test_a_disabled_effect_is_left_out(tmp_path):
    """``enabled = false`` removes the effect: the chain, the words and the truth are the default
    chain's (the effect's file is not even imported)."""
    effects = {"gone": {"kind": "plugin", "function": f"{tmp_path / 'missing.py'}:f", "point": "analog",
                        "enabled": False}}
    cfg = flat_cfg(effects, 100.0, columns=4, lines=4)
    assert sensor_chain(cfg.sensor).effects == ()
    a = run_pass(cfg, [1, 8], 2).dataset
    b = run_pass(flat_cfg({}, 100.0, columns=4, lines=4), [1, 8], 2).dataset
    for name in ("dn", "mean_dn", "noise_std_dn"):
        assert np.array_equal(a[name].values, b[name].values), name
