"""Two rendering engines with one answer: scene radiance per pixel per frame, (frames, M, N).

``reference``
    Mitsuba renders every frame. The drum target texture reads the frame start time (opaque,
    no recompilation) plus each ray's time in the integration window (exact smear).

``fast``
    The factorised engine. With a Lambertian print, direct light only and static lights, the
    radiance a camera sample sees under light ``l`` alone is ``S0_l + albedo(y_material, x) *
    D_l``, where ``D_l`` is what the sample sees on a drum of albedo 1 minus what it sees on a
    drum of albedo 0 (``S0_l``: light from everything that is not the drum's print). The scene is
    linear in each light, so a frame is ``sum_l w_l(k) (S0_l + albedo * D_l)`` with ``w_l(k)``
    the light's power and relative intensity in frame ``k`` (steady lights: constant; flicker:
    :func:`bench_sim.rig.lights.frame_weights`). Mitsuba renders the hit positions once and
    ``S0_l``, ``D_l`` once per light at ``subpixels x subpixels`` records per pixel, at a
    reference power, and the records are cached per process (:mod:`bench_sim.render.records`):
    changing a light's power or flicker, the target, the sensor or DTDI re-renders nothing. Each
    record's bilinear weights on the motion-aligned texture grid (:mod:`bench_sim.render.texture`)
    are summed into a small kernel per pixel and light; since one line period moves the material
    by exactly ``q`` texels, frame ``k`` is the same kernels applied ``k * q`` texels further along
    -- fixed offsets into the texture's phase planes, applied by a compiled loop
    (:mod:`bench_sim.render.frame_kernel`), no lookups. Smear is a box filter of the texture
    along the track (exact for the linear interpolant). Configs where the factorisation is not
    exact (glossy print, indirect light) are refused.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.errors import BenchSimError
from bench_sim.render import kernel_store
from bench_sim.render.frame_kernel import apply_taps
from bench_sim.render.records import (
    REFERENCE_IRRADIANCE_W_M2,
    LightRecords,
    light_power_w_m2,
    light_records,
    render_array,
)
from bench_sim.render.texture import RunTexture, drum_texture, smear_filter
from bench_sim.rig import spectra
from bench_sim.rig.geometry import RigGeometry
from bench_sim.rig.lights import frame_weights
from bench_sim.rig.scene import light_names, scene_dict
from bench_sim.runtime.parallel import parallel_map, thread_count

__all__ = ["ReferenceEngine", "FastEngine", "check_fast_engine_valid", "KERNEL_ENTRIES"]

#: Kernel sets kept with a record set (one per grid: a data set whose drum speed varies per
#: sample makes a new one per sample; the least recently used are dropped)
KERNEL_ENTRIES = 4


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
        self.texture = drum_texture(mi, grid, geom, spectra.reflectance_dict(cfg))
        d = scene_dict(
            mi, cfg, geom, self.texture, width=cfg.sensor.columns, height=cfg.sensor.rows, spp=self.spp,
            spectral=cfg.render.spectral,
        )
        self.scene = mi.load_dict(d)
        self.renders = 0  # Mitsuba renders made by this engine
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
            img = render_array(self.mi, self.scene, self.spp, self.seed * 1_000_003 + k)
            self.renders += 1
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
    """One sensor row's kernels: tap ``(a, b)`` of column ``n`` weighs texel row
    ``base_y + a + k q`` (absolute, frame ``k``) and texel column ``base_x + b + n q``."""

    base_y: int  # absolute texel row (y = index * h_y) of tap 0 at frame 0
    base_x: int  # texel column of tap 0 for column 0 (run texture grid)
    weights: np.ndarray  # (lights, taps_y, taps_x, columns) float32, radiance per unit albedo


class FastEngine:
    """The factorised engine, linear in each light (see module docstring).

    A frame is ``sum_l w_l(k) * (S0_l + kernels_l applied to the smeared texture)``, where the
    records of light ``l`` (:mod:`bench_sim.render.records`, rendered once per process at a
    reference power) are scaled by the light's configured power and ``w_l(k)`` is its mean
    relative intensity over frame ``k`` (:func:`bench_sim.rig.lights.frame_weights`): a change
    of power or flicker needs no render. Lights whose weight is the same over a chunk of frames
    are applied as one combined kernel.
    """

    name = "fast"

    def __init__(
        self, mi: Any, cfg: BenchConfig, geom: RigGeometry, grid: RunTexture, seed: int, first_frame: int = 0,
        *, variant: str | None = None, records: LightRecords | None = None,
    ) -> None:
        """``seed`` is not used: the records are rendered with
        :data:`bench_sim.render.records.RECORD_SEED` (see :mod:`bench_sim.render.records`).
        ``records``: the scene's records already at hand (from the process cache,
        :func:`~bench_sim.render.records.cached_records`); ``mi`` may then be ``None``."""
        check_fast_engine_valid(cfg)
        self.cfg, self.geom, self.grid = cfg, geom, grid
        self.first_frame = int(first_frame)
        if records is not None:
            self.records, self.rendered = records, False
        else:
            self.records, self.rendered = light_records(mi, cfg, geom, variant or mi.variant())
        self.renders = self.records.renders if self.rendered else 0
        # the lights that emit in this bench and their power relative to the records'
        emitting = light_names(cfg)
        self._lights = [
            (li, name, light_power_w_m2(cfg, name) / REFERENCE_IRRADIANCE_W_M2)
            for li, name in enumerate(self.records.lights)
            if name in emitting
        ]
        self.kernels = self._cached_kernels()
        self.records.page_out()  # the kernels made: the records' large arrays not read again
        self._combined: dict[tuple[float, ...], tuple[list[np.ndarray], np.ndarray]] = {}
        # texel rows beyond a smeared row that its box filter reads
        self._smear_rows = int(np.ceil(geom.smear_m / grid.h_y_m)) + 1

    def _cached_kernels(self) -> list[_RowKernel]:
        grid = self.grid
        key = ("kernels", grid.q, grid.h_y_m, grid.h_x_m, grid.x_start_m, self.geom.y_offset_m,
               self.geom.radius_m)
        derived = self.records.derived
        kern = derived.pop(key, None)
        if kern is None:
            kern = self._stored_kernels(key)
        derived[key] = kern  # the most recent last; the oldest dropped beyond KERNEL_ENTRIES
        kept = [k for k in list(derived) if isinstance(k, tuple) and k[:1] == ("kernels",)]
        for old in kept[:-KERNEL_ENTRIES]:
            derived.pop(old, None)
        return kern

    def kernel_key(self, grid_key: tuple[Any, ...]) -> str:
        """The kernels' key in the disk store (:mod:`bench_sim.render.kernel_store`): the records'
        key, the grid's (``grid_key``: floats by their exact repr) and the sensor's rows, columns
        and sub-pixels."""
        cfg = self.cfg
        return json.dumps([self.records.key, repr(grid_key), cfg.sensor.rows, cfg.sensor.columns,
                           cfg.render.subpixels])

    def _stored_kernels(self, grid_key: tuple[Any, ...]) -> list[_RowKernel]:
        """The kernels from the disk store, else derived (:meth:`_kernels`) and stored: the same
        arrays either way."""
        key = self.kernel_key(grid_key)
        stored = kernel_store.load(key)
        if stored is not None:
            return [_RowKernel(by, bx, w) for by, bx, w in stored]
        kern = self._kernels()
        kernel_store.save(key, [(k.base_y, k.base_x, k.weights) for k in kern])
        return kern

    def _kernels(self) -> list[_RowKernel]:
        cfg, geom, grid, rec = self.cfg, self.geom, self.grid, self.records
        M, N, ss, q = cfg.sensor.rows, cfg.sensor.columns, cfg.render.subpixels, grid.q
        n_lights = len(rec.lights)
        pos = rec.position
        theta = np.arctan2(-pos[..., 1].astype(np.float64), pos[..., 2].astype(np.float64))
        fy = geom.y_material(theta, 0.0) / grid.h_y_m  # absolute texel rows at frame 0
        fx = (pos[..., 0].astype(np.float64) - grid.x_start_m) / grid.h_x_m
        col = np.broadcast_to(np.arange(N * ss) // ss, fy.shape)
        valid = rec.hit & np.any(rec.d_rec != 0, axis=0)
        kernels = []
        for i in range(M):
            rows = slice(i * ss, (i + 1) * ss)
            v = valid[rows]
            if not v.any():
                kernels.append(_RowKernel(0, 0, np.zeros((n_lights, 1, 1, N), np.float32)))
                continue
            qy = np.floor(fy[rows]).astype(np.int64)
            ay = (fy[rows] - qy)[v]
            rel = np.floor(fx[rows]).astype(np.int64)
            ax = (fx[rows] - rel)[v]
            rel = rel - col[rows] * q
            by, bx = int(qy[v].min()), int(rel[v].min())
            ty, tx = int(qy[v].max()) - by + 2, int(rel[v].max()) - bx + 2
            qy_v, rel_v, c_v = qy[v] - by, rel[v] - bx, col[rows][v]
            w = np.zeros((n_lights, ty * tx * N), dtype=np.float64)
            for dy, wy in ((0, 1.0 - ay), (1, ay)):
                for dx, wx in ((0, 1.0 - ax), (1, ax)):
                    flat = ((qy_v + dy) * tx + rel_v + dx) * N + c_v
                    for li in range(n_lights):
                        d = rec.d_rec[li, rows][v].astype(np.float64) / (ss * ss)
                        w[li] += np.bincount(flat, weights=d * wy * wx, minlength=w.shape[1])
            kernels.append(_RowKernel(by, bx, w.reshape(n_lights, ty, tx, N).astype(np.float32)))
        nx = grid.shape[1]
        hi_x = max(k.base_x + k.weights.shape[2] + (N - 1) * q for k in kernels)
        if min(k.base_x for k in kernels) < 0 or hi_x > nx:
            raise RuntimeError("fast engine: pixel footprints fall outside the run texture")
        return kernels

    def light_coefficients(self, k0: int, k1: int) -> np.ndarray:
        """(lights, k1 - k0) float64: each light's scale over frames ``k0 .. k1 - 1``: its power
        relative to the records' times its mean relative intensity in each frame."""
        out = np.zeros((len(self.records.lights), k1 - k0), dtype=np.float64)
        for li, name, scale in self._lights:
            out[li] = scale * frame_weights(self.cfg, name, k0, k1)
        return out

    def _combined_kernels(self, coeffs: tuple[float, ...]) -> tuple[list[np.ndarray], np.ndarray]:
        """The kernels and static radiance (M, N) of all lights weighted by ``coeffs`` and summed
        (cached: steady lights keep their coefficients from chunk to chunk)."""
        got = self._combined.get(coeffs)
        if got is None:
            c = np.asarray(coeffs, dtype=np.float32)
            got = (
                [np.tensordot(c, k.weights, axes=1).astype(np.float32) for k in self.kernels],
                np.tensordot(c, self.records.static, axes=1).astype(np.float32),
            )
            self._combined = {coeffs: got}
        return got

    def _window(self, k0: int, k1: int) -> tuple[int, np.ndarray]:
        """Phase planes of the smeared texture for frames ``k0 .. k1 - 1``: ``(w0, planes)``,
        ``planes[a, b, r, c]`` = smeared grid texel ``(w0 + a + r q, b + c q)``, shape (q, q, R,
        C) float32 (the planes padded to one shape; no tap reads the padding)."""
        q, a0 = self.grid.q, self.grid.a0
        lo = min(k.base_y for k in self.kernels) - a0 + k0 * q
        hi = max(k.base_y + k.weights.shape[1] for k in self.kernels) - a0 + (k1 - 1) * q + 1
        w0 = (lo // q) * q
        ny = self.grid.shape[0]
        if w0 < 0 or hi > ny:
            raise RuntimeError("fast engine: frame outside the run texture")
        # the smear reads up to _smear_rows rows further on (clamped at the grid's end, as
        # smear_filter does for the whole grid)
        raw = self.grid.rows(w0, min(hi + self._smear_rows, ny))
        win = smear_filter(raw, self.grid.h_y_m, self.geom.smear_m)[: hi - w0]
        planes = np.zeros((q, q, -(-win.shape[0] // q), -(-win.shape[1] // q)), dtype=np.float32)
        for a in range(q):
            for b in range(q):
                phase = win[a::q, b::q]
                planes[a, b, : phase.shape[0], : phase.shape[1]] = phase
        return w0, planes

    def radiance_frames(self, k0: int, k1: int) -> np.ndarray:
        """Radiance [W m^-2 sr^-1], shape (k1 - k0, rows, columns), float32."""
        cfg, q, a0 = self.cfg, self.grid.q, self.grid.a0
        N = cfg.sensor.columns
        nk = k1 - k0
        coeffs = self.light_coefficients(k0, k1)
        steady = [li for li in range(coeffs.shape[0]) if np.all(coeffs[li] == coeffs[li, 0])]
        varying = [li for li in range(coeffs.shape[0]) if li not in steady]
        steady_coeffs = tuple(float(coeffs[li, 0]) if li in steady else 0.0 for li in range(coeffs.shape[0]))
        combined, static_steady = self._combined_kernels(steady_coeffs)
        static_varying = [(coeffs[li].astype(np.float32)[:, None], self.records.static[li]) for li in varying]
        w0, planes = self._window(k0, k1)
        out = np.empty((nk, cfg.sensor.rows, N), dtype=np.float32)

        def rows(band: range) -> None:
            acc = np.empty((nk, N), dtype=np.float32)
            part = np.empty((nk, N), dtype=np.float32)
            for i in band:
                kern = self.kernels[i]
                # window texel row of tap row 0 at frame k0
                y0 = kern.base_y - a0 + k0 * q - w0
                acc[...] = static_steady[i]
                for w, s0 in static_varying:
                    acc += w * s0[i]
                apply_taps(planes, combined[i], y0, kern.base_x, acc)
                for li in varying:
                    part[...] = 0.0
                    apply_taps(planes, kern.weights[li], y0, kern.base_x, part)
                    part *= coeffs[li].astype(np.float32)[:, None]
                    acc += part
                out[:, i, :] = acc

        # each row is computed whole by one task: the result does not depend on the split
        M = cfg.sensor.rows
        n_bands = min(M, 4 * thread_count())
        parallel_map(rows, [range(M * b // n_bands, M * (b + 1) // n_bands) for b in range(n_bands)])
        return out
