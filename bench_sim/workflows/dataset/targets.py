"""A dataset's camera and the values it records of each sample.

- :func:`fixed_camera` -> one physical sensor (fixed patterns) for every sample of a dataset
  with ``camera = "fixed"``, drawn from its own stream of the dataset's root seed;
  :func:`check_camera` refuses a fixed camera with a randomised ``sensor.*`` key.
- :func:`recorded_values`: a sample's drawn values as its record lists them.

The training targets are the pass's own variables (``true_hdr_dn``, ``eq11_expected_dn``,
``noise_std_dn``, ...: :data:`bench_sim.pipeline.PASS_VARIABLES`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.errors import BenchSimError
from bench_sim.io.strict_json import strict_json
from bench_sim.sensor.emva import FixedPattern, draw_fixed_pattern

__all__ = [
    "CAMERA_SPAWN_KEY",
    "CAMERAS",
    "fixed_camera",
    "strict_json",
    "check_camera",
    "recorded_values",
]

#: ``camera`` values of a dataset spec: a new physical sensor per sample, or one for all.
CAMERAS: dict[str, str] = {
    "per_sample": "every sample draws its own physical sensor (fixed patterns) from its stream",
    "fixed": "one physical sensor for every sample, drawn from SeedSequence(seed, spawn_key=(2**32,))",
}
#: Spawn key of the fixed camera's stream: above every sample index (samples <= 10**9), so it
#: never coincides with a sample's stream ``SeedSequence(seed, spawn_key=(i,))``.
CAMERA_SPAWN_KEY = 2**32


def fixed_camera(cfg: BenchConfig, seed: int) -> FixedPattern:
    """The one physical sensor of a ``camera = "fixed"`` dataset of root seed ``seed``: its
    fixed patterns drawn from ``SeedSequence(seed, spawn_key=(CAMERA_SPAWN_KEY,))`` for the
    bench's sensor (the same for every sample, as the sensor keys are not randomised)."""
    stream = np.random.SeedSequence(int(seed), spawn_key=(CAMERA_SPAWN_KEY,))
    return draw_fixed_pattern(cfg.sensor, np.random.default_rng(stream))


def recorded_values(values: Mapping[str, Any], base_layout: str) -> dict[str, Any]:
    """A sample's drawn values as recorded: ``target.image`` is ``None`` when the sample's
    target layout (drawn, or the base's) uses no image (it was drawn, so the streams are
    unchanged, but does not describe the sample)."""
    out = dict(values)
    if "target.image" in out and out.get("target.layout", base_layout) != "image":
        out["target.image"] = None
    return out


def check_camera(camera: str, randomize: Mapping[str, Any], where: str) -> None:
    """Refuse a ``camera = "fixed"`` spec that randomises a ``sensor.*`` key (one line)."""
    keys = [k for k in randomize if k.startswith("sensor.")]
    if camera == "fixed" and keys:
        raise BenchSimError(
            f"{where}: randomize.{keys[0]}: camera = 'fixed' is one physical sensor for every sample; "
            "randomise no sensor.* key with it (or use camera = 'per_sample')"
        )
