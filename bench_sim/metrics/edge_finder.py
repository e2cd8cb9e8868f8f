"""Every slanted edge of an image with a ROI around it, found without help (``bench-sim mtf IMAGE``).

:func:`find_edges` works on any 2-D image (a camera's photograph of a chart, a stage image, a
truth reflectance), with or without invalid pixels:

1. **Gradient.** Invalid pixels (``valid`` False, NaN, inf) take their nearest valid neighbour's
   value; the image is smoothed by a Gaussian of 1 px and its Sobel gradient taken. Pixels whose
   gradient exceeds :data:`GRADIENT_NOISE_FACTOR` times the gradient's robust noise (its median
   absolute deviation) and 2 % of the largest gradient are *edge pixels*, unless within 2 px of
   an invalid pixel.
2. **Edges.** Edge pixels are split by the gradient's direction -- near-vertical edges
   (``|gx| >= |gy|``) rising or falling to the right, near-horizontal ones rising or falling
   downwards -- and each class into 8-connected components: a square's four sides come apart at
   its corners, where the direction turns.
3. **Lines.** In every component at least ``min_length_px`` long the gradient-weighted centroid
   of each row (column, for a near-horizontal edge) is taken and a line ``x = x0 + s y`` fitted.
   A component whose centroids scatter by more than 1 px rms about its line is not straight and
   an angle outside :data:`~bench_sim.metrics.sfr.ANGLE_MIN_DEG` ..
   :data:`~bench_sim.metrics.sfr.ANGLE_MAX_DEG` is not a slanted edge: both are reported with
   the reason and no ROI.
4. **ROI.** The middle of the line (10 % and at least 3 px left out at either end: away from the
   corners) and up to ``half_width_px`` on either side of it, as a rectangle; its width is cut,
   then its length, until it holds no other edge's pixel and no invalid pixel (within 2 px): the
   longest such ROI at least :data:`GOOD_HALF_WIDTH_PX` wide either side, else the widest. An
   edge without a ROI :data:`MIN_HALF_WIDTH_PX` wide either side and ``min_length_px`` long is
   reported with the reason.

The ROIs then go to :func:`bench_sim.metrics.sfr.edge_sfr`, which has the last word on each.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bench_sim.metrics.sfr import ANGLE_MAX_DEG, ANGLE_MIN_DEG

__all__ = ["EdgeCandidate", "find_edges", "GRADIENT_NOISE_FACTOR", "MIN_HALF_WIDTH_PX", "GOOD_HALF_WIDTH_PX"]

#: an edge pixel's gradient exceeds this many times the gradient's noise
GRADIENT_NOISE_FACTOR = 8.0
#: narrowest ROI either side of the edge [px], and the width either side preferred to length
MIN_HALF_WIDTH_PX = 6
GOOD_HALF_WIDTH_PX = 16
_RELATIVE_FLOOR = 0.02
_GUARD_PX = 2
_NOISE_SAMPLES = 1_000_000
_MAX_RMS_PX = 1.0


@dataclass(frozen=True)
class EdgeCandidate:
    """One straight run of edge pixels (:func:`find_edges`).

    Attributes
    ----------
    orientation
        ``"vertical"`` (the edge runs down the columns: an SFR along the rows) or ``"horizontal"``.
    angle_deg
        The fitted line's angle to the nearest pixel axis [deg].
    centre_xy
        The middle of the fitted line [px] (column, row).
    length_px
        Its length along the edge [px].
    roi
        ``(x0, y0, x1, y1)`` [pixel indices, ends exclusive], or ``None`` when ``problem`` says
        why there is none.
    problem
        Why the edge is unusable (not straight, its angle, no room for a ROI), else ``None``.
    """

    orientation: str
    angle_deg: float
    centre_xy: tuple[float, float]
    length_px: float
    roi: tuple[int, int, int, int] | None
    problem: str | None


def _gradient(a: np.ndarray, bad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sobel gradient [units/px] of ``a`` smoothed by a 1-px Gaussian, bad pixels filled first."""
    from scipy import ndimage

    if bad.any():
        if bad.all():
            return np.zeros(a.shape), np.zeros(a.shape)
        idx = ndimage.distance_transform_edt(bad, return_distances=False, return_indices=True)
        a = a[tuple(idx)]
    s = ndimage.gaussian_filter(a, 1.0, mode="nearest")
    return ndimage.sobel(s, axis=1, mode="nearest") / 8.0, ndimage.sobel(s, axis=0, mode="nearest") / 8.0


def _edge_pixels(gx: np.ndarray, gy: np.ndarray, bad: np.ndarray) -> np.ndarray:
    """Where the gradient stands out of its noise (module docstring, step 1)."""
    from scipy import ndimage

    mag = np.hypot(gx, gy)
    sample = gx.ravel()[:: max(1, gx.size // _NOISE_SAMPLES)]  # the noise from at most 1e6 pixels
    noise = 1.4826 * float(np.median(np.abs(sample - np.median(sample))))
    top = float(mag.max()) if mag.size else 0.0
    if not top > 0:
        return np.zeros(mag.shape, dtype=bool)
    strong = mag > max(GRADIENT_NOISE_FACTOR * noise, _RELATIVE_FLOOR * top)
    if bad.any():
        strong &= ~ndimage.binary_dilation(bad, iterations=_GUARD_PX)
    return strong


def _components(gx: np.ndarray, gy: np.ndarray, strong: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """One label image of the edge pixels' components over the four direction classes, and each
    label's orientation (index ``label - 1``)."""
    from scipy import ndimage

    vertical = np.abs(gx) >= np.abs(gy)
    labels = np.zeros(strong.shape, dtype=np.int64)
    kinds: list[str] = []
    for orient, mask in (("vertical", vertical & (gx > 0)), ("vertical", vertical & (gx < 0)),
                         ("horizontal", ~vertical & (gy > 0)), ("horizontal", ~vertical & (gy < 0))):
        lab, n = ndimage.label(strong & mask, structure=np.ones((3, 3)))
        labels[lab > 0] = lab[lab > 0] + len(kinds)
        kinds.extend([orient] * n)
    return labels, kinds


def _fit_line(
    along: np.ndarray, across: np.ndarray, weight: np.ndarray
) -> tuple[float, float, float, int, int]:
    """``(x0, s, rms, first, last)``: the line ``across = x0 + s along`` through the weighted
    centroid of each ``along`` index, its rms scatter [px] and the first and last index."""
    lo = int(along.min())
    n = int(along.max()) - lo + 1
    w = np.bincount(along - lo, weights=weight, minlength=n)
    c = np.bincount(along - lo, weights=weight * across, minlength=n)
    have = w > 0
    t = np.arange(n)[have] + lo
    x = c[have] / w[have]
    if t.size < 3:
        return 0.0, 0.0, float("inf"), lo, lo + n - 1
    s, x0 = np.polyfit(t, x, 1)
    rms = float(np.sqrt(np.mean((x - (x0 + s * t)) ** 2)))
    return float(x0), float(s), rms, lo, lo + n - 1


class _Room:
    """Counts of forbidden pixels (other edges' pixels, invalid ones) in rectangles, O(1) each."""

    def __init__(self, strong: np.ndarray, bad: np.ndarray) -> None:
        self.strong = strong
        self.sat = np.pad((strong | bad).astype(np.int64).cumsum(0).cumsum(1), ((1, 0), (1, 0)))

    def count(self, box: tuple[int, int, int, int], own_y: np.ndarray, own_x: np.ndarray) -> int:
        x0, y0, x1, y1 = box
        total = int(self.sat[y1, x1] - self.sat[y0, x1] - self.sat[y1, x0] + self.sat[y0, x0])
        mine = int(np.count_nonzero((own_y >= y0) & (own_y < y1) & (own_x >= x0) & (own_x < x1)))
        return total - mine


def _box(x0: float, s: float, t0: int, t1: int, h: int, shape: tuple[int, int], vertical: bool
         ) -> tuple[int, int, int, int] | None:
    """The rectangle around the line ``across = x0 + s along`` for ``along`` in ``t0..t1`` and
    ``h`` px either side, in image coordinates; ``None`` where the image cuts it below
    :data:`MIN_HALF_WIDTH_PX` on a side."""
    ends = (x0 + s * t0, x0 + s * t1)
    lo, hi = math.floor(min(ends)) - h, math.ceil(max(ends)) + h + 1
    size_across = shape[1] if vertical else shape[0]
    lo_c, hi_c = max(lo, 0), min(hi, size_across)
    if lo_c > math.floor(min(ends)) - MIN_HALF_WIDTH_PX or hi_c <= math.ceil(max(ends)) + MIN_HALF_WIDTH_PX:
        return None
    return (lo_c, t0, hi_c, t1 + 1) if vertical else (t0, lo_c, t1 + 1, hi_c)


def _roi(line: tuple[float, float, int, int], own: tuple[np.ndarray, np.ndarray], room: _Room,
         vertical: bool, half_width_px: int, min_length_px: int) -> tuple[int, int, int, int] | None:
    """The clear rectangle around the line (module docstring, step 4): the longest that is at
    least :data:`GOOD_HALF_WIDTH_PX` wide either side, else the widest; ``None`` if none."""
    x0, s, first, last = line
    trim = max(3, math.ceil(0.1 * (last - first + 1)))
    t0, t1 = first + trim, last - trim
    best: tuple[int, tuple[int, int, int, int]] | None = None
    while t1 - t0 + 1 >= min_length_px:
        for h in range(half_width_px, MIN_HALF_WIDTH_PX - 1, -1):
            box = _box(x0, s, t0, t1, h, room.strong.shape, vertical)
            if box is None or (best is not None and h <= best[0]):
                continue
            h_img, w_img = room.strong.shape
            grown = (max(box[0] - _GUARD_PX, 0), max(box[1] - _GUARD_PX, 0),
                     min(box[2] + _GUARD_PX, w_img), min(box[3] + _GUARD_PX, h_img))
            if room.count(grown, *own) == 0:
                best = (h, box)
                break
        if best is not None and best[0] >= min(GOOD_HALF_WIDTH_PX, half_width_px):
            break
        step = max(1, (t1 - t0) // 10)
        t0, t1 = t0 + step, t1 - step
    return None if best is None else best[1]


def find_edges(
    image: np.ndarray,
    valid: np.ndarray | None = None,
    *,
    min_length_px: int = 24,
    half_width_px: int = 32,
    max_edges: int = 200,
) -> list[EdgeCandidate]:
    """Every straight edge of ``image`` with its ROI or the reason it has none (module docstring).

    Parameters
    ----------
    image
        2-D array, linear in the signal or not (only where the edges are is read from it).
    valid
        Boolean array of the image's shape, ``False`` at invalid pixels (``None``: all valid but
        NaN and inf).
    min_length_px
        Shortest edge and ROI along the edge [px].
    half_width_px
        Widest ROI either side of the edge [px].
    max_edges
        At most this many edges, the longest.

    Returns
    -------
    list of EdgeCandidate
        In reading order of their centres (top to bottom, then left to right).
    """
    a = np.asarray(image, dtype=np.float64)
    if a.ndim != 2:
        raise ValueError(f"find_edges: a 2-D image is needed, got shape {a.shape}")
    bad = ~np.isfinite(a) if valid is None else (~np.asarray(valid, dtype=bool) | ~np.isfinite(a))
    gx, gy = _gradient(a, bad)
    strong = _edge_pixels(gx, gy, bad)
    labels, kinds = _components(gx, gy, strong)
    if not kinds:
        return []
    sizes = np.bincount(labels.ravel(), minlength=len(kinds) + 1)
    mag = np.hypot(gx, gy)
    room = _Room(strong, bad)
    ys, xs = np.nonzero(labels)
    order = np.argsort(labels[ys, xs], kind="stable")
    ys, xs = ys[order], xs[order]
    bounds = np.concatenate([[0], np.cumsum(sizes[1:])])
    found: list[EdgeCandidate] = []
    for k, orient in enumerate(kinds):
        if sizes[k + 1] < min_length_px:
            continue
        y, x = ys[bounds[k]:bounds[k + 1]], xs[bounds[k]:bounds[k + 1]]
        c = _candidate(orient, y, x, mag[y, x], room, min_length_px, half_width_px)
        if c is not None:
            found.append(c)
    found.sort(key=lambda c: -c.length_px)
    found = found[:max_edges]
    found.sort(key=lambda c: (round(c.centre_xy[1]), c.centre_xy[0]))
    return found


def _candidate(orient: str, y: np.ndarray, x: np.ndarray, w: np.ndarray, room: _Room,
               min_length_px: int, half_width_px: int) -> EdgeCandidate | None:
    """One component's line and ROI (``None`` when it is shorter than ``min_length_px``)."""
    vertical = orient == "vertical"
    along, across = (y, x) if vertical else (x, y)
    if int(along.max()) - int(along.min()) + 1 < min_length_px:
        return None
    x0, s, rms, first, last = _fit_line(along, across, w)
    angle = math.degrees(math.atan(abs(s)))
    mid = 0.5 * (first + last)
    centre = (x0 + s * mid, mid) if vertical else (mid, x0 + s * mid)
    length = (last - first + 1) / math.cos(math.atan(s))
    problem = None
    if not rms <= _MAX_RMS_PX:
        problem = f"not straight: the edge positions scatter by {rms:.2f} px rms about a line"
    elif not ANGLE_MIN_DEG <= angle <= ANGLE_MAX_DEG:
        problem = f"edge angle {angle:.2f} deg: allowed {ANGLE_MIN_DEG:g}..{ANGLE_MAX_DEG:g} deg"
    roi = None
    if problem is None:
        roi = _roi((x0, s, first, last), (y, x), room, vertical, half_width_px, min_length_px)
        if roi is None:
            problem = (f"no room for a ROI: other edges or invalid pixels within {MIN_HALF_WIDTH_PX} px, "
                       f"or less than {min_length_px} px of it clear")
    return EdgeCandidate(orient, angle, (float(centre[0]), float(centre[1])), float(length), roi, problem)
