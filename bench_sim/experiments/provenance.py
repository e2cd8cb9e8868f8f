"""What every output file carries: the resolved config, its hash, the seed and the versions."""

from __future__ import annotations

from typing import Any

from bench_sim import __version__
from bench_sim.config import BenchConfig, config_sha256, config_to_toml_dict

__all__ = ["provenance"]


def provenance(cfg: BenchConfig, seed: int, **extra: Any) -> dict[str, Any]:
    """Metadata block for an output: ``version``, ``seed``, ``config_sha256``, ``config`` and
    any ``extra`` keys."""
    from bench_sim.backend import versions

    meta: dict[str, Any] = {
        "version": __version__,
        "seed": int(seed),
        "config_sha256": config_sha256(cfg),
        "config": config_to_toml_dict(cfg),
        "versions": versions(),
    }
    meta.update(extra)
    return meta
