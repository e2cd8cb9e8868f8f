"""Per-pass metrics: patches chosen as lit, targets without wedge patches say so."""

from __future__ import annotations

import math

import pytest

from bench_sim.fusion.paper import fuse_dtdi_hdr_eq11
from bench_sim.measure.pass_metrics import pass_metrics
from bench_sim.pipeline import run_pass
from bench_sim.sensor.model import stage_offset_dn
from tests.conftest import tiny_cfg


def _metrics(cfg, seed=3):
    sim = run_pass(cfg, (cfg.fusion.mu1, cfg.fusion.mu2), seed, truth=False)
    mu1, mu2 = cfg.fusion.mu1, cfg.fusion.mu2
    offsets = tuple(stage_offset_dn(cfg.sensor, cfg.dtdi, m) for m in (mu1, mu2))
    fused = fuse_dtdi_hdr_eq11(sim.stage_dn[mu1], sim.stage_dn[mu2], mu1=mu1, mu2=mu2,
                               beta=cfg.dtdi.beta_bits, pedestal_dn=offsets)
    return pass_metrics(cfg, sim, fused)


@pytest.mark.slow
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


@pytest.mark.slow
def test_a_target_without_wedge_says_so_instead_of_failing() -> None:
    pm = _metrics(tiny_cfg(lines=48, target={"layout": "uniform"}))
    assert pm.darkest_patch is None and pm.brightest_patch is None and pm.qualitative is None
    assert pm.no_patches == "target.layout = 'uniform' has no wedge patches"
    assert 0.0 <= pm.saturated_fraction["gamma2"] <= 1.0
    assert math.isfinite(pm.eq18.omega_hdr)
