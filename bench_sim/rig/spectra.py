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
with its spectrum's shape: flat, a blackbody of ``temperature_k``, or a measured spectrum by name
or from a CSV file (:mod:`bench_sim.io.spectral_data`: CIE A, the F-series fluorescent lamps,
white LEDs, measured lamps). The sensor's QE curve is ``sensor.qe_curve``, a measured response
(``sensor.qe_spectrum``) or the default curve, scaled as above. The print's reflectance is grey
unless ``target.reflectance_spectrum`` names one (a ColorChecker patch, a paper's CSV): the
pattern's reflectance times that spectrum (:func:`reflectance_shape`); it multiplies the drum's
reflectance in both engines. A measured table must cover ``render.band_m``
(:func:`check_spectra`); between its points it is linear.
"""

from __future__ import annotations

import numpy as np

from bench_sim.config import BUILTIN_LIGHT_SPECTRA, BenchConfig, LightConfig
from bench_sim.errors import BenchSimError
from bench_sim.io.spectral_data import Spectrum, load_spectrum

__all__ = [
    "DEFAULT_QE_CURVE",
    "qe_curve",
    "response_values",
    "emission_shape",
    "spectrum_dict",
    "light_spectrum",
    "response_dict",
    "MITSUBA_RANGE_NM",
    "reflectance_shape",
    "reflectance_dict",
    "measured_spectra",
    "check_spectra",
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
    if cfg.sensor.qe_spectrum is not None:
        measured = _measured(cfg)["sensor.qe_spectrum"]
        wl, rel = measured.wavelength_nm, measured.values
    else:
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
    """Relative spectral shape of a light on ``wl_nm`` (flat, Planck's law at ``temperature_k``,
    or a measured spectrum), normalised to integrate to 1 over the grid (per nm)."""
    if light.spectrum == "blackbody":
        lam = wl_nm * 1e-9
        c2 = 1.438776877e-2  # h c / k [m K]
        shape = lam**-5 / np.expm1(c2 / (lam * light.temperature_k))
    elif light.spectrum == "flat":
        shape = np.ones_like(wl_nm)
    else:
        shape = _light_spectrum(light.spectrum).at(wl_nm)
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


def reflectance_shape(cfg: BenchConfig, wl_nm: np.ndarray) -> np.ndarray:
    """The print's spectral reflectance factor on ``wl_nm``: ``target.reflectance_spectrum``'s
    values (the pattern's reflectance multiplies them), 1 for a grey print."""
    wl = np.asarray(wl_nm, dtype=np.float64)
    if cfg.target.reflectance_spectrum is None:
        return np.ones_like(wl)
    return _measured(cfg)["target.reflectance_spectrum"].at(wl)


def reflectance_dict(cfg: BenchConfig) -> dict[str, object] | None:
    """The print's reflectance spectrum over ``render.band_m`` as a Mitsuba spectrum (``None``:
    grey, or mono mode)."""
    if not cfg.render.spectral or cfg.target.reflectance_spectrum is None:
        return None
    wl = _grid(cfg)
    return spectrum_dict(wl, reflectance_shape(cfg, wl))


def _light_spectrum(name: str) -> Spectrum:
    return load_spectrum("light", name, "lights.*.spectrum")


def measured_spectra(cfg: BenchConfig) -> dict[str, Spectrum]:
    """Every measured spectrum the bench names, by its key (``lights.NAME.spectrum``,
    ``target.reflectance_spectrum``, ``sensor.qe_spectrum``); read when asked."""
    out = {}
    for name, light in cfg.lights.items():
        if light.emits and light.spectrum not in BUILTIN_LIGHT_SPECTRA:
            out[f"lights.{name}.spectrum"] = load_spectrum("light", light.spectrum, f"lights.{name}.spectrum")
    if cfg.target.reflectance_spectrum is not None:
        out["target.reflectance_spectrum"] = load_spectrum(
            "reflectance", cfg.target.reflectance_spectrum, "target.reflectance_spectrum")
    if cfg.sensor.qe_spectrum is not None:
        out["sensor.qe_spectrum"] = load_spectrum("qe", cfg.sensor.qe_spectrum, "sensor.qe_spectrum")
    return out


_measured = measured_spectra


def check_spectra(cfg: BenchConfig) -> dict[str, str]:
    """Read every measured spectrum of a spectral bench and check it covers ``render.band_m`` (and
    the QE curve ``sensor.wavelength_m``); returns ``{key: source}`` for the provenance. One-line
    :class:`BenchSimError` otherwise. Mono benches use none (``{}``)."""
    if not cfg.render.spectral:
        return {}
    lo, hi = (b * 1e9 for b in cfg.render.band_m)
    found = measured_spectra(cfg)
    for key, s in found.items():
        if not s.covers(lo, hi):
            raise BenchSimError(
                f"{key}: {s.source} covers {s.wavelength_nm[0]:g}..{s.wavelength_nm[-1]:g} nm; "
                f"render.band_m needs {lo:g}..{hi:g} nm"
            )
    qe_curve(cfg)  # its value at sensor.wavelength_m must not be 0
    return {k: s.source for k, s in found.items()}
