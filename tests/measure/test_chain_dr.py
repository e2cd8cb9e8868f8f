"""Measured DR through sensor -> DTDI -> eq. 11 fusion (bench_sim.measure.chain_dr)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench_sim.config import BenchConfig, with_overrides
from bench_sim.fusion.paper import fuse_dtdi_hdr_eq11
from bench_sim.measure.chain_dr import ChainDR, measure_chain_dynamic_range
from bench_sim.measure.uniform_field import (
    PEDESTAL_SIGMAS,
    expose_uniform,
    measurement_offsets_dn,
    measurement_pedestal_dn,
)
from bench_sim.metrics.dynamic_range import dr_increase_eq15_db
from bench_sim.sensor.emva import draw_fixed_pattern
from bench_sim.sensor.model import stage_dark_std_dn, stage_saturation_photons

MU1, MU2 = 10, 80
CFG = BenchConfig()


def _cfg(**dtdi: object) -> BenchConfig:
    return with_overrides(CFG, {"dtdi": dtdi})


@pytest.fixture(scope="module")
def dr12() -> ChainDR:
    return measure_chain_dynamic_range(_cfg(beta_bits=12), 12)


@pytest.fixture(scope="module")
def dr16() -> ChainDR:
    return measure_chain_dynamic_range(_cfg(beta_bits=16), 16)


@pytest.mark.physics
def test_word_limited_gain_over_gamma2_is_eq15_by_construction(dr12: ChainDR) -> None:
    """beta = 12: both stages clip on the word, so HDR - Gamma2 is 20 lg(mu2/mu1) by
    construction: the HDR is Gamma2 at the dark end (same SNR = 1 point) and Gamma1 x mu2/mu1 at
    the bright end."""
    assert dr12.gain_over_gamma2_by_construction
    # the two measured saturation points (EMVA variance maxima of 2 x 32 x 64 pixels per level)
    # scatter: over 30 seeds the gain's standard deviation is 0.25 - 0.36 dB (before / after the
    # sensor pass drew its noise per chunk of frames), so 0.75 dB is 2 - 3 sigma
    assert abs(dr12.gain_over_gamma2_db - dr_increase_eq15_db(MU1, MU2)) <= 0.75
    # where the linear response meets the plateau (no variance scatter) the two saturation
    # points are exactly mu2/mu1 apart: the construction itself, to a few thousandths of a dB
    ext = dr12.images["gamma_hdr"].dr_db_extrapolated - dr12.images["gamma2"].dr_db_extrapolated
    assert abs(ext - dr_increase_eq15_db(MU1, MU2)) <= 0.02
    img = dr12.images
    assert img["gamma_hdr"].photons_min == pytest.approx(img["gamma2"].photons_min)
    assert img["gamma_hdr"].photons_sat == pytest.approx(img["gamma1"].photons_sat, rel=0.02)


@pytest.mark.physics
def test_gain_over_gamma1_is_the_read_noise_ratio(dr12: ChainDR) -> None:
    """Over Gamma1 the HDR gains only at the dark end: the read noise of the digital sum grows as
    sqrt(m), so about 10 lg(mu2/mu1) = 9 dB, and it agrees with the sensor model's prediction."""
    model_gain = dr12.model_dr_db["gamma_hdr"] - dr12.model_dr_db["gamma1"]
    # the measured SNR = 1 points (the dark end, where this gain is made) scatter with the seed:
    # over seeds 0-9 the gain is 9.09 +- 0.26 dB (single-normal sampler) and 9.16 +- 0.30 dB
    # (Box-Muller normals), model 9.10 dB; 0.9 dB is 3 sigma
    assert dr12.gain_over_gamma1_db == pytest.approx(model_gain, abs=0.9)
    assert dr12.gain_over_gamma1_db == pytest.approx(10 * math.log10(MU2 / MU1), abs=1.0)
    for name in ("gamma1", "gamma2", "gamma_hdr"):
        # the model's clip is where the linear response meets the plateau (extrapolated point);
        # EMVA's variance maximum lies a little below it. The SNR = 1 point scatters with the seed:
        # over seeds 0-9 extrapolated - model is -0.04 +- 0.23 dB (Gamma1), 0.03 +- 0.20 dB (Gamma2,
        # Gamma_HDR), so 0.75 dB is over 3 sigma
        img = dr12.images[name]
        assert img.dr_db_extrapolated == pytest.approx(dr12.model_dr_db[name], abs=0.75), name
        assert dr12.model_dr_db[name] - 1.0 < img.dr_db < img.dr_db_extrapolated, name


@pytest.mark.physics
def test_pixel_limited_gain_shrinks(dr16: ChainDR) -> None:
    """beta = 16: stage 10 clips on the pixel, not the word; the gain over Gamma2 is the ratio of
    the two clips (model), about 1.5 dB, not eq. 15's 18 dB, and not 'by construction'. With
    the extrapolated saturation points it is that ratio exactly; with EMVA's variance maxima
    (located from 32 x 64-pixel pairs) it scatters: over 12 seeds -0.14 +- 0.14 dB from the
    ratio (the variance peaks a little below the clip), so 0.6 dB is over 3 sigma."""
    assert not dr16.gain_over_gamma2_by_construction
    ped = dr16.pedestal_dn
    sat = {
        m: stage_saturation_photons(CFG.sensor, CFG.timing.t_int_s, m, beta_bits=16, pedestal_dn=ped)
        for m in (MU1, MU2)
    }
    ratio_db = 20 * math.log10(sat[MU1] / sat[MU2])
    assert dr16.as_dict()["delta_db_vs_gamma2_extrapolated"] == pytest.approx(ratio_db, abs=0.05)
    assert dr16.gain_over_gamma2_db == pytest.approx(ratio_db, abs=0.6)
    assert dr16.dr_db["gamma2"] > dr16.dr_db["gamma1"]


@pytest.mark.physics
def test_hdr_monotonic_noise_off() -> None:
    """Noise off: Gamma_HDR grows with the scene signal, equals gamma2's signal where that is
    unsaturated, and reaches (mu2/mu1) x gamma1's signal range."""
    quiet = with_overrides(
        CFG,
        {"sensor": {k: False for k in (
            "shot_noise", "dark_noise", "read_noise", "prnu_enabled", "dsnu_enabled", "column_fpn"
        )}},
    )
    ped = quiet.dtdi.pedestal_dn
    fixed = draw_fixed_pattern(quiet.sensor, np.random.default_rng(0))
    off = measurement_offsets_dn(quiet, (MU1, MU2), ped)
    hdr, s2 = [], []
    for p in np.linspace(0.0, 25000.0, 120):  # beyond gamma1's saturation (~10,000 photons)
        st = expose_uniform(
            quiet, (MU1, MU2), p, np.random.default_rng(0), fixed=fixed, lines=1, columns=4, images=1,
            pedestal_dn=ped,
        )
        f = fuse_dtdi_hdr_eq11(st[MU1][0], st[MU2][0], mu1=MU1, mu2=MU2, beta=12, pedestal_dn=ped)
        hdr.append(float(f.hdr.mean()))
        s2.append(float(st[MU2][0].mean()) - off[MU2])
    hdr_a, s2_a = np.asarray(hdr), np.asarray(s2)
    assert np.all(np.diff(hdr_a) >= 0)
    unsat = s2_a < 4095 - ped - 8  # one stage-10 DN below gamma2's clip
    assert np.any(unsat) and np.any(~unsat)
    np.testing.assert_array_equal(hdr_a[unsat], s2_a[unsat])
    assert hdr_a.max() == 8 * (4095 - ped)


@pytest.mark.physics
def test_hdr_monotonic_averaged_with_noise(dr12: ChainDR) -> None:
    """With all noise on, the level means of Gamma_HDR rise with the signal (to 4 standard errors)."""
    n_pix = dr12.lines * dr12.columns * 2
    hdr = dr12.images["gamma_hdr"]
    se = hdr.temporal_std_dn / math.sqrt(n_pix)
    assert np.all(np.diff(hdr.mean_dn) >= -4 * np.sqrt(se[1:] ** 2 + se[:-1] ** 2))
    assert hdr.mean_dn[-1] > 7 * 4095 * 0.9  # reaches the extended range


@pytest.mark.physics
def test_measurement_pedestal_keeps_the_dark_value_unclipped() -> None:
    """With no configured pedestal the measurement raises it to 5 sigma of stage 80's dark
    spread: none of the dark stage values is stored as 0; without it about half would be."""
    cfg = _cfg(pedestal_dn=0)
    ped = measurement_pedestal_dn(cfg, (MU1, MU2))
    assert ped >= PEDESTAL_SIGMAS * stage_dark_std_dn(cfg.sensor, cfg.timing.t_int_s, MU2)
    fixed = draw_fixed_pattern(cfg.sensor, np.random.default_rng(1))
    kw = {"fixed": fixed, "lines": 64, "columns": 256, "images": 1}
    dark = expose_uniform(cfg, (MU2,), 0.0, np.random.default_rng(2), pedestal_dn=ped, **kw)[MU2]
    raw = expose_uniform(cfg, (MU2,), 0.0, np.random.default_rng(2), pedestal_dn=0, **kw)[MU2]
    assert np.mean(dark == 0) == 0.0
    assert 0.3 < np.mean(raw == 0) < 0.7
    # the default config's 64 DN already covers it: the measurement runs the configured chain
    assert measurement_pedestal_dn(CFG, (MU1, MU2)) == CFG.dtdi.pedestal_dn == 64


@pytest.mark.physics
def test_gain_without_black_subtraction() -> None:
    """subtract_black off (stage m carries m x black): the offsets differ per stage and are
    removed; stage 80's accumulated black takes word range, so the gain over Gamma2 exceeds
    eq. 15 by the ratio of the two signal ranges (the model's), and is not 'by construction'."""
    r = measure_chain_dynamic_range(_cfg(subtract_black=False), 3, n_levels=30, lines=16)
    assert r.offsets_dn[MU2] - r.offsets_dn[MU1] == (MU2 - MU1) * CFG.sensor.black_offset_dn
    assert not r.gain_over_gamma2_by_construction
    ranges = [4095 - r.offsets_dn[m] for m in (MU1, MU2)]
    predicted = dr_increase_eq15_db(MU1, MU2) + 20 * math.log10(ranges[0] / ranges[1])
    ext = r.images["gamma_hdr"].dr_db_extrapolated - r.images["gamma2"].dr_db_extrapolated
    assert ext == pytest.approx(predicted, abs=0.3)  # the clip points: exact up to noise
    assert r.gain_over_gamma2_db == pytest.approx(predicted, abs=1.5)  # variance maxima: near it


def test_measure_chain_dynamic_range_is_deterministic_for_any_thread_count(monkeypatch) -> None:
    """The levels run on the thread pool, each with its own stream: 1 and 2 threads give the
    same series (refinement rounds included), another seed another one."""
    kw = {"n_levels": 10, "lines": 4, "columns": 8}
    monkeypatch.setenv("BENCH_SIM_THREADS", "2")
    a = measure_chain_dynamic_range(CFG, 7, **kw).as_dict()
    monkeypatch.setenv("BENCH_SIM_THREADS", "1")
    b = measure_chain_dynamic_range(CFG, 7, **kw).as_dict()
    c = measure_chain_dynamic_range(CFG, 8, **kw).as_dict()
    assert a == b
    assert len(a["images"]["gamma2"]["mean_dn"]) > 11  # the refinement rounds added levels
    assert a["images"]["gamma2"]["mean_dn"] != c["images"]["gamma2"]["mean_dn"]


@pytest.mark.physics
def test_variance_max_saturation_is_located_accurately() -> None:
    """A coarse grid (12 levels over 3 decades, ~5 dB apart) refined twice finds Gamma2's
    variance maximum where a dense 0.5 %-step scan (another seed) finds it, to the scatter of
    the maximum itself (~2 % for 1024-pixel images); the parabola on the coarse grid alone is
    off by far more."""
    kw = {"n_levels": 12, "lines": 16, "columns": 32}
    coarse = measure_chain_dynamic_range(CFG, 1, **kw)
    unrefined = measure_chain_dynamic_range(CFG, 1, refine_rounds=0, **kw)
    sat = coarse.images["gamma2"].photons_sat
    assert coarse.level_step_db_max > 4.0
    dense = measure_chain_dynamic_range(
        CFG, 2, levels=np.union1d(coarse.photons, sat * np.linspace(0.85, 1.1, 51)), lines=16,
        columns=32, refine_rounds=0,
    )
    truth = dense.images["gamma2"].photons_sat
    assert sat == pytest.approx(truth, rel=0.04)
    assert abs(unrefined.images["gamma2"].photons_sat / truth - 1) > 0.15
    # EMVA's point lies below the extrapolated one (where the plateau is met)
    assert sat < coarse.images["gamma2"].photons_sat_extrapolated
