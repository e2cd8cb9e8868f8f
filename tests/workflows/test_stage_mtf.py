"""reproduce's sharpness per stage (bench_sim.workflows.reproduce.stage_mtf): the companion pass
keeps the bench and swaps the target, and its figure and table hold the MTF50 of every stage."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from bench_sim.config import with_overrides
from bench_sim.io import read_png_text
from bench_sim.measure.sharpness import add_sharpness
from bench_sim.pipeline import run_pass
from bench_sim.workflows.reproduce.result import SharpnessResult
from bench_sim.workflows.reproduce.sharpness_report import sharpness_section
from bench_sim.workflows.reproduce.stage_mtf import (
    COMPANION_LINES,
    COMPANION_TEXELS_PER_PIXEL,
    companion_config,
    measure_stage_mtf,
    noise_free,
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
    res = measure_stage_mtf(cfg, seed=3)
    assert res.stages == [1, 4, 10, 16, 20]
    names = write_stage_mtf(res, cfg, tmp_path, {"seed": 3, "version": "x"})
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
    res = measure_stage_mtf(cfg, seed=3)
    for d in ("along", "across"):
        v = res.mtf50(d)
        np.testing.assert_allclose(v, v[0], rtol=1e-5, err_msg=d)


def test_companion_on_arrays_is_the_dataset_path() -> None:
    """The companion measures on the pass's arrays (no dataset, no xarray on its lane): the same
    SFRs to the bit as the noise-free dataset through add_sharpness (simulate's and the sweeps' path)."""
    cfg = _bench()
    res = measure_stage_mtf(cfg, seed=3)
    comp = companion_config(cfg)
    rng = np.random.default_rng(np.random.SeedSequence(3).spawn(2)[1])
    ds = add_sharpness(noise_free(run_pass(comp, res.stages, rng, truth=True).dataset, comp), comp)
    assert np.array_equal(ds["dn"].values, ds["mean_dn"].values)
    for d in ("along", "across"):
        assert np.array_equal(res.sfr(d), ds[f"sfr_{d}"].values, equal_nan=True), d
        assert np.array_equal(res.mtf50(d), ds[f"mtf50_{d}"].values, equal_nan=True), d
        assert res.hdr_mtf50(d) == float(ds[f"gamma_hdr_mtf50_{d}"]), d


def test_companion_draws_finer_edges_through_a_lens() -> None:
    """Through a lens that blurs (diffraction, the default) the companion's target has 8 texels per
    pixel; a perfect lens keeps the bench's (the numbers of bench_sim 0.3)."""
    assert companion_config(_bench()).target.texels_per_pixel == COMPANION_TEXELS_PER_PIXEL == 8
    perfect = make_cfg(lens={"diffraction": False})
    assert companion_config(perfect).target.texels_per_pixel == perfect.target.texels_per_pixel == 4


def _sharpness(measured: float | None, warning: str | None = None) -> SharpnessResult:
    return SharpnessResult(
        lens="diffraction: N_w = 4.444 at 550 nm", sharpness_stages=[1, 10], mtf50_across_cyc_px=0.45,
        mtf50_along_cyc_px=0.36, mtf_nyquist_across=measured, mtf_nyquist_along=0.28,
        closed_nyquist_across=0.458, closed_nyquist_across_binned=0.447, closed_mtf50_across_cyc_px=0.467,
        nyquist_warning=warning,
    )


def test_sharpness_section_says_what_was_measured() -> None:
    """The report's sharpness section: the measurement matches the closed form only within 3 %,
    the deviation signed; the Nyquist warning when there is one."""
    close = "\n".join(sharpness_section(_sharpness(0.440)))
    assert "which the measurement matches (-1.6 %)" in close and "Warning" not in close
    assert "| SFR at Nyquist (0.5 cycles/px) | 0.440 | 0.280 |" in close
    far = "\n".join(sharpness_section(_sharpness(0.480, "the system MTF50 ... above Nyquist")))
    assert "from which the measurement differs (+7.4 %)" in far and "**Warning:** the system MTF50" in far
    assert "could not measure" in "\n".join(sharpness_section(_sharpness(None)))
