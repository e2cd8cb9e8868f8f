"""The rig as a Mitsuba 3 scene: drum (analytic cylinder or trimesh meshes), printed target,
thin-lens (or pinhole) camera and the lights (``[lights.<name>]``: spot, fill, directional,
point, area; by default the strong spot and the weak diffuse fill).

The drum never moves in the scene: it is rotationally symmetric, so turning it is the same as
shifting the target along the track. The target texture (see
:mod:`bench_sim.render.texture`) reads the frame's start time as an opaque Dr.Jit scalar and adds
each ray's time inside the integration window, so frame-to-frame rotation and the motion smear
within a frame reuse one compiled kernel.
"""

from __future__ import annotations

import hashlib
import math
import tempfile
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.rig import spectra
from bench_sim.rig.drum_mesh import drum_meshes
from bench_sim.rig.geometry import RigGeometry

__all__ = [
    "scene_dict",
    "light_names",
    "light_emitter",
    "spot_intensity_w_sr",
    "fill_radiance_w_m2_sr",
    "intensity_w_sr",
    "area_radiance_w_m2_sr",
]


def intensity_w_sr(
    irradiance_w_m2: float, position_m: Sequence[float], reference_m: Sequence[float]
) -> float:
    """Radiant intensity [W/sr] of a point-like source (spot inside its beam, point light) that
    gives ``irradiance_w_m2`` on a plane normal to the ray at ``reference_m``: ``E d^2``
    (inverse-square law) with ``d`` the distance from ``position_m``."""
    d = float(np.linalg.norm(np.subtract(reference_m, position_m)))
    return float(irradiance_w_m2) * d * d


def area_radiance_w_m2_sr(irradiance_w_m2: float, size_m: Sequence[float], distance_m: float) -> float:
    """Radiance [W m^-2 sr^-1] of a Lambertian rectangle ``size_m = (w, h)`` that gives
    ``irradiance_w_m2`` at distance ``d`` on its axis, on a plane parallel to it.

    With half sizes ``a = w/2``, ``b = h/2`` (four corner rectangles of the differential-area to
    parallel-rectangle view factor)::

        E = 2 L [ a / sqrt(a^2 + d^2) * atan(b / sqrt(a^2 + d^2))
                + b / sqrt(b^2 + d^2) * atan(a / sqrt(b^2 + d^2)) ]

    which tends to ``L * w * h / d^2`` far away and to ``pi L`` close up.

    References
    ----------
    J. R. Howell, M. P. Mengüç, K. Daun, R. Siegel, *Thermal Radiation Heat Transfer*, 7th ed.,
    CRC Press 2021, view factor catalogue: differential planar element to a parallel rectangle
    with one corner above it (case B-3).
    """
    a, b, d = 0.5 * float(size_m[0]), 0.5 * float(size_m[1]), float(distance_m)
    ra, rb = math.hypot(a, d), math.hypot(b, d)
    per_radiance = 2.0 * (a / ra * math.atan(b / ra) + b / rb * math.atan(a / rb))
    return float(irradiance_w_m2) / per_radiance


def spot_intensity_w_sr(cfg: BenchConfig, name: str = "strong") -> float:
    """Radiant intensity of a spot [W/sr]: ``E_normal * d^2`` at its aim point."""
    s = cfg.lights.get(name)
    return intensity_w_sr(s.irradiance_w_m2, s.position_m, s.aim_m)  # type: ignore[union-attr]


def fill_radiance_w_m2_sr(cfg: BenchConfig, name: str = "weak") -> float:
    """Radiance of a fill (constant environment): ``E / pi``."""
    return cfg.lights.get(name).irradiance_w_m2 / math.pi


def light_names(cfg: BenchConfig) -> tuple[str, ...]:
    """Names of the lights that emit in this bench (enabled, non-zero power), in a fixed order
    (``strong``, ``weak``, then the other ``[lights.<name>]`` by name).

    The scene is linear in each of them: the radiance of any frame is the sum over these lights
    of what the scene shows under that light alone (``scene_dict(..., lights=[name])``), each
    scaled by its relative intensity in that frame (:func:`bench_sim.rig.lights.frame_weights`).
    """
    return tuple(name for name, light in cfg.lights.items() if light.emits)


def _level(cfg: BenchConfig, light: Any, value: float, spectral: bool) -> Any:
    """A light's emission spectrum: uniform (mono) or its spectrum over the band (spectral)."""
    if spectral:
        return spectra.light_spectrum(cfg, light, value)
    return {"type": "uniform", "value": value}


def light_emitter(mi: Any, cfg: BenchConfig, name: str, *, spectral: bool = False) -> dict[str, Any]:
    """The Mitsuba object (emitter, or emitting shape for ``area``) of light ``name``.

    The emitted quantity follows from ``irradiance_w_m2`` in closed form per kind
    (:data:`bench_sim.config.LIGHT_KINDS`): spot and point intensity ``E d^2``
    (:func:`intensity_w_sr`), directional irradiance ``E``, fill radiance ``E / pi``, area
    radiance :func:`area_radiance_w_m2_sr`.
    """
    light = cfg.lights.get(name)
    e = light.irradiance_w_m2
    if light.kind in ("spot", "point"):
        ref = light.aim_m if light.kind == "spot" else light.reference_m
        intensity = _level(cfg, light, intensity_w_sr(e, light.position_m, ref), spectral)
    if light.kind == "spot":
        return {
            "type": "spot",
            "to_world": _look_at(mi, light.position_m, light.aim_m),
            "intensity": intensity,
            "cutoff_angle": light.cutoff_deg,
            "beam_width": light.beam_width_deg,
        }
    if light.kind == "point":
        return {
            "type": "point",
            "position": list(light.position_m),
            "intensity": intensity,
        }
    if light.kind == "directional":
        return {
            "type": "directional",
            "direction": [float(v) for v in np.divide(light.direction, np.linalg.norm(light.direction))],
            "irradiance": _level(cfg, light, e, spectral),
        }
    if light.kind == "fill":
        return {"type": "constant", "radiance": _level(cfg, light, e / math.pi, spectral)}
    if light.kind == "area":
        w, h = light.size_m
        d = float(np.linalg.norm(np.subtract(light.aim_m, light.position_m)))
        radiance = area_radiance_w_m2_sr(e, light.size_m, d)
        return {
            "type": "rectangle",  # [-1, 1]^2 in its local xy plane, emitting along local +z
            "to_world": _look_at(mi, light.position_m, light.aim_m) @ mi.ScalarTransform4f().scale(
                [0.5 * w, 0.5 * h, 1.0]
            ),
            "emitter": {"type": "area", "radiance": _level(cfg, light, radiance, spectral)},
            "bsdf": {"type": "diffuse", "reflectance": {"type": "uniform", "value": 0.0}},  # black back
        }
    raise ValueError(f"light {name!r}: unknown kind {light.kind!r}")  # pragma: no cover - validated


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


_MESH_FOLDER: tempfile.TemporaryDirectory[str] | None = None
_MESH_LOCK = threading.Lock()


def _mesh_files(cfg: BenchConfig) -> dict[str, Path]:
    """PLY files of the drum's meshes, written once per process and drum configuration.

    Mitsuba's ``ply`` shape reads its mesh from a file. The files live in one temporary folder
    per process, removed when the process exits (``TemporaryDirectory``'s finaliser), and are
    named by a hash of ``[drum]`` so a sweep over other keys writes them once.
    """
    with _MESH_LOCK:
        return _mesh_files_locked(cfg)


def _mesh_files_locked(cfg: BenchConfig) -> dict[str, Path]:
    global _MESH_FOLDER
    if _MESH_FOLDER is None:
        _MESH_FOLDER = tempfile.TemporaryDirectory(prefix="bench_sim_mesh_")
    key = hashlib.sha256(cfg.drum.model_dump_json().encode()).hexdigest()[:16]
    folder = Path(_MESH_FOLDER.name) / key
    done = folder / "parts.txt"  # written last: the list of parts whose files are complete
    if not done.is_file():
        folder.mkdir(exist_ok=True)
        meshes = drum_meshes(cfg.drum)
        for name, mesh in meshes.items():
            mesh.export(folder / f"{name}.ply")
        done.write_text("\n".join(meshes))
    return {name: folder / f"{name}.ply" for name in done.read_text().split()}


def _mesh_shapes(mi: Any, cfg: BenchConfig, drum_bsdf: dict[str, Any]) -> dict[str, Any]:
    shapes: dict[str, Any] = {}
    albedo = {"mounts": cfg.drum.mount_albedo, "axle": cfg.drum.mount_albedo, "bench": cfg.drum.bench_albedo}
    for name, path in _mesh_files(cfg).items():
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
    R, L = cfg.drum.radius_m, cfg.drum.length_m
    film = _film(cfg, width, height, spectral=spectral, aov_position=aov_position)
    direct = _direct_integrator(cfg)
    integrator = {"type": "aov", "aovs": "pos:position", "inner": direct} if aov_position else direct
    sensor = _camera(mi, cfg, geom, film, spp)
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
    _add_lights(mi, cfg, scene, direct, lights, spectral=spectral)
    return scene


def _film(cfg: BenchConfig, width: int, height: int, *, spectral: bool, aov_position: bool) -> dict[str, Any]:
    """The film of :func:`scene_dict`: box-filtered ``hdrfilm`` (luminance for mono), ``specfilm``
    with the sensor's response for a spectral render without the position AOV."""
    film: dict[str, Any] = {
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
    return film


def _camera(mi: Any, cfg: BenchConfig, geom: RigGeometry, film: dict[str, Any], spp: int) -> dict[str, Any]:
    """The camera of :func:`scene_dict`: the lens model at ``+z`` looking at the drum's top, its
    shutter open for one integration time ``t_int`` [s]."""
    lens, R = cfg.lens, cfg.drum.radius_m
    D = geom.camera_distance_m
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
    return sensor


def _direct_integrator(cfg: BenchConfig) -> dict[str, Any]:
    """``direct`` (``render.max_depth = 2``) with its sample counts, else ``path``."""
    r = cfg.render
    direct: dict[str, Any] = {
        "type": "direct" if r.max_depth == 2 else "path",
    }
    if r.max_depth == 2:
        direct.update(emitter_samples=r.emitter_samples, bsdf_samples=r.bsdf_samples)
    else:
        direct.update(max_depth=r.max_depth)
    return direct


def _add_lights(
    mi: Any,
    cfg: BenchConfig,
    scene: dict[str, Any],
    direct: dict[str, Any],
    lights: Sequence[str] | None,
    *,
    spectral: bool,
) -> None:
    """Put the emitting lights ``lights`` (``None``: all) into ``scene``; with a fill, steer the
    emitter samples (``direct`` is the integrator in the scene, changed in place)."""
    active = light_names(cfg)
    if lights is not None:
        unknown = [n for n in lights if n not in active]
        if unknown:
            raise ValueError(f"lights {unknown}: not among this bench's emitting lights {list(active)}")
        active = tuple(n for n in active if n in lights)
    for name in active:
        scene[name] = light_emitter(mi, cfg, name, spectral=spectral)
    fills = [n for n in active if cfg.lights.get(n).kind == "fill"]
    if fills:
        # cosine-weighted BSDF sampling is ideal for a uniform fill seen by a diffuse surface:
        # send the emitter samples to the other lights (notes: cuts the fill's noise ~30x), or,
        # with the fill alone, use BSDF samples only
        if len(active) > len(fills):
            scene[fills[0]]["sampling_weight"] = cfg.render.weak_sampling_weight
        elif direct["type"] == "direct":
            direct["emitter_samples"] = 0  # (direct is also the aov integrator's inner one)
