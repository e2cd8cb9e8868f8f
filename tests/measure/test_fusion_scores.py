"""Truth-scored fusion of a simulated pass (:mod:`bench_sim.measure.fusion_scores`): a uniform
target under the fill alone (light flat along the track: no band, eq. 11 exact within noise) and
under the spot (the band appears where the light ratio of the TDI window leaves the tolerance,
and eq. 11's Gamma1 branch is off there by the closed form ``1/r - 1``)."""

from __future__ import annotations

import numpy as np
import pytest

from bench_sim.fusion.paper import fuse_dtdi_hdr_eq11
from bench_sim.measure.fusion_scores import fusion_scores
from bench_sim.metrics.fusion_truth import LIGHT_RATIO_TOLERANCE
from bench_sim.pipeline import run_pass
from bench_sim.sensor.model import stage_offset_dn
from tests.conftest import tiny_cfg

pytestmark = pytest.mark.physics

FIXED_OFF = {"prnu_enabled": False, "dsnu_enabled": False, "column_fpn": False}


def _scored(lights, seed=1, beta_bits=12):
    cfg = tiny_cfg(lines=64, target={"layout": "uniform"}, lights=lights, sensor=FIXED_OFF,
                   dtdi={"beta_bits": beta_bits})
    mu1, mu2 = cfg.fusion.mu1, cfg.fusion.mu2
    sim = run_pass(cfg, [mu1, mu2], seed)
    offs = tuple(stage_offset_dn(cfg.sensor, cfg.dtdi, m) for m in (mu1, mu2))
    beta = cfg.dtdi.beta_bits
    fused = fuse_dtdi_hdr_eq11(
        sim.stage_dn[mu1], sim.stage_dn[mu2], mu1=mu1, mu2=mu2, beta=beta, pedestal_dn=offs
    )
    return cfg, sim, fused, fusion_scores(cfg, sim, fused)


def test_flat_light_along_the_track_has_no_band_and_no_bias():
    cfg, sim, fused, s = _scored({"strong": {"enabled": False}, "weak": {"irradiance_w_m2": 20.0}})
    lr = s.summary["light_ratio"]
    assert lr["outside_fraction"] == 0.0 and lr["max_abs_dev"] < LIGHT_RATIO_TOLERANCE
    e = s.summary["rules"]["eq11"]
    assert e["from_clipped_pixels"] == 0
    err = s.maps["relative_error_eq11"]
    # bias within 5 standard errors of 0 (temporal noise only)
    assert abs(np.nanmean(err)) < 5 * np.nanstd(err) / np.sqrt(np.isfinite(err).sum())


def test_spot_edge_band_follows_the_light_ratio():
    cfg, sim, fused, s = _scored({}, beta_bits=9)  # Gamma2 clips under the spot: eq. 11 takes Gamma1
    mu1, mu2 = cfg.fusion.mu1, cfg.fusion.mu2
    r = s.maps["light_ratio"]
    band = np.abs(r - 1.0) > LIGHT_RATIO_TOLERANCE
    assert band.any() and (~band).any(), "the tiny field shows the spot's edge"
    err = s.maps["relative_error_eq11"]
    ds = sim.dataset
    off = {m: stage_offset_dn(cfg.sensor, cfg.dtdi, m) for m in (mu1, mu2)}
    lin = {m: ds["linear_dn"].sel(stage=m).values - off[m] for m in (mu1, mu2)}
    # closed form of the Gamma1 branch against the truth: (mu2/mu1) E[Gamma1] / E[Gamma2] - 1
    predicted = (mu2 / mu1) * lin[mu1] / lin[mu2] - 1.0
    g1 = (fused.source == mu1) & band & np.isfinite(err)
    assert g1.sum() > 20
    resid = err[g1] - predicted[g1]
    sd = np.sqrt((mu2 / mu1) ** 2 * np.var(sim.stage_dn[mu1][g1] - lin[mu1][g1]
                                          - stage_offset_dn(cfg.sensor, cfg.dtdi, mu1))) / lin[mu2][g1].mean()
    assert abs(resid.mean()) < 5 * sd / np.sqrt(g1.sum()) + 1e-3
    assert np.abs(predicted[g1]).mean() > LIGHT_RATIO_TOLERANCE / 2  # the band is a real error
    # outside the band the light is flat: eq. 11 is unbiased there
    flat = ~band & np.isfinite(err)
    assert abs(err[flat].mean()) < 0.01
