"""Radiometry against closed forms: Lambertian radiance, the camera equation, cos^4, photons."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench_sim.render.exposures import render_photons
from bench_sim.render.radiometry import (
    cos_chief_ray,
    focal_plane_irradiance,
    photon_energy_j,
    photons_per_pixel,
)
from bench_sim.rig.geometry import rig_geometry
from bench_sim.runtime.backend import init_mitsuba
from tests.conftest import tiny_cfg

#: closed forms, invariants and seeded statistical tests (make test-fast)
pytestmark = pytest.mark.physics


def test_diffuse_plane_under_directional_light_is_rho_e_cos_over_pi():
    """Mitsuba's film holds radiance: a Lambertian plane (albedo 0.5) lit by a directional
    irradiance E = 10 W/m^2 at 30 degrees reads rho * E * cos(theta) / pi within 1 %."""
    mi, _ = init_mitsuba()
    rho, e, theta = 0.5, 10.0, math.radians(30.0)
    light_dir = [0.0, -math.sin(theta), -math.cos(theta)]  # travelling towards the plane
    scene = mi.load_dict(
        {
            "type": "scene",
            "integrator": {"type": "direct"},
            "sensor": {
                "type": "perspective",
                "fov": 20.0,
                "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 2], target=[0, 0, 0], up=[0, 1, 0]),
                "film": {"type": "hdrfilm", "width": 16, "height": 16, "rfilter": {"type": "box"}},
                "sampler": {"type": "independent", "sample_count": 16},
            },
            "plane": {
                "type": "rectangle",
                "to_world": mi.ScalarTransform4f().scale([5.0, 5.0, 1.0]),
                "bsdf": {"type": "diffuse", "reflectance": {"type": "uniform", "value": rho}},
            },
            "sun": {
                "type": "directional",
                "direction": light_dir,
                "irradiance": {"type": "uniform", "value": e},
            },
        }
    )
    img = np.array(mi.render(scene))[..., 0]
    expected = rho * e * math.cos(theta) / math.pi
    assert img.mean() == pytest.approx(expected, rel=0.01)
    assert np.abs(img / expected - 1).max() < 0.01


def test_photon_conversion_matches_hand_calculation():
    # L = 10 W m^-2 sr^-1, N = 4, m = 0.1111, tau = 0.9, on axis:
    # E = pi * 0.9 * 10 / (4 * 16 * 1.1111^2) = 0.35785 W/m^2
    e = focal_plane_irradiance(10.0, 4.0, 1.0 / 9.0, 0.9)
    assert float(e) == pytest.approx(math.pi * 9.0 / (64.0 * (10.0 / 9.0) ** 2), rel=1e-12)
    assert float(e) == pytest.approx(0.357847, rel=1e-5)
    # photon energy at 550 nm: 6.62607015e-34 * 299792458 / 550e-9 = 3.6117e-19 J
    assert photon_energy_j(550e-9) == pytest.approx(3.61172e-19, rel=1e-5)
    # n = E * (5.5 um)^2 * 100 us / E_ph = 0.357847 * 3.025e-11 * 1e-4 / 3.61172e-19 = 2997.2
    n = photons_per_pixel(e, 5.5e-6, 100e-6, 550e-9)
    assert float(n) == pytest.approx(2997.2, rel=1e-4)


@pytest.mark.parametrize("engine", ["fast", "reference"])
def test_rig_under_uniform_fill_gives_closed_form_photons(engine):
    """Uniform target (rho = 0.5) under the weak fill alone (constant environment, irradiance E
    on the convex drum): every pixel sees L = rho * E / pi, so the photons per pixel follow the
    camera equation exactly (within 1 %), including the cos^4 fall-off off axis."""
    cfg = tiny_cfg(
        target={"layout": "uniform", "uniform_reflectance": 0.5},
        lights={"strong": {"enabled": False}, "weak": {"irradiance_w_m2": 5.0}},
        sensor={"rows": 8, "columns": 32, "pixel_pitch_m": 4e-4},  # wide field: visible cos^4
        lens={"model": "perspective"},
    )
    photons, setup = render_photons(cfg, 3, np.random.default_rng(3), engine=engine)
    g = rig_geometry(cfg)
    radiance = 0.5 * 5.0 / math.pi
    cos_t = cos_chief_ray(8, 32, 4e-4, g.image_distance_m)
    e = focal_plane_irradiance(radiance, cfg.lens.f_number, g.magnification, cfg.lens.transmission, cos_t)
    expected = photons_per_pixel(e, 4e-4, cfg.timing.t_int_s, cfg.sensor.wavelength_m)
    ratio = photons / expected[None]
    assert np.abs(ratio - 1).max() < 0.01  # BSDF sampling of a uniform fill: exact up to float
    # the fall-off is real and of the cos^4 size: corner / centre well below 1
    corner_over_centre = expected[0, 0] / expected[4, 16]
    assert corner_over_centre < 0.98  # cos^4 of the 6.8 degree corner chief ray: 0.974
    assert photons[:, 0, 0].mean() / photons[:, 4, 16].mean() == pytest.approx(corner_over_centre, rel=0.01)


def test_cos4_can_be_switched_off():
    cfg = tiny_cfg(
        target={"layout": "uniform"},
        lights={"strong": {"enabled": False}},
        sensor={"rows": 8, "columns": 32, "pixel_pitch_m": 4e-4},
        lens={"model": "perspective", "cos4_falloff": False},
    )
    photons, _ = render_photons(cfg, 1, np.random.default_rng(0), engine="fast")
    assert photons[0, 0, 0] / photons[0, 4, 16] == pytest.approx(1.0, abs=0.01)


def test_diffraction_keeps_energy_and_blurs_edges():
    """The lens' diffraction (f/22 here: the first dark ring at 1.5 pixels) conserves the photons
    of a uniform field and lowers the contrast of fine bars; turned off, it is the perfect lens."""
    uni = {"layout": "uniform"}
    a, sa = render_photons(tiny_cfg(target=uni, lens={"f_number": 22.0, "diffraction": False}), 2,
                           np.random.default_rng(0), engine="fast")
    b, sb = render_photons(tiny_cfg(target=uni, lens={"f_number": 22.0}), 2, np.random.default_rng(0),
                           engine="fast")
    assert sa.grid.lens is None and sb.grid.lens is not None
    assert sa.info["lens_blur"].startswith("none") and sb.info["lens_blur"].startswith("diffraction")
    assert b.mean() == pytest.approx(a.mean(), rel=1e-4)
    sharp, _ = render_photons(tiny_cfg(lens={"f_number": 22.0, "diffraction": False}), 4,
                              np.random.default_rng(0), engine="fast", first_frame=60)
    blurred, _ = render_photons(tiny_cfg(lens={"f_number": 22.0}), 4, np.random.default_rng(0), engine="fast",
                                first_frame=60)
    assert blurred.std() < 0.97 * sharp.std()
    # the PSF (out to 16 dark rings, 43 px at f/22) mixes in the target around this 12 x 48 view
    assert blurred.mean() == pytest.approx(sharp.mean(), rel=0.03)
