"""Shared fixtures: tiny benches built from the default rig by overriding a few keys."""

from __future__ import annotations

import copy
from typing import Any

import pytest

from bench_sim.config import BenchConfig, config_from_dict, config_to_toml_dict, load_config


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = copy.deepcopy(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = v
    return out


def make_cfg(**sections: Any) -> BenchConfig:
    """The default rig with sections overridden, e.g. ``make_cfg(sensor={"rows": 8})``."""
    return config_from_dict(_merge(config_to_toml_dict(load_config()), sections))


TINY = {
    "sensor": {"rows": 12, "columns": 48},
    "target": {"panel_lines": 96, "panel_columns": 48},
    "render": {"spp": 16, "subpixels": 4},
    "fusion": {"mu1": 2, "mu2": 8},
}


def tiny_cfg(**sections: Any) -> BenchConfig:
    """A 12 x 48 sensor on the default rig (spot edge and wedges in view), overridable."""
    return make_cfg(**_merge(TINY, sections))


@pytest.fixture
def tiny() -> BenchConfig:
    return tiny_cfg()
