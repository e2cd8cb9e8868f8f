"""The exact mean response of a physical sensor through its chain, and the chain's linearity
error on a measurement's levels: the closed form ``ptc --area`` compares its LE with, and the
twin's curve ``calibrate`` draws over the data.

At every level: the expectation of each read of the physical sensor
(:func:`bench_sim.sensor.chain_truth.law_read_cumulants`, every effect and clip included)
averaged over its pixels, less the dark level's, and the mean temporal variance (the variance an
EMVA 1288 pair measures). The chain's LE is that curve put through EMVA 1288's estimator
(:func:`bench_sim.sensor.linearity.linearity_error`) on the measurement's own grid.

References
----------
EMVA Standard 1288, Release 4.0 Linear (2021), sections 2 and 6.
"""

from __future__ import annotations

import numpy as np

from bench_sim.config import SensorConfig
from bench_sim.sensor.chain_truth import law_read_cumulants, law_read_model
from bench_sim.sensor.effects.chain import sensor_chain
from bench_sim.sensor.fixed_pattern import FixedPattern
from bench_sim.sensor.linearity import LinearityError, linearity_error

__all__ = ["chain_response_curve", "predicted_linearity_error"]


def _poisson_parts(
    sensor: SensorConfig, light_e: np.ndarray, dark_e: np.ndarray
) -> tuple[np.ndarray, np.ndarray, bool]:
    """The Poisson part, the part without noise [e-] and whether the first is Poisson, as the
    draw takes them (:mod:`bench_sim.sensor.chain_draw`, step 2)."""
    if sensor.shot_noise and sensor.dark_noise:
        return light_e + dark_e, np.zeros(()), True
    if sensor.shot_noise:
        return light_e, dark_e, True
    if sensor.dark_noise:
        return np.broadcast_to(dark_e, light_e.shape), light_e, True
    return light_e + dark_e, np.zeros(()), False


def chain_response_curve(
    sensor: SensorConfig,
    fixed: FixedPattern,
    photons: np.ndarray,
    exposure_s: np.ndarray,
    *,
    mask: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The exact mean response of a physical sensor: per level, the dark-subtracted signal [DN]
    (each read's expectation under the chain's law, averaged over the pixels) and the mean
    temporal variance [DN^2] of a read.

    Parameters
    ----------
    sensor
        The sensor and its chain of effects.
    fixed
        The physical sensor (its window: the pixels measured).
    photons, exposure_s
        Mean photons per pixel and exposure time [s] of each level (arrays of one length).
    mask
        (M, N) pixels to average over (default: all).
    """
    p = np.asarray(photons, dtype=np.float64).ravel()
    t = np.broadcast_to(np.asarray(exposure_s, dtype=np.float64).ravel(), p.shape)
    law = sensor_chain(sensor).law(dict(fixed.effects))
    rm = law_read_model(sensor, law)
    rows = slice(0, fixed.shape[0])
    offset = sensor.black_offset_dn + np.broadcast_to(fixed.column_offset_dn, fixed.shape)
    if fixed.offset_dn is not None:
        offset = offset + fixed.offset_dn
    keep = np.ones(fixed.shape, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    qe_g = sensor.quantum_efficiency * fixed.prnu_gain
    signal, var = np.empty(p.size), np.empty(p.size)
    for i, (pi, ti) in enumerate(zip(p, t, strict=True)):
        dark_e = fixed.dark_current_e_s * float(ti)
        means = []
        for light in (qe_g * pi, np.zeros(fixed.shape)):
            lam, det, noisy = _poisson_parts(sensor, light, dark_e)
            k1, k2, _ = law_read_cumulants(lam, det, offset, rm, law, rows, noisy=noisy)
            means.append(float(k1[keep].mean()))
            if len(means) == 1:
                var[i] = float(k2[keep].mean())
        signal[i] = means[0] - means[1]
    return signal, var


def predicted_linearity_error(
    sensor: SensorConfig,
    fixed: FixedPattern,
    photons: np.ndarray,
    exposure_s: np.ndarray,
    *,
    mask: np.ndarray | None = None,
    x: np.ndarray | None = None,
) -> LinearityError:
    """LE of the chain on the measurement's grid: :func:`chain_response_curve` put through
    :func:`linearity_error` (``x``: the irradiation the measurement fits against, default the
    photons)."""
    signal, var = chain_response_curve(sensor, fixed, photons, exposure_s, mask=mask)
    return linearity_error(np.asarray(photons if x is None else x, dtype=np.float64), signal, var)
