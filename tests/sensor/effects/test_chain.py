"""A chain of every effect at once: the same words and truth with 1 and 2 threads, its exact truth
when composed (statistical tests, with each source of noise switched off too), and
``enabled = false`` leaving an effect out."""

from __future__ import annotations

import numpy as np
import pytest

from bench_sim.config import SensorConfig
from bench_sim.pipeline import run_pass
from bench_sim.sensor.effects.chain import sensor_chain
from tests.sensor.effects.chain_stats import (
    assert_reads_follow_the_truth,
    assert_truth,
    clip_cfg,
    draw,
    expose_reads,
    flat_cfg,
)

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
    """Words and truth of a 40-line pass (stages 1, 8 and 40: 79 frames, five chunks of 16
    frames) with every effect and a plug-in drawing from its rng: identical with
    ``BENCH_SIM_THREADS`` 1 and 2."""
    (tmp_path / "noise.py").write_text(NOISE)
    effects = {**EXACT, "flicker": {"kind": "plugin", "function": f"{tmp_path / 'noise.py'}:noise",
                                    "point": "analog", "args": {"rms_dn": 1.5}}}
    cfg = flat_cfg(effects, 150.0, columns=12, lines=40)
    got = []
    for threads in ("1", "2"):
        monkeypatch.setenv("BENCH_SIM_THREADS", threads)
        got.append(run_pass(cfg, [1, 8, 40], 11).dataset)
    one, two = got
    for name in ("dn", "mean_dn", "linear_dn", "noise_std_dn", "clipped"):
        assert np.array_equal(one[name].values, two[name].values), name
    plain = run_pass(flat_cfg({}, 150.0, columns=12, lines=40), [1, 8, 40], 11).dataset
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


@pytest.mark.parametrize("switches", [
    {}, {"dark_noise": False}, {"quantization": False}, {"shot_noise": False}, {"read_noise": False},
    {"shot_noise": False, "dark_noise": False},
], ids=lambda s: ",".join(f"{k}={v}" for k, v in s.items()) or "all on")
def test_every_effect_with_the_pixel_models_switches(switches):
    """10,000 reads per pixel of 4 x 64 pixels with every built-in effect (half the pixels
    defects, dead ones too) from 0 electrons (dark pixels: the exact Poisson law of small means)
    to 125 % of the full well, with a source of noise switched off: the truth's mean and variance
    (chain_stats)."""
    effects = {**EXACT, "pixels": {**EXACT["pixels"], "hot_rate": 0.1, "warm_rate": 0.1, "cold_rate": 0.1,
                                   "cold_gain": 0.0, "stuck_rate": 0.1, "rts_rate": 0.1}}
    sensor = SensorConfig(rows=4, columns=64, effects=effects, **switches)
    small = [0.0, 0.5, 2.0, 8.0, 20.0, 40.0]
    electrons = np.concatenate([small, np.linspace(0.01, 1.25, 58) * sensor.full_well_e])
    photons = np.broadcast_to(electrons / sensor.quantum_efficiency, (4, 64)).copy()
    assert_reads_follow_the_truth(expose_reads(sensor, photons, 10000), str(switches))
