"""The printed target: procedural diffuse reflectance patterns on the drum surface.

A target *panel* is defined in object-pixel units: ``u`` along the track (down the output image,
``0 <= u < panel_lines``) and ``v`` across it (``0 <= v < panel_columns``, ``v = panel_columns/2``
on the optical axis). The panel repeats around the drum with period ``period_px``
(the circumference divided into a whole number of panels); the strip between the panel's end
and the next panel is background.

The ``paper`` layout has two identical halves, so the strongly lit part of the field and the part
lit only by the weak fill each carry a full set of elements:

- a step wedge of ``wedge_steps`` steps (log-spaced reflectance from ``reflectance_max`` down to
  ``reflectance_min``), steps stacked along the track;
- a Siemens star (36 spokes);
- bar groups of periods 2, 3, 4, 6, 8, 12 and 16 pixels, across and along the track;
- fine text-like detail (a typeset line of text).

The reflectance function is the ground truth of a validation data set; :func:`rasterize`
box-filters it onto any texel grid.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from bench_sim.config import TargetConfig
from bench_sim.rig.target_sources import MAP_LAYOUTS, SlantedEdgeMap, panel_source

__all__ = ["Patch", "TargetPanel", "make_panel", "rasterize", "rasterize_at", "BAR_PERIODS_PX"]

BAR_PERIODS_PX: tuple[int, ...] = (2, 3, 4, 6, 8, 12, 16)
_TEXT = "BENCH_SIM DTDI-HDR 0123456789 push-broom"


@dataclass(frozen=True)
class Patch:
    """A uniform patch of the target, in panel pixel coordinates (inner region, edges excluded).

    ``u0..u1`` along the track (lines), ``v0..v1`` across (columns), reflectance in 0..1.
    """

    name: str
    reflectance: float
    u0: float
    u1: float
    v0: float
    v1: float


@dataclass(frozen=True)
class TargetPanel:
    """A target panel and its repeat period (object-pixel units)."""

    cfg: TargetConfig
    period_px: float
    patches: tuple[Patch, ...] = field(default=())
    text_bitmap: np.ndarray | None = None  # (rows, cols) coverage 0..1, 8 samples per pixel
    text_box: tuple[float, float, float, float] | None = None  # u0, u1, v0, v1
    #: map layouts (:mod:`bench_sim.rig.target_sources`): (panel_lines q, panel_columns q) texels
    texture_map: np.ndarray | SlantedEdgeMap | None = None

    @property
    def width_px(self) -> int:
        return self.cfg.panel_columns

    def reflectance(self, u_px: np.ndarray, v_px: np.ndarray) -> np.ndarray:
        """Reflectance at panel coordinates (broadcast arrays, object pixels). ``u`` wraps with
        the panel period; outside ``0 <= v < panel_columns`` is background."""
        u = np.mod(np.asarray(u_px, dtype=np.float64), self.period_px)
        v = np.asarray(v_px, dtype=np.float64)
        u, v = np.broadcast_arrays(u, v)
        out = np.full(u.shape, self._base(), dtype=np.float64)
        if self.texture_map is not None:
            inside = (u < self.cfg.panel_lines) & (v >= 0) & (v < self.cfg.panel_columns)
            out[inside] = self._map_at(u[inside], v[inside])
        elif self.cfg.layout == "paper":
            for v_origin in (0.0, self.cfg.panel_columns / 2.0):
                for box, paint in self._elements():
                    m = _inside(u, v - v_origin, box)
                    if m.any():
                        out[m] = paint(u[m], v[m] - v_origin)
        return out.astype(np.float32)

    def reflectance_grid(self, u_px: np.ndarray, v_px: np.ndarray) -> np.ndarray:
        """Reflectance on the grid ``u_px[:, None] x v_px[None, :]`` (1-D inputs), shape
        (len(u), len(v)), float64. Same values as :meth:`reflectance`; each element is painted
        only over its own bounding box, so this is fast on large grids."""
        u = np.mod(np.asarray(u_px, dtype=np.float64), self.period_px)
        v = np.asarray(v_px, dtype=np.float64)
        out = np.full((u.size, v.size), self._base(), dtype=np.float64)
        if self.texture_map is not None:
            iu = np.nonzero(u < self.cfg.panel_lines)[0]
            iv = np.nonzero((v >= 0) & (v < self.cfg.panel_columns))[0]
            if iu.size and iv.size:
                out[np.ix_(iu, iv)] = self._map_grid(u[iu], v[iv])
            return out
        if self.cfg.layout != "paper":
            return out
        for v_origin in (0.0, self.cfg.panel_columns / 2.0):
            vv = v - v_origin
            for (u0, u1, v0, v1), paint in self._elements():
                iu = np.nonzero((u >= u0) & (u < u1))[0]
                iv = np.nonzero((vv >= v0) & (vv < v1))[0]
                if iu.size == 0 or iv.size == 0:
                    continue
                # the painters broadcast: what depends on u alone is computed once per row
                value = np.broadcast_to(paint(u[iu][:, None], vv[iv][None, :]), (iu.size, iv.size))
                ru, rv = _run(iu), _run(iv)
                if isinstance(ru, slice) or isinstance(rv, slice):
                    out[ru, rv] = value
                else:
                    out[np.ix_(iu, iv)] = value
        return out

    def element_box(self, name: str, half: str) -> tuple[float, float, float, float]:
        """Box ``(u0, u1, v0, v1)`` [panel pixels] of a ``paper`` layout element (``"wedge"``,
        ``"star"``, ``"vbars"``, ``"hbars"``, ``"text"``) in the ``"left"`` or ``"right"`` half."""
        u0, u1, v0, v1 = _layout(self.cfg)[name]
        off = 0.0 if half == "left" else self.cfg.panel_columns / 2.0
        return u0, u1, v0 + off, v1 + off

    def _map_index(self, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The texture map's texel rows of ``u`` and columns of ``v`` [panel pixels]."""
        tm = self.texture_map
        assert tm is not None
        iu = np.clip((u * (tm.shape[0] / self.cfg.panel_lines)).astype(np.int64), 0, tm.shape[0] - 1)
        iv = np.clip((v * (tm.shape[1] / self.cfg.panel_columns)).astype(np.int64), 0, tm.shape[1] - 1)
        return iu, iv

    def _map_at(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The texture map's texel containing each panel point (piecewise constant)."""
        assert self.texture_map is not None
        return self.texture_map[self._map_index(u, v)]

    def _map_grid(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """:meth:`_map_at` on the grid ``u[:, None] x v[None, :]`` (1-D arrays)."""
        tm = self.texture_map
        assert tm is not None
        iu, iv = self._map_index(u, v)
        return tm.grid(iu, iv) if isinstance(tm, SlantedEdgeMap) else tm[np.ix_(iu, iv)]

    def _base(self) -> float:
        return self.cfg.uniform_reflectance if self.cfg.layout == "uniform" else self.cfg.background

    def _elements(self) -> list[tuple[tuple[float, float, float, float], Callable[..., np.ndarray]]]:
        """(box, painter) of each element of one half panel; painters map (u, v) -> reflectance
        for points inside the box (half-panel coordinates)."""
        c = self.cfg
        lay = _layout(c)
        lo, hi, bg = c.reflectance_min, c.reflectance_max, c.background
        levels = _wedge_levels(c)

        def wedge(u, v):
            u0, u1 = lay["wedge"][:2]
            step = np.clip(((u - u0) / (u1 - u0) * c.wedge_steps).astype(int), 0, c.wedge_steps - 1)
            return levels[step]

        u0, u1, v0, v1 = lay["star"]
        cu, cv = 0.5 * (u0 + u1), 0.5 * (v0 + v1)
        radius = 0.48 * min(u1 - u0, v1 - v0)

        def star(u, v):
            du, dv = u - cu, v - cv
            spokes = np.where(np.mod(np.floor(np.arctan2(du, dv) / (2 * np.pi) * 72), 2) == 0, hi, lo)
            return np.where(du * du + dv * dv < radius * radius, spokes, bg)

        def bars(key: str, along: bool):
            bu0, _, bv0, bv1 = lay[key]
            n = len(BAR_PERIODS_PX)

            def paint(u, v):
                cellf = (v - bv0) / (bv1 - bv0) * n
                cell = np.clip(cellf.astype(int), 0, n - 1)
                period = np.asarray(BAR_PERIODS_PX, dtype=np.float64)[cell]
                coord = u - bu0 if along else v - (bv0 + cell * (bv1 - bv0) / n)
                b = np.where(np.mod(np.floor(coord / (period / 2.0)), 2) == 0, hi, lo)
                pos = cellf - cell  # a gap of background keeps the groups apart
                return np.where((pos > 0.08) & (pos < 0.92), b, bg)

            return paint

        elements = [
            (lay["wedge"], wedge),
            ((cu - radius, cu + radius, cv - radius, cv + radius), star),
            (lay["vbars"], bars("vbars", False)),
            (lay["hbars"], bars("hbars", True)),
        ]
        if self.text_bitmap is not None:
            bm = self.text_bitmap
            tu0, tu1, tv0, tv1 = lay["text"]

            def text(u, v):
                iu = np.clip(((u - tu0) / (tu1 - tu0) * bm.shape[0]).astype(int), 0, bm.shape[0] - 1)
                iv = np.clip(((v - tv0) / (tv1 - tv0) * bm.shape[1]).astype(int), 0, bm.shape[1] - 1)
                cov = bm[iu, iv]
                return hi * (1 - cov) + lo * cov

            elements.append((lay["text"], text))
        return elements


def _wedge_levels(c: TargetConfig) -> np.ndarray:
    k = np.arange(c.wedge_steps)
    return c.reflectance_max * (c.reflectance_min / c.reflectance_max) ** (k / (c.wedge_steps - 1))


def _layout(c: TargetConfig) -> dict[str, tuple[float, float, float, float]]:
    """Boxes (u0, u1, v0, v1) of the elements in one half panel of width ``w``."""
    H, w = float(c.panel_lines), c.panel_columns / 2.0
    return {
        "wedge": (0.03 * H, 0.97 * H, 0.03 * w, 0.23 * w),
        "star": (0.03 * H, 0.45 * H, 0.26 * w, 0.96 * w),
        "vbars": (0.48 * H, 0.68 * H, 0.26 * w, 0.96 * w),
        "hbars": (0.70 * H, 0.85 * H, 0.26 * w, 0.96 * w),
        "text": (0.88 * H, 0.96 * H, 0.26 * w, 0.96 * w),
    }


def _run(idx: np.ndarray) -> slice | np.ndarray:
    """A slice for a run of consecutive indices (fast assignment), else the indices."""
    if idx[-1] - idx[0] + 1 == idx.size:
        return slice(int(idx[0]), int(idx[-1]) + 1)
    return idx


def _inside(u, v, box):
    u0, u1, v0, v1 = box
    return (u >= u0) & (u < u1) & (v >= v0) & (v < v1)


def _text_bitmap(c: TargetConfig) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    from PIL import Image, ImageDraw, ImageFont

    box = _layout(c)["text"]
    u0, u1, v0, v1 = box
    scale = 8  # bitmap samples per object pixel
    rows, cols = max(int((u1 - u0) * scale), 8), max(int((v1 - v0) * scale), 8)
    img = Image.new("L", (cols, rows), 0)
    draw = ImageDraw.Draw(img)
    size = max(int(rows * 0.7), 6)
    font = ImageFont.load_default(size=size)
    # fit the line of text into the box
    while size > 6 and draw.textlength(_TEXT, font=font) > 0.98 * cols:
        size = int(size * 0.9)
        font = ImageFont.load_default(size=size)
    draw.text((0.01 * cols, 0.1 * rows), _TEXT, fill=255, font=font)
    return np.asarray(img, dtype=np.float32) / 255.0, box


def make_panel(
    cfg: TargetConfig, circumference_px: float, rng: np.random.Generator | None = None
) -> TargetPanel:
    """Build the target panel for a drum of the given circumference (object pixels).

    The repeat period is the circumference divided by the largest whole number of panels of
    ``panel_lines`` that fits (at least one). The map layouts (``image`` and the generated ones,
    :mod:`bench_sim.rig.target_sources`) read their file or draw from a child of ``rng`` (the
    run's generator; its own stream is left as it is).
    """
    n_rep = max(int(circumference_px // cfg.panel_lines), 1)
    period = circumference_px / n_rep
    if cfg.layout in MAP_LAYOUTS:
        child = rng.spawn(1)[0] if rng is not None else None
        return TargetPanel(cfg, period, (), texture_map=panel_source(cfg, child))
    patches: list[Patch] = []
    if cfg.layout == "paper":
        lay = _layout(cfg)
        u0, u1, v0, v1 = lay["wedge"]
        step_h = (u1 - u0) / cfg.wedge_steps
        half = cfg.panel_columns / 2.0
        for side, off in (("left", 0.0), ("right", half)):
            for k, rho in enumerate(_wedge_levels(cfg)):
                a = u0 + k * step_h
                patches.append(
                    Patch(
                        name=f"wedge_{side}_{k:02d}",
                        reflectance=float(rho),
                        u0=a + 0.2 * step_h,
                        u1=a + 0.8 * step_h,
                        v0=off + v0 + 0.2 * (v1 - v0),
                        v1=off + v0 + 0.8 * (v1 - v0),
                    )
                )
        bitmap, box = _text_bitmap(cfg)
        return TargetPanel(cfg, period, tuple(patches), bitmap, box)
    return TargetPanel(cfg, period, ())


def rasterize(
    panel: TargetPanel,
    u0_px: float,
    nu: int,
    hu_px: float,
    v0_px: float,
    nv: int,
    hv_px: float,
    supersample: int = 2,
) -> np.ndarray:
    """Box-filter the panel's reflectance onto a regular texel grid.

    Texel ``(a, b)`` is centred at ``(u0 + a*hu, v0 + b*hv)`` and averages
    ``supersample**2`` point samples over its ``hu x hv`` area.

    Returns
    -------
    numpy.ndarray
        Reflectance, shape (nu, nv), float32.
    """
    return rasterize_at(
        panel, u0_px + np.arange(nu) * hu_px, hu_px, v0_px + np.arange(nv) * hv_px, hv_px, supersample
    )


def rasterize_at(
    panel: TargetPanel, u_px: np.ndarray, hu_px: float, v_px: np.ndarray, hv_px: float, supersample: int = 2
) -> np.ndarray:
    """:func:`rasterize` on the texel centres ``u_px[:, None] x v_px[None, :]`` (1-D arrays,
    panel pixels) of texels ``hu_px x hv_px``. Each texel depends on its own centre only, so any
    split of a grid into pieces gives the same values. Shape (len(u), len(v)), float32."""
    s = max(int(supersample), 1)
    offs = (np.arange(s) + 0.5) / s - 0.5
    ua, va = np.asarray(u_px, dtype=np.float64), np.asarray(v_px, dtype=np.float64)
    acc = np.zeros((ua.size, va.size), dtype=np.float64)
    for ou in offs:
        for ov in offs:
            acc += panel.reflectance_grid(ua + ou * hu_px, va + ov * hv_px)
    return (acc / (s * s)).astype(np.float32)
