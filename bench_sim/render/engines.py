"""Two rendering engines with one answer: scene radiance per pixel per frame, (frames, M, N).

``reference``
    Mitsuba renders every frame. The drum target texture reads the frame start time (opaque,
    no recompilation) plus each ray's time in the integration window (exact smear).

``fast``
    The factorised engine. With a Lambertian print, direct light only and static lights, the
    radiance a camera sample sees is ``S0 + albedo(y_material, x) * D``, where ``D`` is what the
    sample sees on a drum of albedo 1 minus what it sees on a drum of albedo 0 (``S0``: light from
    everything that is not the drum). Mitsuba renders ``S0``, ``D`` and the hit position once at
    ``subpixels x subpixels`` records per pixel. Each record's bilinear weights on the
    motion-aligned texture grid (:mod:`bench_sim.render.texture`) are summed into a small kernel
    per pixel; since one line period moves the material by exactly ``q`` texels, frame ``k`` is
    the same kernels applied ``k * q`` texels further along -- strided array slices, no lookups.
    Smear is a box filter of the texture along the track (exact for the linear interpolant).
    Configs where the factorisation is not exact (glossy print, indirect light) are refused.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.errors import BenchSimError
from bench_sim.render.texture import RunTexture, drum_texture, smear_filter
from bench_sim.rig.geometry import RigGeometry
from bench_sim.rig.lights import frame_weights
from bench_sim.rig.scene import light_names, scene_dict

__all__ = ["ReferenceEngine", "FastEngine", "check_fast_engine_valid"]


def _render_array(mi: Any, scene: Any, spp: int, seed: int) -> np.ndarray:
    img = mi.render(scene, spp=spp, seed=int(seed) & 0x7FFFFFFF)
    return np.array(img, dtype=np.float32)


#: The Mitsuba parameter holding each kind of light's emitted quantity (under the light's name).
_EMISSION_PARAM = {
    "spot": "intensity",
    "point": "intensity",
    "directional": "irradiance",
    "fill": "radiance",
    "area": "emitter.radiance",
}


class ReferenceEngine:
    """Mitsuba renders every frame (see module docstring).

    Lights that flicker are scaled per frame by their weight
    (:func:`bench_sim.rig.lights.frame_weights`): each one's emission parameter is set to its
    level times the weight as an *opaque* Dr.Jit value before the frame's render, so, like the
    frame's start time, it changes no compiled kernel.
    """

    name = "reference"

    def __init__(
        self, mi: Any, cfg: BenchConfig, geom: RigGeometry, grid: RunTexture, seed: int, first_frame: int = 0
    ) -> None:
        self.mi, self.cfg, self.geom = mi, cfg, geom
        self.spp = cfg.render.spp
        self.seed = int(seed)
        self.texture = drum_texture(mi, grid, geom)
        d = scene_dict(
            mi, cfg, geom, self.texture, width=cfg.sensor.columns, height=cfg.sensor.rows, spp=self.spp,
            spectral=cfg.render.spectral,
        )
        self.scene = mi.load_dict(d)
        self.mitsuba_renders = 0
        # flickering lights: parameter key -> its level at weight 1
        self._params = mi.traverse(self.scene)
        self._levels: dict[str, tuple[str, np.ndarray]] = {}
        for name in light_names(cfg):
            if cfg.lights.get(name).flickers:
                stem = f"{name}.{_EMISSION_PARAM[cfg.lights.get(name).kind]}"
                key = next(k for k in (f"{stem}.value", f"{stem}.values") if k in self._params)
                self._levels[name] = (key, np.array(self._params[key], dtype=np.float64))

    def _set_weights(self, weights: dict[str, float]) -> None:
        import drjit as dr

        for name, (key, level) in self._levels.items():
            value, cls = level * weights[name], type(self._params[key])
            # an array from memory (spectral values) or an opaque scalar: never a literal
            if value.size > 1:
                self._params[key] = cls(value.astype(np.float32))
            else:
                self._params[key] = dr.opaque(cls, float(value[0]))
        self._params.update()

    def radiance_frames(self, k0: int, k1: int) -> np.ndarray:
        """Radiance [W m^-2 sr^-1], shape (k1 - k0, rows, columns), float32."""
        out = np.empty((k1 - k0, self.cfg.sensor.rows, self.cfg.sensor.columns), dtype=np.float32)
        weights = {name: frame_weights(self.cfg, name, k0, k1) for name in self._levels}
        for k in range(k0, k1):
            self.texture.set_frame_start(k * self.geom.line_period_s)
            if weights:
                self._set_weights({name: float(w[k - k0]) for name, w in weights.items()})
            img = _render_array(self.mi, self.scene, self.spp, self.seed * 1_000_003 + k)
            self.mitsuba_renders += 1
            out[k - k0] = img[..., 0]
        return out


def check_fast_engine_valid(cfg: BenchConfig) -> None:
    """Raise :class:`BenchSimError` where the fast engine's factorisation is not exact."""
    if cfg.target.finish != "matte":
        raise BenchSimError(
            f"render.engine = 'fast' with target.finish = {cfg.target.finish!r}: the fast engine is "
            "exact only for a Lambertian (matte) print; use render.engine = 'reference'"
        )
    if cfg.render.max_depth != 2:
        raise BenchSimError(
            f"render.engine = 'fast' with render.max_depth = {cfg.render.max_depth}: the fast engine "
            "is exact only for direct light (max_depth = 2); use render.engine = 'reference'"
        )


@dataclass(frozen=True)
class _RowKernel:
    base_y: int  # texel row of tap 0 at frame 0
    base_x: int  # texel column of tap 0 for column 0
    weights: np.ndarray  # (taps_y, taps_x, columns) float32, radiance per unit albedo


class FastEngine:
    """The factorised engine (see module docstring)."""

    name = "fast"

    def __init__(
        self, mi: Any, cfg: BenchConfig, geom: RigGeometry, grid: RunTexture, seed: int, first_frame: int = 0
    ) -> None:
        check_fast_engine_valid(cfg)
        self.cfg, self.geom, self.grid = cfg, geom, grid
        self.first_frame = int(first_frame)
        M, N, ss = cfg.sensor.rows, cfg.sensor.columns, cfg.render.subpixels
        spp = cfg.render.spp

        spectral = cfg.render.spectral

        def records(albedo: float, aov: bool) -> np.ndarray:
            d = scene_dict(
                mi, cfg, geom, {"type": "uniform", "value": albedo}, width=N * ss, height=M * ss,
                spp=spp, aov_position=aov, spectral=spectral,
            )
            return _render_array(mi, mi.load_dict(d), spp, seed)

        if spectral:
            # radiance from the spectral film; hit positions (per record, averaged) from an aov
            # render with an RGB film: the two cannot share one render in Mitsuba 3.9
            pos = records(1.0, True)[..., -3:]
            rec1 = np.concatenate([records(1.0, False)[..., :1], pos], axis=-1)
        else:
            rec1 = records(1.0, True)
        if cfg.drum.geometry == "analytic":
            # the drum is the only shape: a record either hit it (no light without its albedo)
            # or missed everything (sees the fill, independent of the albedo)
            miss = np.all(rec1[..., 1:4] == 0.0, axis=-1)
            s0 = np.where(miss, rec1[..., 0], 0.0).astype(np.float32)
        else:
            s0 = records(0.0, not spectral)[..., 0]  # same seed, same rays: D is exact per record
        self.static_radiance = s0.reshape(M, ss, N, ss).mean(axis=(1, 3))
        self.kernels = self._kernels(rec1[..., 0] - s0, rec1[..., 1:4])
        smeared = smear_filter(grid.values, grid.h_y_m, geom.smear_m)
        q = grid.q
        # phase planes: plane[a][b][r, c] = smeared[a + r q, b + c q] (contiguous slices)
        self._planes = [
            [np.ascontiguousarray(smeared[a::q, b::q]) for b in range(q)] for a in range(q)
        ]

    def _kernels(self, d_rec: np.ndarray, pos: np.ndarray) -> list[_RowKernel]:
        cfg, geom, grid = self.cfg, self.geom, self.grid
        M, N, ss, q = cfg.sensor.rows, cfg.sensor.columns, cfg.render.subpixels, grid.q
        theta = np.arctan2(-pos[..., 1].astype(np.float64), pos[..., 2].astype(np.float64))
        y0 = geom.y_material(theta, self.first_frame * geom.line_period_s)  # kernels at the first frame
        fy = (y0 - grid.y_start_m) / grid.h_y_m
        fx = (pos[..., 0].astype(np.float64) - grid.x_start_m) / grid.h_x_m
        col = np.broadcast_to(np.arange(N * ss) // ss, fy.shape)
        valid = d_rec != 0
        kernels = []
        for i in range(M):
            rows = slice(i * ss, (i + 1) * ss)
            v = valid[rows]
            d = d_rec[rows].astype(np.float64) / (ss * ss)
            qy = np.floor(fy[rows]).astype(np.int64)
            ay = fy[rows] - qy
            rel = np.floor(fx[rows]).astype(np.int64)
            ax = fx[rows] - rel
            rel = rel - col[rows] * q
            if not v.any():
                kernels.append(_RowKernel(0, 0, np.zeros((1, 1, N), np.float32)))
                continue
            by, bx = int(qy[v].min()), int(rel[v].min())
            ty, tx = int(qy[v].max()) - by + 2, int(rel[v].max()) - bx + 2
            w = np.zeros(ty * tx * N, dtype=np.float64)
            qy_v, rel_v, c_v = qy[v] - by, rel[v] - bx, col[rows][v]
            for dy, wy in ((0, 1.0 - ay[v]), (1, ay[v])):
                for dx, wx in ((0, 1.0 - ax[v]), (1, ax[v])):
                    flat = ((qy_v + dy) * tx + rel_v + dx) * N + c_v
                    w += np.bincount(flat, weights=d[v] * wy * wx, minlength=w.size)
            kernels.append(_RowKernel(by, bx, w.reshape(ty, tx, N).astype(np.float32)))
        ny, nx = grid.shape
        lo = min(k.base_y for k in kernels)
        hi_x = max(k.base_x + k.weights.shape[1] + (N - 1) * q for k in kernels)
        if lo < 0 or min(k.base_x for k in kernels) < 0 or hi_x > nx:
            raise RuntimeError("fast engine: pixel footprints fall outside the run texture")
        return kernels

    def radiance_frames(self, k0: int, k1: int) -> np.ndarray:
        """Radiance [W m^-2 sr^-1], shape (k1 - k0, rows, columns), float32."""
        cfg, q = self.cfg, self.grid.q
        N = cfg.sensor.columns
        nk = k1 - k0
        out = np.empty((nk, cfg.sensor.rows, N), dtype=np.float32)
        acc = np.empty((nk, N), dtype=np.float32)
        tmp = np.empty((nk, N), dtype=np.float32)
        for i, kern in enumerate(self.kernels):
            acc[...] = self.static_radiance[i]
            ty, tx = kern.weights.shape[:2]
            for a in range(ty):
                ya = kern.base_y + a
                r0 = ya // q + k0 - self.first_frame
                for b in range(tx):
                    xb = kern.base_x + b
                    c0 = xb // q
                    plane = self._planes[ya % q][xb % q]
                    if r0 < 0 or r0 + nk > plane.shape[0] or c0 + N > plane.shape[1]:
                        raise RuntimeError("fast engine: frame outside the run texture")
                    np.multiply(plane[r0 : r0 + nk, c0 : c0 + N], kern.weights[a, b], out=tmp)
                    acc += tmp
            out[:, i, :] = acc
        return out
