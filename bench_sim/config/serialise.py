"""A config as data: the resolved dict, its TOML text and its SHA-256 (what output files carry)."""

from __future__ import annotations

import json
import math
from typing import Any

from bench_sim.config.bench import BenchConfig
from bench_sim.io import sha256_text

__all__ = ["config_to_toml_dict", "config_to_toml_text", "config_sha256"]


def config_to_toml_dict(cfg: BenchConfig) -> dict[str, Any]:
    """The fully resolved config as a JSON/TOML-friendly dict (``None`` values dropped; a sensor
    without extra effects has no ``sensor.effects`` table)."""
    data = cfg.model_dump(mode="json", exclude_none=True)
    if not data["sensor"].get("effects"):
        data["sensor"].pop("effects", None)
    return data


def config_sha256(cfg: BenchConfig) -> str:
    """SHA-256 of the resolved config's canonical JSON."""
    return sha256_text(json.dumps(config_to_toml_dict(cfg), sort_keys=True))


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        if isinstance(value, float) and not math.isfinite(value):
            raise ValueError(f"cannot write {value!r} to TOML")
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)  # a TOML basic string (JSON escapes are TOML escapes)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"cannot write {type(value).__name__} to TOML")


def config_to_toml_text(cfg: BenchConfig) -> str:
    """The fully resolved config as TOML text (``tomllib.loads`` gives back
    :func:`config_to_toml_dict`; tuples come back as lists)."""

    def table(data: dict[str, Any], prefix: str) -> list[str]:
        lines = [f"{k} = {_toml_value(v)}" for k, v in data.items() if not isinstance(v, dict)]
        for k, v in data.items():
            if isinstance(v, dict):
                name = f"{prefix}.{k}" if prefix else k
                lines += ["", f"[{name}]", *table(v, name)]
        return lines

    return "\n".join(table(config_to_toml_dict(cfg), "")).lstrip("\n") + "\n"
