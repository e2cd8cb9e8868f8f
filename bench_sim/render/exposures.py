"""Per-row exposures: mean photons per pixel per frame, the sensor model's input.

:func:`prepare` builds the Mitsuba scene and the chosen engine once; :func:`iter_photon_frames`
then streams frames in chunks, each ``(chunk, rows M, columns N)`` photons, so a long pass never
holds all frames at once. Radiometry (camera equation, cos^4, pixel area, integration time,
photon energy) and the optional Airy PSF are applied per chunk.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.errors import BenchSimError
from bench_sim.render.engines import FastEngine, ReferenceEngine, check_fast_engine_valid
from bench_sim.render.radiometry import airy_pixel_kernel, apply_psf, radiance_to_photons_factor
from bench_sim.render.records import mitsuba_render_count
from bench_sim.render.texture import RunTexture, run_texture
from bench_sim.rig.geometry import RigGeometry, rig_geometry
from bench_sim.runtime.backend import BackendChoice, init_mitsuba

__all__ = ["RenderSetup", "prepare", "iter_photon_frames", "render_photons"]


@dataclass
class RenderSetup:
    """Everything a pass needs, built once."""

    cfg: BenchConfig
    geom: RigGeometry
    grid: RunTexture
    engine: Any
    backend: BackendChoice
    photons_per_radiance: np.ndarray  # (M, N) photons per (W m^-2 sr^-1)
    psf: np.ndarray | None
    first_frame: int
    frames: int
    seed: int
    info: dict[str, Any] = field(default_factory=dict)


def prepare(
    cfg: BenchConfig,
    frames: int,
    rng: np.random.Generator,
    *,
    engine: str | None = None,
    first_frame: int = 0,
) -> RenderSetup:
    """Build the rig, the target grid for the pass and the engine.

    Parameters
    ----------
    frames
        Number of line periods (frames) of the pass, starting at ``first_frame``.
    rng
        The run's generator; one integer is drawn from it to seed Mitsuba's samplers.
    engine
        ``"fast"`` or ``"reference"``; default: ``cfg.render.engine``.
    """
    name = engine or cfg.render.engine
    if name not in ("fast", "reference"):
        raise BenchSimError(f"render.engine = {name!r}: allowed 'fast' or 'reference'")
    if frames < 1:
        raise BenchSimError(f"frames = {frames}: must be at least 1")
    if name == "fast":
        check_fast_engine_valid(cfg)
    mi, choice = init_mitsuba(cfg.render.variant, "spectral" if cfg.render.spectral else "mono")
    geom = rig_geometry(cfg)
    grid = run_texture(cfg, geom, first_frame, frames, rng)
    seed = int(rng.integers(0, 2**31 - 1))
    if name == "fast":
        eng: Any = FastEngine(mi, cfg, geom, grid, seed, first_frame, variant=choice.variant)
    else:
        eng = ReferenceEngine(mi, cfg, geom, grid, seed, first_frame)
    s, lens = cfg.sensor, cfg.lens
    factor = radiance_to_photons_factor(
        s.rows,
        s.columns,
        s.pixel_pitch_m,
        geom.image_distance_m,
        lens.f_number,
        geom.magnification,
        lens.transmission,
        geom.t_int_s,
        s.wavelength_m,
        cos4=lens.cos4_falloff,
    ).astype(np.float32)
    psf = None
    if lens.diffraction_psf:
        psf = airy_pixel_kernel(lens.f_number * (1 + geom.magnification), s.wavelength_m, s.pixel_pitch_m)
    info = {
        "engine": name,
        "variant": choice.variant,
        "llvm_path": choice.llvm_path,
        "spp": cfg.render.spp,
        "spectral": cfg.render.spectral,
        "photon_unit": "QE-equivalent photons at sensor.wavelength_m" if cfg.render.spectral
        else "in-band photons at sensor.wavelength_m",
        "texture_shape": list(grid.shape),
        "texels_per_pixel": grid.q,
        "object_pixel_m": geom.object_pixel_m,
        "omega_rad_s": geom.omega_rad_s,
        "drum_rpm": geom.omega_rad_s * 60 / (2 * math.pi),
        "delta_m": geom.delta_m,
        "smear_m": geom.smear_m,
        "fov_x_deg": geom.fov_x_deg,
        "magnification": geom.magnification,
        "panel_period_lines": grid.panel.period_px,
        # Mitsuba renders made for this set-up (0 when the fast engine's records came from the
        # process cache; the reference engine adds one per frame as frames are rendered) and in
        # the whole process so far
        "mitsuba_renders": eng.renders,
        "mitsuba_renders_process": mitsuba_render_count(),
    }
    return RenderSetup(cfg, geom, grid, eng, choice, factor, psf, first_frame, frames, seed, info)


def iter_photon_frames(setup: RenderSetup, chunk: int = 64) -> Iterator[np.ndarray]:
    """Yield photons per pixel per frame in chunks of ``chunk`` frames, shape (n, M, N), float32."""
    k = setup.first_frame
    end = setup.first_frame + setup.frames
    while k < end:
        k1 = min(k + chunk, end)
        photons = setup.engine.radiance_frames(k, k1) * setup.photons_per_radiance
        if setup.psf is not None:
            photons = apply_psf(photons, setup.psf).astype(np.float32)
        np.maximum(photons, 0.0, out=photons)
        setup.info["mitsuba_renders"] = setup.engine.renders
        setup.info["mitsuba_renders_process"] = mitsuba_render_count()
        yield photons
        k = k1


def render_photons(
    cfg: BenchConfig,
    frames: int,
    rng: np.random.Generator,
    *,
    engine: str | None = None,
    first_frame: int = 0,
) -> tuple[np.ndarray, RenderSetup]:
    """Render a whole pass into one array of photons, shape (frames, M, N), float32."""
    setup = prepare(cfg, frames, rng, engine=engine, first_frame=first_frame)
    out = np.concatenate(list(iter_photon_frames(setup)), axis=0)
    return out, setup
