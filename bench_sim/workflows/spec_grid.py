"""The grid a sweep spec and a design spec share, described once for their JSON records."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

__all__ = ["GridSpec", "grid_as_dict"]


class GridSpec(Protocol):
    """A named grid of points over config keys (``SweepSpec``, ``DesignSpec``)."""

    @property
    def path(self) -> Path: ...
    @property
    def name(self) -> str: ...
    @property
    def description(self) -> str: ...
    @property
    def mode(self) -> str: ...
    @property
    def noise(self) -> str: ...
    @property
    def seed(self) -> int: ...
    @property
    def quick(self) -> bool: ...
    @property
    def keys(self) -> Sequence[str]: ...
    @property
    def values(self) -> Mapping[str, Sequence[Any]]: ...
    @property
    def points(self) -> Sequence[Any]: ...


def grid_as_dict(spec: GridSpec) -> dict[str, Any]:
    """JSON-ready description of a spec's grid: the first fields of ``sweep.json``'s and
    ``design.json``'s ``spec`` (the points as their number)."""
    return {
        "path": str(spec.path),
        "name": spec.name,
        "description": spec.description,
        "mode": spec.mode,
        "noise": spec.noise,
        "seed": spec.seed,
        "quick": spec.quick,
        "keys": list(spec.keys),
        "values": {k: list(v) for k, v in spec.values.items()},
        "points": len(spec.points),
    }
