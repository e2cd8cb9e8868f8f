"""The scenario presets in scenes/scenarios: each loads, says what it shows, and is what it says."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench_sim.config import SCENES_DIR, load_config, with_overrides
from bench_sim.errors import BenchSimError
from bench_sim.render.engines import check_fast_engine_valid
from bench_sim.rig.scene import light_names

SCENARIOS = SCENES_DIR / "scenarios"
NAMES = ("backlit", "glint", "flicker_100hz", "dusk", "high_contrast")


@pytest.mark.parametrize("name", NAMES)
def test_each_preset_loads_and_says_what_it_shows(name: str) -> None:
    path = SCENARIOS / f"{name}.toml"
    text = path.read_text()
    assert text.startswith(f'# Scenario "{name}":') and "# What it shows:" in text
    assert load_config(path).name == name


def test_presets_are_what_their_comments_say() -> None:
    paper = load_config()
    backlit = load_config(SCENARIOS / "backlit.toml")
    assert light_names(backlit) == ("weak", "back")
    d = np.asarray(backlit.lights.back.direction)
    # grazing: 8 degrees above the tangent plane at the viewed line (normal +z)
    assert math.degrees(math.asin(-d[2] / np.linalg.norm(d))) == pytest.approx(8.0, abs=0.01)

    glint = load_config(SCENARIOS / "glint.toml")
    assert glint.target.finish == "glossy" and glint.render.engine == "reference"
    with pytest.raises(BenchSimError, match="glossy"):
        check_fast_engine_valid(with_overrides(glint, {"render": {"engine": "fast"}}))

    flicker = load_config(SCENARIOS / "flicker_100hz.toml")
    strong = flicker.lights.strong
    flick = (strong.flicker_hz, strong.flicker_depth, strong.flicker_waveform)
    assert flick == (100.0, 1.0, "rectified_sine")
    assert flicker.timing.line_period_s * strong.flicker_hz == pytest.approx(0.01)  # 100 lines per period
    assert not flicker.lights.weak.flickers

    dusk = load_config(SCENARIOS / "dusk.toml")
    assert light_names(dusk) == ("weak",)
    assert dusk.lights.weak.irradiance_w_m2 == pytest.approx(paper.lights.weak.irradiance_w_m2 / 10)

    high = load_config(SCENARIOS / "high_contrast.toml")
    assert high.lights.strong.irradiance_w_m2 / high.lights.weak.irradiance_w_m2 == pytest.approx(1e4)
    assert high.lights.strong == paper.lights.strong
