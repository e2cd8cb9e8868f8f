"""Train / validation / test splits of a dataset, by a hash of the sample index.

A spec's ``splits = { train = 0.8, val = 0.1, test = 0.1 }`` (names: lower-case identifiers;
fractions >= 0 summing to 1) assigns sample ``i`` of a dataset of root seed ``s`` to the split
whose cumulative interval (the splits in alphabetical order of their names) holds ``u(s, i)``,
the first 8 bytes of ``SHA-256("s:i")`` read as an unsigned integer over ``2**64`` (uniform in
``[0, 1)``). The assignment depends only on ``(s, i, splits)``: not on the number of samples,
workers or runs, and a sample keeps its split when a dataset grows. The split sizes are
binomial around the fractions (exact only on average).
"""

from __future__ import annotations

import hashlib
import math
import re
from collections.abc import Mapping
from typing import Any

from bench_sim.errors import BenchSimError

__all__ = ["DEFAULT_SPLITS", "check_splits", "split_unit", "split_of", "split_indices"]

#: Splits of a spec without ``splits``: every sample in ``train``
DEFAULT_SPLITS: dict[str, float] = {"train": 1.0}
_NAME = re.compile(r"[a-z][a-z0-9_]*")


def check_splits(splits: Any, where: str = "splits") -> dict[str, float]:
    """Validate ``splits`` (name -> fraction): one-line :class:`BenchSimError` otherwise."""
    if not isinstance(splits, Mapping) or not splits:
        raise BenchSimError(f"{where} = {splits!r}: expected a table such as {{ train = 0.8, val = 0.1, "
                            "test = 0.1 }")
    out: dict[str, float] = {}
    for name, frac in splits.items():
        if not isinstance(name, str) or not _NAME.fullmatch(name):
            raise BenchSimError(f"{where}.{name} : split names are lower-case identifiers (train, val, test)")
        if isinstance(frac, bool) or not isinstance(frac, int | float) or not math.isfinite(frac) or frac < 0:
            raise BenchSimError(f"{where}.{name} = {frac!r}: a fraction >= 0 is needed")
        out[name] = float(frac)
    total = sum(out.values())
    if abs(total - 1.0) > 1e-9:
        raise BenchSimError(f"{where} = {out}: the fractions sum to {total:g}, they must sum to 1")
    return out


def split_unit(seed: int, index: int) -> float:
    """``u(seed, index)`` in ``[0, 1)``: the first 8 bytes of ``SHA-256("seed:index")`` / 2**64."""
    digest = hashlib.sha256(f"{int(seed)}:{int(index)}".encode()).digest()
    return int.from_bytes(digest[:8], "big") / 2.0**64


def split_of(seed: int, index: int, splits: Mapping[str, float]) -> str:
    """The split of sample ``index`` (see the module docstring)."""
    u = split_unit(seed, index)
    edge = 0.0
    last = ""
    for name in sorted(splits):  # canonical order: JSON and TOML tables do not keep theirs
        frac = splits[name]
        edge += frac
        if frac > 0:
            last = name
            if u < edge:
                return name
    return last  # rounding of the cumulative sum just below 1


def split_indices(seed: int, samples: int | list[int], splits: Mapping[str, float]) -> dict[str, list[int]]:
    """Split name -> the sorted sample indices in it (``samples``: a count or the indices)."""
    indices = range(samples) if isinstance(samples, int) else sorted(samples)
    out: dict[str, list[int]] = {name: [] for name in splits}
    for i in indices:
        out[split_of(seed, i, splits)].append(int(i))
    return out
