"""Weighted least squares of a straight line, and the rule by which a misfit widens the standard
errors: the tools of every EMVA 1288 fit (:mod:`bench_sim.metrics.emva_fit`).

The misfit rule (Birge's ratio, as the Particle Data Group applies it): with absolute weights a
fit's reduced chi-square ``chi2_red`` is ~1 where the model holds; where it exceeds its 99 %
quantile for the fit's degrees of freedom (:func:`misfit_scale`), the model does not describe the
points within their errors and every standard error of the fit is multiplied by
``sqrt(chi2_red)`` (the statistical ones are kept beside them). With relative weights (the
points' errors unknown) the errors are always scaled by ``sqrt(chi2_red)``: the scatter is the
only measure of them.

References
----------
.. [BR] P. R. Bevington, D. K. Robinson, *Data Reduction and Error Analysis for the Physical
   Sciences*, 3rd ed., McGraw-Hill, 2003, chapter 6 (weighted least squares, standard errors).
.. [Birge] R. T. Birge, Phys. Rev. 40 (1932) 207; Particle Data Group, Rev. Part. Phys.,
   Introduction, section 5.2 (the scale factor ``S = sqrt(chi2 / (N - 1))``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from bench_sim.errors import BenchSimError

__all__ = ["LineFit", "wls_line", "gls_through_origin", "misfit_scale", "MISFIT_QUANTILE"]

#: The quantile of chi-square beyond which a fit with absolute weights is a misfit
MISFIT_QUANTILE = 0.99


def misfit_scale(chi2_red: float, dof: int, absolute: bool) -> float:
    """The factor on a fit's standard errors (module docstring): ``sqrt(chi2_red)`` for relative
    weights or a misfit, else 1."""
    from scipy.stats import chi2

    if dof <= 0 or not math.isfinite(chi2_red):
        return 1.0
    if not absolute:
        return math.sqrt(max(chi2_red, 0.0))
    limit = float(chi2.isf(1.0 - MISFIT_QUANTILE, dof)) / dof
    return math.sqrt(chi2_red) if chi2_red > limit else 1.0


@dataclass(frozen=True)
class LineFit:
    """A weighted straight-line fit ``y = slope x (+ intercept)`` and its standard errors.

    ``chi2_red``: the reduced chi-square with the given weights; ``scale``: the factor on the
    errors (:func:`misfit_scale`; the errors given include it); ``scaled``: whether it is not 1;
    ``slope_se_statistical``: the slope's error from the weights alone.
    """

    slope: float
    slope_se: float
    intercept: float
    intercept_se: float
    chi2_red: float
    n: int
    scaled: bool
    residuals: np.ndarray = field(repr=False)
    scale: float = 1.0
    slope_se_statistical: float = math.nan


def wls_line(
    x: np.ndarray, y: np.ndarray, sigma_y: np.ndarray, *, through_origin: bool, absolute_sigma: bool
) -> LineFit:
    """Weighted least squares of a straight line, weights ``1 / sigma_y^2`` ([BR] chapter 6).

    ``absolute_sigma=False``: ``sigma_y`` are relative; the covariance is scaled by
    ``chi2_red``. With absolute ones it is scaled where the line is a misfit
    (:func:`misfit_scale`). Needs one more point than parameters.
    """
    x, y, s = (np.asarray(a, dtype=np.float64) for a in (x, y, sigma_y))
    p = 1 if through_origin else 2
    if x.size <= p or not (s > 0).all():
        raise BenchSimError(f"line fit: {x.size} points with positive errors, need at least {p + 1}")
    w = 1.0 / (s * s)
    if through_origin:
        sxx = float(np.sum(w * x * x))
        slope, icp = float(np.sum(w * x * y)) / sxx, 0.0
        var_s, var_i = 1.0 / sxx, 0.0
    else:
        sw, sx, sy = float(w.sum()), float(np.sum(w * x)), float(np.sum(w * y))
        sxx, sxy = float(np.sum(w * x * x)), float(np.sum(w * x * y))
        det = sw * sxx - sx * sx
        slope, icp = (sw * sxy - sx * sy) / det, (sxx * sy - sx * sxy) / det
        var_s, var_i = sw / det, sxx / det
    res = y - (slope * x + icp)
    chi2_red = float(np.sum(w * res * res)) / (x.size - p)
    scale = misfit_scale(chi2_red, x.size - p, absolute_sigma)
    return LineFit(
        slope=slope,
        slope_se=math.sqrt(var_s) * scale,
        intercept=icp,
        intercept_se=math.sqrt(var_i) * scale,
        chi2_red=chi2_red,
        n=int(x.size),
        scaled=scale != 1.0,
        residuals=res,
        scale=scale,
        slope_se_statistical=math.sqrt(var_s),
    )


def gls_through_origin(x: np.ndarray, y: np.ndarray, cov: np.ndarray, *, absolute_sigma: bool) -> LineFit:
    """Generalised least squares of ``y = slope x`` with the points' covariance ``cov`` (errors
    shared by several points, such as the dark level they all subtract, are off-diagonal):
    ``slope = x' C^-1 y / x' C^-1 x``, variance ``1 / x' C^-1 x``, ``chi2 = r' C^-1 r``; the
    misfit rule as :func:`wls_line` ([BR] chapter 7; A. C. Aitken, Proc. R. Soc. Edinb. 55 (1935) 42).
    """
    xa, ya = (np.asarray(a, dtype=np.float64) for a in (x, y))
    c = np.asarray(cov, dtype=np.float64)
    if xa.size < 2 or c.shape != (xa.size, xa.size):
        raise BenchSimError(f"line fit: {xa.size} points, need at least 2 and a covariance of their size")
    cinv_x = np.linalg.solve(c, xa)
    sxx = float(xa @ cinv_x)
    slope = float(cinv_x @ ya) / sxx
    res = ya - slope * xa
    chi2_red = float(res @ np.linalg.solve(c, res)) / (xa.size - 1)
    scale = misfit_scale(chi2_red, xa.size - 1, absolute_sigma)
    se = math.sqrt(1.0 / sxx)
    return LineFit(
        slope=slope,
        slope_se=se * scale,
        intercept=0.0,
        intercept_se=0.0,
        chi2_red=chi2_red,
        n=int(xa.size),
        scaled=scale != 1.0,
        residuals=res,
        scale=scale,
        slope_se_statistical=se,
    )
