"""The provenance block of every output a command writes: the run's config, seed and versions
(:func:`bench_sim.runtime.provenance.provenance`) and the sensor's chain of effects with whether
its truth is exact (:meth:`bench_sim.sensor.effects.chain.SensorChain.provenance`)."""

from __future__ import annotations

from typing import Any

from bench_sim.config import BenchConfig
from bench_sim.runtime.provenance import provenance as run_provenance
from bench_sim.sensor.effects.chain import sensor_chain

__all__ = ["provenance"]


def provenance(cfg: BenchConfig, seed: int, **extra: Any) -> dict[str, Any]:
    """Metadata block for an output: ``version``, ``seed``, ``config_sha256``, ``config``,
    ``versions``, ``sensor_chain``, ``truth_exact`` (``truth_not_exact``) and any ``extra`` keys."""
    return run_provenance(cfg, seed, **sensor_chain(cfg.sensor).provenance(), **extra)
