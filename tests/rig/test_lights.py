"""Lights: kinds and their stated irradiance, flicker weights in closed form, flicker through the
reference engine without recompiling, and the banding DTDI leaves of it."""

from __future__ import annotations

import math

import drjit as dr
import numpy as np
import pytest
from scipy import integrate

from bench_sim.config import ConfigError, load_config
from bench_sim.pipeline import run_pass
from bench_sim.render.exposures import prepare
from bench_sim.rig.lights import flicker_fundamental, frame_weights, window_mean
from bench_sim.rig.scene import area_radiance_w_m2_sr, light_names
from tests.conftest import ALL_OFF, make_cfg, tiny_cfg

#: closed forms, invariants and seeded statistical tests (make test-fast)
pytestmark = pytest.mark.physics

R = 0.10  # the default drum radius: the camera looks at (0, 0, R)
OFF = {"strong": {"enabled": False}, "weak": {"enabled": False}}


def _waveform(kind: str, depth: float, f: float, phase: float, t: np.ndarray) -> np.ndarray:
    """The relative intensity w(t) of the config's definition (bench_sim.config.FLICKER_WAVEFORMS)."""
    if kind == "sine":
        return 1 + depth * np.sin(2 * np.pi * f * t + phase)
    return 1 - depth + depth * (np.pi / 2) * np.abs(np.sin(np.pi * f * t + phase / 2))


# --- configuration ---------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["spot", "fill", "directional", "point", "area"])
def test_every_kind_loads_and_emits_after_the_defaults(kind: str) -> None:
    lamp = {"kind": kind, "irradiance_w_m2": 3.0}
    cfg = make_cfg(lights={"lamp": lamp, "weak": {"enabled": kind != "fill"}})
    assert cfg.lights.get("lamp").kind == kind
    expected = ("strong", "weak", "lamp") if kind != "fill" else ("strong", "lamp")
    assert light_names(cfg) == expected
    dark = make_cfg(lights={"lamp": dict(lamp, irradiance_w_m2=0.0)})
    assert light_names(dark) == ("strong", "weak")


def test_presets_keep_strong_and_weak_unchanged() -> None:
    from bench_sim.config import SCENES_DIR

    assert light_names(load_config(SCENES_DIR / "strong.toml")) == ("strong",)
    assert light_names(load_config(SCENES_DIR / "weak.toml")) == ("weak",)
    cfg = load_config()
    assert (cfg.lights.strong.kind, cfg.lights.weak.kind) == ("spot", "fill")
    assert not cfg.lights.strong.flickers and not cfg.lights.weak.flickers


@pytest.mark.parametrize(
    ("lights", "message"),
    [
        ({"lamp": {"irradiance_w_m2": 3.0}}, r"lights: lamp: no kind; a light needs kind = one of 'spot'"),
        ({"lamp": {"kind": "laser"}}, r"lights: lamp: kind = 'laser'; a light needs kind"),
        ({"Lamp": {"kind": "point"}}, r"lights: light name 'Lamp': use a lower-case identifier"),
        ({"drum": {"kind": "point"}}, r"lights: light name 'drum'"),
        ({"lamp": {"kind": "area", "size_m": [0.1, 0.0]}}, r"lights\.lamp\.size_m\[1\] = 0\.0: .*than 0"),
        ({"lamp": {"kind": "point", "cutoff_deg": 3}}, r"unknown key 'lights\.lamp\.cutoff_deg'"),
        ({"lamp": {"kind": "directional", "direction": [0, 0, 0]}}, r"lights\.lamp: direction = \[0, 0, 0\]"),
        ({"lamp": {"kind": "fill"}}, r"lights: fill lights \['weak', 'lamp'\] all emit"),
        ({"weak": {"flicker_depth": 1.5}}, r"lights\.weak\.flicker_depth = 1\.5: .*less than or equal to 1"),
        ({"weak": {"flicker_waveform": "square"}}, r"lights\.weak\.flicker_waveform = 'square'"),
        ({"strong": {"kind": "fill"}}, r"lights\.strong\.kind = 'fill': Input should be 'spot'"),
    ],
)
def test_bad_light_tables_are_one_line_naming_the_key(lights: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=r"^config error: <overrides>: " + message) as info:
        make_cfg(lights=lights)
    assert "\n" not in str(info.value)


# --- closed forms ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("w", "h", "d"), [(0.1, 0.1, 0.4), (0.3, 0.05, 0.1), (1.0, 2.0, 0.05), (0.02, 0.5, 1.0)]
)
def test_area_radiance_inverts_the_view_factor_integral(w: float, h: float, d: float) -> None:
    """E = L * integral over the rectangle of cos(theta) cos(theta') / r^2 = L d^2 / r^4, by
    numerical quadrature, near and far."""
    per_radiance, _ = integrate.dblquad(
        lambda y, x: d * d / (x * x + y * y + d * d) ** 2, -w / 2, w / 2, -h / 2, h / 2, epsabs=1e-12
    )
    assert area_radiance_w_m2_sr(7.0, (w, h), d) * per_radiance == pytest.approx(7.0, rel=1e-7)


@pytest.mark.parametrize("waveform", ["sine", "rectified_sine"])
@pytest.mark.parametrize(
    ("depth", "f", "phase", "t0", "t_int"),
    [
        (1.0, 100.0, 0.0, 0.0, 1e-4),
        (0.3, 120.0, 1.3, 0.0123, 1e-3),
        (1.0, 100.0, -2.0, 0.0071, 0.0237),  # a window over two and a bit periods
        (0.7, 5e3, 0.4, 1.2345, 1e-4),  # half a period
        (0.5, 100.0, 0.0, 0.004, 0.01),  # exactly one period: mean 1
    ],
)
def test_window_mean_is_the_average_of_the_waveform(
    waveform: str, depth: float, f: float, phase: float, t0: float, t_int: float
) -> None:
    want, _ = integrate.quad(
        lambda t: _waveform(waveform, depth, f, phase, np.array(t)), t0, t0 + t_int, limit=200, epsabs=1e-13
    )
    got = window_mean(waveform, depth, f, phase, t0, t_int)
    assert float(got) == pytest.approx(want / t_int, abs=1e-7)


@pytest.mark.parametrize("waveform", ["sine", "rectified_sine"])
def test_fundamental_amplitude_is_the_waveforms_fourier_coefficient(waveform: str) -> None:
    t = np.arange(4096) / 4096 / 100.0  # one period at 100 Hz
    w = _waveform(waveform, 0.8, 100.0, 0.9, t)
    coeff = 2 * abs(np.mean(w * np.exp(-2j * np.pi * 100.0 * t)))
    assert flicker_fundamental(waveform, 0.8) == pytest.approx(coeff, rel=1e-6)


def test_frame_weights_follow_the_line_period_and_integration_window() -> None:
    cfg = make_cfg(
        lights={"weak": {"flicker_hz": 100.0, "flicker_depth": 0.5, "flicker_phase_rad": 0.2}},
        timing={"line_period_s": 1e-3, "integration_time_s": 4e-4},
    )
    w = frame_weights(cfg, "weak", 5, 9)
    want = [integrate.quad(lambda t: _waveform("sine", 0.5, 100.0, 0.2, np.array(t)), k * 1e-3,
                           k * 1e-3 + 4e-4)[0] / 4e-4 for k in range(5, 9)]
    assert w == pytest.approx(want, abs=1e-10)
    assert np.array_equal(frame_weights(cfg, "strong", 5, 9), np.ones(4))
    with pytest.raises(ValueError, match="not among this bench's emitting lights"):
        frame_weights(make_cfg(lights=OFF), "weak", 0, 2)


# --- rendering ---------------------------------------------------------------------------------

_TILT = math.radians(30.0)
_KINDS = {
    "spot": ({"position_m": [0, 0, 0.6], "aim_m": [0, 0, R], "cutoff_deg": 20, "beam_width_deg": 15}, 1.0),
    "point": ({"position_m": [0, 0, 0.6], "reference_m": [0, 0, R]}, 1.0),
    "directional": ({"direction": [0, 0, -1]}, 1.0),
    "fill": ({}, 1.0),
    # off the camera's axis (a panel on it would hide the drum), tilted by 30 deg; small enough
    # that the tilted plane's irradiance is E cos(30 deg) to 1e-3
    "area": (
        {"position_m": [0, 0.3 * math.sin(_TILT), R + 0.3 * math.cos(_TILT)], "aim_m": [0, 0, R],
         "size_m": [0.05, 0.03]},
        math.cos(_TILT),
    ),
}


@pytest.mark.slow
@pytest.mark.parametrize("engine", ["reference", "fast"])
@pytest.mark.parametrize("kind", list(_KINDS))
def test_each_kind_gives_its_stated_irradiance_on_the_drum(kind: str, engine: str) -> None:
    """A uniform print of albedo rho shows the radiance rho E / pi (Lambert) under a light of
    irradiance E at the point the camera looks at, on both engines."""
    table, cos_incidence = _KINDS[kind]
    e, rho = 10.0, 0.5
    cfg = tiny_cfg(
        lights=dict(OFF, lamp={"kind": kind, "irradiance_w_m2": e, **table}),
        target={"layout": "uniform", "uniform_reflectance": rho},
        render={"spp": 32, "engine": engine},
    )
    setup = prepare(cfg, 1, np.random.default_rng(0))
    centre = setup.engine.radiance_frames(0, 1)[0, 5:7, 20:28]
    assert float(centre.mean()) == pytest.approx(rho * e / math.pi * cos_incidence, rel=2e-3)


@pytest.mark.slow
def test_reference_engine_weights_each_frame_without_recompiling() -> None:
    """A flickering fill alone on a uniform print (zero-variance estimator): frame k is exactly
    w_k times the steady frame, and changing the weight reuses the compiled kernels."""
    base = {"lights": {"strong": {"enabled": False}}, "target": {"layout": "uniform"},
            "render": {"spp": 4, "engine": "reference"}, "timing": {"line_period_s": 1e-3}}
    flicker = {"weak": {"flicker_hz": 100.0, "flicker_depth": 0.8, "flicker_waveform": "rectified_sine"}}
    steady_cfg = tiny_cfg(**base)
    cfg = tiny_cfg(**dict(base, lights=dict(base["lights"], **flicker)))
    steady = prepare(steady_cfg, 5, np.random.default_rng(0)).engine.radiance_frames(0, 5)
    engine = prepare(cfg, 5, np.random.default_rng(0)).engine
    first = engine.radiance_frames(0, 1)  # compiles (or loads) the kernels
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()  # clear
        rest = engine.radiance_frames(1, 5)
        jit = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert jit and all(k["cache_hit"] for k in jit)
    w = frame_weights(cfg, "weak", 0, 5)
    assert np.ptp(w) > 0.5
    got = np.concatenate([first, rest])
    np.testing.assert_allclose(got, w[:, None, None] * steady, rtol=2e-6)


@pytest.mark.slow
@pytest.mark.parametrize("engine", ["reference", "fast"])
def test_flicker_banding_falls_with_the_stage_as_averaging_a_sinusoid_over_m_periods(engine: str) -> None:
    """The issue's test 6: a fill with flicker_depth = 1 at 100 Hz over a uniform print, line
    period T = 1 ms (10 lines per flicker period). Nothing imposes the banding: each frame gets
    its window's mean intensity, and DTDI sums the frames. The along-track amplitude of stage m,
    relative to its mean, must be that of a sinusoid averaged over m line periods,
    |sin(pi f m T) / (pi f m T)| -- vanishing at m = 10, a whole period. Both engines: the
    reference one renders each frame with the light's weight, the fast one forms each frame as
    the weighted sum of its per-light records."""
    f, period = 100.0, 1e-3
    cfg = tiny_cfg(
        lights={"strong": {"enabled": False},
                "weak": {"irradiance_w_m2": 10.0, "flicker_hz": f, "flicker_depth": 1.0}},
        target={"layout": "uniform"}, sensor=ALL_OFF, timing={"line_period_s": period},
        render={"spp": 4, "engine": engine}, lines=40, fusion={"mu1": 2, "mu2": 10},
    )
    stages = list(range(1, 11))
    res = run_pass(cfg, stages, 0, truth=False)
    pedestal = cfg.dtdi.pedestal_dn
    for m in stages:
        profile = res.stage_dn[m].astype(np.float64).mean(axis=1) - pedestal
        lines = np.arange(profile.size)
        amplitude = 2 * abs(np.mean(profile * np.exp(-2j * np.pi * f * period * lines))) / profile.mean()
        x = math.pi * f * m * period
        assert amplitude == pytest.approx(abs(math.sin(x) / x), abs=3e-3), m
