"""The sections of a bench config: pydantic models of the rig, sensor, timing, DTDI, rendering
and fusion settings (the lights: :mod:`bench_sim.config.lighting`; the whole bench:
:mod:`bench_sim.config.bench`).

Units are SI and carried in the field names (``_m``, ``_s``, ``_w_m2``, ``_e``, ``_dn``).
The defaults are the paper rig (``scenes/paper_rig.toml`` restates them explicitly).
Unknown keys are rejected, and every float of every section must be finite (``inf``/``nan`` are
refused by :class:`Section`, so sections added later are covered too). The closed forms that
follow from one section alone (a pixel's clip, its dark electrons, the DTDI word's top) are
properties of that section: the one place of each formula.
"""

from __future__ import annotations

import re
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from bench_sim.config.variants import check_variant_name
from bench_sim.io.spectral_data import spectrum_name_problem

__all__ = [
    "Section",
    "PositiveFloat",
    "Fraction",
    "Vec3",
    "BETA_BITS_MIN",
    "BETA_BITS_MAX",
    "word_full_scale_dn",
    "word_top_dn",
    "DrumConfig",
    "LensConfig",
    "TargetConfig",
    "SensorConfig",
    "EffectEntry",
    "EFFECT_NAME",
    "TimingConfig",
    "DTDIConfig",
    "RenderConfig",
    "FusionConfig",
]

#: Bounds of the DTDI output word length ``beta`` [bits] (the one definition; see
#: :func:`bench_sim.sensor.model.check_beta_bits`).
BETA_BITS_MIN, BETA_BITS_MAX = 1, 32

def word_full_scale_dn(beta_bits: int) -> int:
    """``Phi_FS = 2**beta`` [DN] of a ``beta``-bit output word (paper eq. 4); ``beta_bits`` is
    not checked here (:func:`bench_sim.sensor.model.full_scale_dn` checks it)."""
    return 1 << beta_bits


def word_top_dn(beta_bits: int) -> int:
    """Largest value a ``beta``-bit output word stores: ``Phi_FS - 1 = 2**beta - 1`` [DN]."""
    return word_full_scale_dn(beta_bits) - 1


PositiveFloat = Annotated[float, Field(gt=0)]
Fraction = Annotated[float, Field(ge=0, le=1)]
Vec3 = tuple[float, float, float]


class Section(BaseModel):
    """Base of every config section: unknown keys refused, immutable, and every float finite
    (``allow_inf_nan=False`` applies to floats anywhere in a section, in tuples too)."""

    model_config = ConfigDict(
        extra="forbid", frozen=True, validate_default=True, allow_inf_nan=False, defer_build=True
    )



class DrumConfig(Section):
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


class LensConfig(Section):
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
    diffraction: bool = Field(
        True, description="blur by the diffraction of the lens' round aperture (the OTF of an "
        "aberration-free lens at the working f-number f_number (1 + m), at sensor.wavelength_m; "
        "per wavelength of render.band_m in spectral mode), applied before the sensor; false: a "
        "perfect lens (the images of bench_sim 0.3)",
    )
    mtf_file: str | None = Field(
        None, description="a measured lens MTF instead of diffraction: CSV of frequency_cyc_mm (on "
        "the sensor) and mtf, or mtf_sagittal and mtf_tangential (tangential: across the track), "
        "relative to the config file",
    )
    psf_file: str | None = Field(
        None, description="a lens PSF instead of diffraction: a grey image (NPY, TIFF, EXR, PNG) "
        "sampled every psf_pixel_m on the sensor, relative to the config file",
    )
    psf_pixel_m: PositiveFloat | None = Field(None, description="psf_file's sample spacing on the sensor")

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

    @model_validator(mode="after")
    def _lens_files(self) -> LensConfig:
        if self.mtf_file and self.psf_file:
            raise ValueError("mtf_file and psf_file are both set: give one measured lens, not two")
        if self.psf_file and self.psf_pixel_m is None:
            raise ValueError("psf_file needs psf_pixel_m, the PSF image's sample spacing on the sensor [m]")
        if self.psf_pixel_m is not None and not self.psf_file:
            raise ValueError("psf_pixel_m is set without psf_file (the PSF image it describes)")
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


class TargetConfig(Section):
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
    reflectance_spectrum: str | None = Field(
        None, description="spectral mode: the print's reflectance spectrum, times the pattern's "
        "reflectance (1: the spectrum itself): a chart patch by name (ColorChecker N Ohta/dark skin, "
        "...; the names are under allowed) or csv:FILE (a print's or paper's spectrum); default: grey",
    )
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

    @field_validator("reflectance_spectrum")
    @classmethod
    def _reflectance_name(cls, value: str | None) -> str | None:
        problem = None if value is None else spectrum_name_problem("reflectance", value)
        if problem is not None:
            raise ValueError(problem)
        return value

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



#: Names of the sensor's effects (``[sensor.effects.<name>]``): lower-case identifiers
EFFECT_NAME = re.compile(r"[a-z][a-z0-9_]*")


class EffectEntry(BaseModel):
    """One effect of the sensor's chain, ``[sensor.effects.<name>]``: its ``kind`` (a built-in
    effect, or ``"plugin"`` for a function of your own) and its parameters.

    The parameters are checked by the effect itself (:mod:`bench_sim.sensor.effects`: names,
    units, ranges, unit slips), when the chain is built, before anything runs;
    ``bench-sim config keys sensor`` lists every kind with its keys.
    """

    model_config = ConfigDict(extra="allow", frozen=True, allow_inf_nan=False, defer_build=True)

    kind: str = Field(description="the effect: a built-in kind (bench-sim config keys sensor lists them) "
                      "or 'plugin'")
    enabled: bool = Field(True, description="false: the effect is left out of the chain")


class SensorConfig(Section):
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
    qe_spectrum: str | None = Field(
        None, description="spectral mode: a measured spectral response by name (a camera's channel: "
        "Nikon 5100 (NPL)/green, ...; the names are under allowed) or csv:FILE, instead of qe_curve; its "
        "shape, scaled so that QE at wavelength_m is quantum_efficiency",
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
        "skewness; the sensor pass ~5x faster; see bench_sim.sensor.sampler.shot_electrons)",
    )
    dark_noise: bool = True
    read_noise: bool = True
    prnu_enabled: bool = True
    dsnu_enabled: bool = True
    column_fpn: bool = True
    quantization: bool = True
    effects: dict[str, EffectEntry] = Field(
        default_factory=dict,
        description="further effects of the pixel chain, [sensor.effects.<name>] tables with a kind "
        "(non-linearity, defect pixels, offset pattern, row noise, your own function): each acts at "
        "its point of the signal path, in the order written (bench_sim.sensor.effects)",
    )

    @model_validator(mode="after")
    def _effect_names(self) -> SensorConfig:
        for name in self.effects:
            if not EFFECT_NAME.fullmatch(name):
                raise ValueError(f"sensor.effects.{name}: use a lower-case identifier (letters, digits, _)")
        return self

    @field_validator("qe_spectrum")
    @classmethod
    def _qe_name(cls, value: str | None) -> str | None:
        problem = None if value is None else spectrum_name_problem("qe", value)
        if problem is not None:
            raise ValueError(problem)
        return value

    @model_validator(mode="after")
    def _one_qe(self) -> SensorConfig:
        if self.qe_curve is not None and self.qe_spectrum is not None:
            raise ValueError("qe_curve and qe_spectrum are both set: give one QE curve")
        return self

    @model_validator(mode="after")
    def _black_below_adc_top(self) -> SensorConfig:
        top = self.pixel_saturation_dn
        if self.black_offset_dn >= top:
            raise ValueError(
                f"black_offset_dn = {self.black_offset_dn} is at or above the top of the "
                f"{self.adc_bits}-bit ADC ({top} DN): no signal could be recorded; it must be below {top}"
            )
        return self

    @property
    def pixel_saturation_dn(self) -> int:
        """Largest raw pixel value: ``2**adc_bits - 1`` [DN]."""
        return (1 << self.adc_bits) - 1

    @property
    def pixel_saturation_electrons(self) -> float:
        """Electrons [e-] at which a pixel stops responding: the full well, or the ADC top above
        the black offset, ``(2**adc_bits - 1 - b) / K``, whichever comes first."""
        adc = (self.pixel_saturation_dn - self.black_offset_dn) / self.conversion_gain_dn_per_e
        return float(min(self.full_well_e, adc))

    def dark_electrons(self, t_int_s: float) -> float:
        """Mean dark electrons of one read, ``mu_d = I_d t_int`` [e-] (``t_int_s`` in s)."""
        return float(self.dark_current_e_s * t_int_s)


class TimingConfig(Section):
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


class DTDIConfig(Section):
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

    @property
    def full_scale_dn(self) -> int:
        """``Phi_FS = 2**beta_bits`` [DN] of the output word (paper eq. 4)."""
        return word_full_scale_dn(self.beta_bits)

    @property
    def word_clip_dn(self) -> int:
        """Largest value the output word stores: ``2**beta_bits - 1`` [DN]."""
        return word_top_dn(self.beta_bits)


class RenderConfig(Section):
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
        check_variant_name(self.variant, "spectral" if self.spectral else "mono", "variant")
        return self

    @model_validator(mode="after")
    def _band(self) -> RenderConfig:
        lo, hi = self.band_m
        if not 360e-9 <= lo < hi <= 830e-9:
            raise ValueError(f"band_m = {list(self.band_m)} must satisfy 360e-9 <= low < high <= 830e-9")
        return self


class FusionConfig(Section):
    """Stages fused by the paper's rule (eq. 11) and the display transform."""

    mu1: Annotated[int, Field(ge=1)] = 10
    mu2: Annotated[int, Field(ge=1)] = 80
    #: display transform of ``Gamma_TRA``: a name of :data:`bench_sim.fusion.tonemap.TONEMAP_METHODS`
    #: (fusion sits above config; :func:`bench_sim.workflows.preflight.preflight` checks it)
    tra: str = "log"

    @model_validator(mode="after")
    def _order(self) -> FusionConfig:
        if self.mu1 >= self.mu2:
            raise ValueError(f"mu1 = {self.mu1} must be smaller than mu2 = {self.mu2}")
        return self

