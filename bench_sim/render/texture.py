"""The target as seen during a run: a reflectance grid aligned with the drum's motion, and the
Mitsuba texture plugin that reads it at the moving material coordinate.

Grid
    Texel ``(a, b)`` sits at along-track material coordinate ``y = y_start + a * h_y`` and axial
    coordinate ``x = x_start + b * h_x``. ``h_y = delta / q`` with ``delta`` the surface travel per
    line period and ``q = target.texels_per_pixel``, so one line period moves the material by
    exactly ``q`` texels: the fast engine then turns the drum by index arithmetic alone.
    ``h_x = object_pixel / q``. The grid covers exactly the material that passes the field of
    view during the run, plus margins.

Plugin
    ``albedo(p, t) = T(y_material(theta(p), t0 + t), x)`` with bilinear interpolation, where
    ``theta(p) = atan2(-p.y, p.z)``, ``t0`` is the frame's start time (an opaque Dr.Jit scalar, so
    changing it reuses the compiled kernel) and ``t`` the ray's time in ``[0, t_int]`` (smear).

Lens
    Through a lens (:func:`bench_sim.rig.lens_psf.lens_otf`: diffraction by default) the texture
    holds the target as the camera sees it, blurred by the lens (:mod:`bench_sim.render.lens_blur`),
    block by block; the grid then reaches the PSF's radius further beyond the field of view.
    Both engines and the pass's truth (``reflectance``) read it so.

Reuse
    A target that is not drawn (no ``image`` or generated layout: the panel follows from
    ``target.*`` alone) rasterises to the same texels on the same grid, so the rasterised blocks
    of the last such grid are kept for the process (:data:`SHARED_GRIDS`): the next pass over it
    (a sweep point that changes the lights, the sensor's noise, DTDI or fusion) reads them
    instead of rasterising again. Each texel depends on its own centre only, so a block is the
    same whichever pass made it.
"""

from __future__ import annotations

import functools
import json
import threading
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.render import texture_store
from bench_sim.render.lens_blur import TextureLens, texture_lens
from bench_sim.rig.geometry import RigGeometry
from bench_sim.rig.target import TargetPanel, make_panel, rasterize_at
from bench_sim.rig.target_sources import MAP_LAYOUTS, SlantedEdgeMap
from bench_sim.runtime.parallel import parallel_map, thread_count

__all__ = ["RunTexture", "run_texture", "drum_texture", "smear_filter", "ground_truth_reflectance"]

_MARGIN_PX = 6.0
#: Texel rows per rasterised block, and the most blocks a texture keeps (least recently used
#: dropped; a texture keeps fewer when its pass reads fewer at once: :func:`blocks_read_at_once`)
BLOCK_ROWS = 256
CACHE_BLOCKS = 12
#: Frames of the fast engine's longest window, and lines of the truth's longest band (at least
#: ``bench_sim.pipeline.RENDER_CHUNK_FRAMES`` and ``TRUTH_BAND_LINES``; tested)
PASS_WINDOW_FRAMES = 64
#: Grids of a target that is not drawn whose blocks the process keeps between passes
SHARED_GRIDS = 1


class _Blocks:
    """A texture's cache of rasterised blocks of rows (thread-safe)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.blocks: OrderedDict[int, np.ndarray] = OrderedDict()


@dataclass(frozen=True, eq=False)
class RunTexture:
    """Reflectance on a motion-aligned grid (see module docstring), rasterised on demand.

    Grid row ``r`` is the absolute texel row ``a0 + r`` (at ``y = (a0 + r) h_y``); column ``b``
    sits at ``x = x_start + b h_x``. :meth:`rows` rasterises blocks of :data:`BLOCK_ROWS` rows as
    they are asked for and keeps the last :data:`CACHE_BLOCKS`, so a pass that walks along the
    grid holds a few blocks whatever its length; :attr:`values` rasterises the whole grid (the
    reference engine's Mitsuba texture needs it).
    """

    y_start_m: float
    h_y_m: float
    x_start_m: float
    h_x_m: float
    q: int
    panel: TargetPanel
    n_rows: int
    n_cols: int
    #: panel coordinate [object pixels] of column 0, and of one texel along / across the track
    v0_px: float
    hu_px: float
    hv_px: float
    #: the lens' blur of the texture (:mod:`bench_sim.render.lens_blur`), ``None``: a perfect lens
    lens: TextureLens | None = None
    _blocks: _Blocks = field(default_factory=_Blocks, repr=False)
    #: what makes the grid's blocks, as text (:mod:`bench_sim.render.texture_store`); ``None``: not
    #: stored (a target read from a file or drawn as a whole map)
    store_key: str | None = None
    #: blocks kept (:func:`blocks_read_at_once`, at most :data:`CACHE_BLOCKS`)
    cache_blocks: int = CACHE_BLOCKS

    @property
    def shape(self) -> tuple[int, int]:
        return (self.n_rows, self.n_cols)

    @property
    def a0(self) -> int:
        """Absolute index of the grid's first texel row (texel row ``A`` sits at ``y = A h_y``)."""
        return round(self.y_start_m / self.h_y_m)

    def _rasterize(self, r0: int, r1: int) -> np.ndarray:
        u = (self.a0 + np.arange(r0, r1)) * self.hu_px
        v = self.v0_px + np.arange(self.n_cols) * self.hv_px
        # columns in bands on the pool: each texel depends on its own centre only
        bands = np.array_split(np.arange(self.n_cols), max(1, min(thread_count(), 8)))
        parts = parallel_map(
            lambda cols: rasterize_at(self.panel, u, self.hu_px, v[cols], self.hv_px),
            [b for b in bands if b.size],
        )
        return np.concatenate(parts, axis=1) if len(parts) > 1 else parts[0]

    def _made_block(self, b: int) -> np.ndarray:
        """Block ``b``'s rows: rasterised and, through a lens, blurred with its margins."""
        r0, r1 = b * BLOCK_ROWS, min((b + 1) * BLOCK_ROWS, self.n_rows)
        if self.lens is None:
            return self._rasterize(r0, r1)
        m = self.lens.margin_rows
        lo, hi = max(r0 - m, 0), min(r1 + m, self.n_rows)
        return self.lens.apply(self._rasterize(lo, hi), m - (r0 - lo), m - (hi - r1))

    def _stored_block(self, b: int) -> np.ndarray:
        """Block ``b`` from the texture store (:mod:`bench_sim.render.texture_store`: the same
        bytes), else made and stored."""
        if self.store_key is None:
            return self._made_block(b)
        key = f"{self.store_key}|{b}"
        shape = (min((b + 1) * BLOCK_ROWS, self.n_rows) - b * BLOCK_ROWS, self.n_cols)
        got = texture_store.load(key, shape)
        if got is None:
            got = self._made_block(b)
            texture_store.save(key, got)
        return got

    def _block(self, b: int) -> np.ndarray:
        blocks = self._blocks.blocks
        got = blocks.get(b)
        if got is None:
            got = self._stored_block(b)
            blocks[b] = got
            while len(blocks) > self.cache_blocks:
                blocks.popitem(last=False)
        else:
            blocks.move_to_end(b)
        return got

    def rows(self, r0: int, r1: int) -> np.ndarray:
        """Reflectance of grid rows ``r0 .. r1 - 1``, shape (r1 - r0, nx), float32 (a new array)."""
        if not 0 <= r0 <= r1 <= self.n_rows:
            raise ValueError(f"rows {r0}..{r1} outside the run texture's 0..{self.n_rows}")
        if "values" in self.__dict__:
            return self.values[r0:r1].copy()
        out = np.empty((r1 - r0, self.n_cols), dtype=np.float32)
        with self._blocks.lock:
            for b in range(r0 // BLOCK_ROWS, -(-r1 // BLOCK_ROWS)):
                lo, hi = max(r0, b * BLOCK_ROWS), min(r1, (b + 1) * BLOCK_ROWS)
                if hi > lo:
                    out[lo - r0 : hi - r0] = self._block(b)[lo - b * BLOCK_ROWS : hi - b * BLOCK_ROWS]
        return out

    def drop_blocks(self) -> None:
        """Forget the rasterised blocks held (shared with later passes over the same grid): read
        again from the texture store, or rasterised, when next asked for (the same values)."""
        with self._blocks.lock:
            self._blocks.blocks.clear()

    @property
    def held_bytes(self) -> int:
        """Bytes of rasterised texels the texture holds now (its blocks, or the whole grid)."""
        if "values" in self.__dict__:
            return int(self.values.nbytes)
        with self._blocks.lock:
            return int(sum(b.nbytes for b in self._blocks.blocks.values()))

    @functools.cached_property
    def values(self) -> np.ndarray:
        """The whole grid, (ny, nx) float32 (rasterised once, then kept)."""
        if self.lens is None:
            return self._rasterize(0, self.n_rows)
        return np.concatenate([self._made_block(b) for b in range(-(-self.n_rows // BLOCK_ROWS))])


_shared_lock = threading.Lock()
_shared: OrderedDict[str, _Blocks] = OrderedDict()


def _blocks_for(cfg: BenchConfig, circumference_px: float, grid: tuple[float | int | str, ...]) -> _Blocks:
    """The block cache of a grid: shared with the earlier passes over the same grid of the same
    target when the target is not drawn (see the module docstring), else a new one."""
    if cfg.target.layout in MAP_LAYOUTS:
        return _Blocks()
    key = json.dumps([cfg.target.model_dump(mode="json"), circumference_px, grid, BLOCK_ROWS])
    with _shared_lock:
        blocks = _shared.pop(key, None) or _Blocks()
        _shared[key] = blocks
        while len(_shared) > SHARED_GRIDS:
            _shared.popitem(last=False)
    return blocks


def blocks_read_at_once(rows: int, q: int) -> int:
    """The blocks a pass of a sensor of ``rows`` rows over a grid of ``q`` texel rows per line
    reads at once, at most :data:`CACHE_BLOCKS`: the fast engine's window (the rows' footprints
    over :data:`PASS_WINDOW_FRAMES` frames) and, beside it, the truth's band of as many lines over
    the same rows, each over one more block than it spans."""
    span = -(-(int(rows) + PASS_WINDOW_FRAMES) * int(q) // BLOCK_ROWS)
    return min(CACHE_BLOCKS, 2 * (span + 1))


def run_texture(
    cfg: BenchConfig, geom: RigGeometry, first_frame: int, frames: int, rng: np.random.Generator | None = None
) -> RunTexture:
    """The target grid for frames ``first_frame .. first_frame + frames - 1`` (``rng``: the
    run's generator, for generated targets). Nothing is rasterised yet (see :class:`RunTexture`)."""
    p = geom.object_pixel_m
    q = cfg.target.texels_per_pixel
    h_y = geom.delta_m / q
    h_x = p / q
    lens = texture_lens(cfg, geom, h_y, h_x)
    # the lens reads the target beyond the field of view by its PSF's reach
    margin_px = _MARGIN_PX + (0.0 if lens is None else lens.otf.radius_m / cfg.sensor.pixel_pitch_m)
    th = geom.row_theta_rad
    t0 = first_frame * geom.line_period_s
    t1 = (first_frame + frames - 1) * geom.line_period_s + geom.t_int_s
    y_lo = float(geom.y_material(th.max(), t0)) - margin_px * p
    y_hi = float(geom.y_material(th.min(), t1)) + margin_px * p
    # anchor the grid at y = 0 (scene line 0) so that runs starting at other frames share nodes
    a0 = int(np.floor(y_lo / h_y))
    ny = int(np.ceil(y_hi / h_y)) - a0 + 1
    half_w = 0.5 * cfg.sensor.columns * p * 1.01 + margin_px * p
    nx = int(np.ceil(2 * half_w / h_x)) + 1
    x_start = -0.5 * (nx - 1) * h_x
    circumference_px = 2 * np.pi * geom.radius_m / p
    panel = make_panel(cfg.target, circumference_px, rng)
    # panel coordinates: u = y / p (lines), v = x / p + columns / 2
    v0_px, hu_px, hv_px = x_start / p + cfg.target.panel_columns / 2.0, h_y / p, h_x / p
    grid_key: tuple[float | int | str, ...] = (a0, ny, nx, v0_px, hu_px, hv_px)
    grid_key += () if lens is None else (lens.key,)
    blocks = _blocks_for(cfg, float(circumference_px), grid_key)
    return RunTexture(
        a0 * h_y, h_y, x_start, h_x, q, panel, ny, nx, v0_px=v0_px, hu_px=hu_px, hv_px=hv_px, lens=lens,
        _blocks=blocks, store_key=_store_key(cfg, panel, float(circumference_px), grid_key, lens),
        cache_blocks=blocks_read_at_once(cfg.sensor.rows, q),
    )


def _store_key(cfg: BenchConfig, panel: TargetPanel, circumference_px: float,
               grid: tuple[float | int | str, ...], lens_blur: TextureLens | None) -> str | None:
    """What makes a grid's blocks (:attr:`RunTexture.store_key`): the target, the drum, the grid,
    the lens and, for a drawn target evaluated where it is read, its map's own key."""
    tm = panel.texture_map
    if tm is not None and not isinstance(tm, SlantedEdgeMap):
        return None
    drawn = None if tm is None else tm.key
    lens = None if lens_blur is None else lens_blur.exact_key
    return json.dumps([cfg.target.model_dump(mode="json"), circumference_px, grid, BLOCK_ROWS, drawn, lens])


def smear_filter(values: np.ndarray, h_y_m: float, smear_m: float) -> np.ndarray:
    """Box-filter along the track: ``A_s(y) = (1/S) * int_0^S A(y + s) ds`` for the piecewise-linear
    interpolant of ``values`` (axis 0), evaluated at the grid nodes; ``S = smear_m``.

    Exact for the linear interpolant: the integral is the cumulative trapezoid plus the exact
    partial segment. Nodes within ``S`` of the end use the last value beyond it (edge clamp).
    """
    if smear_m <= 0:
        return values.astype(np.float32)
    n = values.shape[0]
    s = smear_m / h_y_m  # in texels
    si = int(round(s))
    if abs(s - si) < 1e-9 and 0 < si < n:
        # whole texels (the usual case, t_int = T): the trapezoid rule over si + 1 nodes is the
        # exact integral of the linear interpolant; the last nodes clamp to the last value
        v32 = np.concatenate([values, np.repeat(values[-1:], si, axis=0)]).astype(np.float32)
        out = 0.5 * (v32[:n] + v32[si : si + n])
        for j in range(1, si):
            out += v32[j : j + n]
        return out / np.float32(si)
    v = values.astype(np.float64)
    cum = np.zeros_like(v)
    np.cumsum(0.5 * (v[1:] + v[:-1]), axis=0, out=cum[1:])

    def integral_to(pos: np.ndarray) -> np.ndarray:
        # integral of the linear interpolant from node 0 to position pos (texel units)
        pos = np.clip(pos, 0, n - 1)
        i = np.minimum(np.floor(pos).astype(int), n - 2)
        f = (pos - i)[:, None] if v.ndim > 1 else pos - i
        a, b = v[i], v[i + 1]
        return cum[i] + f * a + 0.5 * f * f * (b - a)

    idx = np.arange(n, dtype=np.float64)
    out = (integral_to(idx + s) - cum) / s
    # past the end the clamped integral shrinks: extend with the last value
    tail = idx + s > n - 1
    if tail.any():
        covered = np.clip(n - 1 - idx[tail], 0, None)
        extra = (s - covered)[:, None] * v[-1][None, :] if v.ndim > 1 else (s - covered) * v[-1]
        out[tail] = (integral_to(idx[tail] + s) - cum[tail] + extra) / s
    return out.astype(np.float32)


_CLASS_CACHE: dict[str, Any] = {}


def _texture_class(mi: Any) -> Any:
    variant = mi.variant()
    if variant in _CLASS_CACHE:
        return _CLASS_CACHE[variant]
    import drjit as dr

    class DrumTargetTexture(mi.Texture):
        """Reflectance of the moving drum target (see module docstring)."""

        def __init__(self, props: Any) -> None:
            super().__init__(props)
            self.t0 = dr.opaque(mi.Float, 0.0)

        def setup(self, grid: RunTexture, geom: RigGeometry, constant: float | None = None,
                  spectrum: dict[str, object] | None = None) -> None:
            self.constant = constant
            # the print's reflectance spectrum (spectral variants), multiplying the pattern
            self.spectrum = None if spectrum is None else mi.load_dict(spectrum)
            ny, nx = grid.shape
            tensor = mi.TensorXf(np.ascontiguousarray(grid.values[:, :, None], dtype=np.float32))
            self.tex = mi.Texture2f(
                tensor, use_accel=False, filter_mode=dr.FilterMode.Linear, wrap_mode=dr.WrapMode.Clamp
            )
            self.R = float(geom.radius_m)
            self.omega = float(geom.omega_rad_s)
            self.y_off = float(geom.y_offset_m)
            # normalised texture coordinate = (coord - start) * scale + 0.5 / n
            self.sy, self.oy = 1.0 / (grid.h_y_m * ny), 0.5 / ny - grid.y_start_m / (grid.h_y_m * ny)
            self.sx, self.ox = 1.0 / (grid.h_x_m * nx), 0.5 / nx - grid.x_start_m / (grid.h_x_m * nx)
            self._mean = float(grid.values.mean())

        def set_frame_start(self, t0_s: float) -> None:
            self.t0 = dr.opaque(mi.Float, float(t0_s))

        def _albedo(self, si: Any) -> Any:
            theta = dr.atan2(-si.p.y, si.p.z)
            y = self.R * (self.omega * (self.t0 + si.time) - theta) + self.y_off
            uv = mi.Point2f(si.p.x * self.sx + self.ox, y * self.sy + self.oy)
            return self.tex.eval(uv)[0]

        def eval(self, si: Any, active: Any = True) -> Any:
            if self.spectrum is not None:
                return self.spectrum.eval(si, active) * self._albedo(si)
            return mi.UnpolarizedSpectrum(self._albedo(si))

        def eval_1(self, si: Any, active: Any = True) -> Any:
            return self._albedo(si)

        def mean(self) -> float:
            return self._mean

        def is_spatially_varying(self) -> bool:
            return True

        def to_string(self) -> str:
            return "DrumTargetTexture[]"

    name = f"bench_sim_drum_target_{variant}"
    mi.register_texture(name, lambda props: DrumTargetTexture(props))
    _CLASS_CACHE[variant] = name
    return name


def drum_texture(
    mi: Any, grid: RunTexture, geom: RigGeometry, spectrum: dict[str, object] | None = None
) -> Any:
    """A Mitsuba texture instance showing ``grid`` on the moving drum (times the print's
    reflectance ``spectrum``, a Mitsuba spectrum, in a spectral variant)."""
    name = _texture_class(mi)
    tex = mi.load_dict({"type": name})
    tex.setup(grid, geom, spectrum=spectrum)
    return tex


def ground_truth_reflectance(
    cfg: BenchConfig, geom: RigGeometry, panel: TargetPanel, lines: int
) -> np.ndarray:
    """The target's reflectance behind each output pixel: scene line ``j`` (material at
    ``y = j * delta``) and column ``n`` (``x`` of the column centre on the optical axis),
    box-averaged over the pixel's footprint on the drum (4 x 4 samples). Shape (lines, columns).

    This is the exact ground truth a validation data set is judged against: what a perfect
    sensor in perfect sync would report, divided by the illumination.
    """
    p = geom.object_pixel_m
    n = cfg.sensor.columns
    s = 4
    offs = (np.arange(s) + 0.5) / s - 0.5
    u = np.arange(lines) * geom.delta_m / p
    v = np.arange(n) + 0.5 - n / 2.0 + cfg.target.panel_columns / 2.0
    acc = np.zeros((lines, n), dtype=np.float64)
    for ou in offs:
        for ov in offs:
            acc += panel.reflectance_grid(u + ou * geom.delta_m / p, v + ov)
    return (acc / (s * s)).astype(np.float32)
