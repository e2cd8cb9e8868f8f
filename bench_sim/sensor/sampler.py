"""Shot-noise samplers of the pixel model (:mod:`bench_sim.sensor.emva`, ``sensor.shot_noise_sampler``).

* :func:`shot_electrons`: Poisson electron counts, exact (``"poisson"``) or, above
  :data:`SHOT_NOISE_SWITCH_E` mean electrons, a rounded third-order Cornish-Fisher normal
  (``"hybrid"``);
* :func:`shot_and_read_electrons`: shot and read noise drawn together from one normal per pixel
  (``"hybrid"`` with read noise of at least :data:`COMBINED_READ_NOISE_MIN_E`).

All are re-exported by :mod:`bench_sim.sensor.emva`.
"""

from __future__ import annotations

import numpy as np

from bench_sim.errors import BenchSimError
from bench_sim.sensor.exposure_kernel import joint_quantile

__all__ = [
    "box_muller_normals",
    "shot_electrons",
    "shot_and_read_electrons",
    "SHOT_NOISE_SWITCH_E",
    "SKEWNESS_MAX",
    "COMBINED_READ_NOISE_MIN_E",
    "FULL_WELL_SIGMAS",
]

#: Mean electron count from which ``shot_noise_sampler = "hybrid"`` draws shot noise from the
#: rounded Cornish-Fisher normal approximation instead of numpy's exact Poisson sampler.
SHOT_NOISE_SWITCH_E = 30.0
#: Largest skewness of shot + read noise drawn as one normal approximation (``"hybrid"``)
SKEWNESS_MAX = 0.05
#: Read noise [e- rms] from which ``"hybrid"`` draws shot and read noise together: the skewness
#: ``mu / (mu + sigma^2)**1.5`` of Poisson(mu) + N(0, sigma^2) peaks at ``2 / (3 sqrt(3) sigma)``
#: (at ``mu = 2 sigma^2``), at most :data:`SKEWNESS_MAX` from here on.
COMBINED_READ_NOISE_MIN_E = 2.0 / (3.0 * np.sqrt(3.0) * SKEWNESS_MAX)
#: Pixels whose mean electrons come within this many standard deviations of the full well get
#: their shot noise drawn apart (its clip at the full well comes before the read noise).
FULL_WELL_SIGMAS = 8.0


#: 2 pi over 2**32: 32-bit words -> angles [rad]
_ANGLE_PER_WORD = np.float32(2.0 * np.pi / 2.0**32)


def box_muller_normals(rng: np.random.Generator, out: np.ndarray) -> np.ndarray:
    """Fill the float32 array ``out`` with independent standard normal numbers (Box-Muller).

    Draws ``ceil(n / 2)`` 64-bit words from ``rng``'s bit generator (``random_raw``); of the
    ``2 ceil(n / 2)`` 32-bit halves ``w``, the first half gives the radii, the second the
    angles::

        u = (w1 + 1) / 2**32  in (0, 1],   r = sqrt(-2 ln u),   theta = 2 pi w2 / 2**32
        out = [r cos(theta), r sin(theta)]  (the sines after the cosines; the last dropped for odd n)

    in float32 (numpy's vectorised ``log``, ``sin`` and ``cos``), about 2.5x faster than
    ``rng.standard_normal(dtype=np.float32)`` (a ziggurat drawing one word at a time). The
    radius reaches ``sqrt(64 ln 2) = 6.66``: the normal's mass beyond is 3e-11. Used by the
    joint shot and read draw (:func:`shot_and_read_electrons`) in float32.

    Parameters
    ----------
    rng
        Generator whose bit generator supplies the words.
    out
        C-contiguous float32 array of any shape, overwritten.

    Returns
    -------
    numpy.ndarray
        ``out``.

    References
    ----------
    G. E. P. Box, M. E. Muller, "A note on the generation of random normal deviates", Ann.
    Math. Statist. 29 (1958) 610-611.
    """
    flat = out.reshape(-1)
    n = flat.size
    h = (n + 1) // 2
    words = rng.bit_generator.random_raw(h).view(np.uint32)
    r = np.add(words[:h], np.float32(1.0), dtype=np.float32)
    r *= np.float32(2.0**-32)
    np.log(r, out=r)
    r *= np.float32(-2.0)
    np.sqrt(r, out=r)
    theta = np.multiply(words[h:], _ANGLE_PER_WORD, dtype=np.float32)
    np.cos(theta, out=flat[:h])
    flat[:h] *= r
    if n - h == h:
        np.sin(theta, out=flat[h:])
        flat[h:] *= r
    else:
        np.sin(theta, out=theta)
        theta *= r
        flat[h:] = theta[: n - h]
    return out


def _cornish_fisher(
    z: np.ndarray, mean: np.ndarray, var: np.ndarray, k3: np.ndarray, k4: np.ndarray
) -> np.ndarray:
    """Third-order Cornish-Fisher quantile of a distribution with the given mean, variance and
    third and fourth cumulants at the standard normal quantile ``z``::

        x = mean + s z + a (z^2 - 1) / 6 + b (z^3 - 3 z) / 24 - c (2 z^3 - 5 z) / 36

    with ``s = sqrt(var)``, ``a = s gamma_1 = k3 / var``, ``b = s gamma_2 = k4 / (var s)``,
    ``c = s gamma_1^2 = a^2 / s``; evaluated in Horner form in ``z``'s dtype."""
    s = np.sqrt(var)
    a = k3 / var
    b = k4 / (var * s)
    c = a * a / s
    c3 = b / 24 - c / 18
    x = z * c3
    x += a / 6
    x *= z
    x += s - b / 8 + c * (5 / 36)
    x *= z
    x += mean - a / 6
    return x


def shot_electrons(mean_e: np.ndarray, rng: np.random.Generator, sampler: str = "hybrid") -> np.ndarray:
    """Poisson-distributed electron counts of mean ``mean_e`` (an array of integers in
    ``mean_e``'s float dtype).

    ``sampler = "poisson"``: numpy's exact Poisson sampler. ``"hybrid"``: exact below
    :data:`SHOT_NOISE_SWITCH_E` mean electrons; above, one standard normal ``z`` per pixel
    through the third-order Cornish-Fisher expansion of the Poisson quantile (cumulants
    ``kappa_2 = kappa_3 = kappa_4 = lam``), rounded to the nearest count -- the continuity
    correction of a lattice distribution -- with Sheppard's correction: the expansion is taken
    at variance ``lam - 1/12`` so that the rounded counts have variance ``lam``::

        n = rint(CF(z; mean lam, variance lam - 1/12, kappa_3 = kappa_4 = lam))

    This is the normal approximation of sensor simulators (exact Poisson for small means, a
    continuity-corrected normal above) with the skewness ``1/sqrt(lam)`` and kurtosis terms
    added, which a plain rounded normal lacks (a large sample detects that even at thousands of
    electrons). The draws of one call: all normals first, then the exact Poisson counts of the
    pixels below the switch-over.

    References
    ----------
    E. A. Cornish, R. A. Fisher, "Moments and cumulants in the specification of distributions",
    Revue de l'Institut International de Statistique 5 (1937) 307-320.
    W. F. Sheppard, "On the calculation of the most probable values of frequency-constants, for
    data arranged according to equidistant divisions of a scale", Proc. London Math. Soc. 29
    (1898) 353-380.
    """
    lam = np.asarray(mean_e)
    dtype = lam.dtype if lam.dtype in (np.float32, np.float64) else np.dtype(np.float64)
    lam = lam.astype(dtype, copy=False)
    if sampler == "poisson":
        return rng.poisson(lam).astype(dtype)
    if sampler != "hybrid":
        raise BenchSimError(f"sensor.shot_noise_sampler = {sampler!r}: allowed 'hybrid' or 'poisson'")
    z = rng.standard_normal(lam.shape, dtype=dtype)
    big = np.maximum(lam, dtype.type(SHOT_NOISE_SWITCH_E))  # the normal branch serves big means only
    n = _cornish_fisher(z, big, big - dtype.type(1 / 12), big, big)
    np.rint(n, out=n)
    np.maximum(n, 0, out=n)
    low = lam < SHOT_NOISE_SWITCH_E
    if low.any():
        n[low] = rng.poisson(lam[low])
    return n


def shot_and_read_electrons(
    mean_e: np.ndarray, deterministic_e: np.ndarray | float, read_noise_e: float, rng: np.random.Generator
) -> np.ndarray:
    """Electrons after shot and read noise, drawn together: ``d + Poisson(mu) + N(0, sigma^2)``
    from one standard normal per pixel through its third-order Cornish-Fisher expansion
    (cumulants ``kappa_2 = mu + sigma^2``, ``kappa_3 = kappa_4 = mu``). The normals come from
    :func:`box_muller_normals` for float32 ``mean_e`` (the quantised pixel model), from
    ``rng.standard_normal`` for float64; in float32 the expansion is evaluated by
    :func:`bench_sim.sensor.exposure_kernel.joint_quantile` (compiled, the loop the exposure
    loop uses, so every path that makes this draw agrees bit for bit).

    For ``sigma >=`` :data:`COMBINED_READ_NOISE_MIN_E` the sum's skewness is at most
    :data:`SKEWNESS_MAX` at every ``mu``, so the expansion's error terms (order ``gamma^3``) are
    of order 1e-4, and the electron lattice is invisible under the read noise (its ripple on the
    sum's density is ``~2 exp(-2 pi^2 sigma^2)``). The full-well clip between shot and read noise
    is not applied: callers use this only where the full well is more than
    :data:`FULL_WELL_SIGMAS` standard deviations away.

    Parameters
    ----------
    mean_e
        ``mu``: mean electrons of the Poisson part (float32 or float64 array).
    deterministic_e
        ``d``: electrons without noise (a light or dark signal whose noise is switched off).
    read_noise_e
        ``sigma`` [e- rms].
    """
    lam = np.asarray(mean_e)
    var = lam + lam.dtype.type(read_noise_e * read_noise_e)
    if lam.dtype != np.float32:
        z = rng.standard_normal(lam.shape, dtype=lam.dtype)
        return _cornish_fisher(z, lam + deterministic_e, var, lam, lam)
    z = box_muller_normals(rng, np.empty(lam.shape, dtype=np.float32))
    mean = np.asarray(lam + deterministic_e, dtype=np.float32)
    return joint_quantile(z, mean, var, lam, np.empty(lam.shape, dtype=lam.dtype))
