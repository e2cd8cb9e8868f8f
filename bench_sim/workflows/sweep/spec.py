"""Sweep specifications: what ``bench-sim sweep SPEC.toml`` varies, checked before anything runs.

A spec is a TOML file::

    name = "light_ratio_beta"            # default: the file's stem
    base = "../paper_rig.toml"           # bench config, relative to the spec (default: the paper rig)
    quick = true                         # apply reproduce's --quick preset to the base (default false)
    seed = 0                             # root seed of the whole sweep
    mode = "product"                     # "product" | "sequential" | "custom"
    noise = "independent"                # "independent" | "common"

    [overrides]                          # keys set on the base for every point (optional)
    render = { spp = 8 }

    [[parameters]]
    key = "lights.strong.irradiance_w_m2"   # dotted key into the bench config
    logspace = { start = 6.0, stop = 60000.0, num = 5 }

    [[parameters]]
    key = "dtdi.beta_bits"
    values = [12, 16]

Values of a parameter: ``values`` (a list; a value may itself be a list, e.g. a position),
``range = { start, stop, step }`` (``stop`` included when the steps land on it),
``linspace = { start, stop, num }`` or ``logspace = { start, stop, num }`` (geometric, from
``start`` to ``stop``; both > 0).

Modes
-----
``product``
    Every combination: the point count is the product of the value counts; the first
    parameter varies slowest.
``sequential``
    One parameter at a time, the others at the base's values (one-factor-at-a-time): the point
    count is the sum of the value counts.
``custom``
    The points of a CSV file (``points = "file.csv"``, relative to the spec): the header names
    the dotted keys, each row is a point; cells are parsed as TOML values (``12``, ``1.5e3``,
    ``true``, ``"glossy"``, ``[0.0, 0.1, 0.45]``), bare words as strings.

Streams
-------
``seed`` is the sweep's root: point ``i`` draws from
``numpy.random.SeedSequence(seed).spawn(n)[i]``
(:func:`bench_sim.runtime.execution.task_seed_sequence`), so its result never depends on
the number of workers or on the order of completion. ``noise = "common"`` gives every point the
stream of point 0 (paired comparisons: the differences between points are then not noise).
"""

from __future__ import annotations

import csv
import itertools
import json
import math
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, BeforeValidator, ConfigDict, model_validator

from bench_sim.config import (
    BenchConfig,
    ConfigError,
    EffectEntry,
    config_from_dict,
    config_to_toml_dict,
    load_config,
    quick_config,
    read_toml,
    validate_model,
    with_overrides,
)
from bench_sim.errors import BenchSimError
from bench_sim.io.input_files import input_file_problem
from bench_sim.sensor.effects.chain import effect_kinds
from bench_sim.workflows.preflight import SEED_RULE, is_seed
from bench_sim.workflows.spec_grid import grid_as_dict
from bench_sim.workflows.sweep.light_keys import LIGHTING_KEYS, adds_light, check_banding_stages, check_ratio

__all__ = [
    "MODES",
    "NOISE",
    "SPEC_KEYS",
    "SweepSpec",
    "SweepPoint",
    "load_spec",
    "parameter_values",
    "key_exists",
    "set_key",
    "point_combinations",
    "point_config",
]

MODES = ("product", "sequential", "custom")
NOISE = ("independent", "common")
VALUE_FORMS = ("values", "range", "linspace", "logspace")
#: The keys a spec may hold, and what each is.
SPEC_KEYS: dict[str, str] = {
    "name": "name of the sweep (default: the spec file's stem)",
    "description": "free text, copied into sweep.json and report.md",
    "base": "bench config file, relative to the spec (default: the paper rig)",
    "quick": "true: apply reproduce's --quick preset to the base",
    "seed": f"root seed ({SEED_RULE})",
    "mode": "product | sequential | custom",
    "noise": "independent | common",
    "overrides": "table of config keys set on the base for every point",
    "parameters": "[[parameters]] tables: key and one of values, range, linspace, logspace",
    "points": "custom mode: CSV file of points, relative to the spec",
    **LIGHTING_KEYS,
}
#: Points above which a spec is refused (a typo in a range, not a study).
MAX_POINTS = 100_000
_NEED_POINTS = 'custom mode needs points = "FILE.csv" (relative to the spec)'


def _check(ok: Callable[[Any], bool], need: str) -> BeforeValidator:
    """A check of a spec value as it is in the file: ``ok(value)`` or ``ValueError(need)``."""

    def check(value: Any) -> Any:
        if not ok(value):
            raise ValueError(need)
        return value

    return BeforeValidator(check)


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_name(v: Any) -> bool:
    return isinstance(v, str) and v != ""


def _is_tables(v: Any) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(p, dict) for p in v)


class _SpecFile(BaseModel):
    """The top level of a sweep spec (:data:`SPEC_KEYS`; unknown keys refused), each value
    checked as it is in the file (no conversions)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: Annotated[str | None, _check(_is_name, "needs a non-empty string")] = None
    description: Annotated[str, _check(lambda v: isinstance(v, str), "needs a string")] = ""
    base: Annotated[str | None, _check(lambda v: isinstance(v, str), "needs a config file name")] = None
    quick: Annotated[bool, _check(lambda v: isinstance(v, bool), "needs true or false")] = False
    seed: Annotated[int, _check(is_seed, f"needs {SEED_RULE}")] = 0
    mode: Annotated[str, _check(lambda v: v in MODES, f"allowed {', '.join(MODES)}")] = "product"
    noise: Annotated[str, _check(lambda v: v in NOISE, f"allowed {', '.join(NOISE)}")] = "independent"
    overrides: Annotated[
        dict[str, Any], _check(lambda v: isinstance(v, dict), "needs a table ([overrides])")
    ] = {}
    parameters: Annotated[
        list[dict[str, Any]] | None, _check(_is_tables, "needs [[parameters]] tables (key and values)")
    ] = None
    stages: Any = None  # bench_sim.workflows.sweep.light_keys
    ratio: Any = None
    keep_images: Annotated[bool, _check(lambda v: isinstance(v, bool), "needs true or false")] = False
    points: Annotated[
        str | None,
        _check(lambda v: isinstance(v, str), _NEED_POINTS),
    ] = None

    @model_validator(mode="after")
    def _parts_of_the_mode(self) -> _SpecFile:
        if self.mode == "custom":
            if self.parameters is not None:
                raise ValueError("mode = 'custom' takes its keys from the points file: remove [[parameters]]")
            if self.points is None:
                raise ValueError(f"points = None: {_NEED_POINTS}")
        elif self.points is not None:
            raise ValueError(f"points = {self.points!r}: only for mode = 'custom'")
        elif self.parameters is None:
            raise ValueError("needs [[parameters]] tables (key and values)")
        return self


@dataclass(frozen=True)
class SweepPoint:
    """One point: its index, the values of the swept keys and its validated bench config."""

    index: int
    values: dict[str, Any]
    cfg: BenchConfig
    varied: str | None = None  # sequential mode: the key this point varies


@dataclass(frozen=True)
class SweepSpec:
    """A checked spec: every point's config is valid (see :func:`load_spec`)."""

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
    raw: dict[str, Any] = field(repr=False)
    stages: tuple[int, ...] = ()  # banding stages (bench_sim.workflows.sweep.light_keys)
    ratio: tuple[str, str] | None = None
    keep_images: bool = False  # bench_sim.workflows.sweep.point_images

    @property
    def shape(self) -> tuple[int, ...]:
        """Product mode: the number of values per key (the grid of ``sweep.nc``)."""
        return tuple(len(self.values[k]) for k in self.keys)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready description (``sweep.json``'s ``spec``)."""
        return {**grid_as_dict(self), "raw": self.raw}


def _err(spec: Path, msg: str) -> BenchSimError:
    return BenchSimError(f"sweep spec {spec}: {msg}")


def key_exists(cfg: BenchConfig, key: str) -> bool:
    """True when the dotted ``key`` names a setting of ``cfg`` (a field of a section, of a light
    defined in it, or a top-level field; a parameter of an effect of ``sensor.effects``, set in
    ``cfg`` or left at its default, e.g. ``sensor.effects.knee.compression``)."""
    cur: Any = cfg
    for part in key.split("."):
        if isinstance(cur, Mapping):  # a table of named entries (sensor.effects, a plug-in's args)
            if part not in cur:
                return False
            cur = cur[part]
            continue
        if not isinstance(cur, BaseModel):
            return False
        extra = cur.__pydantic_extra__ or {}
        if part in type(cur).model_fields or part in extra:
            cur = getattr(cur, part)
        elif isinstance(cur, EffectEntry) and cur.kind in effect_kinds():
            if part not in effect_kinds()[cur.kind].Params.model_fields:
                return False
            cur = None  # the effect's parameter at its default: nothing below it
        else:
            return False
    return True


def set_key(data: dict[str, Any], key: str, value: Any) -> dict[str, Any]:
    """A nested dict that sets the dotted ``key`` to ``value`` on top of ``data`` (a copy)."""
    out = json.loads(json.dumps(data))
    cur = out
    parts = key.split(".")
    for part in parts[:-1]:
        cur = cur.setdefault(part, {})
    cur[parts[-1]] = value
    return out


def _number(spec: Path, key: str, form: str, table: dict[str, Any], name: str) -> float:
    v = table.get(name)
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise _err(spec, f"parameter {key}: {form}.{name} = {v!r}: needs a finite number")
    return v


def _axis_size(spec: Path, key: str, table: dict[str, Any]) -> int:
    """How many values one ``[[parameters]]`` table gives, from its numbers alone (no list is
    built: a ``num`` of 10**9 costs nothing); the table's form and numbers are checked."""
    forms = [f for f in VALUE_FORMS if f in table]
    if len(forms) != 1:
        raise _err(
            spec, f"parameter {key}: give exactly one of {', '.join(VALUE_FORMS)} (found {forms or 'none'})"
        )
    form = forms[0]
    spec_v = table[form]
    if form == "values":
        if not isinstance(spec_v, list) or not spec_v:
            raise _err(spec, f"parameter {key}: values = {spec_v!r}: needs a non-empty list")
        return len(spec_v)
    if not isinstance(spec_v, dict):
        raise _err(
            spec, f"parameter {key}: {form} = {spec_v!r}: needs a table like {{ start = .., stop = .. }}"
        )
    need = ("start", "stop", "step") if form == "range" else ("start", "stop", "num")
    unknown = sorted(set(spec_v) - set(need))
    if unknown:
        raise _err(spec, f"parameter {key}: {form}.{unknown[0]}: unknown (allowed: {', '.join(need)})")
    start, stop = (_number(spec, key, form, spec_v, n) for n in need[:2])
    if form == "range":
        step = _number(spec, key, form, spec_v, "step")
        if step == 0 or (stop - start) / step < 0:
            raise _err(spec, f"parameter {key}: range step = {step!r} never goes from {start!r} to {stop!r}")
        steps = math.floor((stop - start) / step + 1e-9)
        return int(steps) + 1 if math.isfinite(steps) else MAX_POINTS + 1
    num = spec_v.get("num")
    if isinstance(num, bool) or not isinstance(num, int) or num < 1:
        raise _err(spec, f"parameter {key}: {form}.num = {num!r}: needs an integer >= 1")
    return num


def parameter_values(spec: Path, key: str, table: dict[str, Any], limit: int = MAX_POINTS) -> list[Any]:
    """The values of one ``[[parameters]]`` table (see the module docstring); more than
    ``limit`` of them are refused before any is made."""
    n = _axis_size(spec, key, table)  # checks the form and its numbers
    form = next(f for f in VALUE_FORMS if f in table)
    spec_v = table[form]
    if n > limit:
        raise _err(spec, f"parameter {key}: {form} gives {n} values: more than {MAX_POINTS} points; "
                   "split the sweep")
    if form == "values":
        return list(spec_v)
    start, stop = spec_v["start"], spec_v["stop"]
    if form == "range":
        step = spec_v["step"]
        vals = [start + i * step for i in range(n)]
        if all(isinstance(x, int) for x in (start, stop, step)):
            return [int(v) for v in vals]
        return [float(v) for v in vals]
    if form == "linspace":
        return [float(v) for v in np.linspace(start, stop, n)]
    if start <= 0 or stop <= 0:
        raise _err(spec, f"parameter {key}: logspace from {start!r} to {stop!r}: both must be > 0")
    return [float(v) for v in np.geomspace(start, stop, n)]


def _cell(text: str) -> Any:
    """A CSV cell as a TOML value (bare words as strings)."""
    text = text.strip()
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def _custom_points(spec: Path, table: str) -> tuple[tuple[str, ...], list[dict[str, Any]]]:
    path = (spec.parent / table).resolve()
    problem = input_file_problem(path)  # missing, a folder, a FIFO or device (never opened)
    if problem is not None:
        raise _err(spec, f"points = {table!r}: {path}: {problem}")
    try:
        with path.open(newline="", encoding="utf-8") as fh:  # counted before the rows are kept
            count = sum(1 for r in csv.reader(fh) if r and not r[0].lstrip().startswith("#")) - 1
        if count > MAX_POINTS:
            raise _err(spec, f"points = {table!r}: {count} points: more than {MAX_POINTS}; split the sweep")
        with path.open(newline="", encoding="utf-8") as fh:
            rows = [r for r in csv.reader(fh) if r and not r[0].lstrip().startswith("#")]
    except UnicodeDecodeError as exc:
        raise _err(spec, f"points = {table!r}: not UTF-8 text (offset {exc.start})") from None
    except (OSError, csv.Error) as exc:
        raise _err(spec, f"points = {table!r}: cannot read it ({exc})") from None
    if len(rows) < 2:
        raise _err(spec, f"points = {table!r}: needs a header of dotted keys and at least one row")
    keys = tuple(h.strip() for h in rows[0])
    for n, row in enumerate(rows[1:], start=2):
        if len(row) != len(keys):
            raise _err(spec, f"points = {table!r}: row {n} has {len(row)} cells for {len(keys)} keys")
    return keys, [dict(zip(keys, (_cell(c) for c in row), strict=True)) for row in rows[1:]]


def _validated(spec: Path, base: dict[str, Any], values: dict[str, Any], index: int) -> BenchConfig:
    data = base
    for key, value in values.items():
        data = set_key(data, key, value)
    where = f"{spec} point {index} ({', '.join(f'{k} = {v!r}' for k, v in values.items())})"
    try:
        return config_from_dict(data, source=where)
    except ConfigError as exc:
        raise ConfigError(str(exc).replace("config error: ", "sweep spec ", 1)) from None


def _base_config(spec: Path, top: _SpecFile) -> BenchConfig:
    """The spec's base bench: its config file, the quick preset, then ``[overrides]``."""
    base_cfg = load_config((spec.parent / top.base).resolve() if top.base else None)
    if top.quick:
        base_cfg = quick_config(base_cfg)
    if top.overrides:
        base_cfg = with_overrides(base_cfg, top.overrides, source=f"{spec} [overrides]")
    return base_cfg


def _parameters(spec: Path, tables: list[dict[str, Any]], mode: str) -> dict[str, list[Any]]:
    """Key -> values of the ``[[parameters]]`` tables, in their order. The point count of the
    mode is computed from the axis sizes first (O(axes)) and refused above :data:`MAX_POINTS`
    before any list is made."""
    sizes: dict[str, int] = {}
    for p in tables:
        key = p.get("key")
        if not isinstance(key, str) or not key:
            raise _err(spec, f"[[parameters]] {p!r}: needs key = \"section.setting\"")
        extra = sorted(set(p) - {"key", *VALUE_FORMS})
        if extra:
            allowed = ", ".join(("key", *VALUE_FORMS))
            raise _err(spec, f"parameter {key}: unknown '{extra[0]}' (allowed: {allowed})")
        if key in sizes:
            raise _err(spec, f"parameter {key}: given twice")
        sizes[key] = _axis_size(spec, key, p)
    count = math.prod(sizes.values()) if mode == "product" else sum(sizes.values())
    if count > MAX_POINTS:
        shape = (" x " if mode == "product" else " + ").join(str(n) for n in sizes.values())
        raise _err(spec, f"{count} points ({mode}: {shape}): more than {MAX_POINTS}; split the sweep")
    return {str(p["key"]): parameter_values(spec, str(p["key"]), p) for p in tables}


Combos = list[tuple[dict[str, Any], str | None]]


def point_combinations(
    spec: Path, mode: str, parameters: list[dict[str, Any]] | None, points: str | None
) -> tuple[tuple[str, ...], dict[str, list[Any]], Combos]:
    """The swept keys, their values and the points as ``(values, varied key)`` of a mode
    (:data:`MODES`): the ``[[parameters]]`` tables, or the CSV file ``points`` (custom mode).
    Also used by ``bench-sim design`` for its non-stage keys."""
    if mode == "custom":
        assert points is not None  # checked by the spec's model
        keys, rows = _custom_points(spec, points)
        return keys, {k: [row[k] for row in rows] for k in keys}, [(row, None) for row in rows]
    assert parameters is not None  # checked by the spec's model
    values = _parameters(spec, parameters, mode)
    keys = tuple(values)
    if mode == "product":
        grid = itertools.product(*values.values())
        combos: Combos = [(dict(zip(keys, c, strict=True)), None) for c in grid]
    else:
        combos = [({k: v}, k) for k in keys for v in values[k]]
    return keys, values, combos


def point_config(spec: Path, base: dict[str, Any], values: dict[str, Any], index: int) -> BenchConfig:
    """The validated bench config of point ``index``: ``values`` (dotted keys) set on ``base``
    (a config's TOML dict); a bad value is one line naming the spec, the point and its values."""
    return _validated(spec, base, values, index)


def load_spec(path: str | Path) -> SweepSpec:
    """Read and check a sweep spec: every key, every value and every point's config.

    Raises :class:`~bench_sim.errors.BenchSimError` (one line naming the spec, the key or point
    and what is allowed) on the first problem, before anything runs.
    """
    spec = Path(path).expanduser().resolve()
    label = f"sweep spec {spec}"
    raw = read_toml(spec, label, "a sweep spec")
    top = validate_model(_SpecFile, raw, label, unknown=f"allowed: {', '.join(SPEC_KEYS)}")
    base_cfg = _base_config(spec, top)
    keys, values, combos = point_combinations(spec, top.mode, top.parameters, top.points)
    for k in keys:
        if not key_exists(base_cfg, k) and not adds_light(base_cfg, k):
            raise _err(spec, f"key {k!r}: not a setting of the bench config (check the section and name)")
    if not combos:
        raise _err(spec, "no points")
    base = config_to_toml_dict(base_cfg)
    points = tuple(
        SweepPoint(i, vals, _validated(spec, base, vals, i), varied)
        for i, (vals, varied) in enumerate(combos)
    )
    return SweepSpec(
        spec, top.name or spec.stem, top.description, top.mode, top.noise, top.seed, top.quick, base_cfg,
        keys, values, points, raw, check_banding_stages(spec, top.stages, [p.cfg for p in points]),
        check_ratio(spec, top.ratio, [p.cfg for p in points]), top.keep_images,
    )
