"""``reproduce --seeds N``: the spread over seeds of a per-pixel-averaged number shrinks as
1/sqrt(pixels) when the image grows.

The number is eq. 11's mean relative error against the exact truth over the whole image: a mean
over the image's pixels of their noise. The sensor's fixed patterns are switched off here: in DTDI
a column's pattern (PRNU and DSNU summed over the stage's rows, the column amplifier's offset) is
the same on every line, so with them the spread of a whole-image mean is dominated by a term that
shrinks only with the columns (on the default sensor its sd went from 2.9e-4 at 32 lines to 2.3e-4
at 512, nowhere near a quarter). The image grows along the track only (``lines`` and
``target.panel_lines`` by ``GROWTH``, the columns and the illumination across the track kept), so
every pixel sees the same distribution of light and the per-pixel variance is the same: under
"sd ~ 1/sqrt(pixels)" the ratio of the sample variances over the seeds, divided by the ratio of
the pixel counts, follows Fisher's F(n - 1, n - 1). The test asks it to lie within F's central
99 % interval; with ``GROWTH`` = 16 and 8 seeds a spread that does not shrink falls outside it in
about three runs of four, so the test can fail.
"""

from __future__ import annotations

import pytest
from scipy import stats

from bench_sim.config import load_config, with_overrides
from bench_sim.workflows.reproduce.run import run_reproduce

SEEDS = 8
GROWTH = 16
LINES = 32
COLUMNS = 192
LEVEL = 0.99  # central interval of the F distribution


def _spread(tmp_path, lines: int) -> dict:
    cfg = with_overrides(load_config(), {
        "lines": lines,
        "sensor": {"columns": COLUMNS, "prnu_enabled": False, "dsnu_enabled": False, "column_fpn": False},
        "target": {"panel_lines": lines, "panel_columns": COLUMNS}, "render": {"spp": 2},
    })
    m = run_reproduce(cfg, seed=11, out=tmp_path / f"lines{lines}", seeds=SEEDS)
    assert m["seeds"] == list(range(11, 11 + SEEDS))
    return m["spread"]


@pytest.mark.physics
@pytest.mark.slow
def test_spread_over_seeds_shrinks_as_one_over_sqrt_pixels(tmp_path):
    small, large = _spread(tmp_path, LINES), _spread(tmp_path, LINES * GROWTH)
    a, b = small["truth_bias_eq11"], large["truth_bias_eq11"]
    assert a["n"] == b["n"] == SEEDS
    # the DR figures, the gains, the patch SNRs and the truth errors: mean +- sd over every seed
    for key in ("dr_db_gamma_hdr", "gain_db_vs_gamma1", "snr_darkest_gamma_hdr", "truth_rms_eq11"):
        assert small[key]["n"] == large[key]["n"] == SEEDS, key
    ratio = (a["sd"] / b["sd"]) ** 2 / GROWTH  # ~ F(n - 1, n - 1) if sd ~ 1/sqrt(pixels)
    dof = SEEDS - 1
    lo, hi = stats.f.ppf([(1 - LEVEL) / 2, (1 + LEVEL) / 2], dof, dof)
    assert lo <= ratio <= hi, (a["sd"], b["sd"], ratio, (lo, hi))
