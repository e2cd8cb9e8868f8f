"""Strict JSON: what every JSON parser accepts (no ``NaN`` / ``Infinity`` tokens).

:func:`strict_dumps` is the one JSON encoding of every file and attribute bench_sim writes (JSON
files, journal records, the provenance attributes of EXR, TIFF and PNG images, the provenance
lines of CSV files): :func:`strict_json` first (a non-finite float becomes ``null``, numpy
values Python values, paths text), then ``json.dumps`` with ``allow_nan=False``, so a ``NaN``
token can never be written.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import PurePath
from typing import Any

import numpy as np

__all__ = ["strict_json", "strict_dumps"]


def strict_json(value: Any) -> Any:
    """``value`` with every non-finite float (NaN, inf) replaced by ``None`` (JSON ``null``),
    numpy scalars and arrays as Python numbers and lists, paths as text, tuples as lists,
    recursively."""
    if isinstance(value, Mapping):
        return {k: strict_json(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, list | tuple):
        return [strict_json(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, PurePath):
        return str(value)
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def strict_dumps(value: Any, **kwargs: Any) -> str:
    """``json.dumps(strict_json(value), allow_nan=False, **kwargs)``: strict JSON text."""
    return json.dumps(strict_json(value), allow_nan=False, **kwargs)
