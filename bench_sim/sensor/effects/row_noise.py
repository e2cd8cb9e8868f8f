"""Temporal row noise: one normal draw per row and frame, shared by the row's columns.

A CMOS sensor's row drivers and reference voltages add a noise that is common to every pixel of
a row read at the same time. In a DTDI stage the ``m`` reads of a line come from ``m`` different
rows and frames, so the stage's variance grows by ``m sigma_row^2`` like pixel noise, but the
noise is common to every column of an output line: each line is shifted as a whole, stripes
across the track rather than pixel noise. The effect adds ``sigma_row * z[k, i]`` [DN] to every
read of row ``i`` in frame ``k`` (point ``analog``), ``sigma_row = hypot(rms_dn, K rms_e)``.

Truth: exact (a Gaussian of variance ``sigma_row^2`` added to each read, independent between the
reads of a stage). EMVA 1288: ``row_noise_var_dn2``, the temporal variance of a row's mean beyond
the pixels' own (``sigma_row^2`` [DN^2]).

References
----------
EMVA Standard 1288, Release 4.0 Linear (2021), section 8 (row and column components).
"""

from __future__ import annotations

import math
from typing import Annotated

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from bench_sim.config import SensorConfig
from bench_sim.config.plausible import Typical
from bench_sim.sensor.effects.base import Effect, EmvaTerm, ReadLaw, State

__all__ = ["EFFECT", "RowNoise"]


class RowNoiseParams(BaseModel):
    """Parameters of ``kind = "row_noise"``."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    rms_dn: Annotated[float, Field(ge=0)] = Field(1.0, description="rms of a row's shift in one read [DN]")
    rms_e: Annotated[float, Field(ge=0)] = Field(
        0.0, description="rms of a row's shift in one read [e-] (adds to rms_dn)"
    )


class RowNoise(Effect):
    """Temporal row noise (module docstring)."""

    kind = "row_noise"
    summary = "temporal row noise: one draw per row and frame, common to the row's columns"
    Params = RowNoiseParams
    TYPICAL = {"rms_dn": Typical(1e-3, 100.0, "DN"), "rms_e": Typical(0.01, 1e3, "e-")}

    def __init__(self, name: str, params: RowNoiseParams, sensor: SensorConfig) -> None:
        super().__init__(name, params, sensor)
        self.sigma_dn = math.hypot(params.rms_dn, params.rms_e * sensor.conversion_gain_dn_per_e)

    @property
    def temporal(self) -> bool:
        return self.sigma_dn > 0

    def analog(self, y: np.ndarray, state: State, rng: np.random.Generator) -> np.ndarray:
        if self.sigma_dn > 0:
            y += self.sigma_dn * rng.standard_normal(y.shape[:-1])[..., None]
        return y

    def law(self, law: ReadLaw, state: State) -> ReadLaw:
        return law.with_(extra_read_var_dn2=law.extra_read_var_dn2 + self.sigma_dn**2)

    def emva(self, state: State, t_int_s: float) -> list[EmvaTerm]:
        return [
            EmvaTerm(
                "row_noise_var_dn2",
                self.sigma_dn**2,
                "DN^2",
                "temporal variance of a row's common shift in one read",
            )
        ]


EFFECT = RowNoise
