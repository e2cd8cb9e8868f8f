"""The provenance block of every output a command writes: the run's config, seed and versions
(:func:`bench_sim.runtime.provenance.provenance`) and the sensor's chain of effects with whether
its truth is exact (:meth:`bench_sim.sensor.effects.chain.SensorChain.provenance`).

An output that covers several configs (a sweep's points, which may vary an effect's parameters
or switch one on) says ``truth_exact`` only where every one of them has the exact truth, and lists
every reason it has not (``truth_not_exact``); ``sensor_chain`` is the base config's chain.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from bench_sim.config import BenchConfig
from bench_sim.runtime.provenance import provenance as run_provenance
from bench_sim.sensor.effects.chain import chain_attrs, sensor_chain

__all__ = ["provenance", "chain_provenance", "store_attrs"]


def chain_provenance(cfg: BenchConfig, covers: Iterable[BenchConfig] = ()) -> dict[str, Any]:
    """``sensor_chain`` of ``cfg``, ``truth_exact`` of ``cfg`` and every config of ``covers``
    together, and (when not) ``truth_not_exact``: every reason, once."""
    meta = sensor_chain(cfg.sensor).provenance()
    notes = dict.fromkeys(meta.get("truth_not_exact", []))
    for other in covers:
        notes.update(dict.fromkeys(sensor_chain(other.sensor).not_exact))
    meta["truth_exact"] = not notes
    meta.pop("truth_not_exact", None)
    if notes:
        meta["truth_not_exact"] = list(notes)
    return meta


def store_attrs(cfg: BenchConfig, covers: Iterable[BenchConfig] = ()) -> dict[str, Any]:
    """:func:`chain_provenance` as the attributes of a netCDF or Zarr store
    (:func:`bench_sim.sensor.effects.chain.chain_attrs`)."""
    return chain_attrs(chain_provenance(cfg, covers))


def provenance(
    cfg: BenchConfig, seed: int, *, covers: Iterable[BenchConfig] = (), **extra: Any
) -> dict[str, Any]:
    """Metadata block for an output: ``version``, ``seed``, ``config_sha256``, ``config``,
    ``versions``, ``sensor_chain``, ``truth_exact`` (``truth_not_exact``) of ``cfg`` and the
    configs it ``covers`` (:func:`chain_provenance`) and any ``extra`` keys."""
    return run_provenance(cfg, seed, **chain_provenance(cfg, covers), **extra)
