"""Design specifications: the bench, the design space, the objectives, constraints and ranking of
``bench-sim design SPEC.toml``, checked before anything runs.

A spec is a TOML file (the shipped example: ``bench_sim/scenes/designs/example.toml``)::

    name = "my_camera"                  # default: the file's stem
    base = "../paper_rig.toml"          # any bench config, a calibrated camera's too (relative to the spec)
    quick = true                        # reproduce's --quick preset on the base (default false)
    seed = 0                            # root seed
    noise = "common"                    # "common" (default): every point's pass on the root seed's
                                        # stream; "independent": point i on SeedSequence(seed).spawn(n)[i]
    mode = "product"                    # how [[parameters]] combine: product | sequential | custom
    rules = ["eq11", "clip", "clip_margin"]   # fusion rules (bench_sim.measure.fusion_scores.RULES)
    beta_bits = [12, 16]                # output words, scored from one pass at the widest
    objectives = ["dr_db", "truth_rms", "clipped_share", "snr_dark"]
    rank = ["truth_rms", "dr_db"]       # the ranking rule: objectives in order, each its own way
    chain_dr = "front"                  # DR through the chain: "front" (the Pareto front and the
                                        # chosen designs), "chosen" (these alone) or "none"

    [overrides]                         # keys set on the base (optional)
    lights.strong = { irradiance_w_m2 = 200.0 }

    [stages]                            # the stage candidates (each of a point's sensor rows)
    mu1 = "all"                         # the lower stage: "all", "A:B", "A:B:STEP", "A,B" or a list
    mu2 = "all"                         # the upper stage: every mu1 < mu2 of the two is a pair
    triples = [[10, 30, 80]]            # three-stage candidates (the clip-aware rules fuse them)

    [[constraints]]
    objective = "dr_db"
    min = 75.0

    [[parameters]]                      # any other config key, as in a sweep spec: one pass per point
    key = "timing.line_period_s"
    values = [80e-6, 100e-6, 120e-6]

The ``[[parameters]]`` tables (``values``, ``range``, ``linspace``, ``logspace``) and the modes are
the sweep's (:mod:`bench_sim.workflows.sweep.spec`); without them the design has one point, the
base. The stages, the word and the fusion stages are the design space's own keys, not parameters.
The configured pair ``fusion.mu1``/``fusion.mu2`` (the paper's 10/80) is always among the pairs,
scored by every two-stage rule, so the report can compare the recommendation with it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict

from bench_sim.config import (
    BenchConfig,
    ConfigError,
    config_to_toml_dict,
    load_config,
    quick_config,
    read_toml,
    validate_model,
    with_overrides,
)
from bench_sim.errors import BenchSimError
from bench_sim.measure.design_scores import CandidateSpace, word_config
from bench_sim.measure.fusion_scores import RULES
from bench_sim.sensor.model import stage_offset_dn, word_clip_dn
from bench_sim.workflows.design.objectives import (
    DEFAULT_OBJECTIVES,
    DEFAULT_RANK,
    OBJECTIVES,
    Constraint,
)
from bench_sim.workflows.preflight import SEED_RULE, is_seed
from bench_sim.workflows.simulate import parse_stages_arg
from bench_sim.workflows.spec_grid import grid_as_dict
from bench_sim.workflows.sweep.spec import (
    MODES,
    NOISE,
    SweepPoint,
    key_exists,
    point_combinations,
    point_config,
)

__all__ = ["DESIGN_KEYS", "DesignSpec", "load_design_spec", "CHAIN_DR", "STAGE_KEYS"]

#: what ``chain_dr`` may be
CHAIN_DR = ("front", "chosen", "none")
#: keys of ``[stages]``
STAGE_KEYS = ("mu1", "mu2", "triples")
#: the keys a spec may hold, and what each is
DESIGN_KEYS: dict[str, str] = {
    "name": "name of the design (default: the spec file's stem)",
    "description": "free text, copied into design.json and report.md",
    "base": "bench config file, relative to the spec (default: the paper rig); a calibrated camera's too",
    "quick": "true: apply reproduce's --quick preset to the base",
    "seed": f"root seed ({SEED_RULE})",
    "mode": "product | sequential | custom ([[parameters]] as in a sweep)",
    "noise": "common (default: every point's pass on the root seed's stream) | independent",
    "overrides": "table of config keys set on the base",
    "parameters": "[[parameters]] tables of other config keys: key and values, range, linspace or logspace",
    "points": "custom mode: CSV file of points, relative to the spec",
    "stages": "[stages] mu1, mu2 (stage ranges: every mu1 < mu2 is a pair) and triples",
    "rules": f"fusion rules, of {', '.join(RULES)}",
    "beta_bits": "output words [bits], scored from one pass at the widest",
    "objectives": f"the objectives reported, of {', '.join(OBJECTIVES)}",
    "constraints": "[[constraints]] tables: objective and min and/or max",
    "rank": "the ranking rule: objectives in order, each in its better direction",
    "chain_dr": f"the DR through the chain: {' | '.join(CHAIN_DR)}",
}
#: config keys the design space sets itself (not parameters)
_OWN_KEYS = {"dtdi.beta_bits": "beta_bits", "fusion.mu1": "[stages] mu1", "fusion.mu2": "[stages] mu2"}
#: candidate rows above which a spec is refused (a typo in a range, not a design)
MAX_CANDIDATES = 2_000_000


class _SpecFile(BaseModel):
    """The top level of a design spec (:data:`DESIGN_KEYS`; unknown keys refused), values as written."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)

    name: str | None = None
    description: str = ""
    base: str | None = None
    quick: bool = False
    seed: int = 0
    mode: str = "product"
    noise: str = "common"
    overrides: dict[str, Any] = {}
    parameters: list[dict[str, Any]] | None = None
    points: str | None = None
    stages: dict[str, Any] = {}
    rules: list[str] = ["eq11", "clip", "clip_margin"]
    beta_bits: list[int] | None = None
    objectives: list[str] = list(DEFAULT_OBJECTIVES)
    constraints: list[dict[str, Any]] = []
    rank: list[str] = list(DEFAULT_RANK)
    chain_dr: str = "front"


@dataclass(frozen=True)
class DesignSpec:
    """A checked design spec (:func:`load_design_spec`): every point's config valid at the pass's
    word, every candidate within every point's sensor."""

    path: Path
    name: str
    description: str
    mode: str
    noise: str
    seed: int
    quick: bool
    base: BenchConfig
    keys: tuple[str, ...]
    values: dict[str, list[Any]]
    points: tuple[SweepPoint, ...]
    space: CandidateSpace
    reference: tuple[int, int]
    objectives: tuple[str, ...]
    constraints: tuple[Constraint, ...]
    rank: tuple[str, ...]
    chain_dr: str
    raw: dict[str, Any] = field(repr=False)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready description (``design.json``'s ``spec``)."""
        return {
            **grid_as_dict(self),
            "pairs": len(self.space.pairs),
            "triples": [list(t) for t in self.space.triples],
            "rules": list(self.space.rules),
            "beta_bits": list(self.space.words),
            "reference": list(self.reference),
            "objectives": list(self.objectives),
            "constraints": [c.__dict__ for c in self.constraints],
            "rank": list(self.rank),
            "chain_dr": self.chain_dr,
            "raw": self.raw,
        }


def _err(spec: Path, msg: str) -> BenchSimError:
    return BenchSimError(f"design spec {spec}: {msg}")


def _ours(exc: BenchSimError) -> BenchSimError:
    """A sweep-spec helper's error, worded for a design spec."""
    return type(exc)(str(exc).replace("sweep spec ", "design spec ", 1))


def _check_top(spec: Path, top: _SpecFile) -> None:
    """The values of the top-level keys (one line on the first bad one)."""
    checks: list[tuple[bool, str]] = [
        (top.name is None or top.name != "", "name = '': needs a non-empty string"),
        (is_seed(top.seed), f"seed = {top.seed!r}: needs {SEED_RULE}"),
        (top.mode in MODES, f"mode = {top.mode!r}: allowed {', '.join(MODES)}"),
        (top.noise in NOISE, f"noise = {top.noise!r}: allowed {', '.join(NOISE)}"),
        (top.chain_dr in CHAIN_DR, f"chain_dr = {top.chain_dr!r}: allowed {', '.join(CHAIN_DR)}"),
        (top.mode != "custom" or top.points is not None, 'mode = "custom" needs points = "FILE.csv"'),
        (top.mode == "custom" or top.points is None, f"points = {top.points!r}: only for mode = 'custom'"),
        (
            top.mode != "custom" or top.parameters is None,
            "mode = 'custom' takes its keys from the points file",
        ),
    ]
    for ok, msg in checks:
        if not ok:
            raise _err(spec, msg)
    for key in ("rules", "objectives", "rank"):
        given = getattr(top, key)
        allowed = RULES if key == "rules" else OBJECTIVES
        bad = [v for v in given if v not in allowed]
        if bad:
            raise _err(spec, f"{key}: {bad[0]!r} does not exist (allowed: {', '.join(allowed)})")
        if len(set(given)) != len(given):
            raise _err(spec, f"{key} = {given!r}: each once")
    if not top.rules:
        raise _err(spec, "rules = []: the design space is empty (name at least one rule)")
    if not top.rank:
        raise _err(spec, "rank = []: name at least one objective to rank by")


def _constraints(spec: Path, tables: list[dict[str, Any]]) -> tuple[Constraint, ...]:
    out = []
    for t in tables:
        if not isinstance(t, dict) or set(t) - {"objective", "min", "max"} or "objective" not in t:
            raise _err(spec, f"[[constraints]] {t!r}: needs objective and min and/or max (nothing else)")
        name = t["objective"]
        if name not in OBJECTIVES:
            raise _err(
                spec,
                f"[[constraints]] objective = {name!r} does not exist (allowed: {', '.join(OBJECTIVES)})",
            )
        bounds = {k: t.get(k) for k in ("min", "max")}
        for k, v in bounds.items():
            if v is not None and (isinstance(v, bool) or not isinstance(v, int | float)):
                raise _err(spec, f"[[constraints]] {name}: {k} = {v!r}: needs a number")
        if bounds["min"] is None and bounds["max"] is None:
            raise _err(spec, f"[[constraints]] {name}: give min and/or max")
        out.append(Constraint(name, *(None if v is None else float(v) for v in bounds.values())))
    return tuple(out)


def _stage_list(spec: Path, key: str, value: Any, rows: int) -> tuple[int, ...]:
    """A ``[stages]`` range as stages (``"all"``, ``"A:B[:S]"``, ``"A,B"`` or a list), each in ``1..rows``."""
    try:
        if isinstance(value, str):
            return parse_stages_arg(value, rows)
        if (
            isinstance(value, list)
            and value
            and all(isinstance(v, int) and not isinstance(v, bool) for v in value)
        ):
            return parse_stages_arg(",".join(str(v) for v in value), rows)
    except BenchSimError as exc:
        raise _err(
            spec, str(exc).replace("--stages", f"[stages] {key}", 1).rstrip() + f" (sensor.rows = {rows})"
        ) from None
    raise _err(spec, f"[stages] {key} = {value!r}: needs 'all', 'A:B', 'A:B:STEP', 'A,B' or a list of stages")


def _space(spec: Path, top: _SpecFile, base: BenchConfig) -> CandidateSpace:
    """The candidate space of the spec on the base's sensor (each point is checked later)."""
    unknown = sorted(set(top.stages) - set(STAGE_KEYS))
    if unknown:
        raise _err(spec, f"[stages] {unknown[0]}: unknown key (allowed: {', '.join(STAGE_KEYS)})")
    rows = base.sensor.rows
    lows = _stage_list(spec, "mu1", top.stages.get("mu1", "all"), rows)
    highs = _stage_list(spec, "mu2", top.stages.get("mu2", "all"), rows)
    pairs = {(a, b) for a in lows for b in highs if a < b}
    triples = []
    for t in top.stages.get("triples", []) or []:
        if not (
            isinstance(t, list)
            and len(t) == 3
            and all(isinstance(v, int) and not isinstance(v, bool) for v in t)
            and 1 <= t[0] < t[1] < t[2]
        ):
            raise _err(spec, f"[stages] triples: {t!r}: needs [m1, m2, m3] with 1 <= m1 < m2 < m3")
        if t[2] > rows:
            raise _err(spec, f"[stages] triples: {t!r}: stage {t[2]} is outside the sensor's rows 1..{rows}")
        triples.append(tuple(t))
    words = tuple(sorted(set(top.beta_bits))) if top.beta_bits else (base.dtdi.beta_bits,)
    if not words:
        raise _err(spec, "beta_bits = []: the design space is empty (name at least one word)")
    if len(set(triples)) != len(triples):
        raise _err(spec, "[stages] triples: each triple once")
    if not pairs and not (triples and any(r != "eq11" for r in top.rules)):
        why = "eq11 fuses pairs only" if triples else "no mu1 < mu2"
        raise _err(
            spec,
            f"the design space is empty: [stages] mu1 = {top.stages.get('mu1', 'all')!r}, "
            f"mu2 = {top.stages.get('mu2', 'all')!r}, triples = {[list(t) for t in triples]} "
            f"with rules {top.rules} give no candidate ({why})",
        )
    pairs.add((base.fusion.mu1, base.fusion.mu2))  # the configured pair: the report compares with it
    return CandidateSpace(tuple(sorted(pairs)), tuple(sorted(triples)), tuple(top.rules), words)


def _check_words(spec: Path, cfg: BenchConfig, space: CandidateSpace, where: str) -> None:
    """Every word of the space is a valid word of the bench ``cfg`` and holds every candidate
    stage's offset below half its range, and every candidate stage is one of its sensor rows."""
    rows = cfg.sensor.rows
    top_stage = max(space.stages)
    if top_stage > rows:
        raise _err(spec, f"{where}stage {top_stage} is outside the sensor's rows 1..{rows}")
    for beta in space.words:
        try:
            word_config(cfg, beta)
        except ConfigError as exc:
            raise _err(spec, f"beta_bits = {beta}: {where}{str(exc).split(': ', 2)[-1]}") from None
        top = word_clip_dn(beta)
        off = max(stage_offset_dn(cfg.sensor, cfg.dtdi, m) for m in space.stages)
        if not off < 0.5 * top:
            raise _err(spec, f"beta_bits = {beta}: {where}the offset of the words ({off:g} DN: "
                             "dtdi.pedestal_dn and, with subtract_black off, m x black_offset_dn) is half "
                             f"the {beta}-bit word or more; use wider words or a smaller pedestal")


def _points(
    spec: Path, top: _SpecFile, base_cfg: BenchConfig, pass_beta: int
) -> tuple[tuple[str, ...], dict[str, list[Any]], tuple[SweepPoint, ...]]:
    """The points (one pass each) at the pass's word."""
    if top.parameters is None and top.mode != "custom":
        keys: tuple[str, ...] = ()
        values: dict[str, list[Any]] = {}
        combos: list[tuple[dict[str, Any], str | None]] = [({}, None)]
    else:
        try:
            keys, values, combos = point_combinations(spec, top.mode, top.parameters, top.points)
        except BenchSimError as exc:
            raise _ours(exc) from None
    for k in keys:
        if k in _OWN_KEYS:
            raise _err(spec, f"key {k!r}: the design space sets it ({_OWN_KEYS[k]}), not a parameter")
        if not key_exists(base_cfg, k):
            raise _err(spec, f"key {k!r}: not a setting of the bench config (check the section and name)")
    base = config_to_toml_dict(word_config(base_cfg, pass_beta))
    try:
        points = tuple(
            SweepPoint(i, vals, point_config(spec, base, vals, i), varied)
            for i, (vals, varied) in enumerate(combos)
        )
    except BenchSimError as exc:
        raise _ours(exc) from None
    return keys, values, points


def load_design_spec(path: str | Path) -> DesignSpec:
    """Read and check a design spec: every key and value, every point's config, every candidate
    stage and word. Raises :class:`~bench_sim.errors.BenchSimError` (one line naming the spec
    and what is allowed) on the first problem, before anything runs."""
    spec = Path(path).expanduser().resolve()
    label = f"design spec {spec}"
    raw = read_toml(spec, label, "a design spec")
    top = validate_model(_SpecFile, raw, label, unknown=f"allowed: {', '.join(DESIGN_KEYS)}")
    _check_top(spec, top)
    base_cfg = load_config((spec.parent / top.base).resolve() if top.base else None)
    if top.quick:
        base_cfg = quick_config(base_cfg)
    if top.overrides:
        base_cfg = with_overrides(base_cfg, top.overrides, source=f"{spec} [overrides]")
    constraints = _constraints(spec, top.constraints)
    space = _space(spec, top, base_cfg)
    n = len(space.rows())
    if n > MAX_CANDIDATES:
        raise _err(
            spec, f"{n} candidates per point: more than {MAX_CANDIDATES}; narrow [stages] or beta_bits"
        )
    _check_words(spec, base_cfg, space, "")
    keys, values, points = _points(spec, top, base_cfg, space.pass_beta)
    for p in points:
        _check_words(spec, p.cfg, space, f"point {p.index}: ")
    return DesignSpec(
        spec,
        top.name or spec.stem,
        top.description,
        top.mode,
        top.noise,
        int(top.seed),
        top.quick,
        base_cfg,
        keys,
        values,
        points,
        space,
        (base_cfg.fusion.mu1, base_cfg.fusion.mu2),
        tuple(top.objectives),
        constraints,
        tuple(top.rank),
        top.chain_dr,
        raw,
    )
