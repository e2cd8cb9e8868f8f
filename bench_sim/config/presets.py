"""Named variants of a config: the ``--quick`` preset (``bench-sim reproduce --quick``, a sweep
spec's ``quick = true``)."""

from __future__ import annotations

from typing import Any

from bench_sim.config.bench import BenchConfig
from bench_sim.config.loading import with_overrides

__all__ = ["QUICK_OVERRIDES", "quick_config"]

#: ``--quick``: the same experiment on a 512-column sensor and 256 lines (CI, first runs).
QUICK_OVERRIDES: dict[str, Any] = {
    "lines": 256,
    "sensor": {"columns": 512},
    "target": {"panel_lines": 256, "panel_columns": 512},
    "render": {"spp": 8},
}


def quick_config(cfg: BenchConfig) -> BenchConfig:
    """The ``--quick`` preset of a config (:data:`QUICK_OVERRIDES`)."""
    return with_overrides(cfg, QUICK_OVERRIDES, source="--quick preset")
