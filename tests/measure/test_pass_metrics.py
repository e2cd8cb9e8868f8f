"""Per-pass metrics: patches chosen as lit, targets without wedge patches say so."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench_sim.fusion.paper import fuse_dtdi_hdr_eq11
from bench_sim.measure.pass_metrics import pass_metrics, patch_slices
from bench_sim.pipeline import run_pass
from bench_sim.sensor.emva import draw_fixed_pattern
from bench_sim.sensor.model import stage_offset_dn
from tests.conftest import tiny_cfg


def _metrics(cfg, seed=3):
    sim = run_pass(cfg, (cfg.fusion.mu1, cfg.fusion.mu2), seed, truth=False)
    mu1, mu2 = cfg.fusion.mu1, cfg.fusion.mu2
    offsets = tuple(stage_offset_dn(cfg.sensor, cfg.dtdi, m) for m in (mu1, mu2))
    fused = fuse_dtdi_hdr_eq11(sim.stage_dn[mu1], sim.stage_dn[mu2], mu1=mu1, mu2=mu2,
                               beta=cfg.dtdi.beta_bits, pedestal_dn=offsets)
    return pass_metrics(cfg, sim, fused)


@pytest.mark.physics
@pytest.mark.parametrize(("aim_x_m", "dark_half"), [(-0.0155, "right"), (0.0155, "left")])
def test_darkest_and_brightest_patches_follow_the_light(aim_x_m: float, dark_half: str) -> None:
    """The spot lights one half of the wedge: the darkest patch is the 2 % step of the other
    half, the brightest the 90 % step under the spot, whichever half that is (the fill raised
    tenfold so that the few pixels of a tiny patch rank the steps above the noise)."""
    lights = {"strong": {"aim_m": [aim_x_m, 0.0, 0.10]}, "weak": {"irradiance_w_m2": 60.0}}
    cfg = tiny_cfg(lines=96, lights=lights)
    pm = _metrics(cfg)
    lit = "left" if dark_half == "right" else "right"
    assert pm.darkest_patch["patch"] == f"wedge_{dark_half}_{cfg.target.wedge_steps - 1:02d}"
    assert pm.brightest_patch["patch"] == f"wedge_{lit}_00"
    assert pm.darkest_patch["reflectance"] == pytest.approx(cfg.target.reflectance_min)
    snr = pm.brightest_patch["snr"]
    assert all(v is None or (math.isfinite(v) and v > 0) for v in snr.values())
    assert pm.no_patches is None


def test_a_target_without_wedge_says_so_instead_of_failing() -> None:
    pm = _metrics(tiny_cfg(lines=48, target={"layout": "uniform"}))
    assert pm.darkest_patch is None and pm.brightest_patch is None and pm.qualitative is None
    assert pm.no_patches == "target.layout = 'uniform' has no wedge patches"
    assert 0.0 <= pm.saturated_fraction["gamma2"] <= 1.0
    assert math.isfinite(pm.eq18.omega_hdr)


@pytest.mark.physics
def test_temporal_snr_from_the_truth_matches_repeated_exposures() -> None:
    """The darkest patch's temporal SNR from the truth (closed-form variance of each pixel's stage
    word) against the noise measured over repeated exposures of the same scene by the same
    physical sensor: per pixel the mean and variance over ``n`` noise seeds, then mean signal over
    root mean variance. The relative standard error of a variance from ``n`` draws averaged over
    ``P`` pixels is ``sqrt(2 / ((n - 1) P))``; the SNR's is half that; 4 of them are allowed."""
    lights = {"weak": {"irradiance_w_m2": 60.0}}
    cfg = tiny_cfg(lines=96, lights=lights)
    mu1, mu2 = cfg.fusion.mu1, cfg.fusion.mu2
    offsets = tuple(stage_offset_dn(cfg.sensor, cfg.dtdi, m) for m in (mu1, mu2))
    first = run_pass(cfg, (mu1, mu2), 0)
    fp = draw_fixed_pattern(cfg.sensor, np.random.default_rng(123))
    runs = [run_pass(cfg, (mu1, mu2), seed, fixed_pattern=fp) for seed in range(1, 13)]
    fused = fuse_dtdi_hdr_eq11(runs[0].stage_dn[mu1], runs[0].stage_dn[mu2], mu1=mu1, mu2=mu2,
                               beta=cfg.dtdi.beta_bits, pedestal_dn=offsets)
    pm = pass_metrics(cfg, runs[0], fused)
    sl = patch_slices(first.setup.grid.panel, first.setup.geom, cfg, cfg.lines)[pm.darkest_patch["patch"]]
    predicted = pm.darkest_patch["temporal_snr"]
    n_pix = np.ones(runs[0].stage_dn[mu1].shape)[sl].size
    for name, m in (("gamma1", mu1), ("gamma2", mu2)):
        stack = np.stack([r.stage_dn[m][sl].astype(np.float64) for r in runs])
        measured = (stack.mean(axis=0) - stage_offset_dn(cfg.sensor, cfg.dtdi, m)).mean() / math.sqrt(
            stack.var(axis=0, ddof=1).mean())
        rel_se = 0.5 * math.sqrt(2.0 / ((len(runs) - 1) * n_pix))
        assert measured == pytest.approx(predicted[name], rel=4 * rel_se + 0.01), (name, measured, predicted)
    assert predicted["gamma_hdr"] == pytest.approx(predicted["gamma2"], rel=1e-9)  # eq. 11 keeps Gamma2 there
