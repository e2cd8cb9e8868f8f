"""The printed ``paper`` target against its specification: the step wedge and the bar groups."""

from __future__ import annotations

import numpy as np
import pytest

from bench_sim.config import TargetConfig
from bench_sim.rig.target import BAR_PERIODS_PX, make_panel

CFG = TargetConfig(panel_lines=512, panel_columns=1024)  # reflectance 0.90 .. 0.02, 16 steps
PANEL = make_panel(CFG, circumference_px=4096.0)


@pytest.mark.physics
@pytest.mark.parametrize("half", ["left", "right"])
def test_wedge_has_16_log_spaced_steps_from_90_to_2_percent(half):
    """16 uniform steps stacked along the track: the first at reflectance_max = 0.90, the last at
    reflectance_min = 0.02, equal ratios between neighbours (log spacing, 20 lg of the ratio =
    -2.20 dB per step); each step is uniform over its whole width."""
    u0, u1, v0, v1 = PANEL.element_box("wedge", half)
    h = (u1 - u0) / 16
    u = u0 + (np.arange(16) + 0.5) * h  # step centres
    v = np.linspace(v0 + 0.5, v1 - 0.5, 25)
    grid = PANEL.reflectance_grid(u, v)
    assert np.ptp(grid, axis=1).max() == 0.0
    steps = grid[:, 0]
    assert steps[0] == pytest.approx(0.90, abs=1e-6) and steps[-1] == pytest.approx(0.02, abs=1e-6)
    ratios = steps[1:] / steps[:-1]
    np.testing.assert_allclose(ratios, ratios[0], rtol=1e-6)
    assert 20 * np.log10(ratios[0]) == pytest.approx(20 * np.log10(0.02 / 0.90) / 15, rel=1e-6)
    # the wedge patches the experiments read are inside their steps, with these reflectances
    patches = sorted((p for p in PANEL.patches if p.name.startswith(f"wedge_{half}")), key=lambda p: p.name)
    assert [p.reflectance for p in patches] == pytest.approx(list(steps), abs=1e-6)
    for k, p in enumerate(patches):
        assert u0 + k * h <= p.u0 < p.u1 <= u0 + (k + 1) * h


def _periods(profile: np.ndarray, step_px: float) -> np.ndarray:
    """Distances [px] between the rising edges (lo -> hi) of a two-level bar profile."""
    hi = profile > 0.5 * (profile.max() + profile.min())
    rising = np.flatnonzero(~hi[:-1] & hi[1:])
    return np.diff(rising) * step_px


@pytest.mark.physics
@pytest.mark.parametrize("along", [False, True], ids=["across", "along"])
def test_bar_groups_have_the_specified_periods_and_contrast(along):
    """Bar groups of periods 2, 3, 4, 6, 8, 12, 16 object pixels, across the track ("vbars") and
    along it ("hbars"), each a square wave between reflectance_min and reflectance_max."""
    u0, u1, v0, v1 = PANEL.element_box("hbars" if along else "vbars", "left")
    n = len(BAR_PERIODS_PX)
    cell = (v1 - v0) / n
    step = 1 / 64  # sampling of the profile [px]
    for k, period in enumerate(BAR_PERIODS_PX):
        cv0, cv1 = v0 + (k + 0.1) * cell, v0 + (k + 0.9) * cell
        if along:
            u = np.arange(u0, u1, step)
            profile = PANEL.reflectance_grid(u, np.array([0.5 * (cv0 + cv1)]))[:, 0]
        else:
            v = np.arange(cv0, cv1, step)
            profile = PANEL.reflectance_grid(np.array([0.5 * (u0 + u1)]), v)[0]
        np.testing.assert_allclose(np.unique(profile), [0.02, 0.90], rtol=1e-6, err_msg=str(period))
        got = _periods(profile, step)
        assert got.size >= 1, period
        np.testing.assert_allclose(got, period, atol=2 * step)
