"""Shared fixtures: tiny benches built from the default rig by overriding a few keys."""

from __future__ import annotations

from typing import Any

import pytest

from bench_sim.config import BenchConfig, load_config, with_overrides


def make_cfg(**sections: Any) -> BenchConfig:
    """The default rig with sections overridden, e.g. ``make_cfg(sensor={"rows": 8})``."""
    return with_overrides(load_config(), sections)


#: every noise source of the pixel model switched off
ALL_OFF = dict(
    shot_noise=False, dark_noise=False, read_noise=False, prnu_enabled=False,
    dsnu_enabled=False, column_fpn=False, quantization=False,
)

TINY = {
    "sensor": {"rows": 12, "columns": 48},
    "target": {"panel_lines": 96, "panel_columns": 48},
    "render": {"spp": 16, "subpixels": 4},
    "fusion": {"mu1": 2, "mu2": 8},
}


def tiny_cfg(**sections: Any) -> BenchConfig:
    """A 12 x 48 sensor on the default rig (spot edge and wedges in view), overridable."""
    return with_overrides(with_overrides(load_config(), TINY), sections)


@pytest.fixture
def tiny() -> BenchConfig:
    return tiny_cfg()
