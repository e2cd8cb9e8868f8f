"""Every sentence of ``report.md`` true for every config: the report writer run on the results of
small real ``reproduce`` runs (word widths 10-16 bits, several stage pairs and light levels:
``data/reproduce_grid``), each also perturbed (the better input swapped, fractions at and near 0
and 1, a rising switch, the paper's claims failing), and each statement checked against the
numbers it is about by :mod:`tests.workflows.reproduce_statements`, which parses the text."""

from __future__ import annotations

import copy
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from bench_sim.config import load_config
from bench_sim.workflows.reproduce.report import report_markdown
from bench_sim.workflows.reproduce.result import ReproduceResult

from .reproduce_statements import SNR_IN_NOISE, SNR_ROSE, check_report, frac_ok

GRID = sorted((Path(__file__).parent / "data" / "reproduce_grid").glob("*.json"))
ALWAYS = {"better_input", "gain_over_gamma2", "clip_causes", "hdr_ends", "fig3_fractions", "word_top",
          "from_clipped_gamma2", "pedestal", "fig4_table", "snr_labels", "table1", "inconsistencies", "truth"}


def _requalify(m: dict[str, Any]) -> dict[str, Any]:
    """The paper's claims from the (perturbed) numbers, as pass_metrics decides them."""
    dark, bright = m["darkest_patch"], m["brightest_patch"]
    s = dark["snr"]
    m["qualitative"] = {
        "stage_mu2_saturates_bright_region": bright["gamma2_saturated_fraction"] > 0.99,
        "stage_mu1_leaves_darkest_patch_in_noise": s["gamma1"] < SNR_IN_NOISE,
        "hdr_keeps_bright_unsaturated": bright["gamma_hdr_saturated_fraction"] == 0.0
        and bright["gamma_hdr_from_clipped_gamma2_fraction"] == 0.0,
        "hdr_lifts_darkest_patch": s["gamma_hdr"] >= SNR_ROSE and s["gamma_hdr"] >= 1.8 * s["gamma1"],
    }
    return m


def _swap_better(m: dict[str, Any]) -> None:
    dr = m["dr_db"]
    dr["gamma1"], dr["gamma2"] = dr["gamma2"], dr["gamma1"]
    m["delta_dr_db_vs_gamma1"] = dr["gamma_hdr"] - dr["gamma1"]
    m["delta_dr_db_vs_gamma2"] = dr["gamma_hdr"] - dr["gamma2"]


def _tiny_fractions(m: dict[str, Any]) -> None:
    m["saturated_fraction"].update(gamma1=4e-5, gamma_hdr=4e-5, gamma2=0.99996)
    m["brightest_patch"].update(
        gamma_hdr_saturated_fraction=2e-4, gamma_hdr_from_clipped_gamma2_fraction=3e-4,
        gamma2_saturated_fraction=0.9996,
    )
    m["darkest_patch"]["word_zero_fraction"]["gamma1"] = 1e-4
    eq11 = m["fusion_truth"]["rules"]["eq11"]
    eq11.update(from_clipped_pixels=1, from_clipped_fraction=3e-5, from_word_top_fraction=3e-5)
    m["fusion_truth"]["light_ratio"]["outside_fraction"] = 2e-5


def _nothing_clipped(m: dict[str, Any]) -> None:
    m["saturated_fraction"] = dict.fromkeys(m["saturated_fraction"], 0.0)
    m["brightest_patch"].update(gamma2_saturated_fraction=0.0, gamma_hdr_saturated_fraction=0.0,
                                gamma_hdr_from_clipped_gamma2_fraction=0.0)
    for rule in m["fusion_truth"]["rules"].values():
        rule.update(from_clipped_pixels=0, from_clipped_fraction=0.0, from_word_top_fraction=0.0)


def _switch_rises(m: dict[str, Any]) -> None:
    sw = m["fusion_switch"]
    sw["snr_below"], sw["snr_above"] = 40.0, 55.0


def _dark_claims_fail(m: dict[str, Any]) -> None:
    m["darkest_patch"]["snr"].update(gamma1=2.6, gamma2=3.5, gamma_hdr=3.5)


def _floor_above(m: dict[str, Any]) -> None:
    img = m["dr_details"]["images"]
    img["gamma_hdr"]["photons_min"] = img["gamma1"]["photons_min"] * 1.5
    img["gamma_hdr"]["photons_sat"] = img["gamma1"]["photons_sat"] * 0.5


def _truth_clip_fractions(m: dict[str, Any]) -> None:
    """What run.py gives once it passes the truth's clip fractions (SceneResult.clipped_fraction)."""
    m["clipped_fraction"] = {"gamma1": 0.0, "gamma2": 0.4171, "gamma_hdr": 3e-5}


def _temporal_snr(m: dict[str, Any]) -> None:
    """What run.py gives once it measures the darkest patch's temporal SNR from the truth."""
    m["darkest_patch"]["temporal_snr"] = {"gamma1": 1.41, "gamma2": 3.99, "gamma_hdr": 3.99}


PERTURBATIONS: dict[str, Callable[[dict[str, Any]], None] | None] = {
    "as_run": None, "better_swapped": _swap_better, "tiny_fractions": _tiny_fractions,
    "nothing_clipped": _nothing_clipped, "switch_rises": _switch_rises, "dark_claims_fail": _dark_claims_fail,
    "floor_above": _floor_above, "truth_clip_fractions": _truth_clip_fractions,
    "temporal_snr": _temporal_snr,
}


def _report(m: dict[str, Any]) -> str:
    return report_markdown(ReproduceResult.from_dict(m), load_config(), True)


def test_the_grid_spans_word_widths_stage_pairs_and_light_levels():
    ms = [json.loads(p.read_text()) for p in GRID]
    assert {m["beta"] for m in ms} >= {12, 16}
    assert len({(m["mu1"], m["mu2"]) for m in ms}) >= 1
    assert {_better_name(m) for m in ms} == {"gamma1", "gamma2"}  # both labels occur for real


def _better_name(m: dict[str, Any]) -> str:
    return "gamma1" if m["dr_db"]["gamma1"] >= m["dr_db"]["gamma2"] else "gamma2"


@pytest.mark.parametrize("perturb", list(PERTURBATIONS))
@pytest.mark.parametrize("path", GRID, ids=[p.stem for p in GRID])
def test_every_statement_is_true_for_every_config(path: Path, perturb: str):
    m = json.loads(path.read_text())
    fn = PERTURBATIONS[perturb]
    if fn is not None:
        fn(m)
        _requalify(m)
    found = set(check_report(_report(m), m))
    assert found >= ALWAYS, ALWAYS - found
    if perturb == "switch_rises":
        assert "fusion_switch" in found


def test_the_checks_catch_false_statements():
    """The checks fail on a report whose numbers are not those of the result (so they can)."""
    m = json.loads(GRID[0].read_text())
    text = _report(m)
    wrong = copy.deepcopy(m)
    _swap_better(wrong)
    with pytest.raises(AssertionError):
        check_report(text, wrong)
    wrong = copy.deepcopy(m)
    _tiny_fractions(wrong)
    with pytest.raises(AssertionError):
        check_report(text, wrong)
    # a 16-bit word under a 4x spot: stage 10 clips on its pixels on the brightest step; the
    # report must not say that Gamma_HDR keeps it
    m = json.loads(next(p for p in GRID if p.stem == "tiny_b16_10_80_bright").read_text())
    assert m["brightest_patch"]["snr"]["gamma_hdr"] is None
    assert m["qualitative"]["hdr_keeps_bright_unsaturated"]
    text = _report(m)
    wrong = copy.deepcopy(m)
    wrong["brightest_patch"]["snr"]["gamma_hdr"] = 50.0
    with pytest.raises(AssertionError):
        check_report(text, wrong)
    assert frac_ok("0%", 0.0) and not frac_ok("0%", 1e-4) and not frac_ok("0.0%", 4e-4)
    assert not frac_ok("100%", 0.9996) and frac_ok("99.96%", 0.9996) and frac_ok("1.2%", 0.0117)
