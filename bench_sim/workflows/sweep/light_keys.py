"""The lighting keys of a sweep spec: ``stages`` (the banding table's stages), ``ratio`` (the
light ratio of any two named lights) and keys that add a light to a point.

- ``stages = [5, 10, 20, 50, 100]``: the stages each point also accumulates, whose flicker
  banding (with the closed form beside it) ``points_images.csv`` lists
  (:mod:`bench_sim.workflows.sweep.bands`); each in ``1 .. sensor.rows`` of every point.
- ``ratio = ["lamp_a", "lamp_b"]``: a ``light_ratio`` column, ``irradiance_w_m2`` of the first
  over the second (empty where one of them does not emit); both must be lights of every point.
- A key ``lights.<name>.<field>`` whose light is not in the base config adds that light to the
  point (``lights.lamp.kind`` picks its kind, default of the config model otherwise): a sweep may
  then mix lights of any kind; each point's config is validated as a whole.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from bench_sim.config import BenchConfig
from bench_sim.errors import BenchSimError
from bench_sim.sensor.dtdi import check_stages

__all__ = ["LIGHTING_KEYS", "adds_light", "check_banding_stages", "check_ratio", "light_ratio"]

#: spec keys of this module -> meaning (for the spec's list of keys)
LIGHTING_KEYS: dict[str, str] = {
    "stages": "stages whose flicker banding points_images.csv lists (with the closed form), e.g. "
    "[5, 10, 100]",
    "ratio": "[light_a, light_b]: a light_ratio column, irradiance of light_a / light_b",
    "keep_images": "true: each point's stage images and Gamma_HDR in DIR/images/point_NNNNNN.zarr",
}


def adds_light(base: BenchConfig, key: str) -> bool:
    """Whether ``key`` (``lights.<name>.<field>``) names a light the base does not have: the
    point adds it."""
    parts = key.split(".")
    return len(parts) == 3 and parts[0] == "lights" and parts[1] not in dict(base.lights.items())


def check_banding_stages(spec: Path, stages: Any, cfgs: Sequence[BenchConfig]) -> tuple[int, ...]:
    """``stages`` checked against every point's sensor (one line naming the spec)."""
    if stages is None:
        return ()
    rows = min(c.sensor.rows for c in cfgs)
    try:
        return check_stages(stages, rows, "stages")
    except BenchSimError as exc:
        raise BenchSimError(f"sweep spec {spec}: {exc}") from None


def check_ratio(spec: Path, ratio: Any, cfgs: Sequence[BenchConfig]) -> tuple[str, str] | None:
    """``ratio`` checked: two different names, lights of every point (one line otherwise)."""
    if ratio is None:
        return None
    if (not isinstance(ratio, list) or len(ratio) != 2 or not all(isinstance(n, str) for n in ratio)
            or ratio[0] == ratio[1]):
        raise BenchSimError(f"sweep spec {spec}: ratio = {ratio!r}: needs two different light names, "
                            'e.g. ["lamp_a", "lamp_b"]')
    for i, cfg in enumerate(cfgs):
        names = dict(cfg.lights.items())
        missing = [n for n in ratio if n not in names]
        if missing:
            raise BenchSimError(f"sweep spec {spec}: ratio = {ratio!r}: point {i} has no light "
                                f"{missing[0]!r} (its lights: {', '.join(names)})")
    return ratio[0], ratio[1]


def light_ratio(cfg: BenchConfig, pair: tuple[str, str] | None) -> float | None:
    """``irradiance_w_m2`` of ``pair[0]`` over ``pair[1]``; ``None`` unless both emit."""
    if pair is None:
        return None
    a, b = cfg.lights.get(pair[0]), cfg.lights.get(pair[1])
    if not (a.emits and b.emits):
        return None
    return float(a.irradiance_w_m2 / b.irradiance_w_m2)
