"""The split config package: one TOML reader and one error formatter for configs and both specs,
the closed forms in one place, the re-exported names."""

from __future__ import annotations

from pathlib import Path

import pytest

import bench_sim.config as config
from bench_sim.config import ConfigError, load_config, quick_config, read_toml
from bench_sim.sensor import model
from bench_sim.workflows.dataset.spec import load_spec as load_dataset_spec
from bench_sim.workflows.sweep.spec import load_spec as load_sweep_spec

LOADERS = {"config": load_config, "sweep": load_sweep_spec, "dataset": load_dataset_spec}


def _bad_file(folder: Path, kind: str) -> Path:
    path = folder / f"{kind}.toml"
    if kind == "folder":
        path.mkdir()
    elif kind == "utf8":
        path.write_bytes(b"name = '\xff'\n")
    elif kind == "nul":
        path.write_bytes(b"name = 1\x00\n")
    elif kind == "toml":
        path.write_text("[sensor\n")
    return path


@pytest.mark.parametrize("loader", sorted(LOADERS))
@pytest.mark.parametrize(
    ("kind", "needle"),
    [("missing", "no such file"), ("folder", "is a folder"), ("utf8", "not UTF-8 text (byte 0xff"),
     ("nul", "NUL bytes"), ("toml", "not valid TOML")],
)
def test_every_toml_is_read_by_one_reader(tmp_path: Path, loader: str, kind: str, needle: str) -> None:
    path = _bad_file(tmp_path, kind)
    with pytest.raises(ConfigError) as info:
        LOADERS[loader](path)
    msg = str(info.value)
    assert "\n" not in msg and needle in msg and path.name in msg


def test_read_toml_names_the_file_with_its_label(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"^my label: no such file$"):
        read_toml(tmp_path / "x.toml", "my label")


def test_unknown_spec_keys_list_what_is_allowed(tmp_path: Path) -> None:
    (tmp_path / "s.toml").write_text("seeds = 3\n")
    with pytest.raises(ConfigError, match=r"unknown key 'seeds' \(allowed: name, description, base, quick"):
        load_sweep_spec(tmp_path / "s.toml")


def test_closed_forms_live_once_and_sensor_model_delegates() -> None:
    cfg = load_config()
    s, d = cfg.sensor, cfg.dtdi
    assert model.pixel_saturation_dn(s) == s.pixel_saturation_dn == 2**s.adc_bits - 1
    assert model.pixel_saturation_electrons(s) == s.pixel_saturation_electrons
    adc_top_e = (2**s.adc_bits - 1 - s.black_offset_dn) / s.conversion_gain_dn_per_e
    assert s.pixel_saturation_electrons == min(s.full_well_e, adc_top_e)
    assert model.dark_electrons(s, 1e-4) == s.dark_electrons(1e-4) == s.dark_current_e_s * 1e-4
    assert model.word_clip_dn(d.beta_bits) == d.word_clip_dn == 2**d.beta_bits - 1
    assert model.full_scale_dn(d.beta_bits) == d.full_scale_dn == 2**d.beta_bits


def test_quick_preset_is_a_config_preset() -> None:
    q = quick_config(load_config())
    assert (q.lines, q.sensor.columns, q.render.spp) == (256, 512, 8)


def test_public_names_are_re_exported() -> None:
    for name in config.__all__:
        assert getattr(config, name) is not None
    assert {"load_config", "with_overrides", "ConfigError", "check_variant_name"} <= set(config.__all__)
