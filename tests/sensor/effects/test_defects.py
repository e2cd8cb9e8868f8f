"""``kind = "defects"`` (:mod:`bench_sim.sensor.effects.defects`): hot, warm, cold, stuck and
random-telegraph pixels drawn at their rates (a binomial test) or read from a map (exactly), from
their own random stream, and their exact truth: reads and stage words of many seeds against
``mean_dn`` and ``noise_std_dn`` with each clip acting in turn."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from bench_sim.config import SensorConfig
from bench_sim.errors import BenchSimError
from bench_sim.sensor.effects.chain import sensor_chain
from bench_sim.sensor.effects.defects import KINDS
from bench_sim.sensor.fixed_pattern import draw_fixed_pattern
from tests.sensor.effects.chain_stats import (
    CLIP_CASES,
    assert_reads_follow_the_truth,
    assert_truth,
    clip_cfg,
    draw,
    expose_reads,
    full_well_ramp,
)

pytestmark = pytest.mark.physics

RATES = {"hot_rate": 0.02, "warm_rate": 0.05, "cold_rate": 0.03, "stuck_rate": 0.01, "rts_rate": 0.04}
VALUES = {"hot_dark_current_e_s": 5e5, "warm_dark_current_e_s": 5e4, "cold_gain": 0.25,
          "stuck_value_dn": 300, "rts_amplitude_dn": 15.0, "rts_probability": 0.3}

#: a measured map: (row, column, kind, value); row 0 holds each kind twice or more (stage 1 reads
#: row 0), other rows a few more (stage 80 sums rows 0..79)
MAP = [
    (0, 0, "hot", 5e5), (0, 1, "hot", 2e5), (0, 2, "warm", 5e4), (0, 3, "warm", 2e4),
    (0, 4, "cold", 0.25), (0, 5, "cold", 0.0), (0, 6, "stuck", 300.0), (0, 7, "stuck", 0.0),
    (0, 8, "rts", 15.0), (0, 9, "rts", 6.0), (0, 10, "rts", 30.0), (7, 3, "hot", 3e5),
    (20, 11, "cold", 0.5), (33, 12, "rts", 20.0), (51, 14, "warm", 9e4), (79, 15, "stuck", 200.0),
]


def write_map(folder: Path, rows: list[tuple[int, int, str, float]] = MAP) -> str:
    """The map as a lab exports it: a comment, a header line, one pixel per line."""
    path = folder / "defects.csv"
    path.write_text("# defect pixels of camera 17\nrow, column, kind, value\n"
                    + "".join(f"{r}, {c}, {k}, {v}\n" for r, c, k, v in rows))
    return str(path)


# --- the fixed pattern ----------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rates_give_binomial_counts(seed):
    """On 250 x 200 pixels each kind's count is Binomial(50,000, rate) (two-sided p > 1e-4), the
    kinds exclusive, and each drawn pixel carries its kind's value."""
    sensor = SensorConfig(rows=250, columns=200, effects={"d": {"kind": "defects", **RATES, **VALUES}})
    state = dict(draw_fixed_pattern(sensor, np.random.default_rng(seed)).effects)["d"]
    code, value = np.asarray(state["code"]), np.asarray(state["value"])
    n = code.size
    for j, kind in enumerate(KINDS):
        count = int((code == j + 1).sum())
        assert stats.binomtest(count, n, RATES[f"{kind}_rate"]).pvalue > 1e-4, (kind, count)
    assert int((code == 0).sum()) == n - sum(int((code == j + 1).sum()) for j in range(len(KINDS)))
    expected = {1: 5e5, 2: 5e4, 3: 0.25, 4: 300.0, 5: 15.0}
    for c, v in expected.items():
        assert np.all(value[code == c] == v)


def test_defects_leave_the_default_patterns_and_change_only_their_pixels():
    """The defects draw from their own stream: PRNU, DSNU and column offsets are the default
    chain's (same seed); only hot/warm pixels change the dark current (by their value) and cold
    pixels the gain (times theirs)."""
    plain = SensorConfig(rows=60, columns=50)
    with_defects = SensorConfig(rows=60, columns=50, effects={"d": {"kind": "defects", **RATES, **VALUES}})
    a = draw_fixed_pattern(plain, np.random.default_rng(4))
    b = draw_fixed_pattern(with_defects, np.random.default_rng(4))
    code = np.asarray(dict(b.effects)["d"]["code"])
    hot_or_warm, cold = np.isin(code, (1, 2)), code == 3
    assert np.array_equal(a.column_offset_dn, b.column_offset_dn)
    assert np.array_equal(a.prnu_gain[~cold], b.prnu_gain[~cold])
    assert np.allclose(b.prnu_gain[cold], 0.25 * a.prnu_gain[cold], rtol=1e-15)
    assert np.array_equal(a.dark_current_e_s[~hot_or_warm], b.dark_current_e_s[~hot_or_warm])
    extra = np.where(code == 1, 5e5, 5e4)[hot_or_warm]
    assert np.allclose(b.dark_current_e_s[hot_or_warm] - a.dark_current_e_s[hot_or_warm], extra, rtol=1e-12)


def test_the_map_is_read_exactly(tmp_path):
    """Every listed pixel has its kind and value, and no other pixel is a defect."""
    sensor = SensorConfig(rows=80, columns=16,
                          effects={"d": {"kind": "defects", "map_file": write_map(tmp_path)}})
    state = dict(draw_fixed_pattern(sensor, np.random.default_rng(0)).effects)["d"]
    code, value = np.asarray(state["code"]), np.asarray(state["value"])
    want_code, want_value = np.zeros((80, 16), dtype=int), np.zeros((80, 16))
    for r, c, kind, v in MAP:
        want_code[r, c], want_value[r, c] = KINDS.index(kind) + 1, v
    assert np.array_equal(code, want_code) and np.array_equal(value, want_value)


@pytest.mark.parametrize(("rows", "message"), [
    ([(0, 16, "hot", 1e5)], r"row 1: pixel \(0, 16\) of kind 'hot': needs a pixel of the 80 x 16 sensor"),
    ([(0, 1, "hot", 1e5), (3, 2, "sparkly", 1.0)], "row 2: pixel \\(3, 2\\) of kind 'sparkly'"),
    ([(0, 1, "hot", float("nan"))], "row 1"),
])
def test_a_bad_map_is_one_line_naming_the_row(tmp_path, rows, message):
    sensor = SensorConfig(rows=80, columns=16,
                          effects={"d": {"kind": "defects", "map_file": write_map(tmp_path, rows)}})
    with pytest.raises(BenchSimError, match=r"sensor\.effects\.d\.map_file = .*" + message):
        sensor_chain(sensor)


def test_a_stuck_value_above_the_adc_top_is_refused():
    with pytest.raises(BenchSimError,
                       match=r"sensor\.effects\.d\.stuck_value_dn = 600: above the ADC's top \(511 DN\)"):
        sensor_chain(SensorConfig(adc_bits=9, effects={"d": {"kind": "defects", "stuck_value_dn": 600}}))


@pytest.mark.parametrize("kind", KINDS)
def test_a_rate_above_a_tenth_is_refused_naming_it(kind: str) -> None:
    """Each rate is at most 0.1, so the five always partition ``[0, 1)`` (at most 0.5 in all)."""
    said = rf"sensor\.effects\.d\.{kind}_rate = 0\.11: .*less than or equal to 0\.1"
    with pytest.raises(BenchSimError, match=said):
        sensor_chain(SensorConfig(effects={"d": {"kind": "defects", f"{kind}_rate": 0.11}}))


# --- the truth, one read at a time ----------------------------------------------------------------


@pytest.mark.parametrize("adc_bits", [12, 9])
def test_reads_follow_the_truth(adc_bits):
    """10,000 reads per pixel of 4 x 64 pixels at every rate (half of them defects) from 2 % to
    125 % of the full well: the telegraph's mixture, the stuck pixels' constant, the hot pixels'
    dark current and the cold pixels' gain in the truth, the clips too."""
    rates = {k: 0.1 for k in RATES}
    sensor = SensorConfig(rows=4, columns=64, adc_bits=adc_bits,
                          effects={"d": {"kind": "defects", **rates, **VALUES}})
    photons = full_well_ramp(sensor)
    r = expose_reads(sensor, photons, 10000)
    state = dict(draw_fixed_pattern(sensor, np.random.default_rng(3)).effects)["d"]
    assert all(np.any(np.asarray(state["code"]) == j + 1) for j in range(len(KINDS)))
    assert_reads_follow_the_truth(r, f"defects, {adc_bits}-bit ADC")


# --- the truth of the stage words ------------------------------------------------------------------

@pytest.mark.parametrize(("clip", "stage"), CLIP_CASES)
def test_stage_words_of_the_map_follow_the_truth(tmp_path, clip, stage):
    """The map's pixels (every kind in row 0, which stage 1 reads), 16 seeds on one sensor."""
    effects = {"d": {"kind": "defects", "map_file": write_map(tmp_path)}}
    d = draw(clip_cfg(effects, clip, stage), [stage])[stage]
    assert_truth(d, clip)


@pytest.mark.parametrize(("clip", "irradiance"), [("none", 10.0), ("word at stage 80", 25.0)])
def test_stage_words_at_rates_follow_the_truth(clip, irradiance):
    """Defects drawn at their rates over the 80 rows a stage-80 word sums."""
    effects = {"d": {"kind": "defects", **RATES, **VALUES}}
    d = draw(clip_cfg(effects, clip, 80, irradiance=irradiance), [80])[80]
    assert_truth(d, clip)


def test_linear_dn_of_defects(tmp_path):
    """Where nothing clips ``mean_dn = linear_dn`` (a telegraph pixel's ``p A`` in both); a stuck
    pixel's stage-1 word is its value, pedestal in and black out, in both."""
    d = draw(clip_cfg({"d": {"kind": "defects", "map_file": write_map(tmp_path)}}, "none", 1, columns=16,
                      lines=4), [1], seeds=1)[1]
    assert np.allclose(d.linear, d.mean, rtol=1e-9, atol=1e-6)
    cfg = clip_cfg({}, "none", 1)
    word = 300.0 - cfg.sensor.black_offset_dn + cfg.dtdi.pedestal_dn
    assert np.all(d.mean[:, 6] == word) and np.all(d.linear[:, 6] == word) and np.all(d.dn[:, :, 6] == word)
