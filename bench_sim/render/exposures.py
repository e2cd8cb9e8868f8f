"""Per-row exposures: mean photons per pixel per frame, the sensor model's input.

:func:`prepare` builds the Mitsuba scene and the chosen engine once; :func:`iter_photon_frames`
then streams frames in chunks, each ``(chunk, rows M, columns N)`` photons, so a long pass never
holds all frames at once. Radiometry (camera equation, cos^4, pixel area, integration time,
photon energy) is applied per chunk; the lens' blur (diffraction, or the user's lens) is in the
texture the engines read (:mod:`bench_sim.render.lens_blur`).

:func:`fast_records` makes the fast engine's light records of a config by themselves (a task
that several passes share: :mod:`bench_sim.render.records`) and :func:`records_group` names the
passes that can share them, without Mitsuba.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.errors import BenchSimError
from bench_sim.render import record_store
from bench_sim.render.engines import FastEngine, ReferenceEngine, check_fast_engine_valid
from bench_sim.render.radiometry import radiance_to_photons_factor
from bench_sim.render.records import (
    LightRecords,
    cached_records,
    forget_records,
    light_records,
    mitsuba_render_count,
    records_key,
)
from bench_sim.render.texture import RunTexture, run_texture
from bench_sim.rig.geometry import RigGeometry, rig_geometry
from bench_sim.rig.spectra import check_spectra
from bench_sim.runtime.backend import BackendChoice, init_mitsuba, select_backend

__all__ = [
    "RenderSetup", "prepare", "iter_photon_frames", "iter_radiance_frames", "photons_of", "render_photons",
    "fast_records", "records_group", "release",
]


@dataclass
class RenderSetup:
    """Everything a pass needs, built once."""

    cfg: BenchConfig
    geom: RigGeometry
    grid: RunTexture
    engine: Any
    backend: BackendChoice
    photons_per_radiance: np.ndarray  # (M, N) photons per (W m^-2 sr^-1)
    first_frame: int
    frames: int
    seed: int
    info: dict[str, Any] = field(default_factory=dict)


def _mode(cfg: BenchConfig) -> str:
    return "spectral" if cfg.render.spectral else "mono"


def _mitsuba(cfg: BenchConfig) -> tuple[Any, BackendChoice]:
    return init_mitsuba(cfg.render.variant, _mode(cfg))


def _backend(cfg: BenchConfig, engine: str) -> tuple[Any, BackendChoice, LightRecords | None]:
    """``(mitsuba, backend, records)`` of a pass: the fast engine whose records this process
    holds already (rendered or installed) needs no Mitsuba at all (``mitsuba`` is ``None``; the
    backend is chosen as :func:`~bench_sim.runtime.backend.init_mitsuba` would), else Mitsuba is
    imported and its variant set (``records`` is ``None``)."""
    if engine == "fast":
        choice = select_backend(cfg.render.variant, _mode(cfg))
        records = cached_records(cfg, choice.variant)
        if records is not None:
            return None, choice, records
    mi, choice = _mitsuba(cfg)
    return mi, choice, None


def release(setup: RenderSetup) -> None:
    """Let go of what ``setup`` holds to render frames, once its pass is done: its engine (the
    fast engine's row kernels, their light-weighted sums and its records) and, while the disk
    stores are on (:func:`bench_sim.render.record_store.store_on`: a later pass reads them back
    in a fraction of a second), the scene's records and the grid's rasterised blocks in this
    process's caches. The set-up renders no more frames; its geometry, grid (the panel), info
    and backend stay."""
    engine, setup.engine = setup.engine, None
    if record_store.store_on():
        if isinstance(engine, FastEngine):
            forget_records(engine.records.key)
        setup.grid.drop_blocks()


def records_group(cfg: BenchConfig, engine: str | None = None) -> str | None:
    """What the passes of ``cfg`` that can share one set of light records have in common (their
    records' key before Mitsuba resolves its variant), or ``None`` when the pass renders with the
    reference engine (no records). Computed from the config alone (no Mitsuba)."""
    if (engine or cfg.render.engine) != "fast":
        return None
    return records_key(cfg, "requested")


def fast_records(cfg: BenchConfig) -> LightRecords:
    """The fast engine's light records of ``cfg``'s scene (from this process's cache, or
    rendered now), ready to hand to other processes (:func:`bench_sim.render.records.install_records`).

    A pass of any config of the same :func:`records_group` on the same machine then finds them
    in its process's cache instead of rendering them. Records this process holds or the disk
    store has need no Mitsuba (it is not imported).
    """
    check_fast_engine_valid(cfg)
    mi, choice, rec = _backend(cfg, "fast")  # held already (or in the disk store): no Mitsuba
    if rec is None:
        rec, _ = light_records(mi, cfg, rig_geometry(cfg), choice.variant)
    return rec.shareable()


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
    mi, choice, records = _backend(cfg, name)
    geom = rig_geometry(cfg)
    grid = run_texture(cfg, geom, first_frame, frames, rng)
    seed = int(rng.integers(0, 2**31 - 1))
    if name == "fast":
        eng: Any = FastEngine(mi, cfg, geom, grid, seed, first_frame, variant=choice.variant, records=records)
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
        "lens_blur": "none (a perfect lens)" if grid.lens is None else grid.lens.otf.source,
        **({"spectra": sources} if (sources := check_spectra(cfg)) else {}),
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
    return RenderSetup(cfg, geom, grid, eng, choice, factor, first_frame, frames, seed, info)


def iter_radiance_frames(setup: RenderSetup, chunk: int = 64) -> Iterator[np.ndarray]:
    """Yield radiance [W m^-2 sr^-1] per pixel per frame in chunks of ``chunk`` frames, shape
    (n, M, N), float32 (:func:`photons_of` makes their photons)."""
    k = setup.first_frame
    end = setup.first_frame + setup.frames
    while k < end:
        k1 = min(k + chunk, end)
        radiance = setup.engine.radiance_frames(k, k1)
        setup.info["mitsuba_renders"] = setup.engine.renders
        setup.info["mitsuba_renders_process"] = mitsuba_render_count()
        yield radiance
        k = k1


def photons_of(setup: RenderSetup, radiance: np.ndarray) -> np.ndarray:
    """Photons per pixel per frame of ``radiance`` (n, m, N) of the sensor's first ``m`` rows
    (:func:`iter_radiance_frames`, all or some of its frames and rows), float64, at least 0.
    Elementwise: a part of a chunk gets the same values as in the whole chunk's photons."""
    photons = radiance * setup.photons_per_radiance[: radiance.shape[1]]
    np.maximum(photons, 0.0, out=photons)
    return photons


def iter_photon_frames(setup: RenderSetup, chunk: int = 64) -> Iterator[np.ndarray]:
    """Yield photons per pixel per frame in chunks of ``chunk`` frames, shape (n, M, N), float64."""
    for radiance in iter_radiance_frames(setup, chunk):
        yield photons_of(setup, radiance)


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
