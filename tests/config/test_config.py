"""Config: defaults = paper rig, TOML loading with presets, one-line errors naming key and value."""

from __future__ import annotations

import pytest

from bench_sim.config import DEFAULT_CONFIG_PATH, BenchConfig, ConfigError, load_config


def test_default_file_matches_model_defaults_where_it_restates_them():
    cfg = load_config()
    assert cfg == BenchConfig()  # scenes/paper_rig.toml restates the defaults explicitly


def test_presets_load_and_differ_only_in_lights():
    base = load_config()
    for name in ("strong.toml", "weak.toml"):
        cfg = load_config(DEFAULT_CONFIG_PATH.parent / name)
        assert cfg.sensor == base.sensor and cfg.drum == base.drum
        assert cfg.lights != base.lights


@pytest.mark.parametrize(
    ("toml", "needle"),
    [
        ("[sensor]\nrows = 0\n", "sensor.rows = 0: Input should be greater than or equal to 1"),
        ("[sensor]\nbogus = 1\n", "unknown key 'sensor.bogus'"),
        ("[fusion]\nmu1 = 80\nmu2 = 10\n", "mu1 = 80 must be smaller than mu2 = 10"),
        ("[lens]\nmodel = 'fisheye'\n", "lens.model = 'fisheye'"),
        ("[timing]\nintegration_time_s = 0.05\n", "must not exceed line_period_s"),
        ("[sensor]\nrows = [\n", "not valid TOML"),
        ("base = 'nope.toml'\n", "nope.toml: no such file"),
    ],
)
def test_bad_configs_give_one_line_naming_key_and_value(tmp_path, toml, needle):
    path = tmp_path / "bad.toml"
    path.write_text(toml)
    with pytest.raises(ConfigError) as info:
        load_config(path)
    msg = str(info.value)
    assert "\n" not in msg
    assert needle in msg
    assert msg.startswith("config error: ")


def test_base_chain_overrides(tmp_path):
    (tmp_path / "a.toml").write_text(f"base = '{DEFAULT_CONFIG_PATH}'\n[sensor]\nrows = 90\n")
    (tmp_path / "b.toml").write_text("base = 'a.toml'\n[dtdi]\nbeta_bits = 16\n")
    cfg = load_config(tmp_path / "b.toml")
    assert (cfg.sensor.rows, cfg.dtdi.beta_bits, cfg.sensor.columns) == (90, 16, 1024)


@pytest.mark.parametrize(
    ("dtdi", "warns"),
    [
        ({"beta_bits": 12}, False),  # the paper: 4031 DN of room, one read adds up to 972 DN (K FW)
        ({"beta_bits": 11}, False),  # 1983 DN of room
        ({"beta_bits": 10}, True),  # 959 DN of room above the 64 DN pedestal: less than one read
        ({"beta_bits": 10, "pedestal_dn": 0}, False),  # 1023 DN
        ({"beta_bits": 10, "pedestal_dn": 0, "subtract_black": False}, False),  # a read adds 1023 DN
        # a read adds at most K FW + b = 992 DN (the full well comes before the ADC top, 1023 DN)
        ({"beta_bits": 10, "pedestal_dn": 1, "subtract_black": False}, False),
        ({"beta_bits": 10, "pedestal_dn": 40, "subtract_black": False}, True),  # 983 DN < 992 DN
        ({"beta_bits": 10, "pedestal_dn": 40}, False),  # 983 DN >= 972 DN: nothing clips on the word
        ({"beta_bits": 8}, True),
    ],
)
def test_a_word_narrower_than_one_pixel_is_warned_about_with_the_numbers(tmp_path, dtdi, warns):
    import warnings

    from bench_sim.config import config_warnings, with_overrides
    from bench_sim.errors import ConfigWarning

    path = tmp_path / "b.toml"
    path.write_text(f"base = '{DEFAULT_CONFIG_PATH}'\n[dtdi]\n" + "".join(
        f"{k} = {str(v).lower()}\n" for k, v in dtdi.items()
    ))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cfg = load_config(path)
        with_overrides(cfg, {"lines": 8})  # configs derived in code are not warned about again
    lines = config_warnings(cfg)
    assert len(lines) == int(warns)
    issued = [str(w.message) for w in caught if w.category is ConfigWarning]
    assert issued == [f"{path}: {ln}" for ln in lines]
    if warns:
        room = 2 ** dtdi["beta_bits"] - 1 - dtdi.get("pedestal_dn", 64)
        assert f"beta_bits = {dtdi['beta_bits']}: the word holds {room} DN" in lines[0]
        assert "widen beta_bits to at least" in lines[0] and "\n" not in lines[0]
