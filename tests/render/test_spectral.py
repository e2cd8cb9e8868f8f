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


#: the measured spectra of the photon-count check (colour-science's tables)
LAMP, PATCH, CAMERA = "A", ("ColorChecker N Ohta", "dark skin"), ("Nikon 5100 (NPL)", 1)


def _measured_cfg(engine_spp: int, lamp: str = LAMP, patch: str = "/".join(PATCH)):
    return tiny_cfg(
        target={"layout": "uniform", "uniform_reflectance": 1.0, "reflectance_spectrum": patch},
        lens={"model": "perspective"}, render={"spectral": True, "spp": engine_spp},
        lights={"strong": {"enabled": False}, "weak": {"irradiance_w_m2": 5.0, "spectrum": lamp}},
        sensor={"qe_spectrum": f"{CAMERA[0]}/green"},
    )


def _colour():
    """colour-science, numpy's print options kept (its import sets numpy 1.13's for the process)."""
    options = np.get_printoptions()
    import colour

    np.set_printoptions(**options)
    return colour


def _independent_ratio() -> float:
    """QE-equivalent photons per mono photon of a grey print of reflectance 1, by numpy on a
    0.5-nm grid over 400..700 nm from colour-science's own tables: the lamp's spectrum times the
    patch's reflectance times the response QE(lambda)/QE(550 nm) lambda/550 nm, over the lamp's
    in-band integral."""
    colour = _colour()
    wl = np.arange(400.0, 700.25, 0.5)
    lamp = colour.SDS_ILLUMINANTS[LAMP]
    patch = colour.SDS_COLOURCHECKERS[PATCH[0]][PATCH[1]]
    cam = colour.MSDS_CAMERA_SENSITIVITIES[CAMERA[0]]
    a = np.interp(wl, lamp.wavelengths, lamp.values)
    r = np.interp(wl, patch.wavelengths, patch.values)
    q = np.interp(wl, cam.wavelengths, cam.values[:, CAMERA[1]])
    q550 = np.interp(550.0, cam.wavelengths, cam.values[:, CAMERA[1]])
    return float(np.trapezoid(a * r * q / q550 * wl / 550.0, wl) / np.trapezoid(a, wl))


@pytest.mark.parametrize("engine", ["fast", "reference"])
def test_measured_lamp_patch_and_qe_give_the_integrated_photons(engine):
    """Must show: CIE A on a ColorChecker patch seen through a measured response, in spectral
    mode, gives the photon count of an independent spectral integration within 1e-3 (the grey
    print of reflectance 1 under a flat light, mono, is the reference: its fill is exact)."""
    grey = tiny_cfg(target={"layout": "uniform", "uniform_reflectance": 1.0}, lens={"model": "perspective"},
                    lights={"strong": {"enabled": False}, "weak": {"irradiance_w_m2": 5.0}})
    mono, _ = render_photons(grey, 2, np.random.default_rng(0), engine="fast")
    photons, setup = render_photons(_measured_cfg(64), 2, np.random.default_rng(0), engine=engine)
    assert set(setup.info["spectra"]) == {"lights.weak.spectrum", "target.reflectance_spectrum",
                                          "sensor.qe_spectrum"}
    assert (photons / mono).mean() == pytest.approx(_independent_ratio(), rel=1e-3)


def test_a_lamp_from_csv_is_the_named_one(tmp_path):
    """The same lamp given as a CSV file (its table written out) gives the same photons."""
    lamp = _colour().SDS_ILLUMINANTS[LAMP]
    (tmp_path / "lamp.csv").write_text("wavelength_nm,power\n" + "\n".join(
        f"{w:g},{v:.9g}" for w, v in zip(lamp.wavelengths, lamp.values, strict=True)))
    named, _ = render_photons(_measured_cfg(16), 2, np.random.default_rng(0), engine="fast")
    from_csv, _ = render_photons(_measured_cfg(16, lamp=f"csv:{tmp_path / 'lamp.csv'}"), 2,
                                 np.random.default_rng(0), engine="fast")
    np.testing.assert_allclose(from_csv, named, rtol=1e-6)
