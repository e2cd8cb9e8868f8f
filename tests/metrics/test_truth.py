"""Summary metrics against the exact truth (the dataset manifest's columns)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import bench_sim
from bench_sim.config import config_from_dict
from bench_sim.metrics.truth import region_masks, saturated_fraction, scene_dynamic_range_db, truth_snr
from bench_sim.sensor.model import stage_mean_var_dn
from tests.conftest import TINY

#: closed forms, invariants and seeded statistical tests (make test-fast)
pytestmark = pytest.mark.physics


@pytest.mark.parametrize("irradiance_w_m2", [0.5, 6.0])
def test_truth_snr_of_a_uniform_field_is_the_closed_form(irradiance_w_m2):
    """Under the fill alone on a uniform target, the SNR measured against ``mean_dn`` (one image,
    no pair) is the sensor model's ``signal / sqrt(variance)`` at the pixels' photons (seeded
    statistical test: ~3,000 pixels give the noise to ~1.3 %)."""
    ov = {k: dict(v) for k, v in TINY.items()}
    ov.update(lines=64)
    ov["target"].update(layout="uniform", uniform_reflectance=0.5)
    ov["lights"] = {"strong": {"enabled": False}, "weak": {"irradiance_w_m2": irradiance_w_m2}}
    ds = bench_sim.simulate(ov, stages=[1, 8], seed=11)
    cfg = config_from_dict(ov)
    t_int, ped = ds.attrs["t_int_s"], ds.attrs["pedestal_dn"]
    for s, m in enumerate(ds.stage.values):
        m = int(m)
        photons_per_read = ds.photons.values[s] / m
        ok = ~ds.clipped.values[s]
        assert ok.all()
        dark = float(stage_mean_var_dn(0.0, cfg.sensor, t_int, m, pedestal_dn=ped)[0])
        mean, var = stage_mean_var_dn(photons_per_read, cfg.sensor, t_int, m, pedestal_dn=ped)
        model = (mean.mean() - dark) / math.sqrt(var.mean())
        measured = truth_snr(ds.dn.values[s], ds.mean_dn.values[s], dark, ok)
        assert measured == pytest.approx(model, rel=0.05)


def test_scene_dynamic_range_and_regions():
    rng = np.random.default_rng(3)
    two_levels = np.where(rng.random((40, 50)) < 0.5, 3.0, 3000.0)
    assert scene_dynamic_range_db(two_levels) == pytest.approx(60.0)
    assert scene_dynamic_range_db(7.0 * two_levels) == pytest.approx(60.0)  # scale free
    ramp = np.geomspace(1.0, 1e4, 100_001)
    assert scene_dynamic_range_db(ramp, percentile=0.0) == pytest.approx(80.0)
    assert scene_dynamic_range_db(ramp, percentile=1.0) == pytest.approx(80.0 * 0.98, rel=1e-3)
    assert math.isnan(scene_dynamic_range_db(np.zeros((4, 4))))
    dark, bright = region_masks(ramp, fraction=0.1)
    assert dark.mean() == pytest.approx(0.1, abs=1e-4) and bright.mean() == pytest.approx(0.1, abs=1e-4)
    assert ramp[dark].max() < ramp[bright].min()
    assert saturated_fraction(two_levels > 100) == pytest.approx((two_levels > 100).mean())


def test_truth_snr_edge_cases():
    e = np.full((3, 3), 110.0)
    assert math.isnan(truth_snr(e, e, 10.0, np.zeros((3, 3), bool)))
    assert truth_snr(e, e, 10.0, np.ones((3, 3), bool)) == math.inf
    d = e + np.array([1.0, -1.0, 1.0]).reshape(1, 3)
    assert truth_snr(d, e, 10.0, np.ones((3, 3), bool)) == pytest.approx(100.0)
