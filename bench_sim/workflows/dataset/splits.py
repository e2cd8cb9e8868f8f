"""Train / validation / test splits of a dataset: exact sizes, samples by the rank of a hash.

A spec's ``splits = { train = 0.8, val = 0.1, test = 0.1 }`` (names: lower-case identifiers;
fractions >= 0 summing to 1) splits the ``n`` samples of a dataset of root seed ``s`` into
exactly :func:`split_sizes` samples per split: ``floor(f n)`` each, and the samples left over
one each to the splits with the largest remainders ``f n - floor(f n)`` (ties: names in
alphabetical order); 0.5 / 0.25 / 0.25 of 8 is 4 / 2 / 2, 0.7 / 0.15 / 0.15 of 160 is
112 / 24 / 24. The samples are ranked by ``u(s, i)``, the first 8 bytes of ``SHA-256("s:i")``
read as an unsigned integer over ``2**64`` (uniform in ``[0, 1)``; ties by index), and the
splits, in alphabetical order of their names, take consecutive runs of that ranking. The
assignment depends only on ``(s, n, splits)``: not on workers, shards, runs or the order in which
samples finish.
"""

from __future__ import annotations

import hashlib
import math
import re
from collections.abc import Mapping
from typing import Any

from bench_sim.errors import BenchSimError

__all__ = [
    "DEFAULT_SPLITS", "SPLIT_RULE", "check_splits", "split_unit", "split_sizes", "split_indices", "split_of",
    "split_map",
]

#: Splits of a spec without ``splits``: every sample in ``train``
DEFAULT_SPLITS: dict[str, float] = {"train": 1.0}
#: The rule, as ``dataset.json`` states it
SPLIT_RULE = (
    "exact sizes: floor(fraction * samples) per split, the rest one each to the largest remainders (ties: "
    "names in alphabetical order); samples ranked by u = first 8 bytes of SHA-256('seed:i') / 2**64 (ties: "
    "index), the splits in alphabetical order taking consecutive runs of the ranking "
    "(bench_sim.workflows.dataset.splits)"
)
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


def split_sizes(samples: int, splits: Mapping[str, float]) -> dict[str, int]:
    """Split name -> its number of samples out of ``samples`` (largest remainder; module
    docstring), in alphabetical order of the names; the sizes sum to ``samples``."""
    names = sorted(splits)
    quota = {k: float(splits[k]) * int(samples) for k in names}
    # a quota within 1e-9 of an integer is that integer (0.15 * 160 is 23.999999999999996)
    sizes = {k: math.floor(q + 1e-9) for k, q in quota.items()}
    left = int(samples) - sum(sizes.values())
    by_remainder = sorted(names, key=lambda k: (-(quota[k] - sizes[k]) if splits[k] > 0 else 1.0, k))
    for k in by_remainder[:max(left, 0)]:
        sizes[k] += 1
    return sizes


def split_indices(seed: int, samples: int, splits: Mapping[str, float]) -> dict[str, list[int]]:
    """Split name -> the sorted indices of its samples, of a dataset of ``samples`` samples."""
    ranked = sorted(range(int(samples)), key=lambda i: (split_unit(seed, i), i))
    out: dict[str, list[int]] = {}
    start = 0
    for name, size in split_sizes(samples, splits).items():
        out[name] = sorted(ranked[start : start + size])
        start += size
    return {name: out[name] for name in splits}


def split_map(seed: int, samples: int, splits: Mapping[str, float]) -> dict[int, str]:
    """Sample index -> its split, for every sample of a dataset of ``samples`` samples."""
    return {i: name for name, idx in split_indices(seed, samples, splits).items() for i in idx}


def split_of(seed: int, index: int, splits: Mapping[str, float], samples: int) -> str:
    """The split of sample ``index`` of a dataset of ``samples`` samples (module docstring)."""
    return split_map(seed, samples, splits)[int(index)]
