"""The distributions of a dataset spec's ``[randomize]`` (and ``[scene]``) entries: each a
pydantic model (unknown keys refused) that draws one value from a generator and lists the
extreme values the spec's checks probe (:data:`DISTRIBUTIONS`)."""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

__all__ = [
    "DISTRIBUTIONS", "DIST_MODELS", "Distribution", "Strict", "Uniform", "LogUniform", "Normal", "Choice",
    "Glob",
]

#: ``dist`` values of ``[randomize]`` entries and what they draw.
DISTRIBUTIONS: dict[str, str] = {
    "uniform": "uniform in [low, high)",
    "loguniform": "exp(uniform in [ln low, ln high)), 0 < low < high",
    "normal": "normal(mean, std) truncated to [low, high] (inverse CDF of one uniform draw)",
    "choice": "one of values, uniformly or with weights",
    "glob": "one of the sorted files matching pattern, uniformly (target.image only)",
}

#: Interior point at which continuous distributions are also checked (catches integer keys)
_INTERIOR = 0.381966

Scalar = bool | int | float | str


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


def _finite(**values: float) -> None:
    for k, v in values.items():
        if not math.isfinite(v):
            raise ValueError(f"{k} = {v}: must be finite")


class _Interval(Strict):
    """A distribution over ``[low, high)``: both finite, ``low < high``."""

    low: float
    high: float

    @model_validator(mode="after")
    def _order(self) -> _Interval:
        _finite(low=self.low, high=self.high)
        if not self.low < self.high:
            raise ValueError(
                f"low = {self.low} must be below high = {self.high} (a fixed value goes in [config])"
            )
        return self


class Uniform(_Interval):
    """Uniform in ``[low, high)``."""

    dist: Literal["uniform"]

    def draw(self, rng: np.random.Generator) -> float:
        return float(rng.uniform(self.low, self.high))

    def probes(self) -> list[Any]:
        return [self.low, self.high, self.low + _INTERIOR * (self.high - self.low)]


class LogUniform(_Interval):
    """``exp`` of a uniform draw in ``[ln low, ln high)``: every decade equally likely."""

    dist: Literal["loguniform"]
    low: Annotated[float, Field(gt=0)]
    high: Annotated[float, Field(gt=0)]

    def draw(self, rng: np.random.Generator) -> float:
        return float(np.exp(rng.uniform(np.log(self.low), np.log(self.high))))

    def probes(self) -> list[Any]:
        return [self.low, self.high, self.low * (self.high / self.low) ** _INTERIOR]


class Normal(Strict):
    """Normal ``(mean, std)`` truncated to ``[low, high]``, drawn by the inverse CDF of one uniform:
    ``x = mean + std * Phi^-1(Phi(a) + u (Phi(b) - Phi(a)))`` with ``a``, ``b`` the standardised
    bounds (computed on the side of the mean where the bounds' tail is, so it stays accurate far
    out in a tail)."""

    dist: Literal["normal"]
    mean: float
    std: Annotated[float, Field(gt=0)]
    low: float
    high: float

    @model_validator(mode="after")
    def _order(self) -> Normal:
        _finite(mean=self.mean, std=self.std, low=self.low, high=self.high)
        if not self.low < self.high:
            raise ValueError(f"low = {self.low} must be below high = {self.high}")
        return self

    def draw(self, rng: np.random.Generator) -> float:
        from scipy.special import ndtr, ndtri

        u = float(rng.uniform())
        a, b = (self.low - self.mean) / self.std, (self.high - self.mean) / self.std
        if a > 0:  # both bounds above the mean: mirror into the lower tail
            z = -float(ndtri(ndtr(-b) + (1.0 - u) * (ndtr(-a) - ndtr(-b))))
        else:
            z = float(ndtri(ndtr(a) + u * (ndtr(b) - ndtr(a))))
        return min(max(self.mean + self.std * z, self.low), self.high)

    def probes(self) -> list[Any]:
        return [self.low, self.high, min(max(self.mean, self.low), self.high)]


class Choice(Strict):
    """One of ``values`` (numbers, strings or booleans of one kind), uniformly or with
    ``weights`` (non-negative, not all zero)."""

    dist: Literal["choice"]
    values: list[Scalar]
    weights: list[Annotated[float, Field(ge=0)]] | None = None

    @model_validator(mode="after")
    def _values(self) -> Choice:
        if not self.values:
            raise ValueError("values = []: a choice needs at least one value")
        kinds = {_kind(v) for v in self.values}
        if len(kinds) > 1:
            raise ValueError(f"values = {self.values}: mixes {' and '.join(sorted(kinds))} (one kind only)")
        if self.weights is not None:
            if len(self.weights) != len(self.values):
                raise ValueError(
                    f"weights = {self.weights}: {len(self.weights)} weights for {len(self.values)} values"
                )
            if not all(math.isfinite(w) for w in self.weights) or sum(self.weights) <= 0:
                raise ValueError(f"weights = {self.weights}: must be finite and not all zero")
        return self

    def draw(self, rng: np.random.Generator) -> Any:
        n = len(self.values)
        if self.weights is None:
            return self.values[int(rng.integers(n))]
        p = np.asarray(self.weights, dtype=np.float64)
        return self.values[int(rng.choice(n, p=p / p.sum()))]

    def probes(self) -> list[Any]:
        return list(self.values)


class Glob(Strict):
    """One of the files matching ``pattern`` (relative to the spec), sorted, uniformly.

    ``files`` holds the matches as written relative to the spec folder (filled by
    :func:`load_spec`)."""

    dist: Literal["glob"]
    pattern: Annotated[str, Field(min_length=1)]
    files: tuple[str, ...] = ()

    def draw(self, rng: np.random.Generator) -> str:
        return self.files[int(rng.integers(len(self.files)))]

    def probes(self) -> list[Any]:
        return list(self.files)


Distribution = Uniform | LogUniform | Normal | Choice | Glob
DIST_MODELS: dict[str, type[BaseModel]] = {
    "uniform": Uniform, "loguniform": LogUniform, "normal": Normal, "choice": Choice, "glob": Glob,
}


def _kind(v: Any) -> str:
    if isinstance(v, bool):
        return "booleans"
    if isinstance(v, int | float):
        return "numbers"
    return "strings"
