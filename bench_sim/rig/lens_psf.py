"""The lens' optical transfer function (OTF) on the sensor plane: diffraction, or the user's lens.

Three lenses (:func:`lens_otf`; ``None`` when ``lens.diffraction = false`` and no file is given:
a perfect lens, the images of bench_sim 0.3):

``diffraction`` (``lens.diffraction = true``, the default)
    An aberration-free lens with a round aperture, incoherent light: at the working f-number
    ``N_w = N (1 + m)`` (``m`` the magnification) and wavelength ``lambda`` the OTF is real and
    radially symmetric, ``D(nu) = (2 / pi) (acos(x) - x sqrt(1 - x^2))``, ``x = nu lambda N_w``,
    zero beyond the cut-off ``nu_c = 1 / (lambda N_w)`` [Goodman]_. Mono: at
    ``sensor.wavelength_m``. Spectral: the mean of ``D`` over the grid of ``render.band_m``
    weighted by the photo-electrons each wavelength gives on a grey target -- the lights' summed
    spectra (each at its ``irradiance_w_m2``), the film's response ``QE(lambda) lambda`` and the
    target's reflectance spectrum -- (:func:`spectral_weights`).
``lens.mtf_file``
    A measured MTF: CSV of ``frequency_cyc_mm`` on the sensor and ``mtf`` (one curve) or
    ``mtf_sagittal`` and ``mtf_tangential``, from 0 (where it is normalised to 1), linear between
    the points; beyond the last point it falls as diffraction does, ``MTF_last D(nu) /
    D(nu_last)``. The sensor's line runs across the track, the lens' field along it, so the
    tangential curve applies to frequencies across the track (``x``) and the sagittal one along
    it (``y``), ``H = T(rho) cos^2(phi) + S(rho) sin^2(phi)`` between. A measured MTF holds the
    lens' diffraction already: it is not applied again.
``lens.psf_file`` (with ``lens.psf_pixel_m``)
    A PSF image (grey, non-negative) sampled every ``psf_pixel_m`` on the sensor: its OTF is its
    Fourier transform about its centroid (no shift), normalised to 1 at 0; it too replaces
    diffraction.

The render applies the OTF to the target as the camera sees it (:mod:`bench_sim.render.lens_blur`),
before the pixel aperture and the sensor. :func:`system_mtf_across` is the closed form of the
system across the track (lens and pixel aperture) that ``simulate`` and ``reproduce`` check
against Nyquist.

References
----------
.. [Goodman] J. W. Goodman, *Introduction to Fourier Optics*, 3rd ed., Roberts & Co., 2005,
   section 6.3.2 (the OTF of a diffraction-limited system with a circular pupil).
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.errors import BenchSimError
from bench_sim.io import read_csv_columns, read_image_data
from bench_sim.rig import spectra

__all__ = ["LensOTF", "diffraction_mtf", "working_f_number", "spectral_weights", "lens_otf",
           "lens_mtf_across", "system_mtf_across", "DIFFRACTION_RADIUS_ZEROS"]

#: the lens blur is applied out to this many first-zero radii of the Airy pattern (1.22 lambda N_w)
DIFFRACTION_RADIUS_ZEROS = 16.0
_MAX_RADIUS_PX = 48.0


@dataclass(frozen=True)
class LensOTF:
    """A lens' OTF on the sensor plane (module docstring).

    Attributes
    ----------
    kind
        ``"diffraction"``, ``"mtf_file"`` or ``"psf_file"``.
    source
        What it is, for the provenance (the f-number and wavelengths, or the file and its SHA-256).
    radius_m
        How far from its centre the PSF is applied [m on the sensor].
    grid
        ``grid(fy, fx)``: the OTF at the frequencies ``fy`` (along the track, rows) and ``fx``
        (across, columns) [cycles/m on the sensor], 1-D each; returns ``(len(fy), len(fx))``,
        real or complex.
    """

    kind: str
    source: str
    radius_m: float
    grid: Callable[[np.ndarray, np.ndarray], np.ndarray]

    @property
    def key(self) -> str:
        """What makes this lens' blur, as text (caches)."""
        return f"{self.kind}|{self.source}|{self.radius_m:.9g}"


def working_f_number(cfg: BenchConfig) -> float:
    """``N_w = N (1 + m)``: the f-number of the image-side cone at the bench's magnification."""
    return cfg.lens.f_number * (1.0 + abs(cfg.lens.magnification))


def diffraction_mtf(nu_cyc_m: np.ndarray, wavelength_m: float, working_f: float) -> np.ndarray:
    """The diffraction-limited OTF of a round aperture (module docstring) at the radial frequency
    ``nu`` [cycles/m on the sensor]: ``(2 / pi) (acos(x) - x sqrt(1 - x^2))``, ``x = nu lambda
    N_w``, 0 beyond 1."""
    x = np.minimum(np.abs(np.asarray(nu_cyc_m, dtype=np.float64)) * wavelength_m * working_f, 1.0)
    return (2.0 / math.pi) * (np.arccos(x) - x * np.sqrt(1.0 - x * x))


def spectral_weights(cfg: BenchConfig) -> tuple[np.ndarray, np.ndarray]:
    """``(wavelength [m], weight)`` of the diffraction's wavelengths, weights summing to 1: the
    sensor's wavelength (mono), or the band's grid weighted by the photo-electrons per wavelength
    on a grey target (module docstring)."""
    if not cfg.render.spectral:
        return np.array([cfg.sensor.wavelength_m]), np.array([1.0])
    wl_nm, response = spectra.response_values(cfg)
    light = np.zeros_like(wl_nm)
    for _, lt in cfg.lights.items():
        if lt.emits:
            light += lt.irradiance_w_m2 * spectra.emission_shape(lt, wl_nm)
    w = light * response * spectra.reflectance_shape(cfg, wl_nm)
    if not w.sum() > 0:
        w = response
    return wl_nm * 1e-9, w / w.sum()


def _diffraction(cfg: BenchConfig) -> LensOTF:
    wl, w = spectral_weights(cfg)
    nw = working_f_number(cfg)

    def grid(fy: np.ndarray, fx: np.ndarray) -> np.ndarray:
        rho = np.hypot(np.asarray(fy)[:, None], np.asarray(fx)[None, :])
        out = np.zeros(rho.shape)
        for lk, wk in zip(wl, w, strict=True):
            out += float(wk) * diffraction_mtf(rho, float(lk), nw)
        return out

    band = "" if wl.size == 1 else f"..{wl.max() * 1e9:.0f}"
    source = f"diffraction: N_w = {nw:.4g} at {wl.min() * 1e9:.0f}{band} nm"
    return LensOTF("diffraction", source, DIFFRACTION_RADIUS_ZEROS * 1.22 * float(wl.max()) * nw, grid)


def _digest(path: str) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _curve(freq_m: np.ndarray, mtf: np.ndarray, tail: Callable[[np.ndarray], np.ndarray]
           ) -> Callable[[np.ndarray], np.ndarray]:
    """The tabulated MTF, linear between the points, falling as ``tail`` past the last."""
    def at(rho: np.ndarray) -> np.ndarray:
        inside = np.interp(rho, freq_m, mtf)
        last = float(tail(np.array([freq_m[-1]]))[0])
        beyond = mtf[-1] * tail(rho) / last if last > 0 else np.zeros_like(rho)
        return np.where(rho <= freq_m[-1], inside, beyond)
    return at


def _mtf_file(cfg: BenchConfig, path: str) -> LensOTF:
    label = f"lens.mtf_file = {path!r}"
    cols = read_csv_columns(path, label)
    if "frequency_cyc_mm" not in cols:
        raise BenchSimError(f"{label}: needs a column frequency_cyc_mm (it has {', '.join(cols)})")
    f_m = cols["frequency_cyc_mm"] * 1e3
    if "mtf" in cols:
        sag = tan = cols["mtf"]
    elif "mtf_sagittal" in cols and "mtf_tangential" in cols:
        sag, tan = cols["mtf_sagittal"], cols["mtf_tangential"]
    else:
        raise BenchSimError(f"{label}: needs a column mtf, or mtf_sagittal and mtf_tangential "
                            f"(it has {', '.join(cols)})")
    if f_m[0] != 0 or np.any(np.diff(f_m) <= 0):
        raise BenchSimError(f"{label}: frequency_cyc_mm must start at 0 and increase")
    if min(sag[0], tan[0]) <= 0 or np.any(np.abs(np.concatenate([sag, tan])) > 1.5 * max(sag[0], tan[0])):
        raise BenchSimError(f"{label}: the MTF must be positive at 0 frequency (it is normalised there) "
                            "and not exceed 1.5 times that")
    nw = working_f_number(cfg)
    wl = float(spectral_weights(cfg)[0].max())

    def tail(rho: np.ndarray) -> np.ndarray:
        return diffraction_mtf(rho, wl, nw)

    s_at, t_at = _curve(f_m, sag / sag[0], tail), _curve(f_m, tan / tan[0], tail)

    def grid(fy: np.ndarray, fx: np.ndarray) -> np.ndarray:
        fy2, fx2 = np.asarray(fy)[:, None], np.asarray(fx)[None, :]
        rho = np.hypot(fy2, fx2)
        cos2 = np.divide(fx2 * fx2, rho * rho, out=np.ones(rho.shape), where=rho > 0)
        return t_at(rho) * cos2 + s_at(rho) * (1.0 - cos2)

    above = f_m[np.nonzero(np.minimum(sag, tan) / max(sag[0], tan[0]) <= 0.5)[0]]
    f50 = float(above[0]) if above.size else float(f_m[-1])
    radius = max(4.0 / f50, DIFFRACTION_RADIUS_ZEROS * 1.22 * wl * nw)
    return LensOTF("mtf_file", f"{path} (sha256 {_digest(path)})", radius, grid)


def _psf_file(cfg: BenchConfig, path: str, pixel_m: float) -> LensOTF:
    label = f"lens.psf_file = {path!r}"
    try:
        arr, _ = read_image_data(path)
    except Exception as exc:
        raise BenchSimError(f"{label}: cannot read the image ({' '.join(str(exc).split())[:120]})") from None
    psf = np.asarray(arr, dtype=np.float64)
    if psf.ndim == 3 and psf.shape[-1] == 1:
        psf = psf[..., 0]
    if psf.ndim != 2 or not np.isfinite(psf).all() or psf.min() < 0 or not psf.sum() > 0:
        raise BenchSimError(f"{label}: needs a grey (2-D) image of finite, non-negative values with a "
                            f"positive sum; it has shape {psf.shape}")
    psf = psf / psf.sum()
    y = (np.arange(psf.shape[0]) - (psf.sum(axis=1) * np.arange(psf.shape[0])).sum()) * pixel_m
    x = (np.arange(psf.shape[1]) - (psf.sum(axis=0) * np.arange(psf.shape[1])).sum()) * pixel_m

    def grid(fy: np.ndarray, fx: np.ndarray) -> np.ndarray:
        ey = np.exp(-2j * np.pi * np.outer(np.asarray(fy), y))
        ex = np.exp(-2j * np.pi * np.outer(x, np.asarray(fx)))
        return ey @ psf @ ex

    radius = 0.5 * max(psf.shape) * pixel_m
    return LensOTF("psf_file", f"{path} (sha256 {_digest(path)}), {pixel_m:g} m per sample", radius, grid)


def lens_otf(cfg: BenchConfig) -> LensOTF | None:
    """The bench's lens (module docstring), ``None`` for a perfect lens. Its radius is capped at
    48 pixels."""
    lens = cfg.lens
    if lens.mtf_file:
        otf = _mtf_file(cfg, lens.mtf_file)
    elif lens.psf_file:
        otf = _psf_file(cfg, lens.psf_file, float(lens.psf_pixel_m or 0.0))
    elif lens.diffraction:
        otf = _diffraction(cfg)
    else:
        return None
    cap = _MAX_RADIUS_PX * cfg.sensor.pixel_pitch_m
    return otf if otf.radius_m <= cap else LensOTF(otf.kind, otf.source, cap, otf.grid)


def lens_mtf_across(cfg: BenchConfig, f_cyc_px: np.ndarray) -> np.ndarray:
    """The lens' MTF across the track (:func:`lens_otf`; 1 for a perfect lens) at ``f``
    [cycles/px on the sensor]."""
    f = np.asarray(f_cyc_px, dtype=np.float64)
    otf = lens_otf(cfg)
    return np.ones_like(f) if otf is None else np.abs(otf.grid(np.zeros(1), f / cfg.sensor.pixel_pitch_m)[0])


def system_mtf_across(cfg: BenchConfig, f_cyc_px: np.ndarray) -> np.ndarray:
    """The system's MTF across the track in closed form: the lens (:func:`lens_mtf_across`)
    times the pixel aperture ``|sinc(f)|``, at ``f`` [cycles/px]."""
    f = np.asarray(f_cyc_px, dtype=np.float64)
    return lens_mtf_across(cfg, f) * np.abs(np.sinc(f))
