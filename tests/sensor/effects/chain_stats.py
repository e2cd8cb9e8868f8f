"""Shared statistics of the effects' tests: a flat field through a chain of effects, many seeds on
one physical sensor, and the checks that the sample mean and variance of ``dn`` are the truth's
``mean_dn`` and ``noise_std_dn**2``.

The truth of a pass depends on the config and the physical sensor only (not on the seed of the
temporal noise), so it is computed once per case and the other seeds draw ``dn`` alone.

The checks (pixel ``p``, ``S`` seeds, ``mu_p = mean_dn``, ``sigma_p = noise_std_dn``):

- mean: ``z_p = (mean_s dn - mu_p) / (sigma_p / sqrt(S))`` has mean 0 and variance 1 whatever the
  read's law (the clips make it far from normal: a pixel that sits at a clip dips rarely but far),
  so the mean of the ``z_p`` lies within 5 standard errors of 0 (the standard error from the
  spread of the lines' means of ``z``: the columns of a line share the row noise's draws) and
  their standard deviation in a band around 1;
- variance: the ratio ``R_p = s_p^2 / sigma_p^2`` of the sample variance has mean 1: within 5
  standard errors (from the lines' spread again, which carries the clips' kurtosis); where no clip
  acts the reads are close to normal and every pixel's ``(S - 1) R_p`` also lies within the
  chi-square(S - 1) quantiles of ``1e-3 / P`` (Bonferroni over the ``P`` pixels, valid whatever
  their correlation);
- where a clip acts, ``linear_dn`` (no clip) is not the truth: on the pixels it touched it would
  shift the z-scores' mean by more than 10 standard errors (the test sees a truth that ignores
  the clip);
- a pixel pinned to a clip or stuck (``sigma_p`` below :data:`PINNED_SD_DN`, under a rounding
  step: what little it varies comes from departures too rare for ``S`` seeds to sample) gives
  ``dn`` within half a DN of ``mu_p`` on average (exactly ``mu_p`` where ``sigma_p = 0``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from bench_sim.config import BenchConfig, SensorConfig
from bench_sim.pipeline import run_pass
from bench_sim.sensor.chain_truth import law_read_cumulants, law_read_model
from bench_sim.sensor.effects.chain import sensor_chain
from bench_sim.sensor.emva import expose
from bench_sim.sensor.fixed_pattern import FixedPattern, draw_fixed_pattern
from tests.conftest import tiny_cfg

#: the clips, each put in action in turn (``sections`` of the config; the irradiance [W/m^2] of
#: the default chain's flat field that brings the stage's mean to it, per stage)
CLIPS: dict[str, dict[str, Any]] = {
    "none": {"sections": {"dtdi": {"beta_bits": 20}}, "irradiance": {1: 100.0, 80: 10.0}},
    "full well": {"sections": {"dtdi": {"beta_bits": 20}}, "irradiance": {1: 515.0, 80: 515.0}},
    "ADC": {"sections": {"sensor": {"adc_bits": 9}, "dtdi": {"beta_bits": 20}},
            "irradiance": {1: 260.0, 80: 260.0}},
    "word at stage 1": {"sections": {"dtdi": {"beta_bits": 9}}, "irradiance": {1: 237.0}},
    "word at stage 80": {"sections": {}, "irradiance": {80: 26.7}},
}
#: the band of the standard deviation of the z-scores (1 for the exact truth)
Z_STD_BAND = (0.75, 1.3)
#: noise [DN] below which a pixel counts as pinned to a clip (or stuck): below a rounding step
PINNED_SD_DN = 0.3


def flat_cfg(effects: dict[str, Any], irradiance: float, *, columns: int = 16, lines: int = 16,
             **sections: Any) -> BenchConfig:
    """An 80-row sensor of ``columns`` columns with ``effects`` looking at a uniform panel lit by
    the weak light alone at ``irradiance`` [W/m^2], ``lines`` lines; ``sections`` on top."""
    base: dict[str, Any] = {
        "lines": lines, "sensor": {"rows": 80, "columns": columns, "effects": effects},
        "target": {"layout": "uniform", "panel_columns": 16},
        "lights": {"strong": {"enabled": False}, "weak": {"irradiance_w_m2": irradiance}},
        "fusion": {"mu1": 1, "mu2": 80},
    }
    for k, v in sections.items():
        base[k] = {**base.get(k, {}), **v}
    return tiny_cfg(**base)


def clip_cfg(effects: dict[str, Any], clip: str, stage: int, *, irradiance: float | None = None,
             columns: int = 16, lines: int = 16) -> BenchConfig:
    """:func:`flat_cfg` with the clip ``clip`` of :data:`CLIPS` in action at ``stage``
    (``irradiance``: another level than the default chain's, for a chain that changes the
    response)."""
    case = CLIPS[clip]
    level = case["irradiance"][stage] if irradiance is None else irradiance
    return flat_cfg(effects, level, columns=columns, lines=lines, **case["sections"])


@dataclass(frozen=True)
class Draws:
    """``dn`` of one stage over ``S`` seeds on one physical sensor, and its truth.

    Attributes
    ----------
    dn
        (S, lines, columns) stage words [DN] (float64).
    mean, sd, linear
        (lines, columns) ``mean_dn``, ``noise_std_dn``, ``linear_dn`` [DN].
    clipped
        (lines, columns) the truth's ``clipped``.
    fixed
        The physical sensor.
    """

    dn: np.ndarray
    mean: np.ndarray
    sd: np.ndarray
    linear: np.ndarray
    clipped: np.ndarray
    fixed: FixedPattern

    @property
    def seeds(self) -> int:
        return int(self.dn.shape[0])


def draw(cfg: BenchConfig, stages: list[int], *, seeds: int = 16, sensor_seed: int = 7) -> dict[int, Draws]:
    """``dn`` of ``stages`` over ``seeds`` seeds of the temporal noise on the one physical sensor
    drawn from ``sensor_seed``, and the truth (of the first seed: it does not depend on it)."""
    fp = draw_fixed_pattern(cfg.sensor, np.random.default_rng(sensor_seed))
    first = run_pass(cfg, stages, 1000, fixed_pattern=fp).dataset
    dn = {m: [first.dn.sel(stage=m).values.astype(np.float64)] for m in stages}
    for s in range(1, seeds):
        got = run_pass(cfg, stages, 1000 + s, fixed_pattern=fp, truth=False).stage_dn
        for m in stages:
            dn[m].append(got[m].astype(np.float64))
    out = {}
    for m in stages:
        d = first.sel(stage=m)
        out[m] = Draws(np.stack(dn[m]), d.mean_dn.values, d.noise_std_dn.values, d.linear_dn.values,
                       d.clipped.values, fp)
    return out


def _line_se(values: np.ndarray) -> float:
    """Standard error of the mean of (lines, columns) ``values`` (nan: left out) from the spread
    of the lines' means (columns of a line may be correlated; lines are not)."""
    per_line = np.array([np.mean(r[np.isfinite(r)]) for r in values if np.isfinite(r).any()])
    return float(per_line.std(ddof=1) / np.sqrt(per_line.size))


def assert_mean_is_the_truth(d: Draws, what: str) -> None:
    """The z-scores of the pixels' sample means (module docstring); pinned pixels stay at
    ``mean_dn``."""
    pinned = d.sd < PINNED_SD_DN
    assert np.all(d.dn[:, d.sd == 0] == d.mean[d.sd == 0]), (what, "a pixel without noise left mean_dn")
    assert np.all(np.abs(d.dn[:, pinned] - d.mean[pinned]).mean(axis=0) < 0.5), (what, "a pinned pixel moved")
    se_p = np.where(pinned, 1.0, d.sd) / np.sqrt(d.seeds)
    z = np.where(pinned, np.nan, (d.dn.mean(axis=0) - d.mean) / se_p)
    finite = z[np.isfinite(z)]
    assert finite.size >= 0.5 * z.size, (what, "too few pixels with noise")
    se = _line_se(z)
    assert abs(finite.mean()) < 5 * se, (what, finite.mean(), se)
    lo, hi = Z_STD_BAND
    assert lo < finite.std() < hi, (what, finite.std())


def assert_variance_is_the_truth(d: Draws, what: str, *, normal: bool) -> None:
    """The ratio of the sample variance to ``noise_std_dn**2`` (module docstring); ``normal``:
    no clip acts, every pixel's chi-square bound too."""
    noisy = d.sd >= PINNED_SD_DN
    ratio = np.where(noisy, d.dn.var(axis=0, ddof=1) / np.where(noisy, d.sd, 1.0) ** 2, np.nan)
    finite = ratio[noisy]
    se = _line_se(ratio)
    assert abs(finite.mean() - 1.0) < 5 * se, (what, finite.mean(), se)
    if normal:
        dof = d.seeds - 1
        alpha = 1e-3 / finite.size
        lo, hi = stats.chi2.ppf([alpha / 2, 1 - alpha / 2], dof) / dof
        assert lo < finite.min() and finite.max() < hi, (what, finite.min(), finite.max(), lo, hi)


def assert_clip_acts(d: Draws, clip: str) -> None:
    """The case puts its clip in action (``none``: no clip anywhere), and the clip shapes the
    truth: were ``linear_dn`` (no clip) the truth, the mean z-score of the pixels the clip
    touched would be off by more than 10 standard errors, so the z-scores have the power to see
    a truth that ignores the clip."""
    frac = float(d.clipped.mean())
    if clip == "none":
        assert frac == 0.0, (clip, frac)
        return
    assert frac >= 0.25, (clip, "the clip does not act", frac)
    touched = (d.sd >= PINNED_SD_DN) & d.clipped
    shift = (d.linear - d.mean)[touched] / (d.sd[touched] / np.sqrt(d.seeds))
    assert abs(shift.mean()) > 10 / np.sqrt(shift.size), (clip, "linear_dn is as good a truth", shift.mean())


def assert_truth(d: Draws, clip: str) -> None:
    """All of the above for one stage of one case."""
    assert_clip_acts(d, clip)
    assert_mean_is_the_truth(d, clip)
    assert_variance_is_the_truth(d, clip, normal=clip == "none")


# --- one read at a time: many frames of a small sensor ------------------------------------------


@dataclass(frozen=True)
class Reads:
    """Many reads of every pixel of a small sensor under a chain, and their truth.

    Attributes
    ----------
    reads
        (F, M, N) raw values [DN] (float64) of ``F`` frames.
    k1, k2
        (M, N) the truth's mean [DN] and variance [DN^2] of a read
        (:func:`bench_sim.sensor.chain_truth.law_read_cumulants`).
    """

    reads: np.ndarray
    k1: np.ndarray
    k2: np.ndarray


def expose_reads(sensor: SensorConfig, photons: np.ndarray, frames: int, *, seed: int = 3,
                 t_int_s: float = 1e-4) -> Reads:
    """``frames`` reads of a sensor of ``photons.shape`` (mean photons per pixel per frame,
    (M, N)) through its chain (:func:`bench_sim.sensor.emva.expose`, the draw path), and each
    read's mean and variance by the truth's own computation."""
    rng = np.random.default_rng(seed)
    fp = draw_fixed_pattern(sensor, rng)
    ph = np.broadcast_to(photons, (frames, *photons.shape)).astype(np.float32)
    reads = np.concatenate([expose(ph[f0:f0 + 512], sensor, fp, t_int_s, rng).astype(np.float64)
                            for f0 in range(0, frames, 512)])
    law = sensor_chain(sensor).law(dict(fp.effects))
    rm = law_read_model(sensor, law)
    light = sensor.quantum_efficiency * fp.prnu_gain * photons
    dark = fp.dark_current_e_s * t_int_s
    # the Poisson part and the part without noise (a source whose shot noise is switched off)
    if sensor.shot_noise == sensor.dark_noise:
        lam, det = light + dark, np.zeros(light.shape)
    else:
        lam, det = (light, dark) if sensor.shot_noise else (dark, light)
    offset = sensor.black_offset_dn + fp.column_offset_dn + (0.0 if fp.offset_dn is None else fp.offset_dn)
    k1, k2, _ = law_read_cumulants(lam, det, np.broadcast_to(offset, lam.shape), rm, law,
                                   slice(0, lam.shape[0]), noisy=sensor.shot_noise or sensor.dark_noise)
    return Reads(reads, k1, k2)


def assert_reads_follow_the_truth(r: Reads, what: str) -> None:
    """Every pixel's sample mean within 5 standard errors of ``k1``; its sample variance within 5
    standard errors of ``k2`` (the variance's standard error from the pixel's own fourth moment,
    which carries the clips' kurtosis) where ``k2 >= 0.01`` DN^2, and within 0.01 DN^2 of it
    where a read hardly varies (pinned to a clip: its rare departures are not sampled)."""
    n = r.reads.shape[0]
    mean = r.reads.mean(axis=0)
    dev = r.reads - mean
    var = (dev**2).mean(axis=0)
    m4 = (dev**4).mean(axis=0)
    pinned = r.k2 == 0
    still = np.abs(r.reads[:, pinned] - r.k1[pinned]) < 1e-6
    assert np.all(still), (what, "a read without noise left its mean")
    sel = ~pinned
    z_mean = (mean - r.k1)[sel] / np.sqrt(r.k2[sel] / n)
    assert np.abs(z_mean).max() < 5, (what, "mean", np.abs(z_mean).max())
    wide = r.k2 >= 0.01
    z_var = (var - r.k2)[wide] / np.sqrt(np.maximum(m4 - var**2, 1e-12)[wide] / n)
    assert np.abs(z_var).max() < 5, (what, "variance", np.abs(z_var).max())
    assert np.all(np.abs(var - r.k2)[~wide] < 0.01), (what, "variance of a pinned read")
