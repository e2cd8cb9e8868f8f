"""``bench-sim reproduce --quick`` end to end: files, metrics, the paper's qualitative result."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from bench_sim.cli import app
from bench_sim.config import load_config, with_overrides
from bench_sim.io import read_image, read_png_text
from bench_sim.workflows.reproduce.run import run_reproduce

runner = CliRunner()

FILES = (
    "fig3_stages.png",
    "fig4_hdr.png",
    "gamma1.tiff",
    "gamma2.tiff",
    "gamma_hdr.exr",
    "gamma_tra.png",
    "table1.csv",
    "metrics.json",
    "report.md",
    "snr_vs_signal.png",
    "gamma_hdr_error.png",
    "tdi_light_ratio.png",
    "mtf50_vs_stage.png",
    "mtf50_vs_stage.csv",
)
KEYS = (
    "mu1", "mu2", "beta", "delta_psi_db_eq15", "stage_pairs_26_02_db", "dr_db",
    "delta_dr_db_vs_gamma1", "delta_dr_db_vs_gamma2", "omega", "eq18_holds",
    "saturated_fraction", "seed", "config_sha256", "version", "wall_s", "fusion_truth",
)


@pytest.fixture(scope="module")
def quick_runs(tmp_path_factory):
    """Two runs of the same seed: ``a`` with the usable cores (the DR measurement and the
    sharpness's companion pass beside the pass, figures on two threads), ``b`` on one thread
    (``BENCH_SIM_THREADS=1``: every step in order), so their comparisons below also check that
    the outputs do not depend on the overlap."""
    outs = []
    for name, threads in (("a", None), ("b", "1")):
        out = tmp_path_factory.mktemp(name)
        with pytest.MonkeyPatch.context() as mp:
            if threads is not None:
                mp.setenv("BENCH_SIM_THREADS", threads)
            res = runner.invoke(app, ["reproduce", "--quick", "--seed", "7", "--out", str(out)])
        assert res.exit_code == 0, res.output
        outs.append(out)
    return outs


def test_quick_writes_every_file_and_key(quick_runs):
    out = quick_runs[0]
    for name in FILES:
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    m = json.loads((out / "metrics.json").read_text())
    for key in KEYS:
        assert key in m, key
    assert set(m["dr_db"]) == set(m["omega"]) == set(m["saturated_fraction"]) == {
        "gamma1", "gamma2", "gamma_hdr"
    }
    assert (m["mu1"], m["mu2"], m["beta"], m["seed"]) == (10, 80, 12, 7)
    assert m["delta_psi_db_eq15"] == pytest.approx(20 * math.log10(8), abs=1e-9)  # 18.06 dB
    assert m["stage_pairs_26_02_db"] == [[5, 100]]
    report = (out / "report.md").read_text()
    assert "18.06 dB" in report and "26.02" in report and "eq. 18" in report
    gain1 = m["delta_dr_db_vs_gamma1"]
    assert f"Gain over the better input (by measured DR), Gamma1: {gain1:.2f} dB" in report
    assert "*by construction*" in report and m["gain_over_gamma2_by_construction"]
    assert read_png_text(out / "snr_vs_signal.png")["seed"] == 7


def test_pixels_from_a_clipped_gamma2_agree_with_the_tiffs(quick_runs):
    """On the default rig some Gamma_HDR pixels come from a clipped Gamma2: the fraction in
    metrics.json is > 0 and equals a count made from gamma1.tiff and gamma2.tiff by eq. 11."""
    out = quick_runs[0]
    m = json.loads((out / "metrics.json").read_text())
    g1 = read_image(out / "gamma1.tiff").astype(np.float64)
    g2 = read_image(out / "gamma2.tiff").astype(np.float64)
    off1, off2 = (m["stage_offset_dn"][k] for k in ("gamma1", "gamma2"))
    top = 2 ** m["beta"] - 1
    # eq. 11: Gamma2 where Gamma1's prediction stays inside the word
    from_g2 = (g1 - off1) * m["mu2"] <= (2 ** m["beta"] - off2) * m["mu1"]
    count = float(np.mean(from_g2 & (g2 >= top)))
    eq11 = m["fusion_truth"]["rules"]["eq11"]
    assert eq11["from_word_top_fraction"] > 0
    assert count == pytest.approx(eq11["from_word_top_fraction"], abs=2.0 / g1.size)
    assert eq11["from_clipped_fraction"] >= eq11["from_word_top_fraction"]
    report = (out / "report.md").read_text()
    assert f"{eq11['from_clipped_fraction']:.2%} of Gamma_HDR's pixels" in report
    assert "Gamma_HDR keeps the bright detail: 0.0%" not in report


def _keys(x) -> set:
    if isinstance(x, dict):
        return set(x) | set().union(*(_keys(v) for v in x.values()))
    if isinstance(x, list):
        return set().union(*(_keys(v) for v in x))
    return set()


def test_images_are_keyed_gamma_hdr_everywhere(quick_runs):
    """The fused image is ``gamma_hdr`` in every key of metrics.json, the chain's DR details included."""
    m = json.loads((quick_runs[0] / "metrics.json").read_text())
    assert "hdr" not in _keys(m)
    details = m["dr_details"]
    assert set(details["images"]) == set(details["model_dr_db"]) == {"gamma1", "gamma2", "gamma_hdr"}


@pytest.mark.physics
@pytest.mark.slow
def test_quick_shows_the_papers_qualitative_result(quick_runs):
    m = json.loads((quick_runs[0] / "metrics.json").read_text())
    bright, dark = m["brightest_patch"], m["darkest_patch"]
    # the scene is designed so that stage 10 puts the brightest patch near 90 % of Phi_FS ...
    assert 0.8 < bright["gamma1_fraction_of_phi_fs"] < 1.0
    # ... which saturates stage 80 there, while the fused image keeps it
    assert bright["gamma2_saturated_fraction"] > 0.99
    assert bright["gamma_hdr_saturated_fraction"] == 0.0
    assert m["saturated_fraction"]["gamma2"] > 0.2 and m["saturated_fraction"]["gamma_hdr"] == 0.0
    # stage 10 leaves the darkest patch in the noise, stage 80 (and the HDR image) lift it out
    snr = dark["snr"]
    assert snr["gamma1"] < 2.0
    assert snr["gamma_hdr"] >= 3.0 and snr["gamma_hdr"] == pytest.approx(snr["gamma2"])
    assert all(m["qualitative"].values())
    # through the whole chain the DR gain over Gamma2 is eq. 15's 18.06 dB (both stages are
    # limited by the 12-bit output word): exactly with the extrapolated saturation points, and
    # within the scatter of the variance maxima (a few tenths of a dB) with EMVA's
    assert m["delta_dr_db_vs_gamma2_extrapolated"] == pytest.approx(m["delta_psi_db_eq15"], abs=0.05)
    assert m["delta_dr_db_vs_gamma2"] == pytest.approx(m["delta_psi_db_eq15"], abs=0.8)


def test_same_seed_gives_identical_metrics_except_timing(quick_runs):
    a, b = (json.loads((o / "metrics.json").read_text()) for o in quick_runs)
    for m in (a, b):
        m.pop("wall_s")
        m.pop("timings_s")
    # renders made by the process: 2 (positions, spot) unless an earlier test cached the records;
    # the second run in this process finds them cached
    assert a.pop("mitsuba_renders") in (0, 2) and b.pop("mitsuba_renders") == 0
    assert a == b
    assert (quick_runs[0] / "table1.csv").read_text() == (quick_runs[1] / "table1.csv").read_text()


def test_bad_out_is_one_line_and_writes_nothing(tmp_path):
    target = tmp_path / "file"
    target.write_text("x")
    res = runner.invoke(app, ["reproduce", "--quick", "--out", str(target)])
    assert res.exit_code == 2 and len(res.stderr.strip().splitlines()) == 1
    assert target.read_text() == "x"


def test_same_seed_gives_byte_identical_data_files(quick_runs):
    """Images, figures, tables and the completion record are byte-identical; wall-clock times
    live only in metrics.json's ``wall_s``/``timings_s`` and the report's timing table."""
    a, b = quick_runs
    names = sorted(p.name for p in a.iterdir() if p.name not in ("metrics.json", "report.md"))
    assert set(names) >= {"gamma1.tiff", "gamma2.tiff", "gamma_hdr.exr", "fig3_stages.png", "table1.csv"}
    assert ".bench-sim-output.json" in names
    assert [n for n in names if (a / n).read_bytes() != (b / n).read_bytes()] == []


@pytest.mark.parametrize(
    ("overrides", "clips_on_word"),
    [
        ({"dtdi": {"beta_bits": 16}}, {"gamma1": False, "gamma2": True}),
        ({"fusion": {"mu1": 10, "mu2": 40}}, {"gamma1": True, "gamma2": True}),
    ],
    ids=["beta16", "stages10-40"],
)
def test_report_states_what_this_run_measured(tmp_path, overrides, clips_on_word):
    """Every number, stage pair and verdict of report.md comes from the run: a 16-bit word (stage
    10 clips on its pixels, so eq. 15 does not hold) and another stage pair (eq. 15 = 12.04 dB)."""
    cfg = with_overrides(load_config(), overrides)
    m = run_reproduce(cfg, seed=3, out=tmp_path, quick=True)
    report = (tmp_path / "report.md").read_text()
    mu1, mu2 = m["mu1"], m["mu2"]
    eq15 = 20 * math.log10(mu2 / mu1)
    assert m["delta_psi_db_eq15"] == pytest.approx(eq15)
    assert m["stage_clips_on_word"] == clips_on_word
    assert f"Gain over Gamma2: {m['delta_dr_db_vs_gamma2']:.2f} dB" in report
    assert f"20 lg({mu2}/{mu1}) = {eq15:.2f} dB" in report
    agrees = abs(m["delta_dr_db_vs_gamma2_extrapolated"] - eq15) <= 0.5  # clip points, as eq. 15
    if all(clips_on_word.values()):
        assert m["gain_over_gamma2_by_construction"] and agrees and "*by construction*" in report
    else:
        # 16-bit word: stage 10 tops out at its pixels' clip, far below Phi_FS * mu1/mu2 ...
        assert not m["gain_over_gamma2_by_construction"] and not agrees
        assert "*by construction*" not in report and "does not agree" in report
        assert "clips on the pixel (full well / ADC top)" in report
    if (mu1, mu2) != (10, 80):
        assert "18.06" not in report  # nothing of the default stage pair is left in the text
    assert f"stage {mu2} saturates the brightly lit region" in report
    # the better input is the one with the higher measured DR, and the gain is over it
    better = "gamma1" if m["dr_db"]["gamma1"] >= m["dr_db"]["gamma2"] else "gamma2"
    gain = m[f"delta_dr_db_vs_{better}"]
    name = better.replace("g", "G", 1)
    assert f"Gain over the better input (by measured DR), {name}: {gain:.2f} dB" in report
    if overrides.get("dtdi", {}).get("beta_bits") == 16:
        assert better == "gamma2"  # a 16-bit word: stage 80's DR exceeds stage 10's
    # never "0 %" from a clipped Gamma2 where the truth counts some
    eq11 = m["fusion_truth"]["rules"]["eq11"]
    if eq11["from_clipped_pixels"]:
        assert f"{eq11['from_clipped_fraction']:.2%} of Gamma_HDR's pixels" in report
    else:
        assert "No Gamma_HDR pixel is taken from a clipped stage" in report
    sat2 = m["saturated_fraction"]["gamma2"]
    assert (f"whose {sat2:.0%} saturated pixels" in report) == (sat2 > 0)
    table = report.split("| qualitative result")[1].split("\n\n")[0].splitlines()[2:]
    assert len(table) == len(m["qualitative"])
    assert sum(row.endswith("| **no** |") for row in table) == sum(not v for v in m["qualitative"].values())
