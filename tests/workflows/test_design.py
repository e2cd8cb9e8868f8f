"""``bench-sim design``: the scores against an independent computation from ``simulate``'s output,
bad specs (one line, nothing written), the outputs, and the configured pair against ``reproduce``."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from bench_sim import simulate
from bench_sim.cli import app
from bench_sim.config import BenchConfig, load_config
from bench_sim.fusion.stage_pair import fuse_stage_words, true_hdr_dn
from bench_sim.io import OUTPUT_MARKER
from bench_sim.measure.pass_metrics import stage_temporal_var_dn2
from bench_sim.metrics.fusion_truth import (
    clear_of_clips,
    clip_flags,
    clip_regions,
    error_summary,
    from_clipped_stage,
    illumination_regions,
    relative_error,
    tdi_light_ratio,
)
from bench_sim.sensor.model import hdr_dr_model_db
from bench_sim.workflows.design.run import run_design

ROOT = Path(__file__).resolve().parents[2]
runner = CliRunner()

#: a 24-row sensor on the paper rig: the spot's edge and the wedge in view, stage 16 clipping
TINY = f"""
base = "{ROOT / 'scenes' / 'paper_rig.toml'}"
name = "tiny"
lines = 48
[sensor]
rows = 24
columns = 48
[target]
panel_lines = 48
panel_columns = 48
[render]
spp = 4
[fusion]
mu1 = 2
mu2 = 16
"""
SEED = 11


def _spec(folder: Path, name: str, body: str) -> Path:
    (folder / "tiny.toml").write_text(TINY)
    path = folder / f"{name}.toml"
    path.write_text(f'base = "tiny.toml"\nseed = {SEED}\n{body}')
    return path


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Every pair of the tiny bench by eq. 11 and the clip-aware rule, one word, the chosen chain DRs."""
    folder = tmp_path_factory.mktemp("design")
    spec = _spec(folder, "pairs", 'rules = ["eq11", "clip"]\nchain_dr = "chosen"\n'
                 '[[constraints]]\nobjective = "clipped_share"\nmax = 0.0\n')
    out = folder / "out"
    run_design(spec, out, workers=0, progress=False)
    return out


def _independent(cfg: BenchConfig, ds: xr.Dataset, mu1: int, mu2: int) -> dict[str, float]:
    """The scores of the pair (mu1, mu2) by eq. 11 from a simulate output, with the functions of
    fusion_truth: eq. 11 against linear_dn of stage mu2 less its offsets."""
    sel = {m: {v: ds[v].sel(stage=m).values for v in ("dn", "linear_dn", "mean_dn", "noise_std_dn", "photons",
                                                       "reflectance", "clipped")} for m in (mu1, mu2)}
    fused = fuse_stage_words(cfg, sel[mu1]["dn"], sel[mu2]["dn"], mu1=mu1, mu2=mu2)
    truth = true_hdr_dn(cfg, sel[mu2]["linear_dn"], mu2=mu2)
    err = relative_error(fused.hdr, truth)
    truth_of = ("linear_dn", "mean_dn", "noise_std_dn")
    clear = [clear_of_clips(*(sel[m][v] for v in truth_of)) for m in (mu1, mu2)]
    ratio = tdi_light_ratio(sel[mu1]["photons"], sel[mu2]["photons"], mu1, mu2)
    regions = {**illumination_regions(sel[mu2]["photons"], sel[mu2]["reflectance"], ratio),
               **clip_regions(clip_flags(*clear))}
    out: dict[str, float] = {}
    for region, v in error_summary(err, regions).items():
        suffix = "" if region == "whole" else f"_{region}"
        out[f"truth_bias{suffix}"] = math.nan if v["bias"] is None else v["bias"]
        out[f"truth_rms{suffix}"] = math.nan if v["rms"] is None else v["rms"]
        out[f"pixels_{region}"] = v["pixels"]
    clipped = {m: sel[m]["clipped"] for m in (mu1, mu2)}
    out["clipped_share"] = float(from_clipped_stage(fused.source, clipped).mean())
    out["low_share"] = float(np.mean(fused.source == mu1))
    # the darkest 5 % of the pixels by their light per row at the highest stage of the pass
    top = int(ds.stage.values[-1])
    light = ds["photons"].sel(stage=top).values.ravel() / top
    dark = light <= np.percentile(light, 5.0)
    low = fused.source.ravel()[dark] == mu1
    t = cfg.timing.t_int_s
    s1 = true_hdr_dn(cfg, sel[mu1]["linear_dn"], mu2=mu1).ravel()[dark]
    s2 = truth.ravel()[dark]
    v1 = stage_temporal_var_dn2(cfg, sel[mu1]["photons"].ravel()[dark], mu1, t)
    v2 = stage_temporal_var_dn2(cfg, sel[mu2]["photons"].ravel()[dark], mu2, t)
    k = mu2 / mu1
    sig, var = np.where(low, s1 * k, s2), np.where(low, v1 * k**2, v2)
    out["snr_dark"] = float(np.mean(sig) / math.sqrt(np.mean(var)))
    out["dr_db"] = hdr_dr_model_db(cfg, mu1, mu2)
    return out


@pytest.mark.slow
def test_three_pairs_scored_independently_from_simulate_match_to_1e_9(tiny_run: Path) -> None:
    """The issue's check: the scores of three pairs computed from one ``simulate --stages all``
    output (eq. 11 against ``linear_dn`` of stage mu2 less its offsets) are design's to 1e-9."""
    cfg = load_config(tiny_run.parent / "tiny.toml")
    ds = simulate(cfg, stages="all", seed=SEED)
    got = xr.open_dataset(tiny_run / "design.nc")
    for mu1, mu2 in ((2, 16), (5, 20), (3, 24)):
        i = int(np.flatnonzero((got["mu1"].values == mu1) & (got["mu2"].values == mu2)
                               & (got["rule"].values == "eq11") & (got["mu_mid"].values == 0))[0])
        ref = _independent(cfg, ds, mu1, mu2)
        for name, value in ref.items():
            mine = float(got[name].values[i])
            both_nan = math.isnan(value) and math.isnan(mine)
            assert both_nan or abs(mine - value) <= 1e-9, (mu1, mu2, name, mine, value)
    assert ref["clipped_share"] > 0 or ref["pixels_clipped"] > 0  # the bench clips: the regions are exercised


@pytest.mark.slow
def test_outputs_judgement_and_report(tiny_run: Path) -> None:
    """The files of the set, the judgement columns, the chain DR of the chosen pairs only."""
    record = json.loads((tiny_run / OUTPUT_MARKER).read_text())
    for name in ("candidates.csv", "candidates.csv.json", "design.nc", "design.json", "report.md",
                 "plots/pareto.png", "plots/heatmaps.png", "points/000000.json", "points/000000.npz"):
        assert name in record["files"], name
    got = xr.open_dataset(tiny_run / "design.nc")
    n_pairs = 24 * 23 // 2
    assert got.sizes["candidate"] == 2 * n_pairs
    feasible = got["feasible"].values.astype(bool)
    np.testing.assert_array_equal(feasible, got["clipped_share"].values <= 0.0)
    ranked = got["rank"].values
    assert sorted(ranked[feasible]) == list(range(1, int(feasible.sum()) + 1)) and not ranked[~feasible].any()
    best = int(np.flatnonzero(ranked == 1)[0])
    assert got["truth_rms"].values[best] == np.min(got["truth_rms"].values[feasible])
    chain = np.isfinite(got["dr_chain_db"].values)
    assert chain[best] and 0 < chain.sum() <= 3 * 2  # the chosen pairs (each under both rules)
    assert np.abs(got["dr_chain_db"].values[chain] - got["dr_db"].values[chain]).max() < 3.0
    report = (tiny_run / "report.md").read_text()
    assert f"stages {got['stages'].values[best]}, rule `{got['rule'].values[best]}`" in report
    design = json.loads((tiny_run / "design.json").read_text())
    assert design["status"] == "complete" and design["truth_exact"] and design["seed"] == SEED


BAD = [
    ("empty", '[stages]\nmu1 = "20:24"\nmu2 = "2:10"\n', "design space is empty"),
    ("unknown_key", "wheel = 3\n", "wheel"),
    ("unknown_stage_key", "[stages]\nlow = 3\n", r"\[stages\] low: unknown key"),
    ("outside_rows", '[stages]\nmu2 = "10:30"\n', r"stage.* 25.*outside|outside.*1\.\.24"),
    ("triple_outside", "[stages]\ntriples = [[2, 8, 40]]\n", "outside the sensor's rows"),
    ("objective", 'objectives = ["dr_db", "sharpness"]\n', "'sharpness' does not exist"),
    ("rank", 'rank = ["speed"]\n', "'speed' does not exist"),
    ("constraint", '[[constraints]]\nobjective = "dr_chain_db"\nmin = 70.0\n',
     "'dr_chain_db' does not exist"),
    ("rule", 'rules = ["best"]\n', "'best' does not exist"),
    ("no_rule", "rules = []\n", "design space is empty"),
    ("word", "beta_bits = [7]\n", "half the 7-bit word"),
    ("own_key", '[[parameters]]\nkey = "dtdi.beta_bits"\nvalues = [12, 16]\n', "the design space sets it"),
    ("parameter", '[[parameters]]\nkey = "timing.line_period_ms"\nvalues = [1.0]\n', "not a setting"),
    ("chain", 'chain_dr = "all"\n', "chain_dr = 'all'"),
]


@pytest.mark.parametrize(("name", "body", "message"), BAD, ids=[b[0] for b in BAD])
def test_bad_specs_are_one_line_before_anything_is_written(tmp_path: Path, name: str, body: str,
                                                           message: str) -> None:
    spec = _spec(tmp_path, name, body)
    out = tmp_path / "out"
    r = runner.invoke(app, ["design", str(spec), "--out", str(out)])
    assert r.exit_code == 2, r.output
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("bench-sim: error: design spec"), r.stderr
    assert re.search(message, lines[0]), lines[0]
    assert not out.exists()


# --- the must-shows ---------------------------------------------------------------------


@pytest.mark.slow
def test_the_configured_pair_equals_reproduce_for_the_same_seed_and_size(tmp_path: Path) -> None:
    """On the paper rig (``--quick``, seed 7), the 10/80 candidate's DR (through the chain, and in
    closed form), truth RMS and clipped share are ``reproduce``'s."""
    from bench_sim.workflows.reproduce.run import run_reproduce

    metrics = run_reproduce(load_config(None), seed=7, out=tmp_path / "paper", quick=True)
    spec = tmp_path / "paper.toml"
    spec.write_text(f'base = "{ROOT / "scenes" / "paper_rig.toml"}"\nquick = true\nseed = 7\n'
                    'rules = ["eq11"]\nchain_dr = "chosen"\n'
                    'objectives = ["dr_db", "truth_rms", "clipped_share"]\n'
                    '[stages]\nmu1 = "10"\nmu2 = "80"\n')
    run_design(spec, tmp_path / "design", workers=0, progress=False)
    got = xr.open_dataset(tmp_path / "design" / "design.nc")
    assert got.sizes["candidate"] == 1 and got["stages"].values[0] == "10/80"
    eq11 = metrics["fusion_truth"]["rules"]["eq11"]
    assert float(got["dr_chain_db"].values[0]) == metrics["dr_db"]["gamma_hdr"]
    assert float(got["dr_db"].values[0]) == pytest.approx(metrics["dr_db_model"]["gamma_hdr"], abs=1e-9)
    assert float(got["truth_rms"].values[0]) == pytest.approx(eq11["error"]["whole"]["rms"], rel=1e-12)
    assert float(got["truth_bias"].values[0]) == pytest.approx(eq11["error"]["whole"]["bias"], rel=1e-9)
    assert float(got["clipped_share"].values[0]) == eq11["from_clipped_fraction"]


@pytest.mark.slow
def test_a_16_bit_word_recommends_a_pair_without_clipped_pixels_and_says_the_dr_it_gives_up(
    tmp_path: Path,
) -> None:
    """With a 16-bit word and a brighter spot, the configured 10/100 takes pixels from a clipped
    stage (where the light changes along its TDI window); under DR >= 75 dB and no pixel from a
    clipped stage the design recommends another mu2 and says how much closed-form DR that costs.
    300 W/m^2 lies in the middle of the irradiances where this holds: stage 100's word (100 reads
    of at most 1023 DN) clips from below 270 W/m^2 (measured), stage 10's pixels themselves from
    about 340 W/m^2 (10/80's word only from about 310: too narrow a window for a test)."""
    (tmp_path / "bench.toml").write_text(
        f'base = "{ROOT / "scenes" / "paper_rig.toml"}"\nlines = 128\n[sensor]\ncolumns = 256\n'
        "[target]\npanel_lines = 128\npanel_columns = 256\n[render]\nspp = 8\n[fusion]\nmu2 = 100\n")
    spec = tmp_path / "word16.toml"
    spec.write_text('base = "bench.toml"\nseed = 0\nrules = ["eq11"]\nbeta_bits = [16]\nchain_dr = "chosen"\n'
                    'objectives = ["dr_db", "truth_rms", "clipped_share", "snr_dark"]\n'
                    "[overrides]\nlights.strong = { irradiance_w_m2 = 300.0 }\n"
                    '[stages]\nmu1 = "10"\nmu2 = "20:100:10"\n'
                    '[[constraints]]\nobjective = "dr_db"\nmin = 75.0\n'
                    '[[constraints]]\nobjective = "clipped_share"\nmax = 0.0\n')
    summary = run_design(spec, tmp_path / "out", workers=0, progress=False)
    got = xr.open_dataset(tmp_path / "out" / "design.nc")
    ref = int(np.flatnonzero(got["stages"].values == "10/100")[0])
    best = int(np.flatnonzero(got["rank"].values == 1)[0])
    assert got["clipped_share"].values[ref] > 0 and got["beta_bits"].values[ref] == 16
    assert got["clipped_share"].values[best] == 0 and got["dr_db"].values[best] >= 75.0
    assert summary.recommended is not None and summary.recommended["stages"] == got["stages"].values[best]
    given_up = got["dr_db"].values[ref] - got["dr_db"].values[best]
    assert given_up > 0  # a lower mu2: the SNR = 1 point rises
    report = (tmp_path / "out" / "report.md").read_text()
    assert (f"gives up {given_up:.2f} dB of closed-form DR ({got['dr_db'].values[best]:.2f} dB against "
            f"{got['dr_db'].values[ref]:.2f} dB)") in report
    assert "it fails the constraints, `clipped_share` =" in report
