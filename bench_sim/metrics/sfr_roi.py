"""The region of interest of an e-SFR (:func:`bench_sim.metrics.sfr.edge_sfr`): its bounds in the
image, and its invalid pixels -- not finite, masked (``valid`` False) or clipped (at or above
a saturation level, at or below a floor, or flagged) -- which are left out as NaN; a ROI with
more than 0.1 % of its pixels clipped, or more than :data:`INVALID_MAX_FRACTION` invalid, is
refused (one line)."""

from __future__ import annotations

import numpy as np

from bench_sim.errors import BenchSimError

__all__ = ["INVALID_MAX_FRACTION", "check_roi", "check_roi_bounds", "check_clipping", "mask_roi",
           "invalid_as_nan", "roi_pixels"]

#: a ROI with more than this fraction of clipped pixels is refused
_CLIPPED_MAX_FRACTION = 1e-3
#: a ROI with more than this fraction of invalid (NaN, masked, clipped) pixels is refused
INVALID_MAX_FRACTION = 0.5


def check_roi(shape: tuple[int, ...], roi: tuple[int, int, int, int] | None) -> tuple[int, int, int, int]:
    """``roi`` (``None``: the whole image) checked against a 2-D image of ``shape``."""
    if len(shape) != 2:
        raise BenchSimError(f"image shape {shape}: the e-SFR needs a 2-D (single-channel) image")
    h, w = shape
    if roi is None:
        return 0, 0, w, h
    try:
        x0, y0, x1, y1 = (int(v) for v in roi)
    except (TypeError, ValueError):
        raise BenchSimError(f"roi = {roi!r}: expected four integers x0, y0, x1, y1") from None
    return check_roi_bounds((x0, y0, x1, y1), w, h, f"roi = {x0},{y0},{x1},{y1}")


def check_roi_bounds(
    box: tuple[int, int, int, int], width: int, height: int, given: str
) -> tuple[int, int, int, int]:
    """``box = (x0, y0, x1, y1)`` [pixels, ends exclusive] inside a ``width`` x ``height`` image;
    else one error line that starts with ``given`` (how the caller names the ROI)."""
    x0, y0, x1, y1 = box
    if not (0 <= x0 < x1 <= width and 0 <= y0 < y1 <= height):
        raise BenchSimError(
            f"{given}: must satisfy 0 <= x0 < x1 <= {width} and 0 <= y0 < y1 <= {height} "
            f"(the image is {width} x {height} pixels; ends exclusive)"
        )
    return box


def check_clipping(
    a: np.ndarray, saturation: float | None, floor: float | None, clipped: np.ndarray | None,
    clip_level: float | None, where: str,
) -> None:
    """Refuse a ROI ``a`` with more than 0.1 % of its pixels clipped (any of the three tests)."""
    n = a.size
    checks = []
    with np.errstate(invalid="ignore"):
        if saturation is not None:
            checks.append((a >= saturation, f"at or above saturation ({saturation:g})"))
        if floor is not None:
            checks.append((a <= floor, f"at or below the floor ({floor:g})"))
    if clipped is not None:
        level = "" if clip_level is None else f" ({clip_level:g})"
        checks.append((clipped, f"clipped (at the saturation{level} of the channels read)"))
    for hit, side in checks:
        count = int(np.count_nonzero(hit))
        if count > _CLIPPED_MAX_FRACTION * n:
            raise BenchSimError(
                f"{where}: clipped edge: {count} of {n} pixels are {side}; the e-SFR "
                "needs an unclipped edge (lower the exposure or choose another ROI)"
            )


def mask_roi(
    mask: np.ndarray, shape: tuple[int, ...], box: tuple[int, int, int, int], name: str, where: str
) -> np.ndarray:
    """The ROI of a boolean map of the image (``valid``, ``clipped``), checked for its shape."""
    m = np.asarray(mask)
    if m.shape != tuple(shape):
        raise BenchSimError(f"{where}: the {name}'s shape {m.shape} is not the image's {tuple(shape)}")
    x0, y0, x1, y1 = box
    return m[y0:y1, x0:x1].astype(bool)


def invalid_as_nan(
    raw: np.ndarray, valid: np.ndarray | None, saturation: float | None, floor: float | None, where: str,
) -> tuple[np.ndarray, int]:
    """The ROI's pixels with the invalid ones (not finite, ``valid`` False, clipped) set to NaN,
    and their number; more than :data:`INVALID_MAX_FRACTION` of them is refused."""
    bad = ~np.isfinite(raw)
    if valid is not None:
        bad |= ~valid
    with np.errstate(invalid="ignore"):
        if saturation is not None:
            bad |= raw >= saturation
        if floor is not None:
            bad |= raw <= floor
    count = int(bad.sum())
    if count > INVALID_MAX_FRACTION * raw.size:
        raise BenchSimError(
            f"{where}: {count} of {raw.size} pixels are invalid (NaN, masked or clipped); at most "
            f"{INVALID_MAX_FRACTION:.0%} may be: choose a ROI in the valid part of the image"
        )
    return np.where(bad, np.nan, raw), count


def roi_pixels(
    img: np.ndarray, box: tuple[int, int, int, int], *, saturation: float | None, floor: float | None,
    valid: np.ndarray | None, clipped: np.ndarray | None, clip_level: float | None, where: str,
) -> tuple[np.ndarray, int]:
    """The ROI ``box`` of ``img`` as float64 with its invalid pixels NaN, and their number, after
    refusing a clipped ROI (:func:`check_clipping`) or one mostly invalid (:func:`invalid_as_nan`)."""
    x0, y0, x1, y1 = box
    raw = img[y0:y1, x0:x1].astype(np.float64)
    clip = None if clipped is None else mask_roi(clipped, img.shape, box, "clipped", where)
    check_clipping(raw, saturation, floor, clip, clip_level, where)
    ok = None if valid is None else mask_roi(valid, img.shape, box, "mask", where)
    if clip is not None:
        ok = ~clip if ok is None else ok & ~clip
    return invalid_as_nan(raw, ok, saturation, floor, where)
