"""The sensor's chain of effects: built from ``[sensor.effects.<name>]``, checked before anything
runs, drawn once per physical sensor, and composed into the law of each read.

:func:`sensor_chain` builds the chain of a :class:`~bench_sim.config.SensorConfig` (cached per
sensor): each entry's ``kind`` names an effect, a module ``bench_sim.sensor.effects.<kind>``
holding ``EFFECT`` (its class, :class:`~bench_sim.sensor.effects.base.Effect`); its parameters
are checked against the effect's ``Params`` and ``TYPICAL`` ranges, and a problem is one line
naming ``sensor.effects.<name>.<key>`` (a :class:`~bench_sim.errors.BenchSimError`, exit 2).

Random streams: an effect's fixed pattern comes from child ``j`` (its place in the chain) of one
``SeedSequence`` drawn from the run's generator after the default fixed patterns (only when the
chain has effects, so the default chain's streams are unchanged); its temporal draws from child
``j`` of the chunk's own generator (:meth:`numpy.random.Generator.spawn`), so they depend on
neither threads nor workers.
"""

from __future__ import annotations

import functools
import importlib
import pkgutil
from collections.abc import Mapping
from dataclasses import dataclass
from difflib import get_close_matches
from typing import Any

import numpy as np
from pydantic import ValidationError

from bench_sim.config import SensorConfig
from bench_sim.config.loading import validation_line
from bench_sim.config.plausible import judge
from bench_sim.errors import BenchSimError
from bench_sim.sensor.effects.base import Effect, EmvaTerm, PixelMaps, ReadLaw, State

__all__ = ["SensorChain", "sensor_chain", "effect_kinds", "effect_class", "DEFAULT_CHAIN", "chain_attrs"]

#: The default chain, EMVA 1288's linear model, in signal order (:mod:`bench_sim.sensor.emva`)
DEFAULT_CHAIN = (
    "photons -> electrons: quantum efficiency x PRNU gain",
    "dark current and its non-uniformity (DSNU) [e-/s]",
    "shot noise of light and dark current (sensor.shot_noise_sampler)",
    "full-well clip",
    "read noise [e-]",
    "conversion gain K, black offset, column offsets [DN]",
    "ADC: rounding and clip to 0 .. 2**adc_bits - 1",
)

_PACKAGE = "bench_sim.sensor.effects"
#: modules of the package that are not effects
_NOT_EFFECTS = frozenset({"base", "chain", "effect_files"})


@functools.cache
def effect_kinds() -> dict[str, type[Effect]]:
    """Every built-in effect: kind -> class (each module of :mod:`bench_sim.sensor.effects`
    holding ``EFFECT``)."""
    package = importlib.import_module(_PACKAGE)
    kinds: dict[str, type[Effect]] = {}
    for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda i: i.name):
        if info.name in _NOT_EFFECTS or info.name.startswith("_"):
            continue
        cls = getattr(importlib.import_module(f"{_PACKAGE}.{info.name}"), "EFFECT", None)
        if isinstance(cls, type) and issubclass(cls, Effect):
            kinds[cls.kind] = cls
    return kinds


def effect_class(kind: str, where: str) -> type[Effect]:
    """The class of effect ``kind``; one line naming ``where`` if there is none."""
    kinds = effect_kinds()
    if kind not in kinds:
        near = get_close_matches(kind, kinds, n=1)
        hint = f"; did you mean {near[0]!r}?" if near else ""
        raise BenchSimError(f"{where}.kind = {kind!r}: no such effect (allowed: {', '.join(kinds)}){hint}")
    return kinds[kind]


def _params(cls: type[Effect], extra: Mapping[str, Any], where: str) -> Any:
    """The effect's parameters checked: unit slips first, then its ``Params`` model."""
    for key, typ in cls.TYPICAL.items():
        if key in extra:
            problem = judge(f"{where}.{key}", extra[key], typ)
            if problem:
                raise BenchSimError(f"config error: {problem}")
    try:
        return cls.Params.model_validate(dict(extra))
    except ValidationError as exc:
        line = validation_line(
            exc,
            dict(extra),
            where,
            f"not a key of {cls.kind}; bench-sim config keys sensor lists them",
            cls.Params,
        )
        raise BenchSimError(f"config error: {line}") from None


@dataclass(frozen=True)
class SensorChain:
    """The extra effects of a sensor, in the order they are written (each acts at its points of
    the signal path, :data:`~bench_sim.sensor.effects.base.POINTS`)."""

    effects: tuple[Effect, ...] = ()

    @property
    def temporal(self) -> bool:
        """Whether an effect acts on the reads themselves (the generic path draws them)."""
        return any(e.temporal for e in self.effects)

    def draw_fixed(self, maps: PixelMaps, rng: np.random.Generator) -> tuple[tuple[str, State], ...]:
        """Draw every effect's fixed pattern (streams: module docstring) and apply it to
        ``maps`` (in place); returns ``(name, state)`` per effect. Draws nothing from ``rng``
        when the chain is empty."""
        if not self.effects:
            return ()
        root = np.random.SeedSequence(rng.integers(0, 2**32, size=4, dtype=np.uint64).tolist())
        children = root.spawn(len(self.effects))
        shape = (int(maps.gain.shape[0]), int(maps.gain.shape[1]))
        states = []
        for eff, child in zip(self.effects, children, strict=True):
            state = eff.fixed(shape, np.random.default_rng(child))
            eff.maps(maps, state)
            states.append((eff.name, state))
        return tuple(states)

    def law(self, states: Mapping[str, State]) -> ReadLaw:
        """Each read's distribution under the chain (:class:`ReadLaw`)."""
        law = ReadLaw()
        for eff in self.effects:
            law = eff.law(law, states[eff.name])
        return law

    def emva(self, states: Mapping[str, State], t_int_s: float) -> list[EmvaTerm]:
        """Every effect's EMVA 1288 quantities in closed form."""
        return [term for eff in self.effects for term in eff.emva(states[eff.name], t_int_s)]

    def describe(self) -> list[str]:
        """The whole chain, one line per step: the default model, then each effect."""
        return [*DEFAULT_CHAIN, *(e.describe() for e in self.effects)]

    @property
    def not_exact(self) -> list[str]:
        """Why the truth is not exact: one line per effect that declares no truth (empty: exact)."""
        return [note for e in self.effects if (note := e.truth_note) is not None]

    def provenance(self) -> dict[str, Any]:
        """What every output says of the chain: ``sensor_chain`` (its steps), ``truth_exact``
        and, when it is not, ``truth_not_exact`` (why)."""
        meta: dict[str, Any] = {"sensor_chain": self.describe(), "truth_exact": not self.not_exact}
        if self.not_exact:
            meta["truth_not_exact"] = self.not_exact
        return meta

    def attrs(self) -> dict[str, Any]:
        """:meth:`provenance` as the attributes of a netCDF or Zarr store (:func:`chain_attrs`)."""
        return chain_attrs(self.provenance())


def chain_attrs(meta: Mapping[str, Any]) -> dict[str, Any]:
    """A chain's provenance (:meth:`SensorChain.provenance`) as the attributes of a netCDF or Zarr
    store: ``sensor_chain`` (one step per line), ``truth_exact`` (1 or 0) and, when it is 0,
    ``truth_not_exact`` (the reasons, ``; ``-separated)."""
    attrs: dict[str, Any] = {"sensor_chain": "\n".join(meta["sensor_chain"])}
    attrs["truth_exact"] = int(meta["truth_exact"])
    if meta.get("truth_not_exact"):
        attrs["truth_not_exact"] = "; ".join(meta["truth_not_exact"])
    return attrs


def _build(sensor: SensorConfig) -> SensorChain:
    effects = []
    for name, entry in sensor.effects.items():
        if not entry.enabled:
            continue
        where = f"sensor.effects.{name}"
        cls = effect_class(entry.kind, where)
        params = _params(cls, entry.model_extra or {}, where)
        eff = cls(name, params, sensor)
        check = getattr(eff, "check", None)
        if check is not None:
            check()
        effects.append(eff)
    return SensorChain(tuple(effects))


@functools.lru_cache(maxsize=64)
def _cached(text: str) -> SensorChain:
    return _build(SensorConfig.model_validate_json(text))


def sensor_chain(sensor: SensorConfig) -> SensorChain:
    """The chain of ``sensor`` (built and checked once per distinct sensor in a process)."""
    if not sensor.effects:
        return _EMPTY
    return _cached(sensor.model_dump_json())


_EMPTY = SensorChain()
