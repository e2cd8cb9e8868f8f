"""Target reflectance maps from image files and from seeded generators.

Each source gives a *panel map*: the reflectance of one target panel on a regular grid of
``texels_per_pixel`` texels per object pixel, shape ``(panel_lines * q, panel_columns * q)``
(rows along the track), values in 0..1. :class:`bench_sim.rig.target.TargetPanel` shows it
around the drum like the procedural layouts (piecewise constant over its texels).

``image`` (``target.image``)
    8/16-bit PNG or TIFF, float TIFF, OpenEXR, NPY. Integer values are scaled to 0..1 by the
    type's maximum, decoded from sRGB (``target.image_encoding = "srgb"``, the default for
    integer files) or taken as linear (``"linear"``, the default for float files), reduced to one
    channel (``target.image_channel``: ``"luminance"`` = Rec. 709 ``Y = 0.2126 R + 0.7152 G +
    0.0722 B`` of the linear RGB, or a channel ``R``, ``G``, ``B``, ``A`` / an EXR channel name),
    fitted to the panel (``target.image_fit``), resampled to the texel grid by area averaging
    (OpenCV ``INTER_AREA``), and mapped into ``[reflectance_min, reflectance_max]`` (integer
    files) or taken as reflectance (float files: must lie in 0..1).

    Fits: ``stretch`` -- the whole image onto the panel (aspect ratio not kept); ``crop`` -- scaled
    to cover the panel with its aspect ratio kept, the centre kept; ``tile`` -- one image pixel per
    object pixel, repeated over the panel.
``dead_leaves``
    The dead-leaves (spot) texture of camera texture-quality measurement: opaque discs with
    radii of density ``~ r**-3`` between ``dead_leaves_radius_min_px`` and
    ``dead_leaves_radius_max_px`` (object pixels), uniform random centres and reflectances
    uniform in ``[reflectance_min, reflectance_max]``, each new disc falling *under* the
    earlier ones, until the panel is covered. Scale invariant between the two radii.
``slanted_edges``
    A grid of ``edge_cell_px``-pixel cells, each holding a dark square (``max(reflectance_max / 4,
    reflectance_min)``, the 4:1 contrast of ISO 12233's edge targets) of half the cell size on a
    bright ground (``reflectance_max``), rotated by its own random angle uniform in
    ``edge_angle_deg +- edge_angle_jitter_deg``: each square gives two near-vertical and two
    near-horizontal slanted edges for the edge-spread function / MTF along and across the track.
``random_bars``
    Bars across the whole panel width, stacked along the track, with widths uniform in
    ``[bar_width_min_px, bar_width_max_px]`` object pixels and reflectances uniform in
    ``[reflectance_min, reflectance_max]``: sharp edges along the track at random positions.

The generators draw from the generator they are given (a child of the run's generator), so the
same seed gives the same target.

References
----------
.. [DL] F. Cao, F. Guichard, H. Hornung, "Dead leaves model for measuring texture quality on a
   digital camera", Proc. SPIE 7537, Digital Photography VI, 2010.
.. [ISO] ISO 12233:2017, Photography -- Electronic still picture imaging -- Resolution and spatial
   frequency responses (slanted-edge SFR).
.. [709] ITU-R BT.709-6, Parameter values for the HDTV standards (luma coefficients).
.. [SRGB] IEC 61966-2-1:1999, Multimedia systems -- Colour measurement -- sRGB (transfer function).
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path

import numpy as np

from bench_sim.config import TargetConfig
from bench_sim.errors import BenchSimError
from bench_sim.io.images import image_file_problem, read_image_data, srgb_to_linear

__all__ = [
    "MAP_LAYOUTS",
    "TargetImageError",
    "srgb_to_linear",
    "read_target_image",
    "check_target_image",
    "fit_to_panel",
    "image_map",
    "dead_leaves",
    "slanted_edges",
    "SlantedEdgeMap",
    "random_bars",
    "panel_map",
    "panel_source",
    "area_resize",
]

#: ``target.layout`` values whose reflectance is a panel map from this module
MAP_LAYOUTS = ("image", "dead_leaves", "slanted_edges", "random_bars")

#: Rec. 709 luminance weights of linear R, G, B
REC709_LUMA = (0.2126, 0.7152, 0.0722)

_MAX_DISCS = 2_000_000


class TargetImageError(BenchSimError):
    """A target image file that is missing, unreadable or has bad values (one line, names it)."""


def _unit_values(arr: np.ndarray, path: str) -> tuple[np.ndarray, bool]:
    """The pixels as float64 0..1 (integers scaled by their type's maximum, floats checked to lie
    in 0..1), shape (H, W) or (H, W, C), and whether the file held integers."""
    is_int = np.issubdtype(arr.dtype, np.integer) or arr.dtype == bool
    if not (is_int or np.issubdtype(arr.dtype, np.floating)):
        raise TargetImageError(f"target.image = {path!r}: unsupported pixel type {arr.dtype}")
    if arr.ndim == 3 and arr.shape[0] in (1, 3, 4) and arr.shape[-1] not in (1, 3, 4):
        arr = np.moveaxis(arr, 0, -1)  # planar TIFF
    if arr.ndim == 3 and arr.shape[-1] == 1:
        arr = arr[..., 0]
    if arr.ndim not in (2, 3) or min(arr.shape[:2]) < 1:
        raise TargetImageError(
            f"target.image = {path!r}: shape {arr.shape} is not an image (H, W) or (H, W, channels)"
        )
    if is_int:
        top = 1 if arr.dtype == bool else np.iinfo(arr.dtype).max
        if arr.dtype != bool and arr.size and arr.min() < 0:
            raise TargetImageError(f"target.image = {path!r}: negative values in a {arr.dtype} image")
        return arr.astype(np.float64) / float(top), True
    vals = arr.astype(np.float64)
    if not np.isfinite(vals).all():
        raise TargetImageError(f"target.image = {path!r}: contains NaN or inf values")
    if vals.min() < 0 or vals.max() > 1:
        raise TargetImageError(
            f"target.image = {path!r}: float values {vals.min():.4g}..{vals.max():.4g} lie outside "
            "0..1 (a float image is taken as reflectance)"
        )
    return vals, False


def _one_channel(vals: np.ndarray, names: list[str] | None, channel: str, enc: str, path: str) -> np.ndarray:
    """The channel ``target.image_channel`` of 0..1 values (``luminance``: Rec. 709 of linear
    R, G, B), decoded from sRGB when ``enc`` is ``"srgb"``."""
    if vals.ndim == 2:
        if channel not in ("luminance", "Y", "R", "G", "B"):
            raise TargetImageError(
                f"target.image = {path!r}: target.image_channel = {channel!r}, but the image has one channel"
            )
        return srgb_to_linear(vals) if enc == "srgb" else vals
    n_ch = vals.shape[-1]
    if names is None:
        names = ["R", "G", "B", "A"][:n_ch] if n_ch in (3, 4) else [str(i) for i in range(n_ch)]
    if channel == "luminance":
        idx = [names.index(c) for c in ("R", "G", "B") if c in names]
        if len(idx) != 3:
            raise TargetImageError(
                f"target.image = {path!r}: target.image_channel = 'luminance' needs R, G, B channels "
                f"(the file has {names}); name one channel"
            )
        rgb = vals[..., idx]
        if enc == "srgb":
            rgb = srgb_to_linear(rgb)
        return rgb @ np.asarray(REC709_LUMA)
    if channel not in names:
        raise TargetImageError(
            f"target.image = {path!r}: target.image_channel = {channel!r} is not a channel of "
            f"the file (it has {names})"
        )
    out = vals[..., names.index(channel)]
    return srgb_to_linear(out) if enc == "srgb" else out


@functools.lru_cache(maxsize=8)
def _read_target_image_cached(
    path: str, mtime_ns: int, encoding: str | None, channel: str
) -> tuple[np.ndarray, bool]:
    try:
        arr, names = read_image_data(path)
    except Exception as exc:  # every reader raises its own kinds
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise TargetImageError(f"target.image = {path!r}: cannot read the file ({msg})") from None
    vals, is_int = _unit_values(np.asarray(arr), path)
    enc = encoding or ("srgb" if is_int else "linear")
    out = np.ascontiguousarray(_one_channel(vals, names, channel, enc, path), dtype=np.float64)
    out.setflags(write=False)
    return out, is_int


def read_target_image(cfg: TargetConfig) -> tuple[np.ndarray, bool]:
    """The target image as linear values 0..1 (one channel) and whether the file held integers.

    Raises :class:`TargetImageError` (one line naming the file and the problem) for a missing,
    unreadable or unsupported file (:func:`bench_sim.io.image_file_problem`), NaN/inf, or float
    values outside 0..1.
    """
    if cfg.image is None:
        raise TargetImageError("target.layout = 'image' needs target.image (a file name)")
    problem = image_file_problem(cfg.image)
    if problem is not None:
        raise TargetImageError(f"target.image = {cfg.image!r}: {problem}")
    p = Path(cfg.image).resolve()
    return _read_target_image_cached(str(p), p.stat().st_mtime_ns, cfg.image_encoding, cfg.image_channel)


def check_target_image(cfg: TargetConfig) -> None:
    """Read and check ``target.image`` when the layout is ``image`` (before any rendering)."""
    if cfg.layout == "image":
        read_target_image(cfg)


def area_resize(img: np.ndarray, rows: int, cols: int) -> np.ndarray:
    """Area-averaging resample (OpenCV INTER_AREA: exact box averages when shrinking)."""
    import cv2

    if img.shape == (rows, cols):
        return img.astype(np.float64)
    return cv2.resize(img.astype(np.float64), (cols, rows), interpolation=cv2.INTER_AREA)


def fit_to_panel(img: np.ndarray, fit: str, panel_lines: int, panel_columns: int, q: int) -> np.ndarray:
    """Fit a one-channel image to the panel's texel grid ``(panel_lines q, panel_columns q)``.

    See the module docstring for ``stretch``, ``crop`` and ``tile``.
    """
    rows, cols = panel_lines * q, panel_columns * q
    h, w = img.shape
    if fit == "stretch":
        return area_resize(img, rows, cols)
    if fit == "crop":
        scale = max(rows / h, cols / w)
        sh, sw = max(round(h * scale), rows), max(round(w * scale), cols)
        big = area_resize(img, sh, sw)
        r0, c0 = (sh - rows) // 2, (sw - cols) // 2
        return big[r0 : r0 + rows, c0 : c0 + cols]
    if fit == "tile":
        texels = np.repeat(np.repeat(img.astype(np.float64), q, axis=0), q, axis=1)
        reps = (-(-rows // texels.shape[0]), -(-cols // texels.shape[1]))
        return np.tile(texels, reps)[:rows, :cols]
    raise BenchSimError(f"target.image_fit = {fit!r}: allowed 'stretch', 'tile' or 'crop'")


def image_map(cfg: TargetConfig) -> np.ndarray:
    """Panel map of ``layout = "image"`` (see the module docstring)."""
    vals, is_int = read_target_image(cfg)
    fitted = fit_to_panel(vals, cfg.image_fit, cfg.panel_lines, cfg.panel_columns, cfg.texels_per_pixel)
    if is_int:
        fitted = cfg.reflectance_min + fitted * (cfg.reflectance_max - cfg.reflectance_min)
    return np.clip(fitted, 0.0, 1.0).astype(np.float32)


def dead_leaves(cfg: TargetConfig, rng: np.random.Generator) -> np.ndarray:
    """Panel map of ``layout = "dead_leaves"`` (see the module docstring; [DL]).

    Discs are drawn in batches; within a batch they are painted last to first (so each disc
    lies under the ones drawn before it), and a batch only fills what earlier batches left
    uncovered, until nothing is. Discs are rasterised by OpenCV with 1/16-texel precision.
    """
    import cv2

    q = cfg.texels_per_pixel
    rows, cols = cfg.panel_lines * q, cfg.panel_columns * q
    r_min, r_max = cfg.dead_leaves_radius_min_px * q, cfg.dead_leaves_radius_max_px * q
    out = np.full((rows, cols), np.nan, dtype=np.float32)
    holes = np.ones((rows, cols), dtype=bool)
    drawn = 0
    sub = 16  # fixed-point sub-texel steps of cv2's drawing (shift = 4)
    while holes.any():
        if drawn >= _MAX_DISCS:
            raise BenchSimError(
                f"target.dead_leaves_radius_min_px = {cfg.dead_leaves_radius_min_px}: {_MAX_DISCS} discs "
                "did not cover the panel; raise the smallest radius"
            )
        batch = 65536
        # radius density ~ r^-3 on [r_min, r_max]: inverse transform of its CDF
        u = rng.random(batch)
        radius = 1.0 / np.sqrt(u / r_max**2 + (1.0 - u) / r_min**2)
        cy = rng.random(batch) * rows
        cx = rng.random(batch) * cols
        value = rng.uniform(cfg.reflectance_min, cfg.reflectance_max, batch)
        layer = np.full((rows, cols), np.nan, dtype=np.float32)
        for k in range(batch - 1, -1, -1):
            centre = (int((cx[k] - 0.5) * sub), int((cy[k] - 0.5) * sub))
            cv2.circle(layer, centre, int(radius[k] * sub), float(value[k]), -1, cv2.LINE_8, 4)
        out[holes] = layer[holes]
        holes = np.isnan(out)
        drawn += batch
    return out


class SlantedEdgeMap:
    """The panel map of ``layout = "slanted_edges"`` evaluated where it is read: each cell's angle
    is drawn up front (in the order of the whole map), a texel's value is computed from its cell's
    angle when it is indexed (``map[iu, iv]``), with the same operations as :meth:`full`, so the
    values are the same bits; a pass reads the few cells it shows instead of holding the panel's
    ``(panel_lines q, panel_columns q)`` float32 texels (256 MiB at 1024 x 1024 pixels and 8
    texels per pixel)."""

    def __init__(self, cfg: TargetConfig, rng: np.random.Generator) -> None:
        q = cfg.texels_per_pixel
        self.shape = (cfg.panel_lines * q, cfg.panel_columns * q)
        self.cell = cfg.edge_cell_px * q
        self.bright = np.float32(cfg.reflectance_max)
        self.dark = np.float32(max(cfg.reflectance_max / 4.0, cfg.reflectance_min))
        n_r, n_c = -(-self.shape[0] // self.cell), -(-self.shape[1] // self.cell)
        self.cos = np.empty((n_r, n_c))
        self.sin = np.empty((n_r, n_c))
        for i in range(n_r):
            for j in range(n_c):  # one draw per cell, row by row (the map's order)
                ang = np.deg2rad(cfg.edge_angle_deg + cfg.edge_angle_jitter_deg * rng.uniform(-1.0, 1.0))
                self.cos[i, j], self.sin[i, j] = np.cos(ang), np.sin(ang)

    @property
    def key(self) -> str:
        """What makes the map, as text (its size, cells, values and angles)."""
        h = hashlib.sha256(self.cos.tobytes() + self.sin.tobytes()).hexdigest()
        return f"slanted|{self.shape}|{self.cell}|{float(self.bright)!r}|{float(self.dark)!r}|{h}"

    def __getitem__(self, index: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
        """The texels ``(iu, iv)`` (integer arrays of one shape, inside :attr:`shape`)."""
        iu, iv = (np.asarray(i, dtype=np.int64) for i in index)
        ci, cj = iu // self.cell, iv // self.cell
        cos, sin = self.cos[ci, cj], self.sin[ci, cj]
        y = iu + 0.5 - (ci * self.cell + self.cell / 2.0)
        x = iv + 0.5 - (cj * self.cell + self.cell / 2.0)
        half = self.cell / 4.0
        inside = (np.abs(x * cos + y * sin) <= half) & (np.abs(-x * sin + y * cos) <= half)
        return np.where(inside, self.dark, self.bright)

    def grid(self, iu: np.ndarray, iv: np.ndarray) -> np.ndarray:
        """The texels ``iu[:, None] x iv[None, :]`` (1-D integer arrays inside :attr:`shape`), cell by
        cell: the same values as ``self[np.ix_(iu, iv)]`` at a fraction of the cost."""
        iu, iv = np.asarray(iu, dtype=np.int64), np.asarray(iv, dtype=np.int64)
        out = np.empty((iu.size, iv.size), dtype=np.float32)
        ci, cj = iu // self.cell, iv // self.cell
        half = self.cell / 4.0
        for i in np.unique(ci):
            rows = np.nonzero(ci == i)[0]
            y = (iu[rows] + 0.5 - (i * self.cell + self.cell / 2.0))[:, None]
            for j in np.unique(cj):
                cols = np.nonzero(cj == j)[0]
                x = (iv[cols] + 0.5 - (j * self.cell + self.cell / 2.0))[None, :]
                cos, sin = self.cos[i, j], self.sin[i, j]
                inside = (np.abs(x * cos + y * sin) <= half) & (np.abs(-x * sin + y * cos) <= half)
                out[np.ix_(rows, cols)] = np.where(inside, self.dark, self.bright)
        return out

    def full(self) -> np.ndarray:
        """The whole map, ``shape`` float32, painted cell by cell."""
        rows, cols = self.shape
        cell, half = self.cell, self.cell / 4.0  # the square's half side: half the cell
        out = np.full(self.shape, self.bright, dtype=np.float32)
        for i, r0 in enumerate(range(0, rows, cell)):
            for j, c0 in enumerate(range(0, cols, cell)):
                cos, sin = self.cos[i, j], self.sin[i, j]
                cy, cx = r0 + cell / 2.0, c0 + cell / 2.0
                y = (np.arange(r0, min(r0 + cell, rows)) + 0.5 - cy)[:, None]
                x = (np.arange(c0, min(c0 + cell, cols)) + 0.5 - cx)[None, :]
                # coordinates in the square's own (rotated) frame
                inside = (np.abs(x * cos + y * sin) <= half) & (np.abs(-x * sin + y * cos) <= half)
                out[r0 : r0 + y.shape[0], c0 : c0 + x.shape[1]][inside] = self.dark
        return out


def slanted_edges(cfg: TargetConfig, rng: np.random.Generator) -> np.ndarray:
    """Panel map of ``layout = "slanted_edges"`` (see the module docstring; [ISO])."""
    return SlantedEdgeMap(cfg, rng).full()


def random_bars(cfg: TargetConfig, rng: np.random.Generator) -> np.ndarray:
    """Panel map of ``layout = "random_bars"`` (see the module docstring)."""
    q = cfg.texels_per_pixel
    rows, cols = cfg.panel_lines * q, cfg.panel_columns * q
    out = np.empty((rows, cols), dtype=np.float32)
    pos = 0
    while pos < rows:
        width = int(round(rng.uniform(cfg.bar_width_min_px, cfg.bar_width_max_px) * q))
        out[pos : pos + max(width, 1)] = rng.uniform(cfg.reflectance_min, cfg.reflectance_max)
        pos += max(width, 1)
    return out


def panel_source(cfg: TargetConfig, rng: np.random.Generator | None) -> np.ndarray | SlantedEdgeMap:
    """What :class:`bench_sim.rig.target.TargetPanel` reads of a map layout: :func:`panel_map`,
    or for ``slanted_edges`` the same map evaluated where it is read (:class:`SlantedEdgeMap`)."""
    if cfg.layout == "slanted_edges" and rng is not None:
        return SlantedEdgeMap(cfg, rng)
    return panel_map(cfg, rng)


def panel_map(cfg: TargetConfig, rng: np.random.Generator | None) -> np.ndarray:
    """The panel map of a map layout (:data:`MAP_LAYOUTS`), shape
    ``(panel_lines q, panel_columns q)``, float32 reflectance 0..1."""
    if cfg.layout == "image":
        return image_map(cfg)
    if rng is None:
        raise BenchSimError(f"target.layout = {cfg.layout!r} is generated: it needs the run's generator")
    if cfg.layout == "dead_leaves":
        return dead_leaves(cfg, rng)
    if cfg.layout == "slanted_edges":
        return slanted_edges(cfg, rng)
    if cfg.layout == "random_bars":
        return random_bars(cfg, rng)
    raise BenchSimError(f"target.layout = {cfg.layout!r} is not a map layout ({', '.join(MAP_LAYOUTS)})")
