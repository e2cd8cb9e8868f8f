"""Spectral option: QE-weighted rendering against closed forms and the mono path."""

from __future__ import annotations

import numpy as np
import pytest

from bench_sim.config import ConfigError
from bench_sim.render.exposures import render_photons
from bench_sim.rig.spectra import emission_shape, response_values
from tests.conftest import tiny_cfg

FILL_ONLY = dict(
    target={"layout": "uniform", "uniform_reflectance": 0.5},
    lights={"strong": {"enabled": False}, "weak": {"irradiance_w_m2": 5.0}},
    lens={"model": "perspective"},
)


@pytest.fixture(scope="module")
def mono():
    photons, _ = render_photons(tiny_cfg(**FILL_ONLY), 2, np.random.default_rng(0), engine="fast")
    return photons


@pytest.mark.physics
@pytest.mark.parametrize("engine", ["fast", "reference"])
def test_narrow_flat_band_reduces_to_mono(mono, engine):
    cfg = tiny_cfg(**FILL_ONLY, render={"spectral": True, "band_m": [549e-9, 551e-9]})
    photons, setup = render_photons(cfg, 2, np.random.default_rng(0), engine=engine)
    assert setup.info["variant"].endswith("spectral")
    assert np.abs(photons / mono - 1).max() < 0.003


@pytest.mark.physics
@pytest.mark.parametrize("spectrum", ["flat", "blackbody"])
def test_broad_band_follows_the_qe_weighted_closed_form(mono, spectrum):
    """Electrons = integral n_p(lambda) QE(lambda): with the fill's spectrum shape e(lambda)
    (integral 1 over the band) the QE-equivalent photons are the mono photons times
    integral e(lambda) QE(lambda)/QE_ref * lambda/lambda_ref dlambda."""
    cfg = tiny_cfg(
        **{**FILL_ONLY, "lights": {"strong": {"enabled": False},
                                   "weak": {"irradiance_w_m2": 5.0, "spectrum": spectrum}}},
        render={"spectral": True},
    )
    photons, _ = render_photons(cfg, 2, np.random.default_rng(0), engine="reference")
    wl, s = response_values(cfg)
    e = emission_shape(cfg.lights.weak, wl)
    expected = float(np.trapezoid(e * s, wl))
    assert 0.7 < expected < 0.95  # the QE curve falls off towards both ends of 400-700 nm
    assert (photons / mono).mean() == pytest.approx(expected, rel=0.005)


@pytest.mark.physics
def test_fast_and_reference_agree_in_spectral_mode():
    cfg = tiny_cfg(render={"spectral": True, "spp": 64})
    fast, _ = render_photons(cfg, 4, np.random.default_rng(1), engine="fast")
    ref, _ = render_photons(cfg, 4, np.random.default_rng(2), engine="reference")
    assert np.abs(fast - ref).mean() / ref.mean() < 0.02
    assert abs(fast.mean() / ref.mean() - 1) < 0.005


def test_spectral_config_is_validated():
    with pytest.raises(ConfigError, match="band_m"):
        tiny_cfg(render={"spectral": True, "band_m": [300e-9, 700e-9]})
    with pytest.raises(ConfigError, match="wavelength_m"):
        tiny_cfg(render={"spectral": True, "band_m": [600e-9, 700e-9]})
    with pytest.raises(ConfigError, match="qe_curve"):
        tiny_cfg(sensor={"qe_curve": [[500e-9, 0.5], [400e-9, 0.6]]})
