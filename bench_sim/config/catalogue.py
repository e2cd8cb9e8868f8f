"""Every key of a bench config, read off the schema: type, unit, default, allowed range,
typical range and description (``bench-sim config keys``; the config reference in ``docs/``).

Nothing here is written by hand per key: the list walks the pydantic models of
:class:`~bench_sim.config.bench.BenchConfig` (the bounds of ``Field(ge=..., le=...)``, the
choices of a ``Literal``, the field's ``description``), takes the unit from the key's name
(``_m``, ``_s``, ``_w_m2``, ...) and the typical range from
:data:`bench_sim.config.plausible.TYPICAL`, so it cannot go stale.
"""

from __future__ import annotations

import re
import types
import typing
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, Literal

import annotated_types
from pydantic import BaseModel
from pydantic_core import PydanticUndefined

from bench_sim.config.bench import BenchConfig
from bench_sim.config.lighting import BUILTIN_LIGHT_SPECTRA, LightConfig
from bench_sim.config.plausible import Typical, typical_for
from bench_sim.io.spectral_data import CSV_PREFIX, spectrum_names

__all__ = [
    "KeyInfo", "UNIT_SUFFIXES", "SPECTRUM_KEYS", "unit_of", "config_keys", "config_sections", "model_keys",
]

#: Units carried by key names (longest suffix first).
UNIT_SUFFIXES: tuple[tuple[str, str], ...] = (
    ("_dn_per_e", "DN/e-"),
    ("_w_m2", "W/m^2"),
    ("_e_s", "e-/s"),
    ("_bits", "bit"),
    ("_deg", "deg"),
    ("_rad", "rad"),
    ("_hz", "Hz"),
    ("_px", "object px"),
    ("_dn", "DN"),
    ("_m", "m"),
    ("_s", "s"),
    ("_e", "e-"),
    ("_k", "K"),
)


#: the keys that take a measured spectrum by name, and its kind (:mod:`bench_sim.io.spectral_data`);
#: every light's ``spectrum`` is listed with the names once, at ``lights.strong.spectrum``
SPECTRUM_KEYS = {"lights.strong.spectrum": "light", "target.reflectance_spectrum": "reflectance",
                 "sensor.qe_spectrum": "qe"}


def _spectrum_allowed(key: str) -> str:
    """``allowed`` of a key that names a spectrum: the built-in ones, ``csv:FILE`` and the names
    (those of a light other than ``strong`` by reference)."""
    builtin = ", ".join(BUILTIN_LIGHT_SPECTRA) + ", " if key.startswith("lights.") else ""
    kind = SPECTRUM_KEYS.get(key)
    if kind is None:
        return f"{builtin}{CSV_PREFIX}FILE or a name of lights.strong.spectrum"
    names = spectrum_names(kind)
    return f"{builtin}{CSV_PREFIX}FILE or one of the {len(names)} names: " + "; ".join(names)


@dataclass(frozen=True)
class KeyInfo:
    """One config key: dotted ``key``, ``type``, ``unit`` (``""``: none), ``default`` (as TOML
    text; ``(unset)`` for an optional key without one), ``allowed`` (the schema's bounds or
    choices), ``typical`` (the plausibility range; ``""``: none) and ``description``."""

    key: str
    type: str
    unit: str
    default: str
    allowed: str
    typical: str
    description: str


def unit_of(name: str) -> str:
    """The unit a key's name carries (``line_period_s`` -> ``s``), ``""`` if none."""
    for suffix, unit in UNIT_SUFFIXES:
        if name.endswith(suffix):
            return unit
    return ""


def _type_name(ann: Any) -> str:
    origin, args = typing.get_origin(ann), typing.get_args(ann)
    if origin is typing.Annotated:
        return _type_name(args[0])
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in args)
    if origin in (typing.Union, types.UnionType):
        names = [_type_name(a) for a in args if a is not type(None)]
        return " | ".join(names) + (" (optional)" if type(None) in args else "")
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"list of {_type_name(args[0])}"
        return "[" + ", ".join(_type_name(a) for a in args) + "]"
    return getattr(ann, "__name__", str(ann))


def _bounds(field_metadata: list[Any], ann: Any) -> list[Any]:
    """The annotated-types constraints of a field, wherever they sit (``X | None`` too)."""
    found = list(field_metadata)
    for arg in typing.get_args(ann):
        if typing.get_origin(arg) is typing.Annotated:
            for meta in typing.get_args(arg)[1:]:
                found.extend(getattr(meta, "metadata", [meta]))
        elif typing.get_origin(arg) is not None:
            found.extend(_bounds([], arg))
    return found


def _allowed(metadata: list[Any], ann: Any) -> str:
    ops = (
        (annotated_types.Ge, ">=", "ge"), (annotated_types.Gt, ">", "gt"),
        (annotated_types.Le, "<=", "le"), (annotated_types.Lt, "<", "lt"),
    )
    parts = []
    for meta in _bounds(metadata, ann):
        for cls, op, attr in ops:
            if isinstance(meta, cls):
                parts.append(f"{op} {getattr(meta, attr):g}")
    return ", ".join(dict.fromkeys(parts))


def _toml(value: Any) -> str:
    if value is None or value is PydanticUndefined:
        return "(unset)" if value is None else "(required)"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, tuple | list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def _model_of(ann: Any) -> type[BaseModel] | None:
    if isinstance(ann, type) and issubclass(ann, BaseModel):
        return ann
    return None


def model_keys(
    model: type[BaseModel], prefix: str, typical: Callable[[str], Typical | None] | None = None
) -> Iterator[KeyInfo]:
    """The keys of ``model`` (and of the tables it nests) as :class:`KeyInfo`, each named
    ``prefix + name``; ``typical`` gives a key's typical range (default: the config's,
    :func:`bench_sim.config.plausible.typical_for`)."""
    return _walk(model, prefix, typical)


def _walk(
    model: type[BaseModel], prefix: str, typical: Callable[[str], Typical | None] | None = None
) -> Iterator[KeyInfo]:
    for name, field in model.model_fields.items():
        key = f"{prefix}{name}"
        sub = _model_of(field.annotation)
        if sub is not None:
            yield from _walk(sub, key + ".", typical)
            if sub.model_config.get("extra") == "allow":  # the lights: any other name, any kind
                for kind_model in typing.get_args(LightConfig):
                    kind = kind_model.model_fields["kind"].default
                    yield from _walk(kind_model, f"{key}.<name>[kind={kind}].")
            continue
        typ = (typical or typical_for)(re.sub(r"\[kind=\w+\]", "", key))
        spectral = key in SPECTRUM_KEYS or (key.startswith("lights.") and name == "spectrum")
        yield KeyInfo(
            key=key,
            type=_type_name(field.annotation),
            unit=unit_of(name),
            default=_toml(field.get_default(call_default_factory=True)),
            allowed=_spectrum_allowed(key) if spectral else _allowed(field.metadata, field.annotation),
            typical=typ.describe() if typ is not None else "",
            description=" ".join((field.description or "").split()),
        )


def config_keys(section: str | None = None) -> list[KeyInfo]:
    """Every key of a bench config (``section``: only the keys under it, e.g. ``sensor`` or
    ``lights.strong``), in the schema's order; a light of another name is listed once per kind
    as ``lights.<name>[kind=KIND].KEY``."""
    keys = list(_walk(BenchConfig, ""))
    if section:
        keys = [k for k in keys if k.key == section or k.key.startswith(section.rstrip(".") + ".")]
    return keys


def config_sections() -> list[str]:
    """The names ``config keys`` takes as a section: the tables of the config."""
    return sorted({k.key.rsplit(".", 1)[0] for k in _walk(BenchConfig, "") if "." in k.key})
