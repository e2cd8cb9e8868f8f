"""Metrics of one simulation pass (a :class:`~bench_sim.workflows.simulate.PassResult` and its
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
from bench_sim.metrics.histogram import Eq18Result

__all__ = ["PassMetrics", "pass_metrics", "patch_slices", "spatial_snr", "SNR_IN_NOISE", "SNR_ROSE"]

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


def pass_metrics(cfg: BenchConfig, sim: Any, fused: Any) -> PassMetrics:
    """Metrics of a pass's stage images ``fusion.mu1``, ``fusion.mu2`` and their fusion.

    Parameters
    ----------
    cfg
        The bench of the pass.
    sim
        The :class:`~bench_sim.workflows.simulate.PassResult` (stage words with their pedestal,
        render set-up with the target panel and geometry).
    fused
        :func:`bench_sim.fusion.paper.fuse_dtdi_hdr_eq11` of the two stages, offsets removed.
    """
    from bench_sim.metrics.histogram import evaluate_eq18
    from bench_sim.sensor.model import stage_offset_dn

    mu1, mu2, beta = cfg.fusion.mu1, cfg.fusion.mu2, cfg.dtdi.beta_bits
    lines = cfg.lines
    setup = sim.setup
    g1, g2 = sim.stage_dn[mu1], sim.stage_dn[mu2]
    off1, off2 = (stage_offset_dn(cfg.sensor, cfg.dtdi, m) for m in (mu1, mu2))
    s1, s2 = g1 - off1, g2 - off2
    # eq. 16-17 count the values of the stored words; the HDR carries Gamma2's offset likewise
    eq18 = evaluate_eq18(g1, g2, fused.hdr + off2, mu1=mu1, mu2=mu2, beta=beta)
    clip = 2**beta - 1
    panel = setup.grid.panel
    sat = {
        "gamma1": float(np.mean(g1 >= clip)),
        "gamma2": float(np.mean(g2 >= clip)),
        "gamma_hdr": float(np.mean(fused.saturated)),
    }
    wedge = {k: v for k, v in patch_slices(panel, setup.geom, cfg, lines).items() if k.startswith("wedge_")}
    if not wedge:
        why = (
            f"target.layout = {cfg.target.layout!r} has no wedge patches"
            if not panel.patches
            else f"no wedge patch lies wholly inside the {lines} lines x {cfg.sensor.columns} columns"
        )
        return PassMetrics(eq18, sat, None, None, None, why)
    refl = {p.name: p.reflectance for p in panel.patches}
    # the darkest and brightest patches in the scene as lit: lowest / highest mean photons (the
    # truth) or mean of Gamma_HDR
    truth = sim.truth  # (without building the dataset when there is none)
    scene = sim.dataset["photons"].sel(stage=mu2).values if truth else fused.hdr
    level = {k: float(scene[v].mean()) for k, v in wedge.items()}
    darkest = min(wedge, key=level.__getitem__)
    brightest = max(wedge, key=level.__getitem__)
    images = {"gamma1": s1, "gamma2": s2, "gamma_hdr": fused.hdr}
    snr_dark = {k: spatial_snr(v, wedge[darkest]) for k, v in images.items()}
    bsl = wedge[brightest]
    snr_bright = {k: spatial_snr(v, bsl) for k, v in images.items()}
    bright = {
        "patch": brightest,
        "reflectance": refl[brightest],
        # a patch clipped flat has no SNR: None
        "snr": {k: (x if math.isfinite(x) else None) for k, x in snr_bright.items()},
        "gamma1_mean_dn": float(s1[bsl].mean()),
        "gamma1_fraction_of_phi_fs": float(s1[bsl].mean() / 2**beta),
        "gamma2_saturated_fraction": float(np.mean(g2[bsl] >= clip)),
        "gamma_hdr_saturated_fraction": float(np.mean(fused.saturated[bsl])),
    }
    dark = {
        "patch": darkest,
        "reflectance": refl[darkest],
        "snr": snr_dark,
        # pixels of the patch stored as 0 DN (clipped by the word): 0 with a pedestal above the noise
        "word_zero_fraction": {
            k: float(np.mean(v[wedge[darkest]] <= 0)) for k, v in (("gamma1", g1), ("gamma2", g2))
        },
    }
    # "in the noise": below SNR 2; "out of the noise": the Rose criterion, SNR >= 3
    qualitative = {
        "stage_mu2_saturates_bright_region": bright["gamma2_saturated_fraction"] > 0.99,
        "stage_mu1_leaves_darkest_patch_in_noise": snr_dark["gamma1"] < SNR_IN_NOISE,
        "hdr_keeps_bright_unsaturated": bright["gamma_hdr_saturated_fraction"] == 0.0,
        "hdr_lifts_darkest_patch": snr_dark["gamma_hdr"] >= SNR_ROSE
        and snr_dark["gamma_hdr"] >= 1.8 * snr_dark["gamma1"],
    }
    if not truth:
        return PassMetrics(eq18, sat, dark, bright, qualitative)
    clip1, clip2 = (sim.dataset["clipped"].sel(stage=m).values for m in (mu1, mu2))
    clipped = {"gamma1": clip1, "gamma2": clip2, "gamma_hdr": np.where(fused.source == mu1, clip1, clip2)}
    for name in images:  # a patch more than half clipped has no SNR either
        if float(np.mean(clipped[name][bsl])) >= 0.5:
            bright["snr"][name] = None
    captured = {}
    for name, img in images.items():
        usable = [
            level[k] for k, sl in wedge.items()
            if spatial_snr(img, sl) >= SNR_ROSE and float(np.mean(clipped[name][sl])) < 0.5
        ]
        captured[name] = _range_db(usable) if usable else None
    return PassMetrics(
        eq18, sat, dark, bright, qualitative, None, _range_db(list(level.values())), captured,
        {k: float(np.mean(v)) for k, v in clipped.items()},
    )


def _range_db(levels: list[float]) -> float:
    """``20 lg(max / min)`` of positive levels [dB] (0 for one level)."""
    lo, hi = min(levels), max(levels)
    return float(20.0 * np.log10(hi / lo)) if lo > 0 else float("inf")
