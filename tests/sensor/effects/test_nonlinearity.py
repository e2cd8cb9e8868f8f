"""``kind = "nonlinearity"`` (:mod:`bench_sim.sensor.effects.nonlinearity`): its forms (soft knee,
polynomial, a table from CSV in electrons or DN), refusals of a response that falls, and its exact
truth: the reads and the stage words of many seeds against ``mean_dn`` and ``noise_std_dn`` with
each clip acting in turn, and ``linear_dn`` the linear camera's."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bench_sim.config import SensorConfig, with_overrides
from bench_sim.errors import BenchSimError
from bench_sim.pipeline import run_pass
from bench_sim.sensor.effects.chain import sensor_chain
from bench_sim.sensor.fixed_pattern import draw_fixed_pattern
from tests.sensor.effects.chain_stats import (
    assert_reads_follow_the_truth,
    assert_truth,
    clip_cfg,
    draw,
    expose_reads,
    flat_cfg,
)

pytestmark = pytest.mark.physics

FW = SensorConfig().full_well_e
K = SensorConfig().conversion_gain_dn_per_e
KNEE = {"knee": {"kind": "nonlinearity", "compression": 0.1, "knee_e": 4000.0}}


def _response(effect: dict) -> tuple[object, float]:
    """The composed response ``e -> r(e)`` [e-] of a chain of one effect, and its slope at 0."""
    law = sensor_chain(SensorConfig(effects=effect)).law({name: {} for name in effect})
    return law.response, law.slope0


# --- the forms ------------------------------------------------------------------------------------


@pytest.mark.parametrize(("compression", "knee_e"), [(0.03, None), (0.1, 4000.0), (0.3, 2000.0)])
def test_soft_knee_reaches_one_minus_compression_of_the_full_well(compression, knee_e):
    """Linear up to the knee (default half the full well), continuous with its slope there,
    concave above it, and ``r(FW) = (1 - compression) FW``."""
    eff = {"k": {"kind": "nonlinearity", "compression": compression}}
    if knee_e is not None:
        eff["k"]["knee_e"] = knee_e
    r, slope0 = _response(eff)
    knee = FW / 2 if knee_e is None else knee_e
    assert float(r(np.array([FW]))[0]) == pytest.approx((1 - compression) * FW, rel=1e-9)
    below = np.linspace(0.0, knee, 50)
    assert np.array_equal(r(below), below)
    h = 1e-3 * knee
    assert (float(r(np.array([knee + h]))[0]) - knee) / h == pytest.approx(1.0, abs=1e-3)
    above = r(np.linspace(knee, FW, 2001))
    assert np.all(np.diff(above) > 0) and np.all(np.diff(above, 2) < 1e-9)
    assert slope0 == 1.0


def test_soft_knee_above_what_it_must_reach_is_refused():
    with pytest.raises(BenchSimError, match=r"sensor\.effects\.k\.knee_e = 12500: must lie below"):
        _response({"k": {"kind": "nonlinearity", "compression": 0.1, "knee_e": 12500.0}})


def test_polynomial_response():
    """``r = e (1 + c1 x + c2 x^2)``, ``x = e / FW``: ``c = (-0.1, 0.04)`` gives ``0.94 FW`` at the
    full well and ``(1 - 0.05 + 0.01) FW / 2`` at half of it."""
    r, slope0 = _response({"p": {"kind": "nonlinearity", "form": "polynomial", "coefficients": [-0.1, 0.04]}})
    assert r(np.array([0.0, FW / 2, FW])) == pytest.approx([0.0, 0.96 * FW / 2, 0.94 * FW], rel=1e-12)
    assert slope0 == 1.0


def test_a_polynomial_that_falls_is_refused():
    """``1 - 0.8 x`` falls beyond ``e = 0.625 FW``."""
    with pytest.raises(BenchSimError,
                       match=r"sensor\.effects\.p\.coefficients = \[-0\.8\]: the response falls"):
        _response({"p": {"kind": "nonlinearity", "form": "polynomial", "coefficients": [-0.8]}})


def _table(tmp_path: Path, text: str) -> str:
    path = tmp_path / "response.csv"
    path.write_text(text)
    return str(path)


def test_table_in_electrons_is_interpolated_linearly(tmp_path):
    csv = "# measured response\ninput_e, output_e\n0, 0\n1000, 900\n8000, 7000\n13500, 11000\n"
    r, slope0 = _response({"t": {"kind": "nonlinearity", "form": "table", "table": _table(tmp_path, csv)}})
    assert r(np.array([0.0, 1000.0, 8000.0, 13500.0])) == pytest.approx([0.0, 900.0, 7000.0, 11000.0])
    assert float(r(np.array([4500.0]))[0]) == pytest.approx(900.0 + 0.5 * 6100.0)  # half way
    assert slope0 == pytest.approx(0.9)


def test_table_in_dn_is_read_through_the_conversion_gain(tmp_path):
    """Columns in DN above black: the response in electrons is the table divided by ``K``."""
    csv = "0, 0\n100, 90\n900, 760\n"
    r, slope0 = _response({"t": {"kind": "nonlinearity", "form": "table", "domain": "dn",
                                 "table": _table(tmp_path, csv)}})
    assert r(np.array([100.0, 900.0]) / K) == pytest.approx(np.array([90.0, 760.0]) / K)
    assert slope0 == pytest.approx(0.9)


@pytest.mark.parametrize(("csv", "message"), [
    ("0, 0\n1000, 900\n2000, 800\n", "the response falls between input 1000 and 2000"),
    ("0, 0\n1000, 900\n1000, 950\n", "the input column must increase"),
    ("0, 0\n", "needs at least two rows"),
    ("0, 0\n1000, x\n", "not a table of numbers"),
])
def test_a_bad_table_is_refused(tmp_path, csv, message):
    with pytest.raises(BenchSimError, match=r"sensor\.effects\.t\.table = .*" + message):
        _response({"t": {"kind": "nonlinearity", "form": "table", "table": _table(tmp_path, csv)}})


def test_a_straight_table_is_the_camera_of_a_lower_gain(tmp_path):
    """``r(e) = 0.9 e`` is the linear camera with ``K' = 0.9 K`` and read noise ``sigma_r / 0.9``
    (the read noise follows the response in DN): the same fixed patterns and the same truth --
    ``linear_dn`` to rounding, ``mean_dn`` and ``noise_std_dn`` to the quadrature's accuracy,
    at the full well too (stages 1 and 20)."""
    csv = _table(tmp_path, f"0, 0\n{FW}, {0.9 * FW}\n")
    cfg = flat_cfg({"t": {"kind": "nonlinearity", "form": "table", "table": csv}}, 515.0, columns=4, lines=4,
                   dtdi={"beta_bits": 20})
    twin = flat_cfg({}, 515.0, columns=4, lines=4, dtdi={"beta_bits": 20},
                    sensor={"rows": 80, "columns": 4, "conversion_gain_dn_per_e": 0.9 * K,
                            "read_noise_e": cfg.sensor.read_noise_e / 0.9})
    a = run_pass(cfg, [1, 20], 0).dataset
    b = run_pass(twin, [1, 20], 0).dataset
    assert np.allclose(a.linear_dn, b.linear_dn, rtol=1e-12, atol=1e-9)
    assert np.allclose(a.mean_dn, b.mean_dn, rtol=1e-6, atol=0.02)
    assert np.allclose(a.noise_std_dn, b.noise_std_dn, rtol=2e-3)
    assert float(a.clipped.mean()) > 0.25  # the full well acts


# --- the truth, one read at a time ----------------------------------------------------------------


@pytest.mark.parametrize("adc_bits", [12, 9])
@pytest.mark.parametrize("effect", [
    KNEE,
    {"p": {"kind": "nonlinearity", "form": "polynomial", "coefficients": [-0.15, 0.05]}},
], ids=["soft_knee", "polynomial"])
def test_reads_follow_the_truth_from_zero_to_beyond_the_full_well(effect, adc_bits):
    """10,000 reads per pixel of 4 x 64 pixels from 2 % to 125 % of the full well (through the
    knee, to the full well or the ADC's top): sample mean and variance against the truth's."""
    sensor = SensorConfig(rows=4, columns=64, adc_bits=adc_bits, effects=effect)
    electrons = np.linspace(0.02, 1.25, 64) * FW
    photons = np.broadcast_to(electrons / sensor.quantum_efficiency, (4, 64)).copy()
    assert_reads_follow_the_truth(expose_reads(sensor, photons, 10000), str(effect))


def test_table_reads_follow_the_truth(tmp_path):
    csv = _table(tmp_path, "0, 0\n2000, 2100\n6000, 5600\n13500, 11000\n")
    effects = {"t": {"kind": "nonlinearity", "form": "table", "table": csv}}
    sensor = SensorConfig(rows=4, columns=32, effects=effects)
    photons = np.broadcast_to(np.linspace(0.02, 1.2, 32) * FW / sensor.quantum_efficiency, (4, 32)).copy()
    assert_reads_follow_the_truth(expose_reads(sensor, photons, 10000), "table")


# --- the truth of the stage words ------------------------------------------------------------------

#: (clip, stage, irradiance [W/m^2] with the knee at 4000 e-, 10 % compression) and the tier
CASES = [
    ("none", 1, 100.0), ("none", 1, 200.0), ("full well", 1, 515.0), ("ADC", 1, 266.0),
    ("word at stage 1", 1, 240.0), ("word at stage 80", 80, 26.7),
    pytest.param("none", 80, 200.0, marks=pytest.mark.slow),
    pytest.param("full well", 80, 515.0, marks=pytest.mark.slow),
    pytest.param("ADC", 80, 266.0, marks=pytest.mark.slow),
]


@pytest.mark.parametrize(("clip", "stage", "irradiance"), CASES)
def test_stage_words_follow_the_truth(clip, stage, irradiance):
    """16 seeds on one sensor: ``dn`` against ``mean_dn`` and ``noise_std_dn`` (chain_stats)."""
    d = draw(clip_cfg(KNEE, clip, stage, irradiance=irradiance), [stage])[stage]
    assert_truth(d, clip)


@pytest.mark.parametrize(("irradiance", "bends"), [(100.0, False), (300.0, True)])
def test_linear_dn_is_the_linear_camera(irradiance, bends):
    """Below the knee (2,600 e- at 100 W/m^2) nothing bends: ``mean_dn = linear_dn``; above it
    (7,800 e-) the response falls below the line, ``mean_dn < linear_dn``, by more than 5
    standard errors of a 16-seed mean; ``linear_dn`` is the default camera's (the knee's slope at
    0 is 1)."""
    cfg = clip_cfg(KNEE, "none", 1, irradiance=irradiance, columns=8, lines=4)
    plain = with_overrides(cfg, {"sensor": {"effects": {"knee": {"enabled": False}}}})
    fp = draw_fixed_pattern(cfg.sensor, np.random.default_rng(5))  # the same PRNU, DSNU, columns
    d = run_pass(cfg, [1], 0, fixed_pattern=fp).dataset.sel(stage=1)
    lin = run_pass(plain, [1], 0, fixed_pattern=fp).dataset.sel(stage=1).linear_dn
    assert np.allclose(d.linear_dn.values, lin.values, rtol=1e-12, atol=0)
    gap = (d.linear_dn - d.mean_dn).values
    if bends:
        assert np.all(gap > 5 * d.noise_std_dn.values / 4)
    else:
        assert np.all(np.abs(gap) < 1e-6)
