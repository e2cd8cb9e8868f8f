"""The bench's lights: ``[lights.<name>]`` tables of five kinds (spot, fill, directional, point,
area), each with a physical level, a spectrum and a temporal modulation.
"""

from __future__ import annotations

import re
from typing import Annotated, Any, Literal

from pydantic import ConfigDict, Field, field_validator, model_validator

from bench_sim.config.schema import Fraction, PositiveFloat, Section, Vec3
from bench_sim.io.spectral_data import spectrum_name_problem

__all__ = [
    "BUILTIN_LIGHT_SPECTRA",
    "LIGHT_KINDS",
    "FLICKER_WAVEFORMS",
    "RESERVED_LIGHT_NAMES",
    "SpotLightConfig",
    "FillLightConfig",
    "DirectionalLightConfig",
    "PointLightConfig",
    "AreaLightConfig",
    "LightConfig",
    "LightsConfig",
]

#: Kinds of light (``lights.<name>.kind``) and what ``irradiance_w_m2`` means for each.
LIGHT_KINDS: dict[str, str] = {
    "spot": "on a plane normal to the beam at aim_m (intensity = E d^2 inside the cone)",
    "fill": "on an unoccluded surface from a uniform environment (radiance = E / pi)",
    "directional": "on a plane normal to direction, everywhere (a light at infinity)",
    "point": "on a plane normal to the ray at reference_m (intensity = E d^2)",
    "area": "on a plane facing the emitter at aim_m, on its axis (Lambertian rectangle of size_m)",
}
#: Waveforms of a light's temporal modulation (``flicker_waveform``), as relative intensity
#: ``w(t)`` of mean 1 (see :mod:`bench_sim.rig.lights`).
FLICKER_WAVEFORMS: dict[str, str] = {
    "sine": "w = 1 + depth * sin(2 pi f t + phase)",
    "rectified_sine": "w = 1 - depth + depth * (pi / 2) * |sin(pi f t + phase / 2)| (a lamp on "
    "mains of frequency f / 2)",
}
#: A light's spectra in closed form (``spectrum``); any other value names a measured one
#: (:mod:`bench_sim.io.spectral_data`).
BUILTIN_LIGHT_SPECTRA = ("flat", "blackbody")
#: Names a light cannot take (other objects of the Mitsuba scene).
RESERVED_LIGHT_NAMES = ("integrator", "sensor", "drum", "drum_body", "drum_caps", "axle", "mounts", "bench")
_LIGHT_NAME = re.compile(r"[a-z][a-z0-9_]*")


class _LightBase(Section):
    """What every light has: a switch, a physical level, a spectrum and a temporal modulation.

    ``irradiance_w_m2`` is the in-band irradiance [W/m^2] at the light's reference point (what
    that means per kind: :data:`LIGHT_KINDS`); the scene is linear in it. The light's relative
    intensity in time is ``w(t)`` of mean 1 (:data:`FLICKER_WAVEFORMS`), steady when
    ``flicker_hz = 0`` or ``flicker_depth = 0``; each frame integrates it over its own window
    (:func:`bench_sim.rig.lights.frame_weights`).
    """

    enabled: bool = True
    irradiance_w_m2: Annotated[float, Field(ge=0)] = 1.0
    spectrum: str = Field(
        "flat", description="spectral mode: 'flat', 'blackbody' (at temperature_k), a measured light "
        "by name (A: halogen; FL1..FL12: fluorescent; LED-B1..: white LEDs; lamps; the names are under "
        "allowed) or csv:FILE (wavelength_nm and one value column, relative to the config file)",
    )
    temperature_k: Annotated[float, Field(ge=500, le=20000)] = 3200.0
    flicker_hz: Annotated[float, Field(ge=0, le=1e9)] = Field(
        0.0, description="frequency of the intensity modulation [Hz]; 0: steady (100/120 Hz: a lamp "
        "on 50/60 Hz mains)"
    )
    flicker_depth: Fraction = Field(
        1.0, description="modulation depth: at its troughs the intensity falls to 1 - depth of its "
        "mean (1: to zero); 0: steady"
    )
    flicker_waveform: Literal[tuple(FLICKER_WAVEFORMS)] = "sine"  # type: ignore[valid-type]
    flicker_phase_rad: Annotated[float, Field(ge=-1e6, le=1e6)] = Field(
        0.0, description="phase of the modulation at t = 0 (start of frame 0) [rad of its period]"
    )

    @field_validator("spectrum")
    @classmethod
    def _spectrum_name(cls, value: str) -> str:
        if value not in BUILTIN_LIGHT_SPECTRA:
            problem = spectrum_name_problem("light", value)
            if problem is not None:
                raise ValueError(f"{problem} (or one of {', '.join(BUILTIN_LIGHT_SPECTRA)})")
        return value

    @property
    def flickers(self) -> bool:
        """True when the light's intensity changes in time."""
        return self.flicker_hz > 0 and self.flicker_depth > 0

    @property
    def emits(self) -> bool:
        """True when the light is switched on with a non-zero level."""
        return self.enabled and self.irradiance_w_m2 > 0


class SpotLightConfig(_LightBase):
    """A spot, aimed at a point of the drum surface (the default ``strong`` light).

    ``irradiance_w_m2`` is the in-band irradiance on a plane normal to the beam at the aim point,
    so the spot's intensity is ``irradiance_w_m2 * d**2`` [W/sr] with ``d`` the distance to it.
    """

    kind: Literal["spot"] = "spot"
    irradiance_w_m2: Annotated[float, Field(ge=0)] = 128.0
    position_m: Vec3 = (-0.10, 0.25, 0.45)
    aim_m: Vec3 = (-0.0155, 0.0, 0.10)
    cutoff_deg: Annotated[float, Field(gt=0, le=90)] = 2.0
    beam_width_deg: Annotated[float, Field(gt=0, le=90)] = 1.9

    @model_validator(mode="after")
    def _beam(self) -> SpotLightConfig:
        if self.beam_width_deg > self.cutoff_deg:
            raise ValueError(
                f"beam_width_deg = {self.beam_width_deg} must not exceed cutoff_deg = "
                f"{self.cutoff_deg}"
            )
        if self.position_m == self.aim_m:
            raise ValueError(
                f"position_m = aim_m = {list(self.aim_m)}: a spot must not sit on its aim point"
            )
        return self


class FillLightConfig(_LightBase):
    """A uniform diffuse fill: a constant environment (the default ``weak`` light; at most one
    fill emits in a bench).

    ``irradiance_w_m2`` is the in-band irradiance on an unoccluded surface (``pi * L``).
    """

    kind: Literal["fill"] = "fill"
    irradiance_w_m2: Annotated[float, Field(ge=0)] = 6.0
    temperature_k: Annotated[float, Field(ge=500, le=20000)] = 6500.0


class DirectionalLightConfig(_LightBase):
    """A light at infinity (sun-like): parallel rays travelling along ``direction``.

    ``irradiance_w_m2`` is the in-band irradiance on a plane normal to ``direction``, the same
    everywhere (no reference point is needed).
    """

    kind: Literal["directional"] = "directional"
    direction: Vec3 = Field(
        (0.0, -0.5, -1.0), description="direction the light travels in (need not be normalised)"
    )

    @model_validator(mode="after")
    def _direction(self) -> DirectionalLightConfig:
        if not any(self.direction):
            raise ValueError("direction = [0, 0, 0]: needs a non-zero vector (the way the light travels)")
        return self


class PointLightConfig(_LightBase):
    """An isotropic point light at ``position_m``.

    ``irradiance_w_m2`` is the in-band irradiance on a plane normal to the ray at
    ``reference_m`` (default: the drum point the default camera looks at), so the intensity is
    ``irradiance_w_m2 * d**2`` [W/sr] with ``d`` the distance between the two.
    """

    kind: Literal["point"] = "point"
    position_m: Vec3 = (0.0, 0.15, 0.40)
    reference_m: Vec3 = (0.0, 0.0, 0.10)

    @model_validator(mode="after")
    def _points(self) -> PointLightConfig:
        if self.position_m == self.reference_m:
            raise ValueError(
                f"position_m = reference_m = {list(self.reference_m)}: the reference point must lie "
                "away from the light"
            )
        return self


class AreaLightConfig(_LightBase):
    """A Lambertian emitting rectangle (a diffuser panel, a soft box) centred at ``position_m``
    and facing ``aim_m``; black on its back.

    ``irradiance_w_m2`` is the in-band irradiance at ``aim_m`` on a plane parallel to the
    rectangle (the aim lies on its axis); the radiance follows in closed form
    (:func:`bench_sim.rig.scene.area_radiance_w_m2_sr`).
    """

    kind: Literal["area"] = "area"
    position_m: Vec3 = (0.0, 0.20, 0.45)
    aim_m: Vec3 = (0.0, 0.0, 0.10)
    size_m: tuple[PositiveFloat, PositiveFloat] = Field(
        (0.10, 0.10), description="width and height of the rectangle [m]"
    )

    @model_validator(mode="after")
    def _points(self) -> AreaLightConfig:
        if self.position_m == self.aim_m:
            raise ValueError(
                f"position_m = aim_m = {list(self.aim_m)}: the panel must not sit on its aim point"
            )
        return self


LightConfig = SpotLightConfig | FillLightConfig | DirectionalLightConfig | PointLightConfig | AreaLightConfig
_AnyLight = Annotated[LightConfig, Field(discriminator="kind")]


class LightsConfig(Section):
    """The bench's lights: ``[lights.<name>]`` tables.

    ``strong`` (a spot) and ``weak`` (a fill) are always defined (the paper rig; switch one off
    with ``enabled = false``); any other name adds a light of the ``kind`` it names
    (:data:`LIGHT_KINDS`). Names are lower-case identifiers; at most one fill emits (Mitsuba has
    one environment). :meth:`items` lists them in a fixed order: ``strong``, ``weak``, then the
    others by name.
    """

    model_config = ConfigDict(extra="allow", frozen=True, validate_default=True)
    __pydantic_extra__: dict[str, _AnyLight] = Field(init=False)

    strong: SpotLightConfig = Field(default_factory=SpotLightConfig)
    weak: FillLightConfig = Field(default_factory=FillLightConfig)

    @model_validator(mode="before")
    @classmethod
    def _names_and_kinds(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        for name, table in data.items():
            if name in ("strong", "weak"):
                continue
            if not isinstance(name, str) or not _LIGHT_NAME.fullmatch(name) or name in RESERVED_LIGHT_NAMES:
                raise ValueError(
                    f"light name {name!r}: use a lower-case identifier (letters, digits, _) other "
                    f"than {', '.join(RESERVED_LIGHT_NAMES)}"
                )
            if not isinstance(table, dict):
                raise ValueError(f"{name} = {table!r}: must be a table ([lights.{name}])")
            kind = table.get("kind")
            if kind not in LIGHT_KINDS:
                said = "no kind" if kind is None else f"kind = {kind!r}"
                raise ValueError(
                    f"{name}: {said}; a light needs kind = one of {', '.join(repr(k) for k in LIGHT_KINDS)}"
                )
        return data

    @model_validator(mode="after")
    def _one_fill(self) -> LightsConfig:
        fills = [n for n, light in self.items() if light.kind == "fill" and light.emits]
        if len(fills) > 1:
            raise ValueError(
                f"fill lights {fills} all emit: at most one fill may (one uniform environment); "
                "switch the others off (enabled = false) or merge them"
            )
        return self

    def items(self) -> list[tuple[str, LightConfig]]:
        """``(name, light)`` of every light, enabled or not: ``strong``, ``weak``, then the
        others sorted by name."""
        extra = self.__pydantic_extra__ or {}
        return [("strong", self.strong), ("weak", self.weak), *sorted(extra.items())]

    def get(self, name: str) -> LightConfig:
        """The light called ``name``; :class:`KeyError` if there is none."""
        for n, light in self.items():
            if n == name:
                return light
        raise KeyError(name)

