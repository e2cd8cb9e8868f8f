"""What every output file carries: the resolved config, its hash, the seed and the versions."""

from __future__ import annotations

from typing import Any

from bench_sim.config import BenchConfig, config_sha256, config_to_toml_dict
from bench_sim.runtime.backend import versions
from bench_sim.version import __version__

__all__ = ["provenance", "render_provenance", "PROCESS_KEYS"]

#: Keys of a render set-up's ``info`` that describe the process rather than the run: how many
#: Mitsuba renders it made depends on the record cache the process already holds. They stay out
#: of data files, so the same config and seed give the same bytes in any process.
PROCESS_KEYS = ("mitsuba_renders", "mitsuba_renders_process")


def provenance(cfg: BenchConfig, seed: int, **extra: Any) -> dict[str, Any]:
    """Metadata block for an output: ``version``, ``seed``, ``config_sha256``, ``config`` and
    any ``extra`` keys."""
    meta: dict[str, Any] = {
        "version": __version__,
        "seed": int(seed),
        "config_sha256": config_sha256(cfg),
        "config": config_to_toml_dict(cfg),
        "versions": versions(),
    }
    meta.update(extra)
    return meta


def render_provenance(info: dict[str, Any]) -> dict[str, Any]:
    """A render set-up's ``info`` for an output's metadata: without :data:`PROCESS_KEYS`."""
    return {k: v for k, v in info.items() if k not in PROCESS_KEYS}
