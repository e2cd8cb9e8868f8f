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
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import Field

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
from bench_sim.workflows.dataset.distributions import DIST_MODELS, DISTRIBUTIONS, Distribution, Glob, Strict
from bench_sim.workflows.dataset.sample_scene import SceneValue, draw_scene, parse_scene, place_window
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

#: Config keys that fix the arrays' shape or the fused pair: set by the spec, never randomised.
SHAPE_KEYS = ("lines", "sensor.columns", "sensor.rows", "fusion.mu1", "fusion.mu2")

#: Samples above which a spec is refused (the plan draws every sample's values up front)
MAX_SAMPLES = 100_000

class _SpecFile(Strict):
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
    scene: dict[str, Any] = {}  # bench_sim.workflows.dataset.sample_scene


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
    scene: dict[str, SceneValue] = field(default_factory=dict)

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

    @property
    def word_bits(self) -> int:
        """The widest output word of any sample [bits] (``dtdi.beta_bits``, or the largest value a
        ``[randomize]`` entry of it can take): the stored words' dtype holds it."""
        dist = self.randomize.get("dtdi.beta_bits")
        drawn = [int(v) for v in dist.probes()] if dist is not None else []
        return max([int(self.base.dtdi.beta_bits), *drawn])

    def draw(self, index: int) -> dict[str, Any]:
        """The randomised values of sample ``index`` (as the manifest lists them: image paths
        relative to the spec folder), then its ``[scene]`` values as ``scene.<key>``
        (:mod:`bench_sim.workflows.dataset.sample_scene`), from one generator in that order."""
        rng = np.random.default_rng(sample_streams(self.seed, index)[0])
        values = {key: dist.draw(rng) for key, dist in self.randomize.items()}
        if self.scene:
            rig = any(s.how == "rig" for s in self.scene.values())
            cfg = self.sample_config(values, index) if rig else self.base
            values.update({f"scene.{k}": v for k, v in draw_scene(self.scene, rng, index, cfg).items()})
        return values

    def overrides(self, values: Mapping[str, Any]) -> dict[str, Any]:
        """Nested config overrides of drawn ``values`` (``target.image`` resolved against the
        spec folder, as a config file resolves it against itself; the ``scene.*`` values are not
        config keys: :meth:`sample_config` applies them)."""
        resolved = {k: v for k, v in values.items() if not k.startswith("scene.")}
        if isinstance(resolved.get("target.image"), str):
            resolved["target.image"] = str((self.folder / resolved["target.image"]).resolve())
        return nested(resolved)

    def sample_config(self, values: Mapping[str, Any], index: int | None = None) -> BenchConfig:
        """The bench of a sample with the randomised ``values`` (one-line error if invalid)."""
        where = f"{self.path}: sample {index}" if index is not None else f"{self.path} [randomize]"
        cfg = with_overrides(self.base, self.overrides(values), source=where)
        return place_window(cfg, float(values.get("scene.window_across_mm", 0.0)),
                            float(values.get("scene.window_along_mm", 0.0)))


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
        model = DIST_MODELS.get(entry["dist"])
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
        camera=top.camera, scene=parse_scene(path, top.scene),
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
