"""Non-linearity of the response: a monotone map of the charge a pixel collected.

A real pixel's charge-to-voltage conversion is not perfectly linear: the sense node's capacitance
grows with its voltage, so the response compresses towards the full well (a few per cent in most
CMOS pixels). The effect maps every read's electrons, after the full-well clip and before the
read noise, through a monotone non-decreasing response ``r(e)`` [e- -> e-] (point ``charge``):

``soft_knee``
    linear up to ``knee_e``, then ``r(e) = knee + w ln(1 + (e - knee) / w)``: continuous with its
    slope, concave, with ``w`` chosen so that ``r(FW) = (1 - compression) FW``
    (``knee_e`` default: half the full well);
``polynomial``
    ``r(e) = e (1 + sum_k c_k (e / FW)^k)`` with ``coefficients = [c_1, c_2, ...]`` (checked
    monotone on ``0 .. FW``);
``table``
    a measured response curve from a CSV file of two columns (input, output), in electrons
    (``domain = "e"``) or in DN above the black level (``domain = "dn"``, converted with ``K``),
    interpolated linearly (``numpy.interp``), increasing input, non-decreasing output.

Truth: exact, by the quadrature through ``r`` (:class:`~bench_sim.sensor.effects.base.Response`;
``linear_dn`` takes its small-signal slope at 0). EMVA 1288: the linearity error LE of the whole
chain's response (:func:`bench_sim.sensor.response_curve.predicted_linearity_error`).

References
----------
EMVA Standard 1288, Release 4.0 Linear (2021), section 9 (linearity). J. Janesick, *Photon
Transfer* (SPIE, 2007), ch. 9 (sense-node non-linearity).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from bench_sim.config import SensorConfig
from bench_sim.config.plausible import Typical
from bench_sim.errors import BenchSimError
from bench_sim.sensor.effects.base import Effect, EmvaTerm, ReadLaw, Response, State
from bench_sim.sensor.effects.effect_files import read_response_table
from bench_sim.sensor.linearity import linearity_error

__all__ = ["EFFECT", "Nonlinearity"]

#: Charge steps of the response's own LE (:meth:`Nonlinearity.emva`)
_LE_STEPS = 100


class NonlinearityParams(BaseModel):
    """Parameters of ``kind = "nonlinearity"``."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    form: Literal["soft_knee", "polynomial", "table"] = Field(
        "soft_knee", description="the response's form: soft_knee, polynomial or table"
    )
    compression: Annotated[float, Field(ge=0, lt=1)] = Field(
        0.03, description="soft_knee: relative signal lost at the full well, 1 - r(FW) / FW"
    )
    knee_e: Annotated[float, Field(ge=0)] | None = Field(
        None, description="soft_knee: charge where the compression starts [e-] (default: half the full well)"
    )
    coefficients: tuple[float, ...] = Field(
        (), description="polynomial: c_1, c_2, ... of r(e) = e (1 + sum c_k (e / FW)^k)"
    )
    table: str | None = Field(None, description="table: CSV file of (input, output), relative to the config")
    domain: Literal["e", "dn"] = Field(
        "e", description="table: its columns in electrons or in DN above black"
    )


class Nonlinearity(Effect):
    """The response non-linearity (module docstring)."""

    kind = "nonlinearity"
    summary = "non-linear response of the charge (soft knee, polynomial or a measured table)"
    Params = NonlinearityParams
    TYPICAL = {"knee_e": Typical(1e2, 1e6, "e-")}

    def __init__(self, name: str, params: NonlinearityParams, sensor: SensorConfig) -> None:
        super().__init__(name, params, sensor)
        self.p = params
        self.fw = float(sensor.full_well_e)
        self._function, self._slope0 = self._make()

    @property
    def temporal(self) -> bool:
        return True

    def _where(self, key: str) -> str:
        return f"config error: sensor.effects.{self.name}.{key}"

    def _make(self) -> tuple[Callable[[np.ndarray], np.ndarray], float]:
        if self.p.form == "soft_knee":
            return self._soft_knee()
        if self.p.form == "polynomial":
            return self._polynomial()
        return self._table()

    def _soft_knee(self) -> tuple[Callable[[np.ndarray], np.ndarray], float]:
        c, fw = self.p.compression, self.fw
        knee = 0.5 * fw if self.p.knee_e is None else float(self.p.knee_e)
        if c == 0:
            return (lambda e: e), 1.0
        if knee >= (1.0 - c) * fw:
            raise BenchSimError(
                f"{self._where('knee_e')} = {knee:g}: must lie below (1 - compression) x "
                f"full well = {(1 - c) * fw:g} e- for the response to reach it"
            )
        lo, hi = math.log(1e-9 * fw), math.log(1e9 * fw)  # bisection on log w: r(FW) rises with w
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            w = math.exp(mid)
            if knee + w * math.log1p((fw - knee) / w) < (1.0 - c) * fw:
                lo = mid
            else:
                hi = mid
        w = math.exp(0.5 * (lo + hi))

        def knee_response(e: np.ndarray) -> np.ndarray:
            over = np.maximum(e - knee, 0.0)
            return np.minimum(e, knee) + w * np.log1p(over / w)

        return knee_response, 1.0  # slope 1 below the knee (and of w ln(1 + e / w) at 0)

    def _polynomial(self) -> tuple[Callable[[np.ndarray], np.ndarray], float]:
        coef, fw = tuple(float(x) for x in self.p.coefficients), self.fw

        def poly(e: np.ndarray) -> np.ndarray:
            x = np.asarray(e, dtype=np.float64) / fw
            return e * (1.0 + sum(ck * x ** (k + 1) for k, ck in enumerate(coef)))

        grid = np.linspace(0.0, fw, 4097)
        if np.any(np.diff(poly(grid)) < 0):
            raise BenchSimError(
                f"{self._where('coefficients')} = {list(coef)}: the response falls somewhere "
                "in 0 .. full well; it must be monotone (non-decreasing)"
            )
        return poly, 1.0

    def _table(self) -> tuple[Callable[[np.ndarray], np.ndarray], float]:
        if not self.p.table:
            raise BenchSimError(f"{self._where('table')}: missing: form = 'table' needs a CSV file")
        x, y = read_response_table(Path(self.p.table), self._where("table"))
        if self.p.domain == "dn":
            k = self.sensor.conversion_gain_dn_per_e
            x, y = x / k, y / k
        slope0 = float((y[1] - y[0]) / (x[1] - x[0]))

        def table(e: np.ndarray) -> np.ndarray:
            return np.interp(e, x, y)

        return table, slope0

    def charge(self, e: np.ndarray, state: State, rng: np.random.Generator) -> np.ndarray:
        return self._function(e)

    def law(self, law: ReadLaw, state: State) -> ReadLaw:
        resp = Response(self._function, self._slope0, f"{self.name} ({self.p.form})")
        return law.with_(responses=(*law.responses, resp))

    def emva(self, state: State, t_int_s: float) -> list[EmvaTerm]:
        """The response at the full well, and the LE of the response alone: EMVA 1288's estimator
        (:func:`bench_sim.sensor.linearity.linearity_error`) on ``r(e)`` at 100 equal steps of
        the charge up to the full well, saturation at the last (no noise, no other clip; the
        whole chain's LE on a measurement's levels is
        :func:`bench_sim.sensor.response_curve.predicted_linearity_error`)."""
        at_fw = float(self._function(np.array([self.fw]))[0])
        e = np.linspace(self.fw / _LE_STEPS, self.fw, _LE_STEPS)
        le = linearity_error(e, self._function(e), e, saturation_index=_LE_STEPS - 1)
        return [
            EmvaTerm(
                "response_at_full_well",
                at_fw / self.fw,
                "1",
                "response at the full well relative to a linear one, r(FW) / FW",
            ),
            EmvaTerm(
                "response_linearity_error_percent",
                le.le_percent,
                "%",
                "LE of the response alone over 5-95 % of the full well (EMVA 1288's estimator)",
            ),
        ]


EFFECT = Nonlinearity
