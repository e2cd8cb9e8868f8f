"""Spectra of the rig for the spectral rendering option: the lights' emission and the sensor's
spectral response.

In spectral mode the film records, per pixel, the QE- and photon-weighted radiance

``L_eq = integral L(lambda) * S(lambda) dlambda``,
``S(lambda) = QE(lambda) / QE(lambda_ref) * lambda / lambda_ref``

(``lambda_ref = sensor.wavelength_m``, ``QE(lambda_ref) = sensor.quantum_efficiency``). The usual
radiometry at ``lambda_ref`` then turns ``L_eq`` into *QE-equivalent photons*: the photons at
``lambda_ref`` that give the same photo-electrons, ``n_eq = integral n_p(lambda) QE(lambda)
dlambda / QE(lambda_ref)``, so the sensor model (which applies ``QE(lambda_ref)``) produces the
exact electron count of the spectrum. With a narrow flat band around ``lambda_ref`` this reduces to
the mono result.

A light's ``irradiance_w_m2`` is its irradiance integrated over ``render.band_m``, distributed
with its spectrum's shape (flat, or a blackbody of ``temperature_k``).
"""

from __future__ import annotations

import numpy as np

from bench_sim.config import BenchConfig, LightConfig
from bench_sim.errors import BenchSimError

__all__ = [
    "DEFAULT_QE_CURVE",
    "qe_curve",
    "response_values",
    "emission_shape",
    "spectrum_dict",
    "light_spectrum",
    "response_dict",
    "MITSUBA_RANGE_NM",
]

#: Mitsuba's spectral range [nm]
MITSUBA_RANGE_NM = (360.0, 830.0)

#: Relative QE of a front-side-illuminated monochrome global-shutter CMOS (shape only; scaled so
#: that QE(sensor.wavelength_m) = sensor.quantum_efficiency). (wavelength [m], relative QE)
DEFAULT_QE_CURVE: tuple[tuple[float, float], ...] = (
    (360e-9, 0.10), (400e-9, 0.45), (450e-9, 0.76), (500e-9, 0.95), (550e-9, 1.00),
    (600e-9, 0.95), (650e-9, 0.82), (700e-9, 0.65), (750e-9, 0.49), (800e-9, 0.35),
    (830e-9, 0.28),
)

_GRID_STEP_NM = 2.0


def qe_curve(cfg: BenchConfig) -> tuple[np.ndarray, np.ndarray]:
    """The sensor's QE curve: (wavelength [nm], QE), scaled so QE(lambda_ref) is the configured
    ``sensor.quantum_efficiency``."""
    pts = cfg.sensor.qe_curve if cfg.sensor.qe_curve is not None else DEFAULT_QE_CURVE
    wl = np.array([p[0] for p in pts]) * 1e9
    rel = np.array([p[1] for p in pts], dtype=np.float64)
    ref_nm = cfg.sensor.wavelength_m * 1e9
    at_ref = float(np.interp(ref_nm, wl, rel))
    if at_ref <= 0:
        raise BenchSimError(
            f"sensor.qe_curve: relative QE at sensor.wavelength_m = {cfg.sensor.wavelength_m} is 0"
        )
    return wl, rel * (cfg.sensor.quantum_efficiency / at_ref)


def _grid(cfg: BenchConfig) -> np.ndarray:
    lo, hi = (b * 1e9 for b in cfg.render.band_m)
    n = max(int(round((hi - lo) / _GRID_STEP_NM)) + 1, 2)
    return np.linspace(lo, hi, n)


def response_values(cfg: BenchConfig) -> tuple[np.ndarray, np.ndarray]:
    """The film's response ``S(lambda)`` on a grid over ``render.band_m``: (nm, S)."""
    wl = _grid(cfg)
    qwl, qe = qe_curve(cfg)
    ref_nm = cfg.sensor.wavelength_m * 1e9
    s = np.interp(wl, qwl, qe) / cfg.sensor.quantum_efficiency * wl / ref_nm
    return wl, s


def emission_shape(light: LightConfig, wl_nm: np.ndarray) -> np.ndarray:
    """Relative spectral shape of a light on ``wl_nm`` (flat, or Planck's law at
    ``temperature_k``), normalised to integrate to 1 over the grid (per nm)."""
    if light.spectrum == "blackbody":
        lam = wl_nm * 1e-9
        c2 = 1.438776877e-2  # h c / k [m K]
        shape = lam**-5 / np.expm1(c2 / (lam * light.temperature_k))
    else:
        shape = np.ones_like(wl_nm)
    return shape / np.trapezoid(shape, wl_nm)


def spectrum_dict(wl_nm: np.ndarray, values: np.ndarray) -> dict[str, object]:
    """A Mitsuba ``regular`` spectrum over the (regular) grid ``wl_nm``."""
    return {
        "type": "regular",
        "wavelength_min": float(wl_nm[0]),
        "wavelength_max": float(wl_nm[-1]),
        "values": ",".join(f"{v:.9g}" for v in values),
    }


def light_spectrum(
    cfg: BenchConfig, light: LightConfig, total: float
) -> dict[str, object]:
    """Mitsuba spectrum whose integral over ``render.band_m`` is ``total`` (per-nm values)."""
    wl = _grid(cfg)
    return spectrum_dict(wl, total * emission_shape(light, wl))


def response_dict(cfg: BenchConfig) -> dict[str, object]:
    """The film's band ``S(lambda)`` as a Mitsuba spectrum."""
    return spectrum_dict(*response_values(cfg))
