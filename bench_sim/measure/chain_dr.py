"""Measured dynamic range of ``Gamma1``, ``Gamma2`` and ``Gamma_HDR`` through the whole chain.

A photon-transfer series (EMVA 1288): a uniform field at many levels, from dark to beyond the
saturation of ``Gamma1``, goes through the sensor model, the streaming DTDI accumulator (the
one uniform-field runner, :func:`bench_sim.measure.uniform_field.expose_uniform`, with its
one pedestal rule) and the paper's fusion (eq. 11 with every stage's offset removed, the
fusion of every workflow: :func:`bench_sim.fusion.stage_pair.fuse_stage_words`). Per level and
image the mean and the temporal variance come from an image pair
(:func:`bench_sim.metrics.emva1288.mean_var_from_pair`), and the dynamic range
``20 lg(mu_p.sat / mu_p.min)`` from :func:`bench_sim.metrics.emva1288.dynamic_range_from_series`
(``mu_p.min``: SNR = 1 on the measured SNR curve). The photon unit is mean photons per pixel per
*frame* for all three images, so their DRs compare directly.

Saturation point
----------------
The headline ``dr_db`` uses EMVA 1288's definition: the irradiation of the maximum of the
temporal variance (``"interpolated"``: parabola through the grid maximum and its neighbours,
after ``refine_rounds`` rounds of extra levels around it). The point where the linear response
meets the clipped plateau (``"extrapolated"``, a few per cent higher, independent of the grid)
is reported as well, labelled ``dr_db_extrapolated``.

What the gains mean
-------------------
Below the eq. 11 threshold ``Gamma_HDR`` *is* ``Gamma2``, so the two share the SNR = 1 point;
where both stages clip on the output word (not on the pixel) and carry the same offset, their
saturation points differ by exactly ``mu2 / mu1``. The gain over ``Gamma2`` then equals
``20 lg(mu2 / mu1)`` (eq. 15) *by construction* (exactly for the clip points, to a few tenths
of a dB for the variance maxima): it confirms the code, not the method. The informative
figure is the gain over the better input, ``Gamma1``: the saturation end is the same, and the
noise floor drops by about the ratio of the two stages' read-noise floors, ``sqrt(mu2 / mu1)``
(read noise adds up as ``sqrt(m)`` in the digital sum), so it is about ``10 lg(mu2 / mu1)``, not
``20 lg``. That ratio is not a bound of the gain: at SNR = 1 the signal's own shot noise weighs
less in the longer sum, and the gain exceeds it a little (9.10 dB against 9.03 dB on the paper
rig, in closed form).
:attr:`ChainDR.gain_over_gamma2_by_construction` says whether the condition holds for the run.

References
----------
.. [EMVA] EMVA Standard 1288, Release 4.0 Linear: Standard for Characterization of Image
   Sensors and Cameras, European Machine Vision Association, 2021,
   section 3 (saturation at the variance maximum; SNR = 1
   threshold).
.. [DTDI] *An HDR Imaging Method With DTDI Technology for Push-Broom Cameras* (the paper
   bench_sim reproduces), eq. 11 (fusion) and eq. 15 (predicted gain).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.errors import BenchSimError
from bench_sim.fusion.stage_pair import fuse_stage_words
from bench_sim.measure.uniform_field import (
    expose_uniform,
    measurement_offsets_dn,
    measurement_pedestal_dn,
)
from bench_sim.metrics.dynamic_range import dr_increase_eq15_db
from bench_sim.metrics.emva1288 import SaturationMethod, dynamic_range_from_series, mean_var_from_pair
from bench_sim.metrics.snr import snr_versus_signal
from bench_sim.runtime.parallel import child_sequence, chunk_generator, parallel_map, seed_sequence
from bench_sim.sensor.emva import draw_fixed_pattern
from bench_sim.sensor.model import (
    full_scale_dn,
    hdr_dr_model_db,
    stage_clips_on_word,
    stage_dr_model_db,
    stage_saturation_photons,
    stage_snr1_photons,
)

__all__ = ["IMAGES", "ImageDR", "ChainDR", "default_levels", "measure_chain_dynamic_range"]

#: The three images of the paper, in the order they are reported.
IMAGES: tuple[str, ...] = ("gamma1", "gamma2", "gamma_hdr")


@dataclass(frozen=True)
class ImageDR:
    """Measured dynamic range of one image type (photons per pixel per frame; DN).

    ``dr_db``, ``photons_sat``, ``signal_sat_dn``: EMVA 1288 saturation (variance maximum);
    ``dr_db_extrapolated``, ``photons_sat_extrapolated``: the linear response meeting the
    plateau. ``mean_dn`` (offset removed; HDR in stage-``mu2`` units), ``temporal_std_dn`` and
    ``snr`` per level of the series.
    """

    dr_db: float
    photons_min: float
    photons_sat: float
    signal_sat_dn: float
    dr_db_extrapolated: float
    photons_sat_extrapolated: float
    mean_dn: np.ndarray = field(repr=False)
    temporal_std_dn: np.ndarray = field(repr=False)
    snr: np.ndarray = field(repr=False)

    def as_dict(self) -> dict[str, Any]:
        return {
            "dr_db": self.dr_db,
            "photons_min": self.photons_min,
            "photons_sat": self.photons_sat,
            "signal_sat_dn": self.signal_sat_dn,
            "dr_db_extrapolated": self.dr_db_extrapolated,
            "photons_sat_extrapolated": self.photons_sat_extrapolated,
            "mean_dn": self.mean_dn.tolist(),
            "temporal_std_dn": self.temporal_std_dn.tolist(),
            "snr": [float(x) if np.isfinite(x) else None for x in self.snr],
        }


@dataclass(frozen=True)
class ChainDR:
    """Result of :func:`measure_chain_dynamic_range`."""

    mu1: int
    mu2: int
    beta_bits: int
    adc_bits: int
    t_int_s: float
    lines: int
    columns: int
    pedestal_dn: int
    offsets_dn: dict[int, float]
    photons: np.ndarray = field(repr=False)
    images: dict[str, ImageDR] = field(repr=False)
    stage_clips_on_word: dict[int, bool] = field(default_factory=dict)
    model_dr_db: dict[str, float] = field(default_factory=dict)

    @property
    def dr_db(self) -> dict[str, float]:
        """Headline DR [dB] per image (EMVA 1288 saturation)."""
        return {k: v.dr_db for k, v in self.images.items()}

    @property
    def eq15_db(self) -> float:
        """Eq. 15, ``20 lg(mu2 / mu1)`` [dB]."""
        return dr_increase_eq15_db(self.mu1, self.mu2)

    @property
    def gain_over_gamma1_db(self) -> float:
        """``DR(HDR) - DR(Gamma1)`` [dB]: the gain over the better-exposed input's noise floor."""
        return self.images["gamma_hdr"].dr_db - self.images["gamma1"].dr_db

    @property
    def gain_over_gamma2_db(self) -> float:
        """``DR(HDR) - DR(Gamma2)`` [dB]."""
        return self.images["gamma_hdr"].dr_db - self.images["gamma2"].dr_db

    @property
    def gain_over_gamma2_extrapolated_db(self) -> float:
        """``DR(HDR) - DR(Gamma2)`` [dB] with the extrapolated saturation points (where the
        linear response meets the clipped plateau): the ratio of the clip points that eq. 15
        is about, free of the scatter of the variance maxima (a few tenths of a dB)."""
        return self.images["gamma_hdr"].dr_db_extrapolated - self.images["gamma2"].dr_db_extrapolated

    @property
    def gain_over_gamma2_by_construction(self) -> bool:
        """True when both stages clip on the output word with the same offset: the gain over
        ``Gamma2`` is then ``20 lg(mu2/mu1)`` by construction (see the module doc)."""
        clips = self.stage_clips_on_word
        same_offset = self.offsets_dn.get(self.mu1) == self.offsets_dn.get(self.mu2)
        return bool(clips.get(self.mu1)) and bool(clips.get(self.mu2)) and same_offset

    def fusion_switch(self) -> dict[str, float]:
        """Where ``Gamma_HDR`` switches from ``Gamma2`` to ``(mu2/mu1) Gamma1`` (eq. 11) and what
        its SNR does there.

        The switch sits at the HDR signal ``Phi_FS - P2`` [DN, stage-``mu2`` units] (``P2`` the
        offset of ``Gamma2``'s word). Below it the HDR pixel is ``Gamma2``; above it, the
        ``mu1`` read sum scaled by ``mu2/mu1``, whose relative noise is larger (fewer electrons,
        read noise of ``mu1`` reads), so the SNR drops. Returned: ``threshold_dn``,
        ``photons`` (photons per pixel per frame at the switch, interpolated on the HDR's mean
        response), and the HDR's measured SNR at the last level below 0.9 and the first level
        above 1.1 times the threshold (``snr_below``, ``snr_above``; NaN where the series has no
        such level), with those levels' photons.
        """
        hdr = self.images["gamma_hdr"]
        thr = float(full_scale_dn(self.beta_bits)) - float(self.offsets_dn[self.mu2])
        mean = np.asarray(hdr.mean_dn, dtype=np.float64)
        snr = np.asarray(hdr.snr, dtype=np.float64)
        below = np.flatnonzero((mean < 0.9 * thr) & (self.photons > 0))
        above = np.flatnonzero(mean > 1.1 * thr)
        rising = np.flatnonzero(np.diff(mean) > 0)
        cross = float("nan")
        if rising.size and mean[rising[0]] <= thr <= mean.max():
            k = int(np.argmax(mean >= thr))
            if k > 0:
                m0, m1, p0, p1 = mean[k - 1], mean[k], self.photons[k - 1], self.photons[k]
                cross = float(p0 + (thr - m0) * (p1 - p0) / (m1 - m0)) if m1 > m0 else float(p1)
        nan = float("nan")
        return {
            "threshold_dn": thr,
            "photons": cross,
            "snr_below": float(snr[below[-1]]) if below.size else nan,
            "photons_below": float(self.photons[below[-1]]) if below.size else nan,
            "snr_above": float(snr[above[0]]) if above.size else nan,
            "photons_above": float(self.photons[above[0]]) if above.size else nan,
        }

    @property
    def level_step_db_max(self) -> float:
        p = self.photons[self.photons > 0]
        steps = np.diff(np.log10(p))
        return float(20.0 * steps.max()) if steps.size else float("nan")

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready dict (``metrics.json``'s ``dr_details``)."""
        return {
            "mu1": self.mu1,
            "mu2": self.mu2,
            "beta_bits": self.beta_bits,
            "adc_bits": self.adc_bits,
            "t_int_s": self.t_int_s,
            "lines": self.lines,
            "columns": self.columns,
            "pedestal_dn": self.pedestal_dn,
            "offset_dn": {str(m): v for m, v in self.offsets_dn.items()},
            "saturation": "EMVA 1288: maximum of the temporal variance (parabola between levels)",
            "saturation_extrapolated": "linear response meets the clipped plateau",
            "photon_unit": "mean photons per pixel per frame",
            "level_step_db_max": self.level_step_db_max,
            "photons": self.photons.tolist(),
            "images": {k: v.as_dict() for k, v in self.images.items()},
            "dr_db": self.dr_db,
            "dr_db_extrapolated": {k: v.dr_db_extrapolated for k, v in self.images.items()},
            "model_dr_db": dict(self.model_dr_db),
            "delta_db_vs_gamma1": self.gain_over_gamma1_db,
            "delta_db_vs_gamma2": self.gain_over_gamma2_db,
            "delta_db_vs_gamma2_extrapolated": self.gain_over_gamma2_extrapolated_db,
            "stage_clips_on_word": {str(m): v for m, v in self.stage_clips_on_word.items()},
            "gain_over_gamma2_by_construction": self.gain_over_gamma2_by_construction,
            "eq15_db": self.eq15_db,
            "fusion_switch": self.fusion_switch(),
        }


def _stage_sat(cfg: BenchConfig, m: int, pedestal_dn: float) -> float:
    return stage_saturation_photons(
        cfg.sensor, cfg.timing.t_int_s, m, beta_bits=cfg.dtdi.beta_bits,
        subtract_black=cfg.dtdi.subtract_black, pedestal_dn=pedestal_dn,
    )


def default_levels(
    cfg: BenchConfig, mu1: int, mu2: int, pedestal_dn: float, n_levels: int = 40
) -> np.ndarray:
    """Photon levels of the series: 0 (dark) and ``n_levels`` geometric levels [photons/pixel/frame],
    from a quarter of stage ``mu2``'s SNR = 1 point to twice stage ``mu1``'s saturation (model,
    :mod:`bench_sim.sensor.model`; it only places the levels)."""
    p_lo = 0.25 * stage_snr1_photons(cfg.sensor, cfg.timing.t_int_s, mu2)
    p_hi = 2.0 * _stage_sat(cfg, mu1, pedestal_dn)
    return np.concatenate([[0.0], np.geomspace(p_lo, p_hi, n_levels)])


def _series(
    cfg: BenchConfig, mu1: int, mu2: int, levels: np.ndarray, noise: np.random.SeedSequence, fixed: Any,
    lines: int, columns: int, pedestal: int, offsets: dict[int, float],
) -> dict[str, np.ndarray]:
    """Per image: (levels, 2) array of (mean [DN], temporal variance [DN^2]), offsets removed.

    Level ``i`` draws its temporal noise from its own stream (:func:`chunk_generator`
    ``(noise, i)``), so the levels run on the thread pool and the series does not depend on the
    number of threads."""

    def level(i: int) -> dict[str, tuple[float, float]]:
        st = expose_uniform(
            cfg, (mu1, mu2), float(levels[i]), chunk_generator(noise, i), fixed=fixed, lines=lines,
            columns=columns, images=2, pedestal_dn=pedestal,
        )
        g1 = st[mu1].reshape(2 * lines, columns)
        g2 = st[mu2].reshape(2 * lines, columns)
        fused = fuse_stage_words(cfg, g1, g2, mu1=mu1, mu2=mu2, pedestal_dn=pedestal)
        images = {"gamma1": g1 - offsets[mu1], "gamma2": g2 - offsets[mu2], "gamma_hdr": fused.hdr}
        return {name: mean_var_from_pair(img[:lines], img[lines:]) for name, img in images.items()}

    per_level = parallel_map(level, range(levels.size))
    return {name: np.array([r[name] for r in per_level], dtype=np.float64).reshape(-1, 2) for name in IMAGES}


def _check_args(cfg: BenchConfig, mu1: int, mu2: int, lines: int, columns: int, saturation: str) -> None:
    """Refuse bad arguments of :func:`measure_chain_dynamic_range` (one-line :class:`BenchSimError`)."""
    if not 1 <= mu1 < mu2 <= cfg.sensor.rows:
        raise BenchSimError(f"mu1 = {mu1}, mu2 = {mu2}: need 1 <= mu1 < mu2 <= sensor.rows")
    if not (isinstance(lines, int) and lines >= 1 and isinstance(columns, int) and columns >= 1):
        raise BenchSimError(f"lines = {lines!r}, columns = {columns!r}: need integers >= 1")
    if lines * columns < 2 or columns > cfg.sensor.columns:
        raise BenchSimError(f"lines x columns = {lines} x {columns}: need >= 2 pixels within the sensor")
    if saturation not in ("extrapolated", "interpolated", "max_variance"):
        raise BenchSimError(
            f"saturation = {saturation!r}: allowed 'extrapolated', 'interpolated', 'max_variance'"
        )


def _refine(
    run: Callable[[np.ndarray, int], dict[str, np.ndarray]],
    p: np.ndarray,
    stats: dict[str, np.ndarray],
    refine_rounds: int,
    refine_points: int,
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Rounds of ``refine_points`` extra levels between the neighbours of each image's variance
    maximum; ``run(levels, r)`` measures round ``r``'s levels. Returns all levels (sorted) and
    their statistics."""
    for r in range(1, refine_rounds + 1):
        extra: list[np.ndarray] = []
        for name in IMAGES:
            i = int(np.argmax(stats[name][:, 1]))
            lo, hi = p[max(i - 1, 0)], p[min(i + 1, p.size - 1)]
            if hi > lo:
                extra.append(np.linspace(lo, hi, refine_points + 2)[1:-1])
        new = np.setdiff1d(np.unique(np.concatenate(extra)), p) if extra else np.array([])
        if not new.size:
            break
        more = run(new, r)
        allp = np.concatenate([p, new])
        order = np.argsort(allp, kind="stable")
        p = allp[order]
        stats = {k: np.concatenate([stats[k], more[k]])[order] for k in IMAGES}
    return p, stats


def _image_dr(p: np.ndarray, stats: np.ndarray, saturation: SaturationMethod) -> ImageDR:
    """One image's DR from its series (``stats``: (levels, 2) mean [DN], variance [DN^2])."""
    mean = stats[:, 0]
    std = np.sqrt(np.maximum(stats[:, 1], 0.0))
    dark = float(mean[0])
    main = dynamic_range_from_series(p, mean, std, dark_signal=dark, saturation=saturation)
    ext = dynamic_range_from_series(p, mean, std, dark_signal=dark, saturation="extrapolated")
    return ImageDR(
        dr_db=main.dr_db,
        photons_min=main.photons_min,
        photons_sat=main.photons_sat,
        signal_sat_dn=main.signal_sat,
        dr_db_extrapolated=ext.dr_db,
        photons_sat_extrapolated=ext.photons_sat,
        mean_dn=mean,
        temporal_std_dn=std,
        snr=snr_versus_signal(mean, std, dark)[1],
    )


def _model(cfg: BenchConfig, mu1: int, mu2: int, pedestal: float) -> tuple[dict[int, bool], dict[str, float]]:
    """Where each stage clips (on the word, below the pixel's clip, or on the pixel) and the
    sensor model's DR [dB] per image (:mod:`bench_sim.sensor.model`)."""
    clips = {
        m: stage_clips_on_word(
            cfg.sensor, m, beta_bits=cfg.dtdi.beta_bits, subtract_black=cfg.dtdi.subtract_black,
            pedestal_dn=pedestal,
        )
        for m in (mu1, mu2)
    }
    model = {
        "gamma1": stage_dr_model_db(cfg, mu1, pedestal),
        "gamma2": stage_dr_model_db(cfg, mu2, pedestal),
        "gamma_hdr": hdr_dr_model_db(cfg, mu1, mu2, pedestal),
    }
    return clips, {k: float(v) for k, v in model.items()}


def measure_chain_dynamic_range(
    cfg: BenchConfig,
    seed: int | np.random.SeedSequence | np.random.Generator,
    *,
    mu1: int | None = None,
    mu2: int | None = None,
    levels: np.ndarray | None = None,
    n_levels: int = 40,
    lines: int = 32,
    columns: int = 64,
    saturation: SaturationMethod = "interpolated",
    refine_rounds: int = 2,
    refine_points: int = 8,
) -> ChainDR:
    """Measured DR (EMVA 1288) of ``Gamma1``, ``Gamma2``, ``Gamma_HDR`` through the whole chain.

    Parameters
    ----------
    cfg
        Bench config: sensor, timing, DTDI (word, pedestal) and the fused stages
        (``fusion.mu1``, ``fusion.mu2`` unless given).
    seed
        Seed of the measurement's random generator (a ``Generator`` is used as is): the fixed
        pattern first, then one ``SeedSequence`` whose children give every level of every
        series (first, then each refinement round) its own temporal-noise stream, so the
        levels run on the thread pool and the result does not depend on the thread count.
    mu1, mu2
        Stages fused (default: the config's).
    levels
        Photon levels [photons/pixel/frame], strictly increasing (the dark level 0 is added if
        missing); default :func:`default_levels` with ``n_levels`` lit levels.
    lines, columns
        Image size per level (two images each).
    saturation
        Definition of ``mu_p.sat`` for the headline ``dr_db`` (EMVA's ``"interpolated"`` variance
        maximum by default; ``"extrapolated"`` is always reported as well).
    refine_rounds, refine_points
        For the variance-maximum definitions: rounds of ``refine_points`` extra levels between
        the neighbours of each image's variance maximum.
    """
    mu1 = cfg.fusion.mu1 if mu1 is None else int(mu1)
    mu2 = cfg.fusion.mu2 if mu2 is None else int(mu2)
    _check_args(cfg, mu1, mu2, lines, columns, saturation)
    pedestal = measurement_pedestal_dn(cfg, (mu1, mu2))
    offsets = measurement_offsets_dn(cfg, (mu1, mu2), pedestal)
    if levels is None:
        levels = default_levels(cfg, mu1, mu2, pedestal, n_levels)
    p = np.union1d([0.0], np.asarray(levels, dtype=np.float64))
    if p[0] < 0 or not np.all(np.isfinite(p)):
        raise BenchSimError("levels: need finite photon levels >= 0")
    rng = np.random.default_rng(seed)
    fixed = draw_fixed_pattern(cfg.sensor, rng)
    noise = seed_sequence(rng)  # series r: levels' streams under (noise, r)

    def run(at: np.ndarray, r: int) -> dict[str, np.ndarray]:
        return _series(cfg, mu1, mu2, at, child_sequence(noise, r), fixed, lines, columns, pedestal, offsets)

    stats = run(p, 0)
    if saturation != "extrapolated":
        p, stats = _refine(run, p, stats, refine_rounds, refine_points)
    images = {name: _image_dr(p, stats[name], saturation) for name in IMAGES}
    clips, model = _model(cfg, mu1, mu2, pedestal)
    return ChainDR(
        mu1=mu1, mu2=mu2, beta_bits=cfg.dtdi.beta_bits, adc_bits=cfg.sensor.adc_bits,
        t_int_s=cfg.timing.t_int_s, lines=lines, columns=columns, pedestal_dn=pedestal, offsets_dn=offsets,
        photons=p, images=images, stage_clips_on_word=clips, model_dr_db=model,
    )
