"""Configuration: pydantic models for every section of a bench, loaded from TOML.

Units are SI and carried in the field names (``_m``, ``_s``, ``_w_m2``, ``_e``, ``_dn``).
The defaults are the paper rig (``scenes/paper_rig.toml`` restates them explicitly).
Unknown keys are rejected. A TOML file may name a ``base`` file (relative to itself) whose
values it overrides, which is how the lighting presets in ``scenes/`` are built.

Errors are raised as :class:`ConfigError` with one line naming the file, the key, the value and
what is allowed. Every float of every section must be finite (``inf``/``nan`` are refused by the
base section model, so sections added later are covered too); combinations the physics cannot
mean are refused (:meth:`BenchConfig._cross`), and odd-but-legal ones are reported by
:func:`config_warnings` (issued as :class:`~bench_sim.errors.ConfigWarning` when a user's config
is loaded: :func:`load_config`, :func:`warn_config`), with the numbers.
"""

from __future__ import annotations

import math
import re
import tomllib
import warnings
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from bench_sim.errors import BenchSimError, ConfigWarning

__all__ = [
    "ConfigError",
    "DrumConfig",
    "LensConfig",
    "TargetConfig",
    "SpotLightConfig",
    "FillLightConfig",
    "DirectionalLightConfig",
    "PointLightConfig",
    "AreaLightConfig",
    "LightConfig",
    "LightsConfig",
    "LIGHT_KINDS",
    "FLICKER_WAVEFORMS",
    "SensorConfig",
    "TimingConfig",
    "DTDIConfig",
    "RenderConfig",
    "FusionConfig",
    "BenchConfig",
    "DEFAULT_CONFIG_PATH",
    "SCENES_DIR",
    "BETA_BITS_MIN",
    "BETA_BITS_MAX",
    "TRA_METHODS",
    "load_config",
    "config_from_dict",
    "with_overrides",
    "config_to_toml_dict",
    "config_sha256",
    "config_to_toml_text",
    "config_warnings",
    "warn_config",
]

#: The scenes shipped inside the package (``scenes/`` in a source checkout links here).
SCENES_DIR = Path(__file__).resolve().parents[1] / "scenes"
DEFAULT_CONFIG_PATH = SCENES_DIR / "paper_rig.toml"

#: Bounds of the DTDI output word length ``beta`` [bits] (the one definition; see
#: :func:`bench_sim.sensor.model.check_beta_bits`).
BETA_BITS_MIN, BETA_BITS_MAX = 1, 32

#: Display transforms of ``Gamma_TRA`` (``fusion.tra``, ``bench-sim fuse --tra-method``,
#: :func:`bench_sim.fusion.tonemap.tone_map`): name -> formula (``x`` HDR value, ``X`` full scale,
#: ``y`` display value in 0..1).
TRA_METHODS: dict[str, str] = {
    "log": "y = ln(1 + max(x, 0)) / ln(1 + X)",
    "gamma": "y = clip(x / X, 0, 1) ** (1 / 2.2)",
    "histeq": "y = (C(x) - C(x_min)) / (P - C(x_min)), C = cumulative count of exact values",
    "reinhard": "OpenCV createTonemapReinhard(gamma=2.2) on max(x / X, 0.5 / X) (Reinhard et al. 2005)",
    "drago": "OpenCV createTonemapDrago(gamma=2.2) on max(x / X, 0.5 / X) (Drago et al. 2003)",
    "mantiuk": "OpenCV createTonemapMantiuk(gamma=2.2) on max(x / X, 0.5 / X) (Mantiuk et al. 2006)",
}

PositiveFloat = Annotated[float, Field(gt=0)]
Fraction = Annotated[float, Field(ge=0, le=1)]

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
#: Names a light cannot take (other objects of the Mitsuba scene).
RESERVED_LIGHT_NAMES = ("integrator", "sensor", "drum", "drum_body", "drum_caps", "axle", "mounts", "bench")
_LIGHT_NAME = re.compile(r"[a-z][a-z0-9_]*")


class ConfigError(BenchSimError):
    """A bad configuration: the message is one line naming file, key, value and what is allowed."""


class _Section(BaseModel):
    """Base of every config section: unknown keys refused, immutable, and every float finite
    (``allow_inf_nan=False`` applies to floats anywhere in a section, in tuples too)."""

    model_config = ConfigDict(extra="forbid", frozen=True, validate_default=True, allow_inf_nan=False)


class DrumConfig(_Section):
    """The rotating drum (roller) that carries the printed target.

    The axis is the world ``x`` axis (across the sensor columns); the camera looks along ``-z``
    at the drum surface point ``(0, 0, radius_m)``.
    """

    radius_m: PositiveFloat = 0.10
    length_m: PositiveFloat = 0.30
    geometry: Literal["analytic", "mesh"] = Field(
        "analytic",
        description="'analytic': Mitsuba's cylinder (fastest); 'mesh': trimesh body with end "
        "caps, axle and mount, handed to Mitsuba as a mesh",
    )
    mesh_segments: Annotated[int, Field(ge=16, le=65536)] = 2048
    axle_radius_m: PositiveFloat = 0.012
    axle_overhang_m: Annotated[float, Field(ge=0)] = 0.05
    bench: bool = Field(True, description="add the bench plate under the drum (mesh geometry)")
    bench_albedo: Fraction = 0.05
    mount_albedo: Fraction = 0.05


class LensConfig(_Section):
    """Camera lens. ``thinlens`` (with aperture) or ``perspective`` (pinhole special case)."""

    model: Literal["thinlens", "perspective"] = "thinlens"
    focal_length_m: PositiveFloat = 0.050
    f_number: Annotated[float, Field(ge=0.5, le=128)] = 4.0
    working_distance_m: PositiveFloat = Field(
        0.50, description="lens to the drum surface on the optical axis"
    )
    focus_distance_m: PositiveFloat | None = Field(
        None, description="lens to the plane in focus; default: the working distance"
    )
    transmission: Annotated[float, Field(gt=0, le=1)] = 0.90
    cos4_falloff: bool = True
    diffraction_psf: bool = Field(False, description="convolve the focal plane with an Airy PSF")

    @model_validator(mode="after")
    def _focus_beyond_focal_length(self) -> LensConfig:
        if self.working_distance_m <= self.focal_length_m:
            raise ValueError(
                f"working_distance_m = {self.working_distance_m} must exceed focal_length_m = "
                f"{self.focal_length_m} for a real image"
            )
        if self.focus_distance_m is not None and self.focus_distance_m <= self.focal_length_m:
            raise ValueError(
                f"focus_distance_m = {self.focus_distance_m} must exceed focal_length_m = "
                f"{self.focal_length_m}"
            )
        return self

    @property
    def focus_m(self) -> float:
        """Object distance in focus [m]."""
        return self.focus_distance_m if self.focus_distance_m is not None else self.working_distance_m

    @property
    def image_distance_m(self) -> float:
        """Lens to sensor distance [m] (thin-lens equation for the focus distance)."""
        f, s = self.focal_length_m, self.focus_m
        return f * s / (s - f)

    @property
    def magnification(self) -> float:
        """|m| = image distance / working distance (object on the optical axis)."""
        return self.image_distance_m / self.working_distance_m


class TargetConfig(_Section):
    """The printed target: a reflectance pattern on the drum surface.

    The panel is ``panel_lines`` object pixels long (along the track) and ``panel_columns`` wide;
    it repeats around the drum circumference (rounded so an integer number of panels fits).
    """

    layout: Literal["paper", "uniform", "image", "dead_leaves", "slanted_edges", "random_bars"] = Field(
        "paper",
        description="'paper', 'uniform', 'image' (target.image), or generated from the run's seed: "
        "'dead_leaves', 'slanted_edges', 'random_bars' (see bench_sim.rig.target_sources)",
    )
    panel_lines: Annotated[int, Field(ge=16, le=65536)] = 1024
    panel_columns: Annotated[int, Field(ge=16, le=65536)] = 1024
    texels_per_pixel: Annotated[int, Field(ge=1, le=16)] = 4
    reflectance_min: Annotated[float, Field(gt=0, lt=1)] = 0.02
    reflectance_max: Annotated[float, Field(gt=0, le=1)] = 0.90
    wedge_steps: Annotated[int, Field(ge=12, le=64)] = 16
    background: Fraction = 0.30
    uniform_reflectance: Fraction = 0.5
    finish: Literal["matte", "glossy"] = Field(
        "matte",
        description="'matte': Lambertian print; 'glossy': rough dielectric coating over the print "
        "(glints; reference engine only)",
    )
    gloss_roughness: Annotated[float, Field(gt=0, le=1)] = 0.1
    # layout = "image" and the generated layouts (bench_sim.rig.target_sources)
    image: str | None = Field(
        None,
        description="layout 'image': reflectance map file (8/16-bit PNG/TIFF, float TIFF, EXR, NPY), "
        "relative to the config file that names it",
    )
    image_encoding: Literal["srgb", "linear"] | None = Field(
        None, description="transfer function of the image values; default: srgb for integer files, "
        "linear for float files"
    )
    image_channel: str = Field(
        "luminance", description="'luminance' (Rec. 709 of linear RGB) or one channel: R, G, B, A, "
        "or an EXR channel name"
    )
    image_fit: Literal["stretch", "tile", "crop"] = Field(
        "stretch", description="stretch: whole image onto the panel; crop: cover, aspect kept, centre "
        "kept; tile: one image pixel per object pixel, repeated"
    )
    dead_leaves_radius_min_px: PositiveFloat = Field(1.0, description="smallest disc radius [object px]")
    dead_leaves_radius_max_px: PositiveFloat = Field(64.0, description="largest disc radius [object px]")
    edge_angle_deg: Annotated[float, Field(ge=0, le=45)] = Field(
        5.0, description="slanted_edges: mean angle of the edges to the lines / columns [deg]"
    )
    edge_angle_jitter_deg: Annotated[float, Field(ge=0, le=45)] = Field(
        1.0, description="slanted_edges: each square's angle is uniform in mean +- jitter [deg]"
    )
    edge_cell_px: Annotated[int, Field(ge=8, le=65536)] = Field(
        64, description="slanted_edges: cell of one slanted square [object px]"
    )
    bar_width_min_px: PositiveFloat = Field(2.0, description="random_bars: narrowest bar [object px]")
    bar_width_max_px: PositiveFloat = Field(24.0, description="random_bars: widest bar [object px]")

    @model_validator(mode="after")
    def _range(self) -> TargetConfig:
        if self.reflectance_min >= self.reflectance_max:
            raise ValueError(
                f"reflectance_min = {self.reflectance_min} must be below reflectance_max = "
                f"{self.reflectance_max}"
            )
        return self

    @model_validator(mode="after")
    def _sources(self) -> TargetConfig:
        if self.layout == "image" and not self.image:
            raise ValueError("layout = 'image' needs target.image (a reflectance map file)")
        if self.dead_leaves_radius_min_px >= self.dead_leaves_radius_max_px:
            raise ValueError(
                f"dead_leaves_radius_min_px = {self.dead_leaves_radius_min_px} must be below "
                f"dead_leaves_radius_max_px = {self.dead_leaves_radius_max_px}"
            )
        if self.bar_width_min_px > self.bar_width_max_px:
            raise ValueError(
                f"bar_width_min_px = {self.bar_width_min_px} must not exceed bar_width_max_px = "
                f"{self.bar_width_max_px}"
            )
        return self


Vec3 = tuple[float, float, float]


class _LightBase(_Section):
    """What every light has: a switch, a physical level, a spectrum and a temporal modulation.

    ``irradiance_w_m2`` is the in-band irradiance [W/m^2] at the light's reference point (what
    that means per kind: :data:`LIGHT_KINDS`); the scene is linear in it. The light's relative
    intensity in time is ``w(t)`` of mean 1 (:data:`FLICKER_WAVEFORMS`), steady when
    ``flicker_hz = 0`` or ``flicker_depth = 0``; each frame integrates it over its own window
    (:func:`bench_sim.rig.lights.frame_weights`).
    """

    enabled: bool = True
    irradiance_w_m2: Annotated[float, Field(ge=0)] = 1.0
    spectrum: Literal["flat", "blackbody"] = Field("flat", description="spectral mode only")
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


class LightsConfig(_Section):
    """The bench's lights: ``[lights.<name>]`` tables.

    ``strong`` (a spot) and ``weak`` (a fill) are always defined (the paper rig; switch one off
    with ``enabled = false``); any other name adds a light of the ``kind`` it names
    (:data:`LIGHT_KINDS`). Names are lower-case identifiers; at most one fill emits (Mitsuba has
    one environment). :meth:`items` lists them in a fixed order: ``strong``, ``weak``, then the
    others by name.
    """

    model_config = ConfigDict(extra="allow", frozen=True, validate_default=True)
    __pydantic_extra__: dict[str, _AnyLight] = Field(init=False)  # type: ignore[assignment]

    strong: SpotLightConfig = SpotLightConfig()
    weak: FillLightConfig = FillLightConfig()

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


class SensorConfig(_Section):
    """Area CMOS sensor: geometry and EMVA 1288 (Release 4) pixel model.

    Noise switches let every source be turned off for studies and tests.
    """

    rows: Annotated[int, Field(ge=1, le=4096)] = 100
    columns: Annotated[int, Field(ge=1, le=16384)] = 1024
    pixel_pitch_m: PositiveFloat = 5.5e-6
    wavelength_m: Annotated[float, Field(gt=200e-9, lt=2000e-9)] = 550e-9
    quantum_efficiency: Annotated[float, Field(gt=0, le=1)] = 0.55
    qe_curve: tuple[tuple[float, float], ...] | None = Field(
        None,
        description="spectral mode: (wavelength_m, relative QE) pairs, scaled so that QE at "
        "wavelength_m is quantum_efficiency; default: a front-side-illuminated CMOS curve",
    )
    full_well_e: PositiveFloat = 13500.0
    read_noise_e: Annotated[float, Field(ge=0)] = 13.0
    dark_current_e_s: Annotated[float, Field(ge=0)] = 125.0
    dsnu_e_s: Annotated[float, Field(ge=0)] = Field(
        12.5, description="dark signal non-uniformity, rms over pixels of the dark current [e-/s]"
    )
    prnu: Annotated[float, Field(ge=0, le=0.5)] = 0.01
    column_offset_dn: Annotated[float, Field(ge=0)] = Field(
        0.05, description="rms of the per-column offset of the CMOS column amplifiers [DN]; it adds "
        "up coherently over the m rows of a DTDI stage"
    )
    conversion_gain_dn_per_e: PositiveFloat = Field(
        0.072, description="K: digital numbers per electron"
    )
    black_offset_dn: Annotated[float, Field(ge=0)] = 20.0
    adc_bits: Annotated[int, Field(ge=1, le=16)] = 10
    shot_noise: bool = True
    shot_noise_sampler: Literal["hybrid", "poisson"] = Field(
        "hybrid",
        description="shot noise draws: 'poisson' exact everywhere; 'hybrid' exact below 30 mean "
        "electrons and a rounded third-order Cornish-Fisher normal above (same mean, variance and "
        "skewness; ~4x faster; see bench_sim.sensor.emva.shot_electrons)",
    )
    dark_noise: bool = True
    read_noise: bool = True
    prnu_enabled: bool = True
    dsnu_enabled: bool = True
    column_fpn: bool = True
    quantization: bool = True

    @model_validator(mode="after")
    def _black_below_adc_top(self) -> SensorConfig:
        top = 2**self.adc_bits - 1
        if self.black_offset_dn >= top:
            raise ValueError(
                f"black_offset_dn = {self.black_offset_dn} is at or above the top of the "
                f"{self.adc_bits}-bit ADC ({top} DN): no signal could be recorded; it must be below {top}"
            )
        return self


class TimingConfig(_Section):
    """Line period and integration time. The drum speed follows from them (see rig.geometry)."""

    line_period_s: PositiveFloat = 100e-6
    integration_time_s: PositiveFloat | None = Field(
        None, description="per-frame exposure; default: the whole line period"
    )
    sync_error: Annotated[float, Field(gt=-0.5, lt=0.5)] = Field(
        0.0, description="relative speed error of the drum: image moves (1 + e) pixels per line"
    )

    @model_validator(mode="after")
    def _t_int(self) -> TimingConfig:
        if self.integration_time_s is not None and self.integration_time_s > self.line_period_s:
            raise ValueError(
                f"integration_time_s = {self.integration_time_s} must not exceed line_period_s = "
                f"{self.line_period_s}"
            )
        return self

    @property
    def t_int_s(self) -> float:
        return self.integration_time_s if self.integration_time_s is not None else self.line_period_s


class DTDIConfig(_Section):
    """Digital TDI accumulation: output word of ``beta_bits`` (Phi_FS = 2**beta, eq. 4).

    ``pedestal_dn`` is a digital pedestal added to every stage sum and kept in the word (as
    real DTDI cameras do): it keeps the dark signal's noise above 0 DN, so dark statistics are
    unbiased, at the cost of ``pedestal_dn`` DN of the word's range. Every consumer (fusion,
    metrics, reports, ``ptc``) subtracts it again.
    """

    beta_bits: Annotated[int, Field(ge=BETA_BITS_MIN, le=BETA_BITS_MAX)] = 12
    subtract_black: bool = True
    pedestal_dn: Annotated[int, Field(ge=0)] = Field(
        64, description="digital pedestal added to every stage sum and kept in the word [DN]"
    )

    @model_validator(mode="after")
    def _pedestal_in_word(self) -> DTDIConfig:
        if self.pedestal_dn >= 2 ** (self.beta_bits - 1):
            raise ValueError(
                f"pedestal_dn = {self.pedestal_dn} must be below half the {self.beta_bits}-bit word "
                f"({2 ** (self.beta_bits - 1)} DN); lower it or widen beta_bits"
            )
        return self


class RenderConfig(_Section):
    """How exposures are rendered."""

    engine: Literal["fast", "reference"] = "fast"
    variant: str = Field("auto", description="'auto' or a Mitsuba variant name")
    spectral: bool = Field(False, description="render spectrally and weight by the QE curve")
    band_m: tuple[float, float] = Field(
        (400e-9, 700e-9), description="spectral mode: wavelength band of the lights [m]"
    )
    spp: Annotated[int, Field(ge=1, le=65536)] = 16
    subpixels: Annotated[int, Field(ge=1, le=8)] = Field(
        4, description="fast engine: sub-pixel records per pixel side"
    )
    max_depth: Annotated[int, Field(ge=2, le=64)] = Field(
        2, description="path depth; 2 = direct light only (required by the fast engine)"
    )
    emitter_samples: Annotated[int, Field(ge=1, le=64)] = 1
    bsdf_samples: Annotated[int, Field(ge=1, le=64)] = 1
    weak_sampling_weight: Annotated[float, Field(gt=0, le=1)] = 1e-3


    @model_validator(mode="after")
    def _variant(self) -> RenderConfig:
        from bench_sim.runtime.backend import check_variant_name

        check_variant_name(self.variant, "spectral" if self.spectral else "mono", "variant")
        return self

    @model_validator(mode="after")
    def _band(self) -> RenderConfig:
        lo, hi = self.band_m
        if not 360e-9 <= lo < hi <= 830e-9:
            raise ValueError(f"band_m = {list(self.band_m)} must satisfy 360e-9 <= low < high <= 830e-9")
        return self


class FusionConfig(_Section):
    """Stages fused by the paper's rule (eq. 11) and the display transform."""

    mu1: Annotated[int, Field(ge=1)] = 10
    mu2: Annotated[int, Field(ge=1)] = 80
    tra: Literal[tuple(TRA_METHODS)] = "log"  # type: ignore[valid-type]

    @model_validator(mode="after")
    def _order(self) -> FusionConfig:
        if self.mu1 >= self.mu2:
            raise ValueError(f"mu1 = {self.mu1} must be smaller than mu2 = {self.mu2}")
        return self


class BenchConfig(_Section):
    """A whole bench: rig, sensor, timing, DTDI, rendering and fusion settings."""

    name: str = "paper_rig"
    lines: Annotated[int, Field(ge=1, le=1_000_000)] = Field(
        1024, description="scene lines (output image height) of a default run"
    )
    drum: DrumConfig = DrumConfig()
    lens: LensConfig = LensConfig()
    target: TargetConfig = TargetConfig()
    lights: LightsConfig = LightsConfig()
    sensor: SensorConfig = SensorConfig()
    timing: TimingConfig = TimingConfig()
    dtdi: DTDIConfig = DTDIConfig()
    render: RenderConfig = RenderConfig()
    fusion: FusionConfig = FusionConfig()

    @model_validator(mode="after")
    def _cross(self) -> BenchConfig:
        if self.fusion.mu2 > self.sensor.rows:
            raise ValueError(
                f"fusion.mu2 = {self.fusion.mu2} exceeds sensor.rows = {self.sensor.rows} "
                "(stages are 1..rows)"
            )
        half_fov = 0.5 * self.sensor.columns * self.sensor.pixel_pitch_m / self.lens.magnification
        if half_fov >= 0.5 * self.drum.length_m:
            raise ValueError(
                f"drum.length_m = {self.drum.length_m} is shorter than the field of view "
                f"({2 * half_fov:.4g} m) seen by sensor.columns = {self.sensor.columns}"
            )
        half_h = 0.5 * self.sensor.rows * self.sensor.pixel_pitch_m / self.lens.magnification
        if half_h >= 0.5 * self.drum.radius_m:
            raise ValueError(
                f"drum.radius_m = {self.drum.radius_m} is too small for the {2 * half_h:.4g} m "
                "along-track field of view (must exceed 4 x half height)"
            )
        if self.render.spectral:
            lo, hi = self.render.band_m
            if not lo <= self.sensor.wavelength_m <= hi:
                raise ValueError(
                    f"sensor.wavelength_m = {self.sensor.wavelength_m} must lie in render.band_m = "
                    f"{list(self.render.band_m)}"
                )
        if self.sensor.qe_curve is not None:
            wl = [p[0] for p in self.sensor.qe_curve]
            if len(wl) < 2 or any(b <= a for a, b in zip(wl, wl[1:], strict=False)):
                raise ValueError("sensor.qe_curve: wavelengths must be at least two, increasing")
            if any(not 0 <= p[1] <= 1 for p in self.sensor.qe_curve):
                raise ValueError("sensor.qe_curve: relative QE values must lie in 0..1")
        if not math.isfinite(self.lens.magnification):
            raise ValueError("lens magnification is not finite")
        for name, light in self.lights.items():
            pos = getattr(light, "position_m", None)
            if light.enabled and pos is not None and math.hypot(pos[1], pos[2]) <= self.drum.radius_m:
                raise ValueError(
                    f"lights.{name}.position_m = {list(pos)} lies inside the drum (drum.radius_m = "
                    f"{self.drum.radius_m} around the x axis): it could light nothing; move it outside"
                )
        from bench_sim.sensor.model import dark_electrons, pixel_saturation_electrons

        dark_e = dark_electrons(self.sensor, self.timing.t_int_s)
        clip_e = pixel_saturation_electrons(self.sensor)
        if dark_e >= clip_e:
            raise ValueError(
                f"sensor.dark_current_e_s = {self.sensor.dark_current_e_s} over t_int = "
                f"{self.timing.t_int_s:g} s gives {dark_e:.4g} dark e- per read, at or above the "
                f"pixel's clip ({clip_e:.4g} e-: full well or ADC top): every pixel saturates in the "
                "dark; lower the dark current or the integration time"
            )
        return self


def config_warnings(cfg: BenchConfig) -> list[str]:
    """Legal but odd settings of ``cfg``, one line each with the numbers (empty if none).

    - ``dtdi.beta_bits`` narrower than one pixel: the word's room above the pedestal,
      ``2**beta - 1 - P``, is less than what one read adds to a stage sum (``2**adc_bits - 1``,
      less the black offset when it is subtracted), so even stage 1 clips on the word.
    """
    from bench_sim.sensor.model import pixel_saturation_dn, word_clip_dn

    out: list[str] = []
    s, d = cfg.sensor, cfg.dtdi
    room = word_clip_dn(d.beta_bits) - d.pedestal_dn
    read = pixel_saturation_dn(s) - (s.black_offset_dn if d.subtract_black else 0.0)
    if room < read:
        out.append(
            f"dtdi.beta_bits = {d.beta_bits}: the word holds {room:g} DN above the {d.pedestal_dn} DN "
            f"pedestal, less than one pixel read can add ({read:g} DN: sensor.adc_bits = {s.adc_bits}"
            f"{', black subtracted' if d.subtract_black else ''}): every stage clips on the word at "
            f"{100 * room / read:.0f} % of one pixel's range or less; widen beta_bits to at least "
            f"{math.ceil(math.log2(read + d.pedestal_dn + 1))}"
        )
    return out


def _format_loc(loc: tuple[int | str, ...]) -> str:
    """``('lights', 'strong', 'spot', 'position_m', 0)`` -> ``lights.strong.position_m[0]``."""
    parts = [p for p in loc if not (isinstance(p, str) and p.startswith("function-"))]
    if len(parts) > 2 and parts[0] == "lights" and parts[2] in LIGHT_KINDS:
        del parts[2]  # the union's tag (the light's kind) is not a key of the file
    out = ""
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else p)
    return out


def _lookup(data: Any, loc: tuple[int | str, ...]) -> Any:
    cur = data
    for part in loc:
        if isinstance(cur, dict) and part in cur:
            cur = cur[part]
        elif isinstance(cur, list | tuple) and isinstance(part, int) and part < len(cur):
            cur = cur[part]
        else:
            return None
    return cur


def _validation_message(exc: ValidationError, data: dict[str, Any], source: str) -> str:
    err = exc.errors(include_url=False)[0]
    loc = tuple(err.get("loc", ()))
    key = _format_loc(loc) or "(top level)"
    msg = err.get("msg", "invalid")
    if err.get("type") == "extra_forbidden":
        return f"config error: {source}: unknown key '{key}' (not a setting of this section)"
    value = err.get("input") if loc else None
    if loc and value is None:
        value = _lookup(data, loc)
    msg = " ".join(msg.removeprefix("Value error, ").split())
    if isinstance(value, dict) or not loc:
        where = f"{key}: " if loc else ""
        return f"config error: {source}: {where}{msg}"
    shown = repr(value)
    if len(shown) > 60:
        shown = shown[:40] + "..." + shown[-12:]
    return f"config error: {source}: {key} = {shown}: {msg}"


def _deep_merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _deep_merge(out[k], v)
        else:
            out[k] = v
    return out


def _read_toml(path: Path, chain: tuple[Path, ...] = ()) -> dict[str, Any]:
    if path.is_dir():
        raise ConfigError(f"config error: {path}: is a folder, not a TOML file")
    if not path.is_file():
        raise ConfigError(f"config error: {path}: no such file")
    if path in chain:
        raise ConfigError(f"config error: {path}: 'base' chain loops back to itself")
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"config error: {path}: cannot read it ({exc.strerror})") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(
            f"config error: {path}: not UTF-8 text (byte 0x{raw[exc.start]:02x} at offset {exc.start}); "
            "a config is a TOML text file in UTF-8"
        ) from None
    if "\x00" in text:
        raise ConfigError(f"config error: {path}: holds NUL bytes (a binary file?); a config is TOML text")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"config error: {path}: not valid TOML ({' '.join(str(exc).split())})") from None
    image = data.get("target", {}).get("image") if isinstance(data.get("target"), dict) else None
    if isinstance(image, str) and image and not Path(image).is_absolute():
        data["target"]["image"] = str((path.parent / image).resolve())  # relative to this file
    base = data.pop("base", None)
    if base is None:
        return data
    if not isinstance(base, str):
        raise ConfigError(f"config error: {path}: base = {base!r}: must be a file name string")
    base_data = _read_toml((path.parent / base).resolve(), (*chain, path))
    return _deep_merge(base_data, data)


def config_from_dict(data: dict[str, Any], source: str = "<dict>", *, warn: bool = False) -> BenchConfig:
    """Validate a plain dict (as parsed from TOML) into a :class:`BenchConfig`.

    With ``warn``, each line of :func:`config_warnings` is issued as a
    :class:`~bench_sim.errors.ConfigWarning` (a user's config; not the configs the code derives).
    """
    if not isinstance(data, dict):
        raise ConfigError(f"config error: {source}: expected a table of settings, got {type(data).__name__}")
    try:
        cfg = BenchConfig.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(_validation_message(exc, data, source)) from None
    if warn:
        warn_config(cfg, source)
    return cfg


def warn_config(cfg: BenchConfig, source: str) -> None:
    """Issue each line of :func:`config_warnings` as a :class:`~bench_sim.errors.ConfigWarning`
    (``source``: the file or argument the config came from)."""
    for line in config_warnings(cfg):
        warnings.warn(f"{source}: {line}", ConfigWarning, stacklevel=3)


def load_config(path: str | Path | None = None) -> BenchConfig:
    """Load and validate a bench config from TOML (default: ``scenes/paper_rig.toml``); its odd
    but legal settings are warned about (:func:`config_warnings`)."""
    p = Path(path) if path is not None else DEFAULT_CONFIG_PATH
    p = p.resolve()
    return config_from_dict(_read_toml(p), source=str(p), warn=True)


def with_overrides(cfg: BenchConfig, overrides: dict[str, Any], source: str = "<overrides>") -> BenchConfig:
    """A copy of ``cfg`` with the (nested) keys of ``overrides`` replaced, validated again."""
    return config_from_dict(_deep_merge(config_to_toml_dict(cfg), overrides), source=source)


def config_to_toml_dict(cfg: BenchConfig) -> dict[str, Any]:
    """The fully resolved config as a JSON/TOML-friendly dict (``None`` values dropped)."""
    return cfg.model_dump(mode="json", exclude_none=True)


def config_sha256(cfg: BenchConfig) -> str:
    """SHA-256 of the resolved config's canonical JSON."""
    import json

    from bench_sim.io import sha256_text

    return sha256_text(json.dumps(config_to_toml_dict(cfg), sort_keys=True))


def _toml_value(value: Any) -> str:
    import json

    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        if isinstance(value, float) and not math.isfinite(value):
            raise ValueError(f"cannot write {value!r} to TOML")
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)  # a TOML basic string (JSON escapes are TOML escapes)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"cannot write {type(value).__name__} to TOML")


def config_to_toml_text(cfg: BenchConfig) -> str:
    """The fully resolved config as TOML text (``tomllib.loads`` gives back
    :func:`config_to_toml_dict`; tuples come back as lists)."""

    def table(data: dict[str, Any], prefix: str) -> list[str]:
        lines = [f"{k} = {_toml_value(v)}" for k, v in data.items() if not isinstance(v, dict)]
        for k, v in data.items():
            if isinstance(v, dict):
                name = f"{prefix}.{k}" if prefix else k
                lines += ["", f"[{name}]", *table(v, name)]
        return lines

    return "\n".join(table(config_to_toml_dict(cfg), "")).lstrip("\n") + "\n"
