"""``report.md`` of a design: the recommended design with its numbers, why it beats the runner-up
and the configured pair (the paper's 10/80 on the paper rig), where the output word caps the DR
and by how much, the Pareto front, and how every number was made.

Every sentence is computed from the candidate table and the judgement
(:func:`report_markdown`); ``tests/workflows/design_statements.py`` checks each against the
numbers over a grid of designs.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.config import config_sha256
from bench_sim.io import markdown_table, write_text
from bench_sim.measure.design_scores import DARK_FRACTION, word_config
from bench_sim.metrics.fusion_truth import CLIP_MARGIN_SIGMAS
from bench_sim.sensor.effects.chain import sensor_chain
from bench_sim.sensor.model import stage_clips_on_word, stage_dr_model_db, stage_saturation_photons
from bench_sim.version import __version__
from bench_sim.workflows.design.charts import plot_heatmaps, plot_pareto
from bench_sim.workflows.design.objectives import FRONT_OBJECTIVES, OBJECTIVES, Choice
from bench_sim.workflows.design.spec import DesignSpec
from bench_sim.workflows.design.table import DesignTable
from bench_sim.workflows.output_meta import provenance
from bench_sim.workflows.reproduce.wording import pct

__all__ = ["report_markdown", "write_report", "fmt_value", "fmt_pair", "word_cap", "WordCap", "FRONT_ROWS"]

#: rows of the front's table in the report (all of them are in candidates.csv)
FRONT_ROWS = 30
#: widest word searched for one that no longer caps a stage [bits]
_WIDEST = 32


def fmt_value(name: str, v: Any, more: int = 0) -> str:
    """A column's value as the report writes it: dB with two decimals, shares and relative errors
    as percentages that read 0 % / 100 % only when exact, SNR with three digits; ``more``
    digits besides."""
    if v is None or (isinstance(v, float | np.floating) and not math.isfinite(v)):
        return "n/a"
    v = float(v)
    if name.endswith("_db"):
        return f"{v:.{2 + more}f} dB"
    if name in ("clipped_share", "low_share"):
        return pct(v, 2 + more)
    if name.startswith("truth_"):
        return pct(v, 3 + more, sign=name.startswith("truth_bias"))
    if name == "mtf50_along":
        return f"{v:.{3 + more}f} cycles/px"
    return f"{v:.{3 + more}g}"


def fmt_pair(name: str, a: Any, b: Any) -> tuple[str, str]:
    """Two values of a column as the report writes them, with as many more digits as it takes
    (up to 14) for two different values not to read alike."""
    for more in range(15):
        fa, fb = fmt_value(name, a, more), fmt_value(name, b, more)
        if fa != fb or a == b or "n/a" in (fa, fb):
            break
    return fa, fb


def _name(c: Mapping[str, Any], i: int) -> str:
    """A candidate in words: stages, rule, word."""
    return f"{c['stages'][i]} (`{c['rule'][i]}`, {int(c['beta_bits'][i])}-bit)"


def _where(spec: DesignSpec, c: Mapping[str, Any], i: int) -> str:
    """The point of a candidate, with its keys' values."""
    vals = ", ".join(
        f"`{k}` = {c[k][i]:.4g}" if isinstance(c[k][i], float) else f"`{k}` = {c[k][i]}" for k in spec.keys
    )
    return f"point {int(c['point'][i])}" + (f" ({vals})" if vals else "")


class WordCap:
    """What the output word does to a candidate's DR: ``cap_db`` (closed form with a word that
    never clips, less with this word), whether its lowest stage clips on the word, the photons per
    pixel per frame at the word's clip and at the pixel's, and the narrowest word that no longer
    caps it (``None``: none up to 32 bits)."""

    def __init__(
        self,
        cap_db: float,
        on_word: bool,
        word_photons: float,
        pixel_photons: float,
        enough_bits: int | None,
        single_read_db: float,
    ) -> None:
        self.cap_db, self.on_word = cap_db, on_word
        self.word_photons, self.pixel_photons = word_photons, pixel_photons
        self.enough_bits, self.single_read_db = enough_bits, single_read_db


def word_cap(spec: DesignSpec, c: Mapping[str, Any], i: int) -> WordCap:
    """:class:`WordCap` of candidate ``i`` (closed forms of :mod:`bench_sim.sensor.model`)."""
    cfg = word_config(spec.points[int(c["point"][i])].cfg, int(c["beta_bits"][i]))
    s, t, m = cfg.sensor, cfg.timing.t_int_s, int(c["mu1"][i])
    kw: dict[str, Any] = {"subtract_black": cfg.dtdi.subtract_black, "pedestal_dn": cfg.dtdi.pedestal_dn}
    on_word = stage_clips_on_word(s, m, beta_bits=cfg.dtdi.beta_bits, **kw)
    enough = (
        next(
            (
                b
                for b in range(cfg.dtdi.beta_bits + 1, _WIDEST + 1)
                if not stage_clips_on_word(s, m, beta_bits=b, **kw)
            ),
            None,
        )
        if on_word
        else None
    )
    return WordCap(
        float(c["dr_cap_db"][i]),
        on_word,
        stage_saturation_photons(s, t, m, beta_bits=cfg.dtdi.beta_bits, **kw),
        stage_saturation_photons(s, t, m, beta_bits=None, **kw),
        enough,
        stage_dr_model_db(cfg, 1),
    )


def _db(x: float) -> str:
    return f"{x:.2f}" if abs(x) >= 0.005 else ("< 0.01" if x > 0 else "0.00")


def _cap_lines(spec: DesignSpec, c: Mapping[str, Any], picks: Sequence[tuple[str, int]]) -> list[str]:
    """Where the output word caps the DR of the chosen designs, and by how much."""
    out = ["## The output word and the dynamic range", ""]
    for label, i in picks:
        w = word_cap(spec, c, i)
        beta, m = int(c["beta_bits"][i]), int(c["mu1"][i])
        if w.on_word:
            more = (
                f"a word of {w.enough_bits} bits or more would not cap it"
                if w.enough_bits
                else "no word up to 32 bits would lift it"
            )
            out.append(
                f"- The {beta}-bit output word caps the DR of the {label} {_name(c, i)} by {_db(w.cap_db)} "
                "dB: "
                f"its stage {m} clips on the word at {w.word_photons:.4g} photons per pixel per frame, below "
                f"its pixel's clip at {w.pixel_photons:.4g}; {more}."
            )
        else:
            out.append(
                f"- The {beta}-bit output word does not cap the DR of the {label} {_name(c, i)}: its stage "
                f"{m} clips on the pixel ({w.pixel_photons:.4g} photons per pixel per frame)."
            )
        dr = float(c["dr_db"][i])
        if math.isfinite(dr) and dr < w.single_read_db:
            out.append(
                f"  Its DR ({dr:.2f} dB) is below that of a single read of the same camera at this word "
                f"(stage 1: {w.single_read_db:.2f} dB): the fusion gives less range than one frame."
            )
    return [*out, ""]


def _versus(c: Mapping[str, Any], a: int, b: int, names: Sequence[str]) -> str:
    """Objective by objective, ``a`` against ``b``: values and which is better."""
    parts = []
    for n in names:
        va, vb = float(c[n][a]), float(c[n][b])
        o = OBJECTIVES.get(n)
        if o is None or not (math.isfinite(va) and math.isfinite(vb)):
            verdict = "not comparable" if o is not None else ""
        else:
            ka, kb = o.key(va), o.key(vb)
            verdict = "better" if ka < kb else ("worse" if ka > kb else "equal")
        fa, fb = fmt_pair(n, va, vb)
        parts.append(f"`{n}` {fa} against {fb}" + (f" ({verdict})" if verdict else ""))
    return "; ".join(parts)


def _first_difference(c: Mapping[str, Any], rank: Sequence[str], a: int, b: int) -> str | None:
    """The first ranking objective on which ``a`` and ``b`` differ."""
    for r in rank:
        if OBJECTIVES[r].key(float(c[r][a])) != OBJECTIVES[r].key(float(c[r][b])):
            return r
    return None


def _why_runner_up(spec: DesignSpec, c: Mapping[str, Any], best: int, second: int | None) -> list[str]:
    if second is None:
        return ["No other candidate meets the constraints: there is no runner-up."]
    r = _first_difference(c, spec.rank, best, second)
    head = f"It ranks above the runner-up, {_name(c, second)} at {_where(spec, c, second)}"
    if r is None:
        return [
            f"{head}: they tie on every ranking objective ({', '.join(f'`{x}`' for x in spec.rank)}) and it "
            "comes first in the table."
        ]
    before = spec.rank[: spec.rank.index(r)]
    tie = f", after equal {', '.join(f'`{x}`' for x in before)}" if before else ""
    fa, fb = fmt_pair(r, c[r][best], c[r][second])
    return [f"{head}, on `{r}`{tie}: {fa} against {fb}."]


def _constraint_failures(spec: DesignSpec, c: Mapping[str, Any], i: int) -> list[str]:
    return [
        f"`{k.objective}` = {fmt_value(k.objective, c[k.objective][i])} (needs {k.text()})"
        for k in spec.constraints
        if not k.met(float(c[k.objective][i]))
    ]


def _against_reference(spec: DesignSpec, c: Mapping[str, Any], choice: Choice) -> list[str]:
    best, ref = choice.recommended, choice.reference
    assert best is not None
    if ref is None:
        return ["The configured pair is not among this point's candidates."]
    label = f"the configured pair {_name(c, ref)} (`fusion.mu1`, `fusion.mu2` of the base)"
    if ref == best:
        return [f"The recommended design is {label} itself."]
    fails = _constraint_failures(spec, c, ref)
    out = [
        f"Against {label}: it fails the constraints, {'; '.join(fails)}."
        if fails
        else f"Against {label}: it meets the constraints and ranks {int(c['rank'][ref])} of "
        f"{len(choice.ranked)}."
    ]
    d = float(c["dr_db"][best]) - float(c["dr_db"][ref])
    trade = (
        ("gains" if d > 0 else "gives up") + f" {_db(abs(d))} dB of closed-form DR"
        if d
        else "has the same closed-form DR"
    )
    fa, fb = fmt_pair("dr_db", c["dr_db"][best], c["dr_db"][ref])
    out.append(f"The recommended design {trade} ({fa} against {fb}).")
    names = [n for n in spec.objectives if n != "dr_db"]
    if names:
        out.append(f"On the other objectives: {_versus(c, best, ref, names)}.")
    return out


def _numbers_table(spec: DesignSpec, c: Mapping[str, Any], picks: Sequence[tuple[str, int]]) -> list[str]:
    names = [*dict.fromkeys([*spec.objectives, "dr_db", "dr_cap_db", "dr_chain_db", "low_share"])]
    head = [
        "",
        *(f"{label}: {c['stages'][i]} `{c['rule'][i]}` {int(c['beta_bits'][i])}-bit" for label, i in picks),
    ]
    rows = [[f"`{n}`", *(fmt_value(n, c[n][i]) for _, i in picks)] for n in names]
    return [*markdown_table(head, rows), ""]


def _recommendation(spec: DesignSpec, table: DesignTable, choice: Choice) -> list[str]:
    c = table.columns
    out = ["## Recommendation", ""]
    best = choice.recommended
    if best is None:
        return [
            *out,
            f"**No candidate meets the constraints** ({', '.join(k.text() for k in spec.constraints)}); "
            "relax them or widen the space. The Pareto front below holds the best trade-offs.",
            "",
        ]
    out += [
        f"**Recommended design: stages {c['stages'][best]}, rule `{c['rule'][best]}`, "
        f"{int(c['beta_bits'][best])}-bit word**, at {_where(spec, c, best)} (candidate "
        f"{int(c['candidate'][best])}).",
        "",
    ]
    picks = [("recommended", best)]
    if choice.runner_up is not None:
        picks.append(("runner-up", choice.runner_up))
    if choice.reference is not None and choice.reference not in (best, choice.runner_up):
        picks.append(("configured pair", choice.reference))
    out += _numbers_table(spec, c, picks)
    out += [*_why_runner_up(spec, c, best, choice.runner_up), ""]
    out += [" ".join(_against_reference(spec, c, choice)), ""]
    return out + _cap_lines(spec, c, picks)


def _feasibility(spec: DesignSpec, table: DesignTable, choice: Choice) -> list[str]:
    c = table.columns
    n = len(table)
    rank = ", ".join(
        f"`{r}` ({ {'max': 'higher', 'min': 'lower', 'zero': 'nearer 0'}[OBJECTIVES[r].direction] } first)"
        for r in spec.rank
    )
    out = ["## Constraints and ranking", ""]
    if not spec.constraints:
        out.append(
            f"No constraints: all {n} candidates are feasible. Ranking rule: {rank}; ties go to the "
            "candidate "
            "listed first."
        )
        return [*out, ""]
    out.append(
        f"{int(choice.feasible.sum())} of {n} candidates meet the constraints; ranking rule: {rank}; ties go "
        "to the candidate listed first."
    )
    for k in spec.constraints:
        fails = sum(1 for v in c[k.objective] if not k.met(float(v)))
        out.append(f"- {k.text()}: {fails} candidates fail it.")
    return [*out, ""]


def _front(
    spec: DesignSpec, table: DesignTable, choice: Choice, chain: Mapping[int, Mapping[str, Any]]
) -> list[str]:
    c = table.columns
    on = [int(i) for i in sorted(range(len(table)), key=lambda i: -float(c["dr_db"][i])) if choice.front[i]]
    measured = sum(1 for r in chain.values() if r.get("status") == "ok")
    failed = [r for r in chain.values() if r.get("status") != "ok"]
    how = {
        "front": "the chosen designs and the pairs on the front (at most 32, best ranked first)",
        "chosen": "the chosen designs (recommended, runner-up, configured pair) only",
        "none": 'no candidate (chain_dr = "none")',
    }[spec.chain_dr]
    out = [
        "## Pareto front",
        "",
        f"{len(on)} candidates are on the Pareto front of {', '.join(f'`{o}`' for o in FRONT_OBJECTIVES)}: "
        "no other "
        "candidate is at least as good on all three and better on one (`plots/pareto.png`). The DR through "
        "the "
        "chain (a photon-transfer series through the sensor and DTDI, eq. 11's fusion, as `reproduce` "
        "measures "
        f"it) is expensive, so it was measured for {how}: {measured} pairs"
        + (f", {len(failed)} failed ({failed[0].get('error')})" if failed else "")
        + ".",
        "",
    ]
    names = ["dr_db", "dr_chain_db", "truth_rms", "clipped_share"]
    rows = [
        [
            str(int(c["candidate"][i])),
            _name(c, i),
            str(int(c["point"][i])),
            *(fmt_value(n, c[n][i]) for n in names),
        ]
        for i in on[:FRONT_ROWS]
    ]
    out += markdown_table(["candidate", "design", "point", *(f"`{n}`" for n in names)], rows)
    if len(on) > FRONT_ROWS:
        out.append(f"| ... {len(on) - FRONT_ROWS} more (`on_front` in candidates.csv) | | | | | | |")
    return [*out, ""]


def _method(spec: DesignSpec, records: Mapping[int, Mapping[str, Any]]) -> list[str]:
    notes = sorted({n for r in records.values() for n in (r.get("truth_not_exact") or [])})
    words = spec.space.words
    lines = [
        "## How the scores were made",
        "",
        f"- One pass per point with its exact truth at every candidate stage ({len(spec.space.stages)} "
        "stages, the "
        f"{spec.space.pass_beta}-bit word); every candidate of the point is scored on it.",
        "- The true HDR target of a candidate is `linear_dn` of its highest stage less that stage's "
        "offsets: the "
        "noise-free signal without any clip. `truth_rms` and `truth_bias` are the RMS and mean relative "
        "error of "
        "the fused image against it where it is at least 1 DN, over the whole image and per region "
        "(`spot`, `fill`, "
        "`spot_edge` where the TDI window's light changes, `clipped` where a fused stage is not clear of "
        "its clips, "
        "`recoverable`, `lost`).",
        "- `clipped_share`: the pixels taken from a stage that clipped there (a read at full well or the "
        "ADC top, "
        "or the word at its top).",
        f"- `snr_dark`: the temporal SNR of the darkest {DARK_FRACTION:.0%} of the pixels (by their light "
        "per row over the sensor's whole TDI window, the same pixels for every candidate): the mean true "
        "signal of the stage each pixel came from over the square root of its mean model variance.",
        "- `dr_db`: closed form of the EMVA 1288 linear model, `20 lg(saturation of the lowest stage / SNR "
        "= 1 of "
        "the highest stage)`; `dr_cap_db` is what the output word takes from it.",
    ]
    if len(words) > 1:
        lines.append(
            f"- The words {', '.join(str(b) for b in words)} bits come from the one pass at "
            f"{max(words)} bits: a narrower word is the wider word clipped at its top (exact), a stage's "
            "`clipped` adds where it reaches that top (exact), and a stage is clear of the narrower word's "
            f"clip where its expectation lies {CLIP_MARGIN_SIGMAS:g} temporal standard deviations below it."
        )
    if "mtf50_along" in spec.objectives:
        lines.append(
            "- `mtf50_along`: the ISO 12233 e-SFR MTF50 along the track of the least sharp stage the "
            "candidate "
            "fuses, on a noise-free companion pass of the same bench with slanted edges (as `reproduce`'s "
            "`mtf50_vs_stage`)."
        )
    lines.append(
        "- The truth is exact for this sensor's chain."
        if not notes
        else "- The truth is not exact for this sensor's chain: " + "; ".join(notes) + "."
    )
    effects = sorted({e.name for p in spec.points for e in sensor_chain(p.cfg.sensor).effects})
    if effects:
        names = ", ".join(f"`{e}`" for e in effects)
        lines.append(f"- The sensor's chain has effects ({names}): the words, the truth and the DR through "
                     "the chain include them; the closed forms (`dr_db`, `dr_cap_db`, `snr_dark`'s variance) "
                     "are the linear model's.")
    return [*lines, ""]


def report_markdown(
    spec: DesignSpec,
    table: DesignTable,
    choice: Choice,
    records: Mapping[int, Mapping[str, Any]],
    chain: Mapping[int, Mapping[str, Any]],
    files: Sequence[str] = (),
) -> str:
    """The text of ``report.md`` (module docstring)."""
    ok = sum(1 for r in records.values() if r.get("status") == "ok")
    failed = {i: r for i, r in records.items() if r.get("status") != "ok"}
    space = spec.space
    lines = [f"# Design `{spec.name}`", ""]
    if spec.description:
        lines += [spec.description.strip(), ""]
    lines += [
        f"Spec `{spec.path.name}`, base config `{spec.base.name}` (SHA-256 "
        f"`{config_sha256(spec.base)[:16]}`), root "
        f"seed {spec.seed}, noise **{spec.noise}**{', --quick preset' if spec.quick else ''}, bench_sim "
        f"{__version__}.",
        "",
        f"**{len(table)} candidates** of {len(spec.points)} point{'s' if len(spec.points) != 1 else ''} "
        f"({ok} scored, {len(failed)} failed): "
        f"{len(space.pairs)} stage pairs and {len(space.triples)} triples, rules "
        f"{', '.join(f'`{r}`' for r in space.rules)}, words {', '.join(str(b) for b in space.words)} bits"
        + (f", over {', '.join(f'`{k}`' for k in spec.keys)}" if spec.keys else "")
        + ".",
        "",
    ]
    if len(table):
        lines += _recommendation(spec, table, choice)
        lines += _feasibility(spec, table, choice)
        lines += _front(spec, table, choice, chain)
    else:
        lines += ["No candidate was scored: every point failed.", ""]
    lines += _method(spec, records)
    if failed:
        lines += ["## Failed points", ""]
        lines += [f"- point {i}: `{r.get('error')}`" for i, r in sorted(failed.items())]
        lines.append("")
    lines += [
        "## Files",
        "",
        *(f"- `{f}`" for f in files),
        "",
        f"Regenerate with `bench-sim design {spec.path.name} --out DIR`.",
        "",
    ]
    return "\n".join(lines)


def write_report(
    out: Path,
    spec: DesignSpec,
    table: DesignTable,
    choice: Choice,
    records: Mapping[int, Mapping[str, Any]],
    chain: Mapping[int, Mapping[str, Any]],
    plots: bool = True,
) -> list[str]:
    """``plots/`` (unless ``plots`` is false or nothing was scored) and ``report.md``; returns their names."""
    meta = provenance(spec.base, spec.seed, kind="design", design=spec.name)
    files = ["candidates.csv", "candidates.csv.json", "design.nc", "design.json"]
    if plots and len(table):
        files.append(plot_pareto(out, table, choice, meta))
        files += plot_heatmaps(out, table, choice, spec.objectives, meta)
    files.append("report.md")
    write_text(out / "report.md", report_markdown(spec, table, choice, records, chain, files))
    return files
