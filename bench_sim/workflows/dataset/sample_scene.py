"""The scene of each sample of a dataset: where its window sits on the rig and how much light it
gets relative to the camera's full scale (a spec's ``[scene]`` table).

::

    [scene]
    window_across_mm = 30.0                                    # fixed: every sample
    window_along_mm = [0.0, 12.0, -12.0]                       # listed: sample i takes entry i % 3
    peak_of_mu2_clip = { dist = "loguniform", low = 0.5, high = 8.0 }   # drawn
    # window_across_mm = "rig"                                 # drawn over the rig's area

- ``window_across_mm``: the window's centre across the track [mm], along the drum axis from the
  bench's optical axis; ``"rig"``: uniform over the drum's length less the window's width.
- ``window_along_mm``: the window's centre along the track [mm], as arc length on the drum
  surface from the bench's view, in the direction the surface moves; ``"rig"``: uniform over the
  whole circumference.
- ``peak_of_mu2_clip``: every light of the sample scaled together so that the brightest pixel's
  noise-free stage-``mu2`` signal (``K eta`` times its photons: no PRNU, no dark signal) is this
  fraction of the stage-``mu2`` word's signal range ``2**beta - 1 - o_mu2`` (above 1: stage
  ``mu2`` clips there). Found from a render of the sample's scene before its pass
  (:func:`peak_signal_fraction`; the renders are linear in the light, so the fraction is then met
  exactly by the fast engine).

A value is a number (every sample), a list of numbers (sample ``i`` takes entry ``i % n``), a
distribution table of :mod:`bench_sim.workflows.dataset.spec` (``uniform``, ``loguniform``,
``normal``, ``choice``) or, for the window, ``"rig"``. Drawn values come from the sample's
parameter stream after its ``[randomize]`` keys, in the order above.

**How the window moves.** The camera stays; the lights move the other way (translated by
``-x0`` along the drum axis, turned by ``-s0 / R`` about it), which is the same scene for the
drum (a cylinder, the same all along its axis and all round it) and its print: the window sees
the same target, lit as if it sat at ``(x0, s0)`` on the rig. With ``drum.geometry = "mesh"`` the
bench plate and the mount stay where they are. The sample's physical coordinates follow
(``across_track_mm`` from ``x0``, :func:`bench_sim.pipeline.physical_coords`); ``s0`` is the
sample coordinate ``window_along_mm``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig, validate_model, with_overrides
from bench_sim.errors import BenchSimError
from bench_sim.fusion.stage_pair import stage_offsets_dn
from bench_sim.pipeline import RENDER_CHUNK_FRAMES
from bench_sim.render.exposures import iter_photon_frames, prepare
from bench_sim.rig.geometry import rig_geometry
from bench_sim.sensor.dtdi import frames_needed
from bench_sim.sensor.model import word_clip_dn
from bench_sim.sensor.stage_truth import StageSums
from bench_sim.workflows.dataset.distributions import DIST_MODELS

__all__ = [
    "SCENE_KEYS", "SceneValue", "parse_scene", "draw_scene", "place_window", "rig_range",
    "peak_signal_fraction", "scale_lights", "SampleScene",
]

#: the keys of ``[scene]`` in the order they are drawn -> what they set
SCENE_KEYS: dict[str, str] = {
    "window_across_mm": "the window's centre across the track, from the optical axis [mm]",
    "window_along_mm": "the window's centre along the track, arc length from the bench's view [mm]",
    "peak_of_mu2_clip": "the brightest pixel's noise-free stage-mu2 signal over the word's signal range",
}
#: the keys that take ``"rig"`` (drawn over the rig's area)
RIG_KEYS = ("window_across_mm", "window_along_mm")


@dataclass(frozen=True)
class SceneValue:
    """One ``[scene]`` entry: ``fixed`` (a number), ``listed`` (numbers), ``dist`` (a
    distribution of :mod:`bench_sim.workflows.dataset.spec`) or ``rig``."""

    key: str
    how: str
    value: Any = None

    def describe(self) -> str:
        if self.how == "dist":
            params = {k: v for k, v in self.value.model_dump().items() if k != "dist"}
            return f"{self.value.dist}(" + ", ".join(f"{k}={v}" for k, v in params.items()) + ")"
        if self.how == "fixed":
            return f"{self.value:g}"
        return f"listed {self.value}" if self.how == "listed" else "over the rig"

    def as_json(self) -> Any:
        return self.value.model_dump() if self.how == "dist" else ("rig" if self.how == "rig" else self.value)


def parse_scene(path: Path, table: Mapping[str, Any]) -> dict[str, SceneValue]:
    """The ``[scene]`` table of the spec ``path``, checked (one-line :class:`BenchSimError`
    naming the key, the value and what is allowed)."""
    out: dict[str, SceneValue] = {}
    for key, v in table.items():
        where = f"{path}: scene.{key}"
        if key not in SCENE_KEYS:
            raise BenchSimError(f"{path}: unknown key 'scene.{key}': allowed {', '.join(SCENE_KEYS)}")
        if isinstance(v, bool):
            raise BenchSimError(f"{where} = {v!r}: expected a number, a list of numbers or a distribution")
        if isinstance(v, int | float):
            out[key] = SceneValue(key, "fixed", _finite(where, v))
        elif isinstance(v, list) and v and all(_number(x) for x in v):
            out[key] = SceneValue(key, "listed", [_finite(where, x) for x in v])
        elif v == "rig" and key in RIG_KEYS:
            out[key] = SceneValue(key, "rig")
        elif isinstance(v, dict) and v.get("dist") in DIST_MODELS and v.get("dist") != "glob":
            dist = validate_model(DIST_MODELS[v["dist"]], v, str(path), f"scene.{key}")
            out[key] = SceneValue(key, "dist", dist)
        else:
            rig = ", 'rig'" if key in RIG_KEYS else ""
            raise BenchSimError(f"{where} = {v!r}: expected a number, a non-empty list of numbers{rig} or "
                                "a table with dist = uniform | loguniform | normal | choice")
        if key == "peak_of_mu2_clip":
            for probe in _probes(out[key]):
                if not (isinstance(probe, int | float) and probe > 0):
                    raise BenchSimError(f"{where}: {probe!r} is not a fraction > 0 of the stage-mu2 clip")
    return {k: out[k] for k in SCENE_KEYS if k in out}


def _number(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool)


def _finite(where: str, v: float) -> float:
    if not math.isfinite(v):
        raise BenchSimError(f"{where} = {v}: must be finite")
    return float(v)


def _probes(sv: SceneValue) -> list[Any]:
    return {"fixed": [sv.value], "listed": list(sv.value or []), "rig": []}.get(sv.how) or sv.value.probes()


def rig_range(cfg: BenchConfig, key: str) -> tuple[float, float]:
    """Where the window's centre can sit on the rig [mm]: across, the drum's length less the
    window's width (``sensor.columns`` projected pixels); along, the whole circumference."""
    if key == "window_along_mm":
        half = math.pi * cfg.drum.radius_m * 1e3
        return -half, half
    half = 0.5 * (cfg.drum.length_m - cfg.sensor.columns * rig_geometry(cfg).object_pixel_m) * 1e3
    if half <= 0:
        raise BenchSimError(f"scene.{key} = 'rig': the window ({cfg.sensor.columns} columns) is wider than "
                            f"the drum (drum.length_m = {cfg.drum.length_m:g})")
    return -half, half


def draw_scene(
    scene: Mapping[str, SceneValue], rng: np.random.Generator, index: int, cfg: BenchConfig
) -> dict[str, float]:
    """The ``[scene]`` values of sample ``index`` (``rng``: its parameter generator, after its
    ``[randomize]`` draws; ``cfg``: its bench, for the rig's area)."""
    out: dict[str, float] = {}
    for key, sv in scene.items():
        if sv.how == "fixed":
            out[key] = float(sv.value)
        elif sv.how == "listed":
            out[key] = float(sv.value[index % len(sv.value)])
        elif sv.how == "rig":
            out[key] = float(rng.uniform(*rig_range(cfg, key)))
        else:
            out[key] = float(sv.value.draw(rng))
    return out


def _turned(v: tuple[float, float, float], angle: float, *, point: bool, shift: float) -> list[float]:
    """A position (``point``) or direction turned by ``angle`` about the drum axis (``x``), in the
    sense of the drum angle ``atan2(-y, z)``, and a position moved by ``shift`` along it."""
    x, y, z = (float(c) for c in v)
    c, s = math.cos(angle), math.sin(angle)
    return [x - shift if point else x, y * c - z * s, z * c + y * s]


def place_window(cfg: BenchConfig, across_mm: float = 0.0, along_mm: float = 0.0) -> BenchConfig:
    """The bench ``cfg`` seen through a window whose centre sits ``across_mm`` along the drum axis
    and ``along_mm`` along the track from the bench's view (module docstring): every light moved
    by ``-across_mm`` along the axis and turned by ``-along_mm / R`` about it."""
    if not across_mm and not along_mm:
        return cfg
    angle = -float(along_mm) * 1e-3 / cfg.drum.radius_m
    shift = float(across_mm) * 1e-3
    lights: dict[str, dict[str, Any]] = {}
    for name, light in cfg.lights.items():
        moved: dict[str, Any] = {}
        for key in ("position_m", "aim_m", "reference_m"):
            if hasattr(light, key):
                moved[key] = _turned(getattr(light, key), angle, point=True, shift=shift)
        if hasattr(light, "direction"):
            moved["direction"] = _turned(light.direction, angle, point=False, shift=0.0)
        if moved:
            lights[name] = moved
    return with_overrides(cfg, {"lights": lights}, source=f"window at {across_mm:g}, {along_mm:g} mm")


def peak_signal_fraction(cfg: BenchConfig, stages: tuple[int, ...], stream: np.random.SeedSequence) -> float:
    """The brightest pixel's noise-free stage-``mu2`` signal over the word's signal range:
    ``K eta max(photons_mu2) / (2**beta - 1 - o_mu2)``, from a render of the pass the sample
    ``stream`` makes of ``cfg`` at ``stages`` (the same target and render seed; no sensor)."""
    mu2, lines = cfg.fusion.mu2, cfg.lines
    setup = prepare(cfg, frames_needed(lines, stages), np.random.default_rng(stream))
    sums = StageSums(cfg.sensor.columns, (mu2,), 1)
    peak, done = 0.0, 0
    for chunk in iter_photon_frames(setup, chunk=RENDER_CHUNK_FRAMES):
        block = sums.push([chunk[:, :mu2]])[mu2][0, : max(lines - done, 0)]
        if block.size:
            peak = max(peak, float(block.max()))
        done += len(block)
    s = cfg.sensor
    top = word_clip_dn(cfg.dtdi.beta_bits) - stage_offsets_dn(cfg, (mu2,))[mu2]
    return s.conversion_gain_dn_per_e * s.quantum_efficiency * peak / top


def scale_lights(cfg: BenchConfig, factor: float) -> BenchConfig:
    """The bench with every light's irradiance times ``factor`` (their ratios kept)."""
    lights = {name: {"irradiance_w_m2": light.irradiance_w_m2 * float(factor)}
              for name, light in cfg.lights.items()}
    return with_overrides(cfg, {"lights": lights}, source=f"lights x {factor:.6g}")


@dataclass(frozen=True)
class SampleScene:
    """What the scene did to a sample: the drawn ``values`` (``[scene]`` keys) and the light
    scale that met ``peak_of_mu2_clip`` (1 without it)."""

    values: dict[str, float]
    light_scale: float = 1.0

    def as_record(self) -> dict[str, float]:
        return {**self.values, "light_scale": self.light_scale}
