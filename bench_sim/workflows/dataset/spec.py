"""Dataset specs: what ``bench-sim dataset SPEC.toml`` makes, and how sample ``i`` is drawn.

A spec is a TOML file::

    name = "example"                  # optional (default: the file's stem)
    description = "..."               # optional, shown on the dataset card
    base = "../paper_rig.toml"        # bench config, relative to the spec (default: the paper rig)
    samples = 16
    seed = 2024                       # root seed of the whole dataset
    stages = [10, 80]                 # or "all" (1 .. sensor.rows)
    lines = 256                       # output size: scene lines ...
    columns = 256                     # ... and sensor columns (default: the base config's)

    [config]                          # fixed overrides on the base, like a config file
    target.panel_lines = 256

    [randomize]                       # dotted config keys, each with a distribution
    "lights.strong.irradiance_w_m2" = { dist = "loguniform", low = 32.0, high = 512.0 }
    "timing.sync_error" = { dist = "normal", mean = 0.0, std = 0.02, low = -0.05, high = 0.05 }
    "target.layout" = { dist = "choice", values = ["dead_leaves", "image"], weights = [3, 1] }
    "target.image" = { dist = "glob", pattern = "../targets/*.png" }

Distributions (:data:`DISTRIBUTIONS`): ``uniform`` (``low < high``), ``loguniform``
(``0 < low < high``), ``normal`` (``mean``, ``std > 0``, truncated to ``low < high``),
``choice`` (``values``: numbers, strings or booleans of one kind; optional ``weights``) and, for
``target.image`` only, ``glob`` (``pattern``: image files relative to the spec, at least one
match; drawn uniformly from the sorted matches). Keys may also be written as nested tables
(``[randomize.lights.strong]``). Paths in a spec (``base``, ``target.image`` in ``[config]``,
glob patterns and the files they match) are relative to the spec file.

**Streams.** Sample ``i`` of a dataset with root seed ``s`` owns
:func:`bench_sim.runtime.execution.task_seed_sequence` ``(s, i)``
(``SeedSequence(s).spawn(n)[i]``) and splits it in two (:func:`sample_streams`): the first child
draws its parameters (keys in sorted order, one generator), the second drives its simulation
(render seed, target generator, the sensor's fixed pattern, the temporal noise). A sample's
content depends only on (spec, seed, ``i``).

**Checks before anything runs** (:func:`load_spec`): unknown spec keys, bad types, a base config
that does not load, stages outside ``1 .. sensor.rows``, unknown or shape-changing randomised
keys, impossible distributions (``low >= high``, an empty choice, a glob matching nothing), and
every distribution's extreme values against the config model; then (:func:`check_sample_configs`)
every sample's drawn config and its target image file. Each refusal is one line naming the spec,
the key, the value and what is allowed.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from bench_sim.config import (
    DEFAULT_CONFIG_PATH,
    BenchConfig,
    config_sha256,
    load_config,
    read_toml,
    validate_model,
    with_overrides,
)
from bench_sim.errors import BenchSimError
from bench_sim.io import sha256_file
from bench_sim.io.glob_walk import bounded_glob
from bench_sim.runtime.execution import task_seed_sequence
from bench_sim.sensor.dtdi import check_stages
from bench_sim.workflows.dataset.splits import DEFAULT_SPLITS, check_splits
from bench_sim.workflows.dataset.targets import check_camera
from bench_sim.workflows.preflight import SeedField
from bench_sim.workflows.simulate import check_inputs

__all__ = [
    "DISTRIBUTIONS",
    "SHAPE_KEYS",
    "DatasetSpec",
    "Distribution",
    "load_spec",
    "sample_streams",
    "nested",
    "check_sample_configs",
]

#: ``dist`` values of ``[randomize]`` entries and what they draw.
DISTRIBUTIONS: dict[str, str] = {
    "uniform": "uniform in [low, high)",
    "loguniform": "exp(uniform in [ln low, ln high)), 0 < low < high",
    "normal": "normal(mean, std) truncated to [low, high] (inverse CDF of one uniform draw)",
    "choice": "one of values, uniformly or with weights",
    "glob": "one of the sorted files matching pattern, uniformly (target.image only)",
}

#: Config keys that fix the arrays' shape or the fused pair: set by the spec, never randomised.
SHAPE_KEYS = ("lines", "sensor.columns", "sensor.rows", "fusion.mu1", "fusion.mu2")

#: Interior point at which continuous distributions are also checked (catches integer keys)
_INTERIOR = 0.381966

Scalar = bool | int | float | str
#: Samples above which a spec is refused (the plan draws every sample's values up front)
MAX_SAMPLES = 100_000


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


def _finite(**values: float) -> None:
    for k, v in values.items():
        if not math.isfinite(v):
            raise ValueError(f"{k} = {v}: must be finite")


class _Interval(_Strict):
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


class Normal(_Strict):
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


class Choice(_Strict):
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


class Glob(_Strict):
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
_DIST_MODELS: dict[str, type[BaseModel]] = {
    "uniform": Uniform, "loguniform": LogUniform, "normal": Normal, "choice": Choice, "glob": Glob,
}


def _kind(v: Any) -> str:
    if isinstance(v, bool):
        return "booleans"
    if isinstance(v, int | float):
        return "numbers"
    return "strings"


class _SpecFile(_Strict):
    """The top level of a spec file (unknown keys refused)."""

    name: str | None = None
    description: str = ""
    base: str | None = None
    samples: Annotated[int, Field(ge=1, le=MAX_SAMPLES)]  # refused before anything is drawn
    seed: SeedField
    stages: Any  # a list of stages or "all", checked by simulate.check_stages
    lines: Annotated[int, Field(ge=1)] | None = None
    columns: Annotated[int, Field(ge=1)] | None = None
    config: dict[str, Any] = {}
    randomize: dict[str, Any] = {}
    splits: dict[str, Any] | None = None  # bench_sim.workflows.dataset.splits
    camera: Literal["per_sample", "fixed"] = "per_sample"  # bench_sim.workflows.dataset.targets


def nested(dotted: Mapping[str, Any]) -> dict[str, Any]:
    """``{"a.b.c": v}`` -> ``{"a": {"b": {"c": v}}}`` (overrides for
    :func:`bench_sim.config.with_overrides`)."""
    out: dict[str, Any] = {}
    for key, value in dotted.items():
        parts = key.split(".")
        cur = out
        for p in parts[:-1]:
            cur = cur.setdefault(p, {})
        cur[parts[-1]] = value
    return out


def _flatten(table: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Leaves of a nested table as dotted keys; a table with a ``dist`` key is a leaf."""
    out: dict[str, Any] = {}
    for k, v in table.items():
        key = f"{prefix}.{k}" if prefix else str(k)
        if isinstance(v, dict) and "dist" not in v and v:
            out.update(_flatten(v, key))
        else:
            out[key] = v
    return out


def sample_streams(seed: int, index: int) -> tuple[np.random.SeedSequence, np.random.SeedSequence]:
    """(parameter stream, simulation stream) of sample ``index``: the two children of
    :func:`~bench_sim.runtime.execution.task_seed_sequence` ``(seed, index)``."""
    params, simulation = task_seed_sequence(seed, index).spawn(2)
    return params, simulation



@dataclass(frozen=True)
class DatasetSpec:
    """A loaded, checked dataset spec.

    Attributes
    ----------
    path
        The spec file (absolute).
    name, description
        For the dataset card.
    samples, seed, stages
        Number of samples, root seed, stored stages (sorted).
    base
        The bench every sample starts from: the base config with ``[config]``, ``lines`` and
        ``columns`` applied.
    randomize
        Dotted config key -> distribution, in sorted key order (the order of the draws).
    raw
        The spec as parsed from TOML (for ``dataset.json`` and the card).
    images
        Every image file the spec can draw (relative to the spec folder) -> SHA-256.
    """

    path: Path
    name: str
    description: str
    samples: int
    seed: int
    stages: tuple[int, ...]
    base: BenchConfig
    randomize: dict[str, Any]
    raw: dict[str, Any] = field(repr=False)
    images: dict[str, str] = field(default_factory=dict)
    splits: dict[str, float] = field(default_factory=lambda: dict(DEFAULT_SPLITS))
    camera: str = "per_sample"

    @property
    def folder(self) -> Path:
        return self.path.parent

    @property
    def fused(self) -> bool:
        """Whether every sample carries ``gamma_hdr`` (both fusion stages are stored)."""
        return self.base.fusion.mu1 in self.stages and self.base.fusion.mu2 in self.stages

    def identity(self) -> str:
        """SHA-256 of what fixes the dataset's content: the spec as parsed, the resolved base
        bench and the image files' contents (a resumed run must match it)."""
        blob = {"spec": self.raw, "base_config_sha256": config_sha256(self.base), "images": self.images}
        return hashlib.sha256(json.dumps(blob, sort_keys=True, default=str).encode()).hexdigest()

    def draw(self, index: int) -> dict[str, Any]:
        """The randomised values of sample ``index`` (as the manifest lists them: image paths
        relative to the spec folder)."""
        rng = np.random.default_rng(sample_streams(self.seed, index)[0])
        return {key: dist.draw(rng) for key, dist in self.randomize.items()}

    def overrides(self, values: Mapping[str, Any]) -> dict[str, Any]:
        """Nested config overrides of drawn ``values`` (``target.image`` resolved against the
        spec folder, as a config file resolves it against itself)."""
        resolved = dict(values)
        if isinstance(resolved.get("target.image"), str):
            resolved["target.image"] = str((self.folder / resolved["target.image"]).resolve())
        return nested(resolved)

    def sample_config(self, values: Mapping[str, Any], index: int | None = None) -> BenchConfig:
        """The bench of a sample with the randomised ``values`` (one-line error if invalid)."""
        where = f"{self.path}: sample {index}" if index is not None else f"{self.path} [randomize]"
        return with_overrides(self.base, self.overrides(values), source=where)


def _resolve_glob(path: Path, key: str, dist: Glob) -> Glob:
    pattern = Path(dist.pattern)
    full = str(pattern if pattern.is_absolute() else path.parent / pattern)
    where = f"{path}: randomize.{key}.pattern = {dist.pattern!r}"
    hits = sorted(p for p in bounded_glob(full, where) if Path(p).is_file())  # a bounded walk
    if not hits:
        raise BenchSimError(f"{where}: matches no file (relative to {path.parent})")
    rel = tuple(h if pattern.is_absolute() else os.path.relpath(h, path.parent) for h in hits)
    return dist.model_copy(update={"files": rel})


def _parse_distributions(path: Path, table: Mapping[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, entry in sorted(_flatten(table).items()):
        if key in SHAPE_KEYS:
            raise BenchSimError(
                f"{path}: randomize.{key}: fixes the arrays' shape or the fused stages; set it with "
                "lines / columns / stages / [config] instead"
            )
        if not isinstance(entry, dict) or "dist" not in entry:
            raise BenchSimError(
                f"{path}: randomize.{key} = {entry!r}: expected a table with dist = "
                f"{' | '.join(DISTRIBUTIONS)}"
            )
        model = _DIST_MODELS.get(entry["dist"])
        if model is None:
            raise BenchSimError(
                f"{path}: randomize.{key}.dist = {entry['dist']!r}: allowed {', '.join(DISTRIBUTIONS)}"
            )
        if entry["dist"] == "glob" and key != "target.image":
            raise BenchSimError(f"{path}: randomize.{key}: dist = 'glob' is for target.image only")
        if "files" in entry and entry["dist"] == "glob":
            raise BenchSimError(f"{path}: unknown key 'randomize.{key}.files'")
        allowed = ", ".join(f for f in model.model_fields if f != "files")
        dist = validate_model(model, entry, str(path), f"randomize.{key}", f"allowed: {allowed}")
        if isinstance(dist, Glob):
            dist = _resolve_glob(path, key, dist)
        out[key] = dist
    return out


def _check_keys_and_extremes(spec: DatasetSpec, fixed_keys: Iterable[str]) -> None:
    """Each randomised key exists in the config model and each distribution's extreme values
    are allowed (the other keys at their first extreme)."""
    fixed = set(fixed_keys)
    for key in spec.randomize:
        clash = next((f for f in fixed if f == key or f.startswith(key + ".") or key.startswith(f + ".")),
                     None)
        if clash is not None:
            raise BenchSimError(
                f"{spec.path}: randomize.{key}: also fixed in [config] as {clash} (set it once)"
            )
    reps = {k: d.probes()[0] for k, d in spec.randomize.items()}
    for key, dist in spec.randomize.items():
        for value in dist.probes():
            spec.sample_config({**reps, key: value})


def load_spec(path: str | Path) -> DatasetSpec:
    """Load and check a dataset spec (see the module docstring); one-line :class:`BenchSimError`
    naming the file, the key, the value and what is allowed."""
    path = Path(path).expanduser().resolve()
    raw = read_toml(path, f"dataset spec {str(path)!r}", "a dataset spec")
    top = validate_model(_SpecFile, raw, str(path), unknown=f"allowed: {', '.join(_SpecFile.model_fields)}")
    base_path = DEFAULT_CONFIG_PATH if top.base is None else (path.parent / top.base).resolve()
    if top.base is not None and not base_path.is_file():
        raise BenchSimError(f"{path}: base = {top.base!r}: no such config file ({base_path})")
    base = load_config(base_path)
    fixed = nested(_flatten(top.config))
    image = fixed.get("target", {}).get("image") if isinstance(fixed.get("target"), dict) else None
    if isinstance(image, str) and image and not Path(image).is_absolute():
        fixed["target"]["image"] = str((path.parent / image).resolve())  # relative to the spec
    size: dict[str, Any] = {}
    if top.lines is not None:
        size["lines"] = top.lines
    if top.columns is not None:
        size["sensor"] = {"columns": top.columns}
    base = with_overrides(base, fixed, source=f"{path} [config]")
    base = with_overrides(base, size, source=f"{path} (lines, columns)")
    try:
        stages = check_stages(top.stages, base.sensor.rows, "stages")
    except BenchSimError as exc:
        raise BenchSimError(f"{path}: {exc}") from None
    randomize = _parse_distributions(path, top.randomize)
    images: dict[str, str] = {}
    for dist in randomize.values():
        if isinstance(dist, Glob):
            for f in dist.files:
                images[f] = sha256_file(path.parent / f)
    spec = DatasetSpec(
        path=path, name=top.name or path.stem, description=top.description, samples=top.samples,
        seed=top.seed, stages=stages, base=base, randomize=randomize, raw=raw, images=images,
        splits=DEFAULT_SPLITS if top.splits is None else check_splits(top.splits, f"{path}: splits"),
        camera=top.camera,
    )
    _check_keys_and_extremes(spec, _flatten(top.config))
    check_camera(spec.camera, spec.randomize, str(path))
    return spec


def check_sample_configs(
    spec: DatasetSpec, values: Mapping[int, Mapping[str, Any]]
) -> dict[int, BenchConfig]:
    """Validate the benches of samples drawn as ``values`` (index -> :meth:`DatasetSpec.draw`):
    index -> config; every target image a sample reads is checked once (one-line errors naming
    the sample or the file)."""
    out: dict[int, BenchConfig] = {}
    seen: set[Any] = set()
    for i, vals in values.items():
        cfg = spec.sample_config(vals, index=i)
        t = cfg.target
        if t.layout == "image" and (t.image, t.image_encoding, t.image_channel, t.image_fit) not in seen:
            seen.add((t.image, t.image_encoding, t.image_channel, t.image_fit))
            check_inputs(cfg)
        out[i] = cfg
    return out
