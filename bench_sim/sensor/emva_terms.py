"""The EMVA 1288 quantities a physical sensor has, in closed form: what ``ptc --area`` measures
of it and what ``calibrate`` fits.

:func:`sensor_emva_terms` collects, for a physical sensor (its :class:`FixedPattern`, e.g. the
window a measurement exposes):

* the default chain's quantities (:func:`default_emva_terms`): ``K``, the quantum efficiency and
  the read noise (the config's), and of the drawn maps over the pixels that are not defects: the
  mean dark current and its non-uniformity (``dark_current_nu_e_s``, the rms of the dark-current
  map), PRNU (the rms of the gain map) and the column offsets' rms in electrons
  (``dsnu0_column_e``, the column part of the offset pattern at 0 s);
* every effect's own terms (:meth:`bench_sim.sensor.effects.chain.SensorChain.emva`): the offset
  pattern's ``dsnu0_e``, the row noise's ``row_noise_var_dn2``, the defect pixels' counts and
  positions, the response at the full well;
* where levels are given, the linearity error of the whole chain on them
  (:func:`bench_sim.sensor.response_curve.predicted_linearity_error`).

References
----------
EMVA Standard 1288, Release 4.0 Linear (2021), sections 2 and 8.
"""

from __future__ import annotations

import numpy as np

from bench_sim.config import SensorConfig
from bench_sim.sensor.effects.base import EmvaTerm
from bench_sim.sensor.effects.chain import sensor_chain
from bench_sim.sensor.fixed_pattern import FixedPattern
from bench_sim.sensor.response_curve import predicted_linearity_error

__all__ = ["default_emva_terms", "defect_mask", "sensor_emva_terms"]


def defect_mask(terms: list[EmvaTerm], shape: tuple[int, int]) -> np.ndarray:
    """(M, N) mask of the pixels some term names (the defect pixels)."""
    mask = np.zeros(shape, dtype=bool)
    for term in terms:
        for r, c in term.positions:
            mask[r, c] = True
    return mask


def default_emva_terms(sensor: SensorConfig, fixed: FixedPattern, good: np.ndarray) -> list[EmvaTerm]:
    """The default chain's EMVA 1288 quantities of the physical sensor ``fixed`` over the pixels
    of ``good`` (module docstring)."""
    k = sensor.conversion_gain_dn_per_e
    dark = fixed.dark_current_e_s[good]
    gain = fixed.prnu_gain[good]
    return [
        EmvaTerm("K_dn_per_e", k, "DN/e-", "overall system gain (the config's)"),
        EmvaTerm("quantum_efficiency", sensor.quantum_efficiency, "1", "quantum efficiency (the config's)"),
        EmvaTerm("read_noise_e", sensor.read_noise_e if sensor.read_noise else 0.0, "e-", "read noise"),
        EmvaTerm("dark_current_e_s", float(dark.mean()), "e-/s", "mean dark current of the drawn map"),
        EmvaTerm(
            "dark_current_nu_e_s",
            float(dark.std()),
            "e-/s",
            "rms over the pixels of the drawn dark-current map (its non-uniformity)",
        ),
        EmvaTerm("prnu", float(gain.std() / gain.mean()), "1", "rms over the pixels of the drawn gain map"),
        EmvaTerm(
            "dsnu0_column_e",
            float(np.std(fixed.column_offset_dn)) / k,
            "e-",
            "rms of the column offsets (the column part of the offset pattern at 0 s), in electrons",
        ),
    ]


def sensor_emva_terms(
    sensor: SensorConfig,
    fixed: FixedPattern,
    t_int_s: float,
    *,
    photons: np.ndarray | None = None,
    exposure_s: np.ndarray | float | None = None,
) -> dict[str, EmvaTerm]:
    """Every EMVA 1288 quantity of the physical sensor ``fixed`` in closed form, by name (module
    docstring); with ``photons`` (and their ``exposure_s``, default ``t_int_s``) also the chain's
    ``linearity_error_percent`` on those levels."""
    effect_terms = sensor_chain(sensor).emva(dict(fixed.effects), t_int_s)
    good = ~defect_mask(effect_terms, fixed.shape)
    terms = {t.name: t for t in [*default_emva_terms(sensor, fixed, good), *effect_terms]}
    if photons is not None:
        p = np.asarray(photons, dtype=np.float64)
        t = np.broadcast_to(
            np.asarray(t_int_s if exposure_s is None else exposure_s, dtype=np.float64), p.shape
        )
        le = predicted_linearity_error(sensor, fixed, p, t, mask=good)
        terms["linearity_error_percent"] = EmvaTerm(
            "linearity_error_percent",
            le.le_percent,
            "%",
            "the chain's exact mean response on the levels through the EMVA 1288 LE estimator",
        )
    return terms
