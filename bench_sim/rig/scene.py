"""The rig as a Mitsuba 3 scene: drum (analytic cylinder or trimesh meshes), printed target,
thin-lens (or pinhole) camera, strong spot and weak diffuse fill.

The drum never moves in the scene: it is rotationally symmetric, so turning it is the same as
shifting the target along the track. The target texture (see
:mod:`bench_sim.render.texture`) reads the frame's start time as an opaque Dr.Jit scalar and adds
each ray's time inside the integration window, so frame-to-frame rotation and the motion smear
within a frame reuse one compiled kernel.
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.rig.geometry import RigGeometry

__all__ = ["scene_dict", "light_names", "spot_intensity_w_sr", "fill_radiance_w_m2_sr"]


def spot_intensity_w_sr(cfg: BenchConfig) -> float:
    """Radiant intensity of the strong spot [W/sr]: ``E_normal * d^2`` at the aim point."""
    s = cfg.lights.strong
    d = float(np.linalg.norm(np.subtract(s.aim_m, s.position_m)))
    return s.irradiance_w_m2 * d * d


def fill_radiance_w_m2_sr(cfg: BenchConfig) -> float:
    """Radiance of the weak fill (constant environment): ``E / pi``."""
    return cfg.lights.weak.irradiance_w_m2 / math.pi


def light_names(cfg: BenchConfig) -> tuple[str, ...]:
    """Names of the lights that emit in this bench (enabled, non-zero power), in a fixed order.

    The scene is linear in each of them: the radiance of any frame is the sum over these lights
    of what the scene shows under that light alone (``scene_dict(..., lights=[name])``), each
    scaled by its relative intensity in that frame (:func:`bench_sim.rig.lights.frame_weights`).
    """
    names = []
    if cfg.lights.strong.enabled and cfg.lights.strong.irradiance_w_m2 > 0:
        names.append("strong")
    if cfg.lights.weak.enabled and cfg.lights.weak.irradiance_w_m2 > 0:
        names.append("weak")
    return tuple(names)


def _look_at(mi: Any, origin, target, up=(0.0, 1.0, 0.0)) -> Any:
    d = np.subtract(target, origin)
    d = d / np.linalg.norm(d)
    if abs(float(np.dot(d, up))) > 0.99:
        up = (1.0, 0.0, 0.0)
    return mi.ScalarTransform4f().look_at(origin=list(origin), target=list(target), up=list(up))


def _drum_bsdf(cfg: BenchConfig, reflectance: Any) -> dict[str, Any]:
    """The print on the drum: Lambertian, or with a rough dielectric coating (glints)."""
    if cfg.target.finish == "glossy":
        return {
            "type": "roughplastic",
            "diffuse_reflectance": reflectance,
            "alpha": cfg.target.gloss_roughness,
            "int_ior": 1.5,
        }
    return {"type": "diffuse", "reflectance": reflectance}


def _mesh_shapes(mi: Any, cfg: BenchConfig, drum_bsdf: dict[str, Any]) -> dict[str, Any]:
    from bench_sim.rig.drum_mesh import drum_meshes

    folder = Path(tempfile.mkdtemp(prefix="bench_sim_mesh_"))
    shapes: dict[str, Any] = {}
    albedo = {"mounts": cfg.drum.mount_albedo, "axle": cfg.drum.mount_albedo, "bench": cfg.drum.bench_albedo}
    for name, mesh in drum_meshes(cfg.drum).items():
        path = folder / f"{name}.ply"
        mesh.export(path)
        if name in ("body", "caps"):
            bsdf = drum_bsdf
        else:
            bsdf = {"type": "diffuse", "reflectance": {"type": "uniform", "value": albedo[name]}}
        shapes[f"drum_{name}" if name in ("body", "caps") else name] = {
            "type": "ply",
            "filename": str(path),
            "face_normals": name != "body",
            "bsdf": bsdf,
        }
    return shapes


def scene_dict(
    mi: Any,
    cfg: BenchConfig,
    geom: RigGeometry,
    reflectance: Any,
    *,
    width: int,
    height: int,
    spp: int,
    aov_position: bool = False,
    spectral: bool = False,
    lights: Sequence[str] | None = None,
) -> dict[str, Any]:
    """Mitsuba scene description of the rig.

    Parameters
    ----------
    mi
        The mitsuba module with its variant set.
    reflectance
        Texture (dict or instance) of the drum's diffuse reflectance.
    width, height
        Film size in film pixels: ``columns * s`` by ``rows * s`` for ``s`` sub-pixels per side.
    aov_position
        Wrap the integrator in an ``aov`` integrator that also outputs the hit position.
    spectral
        Spectral variant: the lights get their spectra and the film records the QE- and
        photon-weighted radiance (``specfilm``, see :mod:`bench_sim.rig.spectra`); with
        ``aov_position`` an ``hdrfilm`` is used instead (Mitsuba's ``aov`` integrator corrupts
        memory with ``specfilm``), whose first channels are not radiance.
    lights
        Names (from :func:`light_names`) of the lights to put in the scene; ``None``: all of
        them. A scene with a subset shows what the bench looks like under those lights alone.
    """
    from bench_sim.rig import spectra
    lens, R, L = cfg.lens, cfg.drum.radius_m, cfg.drum.length_m
    D = geom.camera_distance_m
    film = {
        "type": "hdrfilm",
        "width": int(width),
        "height": int(height),
        "rfilter": {"type": "box"},  # pixel value = mean of its samples
        "sample_border": False,
    }
    if spectral and not aov_position:
        film = {k: v for k, v in film.items() if k != "pixel_format"}
        film.update(type="specfilm", component_format="float32", Y=spectra.response_dict(cfg))
    elif not spectral:
        film["pixel_format"] = "luminance"
    sensor: dict[str, Any] = {
        "type": lens.model,
        "fov": geom.fov_x_deg,
        "fov_axis": "x",
        "to_world": _look_at(mi, (0.0, 0.0, D), (0.0, 0.0, R)),
        "near_clip": 1e-3,
        "far_clip": 10.0 * D,
        "shutter_open": 0.0,
        "shutter_close": float(geom.t_int_s),
        "film": film,
        "sampler": {"type": "independent", "sample_count": int(spp)},
    }
    if lens.model == "thinlens":
        sensor["aperture_radius"] = lens.focal_length_m / (2.0 * lens.f_number)
        sensor["focus_distance"] = lens.focus_m
    r = cfg.render
    direct = {
        "type": "direct" if r.max_depth == 2 else "path",
    }
    if r.max_depth == 2:
        direct.update(emitter_samples=r.emitter_samples, bsdf_samples=r.bsdf_samples)
    else:
        direct.update(max_depth=r.max_depth)
    integrator = {"type": "aov", "aovs": "pos:position", "inner": direct} if aov_position else direct
    scene: dict[str, Any] = {"type": "scene", "integrator": integrator, "sensor": sensor}
    drum_bsdf = _drum_bsdf(cfg, reflectance)
    if cfg.drum.geometry == "analytic":
        scene["drum"] = {
            "type": "cylinder",
            "p0": [-0.5 * L, 0.0, 0.0],
            "p1": [0.5 * L, 0.0, 0.0],
            "radius": R,
            "bsdf": drum_bsdf,
        }
    else:
        scene.update(_mesh_shapes(mi, cfg, drum_bsdf))
    active = light_names(cfg)
    if lights is not None:
        unknown = [n for n in lights if n not in active]
        if unknown:
            raise ValueError(f"lights {unknown}: not among this bench's emitting lights {list(active)}")
        active = tuple(n for n in active if n in lights)
    strong = cfg.lights.strong
    if "strong" in active:
        scene["strong"] = {
            "type": "spot",
            "to_world": _look_at(mi, strong.position_m, strong.aim_m),
            "intensity": spectra.light_spectrum(cfg, strong, spot_intensity_w_sr(cfg))
            if spectral
            else {"type": "uniform", "value": spot_intensity_w_sr(cfg)},
            "cutoff_angle": strong.cutoff_deg,
            "beam_width": strong.beam_width_deg,
        }
    weak = cfg.lights.weak
    if "weak" in active:
        scene["weak"] = {
            "type": "constant",
            "radiance": spectra.light_spectrum(cfg, weak, fill_radiance_w_m2_sr(cfg))
            if spectral
            else {"type": "uniform", "value": fill_radiance_w_m2_sr(cfg)},
        }
        # cosine-weighted BSDF sampling is ideal for a uniform fill seen by a diffuse surface:
        # send the emitter samples to the spot (notes: cuts the fill's noise ~30x), or, with the
        # fill alone, use BSDF samples only
        if scene.get("strong") is not None:
            scene["weak"]["sampling_weight"] = r.weak_sampling_weight
        elif direct["type"] == "direct":
            direct["emitter_samples"] = 0  # (direct is also the aov integrator's inner one)
    return scene
