"""ISO 12233:2017 edge spatial frequency response (e-SFR) of a slanted edge.

:func:`edge_sfr` measures the SFR (the MTF of a linear system) of a straight edge slanted by a
few degrees against the pixel grid, in any 2-D array and region of interest (ROI), so it works
on bench_sim's stage images and on a real camera's images alike. The steps are those of
ISO 12233:2017, clause 6 and annex D, as in Burns' ``sfrmat3`` [ISO]_ [SFRMAT]_:

1. **Orientation.** The ROI is turned so that the edge runs down its columns (a *vertical*
   edge: the profile is taken along each row) and so that the signal rises from left to right.
2. **Edge location per row.** The row's derivative (the central difference
   ``[-1/2, 0, 1/2]``), weighted by a Hamming window, has its centroid at the edge; a
   first-order polynomial (a line, ``x = x0 + s y``) is fitted to the centroids of all rows,
   the window is re-centred on the line and the fit repeated.
3. **Phase cycles.** The rows used are cut to a whole number of phase cycles,
   ``floor(floor(N |s|) / |s|)``, so every sub-pixel phase is sampled equally.
4. **4x oversampled edge-spread function (ESF).** Every pixel's horizontal distance to the
   fitted line, ``x - x0 - s y``, is put into bins of 1/4 pixel; each bin's mean is the ESF.
   Empty bins (too few phases) are filled from their neighbours.
5. **Line-spread function (LSF).** The ESF's central difference, weighted by a Hamming window
   centred on the LSF's centroid.
6. **SFR.** ``|DFT(LSF)|`` normalised to 1 at zero frequency, divided by the transfer of the
   central difference, ``sinc(2 f d)`` (``d`` the ESF's sample interval along the edge normal;
   the standard's FIR correction, capped at 10).
7. **Frequencies.** Along the edge normal: the ESF's sample interval is ``cos(theta) / 4``
   pixels (``theta`` the edge angle), so ``f_k = k / (n cos(theta) / 4)`` cycles per pixel,
   ``k = 0, 1, ...`` up to the first sample at or past 1 cycle/pixel (twice the Nyquist
   frequency); in cycles/mm with the pixel pitch.

What it measures: the 2-D optical transfer function of the system along the edge's normal.
For a square pixel aperture of side 1 pixel that is ``sinc(f cos theta) sinc(f sin theta)``,
which tends to ``sinc(f)`` at small angles; a rotationally symmetric blur does not depend on
the angle. The 1/4-pixel bin average of step 4 is part of the standard's e-SFR and is *not*
divided out: it multiplies the response by ``sinc(f cos(theta) / 4)`` (0.974 at the Nyquist
frequency, 0.90 at 1 cycle/pixel).

Direction convention in bench_sim's images (rows = lines = along the track, columns across):
a near-*horizontal* edge (its normal along the lines) gives the **along-track** SFR, a
near-*vertical* edge the **across-track** SFR (:attr:`SFRResult.orientation`).

The input is taken as linear in the signal (no OECF is applied); a camera's gamma-encoded
image must be linearised first.

References
----------
.. [ISO] ISO 12233:2017, Photography -- Electronic still picture imaging -- Resolution and
   spatial frequency responses, clause 6 and annex D (edge-based SFR, e-SFR).
.. [SFRMAT] P. D. Burns, "sfrmat3: SFR evaluation for digital cameras and scanners", Burns
   Digital Imaging (2015); P. D. Burns, "Slanted-edge MTF for digital camera and scanner
   analysis", Proc. IS&T PICS Conference, pp. 135-138 (2000).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from bench_sim.errors import BenchSimError
from bench_sim.metrics.sfr_readings import SHARPENING_PEAK, mtf50, mtf50p, mtf_at, sfr_peak
from bench_sim.metrics.sfr_roi import INVALID_MAX_FRACTION, check_roi, check_roi_bounds, roi_pixels

__all__ = [
    "SFRResult",
    "edge_sfr",
    "check_roi_bounds",
    "mtf50",
    "mtf_at",
    "OVERSAMPLING",
    "ANGLE_MIN_DEG",
    "ANGLE_MAX_DEG",
    "MIN_ACROSS_PX",
    "MIN_ALONG_PX",
    "INVALID_MAX_FRACTION",
]

#: bins per pixel of the edge-spread function (ISO 12233: 4)
OVERSAMPLING = 4
#: allowed edge angles to the nearest pixel axis [deg]: near 0 the phases are not sampled, near
#: 45 the edge's direction (vertical or horizontal) is ambiguous
ANGLE_MIN_DEG = 1.0
ANGLE_MAX_DEG = 40.0
#: smallest ROI: pixels across the edge and rows along it
MIN_ACROSS_PX = 10
MIN_ALONG_PX = 8
#: largest correction of the derivative's transfer (as sfrmat3)
_FIR_CORRECTION_MAX = 10.0
#: rows with an invalid pixel within this distance [px] of the edge are left out of its fit
_GUARD_PX = 6.0
_AXIS = {"vertical": "columns", "horizontal": "rows"}


@dataclass(frozen=True)
class SFRResult:
    """The e-SFR of one slanted edge (:func:`edge_sfr`).

    Attributes
    ----------
    frequency_cyc_px
        Spatial frequency along the edge normal [cycles/pixel], ``0 .. 1``.
    frequency_cyc_mm
        The same in cycles/mm (``frequency_cyc_px / pitch_mm``), ``None`` without a pitch.
    sfr
        SFR at each frequency (1 at 0), dimensionless.
    mtf50_cyc_px
        Lowest frequency at which the SFR falls to 0.5 (linear interpolation) [cycles/pixel];
        NaN if it stays above 0.5 up to 1 cycle/pixel.
    mtf50_cyc_mm
        MTF50 in cycles/mm, ``None`` without a pitch.
    mtf_nyquist
        SFR at the Nyquist frequency, 0.5 cycles/pixel.
    edge_angle_deg
        Angle of the edge to the nearest pixel axis [deg] (to the columns for a vertical edge,
        to the rows for a horizontal one), 0 .. 45.
    orientation
        ``"vertical"`` (the edge runs down the columns, the SFR is along the rows) or
        ``"horizontal"`` (the SFR is along the columns).
    esf, lsf
        The 4x oversampled edge-spread function [input units] and line-spread function (before
        the window), one sample per 1/4 pixel (horizontal distance to the edge).
    rows_used
        Rows (along the edge) used: a whole number of phase cycles.
    contrast
        Step of the edge [input units]: mean of the bright side minus mean of the dark side.
    roi
        ``(x0, y0, x1, y1)`` of the ROI in the input image (pixel indices, ends exclusive).
    mtf50p_cyc_px
        MTF50P [cycles/px]: where the SFR falls to half its peak below Nyquist
        (:func:`bench_sim.metrics.sfr_readings.mtf50p`); equals MTF50 without sharpening.
    sfr_peak
        The largest SFR up to Nyquist (1 at 0 frequency without sharpening).
    sharpened
        The peak exceeds :data:`~bench_sim.metrics.sfr_readings.SHARPENING_PEAK`.
    excluded_px
        Pixels of the ROI left out as invalid (NaN, masked or clipped).

    Frequencies run along the edge normal (the standard); along the pixel axis across the edge
    they are ``f cos(edge_angle)`` (:func:`bench_sim.metrics.sfr_readings.axis_frequency`).
    """

    frequency_cyc_px: np.ndarray
    frequency_cyc_mm: np.ndarray | None
    sfr: np.ndarray
    mtf50_cyc_px: float
    mtf50_cyc_mm: float | None
    mtf_nyquist: float
    edge_angle_deg: float
    orientation: str
    esf: np.ndarray
    lsf: np.ndarray
    rows_used: int
    contrast: float
    roi: tuple[int, int, int, int]
    mtf50p_cyc_px: float = float("nan")
    sfr_peak: float = 1.0
    sharpened: bool = False
    excluded_px: int = 0


def _orient(a: np.ndarray) -> tuple[np.ndarray, str]:
    """The ROI turned so the edge is vertical and rises to the right, and its orientation
    (invalid pixels are NaN and stay so)."""
    k = max(1, min(a.shape) // 8)
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an all-NaN strip: a NaN mean
        lr = abs(np.nanmean(a[:, -k:]) - np.nanmean(a[:, :k]))
        tb = abs(np.nanmean(a[-k:, :]) - np.nanmean(a[:k, :]))
        orientation = "vertical" if not tb > lr else "horizontal"
        if orientation == "horizontal":
            a = a.T
        if np.nanmean(a[:, -k:]) < np.nanmean(a[:, :k]):
            a = a[:, ::-1]
    return np.ascontiguousarray(a), orientation


def _hamming(n: int, centre: np.ndarray | float) -> np.ndarray:
    """Hamming window(s) of length ``n`` centred at ``centre`` (sfrmat3's ``ahamming``): 1 at
    the centre, 0.08 at the farther end."""
    c = np.asarray(centre, dtype=np.float64)[..., None]
    half = np.maximum(c, n - 1 - c)
    half = np.where(half > 0, half, 1.0)
    return 0.54 + 0.46 * np.cos(np.pi * (np.arange(n) - c) / half)


def _centroids(a: np.ndarray, centre: np.ndarray, guard_px: float) -> np.ndarray:
    """Centroid [px] of each row's windowed central-difference derivative. Invalid (NaN)
    pixels within ``guard_px`` of ``centre`` leave the row out (NaN); farther ones count as a
    zero derivative."""
    d = np.zeros_like(a)
    d[:, 1:-1] = 0.5 * (a[:, 2:] - a[:, :-2])
    bad = np.isnan(d)
    near = bad & (np.abs(np.arange(a.shape[1])[None, :] - centre[:, None]) <= guard_px)
    d[bad] = 0.0
    d *= _hamming(a.shape[1], centre)
    s = d.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        c = (d * np.arange(a.shape[1])).sum(axis=1) / s
    c[near.any(axis=1)] = np.nan
    return c


def _locate_edge(a: np.ndarray) -> tuple[float, float, float]:
    """Fit ``x = x0 + s y`` to the edge of an oriented ROI; returns ``(x0, s, rms residual)``.
    The first fit takes the rows without an invalid pixel (all rows when fewer than half are
    whole); the refits leave out the rows with an invalid pixel near the line."""
    rows, cols = a.shape
    y = np.arange(rows, dtype=np.float64)
    middle = np.full(rows, (cols - 1) / 2.0)
    c = _centroids(a, middle, float(cols))
    if np.isfinite(c).sum() < max(3, rows // 2):
        c = _centroids(a, middle, -1.0)
    for _ in range(2):
        ok = np.isfinite(c)
        if ok.sum() < max(3, rows // 2):
            raise BenchSimError(
                f"ROI {cols} x {rows} px (oriented): no edge found in most rows (no rise across them)"
            )
        s, x0 = np.polyfit(y[ok], c[ok], 1)
        c = _centroids(a, np.clip(x0 + s * y, 0, cols - 1), _GUARD_PX)
    ok = np.isfinite(c)
    s, x0 = np.polyfit(y[ok], c[ok], 1)
    rms = float(np.sqrt(np.mean((c[ok] - (x0 + s * y[ok])) ** 2)))
    return float(x0), float(s), rms


def _check_edge(a: np.ndarray, where: str) -> float:
    """The edge's step (bright minus dark side) [input units]; refuses a ROI without one."""
    k = max(2, a.shape[1] // 4)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a row with one side all invalid: NaN
        steps = np.nanmean(a[:, -k:], axis=1) - np.nanmean(a[:, :k], axis=1)
    steps = steps[np.isfinite(steps)]
    step = float(np.median(steps)) if steps.size else float("nan")
    dev = np.diff(a, axis=1).ravel()
    dev = dev[np.isfinite(dev)]
    if dev.size == 0:
        dev = np.zeros(1)
    noise = 1.4826 * float(np.median(np.abs(dev - np.median(dev)))) / np.sqrt(2.0)
    if not step > 0 or step < 4.0 * noise:
        raise BenchSimError(
            f"{where}: no edge: the step across it is {step:.4g} against a pixel noise of "
            f"{noise:.4g} (need a straight edge with a step of at least 4x the noise)"
        )
    return step


def _esf(a: np.ndarray, x0: float, s: float) -> tuple[np.ndarray, int]:
    """The 4x oversampled ESF over the rows of whole phase cycles, and the rows used."""
    rows, cols = a.shape
    n_rows = int(round(np.floor(rows * abs(s)) / abs(s)))
    n_rows = min(rows, n_rows)
    y0 = (rows - n_rows) // 2
    y = np.arange(y0, y0 + n_rows, dtype=np.float64)[:, None]
    dist = np.arange(cols, dtype=np.float64)[None, :] - (x0 + s * y)
    nbins = OVERSAMPLING * cols
    idx = np.floor(dist * OVERSAMPLING).astype(np.int64) + nbins // 2
    vals = a[y0 : y0 + n_rows]
    keep = (idx >= 0) & (idx < nbins) & np.isfinite(vals)
    idx, vals = idx[keep], vals[keep]
    count = np.bincount(idx, minlength=nbins).astype(np.float64)
    total = np.bincount(idx, weights=vals, minlength=nbins)
    filled = count > 0
    centre = slice(nbins // 2 - nbins // 8, nbins // 2 + nbins // 8)
    if not filled[centre].all():
        raise BenchSimError(
            f"ROI: {n_rows} rows at an edge angle of {np.degrees(np.arctan(abs(s))):.2f} deg leave "
            f"{int((~filled[centre]).sum())} of the 1/{OVERSAMPLING}-px bins near the edge empty; "
            "use more rows along the edge or a larger angle"
        )
    k = np.arange(nbins)
    esf = np.interp(k, k[filled], total[filled] / count[filled])
    return esf, n_rows


def _spectrum(esf: np.ndarray, cos_t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """LSF (before the window), frequencies [cycles/px along the normal] and SFR up to 1."""
    n = esf.size
    lsf = np.zeros(n)
    lsf[1:-1] = 0.5 * (esf[2:] - esf[:-2])
    lsf[0], lsf[-1] = lsf[1], lsf[-2]
    pos = np.clip(lsf, 0, None)
    centre = float((pos * np.arange(n)).sum() / pos.sum()) if pos.sum() > 0 else (n - 1) / 2.0
    spec = np.abs(np.fft.rfft(lsf * _hamming(n, centre)))
    d = cos_t / OVERSAMPLING  # ESF sample interval along the edge normal [px]
    freq = np.arange(spec.size) / (n * d)
    keep = np.arange(spec.size) <= np.ceil(n * d)  # up to the first sample at or past 1 cycle/px
    freq, spec = freq[keep], spec[keep]
    sfr = spec / spec[0]
    corr = np.minimum(1.0 / np.sinc(2.0 * freq * d), _FIR_CORRECTION_MAX)
    return lsf, freq, sfr * corr


def _check_fit(
    x0: float, s: float, rms: float, shape: tuple[int, int], orientation: str, where: str
) -> float:
    """The edge angle [deg] of the fitted line ``x = x0 + s y`` in an oriented ROI of ``shape``,
    after refusing a bad angle, a crooked edge, an edge at the ROI's side, or too few rows for
    one phase cycle."""
    rows, cols = shape
    angle = float(np.degrees(np.arctan(abs(s))))
    if not ANGLE_MIN_DEG <= angle <= ANGLE_MAX_DEG:
        raise BenchSimError(
            f"{where}: edge angle {angle:.2f} deg to the {_AXIS[orientation]}: "
            f"allowed {ANGLE_MIN_DEG:g}..{ANGLE_MAX_DEG:g} deg (a slanted edge, not along the "
            "pixel grid nor near its diagonal)"
        )
    if rms > 1.0:
        raise BenchSimError(f"{where}: no straight edge: the edge positions scatter by {rms:.2f} px rms "
                            "about a line (more than one edge, a corner or no edge in the ROI?)")
    x_ends = (x0, x0 + s * (rows - 1))
    if min(x_ends) < 3 or max(x_ends) > cols - 4:
        raise BenchSimError(f"{where}: the edge comes within 3 px of the ROI's side; widen the ROI across it")
    if rows * abs(s) < 1.0:
        raise BenchSimError(
            f"{where}: {rows} rows at {angle:.2f} deg do not cover one phase cycle (rows x tan(angle) "
            f"= {rows * abs(s):.2f} < 1); use more rows along the edge or a larger angle"
        )
    return angle


def edge_sfr(
    image: np.ndarray,
    roi: tuple[int, int, int, int] | None = None,
    *,
    pixel_pitch_m: float | None = None,
    saturation: float | None = None,
    floor: float | None = None,
    valid: np.ndarray | None = None,
    clipped: np.ndarray | None = None,
    clip_level: float | None = None,
    where: str = "ROI",
) -> SFRResult:
    """ISO 12233:2017 e-SFR of the one slanted edge in ``image[y0:y1, x0:x1]`` (module docstring).

    Parameters
    ----------
    image
        2-D array, linear in the signal (any units: DN, electrons, reflectance).
    roi
        ``(x0, y0, x1, y1)`` [pixel indices, ends exclusive]; ``None``: the whole image. It must
        hold one straight edge, slanted by ``ANGLE_MIN_DEG .. ANGLE_MAX_DEG`` to the pixel
        axes, with at least :data:`MIN_ACROSS_PX` pixels across and :data:`MIN_ALONG_PX` along.
    pixel_pitch_m
        Pixel pitch [m] for the frequencies in cycles/mm (``None``: cycles/pixel only).
    saturation, floor
        Values at or above ``saturation`` / at or below ``floor`` count as clipped; a ROI with
        more than 0.1 % of its pixels clipped is refused (``None``: not checked); fewer clipped
        pixels are left out like invalid ones.
    valid
        Boolean array of the image's shape, ``False`` where a pixel is invalid (a mask); NaN
        and infinite pixels are invalid too. Invalid pixels are left out of the edge's fit
        (a row with one within 6 px of the edge) and of the ESF; more than half of the ROI
        invalid is refused.
    clipped
        Boolean array of the image's shape, ``True`` where a pixel clipped (a colour image's
        channels, a camera's flags): counted and left out as ``saturation`` is; ``clip_level``
        names the level in the message.
    where
        How the ROI is named in error messages.

    Returns
    -------
    SFRResult

    Raises
    ------
    BenchSimError
        One line: a bad ROI, a ROI too small, without an edge, a clipped edge, an edge angle
        outside ``ANGLE_MIN_DEG .. ANGLE_MAX_DEG``, or a crooked edge.
    """
    img = np.asarray(image)
    x0r, y0r, x1r, y1r = check_roi(img.shape, roi)
    if pixel_pitch_m is not None and not (np.isfinite(pixel_pitch_m) and pixel_pitch_m > 0):
        raise BenchSimError(f"pixel pitch = {pixel_pitch_m!r} m: must be a positive number")
    raw, excluded = roi_pixels(img, (x0r, y0r, x1r, y1r), saturation=saturation, floor=floor, valid=valid,
                               clipped=clipped, clip_level=clip_level, where=where)
    a, orientation = _orient(raw)
    rows, cols = a.shape
    if cols < MIN_ACROSS_PX or rows < MIN_ALONG_PX:
        raise BenchSimError(
            f"{where}: too small ({raw.shape[1]} x {raw.shape[0]} px): a {orientation} edge needs at "
            f"least {MIN_ACROSS_PX} px across it and {MIN_ALONG_PX} along it"
        )
    contrast = _check_edge(a, where)
    x0, s, rms = _locate_edge(a)
    angle = _check_fit(x0, s, rms, a.shape, orientation, where)
    esf, n_rows = _esf(a, x0, s)
    lsf, freq, sfr = _spectrum(esf, float(np.cos(np.arctan(s))))
    pitch_mm = None if pixel_pitch_m is None else pixel_pitch_m * 1e3
    f50 = mtf50(freq, sfr)
    peak = sfr_peak(freq, sfr)[0]
    return SFRResult(
        frequency_cyc_px=freq, frequency_cyc_mm=None if pitch_mm is None else freq / pitch_mm, sfr=sfr,
        mtf50_cyc_px=f50, mtf50_cyc_mm=None if pitch_mm is None else f50 / pitch_mm,
        mtf_nyquist=mtf_at(freq, sfr, 0.5), edge_angle_deg=angle, orientation=orientation, esf=esf, lsf=lsf,
        rows_used=n_rows, contrast=contrast, roi=(x0r, y0r, x1r, y1r), mtf50p_cyc_px=mtf50p(freq, sfr),
        sfr_peak=peak, sharpened=peak > SHARPENING_PEAK, excluded_px=excluded,
    )
