"""reproduce's sharpness per stage (bench_sim.workflows.reproduce.stage_mtf): the companion pass
keeps the bench and swaps the target, and its figure and table hold the MTF50 of every stage."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from bench_sim.config import with_overrides
from bench_sim.io import read_png_text
from bench_sim.workflows.reproduce.stage_mtf import (
    COMPANION_LINES,
    companion_config,
    measure_stage_mtf,
    write_stage_mtf,
)
from tests.conftest import make_cfg


def _bench():
    return make_cfg(sensor={"rows": 24, "columns": 128}, target={"panel_lines": 256, "panel_columns": 128},
                    lights={"strong": {"enabled": False}, "weak": {"irradiance_w_m2": 30.0}},
                    render={"spp": 4}, fusion={"mu1": 4, "mu2": 16}, timing={"sync_error": 0.15})


def test_companion_pass_keeps_the_bench_and_swaps_the_target() -> None:
    cfg = _bench()
    comp = companion_config(cfg)
    assert comp.target.layout == "slanted_edges" and cfg.target.layout == "paper"
    assert comp.lines == COMPANION_LINES and comp.sensor.columns == 128
    patterns = {"columns": 0, "prnu_enabled": False, "dsnu_enabled": False, "column_fpn": False}
    for section in ("sensor", "timing", "dtdi", "lens", "drum", "lights", "fusion"):
        a, b = getattr(comp, section).model_dump(), getattr(cfg, section).model_dump()
        assert a == b or section == "sensor" and {**a, **patterns} == {**b, **patterns}, section
    assert not (comp.sensor.prnu_enabled or comp.sensor.dsnu_enabled or comp.sensor.column_fpn)


@pytest.mark.physics
def test_mtf50_vs_stage_files(tmp_path: Path) -> None:
    cfg = _bench()
    ds = measure_stage_mtf(cfg, seed=3)
    assert [int(m) for m in ds.stage.values] == [1, 4, 10, 16, 20]
    names = write_stage_mtf(ds, cfg, tmp_path, {"seed": 3, "version": "x"})
    assert names == ["mtf50_vs_stage.csv", "mtf50_vs_stage.png"]
    with (tmp_path / "mtf50_vs_stage.csv").open() as fh:
        rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))
    assert [r["stage"] for r in rows] == ["1", "4", "10", "16", "20", "gamma_hdr"]
    along = np.array([float(r["mtf50_along_cyc_px"]) for r in rows[:-1]])
    across = np.array([float(r["mtf50_across_cyc_px"]) for r in rows[:-1]])
    # a sync error of 0.15 line per line: the along-track MTF50 falls with the stage, across does not
    assert np.all(np.diff(along) < 0) and along[-1] < 0.8 * along[0]
    np.testing.assert_allclose(across, np.median(across), rtol=0.06)
    assert float(rows[-1]["mtf50_along_cyc_px"]) == pytest.approx(along[3], rel=0.03)  # HDR from stage 16
    assert read_png_text(tmp_path / "mtf50_vs_stage.png")["seed"] == 3
    assert "noise-free" in read_png_text(tmp_path / "mtf50_vs_stage.png")["noise"]


@pytest.mark.physics
def test_mtf50_vs_stage_is_noise_free() -> None:
    """No noise makes a trend: without a sync error nothing changes with the stage but the noise,
    and the companion's MTF50s are the same at every stage to 1e-5 (the expected words of a
    sensor without fixed patterns; a noisy pass scatters them by per cents)."""
    cfg = with_overrides(_bench(), {"timing": {"sync_error": 0.0}})
    ds = measure_stage_mtf(cfg, seed=3)
    for d in ("along", "across"):
        v = ds[f"mtf50_{d}"].values
        np.testing.assert_allclose(v, v[0], rtol=1e-5, err_msg=d)
    assert np.array_equal(ds["dn"].values, ds["mean_dn"].values)
