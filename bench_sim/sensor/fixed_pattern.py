"""The fixed patterns of one physical sensor: what repeats exactly from frame to frame.

:class:`FixedPattern` holds, per pixel, the light gain (PRNU and gain defects), the dark current
(DSNU, hot pixels), the column amplifiers' offsets, the offset pattern and every effect's own
fixed state; :func:`draw_fixed_pattern` draws them once per physical sensor from the run's
generator (EMVA 1288 R4 section 2; the effects: :mod:`bench_sim.sensor.effects`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from bench_sim.config import SensorConfig
from bench_sim.sensor.effects.base import PixelMaps, State
from bench_sim.sensor.effects.chain import sensor_chain

__all__ = ["FixedPattern", "draw_fixed_pattern"]


def _readonly(arr: np.ndarray) -> np.ndarray:
    arr = np.ascontiguousarray(arr)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class FixedPattern:
    """The fixed-pattern properties of one physical sensor (read-only arrays).

    Attributes
    ----------
    prnu_gain
        (M, N) relative gain of each pixel for the light signal (PRNU, and the gain of defect
        pixels), mean 1, dimensionless.
    dark_current_e_s
        (M, N) dark current of each pixel [e-/s] (mean ``dark_current_e_s``, rms ``dsnu_e_s``).
    column_offset_dn
        (N,) offset of each column amplifier [DN], mean 0.
    offset_dn
        (M, N) offset of each pixel [DN] beyond the black and column offsets (an offset pattern,
        :mod:`bench_sim.sensor.effects`), or ``None``.
    effects
        ``(name, state)`` of every effect of the chain: its own fixed pattern.
    """

    prnu_gain: np.ndarray
    dark_current_e_s: np.ndarray
    column_offset_dn: np.ndarray
    offset_dn: np.ndarray | None = None
    effects: tuple[tuple[str, State], ...] = ()

    def __post_init__(self) -> None:
        shape = np.shape(self.prnu_gain)
        if len(shape) != 2:
            raise ValueError(f"prnu_gain must be 2-D (rows, columns), got shape {shape}")
        if np.shape(self.dark_current_e_s) != shape:
            raise ValueError(
                f"dark_current_e_s shape {np.shape(self.dark_current_e_s)} != prnu_gain shape {shape}"
            )
        if np.shape(self.column_offset_dn) != (shape[1],):
            raise ValueError(
                f"column_offset_dn shape {np.shape(self.column_offset_dn)} != ({shape[1]},)"
            )
        object.__setattr__(self, "prnu_gain", _readonly(np.asarray(self.prnu_gain, np.float64)))
        object.__setattr__(
            self, "dark_current_e_s", _readonly(np.asarray(self.dark_current_e_s, np.float64))
        )
        object.__setattr__(
            self, "column_offset_dn", _readonly(np.asarray(self.column_offset_dn, np.float64))
        )
        if self.offset_dn is not None:
            if np.shape(self.offset_dn) != shape:
                raise ValueError(f"offset_dn shape {np.shape(self.offset_dn)} != prnu_gain shape {shape}")
            object.__setattr__(self, "offset_dn", _readonly(np.asarray(self.offset_dn, np.float64)))

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, columns) of the sensor."""
        return (int(self.prnu_gain.shape[0]), int(self.prnu_gain.shape[1]))

    def window(self, rows: int | None = None, columns: int | None = None) -> FixedPattern:
        """The fixed pattern of the top-left ``rows`` x ``columns`` pixels (a region of interest)."""
        r = self.shape[0] if rows is None else rows
        c = self.shape[1] if columns is None else columns
        if not (1 <= r <= self.shape[0] and 1 <= c <= self.shape[1]):
            raise ValueError(f"window {r} x {c} outside the sensor {self.shape[0]} x {self.shape[1]}")
        return FixedPattern(
            prnu_gain=self.prnu_gain[:r, :c],
            dark_current_e_s=self.dark_current_e_s[:r, :c],
            column_offset_dn=self.column_offset_dn[:c],
            offset_dn=None if self.offset_dn is None else self.offset_dn[:r, :c],
            effects=tuple((name, _window_state(state, r, c)) for name, state in self.effects),
        )


def _window_state(state: State, rows: int, columns: int) -> dict[str, Any]:
    """An effect's fixed pattern on the top-left ``rows`` x ``columns`` pixels (its (M, N)
    arrays cut, anything else kept)."""
    return {
        k: v[:rows, :columns] if isinstance(v, np.ndarray) and v.ndim == 2 else v for k, v in state.items()
    }


def draw_fixed_pattern(sensor: SensorConfig, rng: np.random.Generator) -> FixedPattern:
    """Draw the fixed patterns of one physical sensor of ``sensor.rows`` x ``sensor.columns``.

    The three patterns are always drawn, in the order PRNU, DSNU, column offsets, each from
    standard normal numbers, so switching one of them off does not change the others. Then the
    chain's effects draw theirs (:meth:`bench_sim.sensor.effects.chain.SensorChain.draw_fixed`:
    defect pixels, an offset pattern, ...) and apply them to the maps; without effects nothing
    more is drawn.

    * PRNU gain ``g = max(1 + prnu * z, 0)`` (EMVA 1288 R4 section 2: the spatial standard
      deviation of the photo-response is ``prnu * mu``); ``1`` when ``prnu_enabled`` is off.
    * dark current ``I_d = max(dark_current_e_s + dsnu_e_s * z, 0)`` [e-/s];
      ``dark_current_e_s`` everywhere when ``dsnu_enabled`` is off.
    * column offsets ``column_offset_dn * z`` [DN]; ``0`` when ``column_fpn`` is off.

    Parameters
    ----------
    sensor
        Sensor geometry and pixel model.
    rng
        The run's random generator.
    """
    shape = (sensor.rows, sensor.columns)
    z_prnu = rng.standard_normal(shape)
    z_dsnu = rng.standard_normal(shape)
    z_col = rng.standard_normal(sensor.columns)
    if sensor.prnu_enabled:
        gain = np.maximum(1.0 + sensor.prnu * z_prnu, 0.0)
    else:
        gain = np.ones(shape)
    if sensor.dsnu_enabled:
        dark = np.maximum(sensor.dark_current_e_s + sensor.dsnu_e_s * z_dsnu, 0.0)
    else:
        dark = np.full(shape, float(sensor.dark_current_e_s))
    col = sensor.column_offset_dn * z_col if sensor.column_fpn else np.zeros(sensor.columns)
    maps = PixelMaps(gain, dark)
    states = sensor_chain(sensor).draw_fixed(maps, rng)  # nothing drawn without effects
    return FixedPattern(prnu_gain=maps.gain, dark_current_e_s=maps.dark_current_e_s, column_offset_dn=col,
                        offset_dn=maps.offset_dn, effects=states)


