"""A whole bench (:class:`BenchConfig`): its sections, the combinations of them the physics
cannot mean (refused by :meth:`BenchConfig._cross`) and the odd-but-legal ones
(:func:`config_warnings`, with the numbers).
"""

from __future__ import annotations

import math
from typing import Annotated

from pydantic import Field, model_validator

from bench_sim.config.lighting import LightsConfig
from bench_sim.config.schema import (
    DrumConfig,
    DTDIConfig,
    FusionConfig,
    LensConfig,
    RenderConfig,
    Section,
    SensorConfig,
    TargetConfig,
    TimingConfig,
)

__all__ = ["BenchConfig", "config_warnings"]


class BenchConfig(Section):
    """A whole bench: rig, sensor, timing, DTDI, rendering and fusion settings."""

    name: str = "paper_rig"
    lines: Annotated[int, Field(ge=1, le=1_000_000)] = Field(
        1024, description="scene lines (output image height) of a default run"
    )
    drum: DrumConfig = Field(default_factory=DrumConfig)
    lens: LensConfig = Field(default_factory=LensConfig)
    target: TargetConfig = Field(default_factory=TargetConfig)
    lights: LightsConfig = Field(default_factory=LightsConfig)
    sensor: SensorConfig = Field(default_factory=SensorConfig)
    timing: TimingConfig = Field(default_factory=TimingConfig)
    dtdi: DTDIConfig = Field(default_factory=DTDIConfig)
    render: RenderConfig = Field(default_factory=RenderConfig)
    fusion: FusionConfig = Field(default_factory=FusionConfig)

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
        dark_e = self.sensor.dark_electrons(self.timing.t_int_s)
        clip_e = self.sensor.pixel_saturation_electrons
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
      ``2**beta - 1 - P``, is less than what one read can really add to a stage sum, so even
      stage 1 clips on the word. One read adds at most ``min(2**adc_bits - 1, K * FW + b)``
      [DN] (the ADC top, or the full well ``FW`` [e-] converted with the gain ``K`` [DN/e-] above
      the black offset ``b``, whichever comes first), less ``b`` when it is subtracted; a bench
      whose pixel saturates below the ADC top is not warned about the ADC's range.
    - a measured spectrum of the print or the sensor named in a mono bench, which renders at
      ``sensor.wavelength_m`` alone and does not use it.
    """
    out: list[str] = []
    if not cfg.render.spectral:
        named = [k for k, v in (("target.reflectance_spectrum", cfg.target.reflectance_spectrum),
                                ("sensor.qe_spectrum", cfg.sensor.qe_spectrum)) if v is not None]
        if named:
            out.append(f"{', '.join(named)} set, but render.spectral = false: a mono bench renders at "
                       "sensor.wavelength_m alone and does not use it (set render.spectral = true)")
    s, d = cfg.sensor, cfg.dtdi
    room = d.word_clip_dn - d.pedestal_dn
    signal_dn = s.conversion_gain_dn_per_e * s.pixel_saturation_electrons  # min(ADC top - b, K FW)
    read = signal_dn + (0.0 if d.subtract_black else s.black_offset_dn)
    if room < read:
        by_well = s.full_well_e <= (s.pixel_saturation_dn - s.black_offset_dn) / s.conversion_gain_dn_per_e
        why = (
            f"sensor.full_well_e = {s.full_well_e:g} e- x K = {s.conversion_gain_dn_per_e:g} DN/e-"
            if by_well else f"the top of the {s.adc_bits}-bit ADC, sensor.adc_bits = {s.adc_bits}"
        )
        out.append(
            f"dtdi.beta_bits = {d.beta_bits}: the word holds {room:g} DN above the {d.pedestal_dn} DN "
            f"pedestal, less than one pixel read can add ({read:.0f} DN: {why}"
            f"{', black subtracted' if d.subtract_black else ''}): every stage clips on the word at "
            f"{100 * room / read:.0f} % of one pixel's range or less; widen beta_bits to at least "
            f"{math.ceil(math.log2(read + d.pedestal_dn + 1))}"
        )
    return out
