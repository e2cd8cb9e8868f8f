"""``kind = "plugin"`` (:mod:`bench_sim.sensor.effects.plugin`): a user's function, by file or by
module path, at the charge, analog or digital point. A response declared ``truth = "monotone"`` (a
gamma curve) has the exact truth: reads and stage words of many seeds against ``mean_dn`` and
``noise_std_dn`` with each clip acting in turn; one declared ``truth = "none"`` is labelled on
every truth variable and the pass's attributes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bench_sim.config import SensorConfig
from bench_sim.pipeline import run_pass
from tests.sensor.effects.chain_stats import (
    assert_reads_follow_the_truth,
    assert_truth,
    clip_cfg,
    draw,
    expose_reads,
    flat_cfg,
)

pytestmark = pytest.mark.physics

#: the user's file, outside the package: a gamma curve, a linear gain, an analog offset, a
#: digital effect and a noise drawn from the rng it is given
USER_EFFECTS = '''
import numpy as np


def gamma_response(e, *, rng, gamma, full_well_e):
    """A gamma curve of the charge: full_well_e * (e / full_well_e) ** gamma [e-]."""
    return full_well_e * (e / full_well_e) ** gamma


def gain(e, *, rng, factor):
    return factor * e


def offset(y, *, rng, dn):
    return y + dn


def drop_lsb(v, *, rng):
    return v - v % 2


def flicker(y, *, rng, rms_dn):
    y += rms_dn * rng.standard_normal(y.shape)
    return y
'''


@pytest.fixture(scope="module")
def user_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("user") / "my_effects.py"
    path.write_text(USER_EFFECTS)
    return path


def plugin(user_file: Path, function: str, point: str, truth: str = "none", **args: float) -> dict:
    return {"kind": "plugin", "function": f"{user_file}:{function}", "point": point, "truth": truth,
            "args": args}


def gamma(user_file: Path) -> dict:
    return {"g": plugin(user_file, "gamma_response", "charge", "monotone", gamma=0.85, full_well_e=13500.0)}


@pytest.mark.parametrize("adc_bits", [12, 9])
def test_gamma_reads_follow_the_truth(user_file, adc_bits):
    """10,000 reads per pixel of 4 x 64 pixels from 2 % to 125 % of the full well (the gamma
    curve's steep foot included)."""
    sensor = SensorConfig(rows=4, columns=64, adc_bits=adc_bits, effects=gamma(user_file))
    electrons = np.linspace(0.02, 1.25, 64) * sensor.full_well_e
    photons = np.broadcast_to(electrons / sensor.quantum_efficiency, (4, 64)).copy()
    assert_reads_follow_the_truth(expose_reads(sensor, photons, 10000), f"gamma, {adc_bits}-bit ADC")


#: (clip, stage, irradiance [W/m^2] through a gamma of 0.85)
CASES = [
    ("none", 1, 100.0), ("full well", 1, 515.0), ("ADC", 1, 230.0), ("word at stage 1", 1, 205.0),
    ("none", 80, 10.0), ("word at stage 80", 80, 15.8),
    pytest.param("full well", 80, 515.0, marks=pytest.mark.slow),
    pytest.param("ADC", 80, 230.0, marks=pytest.mark.slow),
]


@pytest.mark.parametrize(("clip", "stage", "irradiance"), CASES)
def test_gamma_stage_words_follow_the_truth(user_file, clip, stage, irradiance):
    d = draw(clip_cfg(gamma(user_file), clip, stage, irradiance=irradiance), [stage])[stage]
    assert_truth(d, clip)


def test_a_linear_plugin_is_the_camera_of_a_higher_gain(user_file):
    """``r(e) = 1.2 e`` declared monotone is the linear camera with ``K' = 1.2 K`` and read noise
    ``sigma_r / 1.2``: the same truth (``linear_dn`` too: the secant slope of a line is its
    slope), at the full well too."""
    effects = {"x": plugin(user_file, "gain", "charge", "monotone", factor=1.2)}
    cfg = flat_cfg(effects, 515.0, columns=4, lines=4, dtdi={"beta_bits": 20})
    k = cfg.sensor.conversion_gain_dn_per_e
    twin = flat_cfg({}, 515.0, columns=4, lines=4, dtdi={"beta_bits": 20},
                    sensor={"rows": 80, "columns": 4, "conversion_gain_dn_per_e": 1.2 * k,
                            "read_noise_e": cfg.sensor.read_noise_e / 1.2})
    a, b = run_pass(cfg, [1, 20], 0).dataset, run_pass(twin, [1, 20], 0).dataset
    assert np.allclose(a.linear_dn, b.linear_dn, rtol=1e-12)
    assert np.allclose(a.mean_dn, b.mean_dn, rtol=1e-6, atol=0.02)
    assert np.allclose(a.noise_std_dn, b.noise_std_dn, rtol=2e-3)


def test_a_module_path_works_like_a_file(user_file, monkeypatch):
    """``package.module:function`` imports the same function as ``file.py:function``."""
    monkeypatch.syspath_prepend(str(user_file.parent))
    by_file = gamma(user_file)
    by_module = {"g": {**by_file["g"], "function": "my_effects:gamma_response"}}
    a = run_pass(flat_cfg(by_file, 100.0, columns=4, lines=4), [1, 8], 3).dataset
    b = run_pass(flat_cfg(by_module, 100.0, columns=4, lines=4), [1, 8], 3).dataset
    for name in ("dn", "mean_dn", "noise_std_dn", "linear_dn"):
        assert np.array_equal(a[name].values, b[name].values), name


def test_a_digital_plugin_acts_on_the_raw_values(user_file):
    """Dropping the raw value's lowest bit makes every raw read even: a stage-1 word is then the
    raw read less the black offset plus the pedestal, all even here."""
    cfg = flat_cfg({"lsb": plugin(user_file, "drop_lsb", "digital")}, 100.0, columns=8, lines=8)
    assert (cfg.dtdi.pedestal_dn - cfg.sensor.black_offset_dn) % 2 == 0
    dn = run_pass(cfg, [1], 0).stage_dn[1]
    plain = run_pass(flat_cfg({}, 100.0, columns=8, lines=8), [1], 0).stage_dn[1]
    assert np.all(dn % 2 == 0) and np.any(plain % 2 == 1)


def test_truth_none_is_labelled_and_an_exact_chain_is_not(user_file):
    """An analog offset of +6 DN declared ``truth = "none"``: the words move by 6 DN from
    ``mean_dn`` (the truth does not know it), and the pass says so -- ``truth_exact = 0`` and
    ``truth_not_exact`` naming the effect, on the dataset and on every truth variable; the
    gamma curve's pass says ``truth_exact = 1``."""
    cfg = flat_cfg({"bias": plugin(user_file, "offset", "analog", dn=6.0)}, 100.0, columns=16, lines=16)
    d = run_pass(cfg, [1], 0).dataset
    assert abs(float((d.dn - d.mean_dn).mean()) - 6.0) < 1.0
    assert d.attrs["truth_exact"] == 0 and "bias: plug-in" in d.attrs["truth_not_exact"]
    assert "bias (plugin)" in d.attrs["sensor_chain"]
    for name in ("mean_dn", "linear_dn", "noise_std_dn", "photons", "clipped", "reflectance"):
        assert d[name].attrs["truth_exact"] == 0 and "bias" in d[name].attrs["truth_not_exact"], name
    assert "truth_exact" not in d.dn.attrs
    exact = run_pass(flat_cfg(gamma(user_file), 100.0, columns=4, lines=4), [1], 0).dataset
    assert exact.attrs["truth_exact"] == 1 and "truth_not_exact" not in exact.attrs
    assert exact.mean_dn.attrs["truth_exact"] == 1


def test_a_plugin_draws_from_the_rng_it_is_given(user_file):
    """A noise drawn from ``rng``: the same seed gives the same words, another seed others, and
    the words' variance grows by the noise's (``truth = "none"``: the truth does not have it)."""
    cfg = flat_cfg({"f": plugin(user_file, "flicker", "analog", rms_dn=20.0)}, 100.0, columns=16, lines=16)
    a, b, c = (run_pass(cfg, [1], s).stage_dn[1].astype(float) for s in (5, 5, 6))
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    d = run_pass(cfg, [1], 5).dataset.sel(stage=1)
    ratio = float(((a - d.mean_dn.values) ** 2).mean() / (d.noise_std_dn.values**2).mean())
    assert ratio > 5  # 400 DN^2 of the plugin's noise over the ~30 DN^2 the truth knows
