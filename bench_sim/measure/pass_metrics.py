"""Metrics of one simulation pass (a :class:`~bench_sim.pipeline.PassResult` and its
eq. 11 fusion): eq. 16-18 (omega of ``Gamma1``, ``Gamma2``, ``Gamma_HDR``), saturated fractions,
the darkest and brightest wedge patches (spatial SNR, level, clipping) and the paper's
qualitative claims. ``reproduce`` and ``sweep`` both report them.

All of them are *scene-referred*: they depend on the lights and the target as much as on the
camera (unlike the dynamic range measured through the chain,
:mod:`bench_sim.measure.chain_dr`). The darkest and brightest patches are the wedge steps
(of either half of the ``paper`` target) with the lowest and highest mean ``Gamma_HDR``, i.e.
as lit; other targets have no wedge and give ``None`` with the reason.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.fusion.common import FusionResult
from bench_sim.metrics.histogram import Eq18Result, evaluate_eq18
from bench_sim.pipeline import PassResult
from bench_sim.sensor.model import dark_noise_e, stage_offset_dn, stage_variance_dn2

__all__ = [
    "PassMetrics", "pass_metrics", "patch_slices", "spatial_snr", "temporal_snr", "SNR_IN_NOISE", "SNR_ROSE",
    "stage_temporal_var_dn2",
]

#: SNR below which a patch counts as "in the noise", and the Rose criterion for "out of it"
SNR_IN_NOISE = 2.0
SNR_ROSE = 3.0


@dataclass(frozen=True)
class PassMetrics:
    """What :func:`pass_metrics` returns (the dicts are ``metrics.json``'s entries).

    ``darkest_patch``, ``brightest_patch`` and ``qualitative`` are ``None`` when the image holds
    no wedge patch (targets other than ``paper``, or too few lines); ``no_patches`` then says
    why.

    With the pass's truth (``run_pass(..., truth=True)``) the patches are ranked by their exact
    mean photons instead of ``Gamma_HDR`` (which ties where it clips), and the wedge measures
    ranges in scene terms: ``scene_range_db``, the range of the wedge as lit,
    ``20 lg(brightest / darkest)``; ``captured_range_db[image]``, the range of the patches the
    image renders usefully (spatial SNR at least :data:`SNR_ROSE` and under half its pixels
    clipped), ``None`` when it renders none; ``clipped_fraction[image]``, the pixels whose value
    is clipped anywhere in the chain (a read at full well or the ADC's top, or the word at its
    top; ``Gamma_HDR``: in the stage it takes) -- unlike ``saturated_fraction`` (the word at its
    top) it also sees a stage that clips on the pixel. The brightest patch then has no SNR in an
    image where more than half of it is clipped.
    """

    eq18: Eq18Result
    saturated_fraction: dict[str, float]
    darkest_patch: dict[str, Any] | None
    brightest_patch: dict[str, Any] | None
    qualitative: dict[str, bool] | None
    no_patches: str | None = None
    scene_range_db: float | None = None
    captured_range_db: dict[str, float | None] | None = None
    clipped_fraction: dict[str, float] | None = None


def patch_slices(panel: Any, geom: Any, cfg: BenchConfig, lines: int) -> dict[str, tuple[slice, slice]]:
    """Patch name -> (line slice, column slice) in the output images."""
    scale = geom.object_pixel_m / geom.delta_m  # panel pixels -> lines (1 in sync)
    n = cfg.sensor.columns
    off = n / 2.0 - cfg.target.panel_columns / 2.0 - 0.5  # column = v + off
    out = {}
    for p in panel.patches:
        l0, l1 = math.ceil(p.u0 * scale), math.floor(p.u1 * scale)
        c0, c1 = math.ceil(p.v0 + off), math.floor(p.v1 + off)
        if 0 <= l0 < l1 <= lines and 0 <= c0 < c1 <= n:
            out[p.name] = (slice(l0, l1), slice(c0, c1))
    return out


def spatial_snr(img: np.ndarray, sl: tuple[slice, slice]) -> float:
    """Mean over standard deviation of the pixels of a region (``inf`` for a constant one)."""
    region = np.asarray(img[sl], dtype=np.float64)
    sd = float(region.std())
    return float(region.mean() / sd) if sd > 0 else float("inf")


def _saturated_fractions(g1: np.ndarray, g2: np.ndarray, fused: FusionResult, clip: int) -> dict[str, float]:
    """Fraction of each image's pixels at the top of the word (``Gamma_HDR``: where it clips)."""
    return {
        "gamma1": float(np.mean(g1 >= clip)),
        "gamma2": float(np.mean(g2 >= clip)),
        "gamma_hdr": float(np.mean(fused.saturated)),
    }


def _no_wedge_reason(cfg: BenchConfig, panel: Any, lines: int) -> str:
    return (
        f"target.layout = {cfg.target.layout!r} has no wedge patches"
        if not panel.patches
        else f"no wedge patch lies wholly inside the {lines} lines x {cfg.sensor.columns} columns"
    )


def _bright_patch(
    name: str, reflectance: float, sl: tuple[slice, slice], images: dict[str, np.ndarray],
    s1: np.ndarray, g2: np.ndarray, fused: FusionResult, beta: int,
) -> dict[str, Any]:
    """The brightest patch's entry: SNR per image, Gamma1's level, the clipped fractions."""
    clip = 2**beta - 1
    snr = {k: spatial_snr(v, sl) for k, v in images.items()}
    return {
        "patch": name,
        "reflectance": reflectance,
        # a patch clipped flat has no SNR: None
        "snr": {k: (x if math.isfinite(x) else None) for k, x in snr.items()},
        "gamma1_mean_dn": float(s1[sl].mean()),
        "gamma1_fraction_of_phi_fs": float(s1[sl].mean() / 2**beta),
        "gamma2_saturated_fraction": float(np.mean(g2[sl] >= clip)),
        "gamma_hdr_saturated_fraction": float(np.mean(fused.saturated[sl])),
        # eq. 11 keeps Gamma2 where Gamma1 is below its threshold: there Gamma2 may be clipped already
        "gamma_hdr_from_clipped_gamma2_fraction": float(
            np.mean((fused.source[sl] == fused.unit_stage) & (g2[sl] >= clip))
        ),
    }


def _dark_patch(
    name: str, reflectance: float, sl: tuple[slice, slice], images: dict[str, np.ndarray],
    g1: np.ndarray, g2: np.ndarray,
) -> dict[str, Any]:
    """The darkest patch's entry: SNR per image and the pixels the word stores as 0 DN."""
    return {
        "patch": name,
        "reflectance": reflectance,
        "snr": {k: spatial_snr(v, sl) for k, v in images.items()},
        # pixels of the patch stored as 0 DN (clipped by the word): 0 with a pedestal above the noise
        "word_zero_fraction": {k: float(np.mean(v[sl] <= 0)) for k, v in (("gamma1", g1), ("gamma2", g2))},
    }


def _qualitative(dark: dict[str, Any], bright: dict[str, Any]) -> dict[str, bool]:
    """The paper's qualitative claims: "in the noise" is below SNR 2, "out of the noise" the
    Rose criterion, SNR >= 3."""
    snr_dark = dark["snr"]
    return {
        "stage_mu2_saturates_bright_region": bright["gamma2_saturated_fraction"] > 0.99,
        "stage_mu1_leaves_darkest_patch_in_noise": snr_dark["gamma1"] < SNR_IN_NOISE,
        "hdr_keeps_bright_unsaturated": bright["gamma_hdr_saturated_fraction"] == 0.0
        and bright["gamma_hdr_from_clipped_gamma2_fraction"] == 0.0,
        "hdr_lifts_darkest_patch": snr_dark["gamma_hdr"] >= SNR_ROSE
        and snr_dark["gamma_hdr"] >= 1.8 * snr_dark["gamma1"],
    }


def _truth_ranges(
    sim: PassResult, fused: FusionResult, mu1: int, mu2: int, images: dict[str, np.ndarray],
    wedge: dict[str, tuple[slice, slice]], level: dict[str, float], bright: dict[str, Any],
) -> tuple[float, dict[str, float | None], dict[str, float]]:
    """With the pass's truth: the scene range, the range each image captures and its clipped
    fraction (:class:`PassMetrics`); clears the bright patch's SNR where it is over half clipped."""
    clip1, clip2 = (sim.stage_array("clipped", m) for m in (mu1, mu2))
    clipped = {"gamma1": clip1, "gamma2": clip2, "gamma_hdr": np.where(fused.source == mu1, clip1, clip2)}
    bsl = wedge[bright["patch"]]
    for name in images:  # a patch more than half clipped has no SNR either
        if float(np.mean(clipped[name][bsl])) >= 0.5:
            bright["snr"][name] = None
    captured: dict[str, float | None] = {}
    for name, img in images.items():
        usable = [
            level[k] for k, sl in wedge.items()
            if spatial_snr(img, sl) >= SNR_ROSE and float(np.mean(clipped[name][sl])) < 0.5
        ]
        captured[name] = _range_db(usable) if usable else None
    return _range_db(list(level.values())), captured, {k: float(np.mean(v)) for k, v in clipped.items()}


def pass_metrics(cfg: BenchConfig, sim: PassResult, fused: FusionResult) -> PassMetrics:
    """Metrics of a pass's stage images ``fusion.mu1``, ``fusion.mu2`` and their fusion.

    Parameters
    ----------
    cfg
        The bench of the pass.
    sim
        The :class:`~bench_sim.pipeline.PassResult` (stage words with their pedestal,
        render set-up with the target panel and geometry).
    fused
        :func:`bench_sim.fusion.paper.fuse_dtdi_hdr_eq11` of the two stages, offsets removed.
    """
    mu1, mu2, beta = cfg.fusion.mu1, cfg.fusion.mu2, cfg.dtdi.beta_bits
    lines = cfg.lines
    setup = sim.setup
    g1, g2 = sim.stage_dn[mu1], sim.stage_dn[mu2]
    off1, off2 = (stage_offset_dn(cfg.sensor, cfg.dtdi, m) for m in (mu1, mu2))
    s1, s2 = g1 - off1, g2 - off2
    # eq. 16-17 count the values of the stored words; the HDR carries Gamma2's offset likewise
    eq18 = evaluate_eq18(g1, g2, fused.hdr + off2, mu1=mu1, mu2=mu2, beta=beta)
    panel = setup.grid.panel
    sat = _saturated_fractions(g1, g2, fused, 2**beta - 1)
    wedge = {k: v for k, v in patch_slices(panel, setup.geom, cfg, lines).items() if k.startswith("wedge_")}
    if not wedge:
        return PassMetrics(eq18, sat, None, None, None, _no_wedge_reason(cfg, panel, lines))
    refl = {p.name: p.reflectance for p in panel.patches}
    # the darkest and brightest patches in the scene as lit: lowest / highest mean photons (the
    # truth) or mean of Gamma_HDR
    truth = sim.truth  # (without building the dataset when there is none)
    scene = sim.stage_array("photons", mu2) if truth else fused.hdr
    level = {k: float(scene[v].mean()) for k, v in wedge.items()}
    darkest = min(wedge, key=level.__getitem__)
    brightest = max(wedge, key=level.__getitem__)
    images = {"gamma1": s1, "gamma2": s2, "gamma_hdr": fused.hdr}
    dark = _dark_patch(darkest, refl[darkest], wedge[darkest], images, g1, g2)
    bright = _bright_patch(brightest, refl[brightest], wedge[brightest], images, s1, g2, fused, beta)
    qualitative = _qualitative(dark, bright)
    if not truth:
        return PassMetrics(eq18, sat, dark, bright, qualitative)
    scene_db, captured, clipped = _truth_ranges(sim, fused, mu1, mu2, images, wedge, level, bright)
    dark["temporal_snr"] = temporal_snr(cfg, sim, fused, wedge[darkest])
    return PassMetrics(eq18, sat, dark, bright, qualitative, None, scene_db, captured, clipped)


def stage_temporal_var_dn2(cfg: BenchConfig, photons: np.ndarray, m: int, t_int_s: float) -> np.ndarray:
    """Temporal variance [DN^2] of stage ``m``'s word at the truth's ``photons`` (the sum over its
    ``m`` rows): ``m`` independent reads of the pixel's mean signal ``eta photons / m``
    (:func:`bench_sim.sensor.model.stage_variance_dn2`; EMVA 1288 R4 eq. 7 per read), in the
    linear range."""
    s = cfg.sensor
    return stage_variance_dn2(
        m, s.quantum_efficiency * photons / m, conversion_gain_dn_per_e=s.conversion_gain_dn_per_e,
        dark_noise_e=dark_noise_e(s, t_int_s), quantization=s.quantization, shot_noise=s.shot_noise,
    )


def temporal_snr(
    cfg: BenchConfig, sim: PassResult, fused: FusionResult, sl: tuple[slice, slice]
) -> dict[str, float]:
    """Temporal SNR of a patch in ``gamma1``, ``gamma2`` and ``gamma_hdr``, from the pass's truth.

    ``SNR = mean(mu) / sqrt(mean(sigma^2))`` over the patch's pixels: ``mu`` the expected signal
    of the stage word above its offset (the truth's ``linear_dn`` less
    :func:`bench_sim.sensor.model.stage_offset_dn`), ``sigma^2`` its temporal variance, ``m``
    independent reads of the pixel's own mean signal (:func:`bench_sim.sensor.model.
    stage_variance_dn2` on the truth's ``photons``; EMVA 1288 R4 eq. 7 per read). The noise of
    one image over repeated exposures of the same scene, not the spread over the patch (which adds
    the fixed pattern and shading: :func:`spatial_snr`). ``gamma_hdr`` takes each pixel's source
    stage (``fused.source``) scaled to ``mu2`` units as eq. 11 does. Linear range: valid where
    the patch does not clip (the darkest patch).
    """
    s, mu1, mu2 = cfg.sensor, cfg.fusion.mu1, cfg.fusion.mu2
    sig: dict[int, np.ndarray] = {}
    var: dict[int, np.ndarray] = {}
    for m in (mu1, mu2):
        photons = sim.stage_array("photons", m)[sl]
        var[m] = stage_temporal_var_dn2(cfg, photons, m, sim.setup.geom.t_int_s)
        sig[m] = sim.stage_array("linear_dn", m)[sl] - stage_offset_dn(s, cfg.dtdi, m)
    low = fused.source[sl] == mu1
    scale = mu2 / mu1
    hdr_sig = np.where(low, sig[mu1] * scale, sig[mu2])
    hdr_var = np.where(low, var[mu1] * scale**2, var[mu2])
    pairs = {"gamma1": (sig[mu1], var[mu1]), "gamma2": (sig[mu2], var[mu2]), "gamma_hdr": (hdr_sig, hdr_var)}
    return {k: float(np.mean(a) / math.sqrt(float(np.mean(v)))) for k, (a, v) in pairs.items()}


def _range_db(levels: list[float]) -> float:
    """``20 lg(max / min)`` of positive levels [dB] (0 for one level)."""
    lo, hi = min(levels), max(levels)
    return float(20.0 * np.log10(hi / lo)) if lo > 0 else float("inf")
