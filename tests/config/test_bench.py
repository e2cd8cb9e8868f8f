"""The ``dtdi.beta_bits`` warning knows the full well: it fires exactly where stage 1 can clip
on the word (checked against a seeded simulation of a saturated bench)."""

from __future__ import annotations

import numpy as np
import pytest

from bench_sim.config import config_warnings
from bench_sim.workflows.simulate import simulate
from tests.conftest import tiny_cfg

pytestmark = pytest.mark.physics

#: a uniform print under a fill strong enough to fill every pixel's well at stage 1
SATURATED = dict(
    target={"layout": "uniform", "uniform_reflectance": 0.9},
    lights={"strong": {"enabled": False}, "weak": {"irradiance_w_m2": 5000.0}},
    lines=16,
)


@pytest.mark.parametrize(("pedestal", "warns"), [(40, False), (64, True)])
def test_the_warning_fires_exactly_where_a_full_pixel_clips_on_the_word(pedestal: int, warns: bool) -> None:
    """10-bit word, default sensor: a full pixel reads K FW = 972 DN above black (the well fills
    before the 10-bit ADC's 1003 DN). Above a 40 DN pedestal the word has 983 DN of room: no
    warning, and no pixel reaches the word's top; above 64 DN it has 959: the warning, and the
    saturated pixels sit at the top."""
    cfg = tiny_cfg(dtdi={"beta_bits": 10, "pedestal_dn": pedestal}, **SATURATED)
    assert bool(config_warnings(cfg)) is warns
    ds = simulate(cfg, stages=[1, 2], seed=3)
    dn = ds["dn"].sel(stage=1).values.astype(np.int64)
    full = cfg.sensor.full_well_e * cfg.sensor.conversion_gain_dn_per_e + pedestal
    top = 2**10 - 1
    assert bool((dn >= top).any()) is warns
    if warns:  # the saturated pixels sit at the word's top
        assert np.median(dn) == top
    else:  # every well full, read below the word's top
        assert np.median(dn) == pytest.approx(full, abs=2)
