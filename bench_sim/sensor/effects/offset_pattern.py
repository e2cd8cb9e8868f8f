"""The offset fixed pattern at 0 s: each pixel's own dark offset (DSNU at zero exposure).

EMVA 1288 R4 separates the dark signal non-uniformity into the part that does not depend on the
exposure time (each pixel's offset, from its source follower and the reset level) and the dark
current's non-uniformity, which grows with it (``sensor.dsnu_e_s``); they are told apart by dark
images at several exposure times. This effect draws the first: a normal offset of rms ``rms_e``
[e-] (or ``rms_dn`` [DN]; the two add in quadrature) per pixel, fixed for the physical sensor,
added to the black offset (a change of the offset map, point ``maps``; it takes the generic path,
whose offsets are per pixel).

Truth: exact (a per-pixel offset of the read). EMVA 1288: ``dsnu0_e``, the pattern's rms in
electrons (``rms / K`` of the drawn map; its spatial variance over the pixels).

References
----------
EMVA Standard 1288, Release 4.0 Linear (2021), section 8 (DSNU; its dependence on the exposure
time).
"""

from __future__ import annotations

import math
from typing import Annotated

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from bench_sim.config import SensorConfig
from bench_sim.config.plausible import Typical
from bench_sim.sensor.effects.base import Effect, EmvaTerm, PixelMaps, State

__all__ = ["EFFECT", "OffsetPattern"]


class OffsetPatternParams(BaseModel):
    """Parameters of ``kind = "offset_pattern"``."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    rms_e: Annotated[float, Field(ge=0)] = Field(1.5, description="rms of the pixels' offsets [e-]")
    rms_dn: Annotated[float, Field(ge=0)] = Field(
        0.0, description="rms of the pixels' offsets [DN] (adds to rms_e)"
    )


class OffsetPattern(Effect):
    """The offset fixed pattern (module docstring)."""

    kind = "offset_pattern"
    summary = "each pixel's own dark offset: the DSNU at 0 s (EMVA 1288 R4)"
    Params = OffsetPatternParams
    TYPICAL = {"rms_e": Typical(0.05, 1e3, "e-"), "rms_dn": Typical(1e-3, 100.0, "DN")}

    def __init__(self, name: str, params: OffsetPatternParams, sensor: SensorConfig) -> None:
        super().__init__(name, params, sensor)
        k = sensor.conversion_gain_dn_per_e
        self.rms_dn = math.hypot(params.rms_e * k, params.rms_dn)

    def fixed(self, shape: tuple[int, int], rng: np.random.Generator) -> State:
        return {"offset_dn": self.rms_dn * rng.standard_normal(shape)}

    def maps(self, maps: PixelMaps, state: State) -> None:
        maps.add_offset(np.asarray(state["offset_dn"]))

    def emva(self, state: State, t_int_s: float) -> list[EmvaTerm]:
        k = self.sensor.conversion_gain_dn_per_e
        drawn = float(np.std(np.asarray(state["offset_dn"])))
        return [
            EmvaTerm(
                "dsnu0_e",
                drawn / k,
                "e-",
                "rms over the pixels of the offset pattern at 0 s (the drawn map), in electrons",
            )
        ]


EFFECT = OffsetPattern
