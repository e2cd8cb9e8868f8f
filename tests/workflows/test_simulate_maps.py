"""``simulate``'s truth maps of the fusion (issue 21): ``gamma_hdr_error`` and ``tdi_light_ratio``."""

from __future__ import annotations

import numpy as np
import pytest

import bench_sim
from bench_sim.metrics.fusion_truth import LIGHT_RATIO_TOLERANCE
from bench_sim.pipeline import VARIABLES_BY_NAME
from tests.conftest import TINY

#: a uniform target under the fill light alone: no light gradient along the track
UNIFORM = {
    **TINY,
    "lines": 64,
    "target": {"layout": "uniform", "panel_lines": 96, "panel_columns": 48},
    "lights": {"strong": {"enabled": False}, "weak": {"irradiance_w_m2": 1.0}},
}


def test_maps_are_float32_line_column_maps_with_units():
    ds = bench_sim.simulate(UNIFORM, stages=[2, 8], seed=1)
    for name in ("gamma_hdr_error", "tdi_light_ratio"):
        assert ds[name].dims == ("line", "column")
        assert ds[name].dtype == np.float32
        assert ds[name].attrs["units"] == "1" == VARIABLES_BY_NAME[name].units
        assert ds[name].attrs["long_name"] == VARIABLES_BY_NAME[name].doc
    assert "gamma_hdr_error" not in bench_sim.simulate(UNIFORM, stages=[2], seed=1)


@pytest.mark.physics
def test_uniform_target_has_light_ratio_one_and_no_error_beyond_noise():
    """Uniform light along the track: every row of the TDI window sees the same light, ``r = 1``
    within :data:`LIGHT_RATIO_TOLERANCE`; nothing clips, so ``gamma_hdr`` is the stage-``mu2``
    word less the pedestal, unbiased: its relative error averages to 0 within 5 standard errors
    (the spread of the error itself, pixels independent), over several seeds."""
    errors = []
    for seed in range(3):
        ds = bench_sim.simulate(UNIFORM, stages=[2, 8], seed=seed)
        assert not ds.clipped.values.any()
        r = ds.tdi_light_ratio.values
        assert np.isfinite(r).all() and np.abs(r - 1.0).max() < LIGHT_RATIO_TOLERANCE
        err = ds.gamma_hdr_error.values.astype(np.float64)
        assert np.isfinite(err).all()
        errors.append(err.ravel())
        assert (ds.gamma_hdr_source.values == 8).all()  # unclipped: eq. 11 keeps Gamma2
    e = np.concatenate(errors)
    assert abs(e.mean()) < 5 * e.std() / np.sqrt(e.size)
    assert e.std() < 0.2  # a lit field: the noise is a small fraction of the signal
