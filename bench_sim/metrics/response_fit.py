"""The camera's mean response curve, fitted: a polynomial through the origin of the
dark-subtracted signal against the irradiation, whose small-signal slope is the responsivity and
whose shape is the non-linearity the twin carries.

The slope's standard error is widened by the misfit rule of
:func:`bench_sim.metrics.weighted_fit.misfit_scale`.

``y = sum_{k=1..d} a_k x^k`` [DN] over the levels from 0 to 95 % of the saturation signal (the
range of EMVA 1288's linearity error), weighted by the signals' standard errors. The degree
starts at 1 and grows while the next term lowers the chi-square by more than
:data:`TERM_CHI2` times the larger model's reduced chi-square (a 3-sigma F-test; at most
:data:`MAX_DEGREE`). With the linear signal ``s = a_1 x`` the response is ``y = f(s)``, its slope
``f'(s) = P'(x) / a_1``; a read's variance scales by ``f'(s)^2`` (the noise passes through the
response), which is how :func:`bench_sim.metrics.emva_fit.fit_camera` linearises the photon
transfer of a non-linear camera before it fits ``K``.

References
----------
EMVA Standard 1288, Release 4.0 Linear (2021), linearity; J. Janesick, *Photon Transfer* (SPIE,
2007), ch. 9 (non-linearity and the photon-transfer curve). P. R. Bevington, D. K. Robinson,
*Data Reduction and Error Analysis*, 3rd ed. (2003), sections 7.2 and 11.4 (polynomial fits, the
F-test for an added term).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bench_sim.errors import BenchSimError
from bench_sim.metrics.weighted_fit import misfit_scale

__all__ = ["ResponseFit", "fit_response", "MAX_DEGREE", "TERM_CHI2"]

#: Largest degree of the response polynomial
MAX_DEGREE = 5
#: rms relative residual below which a fit is exact (float64 data of a model): no term is added
EXACT_RELATIVE = 1e-9
#: Chi-square drop (in units of the larger model's reduced chi-square) that keeps a term: 3 sigma
TERM_CHI2 = 9.0


@dataclass(frozen=True)
class ResponseFit:
    """``y = sum a_k x^k`` (:func:`fit_response`): ``coefficients`` ``a_1 .. a_d`` [DN per unit
    of x^k], the slope's standard error ``slope_se`` (scaled by the misfit where the weights are
    relative or the fit is poor), ``chi2_red``, the levels ``n``, the rms relative residual
    ``rms_relative`` and the largest irradiation fitted ``x_max``."""

    coefficients: np.ndarray
    slope_se: float
    chi2_red: float
    n: int
    rms_relative: float
    x_max: float = math.inf

    @property
    def degree(self) -> int:
        """The polynomial's degree (1: linear)."""
        return int(self.coefficients.size)

    @property
    def slope(self) -> float:
        """``a_1``: the small-signal slope [DN per unit of x]."""
        return float(self.coefficients[0])

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """``y(x)`` [DN]."""
        xa = np.asarray(x, dtype=np.float64)
        return sum(a * xa ** (k + 1) for k, a in enumerate(self.coefficients))

    def gain_ratio(self, x: np.ndarray) -> np.ndarray:
        """``f'(s) = P'(x) / a_1``: the response's slope relative to its small-signal slope [1]."""
        xa = np.asarray(x, dtype=np.float64)
        deriv = sum((k + 1) * a * xa**k for k, a in enumerate(self.coefficients))
        return np.asarray(deriv, dtype=np.float64) / self.slope

    def electrons_response(self, e: np.ndarray, k_dn_per_e: float) -> np.ndarray:
        """The response in electrons, ``r(e) = f(K e) / K`` [e-] (``e``: linear electrons, increasing), made
        monotone: beyond the fitted range (``x_max``) it continues as the straight line of its
        slope there (never falling)."""
        x = np.asarray(e, dtype=np.float64) * k_dn_per_e / self.slope
        end = min(float(np.max(x)) if x.size else 0.0, self.x_max)
        slope_end = max(float(self.gain_ratio(np.array([end]))[0]) * self.slope, 0.0)
        y = np.where(
            x <= end, self(np.minimum(x, end)), float(self(np.array([end]))[0]) + slope_end * (x - end)
        )
        return np.maximum.accumulate(np.asarray(y, dtype=np.float64).ravel()).reshape(x.shape) / k_dn_per_e


def _wls(x: np.ndarray, y: np.ndarray, chol: np.ndarray, degree: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Generalised least-squares polynomial through the origin (the points' covariance given by
    its Cholesky factor): coefficients, their covariance (absolute) and chi2."""
    from scipy.linalg import solve_triangular

    scale = float(np.max(np.abs(x)))
    u = x / scale
    design = np.column_stack([u ** (k + 1) for k in range(degree)])
    wd = solve_triangular(chol, design, lower=True)
    wy = solve_triangular(chol, y, lower=True)
    coef, *_ = np.linalg.lstsq(wd, wy, rcond=None)
    res = wy - wd @ coef
    cov = np.linalg.pinv(wd.T @ wd)
    powers = scale ** np.arange(1, degree + 1)
    return coef / powers, cov / np.outer(powers, powers), float(np.sum(res**2))


def _rms(x: np.ndarray, y: np.ndarray, coef: np.ndarray) -> float:
    fit = sum(a * x ** (k + 1) for k, a in enumerate(coef))
    rel = (y - fit) / np.where(fit != 0, fit, 1.0)
    return float(np.sqrt(np.mean(rel * rel)))


def fit_response(
    x: np.ndarray, y: np.ndarray, cov: np.ndarray, *, absolute: bool, max_degree: int = MAX_DEGREE
) -> ResponseFit:
    """The response polynomial (module docstring) over the levels given.

    Parameters
    ----------
    x
        Irradiation of each level (photons, a relative irradiance or the exposure time), > 0.
    y
        Dark-subtracted signal [DN].
    cov
        Covariance of the signals [DN^2] (relative where ``absolute`` is False): a vector is
        their variances (independent), a matrix holds the errors they share (a dark level).
    absolute
        Whether ``cov`` is absolute (else the slope's error is scaled by ``sqrt(chi2_red)``).

    Raises
    ------
    BenchSimError
        Fewer than 3 levels.
    """
    xa, ya = (np.asarray(a, dtype=np.float64) for a in (x, y))
    c = np.asarray(cov, dtype=np.float64)
    sa = np.linalg.cholesky(np.diag(c) if c.ndim == 1 else c)
    if xa.size < 3:
        raise BenchSimError(f"response fit: {xa.size} levels below 95 % of saturation, need at least 3")
    degree = 1
    coef, cov, chi2 = _wls(xa, ya, sa, 1)
    while degree < min(max_degree, xa.size - 2) and _rms(xa, ya, coef) > EXACT_RELATIVE:
        c2, v2, chi2_next = _wls(xa, ya, sa, degree + 1)
        red_next = chi2_next / max(xa.size - degree - 1, 1)
        if chi2 - chi2_next <= TERM_CHI2 * (max(red_next, 1.0) if absolute else red_next):
            break
        degree, coef, cov, chi2 = degree + 1, c2, v2, chi2_next
    red = chi2 / max(xa.size - degree, 1)
    scale = misfit_scale(red, xa.size - degree, absolute)
    return ResponseFit(
        coefficients=np.asarray(coef, dtype=np.float64),
        slope_se=math.sqrt(max(float(cov[0, 0]), 0.0)) * scale,
        chi2_red=red,
        n=int(xa.size),
        rms_relative=_rms(xa, ya, coef),
        x_max=float(xa.max()),
    )
