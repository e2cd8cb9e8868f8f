"""The contract of a sensor effect: where it acts, how it draws, what it does to the truth, and
its EMVA 1288 closed form.

The signal path of one read (pixel ``(i, n)``, frame ``k``), with the points an effect acts at
(:data:`POINTS`)::

    lam = mu_p * QE * g[i, n]               "maps": gain g (PRNU, cold pixels)        [e-]
    d   = I_d[i, n] * t_int                 "maps": dark current (DSNU, hot pixels)   [e-]
    e   = min(Poisson(lam + d), FW)         shot noise, full-well clip                [e-]
    e   = r(e)                              "charge": monotone responses (non-linearity) [e-]
    y   = K e + o[i, n] + K sigma_r eps     "maps": offsets o (black, column, offset pattern)
    y   = y + ...                           "analog": row noise, telegraph pixels     [DN]
    v   = clip(rint(y), 0, T)               the ADC                                   [DN]
    v   = ...                               "digital": stuck pixels                   [DN]

The default chain (EMVA 1288's linear model: QE, PRNU, dark current and its non-uniformity, shot
noise, full well, read noise, gain, black and column offsets, the ADC) is
:mod:`bench_sim.sensor.emva` with its compiled fast path; an :class:`Effect` adds to it. Each
effect declares, in its one file:

- its parameters (:attr:`Effect.Params`, a pydantic model whose field names carry the units)
  and their typical ranges (:attr:`Effect.TYPICAL`, the unit-slip check);
- how it draws: :meth:`Effect.fixed` (its fixed pattern, drawn once per physical sensor from the
  generator it is given), :meth:`Effect.maps` (what that pattern does to the per-pixel gain,
  dark current and offset maps), :meth:`Effect.charge`, :meth:`Effect.analog` and
  :meth:`Effect.digital` (what it does to a block of reads at its point, with the generator it
  is given: one per effect and chunk of frames, so the draws never depend on threads or workers);
- what it does to the truth, :meth:`Effect.law`: each read's distribution as a
  :class:`ReadLaw` (extra Gaussian variance, a monotone response the truth integrates through,
  telegraph or stuck pixels), or ``exact = False`` (then every output says its truth is not exact);
- its EMVA 1288 closed form, :meth:`Effect.emva` (what ``ptc`` measures of it, what
  ``calibrate`` fits).

References
----------
EMVA Standard 1288, Release 4.0 Linear (2021), sections 2 (model), 8 (non-uniformity, defect
pixels), 9 (linearity). Pyxel (Arko et al., 2022), whose chain of detector models this follows.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import numpy as np
from pydantic import BaseModel

from bench_sim.config import SensorConfig
from bench_sim.config.plausible import Typical
from bench_sim.errors import BenchSimError

__all__ = [
    "POINTS",
    "State",
    "PixelMaps",
    "Response",
    "Telegraph",
    "Stuck",
    "ReadLaw",
    "EmvaTerm",
    "Effect",
    "check_block",
]

#: The points of the signal path an effect acts at (module docstring), in signal order
POINTS: dict[str, str] = {
    "maps": "fixed per-pixel gain [1], dark current [e-/s] and offset [DN] maps",
    "charge": "electrons after shot noise and the full-well clip [e-], before the read noise",
    "analog": "the read's analog value [DN] (gain, offsets and read noise in), before the ADC",
    "digital": "the raw value [DN] after the ADC",
}

#: An effect's fixed pattern: name -> (rows, columns) array (or a scalar), drawn once per sensor
State = Mapping[str, Any]


@dataclass
class PixelMaps:
    """The per-pixel linear parameters of one physical sensor, as effects modify them.

    Attributes
    ----------
    gain
        (M, N) relative light gain: PRNU times what effects add (a cold pixel's low gain) [1].
    dark_current_e_s
        (M, N) dark current [e-/s] (DSNU, hot and warm pixels).
    offset_dn
        (M, N) offset [DN] beyond the black offset and the column offsets (an offset pattern),
        or ``None`` (none).
    """

    gain: np.ndarray
    dark_current_e_s: np.ndarray
    offset_dn: np.ndarray | None = None

    def add_offset(self, offset_dn: np.ndarray) -> None:
        """Add an (M, N) offset [DN] to :attr:`offset_dn`."""
        self.offset_dn = (
            offset_dn.astype(np.float64) if self.offset_dn is None else self.offset_dn + offset_dn
        )


@dataclass(frozen=True)
class Response:
    """A monotone, non-decreasing response of the charge ``e -> r(e)`` [e- -> e-] (a
    non-linearity): the draw applies it to every read's electrons after the full-well clip and
    the truth integrates through it. ``slope0`` [1] is its small-signal slope at 0 (the linear
    truth's gain); ``name`` says whose it is."""

    function: Callable[[np.ndarray], np.ndarray]
    slope0: float
    name: str


@dataclass(frozen=True)
class Telegraph:
    """Random-telegraph pixels: in each read, pixel ``(i, n)`` with ``mask`` set adds
    ``amplitude_dn`` with probability ``probability`` (independently per frame), in the analog
    domain. Arrays (M, N)."""

    mask: np.ndarray
    amplitude_dn: np.ndarray
    probability: np.ndarray


@dataclass(frozen=True)
class Stuck:
    """Stuck pixels: every read of pixel ``(i, n)`` with ``mask`` set is ``value_dn`` (an
    integer in the ADC's range). Arrays (M, N)."""

    mask: np.ndarray
    value_dn: np.ndarray


@dataclass(frozen=True)
class ReadLaw:
    """What the chain's effects do to the distribution of each read (the truth's input).

    Attributes
    ----------
    extra_read_var_dn2
        Variance [DN^2] of zero-mean Gaussian noise added in the analog domain besides the read
        noise (row noise: one draw per row and frame, so independent between the reads a stage
        sums).
    responses
        Monotone charge responses, in the order they act.
    telegraph, stuck
        Telegraph and stuck pixels (``None``: none).
    """

    extra_read_var_dn2: float = 0.0
    responses: tuple[Response, ...] = ()
    telegraph: Telegraph | None = None
    stuck: Stuck | None = None

    @property
    def linear(self) -> bool:
        """No response, telegraph or stuck pixel: the default truth's computation applies."""
        return not self.responses and self.telegraph is None and self.stuck is None

    def response(self, e: np.ndarray) -> np.ndarray:
        """The composed responses applied to electrons ``e`` [e-]."""
        for r in self.responses:
            e = r.function(e)
        return e

    @property
    def slope0(self) -> float:
        """The composed responses' small-signal slope at 0 [1]."""
        return float(np.prod([r.slope0 for r in self.responses])) if self.responses else 1.0

    def with_(self, **changes: Any) -> ReadLaw:
        """A copy with ``changes``."""
        return replace(self, **changes)


@dataclass(frozen=True)
class EmvaTerm:
    """One EMVA 1288 quantity an effect predicts in closed form: ``name`` (e.g.
    ``dsnu0_e``, ``row_noise_var_dn2``, ``hot_pixels``), its ``value``, ``units`` and a sentence
    (``meaning``); ``positions`` lists (row, column) pixels where it names pixels."""

    name: str
    value: float
    units: str
    meaning: str
    positions: tuple[tuple[int, int], ...] = field(default=())


class Effect:
    """A sensor effect (module docstring): subclass it in one file of
    :mod:`bench_sim.sensor.effects` with its ``kind``, ``Params`` and the hooks it needs; every
    hook defaults to doing nothing.

    Parameters
    ----------
    name
        The effect's name in the config (``[sensor.effects.<name>]``).
    params
        Its parameters (an instance of :attr:`Params`).
    sensor
        The sensor it belongs to (full well, gain, ADC range, ...).
    """

    #: the effect's ``kind`` in the config
    kind: ClassVar[str] = ""
    #: one line: what it models
    summary: ClassVar[str] = ""
    #: its parameters (field names carry the units, as every config key does)
    Params: ClassVar[type[BaseModel]]
    #: typical range of each physical parameter (the unit-slip check), by field name
    TYPICAL: ClassVar[dict[str, Typical]] = {}

    def __init__(self, name: str, params: BaseModel, sensor: SensorConfig) -> None:
        self.name, self.params, self.sensor = name, params, sensor

    # --- how it draws -----------------------------------------------------------------------------

    @property
    def temporal(self) -> bool:
        """Whether it acts on the reads themselves (a response, noise, defects that override
        reads), so the chain takes the generic path; effects that only change the fixed maps
        keep the compiled fast path."""
        return False

    def fixed(self, shape: tuple[int, int], rng: np.random.Generator) -> State:
        """Draw its fixed pattern for a sensor of ``shape`` (rows, columns) from ``rng``."""
        return {}

    def maps(self, maps: PixelMaps, state: State) -> None:
        """Modify the per-pixel gain, dark current and offset maps (in place)."""

    def charge(self, e: np.ndarray, state: State, rng: np.random.Generator) -> np.ndarray:
        """Electrons [e-] of a block of reads (frames, rows, columns) after the full-well clip ->
        electrons."""
        return e

    def analog(self, y: np.ndarray, state: State, rng: np.random.Generator) -> np.ndarray:
        """Analog values [DN] of a block of reads (frames, rows, columns) -> analog values."""
        return y

    def digital(self, v: np.ndarray, state: State, rng: np.random.Generator) -> np.ndarray:
        """Raw values [DN] (float64, whole numbers) of a block of reads -> raw values."""
        return v

    # --- its truth and its closed forms ---------------------------------------------------------

    def law(self, law: ReadLaw, state: State) -> ReadLaw:
        """What it does to each read's distribution (default: nothing)."""
        return law

    @property
    def truth_note(self) -> str | None:
        """``None`` when :meth:`law` states the effect on a read exactly; else why not (every
        output then says its truth is not exact)."""
        return None

    def emva(self, state: State, t_int_s: float) -> list[EmvaTerm]:
        """Its EMVA 1288 quantities in closed form (default: none)."""
        return []

    def describe(self) -> str:
        """One line for provenance and reports: ``name (kind): parameters``."""
        values = ", ".join(f"{k} = {v!r}" for k, v in self.params.model_dump().items())
        return f"{self.name} ({self.kind}): {values}"


def check_block(x: Any, shape: tuple[int, ...], where: str, electrons: bool) -> np.ndarray:
    """An effect's output on a block of reads, checked: a numpy array of ``shape`` and a real
    dtype, finite, and ``>= 0`` for ``electrons``; one line naming ``where`` otherwise. Returns it
    as float64."""
    if not isinstance(x, np.ndarray):
        raise BenchSimError(f"{where}: returned {type(x).__name__}, expected a numpy array")
    if x.shape != shape:
        raise BenchSimError(
            f"{where}: returned shape {x.shape} for reads of shape {shape}; it must keep the shape"
        )
    if x.dtype.kind not in "fiu":
        raise BenchSimError(f"{where}: returned dtype {x.dtype}, expected a real (float or integer) array")
    if not np.all(np.isfinite(x)):
        raise BenchSimError(f"{where}: returned NaN or infinite values")
    if electrons and x.size and float(x.min()) < 0:
        raise BenchSimError(f"{where}: returned negative electrons ({float(x.min()):g} e-)")
    return x.astype(np.float64, copy=False)
