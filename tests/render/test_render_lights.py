"""The fast engine is linear in each light: records rendered once per light and reused."""

from __future__ import annotations

import numpy as np
import pytest

from bench_sim.render import engines, records
from bench_sim.render.exposures import iter_photon_frames, prepare
from tests.conftest import tiny_cfg

FIRST = 60  # bar groups of the tiny panel in view


def _frames(cfg, frames=6, seed=0):
    setup = prepare(cfg, frames, np.random.default_rng(seed), engine="fast", first_frame=FIRST)
    return np.concatenate(list(iter_photon_frames(setup))), setup


def _lights(strong_w_m2: float, weak_w_m2: float, **sections):
    lights = {"strong": {"irradiance_w_m2": strong_w_m2}, "weak": {"irradiance_w_m2": weak_w_m2}}
    return tiny_cfg(lights=lights, **sections)


def test_light_power_change_reuses_records_and_equals_a_fresh_render():
    """A new light power, target or sensor noise model makes no Mitsuba render; the frames
    equal those of a fresh render at the new power, and are linear in each light's power:
    ``P(3 E_s) - P(E_s) = 2 (P(E_s) - P(0))``."""
    records.clear_record_cache()
    base, s0 = _frames(_lights(128.0, 6.0))
    assert s0.info["mitsuba_renders"] == 2  # hit positions, then the spot (the fill: closed form)
    n0 = records.mitsuba_render_count()
    tripled, s1 = _frames(_lights(384.0, 6.0), seed=1)
    dark, _ = _frames(_lights(0.0, 6.0))
    other, _ = _frames(_lights(128.0, 6.0, target={"layout": "uniform"}, sensor={"read_noise_e": 3.0}))
    assert records.mitsuba_render_count() == n0 and s1.info["mitsuba_renders"] == 0
    assert not np.allclose(other, base)
    scale = float(base.mean())
    np.testing.assert_allclose(tripled - base, 2.0 * (base - dark), rtol=0, atol=2e-5 * scale)
    assert float((base - dark).mean()) > 0.1 * scale  # the spot is really in view
    records.clear_record_cache()
    fresh, s2 = _frames(_lights(384.0, 6.0))
    assert s2.info["mitsuba_renders"] == 2
    np.testing.assert_allclose(tripled, fresh, rtol=1e-6, atol=1e-6 * scale)


@pytest.mark.physics
def test_flicker_weights_scale_each_light_per_frame(monkeypatch):
    """With per-frame weights ``w_l(k)`` (flicker), frame ``k`` is ``sum_l w_l(k) P_l(k)``, where
    ``P_l`` are the frames under light ``l`` alone (the other light at zero power) -- and no
    render is made for it."""
    strong_only, _ = _frames(_lights(128.0, 0.0))
    weak_only, _ = _frames(_lights(0.0, 6.0))
    n0 = records.mitsuba_render_count()
    ks = np.arange(FIRST, FIRST + 6)
    weights = {"strong": 1.0 + 0.8 * np.sin(0.9 * ks), "weak": np.full(ks.size, 0.25)}

    def frame_weights(cfg, name, k0, k1):
        return weights[name][k0 - FIRST : k1 - FIRST]

    monkeypatch.setattr(engines, "frame_weights", frame_weights)
    both, setup = _frames(_lights(128.0, 6.0))
    assert setup.info["mitsuba_renders"] == 0 and records.mitsuba_render_count() == n0
    expected = weights["strong"][:, None, None] * strong_only + weights["weak"][:, None, None] * weak_only
    np.testing.assert_allclose(both, expected, rtol=1e-5, atol=1e-5 * float(expected.mean()))
    # the weights really vary: frames differ from the steady sum by more than float error
    assert np.abs(both - (strong_only + weak_only)).max() > 0.1 * float(expected.mean())


@pytest.mark.parametrize(
    "change", [{"lens": {"f_number": 5.6}}, {"lights": {"strong": {"aim_m": [0.0, 0.0, 0.1]}}}]
)
def test_geometry_or_light_placement_change_renders_again(change):
    records.clear_record_cache()
    _frames(tiny_cfg())
    _, setup = _frames(tiny_cfg(**change))
    assert setup.info["mitsuba_renders"] == 2  # positions and the spot (the fill: closed form)


@pytest.mark.physics
@pytest.mark.parametrize("lens", ["thinlens", "perspective"])
def test_fill_records_in_closed_form_equal_a_mitsuba_render(monkeypatch, lens):
    """A fill (uniform sky) on the analytic drum: its records are the fill's radiance L per unit
    albedo in closed form (a convex drum sees the whole sky above its tangent plane), the same
    as Mitsuba's render of the fill alone, record by record."""
    cfg = _lights(128.0, 6.0, lens={"model": lens})
    records.clear_record_cache()
    closed, s_closed = _frames(cfg)
    monkeypatch.setattr(records, "_fill_in_closed_form", lambda cfg, name: False)
    records.clear_record_cache()
    rendered, s_rendered = _frames(cfg)
    records.clear_record_cache()
    assert (s_closed.info["mitsuba_renders"], s_rendered.info["mitsuba_renders"]) == (2, 3)
    np.testing.assert_allclose(closed, rendered, rtol=1e-5, atol=1e-6 * float(rendered.mean()))


def test_records_made_elsewhere_are_installed_and_give_identical_frames():
    """Records made by :func:`fast_records` (what another worker hands over) and installed in
    a fresh cache make no render, and the frames are bit for bit those of records rendered by
    the pass itself; a sync error or a new light power does not change the records' group."""
    from bench_sim.render.exposures import fast_records, records_group

    cfg = _lights(128.0, 6.0)
    records.clear_record_cache()
    own, _ = _frames(cfg)
    shipped = fast_records(cfg)  # from the cache: the same arrays, without the derived kernels
    assert shipped.derived == {} and shipped.renders == 2
    records.clear_record_cache()
    assert records.install_records(shipped) and not records.install_records(shipped)
    n0 = records.mitsuba_render_count()
    installed, setup = _frames(cfg)
    assert records.mitsuba_render_count() == n0 and setup.info["mitsuba_renders"] == 0
    np.testing.assert_array_equal(installed, own)
    assert records_group(cfg) == records_group(_lights(512.0, 1.0, timing={"sync_error": 0.01}))
    assert records_group(cfg) != records_group(_lights(128.0, 6.0, render={"subpixels": 2}))
    assert records_group(cfg, engine="reference") is None
    records.clear_record_cache()


def test_kernel_sets_kept_with_the_records_are_bounded():
    """A drum speed per sample (sync error) makes a new kernel set each time; the records keep
    only the last :data:`~bench_sim.render.engines.KERNEL_ENTRIES`."""
    records.clear_record_cache()
    for k in range(engines.KERNEL_ENTRIES + 2):
        _, setup = _frames(_lights(128.0, 6.0, timing={"sync_error": 0.001 * k}), frames=2)
    kept = [key for key in setup.engine.records.derived if key[0] == "kernels"]
    assert len(kept) == engines.KERNEL_ENTRIES
    records.clear_record_cache()
