"""Defect pixels: hot, warm, cold (dead), stuck and random-telegraph pixels.

EMVA 1288 R4 counts defect pixels apart from the non-uniformities (they are kept out of DSNU and
PRNU). Each kind, drawn per physical sensor with its rate (the probability that a pixel is of
it; the kinds are exclusive), or read from a map of the pixels a user measured:

``hot`` / ``warm``
    extra dark current ``hot_dark_current_e_s`` / ``warm_dark_current_e_s`` [e-/s] (with its own
    shot noise): a change of the dark-current map;
``cold``
    relative light gain ``cold_gain`` (0: dead): a change of the gain map;
``stuck``
    every read is ``stuck_value_dn`` [DN] (point ``digital``);
``rts``
    a random-telegraph pixel: each read adds ``rts_amplitude_dn`` [DN] with probability
    ``rts_probability``, independently per frame (point ``analog``; the telegraph's dwell time
    is taken as shorter than a line period).

``map_file``: a CSV of ``row, column, kind, value`` (value: the dark current [e-/s] of a hot or
warm pixel, the gain of a cold one, the value [DN] of a stuck one, the amplitude [DN] of a
telegraph one), used instead of the rates.

Truth: exact (the maps change the read's Poisson mean or gain; a stuck read is a constant; a
telegraph read is a two-point mixture: :mod:`bench_sim.sensor.chain_truth`). EMVA 1288: the count
and the positions of each kind.

References
----------
EMVA Standard 1288, Release 4.0 Linear (2021), section 8.4 (defect pixels). M. J. Kirton,
M. J. Uren, Adv. Phys. 38 (1989) 367 (random telegraph signals).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from bench_sim.config import SensorConfig
from bench_sim.config.plausible import Typical
from bench_sim.errors import BenchSimError
from bench_sim.sensor.effects.base import Effect, EmvaTerm, PixelMaps, ReadLaw, State, Stuck, Telegraph
from bench_sim.sensor.effects.effect_files import read_csv_columns

__all__ = ["EFFECT", "Defects", "KINDS"]

#: the kinds of defect pixel, in the order their rates partition ``[0, 1)``, and their code
KINDS = ("hot", "warm", "cold", "stuck", "rts")
#: a kind's rate: at most 0.1, so the five add up to at most 0.5 and always partition ``[0, 1)``
Rate = Annotated[float, Field(ge=0, le=0.1)]


class DefectsParams(BaseModel):
    """Parameters of ``kind = "defects"``."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    hot_rate: Rate = Field(0.0, description="fraction of hot pixels")
    hot_dark_current_e_s: Annotated[float, Field(ge=0)] = Field(
        20000.0, description="extra dark current of a hot pixel [e-/s]"
    )
    warm_rate: Rate = Field(0.0, description="fraction of warm pixels")
    warm_dark_current_e_s: Annotated[float, Field(ge=0)] = Field(
        2000.0, description="extra dark current of a warm pixel [e-/s]"
    )
    cold_rate: Rate = Field(0.0, description="fraction of cold (low-gain) pixels")
    cold_gain: Annotated[float, Field(ge=0, le=1)] = Field(
        0.0, description="relative gain of a cold pixel (0: dead)"
    )
    stuck_rate: Rate = Field(0.0, description="fraction of stuck pixels")
    stuck_value_dn: Annotated[int, Field(ge=0)] = Field(
        0, description="value every read of a stuck pixel gives [DN]"
    )
    rts_rate: Rate = Field(0.0, description="fraction of random-telegraph pixels")
    rts_amplitude_dn: Annotated[float, Field(ge=0)] = Field(
        20.0, description="step of a telegraph pixel [DN]"
    )
    rts_probability: Annotated[float, Field(gt=0, lt=1)] = Field(
        0.5, description="probability that a telegraph pixel is in its high state in a read"
    )
    map_file: str | None = Field(
        None, description="CSV of row, column, kind, value: the pixels a user measured (instead of the rates)"
    )


class Defects(Effect):
    """Defect pixels (module docstring)."""

    kind = "defects"
    summary = "hot, warm, cold (dead), stuck and random-telegraph pixels, by rates or from a map"
    Params = DefectsParams
    TYPICAL = {
        "hot_dark_current_e_s": Typical(10.0, 1e7, "e-/s"),
        "warm_dark_current_e_s": Typical(1.0, 1e6, "e-/s"),
        "rts_amplitude_dn": Typical(0.1, 1e4, "DN"),
    }

    def __init__(self, name: str, params: DefectsParams, sensor: SensorConfig) -> None:
        super().__init__(name, params, sensor)
        self.p = params
        top = sensor.pixel_saturation_dn
        if params.stuck_value_dn > top:
            raise BenchSimError(
                f"config error: sensor.effects.{name}.stuck_value_dn = {params.stuck_value_dn}: "
                f"above the ADC's top ({top} DN)"
            )
        self.map = None if params.map_file is None else self._read_map(Path(params.map_file))

    def _read_map(self, path: Path) -> list[tuple[int, int, int, float]]:
        where = f"config error: sensor.effects.{self.name}.map_file"
        rows, cols = self.sensor.rows, self.sensor.columns
        out = []
        for i, r in enumerate(read_csv_columns(path, where, 4)):
            try:
                row, col, kind, value = int(r[0]), int(r[1]), r[2].lower(), float(r[3])
            except ValueError:
                raise BenchSimError(
                    f"{where} = {str(path)!r}: row {i + 1}: expected row, column, kind, value"
                ) from None
            if kind not in KINDS or not (0 <= row < rows and 0 <= col < cols) or not np.isfinite(value):
                raise BenchSimError(
                    f"{where} = {str(path)!r}: row {i + 1}: pixel ({row}, {col}) of kind "
                    f"{kind!r}: needs a pixel of the {rows} x {cols} sensor and a kind of "
                    f"{', '.join(KINDS)}"
                )
            out.append((row, col, KINDS.index(kind) + 1, value))
        return out

    @property
    def temporal(self) -> bool:
        p = self.p
        if self.map is not None:
            return any(k >= KINDS.index("stuck") + 1 for _, _, k, _ in self.map)
        return p.stuck_rate > 0 or p.rts_rate > 0

    def fixed(self, shape: tuple[int, int], rng: np.random.Generator) -> State:
        """``code`` (0: good, 1 + index in :data:`KINDS`) and ``value`` (the kind's value) maps."""
        code = np.zeros(shape, dtype=np.int8)
        value = np.zeros(shape)
        if self.map is not None:
            for row, col, code_of, v in self.map:
                code[row, col], value[row, col] = code_of, v
            return {"code": code, "value": value}
        u = rng.random(shape)
        edge = 0.0
        defaults = {
            "hot": self.p.hot_dark_current_e_s,
            "warm": self.p.warm_dark_current_e_s,
            "cold": self.p.cold_gain,
            "stuck": float(self.p.stuck_value_dn),
            "rts": self.p.rts_amplitude_dn,
        }
        for j, kind in enumerate(KINDS):
            rate = getattr(self.p, f"{kind}_rate")
            sel = (u >= edge) & (u < edge + rate)
            code[sel], value[sel] = j + 1, defaults[kind]
            edge += rate
        return {"code": code, "value": value}

    def _is(self, state: State, kind: str) -> np.ndarray:
        return np.asarray(state["code"]) == KINDS.index(kind) + 1

    def maps(self, maps: PixelMaps, state: State) -> None:
        value = np.asarray(state["value"])
        extra = np.where(self._is(state, "hot") | self._is(state, "warm"), value, 0.0)
        maps.dark_current_e_s = maps.dark_current_e_s + extra
        maps.gain = np.where(self._is(state, "cold"), maps.gain * value, maps.gain)

    def analog(self, y: np.ndarray, state: State, rng: np.random.Generator) -> np.ndarray:
        rts = self._is(state, "rts")
        if not rts.any():
            return y
        high = rng.random((y.shape[0], int(rts.sum()))) < self.p.rts_probability
        y[:, rts] += high * np.asarray(state["value"])[rts]
        return y

    def digital(self, v: np.ndarray, state: State, rng: np.random.Generator) -> np.ndarray:
        stuck = self._is(state, "stuck")
        if stuck.any():
            v[:, stuck] = np.asarray(state["value"])[stuck]
        return v

    def law(self, law: ReadLaw, state: State) -> ReadLaw:
        value = np.asarray(state["value"])
        rts, stuck = self._is(state, "rts"), self._is(state, "stuck")
        if rts.any():
            law = law.with_(
                telegraph=Telegraph(
                    rts, np.where(rts, value, 0.0), np.full(rts.shape, self.p.rts_probability)
                )
            )
        if stuck.any():
            law = law.with_(stuck=Stuck(stuck, np.where(stuck, value, 0.0)))
        return law

    def emva(self, state: State, t_int_s: float) -> list[EmvaTerm]:
        out = []
        for kind in KINDS:
            where = np.argwhere(self._is(state, kind))
            pos = tuple((int(r), int(c)) for r, c in where)
            out.append(EmvaTerm(f"{kind}_pixels", float(len(pos)), "1", f"number of {kind} pixels", pos))
        return out


EFFECT = Defects
