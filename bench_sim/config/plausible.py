"""Plausibility ranges of the physical config keys: unit slips caught before anything runs.

A value written in the wrong unit (``timing.line_period_s = 100`` meant as microseconds,
``sensor.pixel_pitch_m = 5.5`` meant as micrometres) is legal to the schema's bounds but lies
orders of magnitude away from any real bench. Every physical key has a *typical* range here
(:data:`TYPICAL`, shown by ``bench-sim config keys``); a value more than :data:`MARGIN` times
outside it is refused with the key the user wrote, the typical range and, when one SI prefix
brings the value into it, a guess (``did you mean 100e-6?``). Zero stays legal where the
schema allows it (a light switched off, a noise source turned off): only non-zero magnitudes
are judged. The check runs on the raw settings before the model's own checks, so a slip is
named as itself and not as the cross-check it would break (a 5.5 m pixel blamed on
``drum.length_m``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

__all__ = ["MARGIN", "Typical", "TYPICAL", "typical_for", "plausibility_error", "judge"]

#: How far outside its typical range (a factor) a value may lie before it is refused.
MARGIN = 10.0


@dataclass(frozen=True)
class Typical:
    """The typical range ``low..high`` [``unit``] of a physical key; ``vector``: the bound is on
    the magnitude of each component of a point or size (``high`` only)."""

    low: float
    high: float
    unit: str
    vector: bool = False

    @property
    def refused_below(self) -> float:
        """Non-zero magnitudes below this are refused (``low / MARGIN``)."""
        return 0.0 if self.vector else self.low / MARGIN

    @property
    def refused_above(self) -> float:
        """Magnitudes above this are refused (``high * MARGIN``)."""
        return self.high * MARGIN

    def describe(self) -> str:
        """``1e-05..0.01 s`` (``|x| <= 2 m`` for a vector)."""
        if self.vector:
            return f"|x| <= {self.high:g} {self.unit}"
        return f"{self.low:g}..{self.high:g} {self.unit}"


#: Typical range of every physical key (``lights.*``: any light). Keys are dotted config paths.
TYPICAL: dict[str, Typical] = {
    "drum.radius_m": Typical(0.01, 1.0, "m"),
    "drum.length_m": Typical(0.01, 3.0, "m"),
    "drum.axle_radius_m": Typical(1e-3, 0.1, "m"),
    "drum.axle_overhang_m": Typical(1e-3, 0.5, "m"),
    "lens.focal_length_m": Typical(4e-3, 0.6, "m"),
    "lens.working_distance_m": Typical(0.02, 10.0, "m"),
    "lens.focus_distance_m": Typical(0.02, 10.0, "m"),
    "lens.psf_pixel_m": Typical(5e-8, 2e-5, "m"),
    "sensor.pixel_pitch_m": Typical(1e-6, 5e-5, "m"),
    "sensor.wavelength_m": Typical(3e-7, 1.1e-6, "m"),
    "sensor.full_well_e": Typical(1e3, 1e6, "e-"),
    "sensor.read_noise_e": Typical(0.5, 100.0, "e-"),
    "sensor.dark_current_e_s": Typical(0.1, 1e5, "e-/s"),
    "sensor.dsnu_e_s": Typical(0.01, 1e4, "e-/s"),
    "sensor.conversion_gain_dn_per_e": Typical(1e-3, 5.0, "DN/e-"),
    "sensor.column_offset_dn": Typical(1e-3, 10.0, "DN"),
    "timing.line_period_s": Typical(1e-5, 1e-2, "s"),
    "timing.integration_time_s": Typical(1e-6, 1e-2, "s"),
    "render.band_m": Typical(3.6e-7, 8.3e-7, "m", vector=True),
    "target.dead_leaves_radius_min_px": Typical(0.5, 1000.0, "object px"),
    "target.dead_leaves_radius_max_px": Typical(0.5, 1000.0, "object px"),
    "target.bar_width_min_px": Typical(0.5, 1000.0, "object px"),
    "target.bar_width_max_px": Typical(0.5, 1000.0, "object px"),
    "lights.*.irradiance_w_m2": Typical(1e-2, 1e5, "W/m^2"),
    "lights.*.flicker_hz": Typical(1.0, 1e5, "Hz"),
    "lights.*.position_m": Typical(0.0, 10.0, "m", vector=True),
    "lights.*.aim_m": Typical(0.0, 10.0, "m", vector=True),
    "lights.*.reference_m": Typical(0.0, 10.0, "m", vector=True),
    "lights.*.size_m": Typical(0.0, 3.0, "m", vector=True),
}

#: SI prefixes tried for a guess, as (factor, how it is written after the number).
_PREFIXES = ((1e-6, "e-6"), (1e-3, "e-3"), (1e-9, "e-9"), (1e-2, "e-2"), (1e3, "e3"), (1e6, "e6"))


def typical_for(key: str) -> Typical | None:
    """The typical range of the dotted config key ``key`` (a light's key by any light name)."""
    parts = key.split(".")
    if len(parts) == 3 and parts[0] == "lights":
        key = f"lights.*.{parts[2]}"
    return TYPICAL.get(key)


def _guess(value: float, typ: Typical) -> str:
    """``; did you mean 100e-6?`` when one SI prefix brings ``value`` into the typical range
    (the one nearest its middle, in log), else empty."""
    low = typ.low or typ.high / 100  # a vector's components: within two decades of the bound
    mid = 0.5 * (math.log10(low) + math.log10(typ.high))
    plain = "e" not in f"{value:g}"  # 100 -> "100e-6"; 1.28e+08 -> "128"
    fits = [
        (abs(math.log10(abs(value) * f) - mid), f"{value:g}{suffix}" if plain else f"{value * f:g}")
        for f, suffix in _PREFIXES
        if low <= abs(value) * f <= typ.high
    ]
    return f"; did you mean {min(fits)[1]}?" if fits else ""


def judge(key: str, value: Any, typ: Typical) -> str | None:
    """The unit-slip line of ``key = value`` against the typical range ``typ`` (``None`` when
    the value is plausible, zero, or not a finite number): the check of every config key, and of
    the physical quantities of other inputs (``bench-sim calibrate``'s exposure times)."""
    if typ.vector:
        if not isinstance(value, list | tuple):
            return None
        parts = [v for v in value if isinstance(v, int | float) and not isinstance(v, bool)]
        worst = max((abs(v) for v in parts if math.isfinite(v)), default=0.0)
        if worst <= typ.refused_above:
            return None
        shown = "[" + ", ".join(f"{v:g}" for v in parts) + "]"
        return (
            f"{key} = {shown}: expected {typ.describe()} per component, refused above "
            f"{typ.refused_above:g} {typ.unit} (a unit slip?){_guess(worst, typ)}"
        )
    if not isinstance(value, int | float) or isinstance(value, bool) or not math.isfinite(value):
        return None  # wrong types and inf/nan: the schema's own message
    mag = abs(value)
    if mag == 0 or typ.refused_below <= mag <= typ.refused_above:
        return None
    return (
        f"{key} = {value!r}: expected about {typ.describe()}, refused outside "
        f"{typ.refused_below:g}..{typ.refused_above:g} {typ.unit} (a unit slip?){_guess(value, typ)}"
    )


def plausibility_error(data: Any) -> str | None:
    """The first unit slip in the raw settings ``data`` (a config as parsed from TOML) as one
    line ``key = value: expected about LOW..HIGH UNIT, ...; did you mean ...?``; ``None`` if none.

    Only keys present in ``data`` are judged, in the order of :data:`TYPICAL`; values of the
    wrong type are left to the schema's checks.
    """
    if not isinstance(data, dict):
        return None
    for pattern, typ in TYPICAL.items():
        section, *rest = pattern.split(".")
        table = data.get(section)
        if not isinstance(table, dict):
            continue
        if section == "lights":
            entries = [
                (f"lights.{n}.{rest[1]}", t.get(rest[1])) for n, t in table.items() if isinstance(t, dict)
            ]
        else:
            entries = [(pattern, table.get(rest[0]))]
        for key, value in entries:
            problem = judge(key, value, typ) if value is not None else None
            if problem:
                return problem
    return None
