"""Unit slips and misspelled keys, refused through the command line with a hint (exit 2).

A value in the wrong unit is refused naming the key the user wrote, its typical range and a
guess (``did you mean 100e-6?``); a misspelled key is refused with the closest key of its table.
Both happen before anything is computed: no output folder appears.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from bench_sim.cli import app
from bench_sim.config import DEFAULT_CONFIG_PATH, SCENES_DIR, ConfigError, config_from_dict, load_config
from bench_sim.config.catalogue import config_keys
from bench_sim.config.plausible import TYPICAL, typical_for
from bench_sim.workflows.dataset import spec as dataset_spec
from bench_sim.workflows.sweep import spec as sweep_spec

runner = CliRunner()

LAMP = '[lights.lamp]\nkind = "{kind}"\n'

#: (what the user wrote, the text the one-line error must hold)
SLIPS: list[tuple[str, list[str]]] = [
    ("[timing]\nline_period_s = 100\n",
     ["timing.line_period_s = 100", "1e-05..0.01 s", "did you mean 100e-6?"]),
    ("[timing]\nintegration_time_s = 50\n", ["timing.integration_time_s = 50", "did you mean 50e-6?"]),
    ("[sensor]\npixel_pitch_m = 5.5\n", ["sensor.pixel_pitch_m = 5.5", "did you mean 5.5e-6?"]),
    ("[sensor]\nwavelength_m = 550\n", ["sensor.wavelength_m = 550", "did you mean 550e-9?"]),
    ("[lens]\nfocal_length_m = 50\n", ["lens.focal_length_m = 50", "did you mean 50e-3?"]),
    ("[lens]\nworking_distance_m = 500\n", ["lens.working_distance_m = 500", "did you mean 500e-3?"]),
    ("[lens]\nfocus_distance_m = 450\n", ["lens.focus_distance_m = 450", "did you mean 450e-3?"]),
    ("[drum]\nradius_m = 100\n", ["drum.radius_m = 100", "did you mean 100e-3?"]),
    ("[drum]\nlength_m = 300\n", ["drum.length_m = 300", "did you mean 300e-3?"]),
    ("[drum]\naxle_radius_m = 12\n", ["drum.axle_radius_m = 12", "did you mean 12e-3?"]),
    ("[sensor]\nfull_well_e = 13.5\n", ["sensor.full_well_e = 13.5", "did you mean 13.5e3?"]),
    ("[sensor]\nconversion_gain_dn_per_e = 72\n",
     ["sensor.conversion_gain_dn_per_e = 72", "did you mean 72e-3?"]),
    ("[sensor]\nread_noise_e = 13000\n", ["sensor.read_noise_e = 13000", "did you mean 13000e-3?"]),
    ("[sensor]\ndark_current_e_s = 1.25e8\n", ["sensor.dark_current_e_s = 125000000.0", "e-/s"]),
    ("[lights.strong]\nirradiance_w_m2 = 1.28e8\n", ["lights.strong.irradiance_w_m2", "did you mean 128?"]),
    ("[lights.weak]\nirradiance_w_m2 = 6e-6\n", ["lights.weak.irradiance_w_m2", "did you mean 6?"]),
    ("[lights.strong]\nflicker_hz = 1e8\n", ["lights.strong.flicker_hz", "Hz"]),
    ("[lights.strong]\nposition_m = [-100, 250, 450]\n",
     ["lights.strong.position_m", "did you mean 450e-3?"]),
    ("[lights.strong]\naim_m = [-15.5, 0, 1000]\n", ["lights.strong.aim_m", "per component"]),
    (LAMP.format(kind="point") + "position_m = [0, 150, 400]\n",
     ["lights.lamp.position_m", "did you mean 400e-3?"]),
    (LAMP.format(kind="area") + "size_m = [100, 100]\n", ["lights.lamp.size_m", "did you mean 100e-3?"]),
    ("[render]\nband_m = [400, 700]\n", ["render.band_m", "did you mean 700e-9?"]),
    # misspellings: the closest key of the table
    ("[sensor]\npixel_pich_m = 5.5e-6\n",
     ["unknown key 'sensor.pixel_pich_m'", "did you mean 'pixel_pitch_m'?"]),
    ("[sensr]\nrows = 10\n", ["unknown key 'sensr'", "did you mean 'sensor'?"]),
    ("[timing]\nline_period = 1e-4\n", ["unknown key 'timing.line_period'", "did you mean 'line_period_s'?"]),
    ("[lights.strong]\nirradiance = 10\n", ["unknown key 'lights.strong.irradiance'", "'irradiance_w_m2'"]),
    (LAMP.format(kind="spot") + "aim = [0, 0, 0.1]\n",
     ["unknown key 'lights.lamp.aim'", "did you mean 'aim_m'?"]),
    ("[dtdi]\nbeta_bit = 12\n", ["unknown key 'dtdi.beta_bit'", "did you mean 'beta_bits'?"]),
    ("[fusion]\nmu_1 = 10\n", ["unknown key 'fusion.mu_1'", "did you mean 'mu1'?"]),
]


def test_the_table_is_large_enough() -> None:
    assert len(SLIPS) >= 20


@pytest.mark.parametrize(("toml", "needles"), SLIPS, ids=[s[1][0] for s in SLIPS])
def test_unit_slips_and_misspellings_are_refused_with_a_hint(
    tmp_path: Path, toml: str, needles: list[str]
) -> None:
    cfg = tmp_path / "bench.toml"
    cfg.write_text('base = "' + str(DEFAULT_CONFIG_PATH) + '"\n' + toml)
    r = runner.invoke(app, ["config", "show", str(cfg)])
    assert r.exit_code == 2, (r.exit_code, r.stdout, r.stderr)
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("bench-sim: error: config error: "), r.stderr
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])


def test_a_slip_blames_the_key_written_not_a_cross_check(tmp_path: Path) -> None:
    """sensor.pixel_pitch_m = 5.5 would otherwise break the field-of-view check on the drum."""
    with pytest.raises(ConfigError) as info:
        config_from_dict({"sensor": {"pixel_pitch_m": 5.5}})
    assert "sensor.pixel_pitch_m = 5.5" in str(info.value) and "drum.length_m" not in str(info.value)


def test_a_run_refuses_a_slip_before_computing(tmp_path: Path) -> None:
    cfg = tmp_path / "bench.toml"
    cfg.write_text("[timing]\nline_period_s = 100\n")
    out = tmp_path / "out"
    r = runner.invoke(app, ["simulate", str(cfg), "--out", str(out)])
    assert r.exit_code == 2 and "did you mean 100e-6?" in r.stderr
    assert not out.exists()


@pytest.mark.parametrize(
    "data",
    [
        {"lights": {"weak": {"irradiance_w_m2": 0.0}, "strong": {"flicker_hz": 0.0}}},  # off is legal
        {"sensor": {"read_noise_e": 0.0, "dark_current_e_s": 0.0}},
        {"timing": {"line_period_s": 1e-6 * 1.01}},  # inside the margin of the typical range
        {"sensor": {"full_well_e": 150.0}},
    ],
)
def test_zero_and_values_inside_the_margin_pass(data: dict) -> None:
    config_from_dict(data)


def test_shipped_configs_and_specs_lie_inside_the_ranges() -> None:
    scenes = SCENES_DIR
    for path in sorted(scenes.glob("*.toml")) + sorted((scenes / "scenarios").glob("*.toml")):
        load_config(path)
    for path in sorted((scenes / "sweeps").glob("*.toml")):
        sweep_spec.load_spec(path)
    for path in sorted((scenes / "datasets").glob("*.toml")):
        dataset_spec.load_spec(path)


PHYSICAL = {"m", "s", "W/m^2", "e-", "e-/s", "DN/e-", "Hz"}


def test_every_physical_float_key_has_a_typical_range() -> None:
    """A new physical key (a float with a unit among PHYSICAL) must get its range in TYPICAL."""
    missing = sorted(
        k.key for k in config_keys()
        if k.unit in PHYSICAL and k.type.startswith(("float", "[float"))
        and typical_for(re.sub(r"\[kind=\w+\]", "", k.key)) is None
    )
    assert not missing, f"physical keys without a range in bench_sim.config.plausible.TYPICAL: {missing}"
    assert all(t.low < t.high for t in TYPICAL.values())
