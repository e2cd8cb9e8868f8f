"""Radiometry: scene radiance -> focal-plane irradiance -> photons per pixel per frame.

Mitsuba's film holds pixel-averaged scene radiance ``L`` [W m^-2 sr^-1] (in-band, mono). Neither
its ``perspective`` nor its ``thinlens`` camera includes the lens' f-number, transmission or
the cos^4 off-axis fall-off (a uniformly lit plane renders to the same radiance in the corner as
in the centre), so they are applied here. The lens' blur is not: it acts on the image before the
pixels integrate it (:mod:`bench_sim.render.lens_blur`).

References
----------
.. [Slater] P. N. Slater, *Remote Sensing: Optics and Optical Systems*, Addison-Wesley, 1980
   (camera equation: image irradiance of an extended Lambertian scene, cos^4 law).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "PLANCK_J_S",
    "SPEED_OF_LIGHT_M_S",
    "photon_energy_j",
    "focal_plane_irradiance",
    "photons_per_pixel",
    "cos_chief_ray",
    "radiance_to_photons_factor",
]

#: Planck constant [J s] and speed of light in vacuum [m/s]: exact in the SI since 2019 (the values
#: of ``scipy.constants.h`` and ``.c``, written out so importing this module does not start scipy)
PLANCK_J_S: float = 6.62607015e-34
SPEED_OF_LIGHT_M_S: float = 299792458.0


def photon_energy_j(wavelength_m: float) -> float:
    """Energy of one photon, ``h c / lambda`` [J]."""
    return PLANCK_J_S * SPEED_OF_LIGHT_M_S / wavelength_m


def focal_plane_irradiance(
    radiance_w_m2_sr: np.ndarray | float,
    f_number: float,
    magnification: float,
    transmission: float,
    cos_theta: np.ndarray | float = 1.0,
) -> np.ndarray:
    """Image-plane irradiance of a lens (camera equation) [W m^-2].

    ``E = pi * tau * L * cos^4(theta) / (4 * N^2 * (1 + |m|)^2)``, with ``N (1 + |m|)`` the
    working f-number.
    """
    n_w = f_number * (1.0 + abs(magnification))
    return (
        math.pi
        * transmission
        * np.asarray(radiance_w_m2_sr, dtype=np.float64)
        * np.asarray(cos_theta, dtype=np.float64) ** 4
        / (4.0 * n_w * n_w)
    )


def photons_per_pixel(
    irradiance_w_m2: np.ndarray | float, pixel_pitch_m: float, t_int_s: float, wavelength_m: float
) -> np.ndarray:
    """Mean photons per pixel per frame: ``n_p = E * A_pix * t_int / (h c / lambda)``."""
    return np.asarray(irradiance_w_m2, dtype=np.float64) * (
        pixel_pitch_m * pixel_pitch_m * t_int_s / photon_energy_j(wavelength_m)
    )


def cos_chief_ray(rows: int, columns: int, pixel_pitch_m: float, image_distance_m: float) -> np.ndarray:
    """Cosine of the chief-ray angle at each pixel centre, shape (rows, columns)."""
    yy = (np.arange(rows) + 0.5 - rows / 2.0) * pixel_pitch_m
    xx = (np.arange(columns) + 0.5 - columns / 2.0) * pixel_pitch_m
    r2 = yy[:, None] ** 2 + xx[None, :] ** 2
    return image_distance_m / np.sqrt(image_distance_m**2 + r2)


def radiance_to_photons_factor(
    rows: int,
    columns: int,
    pixel_pitch_m: float,
    image_distance_m: float,
    f_number: float,
    magnification: float,
    transmission: float,
    t_int_s: float,
    wavelength_m: float,
    cos4: bool = True,
) -> np.ndarray:
    """Photons per pixel per frame per unit radiance [photons / (W m^-2 sr^-1)], shape (rows,
    columns): the camera equation, the pixel area, the integration time and the photon energy
    in one factor (with the cos^4 fall-off when ``cos4``)."""
    cos_t = cos_chief_ray(rows, columns, pixel_pitch_m, image_distance_m) if cos4 else 1.0
    e = focal_plane_irradiance(1.0, f_number, magnification, transmission, cos_t)
    return np.broadcast_to(photons_per_pixel(e, pixel_pitch_m, t_int_s, wavelength_m), (rows, columns)).copy()
