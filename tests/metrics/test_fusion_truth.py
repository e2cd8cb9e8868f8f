"""Truth-scored fusion metrics (:mod:`bench_sim.metrics.fusion_truth`) on synthetic DTDI stages
with a closed-form illumination along the track: flat (eq. 11 exact) and a linear gradient (the
light ratio of the TDI window and the error of eq. 11's Gamma1 branch in closed form)."""

from __future__ import annotations

import numpy as np
import pytest

from bench_sim.fusion.paper import fuse_dtdi_hdr_eq11
from bench_sim.metrics.fusion_truth import (
    LIGHT_RATIO_TOLERANCE,
    error_summary,
    from_clipped_stage,
    illumination_regions,
    relative_error,
    tdi_light_ratio,
)

pytestmark = pytest.mark.physics

MU1, MU2, LINES, COLS = 10, 80, 200, 8


def _stage_photons(per_row: np.ndarray, m: int) -> np.ndarray:
    """Stage m of line j sums rows i < m, which saw line j at along-track light per_row[j + i]."""
    out = np.array([per_row[j : j + m].sum() for j in range(LINES)])
    return np.repeat(out[:, None], COLS, axis=1)


@pytest.mark.parametrize("slope", [0.0, 0.02])
def test_light_ratio_and_eq11_error_follow_the_closed_form(slope):
    """Light per row ``a (1 + s y)`` along the track (y in lines): the stage-m pixel of line j sees
    ``a m (1 + s (j + (m - 1) / 2))``, so ``r = (1 + s (j + (mu2-1)/2)) / (1 + s (j + (mu1-1)/2))``;
    eq. 11's Gamma1 branch is off by ``1/r - 1``. Flat light: r = 1 and no error."""
    a = 30.0
    y = np.arange(LINES + MU2)
    per_row = a * (1.0 + slope * y)
    p1, p2 = _stage_photons(per_row, MU1), _stage_photons(per_row, MU2)
    j = np.arange(LINES)[:, None]
    r_closed = (1 + slope * (j + (MU2 - 1) / 2)) / (1 + slope * (j + (MU1 - 1) / 2))
    r = tdi_light_ratio(p1, p2, MU1, MU2)
    np.testing.assert_allclose(r, np.broadcast_to(r_closed, r.shape), rtol=1e-12)
    # noise-free words, no clip (16-bit word): eq. 11 takes Gamma1 where it predicts Gamma2 outside
    fused = fuse_dtdi_hdr_eq11(np.rint(p1), np.rint(p2), mu1=MU1, mu2=MU2, beta=16)
    err = relative_error(fused.hdr, p2)
    from_g1 = fused.source == MU1
    expected = np.where(from_g1, 1.0 / r_closed, 1.0) - 1.0
    np.testing.assert_allclose(err, expected, atol=2.0 / p2.min() * MU2 / MU1)
    regions = illumination_regions(p2, np.full(p2.shape, 0.5), r)
    band = np.abs(r_closed - 1.0) > LIGHT_RATIO_TOLERANCE
    assert np.array_equal(regions["spot_edge"], np.broadcast_to(band, r.shape))
    if slope == 0.0:
        assert not regions["spot_edge"].any()
        assert error_summary(err, regions)["whole"]["rms"] < 1e-3
    else:
        assert regions["spot_edge"].mean() > 0.5
        s = error_summary(err, regions)["spot_edge"]
        assert s["bias"] == pytest.approx(float(np.mean(expected[regions["spot_edge"]])), abs=1e-3)


def test_from_clipped_stage_counts_the_chosen_stage_only():
    source = np.array([[10, 80], [80, 10]])
    clipped = {10: np.array([[True, True], [False, False]]), 80: np.array([[False, True], [False, True]])}
    assert np.array_equal(from_clipped_stage(source, clipped), [[True, True], [False, False]])


def test_error_summary_and_relative_error_floor():
    err = relative_error([2.0, 1.5, 9.0], [1.0, 1.0, 0.5])
    assert np.isnan(err[2]) and err[0] == 1.0
    s = error_summary(err, {"all": np.ones(3, bool), "none": np.zeros(3, bool)})
    assert s["all"]["bias"] == pytest.approx(0.75) and s["all"]["rms"] == pytest.approx(np.sqrt(0.625))
    assert s["none"] == {"bias": None, "rms": None, "pixels": 0}
