"""Regions of interest around the slanted edges of a target, found in its reflectance image.

The ``slanted_edges`` target (:func:`bench_sim.rig.target_sources.slanted_edges`) holds dark
squares, each rotated by a few degrees, on a bright ground: every square gives two
near-vertical and two near-horizontal edges. :func:`slanted_edge_rois` finds them in the truth
reflectance of an image (``simulate``'s ``reflectance``: the target as the pixels see it, so
the ROIs are in the image's own pixel grid, whatever the magnification, sync error or start
phase): the dark squares are the connected regions below the midpoint between the darkest and
brightest reflectance; those that lie wholly inside the image give four ROIs, each centred on
one side and covering the middle half of it (the corners left out) and a quarter of the
square's size on either side of the edge.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["EdgeROI", "slanted_edge_rois"]


@dataclass(frozen=True)
class EdgeROI:
    """One edge's ROI ``(x0, y0, x1, y1)`` [pixel indices, ends exclusive] and its orientation:
    ``"vertical"`` (the edge runs down the columns: the SFR along the rows, across the track in
    bench_sim's images) or ``"horizontal"`` (the SFR along the lines: along the track)."""

    roi: tuple[int, int, int, int]
    orientation: str


def slanted_edge_rois(
    reflectance: np.ndarray, min_side_px: int = 24, max_squares: int = 8
) -> list[EdgeROI]:
    """The ROIs of the edges of every dark square wholly inside ``reflectance`` (module docstring).

    Parameters
    ----------
    reflectance
        2-D truth reflectance (0..1) of the image, rows = lines.
    min_side_px
        Smallest square side [px] taken (the ROIs are half a side wide across the edge: the
        e-SFR needs :data:`bench_sim.metrics.sfr.MIN_ACROSS_PX`; ``target.edge_cell_px = 48`` or
        more gives 24 px squares).
    max_squares
        At most this many squares, spread evenly over those found (the cost of a measurement
        stays bounded on long images).

    Returns
    -------
    list of EdgeROI
        In the order of the squares (top to bottom, left to right), four per square: left,
        right (vertical), top, bottom (horizontal). Empty when there is no such square.
    """
    from scipy import ndimage

    r = np.asarray(reflectance, dtype=np.float64)
    lo, hi = np.percentile(r, [1.0, 99.0])
    if not hi > lo:
        return []
    labels, _ = ndimage.label(r < 0.5 * (lo + hi))
    h_img, w_img = r.shape
    squares = []
    for sl in ndimage.find_objects(labels):
        if sl is None:
            continue
        y0, y1, x0, x1 = sl[0].start, sl[0].stop, sl[1].start, sl[1].stop
        inside = y0 >= 1 and x0 >= 1 and y1 <= h_img - 1 and x1 <= w_img - 1
        if inside and min(y1 - y0, x1 - x0) >= min_side_px:
            squares.append((y0, y1, x0, x1))
    if len(squares) > max_squares:
        squares = [squares[int(i)] for i in np.linspace(0, len(squares) - 1, max_squares).round()]
    out: list[EdgeROI] = []
    for y0, y1, x0, x1 in squares:
        h, w = y1 - y0, x1 - x0
        qh, qw = h // 4, w // 4
        boxes = (
            ((x0 - qw, y0 + qh, x0 + qw, y1 - qh), "vertical"),
            ((x1 - qw, y0 + qh, x1 + qw, y1 - qh), "vertical"),
            ((x0 + qw, y0 - qh, x1 - qw, y0 + qh), "horizontal"),
            ((x0 + qw, y1 - qh, x1 - qw, y1 + qh), "horizontal"),
        )
        for (a, b, c, d), orientation in boxes:
            box = (max(a, 0), max(b, 0), min(c, w_img), min(d, h_img))
            out.append(EdgeROI(box, orientation))
    return out
