"""The linearity error LE of EMVA 1288 R4: the one estimator, and the chain's prediction through it.

Estimator (:func:`linearity_error`)
-----------------------------------
From a series of levels (an irradiation ``x``: photons per pixel, or the exposure time of an
exposure-time series at constant irradiance; the dark-subtracted mean ``y = mu_y - mu_y.dark``
[DN]; the temporal variance ``sigma_y^2`` [DN^2]):

1. the saturation point is the level of the largest temporal variance (EMVA 1288 R4), unless
   given;
2. the fit range holds the levels up to it whose signal lies between 5 % and 95 % of the
   saturation signal ``y_sat`` (:data:`LE_RANGE`);
3. over it, the line ``y = a0 + a1 x`` minimising ``sum ((y - a0 - a1 x) / y)^2`` (relative
   weights: every level counts by its relative deviation);
4. the relative deviation of every level, ``delta = 100 (y - (a0 + a1 x)) / (a0 + a1 x)`` [%];
5. ``LE = (max delta - min delta) / 2`` over the range [%] (the extremes are reported too).

Stated error: the deviations' own scatter (``100 se(y) / fit`` at the two extreme levels, where
the signal's standard error is given), the placement of the saturation point on the level grid
(LE recomputed with the saturation one level lower and higher; half their spread, as a uniform
error) and the noise floor, in quadrature. LE is a range, so noise alone makes it positive: the
floor is the mean LE of the signals' noise alone about the fitted line (:data:`FLOOR_DRAWS`
draws of a fixed generator), also reported; a measured LE at the floor is a linear camera.

Prediction
----------
A chain's LE is its exact mean response curve put through the same estimator
(:func:`bench_sim.sensor.response_curve.predicted_linearity_error`).

References
----------
EMVA Standard 1288, Release 4.0 Linear (2021), section on linearity (fit over 5-95 % of the
saturation range, relative deviation, LE); the ``emva1288`` reference package
(``Results1288.linearity``) computes the same fit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from bench_sim.errors import BenchSimError

__all__ = ["LE_RANGE", "LinearityError", "linearity_error"]

#: The fit range of LE: 5 % to 95 % of the saturation signal (EMVA 1288 R4)
LE_RANGE = (0.05, 0.95)
#: Fewest levels in the fit range
_MIN_POINTS = 3
#: Draws of the noise floor of LE (a fixed generator: the same series gives the same floor)
FLOOR_DRAWS = 200


@dataclass(frozen=True)
class LinearityError:
    """EMVA 1288 R4 linearity of a series (:func:`linearity_error`).

    Attributes
    ----------
    le_percent, le_se_percent
        ``LE = (max delta - min delta) / 2`` [%] and its stated standard error [%].
    le_min_percent, le_max_percent
        The extreme relative deviations over the range [%].
    slope, offset
        ``a1`` [DN per unit of x] and ``a0`` [DN] of the fitted line.
    deviation_percent
        ``delta`` of every level [%] (outside the range too).
    in_range
        Mask of the levels of the fit range.
    saturation_index
        The level of the saturation point.
    grid_percent
        Half the spread of LE with the saturation point one level either side [%].
    floor_percent
        The noise floor: the mean LE of the signals' noise alone [%] (0 without their errors).
    """

    le_percent: float
    le_se_percent: float
    le_min_percent: float
    le_max_percent: float
    slope: float
    offset: float
    saturation_index: int
    grid_percent: float
    floor_percent: float
    deviation_percent: np.ndarray = field(repr=False)
    in_range: np.ndarray = field(repr=False)

    def summary(self) -> dict[str, float | int]:
        """The scalars (JSON-ready)."""
        return {
            "le_percent": self.le_percent,
            "le_se_percent": self.le_se_percent,
            "le_min_percent": self.le_min_percent,
            "le_max_percent": self.le_max_percent,
            "fit_slope": self.slope,
            "fit_offset_dn": self.offset,
            "saturation_index": self.saturation_index,
            "grid_percent": self.grid_percent,
            "levels_in_range": int(self.in_range.sum()),
        }


def _fit(x: np.ndarray, y: np.ndarray, i_sat: int) -> tuple[float, float, np.ndarray, np.ndarray] | None:
    """The weighted line over the 5-95 % range of saturation ``i_sat``: ``(a0, a1, delta, mask)``,
    or None with fewer than :data:`_MIN_POINTS` levels in it."""
    y_sat = float(y[i_sat])
    lo, hi = LE_RANGE
    mask = (y >= lo * y_sat) & (y <= hi * y_sat) & (np.arange(y.size) <= i_sat) & (y > 0)
    if int(mask.sum()) < _MIN_POINTS or y_sat <= 0:
        return None
    xs, ys = x[mask], y[mask]
    design = np.column_stack([1.0 / ys, xs / ys])  # rows (1, x) / y; target y / y = 1
    (a0, a1), *_ = np.linalg.lstsq(design, np.ones(ys.size), rcond=None)
    line = a0 + a1 * x
    with np.errstate(divide="ignore", invalid="ignore"):
        delta = np.where(line != 0, 100.0 * (y - line) / line, np.nan)
    return float(a0), float(a1), delta, mask


def _noise_floor(x: np.ndarray, line: np.ndarray, se: np.ndarray) -> float:
    """Mean LE [%] of a straight line ``line`` at ``x`` plus the signals' noise ``se`` alone."""
    rng = np.random.default_rng(0)
    out = []
    design_x = x
    for _ in range(FLOOR_DRAWS):
        y = line + se * rng.standard_normal(line.size)
        design = np.column_stack([1.0 / y, design_x / y])
        (b0, b1), *_ = np.linalg.lstsq(design, np.ones(y.size), rcond=None)
        fit = b0 + b1 * design_x
        d = 100.0 * (y - fit) / fit
        out.append(0.5 * float(d.max() - d.min()))
    return float(np.mean(out))


def linearity_error(
    x: np.ndarray,
    signal_dn: np.ndarray,
    var_dn2: np.ndarray,
    *,
    signal_se_dn: np.ndarray | None = None,
    saturation_index: int | None = None,
) -> LinearityError:
    """The linearity error LE of EMVA 1288 R4 (module docstring).

    Parameters
    ----------
    x
        Irradiation of each level, increasing: mean photons per pixel, or the exposure time [s]
        of an exposure-time series at constant irradiance (LE does not depend on its unit).
    signal_dn
        Dark-subtracted mean signal ``mu_y - mu_y.dark`` [DN].
    var_dn2
        Temporal variance ``sigma_y^2`` [DN^2] (its maximum is the saturation point).
    signal_se_dn
        Standard error of each signal [DN] (its share of the stated error; omitted: none).
    saturation_index
        The level of the saturation point (default: the variance maximum).

    Raises
    ------
    BenchSimError
        Fewer than 3 levels between 5 % and 95 % of the saturation signal.
    """
    xa = np.asarray(x, dtype=np.float64).ravel()
    y = np.asarray(signal_dn, dtype=np.float64).ravel()
    v = np.asarray(var_dn2, dtype=np.float64).ravel()
    if not (xa.size == y.size == v.size) or not np.all(np.isfinite(xa) & np.isfinite(y) & np.isfinite(v)):
        raise BenchSimError("linearity: x, signal and variance must be finite and of one length")
    i_sat = int(np.argmax(v)) if saturation_index is None else int(saturation_index)
    got = _fit(xa, y, i_sat)
    if got is None:
        raise BenchSimError(
            f"linearity: fewer than {_MIN_POINTS} levels between 5 % and 95 % of the saturation "
            "signal; add levels below saturation"
        )
    a0, a1, delta, mask = got
    d = delta[mask]
    le = 0.5 * float(d.max() - d.min())
    stat = floor = 0.0
    if signal_se_dn is not None:
        se = 100.0 * np.asarray(signal_se_dn, dtype=np.float64).ravel() / np.abs(a0 + a1 * xa)
        idx = np.flatnonzero(mask)
        stat = 0.5 * math.hypot(float(se[idx[int(np.argmax(d))]]), float(se[idx[int(np.argmin(d))]]))
        floor = _noise_floor(xa[mask], (a0 + a1 * xa)[mask], np.asarray(signal_se_dn, dtype=np.float64)[mask])
    others = []
    for j in (i_sat - 1, i_sat + 1):
        if 0 < j < y.size and (alt := _fit(xa, y, j)) is not None:
            da = alt[2][alt[3]]
            others.append(0.5 * float(da.max() - da.min()))
    grid = 0.5 * (max([le, *others]) - min([le, *others]))
    return LinearityError(
        le_percent=le,
        le_se_percent=math.sqrt(stat**2 + grid**2 / 3.0 + floor**2),
        le_min_percent=float(d.min()),
        le_max_percent=float(d.max()),
        slope=a1,
        offset=a0,
        saturation_index=i_sat,
        grid_percent=grid,
        floor_percent=floor,
        deviation_percent=delta,
        in_range=mask,
    )
