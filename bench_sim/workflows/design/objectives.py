"""What a design is judged by: the objectives, the constraints, the ranking rule and the Pareto front.

Every objective is a column of the candidate table (:data:`OBJECTIVES`: units, the direction that
is better, meaning). A spec names the objectives it reports (``objectives``), the constraints a
candidate must meet (``[[constraints]]``: ``objective`` with ``min`` and/or ``max``) and the
ranking rule (``rank``: objectives compared in order, each in its own direction; ties go to the
candidate listed first). The recommended design is the best feasible candidate, the runner-up
the next one.

The **Pareto front** is the set of candidates no other candidate beats on all three of: the
dynamic range of the fused image (``dr_db``, higher is better), its RMS error against the true
HDR target (``truth_rms``, lower) and the share of pixels taken from a clipped stage
(``clipped_share``, lower): the candidates worth a look whatever the weights
(:data:`FRONT_OBJECTIVES`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from bench_sim.measure.design_scores import SCORE_COLUMNS
from bench_sim.metrics.fusion_truth import TRUTH_REGIONS

__all__ = [
    "Objective",
    "OBJECTIVES",
    "DEFAULT_OBJECTIVES",
    "DEFAULT_RANK",
    "FRONT_OBJECTIVES",
    "Constraint",
    "feasible",
    "rank_order",
    "pareto_front",
    "better",
]


@dataclass(frozen=True)
class Objective:
    """One objective: its column, units, the better direction (``max``, ``min``, or ``zero``:
    nearer 0 is better) and meaning."""

    name: str
    units: str
    direction: str
    meaning: str

    def key(self, value: float) -> float:
        """A number that is lower the better ``value`` is (NaN: worst)."""
        if value is None or not math.isfinite(value):
            return math.inf
        return -value if self.direction == "max" else (abs(value) if self.direction == "zero" else value)


def _objectives() -> dict[str, Objective]:
    out = {
        "dr_db": Objective("dr_db", "dB", "max", SCORE_COLUMNS["dr_db"][1]),
        "truth_rms": Objective("truth_rms", "1", "min", SCORE_COLUMNS["truth_rms"][1]),
        "truth_bias": Objective("truth_bias", "1", "zero", SCORE_COLUMNS["truth_bias"][1]),
    }
    for region in TRUTH_REGIONS[1:]:
        for stat, way in (("rms", "min"), ("bias", "zero")):
            name = f"truth_{stat}_{region}"
            out[name] = Objective(name, "1", way, SCORE_COLUMNS[name][1])
    out["clipped_share"] = Objective("clipped_share", "1", "min", SCORE_COLUMNS["clipped_share"][1])
    out["snr_dark"] = Objective("snr_dark", "1", "max", SCORE_COLUMNS["snr_dark"][1])
    out["mtf50_along"] = Objective(
        "mtf50_along",
        "cycles/px",
        "max",
        "MTF50 along the track of the least sharp stage fused (ISO 12233 e-SFR on a noise-free companion "
        "pass of the bench with slanted edges)",
    )
    return out


#: every objective a spec may name, by its column
OBJECTIVES: dict[str, Objective] = _objectives()
#: the objectives reported when a spec names none
DEFAULT_OBJECTIVES = ("dr_db", "truth_rms", "truth_bias", "clipped_share", "snr_dark", "mtf50_along")
#: the ranking rule when a spec gives none
DEFAULT_RANK = ("truth_rms",)
#: the objectives of the Pareto front
FRONT_OBJECTIVES = ("dr_db", "truth_rms", "clipped_share")


@dataclass(frozen=True)
class Constraint:
    """``objective`` must lie in ``[min, max]`` (either bound may be ``None``)."""

    objective: str
    min: float | None = None
    max: float | None = None

    def met(self, value: float) -> bool:
        """Whether ``value`` meets the constraint (NaN never does)."""
        if value is None or not math.isfinite(value):
            return False
        return (self.min is None or value >= self.min) and (self.max is None or value <= self.max)

    def text(self) -> str:
        """The constraint as the report writes it."""
        if self.min is not None and self.max is not None:
            return f"{self.min:g} <= {self.objective} <= {self.max:g}"
        return (
            f"{self.objective} >= {self.min:g}"
            if self.min is not None
            else f"{self.objective} <= {self.max:g}"
        )


def feasible(columns: Mapping[str, np.ndarray], constraints: Sequence[Constraint]) -> np.ndarray:
    """Per candidate, whether it meets every constraint (bool)."""
    n = len(next(iter(columns.values())))
    ok = np.ones(n, dtype=bool)
    for c in constraints:
        vals = columns[c.objective]
        ok &= np.array([c.met(float(v)) for v in vals], dtype=bool)
    return ok


def better(objective: str, a: float, b: float) -> bool:
    """Whether ``a`` is strictly better than ``b`` on ``objective``."""
    o = OBJECTIVES[objective]
    return o.key(a) < o.key(b)


def rank_order(columns: Mapping[str, np.ndarray], rank: Sequence[str], candidates: np.ndarray) -> list[int]:
    """The ``candidates`` (indices) best first by the ranking rule ``rank`` (objectives in order,
    each in its direction; ties by index)."""
    keys = [(tuple(OBJECTIVES[r].key(float(columns[r][i])) for r in rank), int(i)) for i in candidates]
    return [i for _, i in sorted(keys)]


def pareto_front(columns: Mapping[str, np.ndarray]) -> np.ndarray:
    """Per candidate, whether it is on the Pareto front of :data:`FRONT_OBJECTIVES` (module
    docstring); a candidate with a NaN among them is not. Candidates are taken best first by
    the three objectives in order, so one that dominates another comes before it: a candidate
    is on the front when no candidate on it so far dominates it."""
    keys = np.stack([[OBJECTIVES[o].key(float(v)) for v in columns[o]] for o in FRONT_OBJECTIVES], axis=1)
    n = keys.shape[0]
    on = np.zeros(n, dtype=bool)
    finite = np.all(np.isfinite(keys), axis=1)
    order = np.lexsort(keys.T[::-1])
    front: list[np.ndarray] = []
    for i in order:
        if not finite[i]:
            continue
        k = keys[i]
        if front:
            f = np.asarray(front)
            if np.any(np.all(f <= k, axis=1) & np.any(f < k, axis=1)):
                continue
        front.append(k)
        on[i] = True
    return on


@dataclass(frozen=True)
class Choice:
    """The judgement of a candidate table: per candidate whether it is feasible and on the front,
    the feasible ones best first, the recommended design and the runner-up (the first two of
    them; ``None`` where fewer are feasible) and the reference (the configured pair, eq. 11, at the
    base's word, at the recommended design's point)."""

    feasible: np.ndarray
    front: np.ndarray
    ranked: tuple[int, ...]
    recommended: int | None
    runner_up: int | None
    reference: int | None


def choose(
    columns: Mapping[str, np.ndarray],
    constraints: Sequence[Constraint],
    rank: Sequence[str],
    reference: tuple[int, int, int, str],
) -> Choice:
    """Judge the candidates (module docstring). ``reference``: ``(mu1, mu2, beta_bits, rule)``
    of the reference candidate."""
    ok = feasible(columns, constraints)
    front = pareto_front(columns)
    ranked = tuple(rank_order(columns, rank, np.flatnonzero(ok)))
    best = ranked[0] if ranked else None
    point = int(columns["point"][best]) if best is not None else (int(columns["point"][0]) if len(ok) else 0)
    mu1, mu2, beta, rule = reference
    ref = np.flatnonzero(
        (columns["point"] == point)
        & (columns["mu1"] == mu1)
        & (columns["mu2"] == mu2)
        & (columns["mu_mid"] == 0)
        & (columns["beta_bits"] == beta)
        & (columns["rule"] == rule)
    )
    return Choice(
        ok, front, ranked, best, ranked[1] if len(ranked) > 1 else None, int(ref[0]) if ref.size else None
    )
