"""Every sentence of ``bench-sim design``'s ``report.md`` true for every config: the report writer run
on candidate tables over a grid of benches and specs (words 8-16 bits, the black offset kept, large
pedestals, pairs and triples, every rule, constraints that leave many, one or no candidate, ranking
rules of one and two objectives, several points), with the closed forms of each bench and scores
drawn at random (exact zeros, tiny shares, ties), each also perturbed (a tie with the runner-up, the
configured pair recommended, the same DR as the configured pair), and each statement checked against
the numbers by :mod:`tests.workflows.design_statements`, which parses the text. One table is a real
design's."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bench_sim.measure.design_scores import SCORE_COLUMNS, word_config
from bench_sim.metrics.fusion_truth import TRUTH_REGIONS
from bench_sim.sensor.model import hdr_dr_model_db
from bench_sim.workflows.design.report import report_markdown
from bench_sim.workflows.design.run import run_design
from bench_sim.workflows.design.spec import load_design_spec
from bench_sim.workflows.design.table import build_table, judge

from .design_statements import check_report

ROOT = Path(__file__).resolve().parents[2]
BASE = f'base = "{ROOT / "scenes" / "paper_rig.toml"}"\n'
TINY = 'lines = 48\nsensor = { rows = 24, columns = 48 }\ntarget = { panel_lines = 48, panel_columns = 48 }\n'

#: (name, [overrides] body, spec body before the tables, tables)
GRID = [
    ("words", "", 'rules = ["eq11", "clip"]\nbeta_bits = [10, 12, 16]\n',
     '[stages]\nmu1 = "1:6"\nmu2 = "6:24:3"\ntriples = [[2, 8, 20]]\n'
     '[[constraints]]\nobjective = "clipped_share"\nmax = 0.0\n'),
    ("black_kept", "dtdi = { subtract_black = false, pedestal_dn = 0 }\n", 'beta_bits = [12]\n'
     'rank = ["dr_db", "truth_rms"]\n', '[stages]\nmu1 = "2:10:2"\nmu2 = "12:24:4"\n'),
    ("pedestal", "dtdi = { pedestal_dn = 200 }\n", 'beta_bits = [11, 14]\nrules = ["clip_margin"]\n',
     '[stages]\nmu1 = "1,3,5"\nmu2 = "16,20,24"\n[[constraints]]\nobjective = "dr_db"\nmin = 60.0\n'
     '[[constraints]]\nobjective = "truth_rms"\nmax = 0.08\n'),
    ("none_feasible", "", 'rules = ["eq11"]\n',
     '[stages]\nmu1 = "1:4"\nmu2 = "20:24"\n[[constraints]]\nobjective = "dr_db"\nmin = 500.0\n'),
    ("narrow_word", "", 'beta_bits = [8]\nobjectives = ["dr_db", "snr_dark", "truth_bias"]\n'
     'rank = ["snr_dark"]\n', '[stages]\nmu1 = "1:3"\nmu2 = "4:6"\n'),
    ("points", "", 'rules = ["eq11", "clip"]\n'
     'objectives = ["dr_db", "truth_rms", "clipped_share", "mtf50_along"]\n',
     '[stages]\nmu1 = "1:4"\nmu2 = "12:24:6"\n[[constraints]]\nobjective = "clipped_share"\nmax = 0.001\n'
     '[[parameters]]\nkey = "timing.line_period_s"\nvalues = [80e-6, 120e-6]\n'),
]


def _spec(tmp: Path, name: str, over: str, body: str, tables: str) -> Any:
    path = tmp / f"{name}.toml"
    text = f'{BASE}seed = 3\n{body}[overrides]\n{TINY}fusion = {{ mu1 = 2, mu2 = 16 }}\n{over}{tables}'
    path.write_text(text)
    return load_design_spec(path)


def _scores(spec: Any, point: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """A point's score columns: the closed forms of its bench, the rest drawn (exact zeros, tiny
    shares and a few NaN among them)."""
    rows = spec.space.rows()
    n = len(rows)
    cols: dict[str, Any] = {k: np.array([r[i] for r in rows]) for i, k in
                            enumerate(("beta_bits", "rule", "mu1", "mu_mid", "mu2"))}
    cfg = spec.points[point].cfg
    dr = [hdr_dr_model_db(word_config(cfg, b), a, m) for b, _, a, _, m in rows]
    cap = [hdr_dr_model_db(word_config(cfg, b), a, m, beta_bits=None) - d
           for (b, _, a, _, m), d in zip(rows, dr, strict=True)]
    cols["dr_db"], cols["dr_cap_db"] = np.array(dr), np.maximum(np.array(cap), 0.0)
    for r in TRUTH_REGIONS:
        suffix = "" if r == "whole" else f"_{r}"
        cols[f"truth_rms{suffix}"] = rng.uniform(0.01, 0.2, n)
        cols[f"truth_bias{suffix}"] = rng.normal(0.0, 0.01, n)
        cols[f"pixels_{r}"] = rng.integers(0, 2304, n).astype(float)
    share = rng.uniform(0.0, 0.05, n)
    share[rng.random(n) < 0.4] = 0.0
    share[rng.random(n) < 0.1] = 3e-7
    cols["clipped_share"], cols["low_share"] = share, rng.uniform(0.0, 1.0, n)
    cols["snr_dark"] = rng.uniform(1.0, 20.0, n)
    cols["truth_rms_lost"][rng.random(n) < 0.5] = np.nan
    return {k: np.asarray(v) for k, v in cols.items() if k in SCORE_COLUMNS or k in
            ("beta_bits", "rule", "mu1", "mu_mid", "mu2")}


def _table(spec: Any, seed: int) -> tuple[Any, dict[int, Any]]:
    rng = np.random.default_rng(seed)
    records = {p.index: {"status": "ok", "values": p.values, "truth_not_exact": [],
                         "stage_mtf50_along": {str(m): float(rng.uniform(0.2, 0.5))
                                               for m in spec.space.stages}}
               for p in spec.points}
    return build_table(spec, records, {p.index: _scores(spec, p.index, rng) for p in spec.points}), records


def _chain(table: Any, choice: Any) -> dict[int, Any]:
    c = table.columns
    chain = {}
    chosen = (choice.recommended, choice.runner_up, choice.reference)
    for n, i in enumerate(i for i in chosen if i is not None):
        c["dr_chain_db"][i] = c["dr_db"][i] - 0.3
        chain[n] = {"status": "ok"}
    return chain


def _perturb(kind: str, table: Any, choice: Any, spec: Any) -> None:
    """Make a tie, the configured pair the best, or the same DR as the configured pair."""
    c = table.columns
    if choice.recommended is None or choice.runner_up is None or choice.reference is None:
        return
    best, second, ref = choice.recommended, choice.runner_up, choice.reference
    if kind == "tie":
        for r in spec.rank:
            c[r][second] = c[r][best]
    elif kind == "reference_best":
        for k in spec.constraints:
            c[k.objective][ref] = c[k.objective][best]
        for r in spec.rank:
            c[r][ref] = c[r][best] - (1.0 if r in ("dr_db", "snr_dark") else -1.0) * -1e-6
    elif kind == "same_dr":
        c["dr_db"][best] = c["dr_db"][ref]


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("kind", ["plain", "tie", "reference_best", "same_dr"])
@pytest.mark.parametrize("name", [g[0] for g in GRID])
def test_every_statement_is_true(tmp_path: Path, name: str, kind: str, seed: int) -> None:
    spec = _spec(tmp_path, *next(g for g in GRID if g[0] == name))
    table, records = _table(spec, seed)
    choice = judge(table, spec)
    _perturb(kind, table, choice, spec)
    choice = judge(table, spec)
    chain = _chain(table, choice)
    text = report_markdown(spec, table, choice, records, chain)
    found = check_report(text, table.columns, choice, spec, chain)
    assert "counts" in found
    if choice.recommended is not None:
        assert {"recommended", "reference"} <= set(found) or "reference_is_best" in found
        assert any(f in found for f in ("runner_up", "runner_up_tie", "no_runner_up"))
        assert any(f in found for f in ("caps", "no_cap"))
    if kind == "tie" and choice.runner_up is not None:
        assert "runner_up_tie" in found or "runner_up" in found


def test_the_statements_of_a_real_design(tmp_path: Path) -> None:
    """The tiny bench with a 10-bit and a 12-bit word, every rule and a triple, run for real."""
    spec_path = tmp_path / "real.toml"
    spec_path.write_text(f'{BASE}seed = 1\nbeta_bits = [10, 12]\nchain_dr = "front"\n'
                         f'[overrides]\n{TINY}fusion = {{ mu1 = 2, mu2 = 16 }}\n'
                         '[stages]\nmu1 = "1:8"\nmu2 = "10:24:2"\ntriples = [[2, 8, 20]]\n'
                         '[[constraints]]\nobjective = "clipped_share"\nmax = 0.0\n')
    summary = run_design(spec_path, tmp_path / "out", workers=0, progress=False, plots=False)
    assert summary.table is not None
    spec = load_design_spec(spec_path)
    records = {0: json.loads((tmp_path / "out" / "points" / "000000.json").read_text())}
    chain = {int(p.stem): json.loads(p.read_text()) for p in (tmp_path / "out" / "chain").glob("*.json")}
    choice = judge(summary.table, spec)
    text = (tmp_path / "out" / "report.md").read_text()
    assert text.startswith(report_markdown(spec, summary.table, choice, records, chain).split("## Files")[0])
    found = check_report(text, summary.table.columns, choice, spec, chain)
    assert {"recommended", "runner_up", "counts"} <= set(found) and ("caps" in found or "no_cap" in found)


@pytest.mark.parametrize(("old", "new"), [
    (" (better)", " (worse)"), ("(candidate ", "(candidate 1"), ("gives up", "gains"), ("gains", "gives up"),
    (" candidates meet the constraints", "1 candidates meet the constraints"),
    ("caps the DR", "does not cap the DR"),
    ("runner-up, ", "runner-up, 1"),
])
def test_the_checks_catch_a_false_statement(tmp_path: Path, old: str, new: str) -> None:
    """Each check fails on a report with one statement made false (where the report has it)."""
    for name in ("words", "black_kept", "pedestal"):
        spec = _spec(tmp_path, *next(g for g in GRID if g[0] == name))
        table, records = _table(spec, 0)
        choice = judge(table, spec)
        chain = _chain(table, choice)
        text = report_markdown(spec, table, choice, records, chain)
        if old in text:
            with pytest.raises(AssertionError):
                check_report(text.replace(old, new, 1), table.columns, choice, spec, chain)
            return
    pytest.fail(f"no report of the grid says {old!r}")
