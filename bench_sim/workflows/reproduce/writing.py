"""The reproduction's image files and figures, written by two threads at once.

The image files (``gamma1.tiff``, ``gamma2.tiff``, ``gamma_hdr.exr``, ``gamma_tra.png``) go to
the thread pool (:func:`start_image_files`); the figures are drawn by whichever thread has their
inputs -- the workflow's own and its :class:`~bench_sim.runtime.parallel.Lane` -- one at a time
(:data:`FIGURE_LOCK`: matplotlib is not thread-safe, its mathtext parser least of all, and its
drawing holds the GIL anyway), while the other thread computes. Every file's bytes depend only
on its inputs, never on which thread wrote it or when.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.fusion.common import FusionResult
from bench_sim.io import write_exr, write_png, write_tiff16
from bench_sim.measure.chain_dr import ChainDR
from bench_sim.runtime.parallel import start
from bench_sim.workflows.reproduce.fig4_captions import pass_inset_captions
from bench_sim.workflows.reproduce.figures import (
    Box,
    fig3_stages,
    fig4_hdr,
    snr_versus_signal_figure,
    stage_display,
)

__all__ = ["FIGURE_LOCK", "drawn", "warm_up", "start_image_files", "snr_figure", "fig3", "fig4"]

T = TypeVar("T")

#: held while a figure is built, drawn and encoded (one figure at a time in the process)
FIGURE_LOCK = threading.Lock()


def drawn(draw: Callable[[], T]) -> T:
    """``draw()`` (a figure's whole making) under :data:`FIGURE_LOCK`."""
    with FIGURE_LOCK:
        return draw()


def warm_up() -> None:
    """Make matplotlib's one-time set-up before the figures are due (beside the pass, once the
    pass's set-up is done: not beside the set-up, whose Python it would slow): its import (about a
    second), its mathtext parser (about half a second at its first formula) and the default font."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot  # noqa: F401
    from matplotlib import font_manager
    from matplotlib.mathtext import MathTextParser

    with FIGURE_LOCK:
        MathTextParser("path").parse("$\\Gamma_{HDR}$", dpi=110)
        font_manager.findfont(font_manager.FontProperties())


def start_image_files(
    out: Path, cfg: BenchConfig, meta: dict[str, Any], stage_images: dict[int, np.ndarray],
    fused: FusionResult, tra8: np.ndarray,
) -> Callable[[], list[Path]]:
    """Start writing the image files on the thread pool; returns the wait for them."""
    mu1, mu2 = cfg.fusion.mu1, cfg.fusion.mu2
    g1, g2 = stage_images[mu1], stage_images[mu2]
    return start([
        lambda: write_tiff16(out / "gamma1.tiff", g1, dict(meta, image=f"Gamma1, stage {mu1} [DN]")),
        lambda: write_tiff16(out / "gamma2.tiff", g2, dict(meta, image=f"Gamma2, stage {mu2} [DN]")),
        lambda: write_exr(
            out / "gamma_hdr.exr",
            {"Y": fused.hdr, "source": fused.source.astype(np.float32)},
            dict(meta, image=f"Gamma_HDR (eq. 11) [DN, stage-{mu2} units]; source = stage used"),
        ),
        lambda: write_png(out / "gamma_tra.png", tra8, dict(meta, image=f"Gamma_TRA ({cfg.fusion.tra})")),
    ])


def snr_figure(path: Path, chain: ChainDR, meta: dict[str, Any]) -> None:
    """``snr_vs_signal.png``: SNR of Gamma1, Gamma2 and Gamma_HDR versus signal (the chain's
    photon-transfer series)."""
    names = {"gamma1": f"$\\Gamma_1$ (m = {chain.mu1})", "gamma2": f"$\\Gamma_2$ (m = {chain.mu2})",
             "gamma_hdr": "$\\Gamma_{HDR}$ (eq. 11)"}
    img = chain.images
    drawn(lambda: snr_versus_signal_figure(
        chain.photons,
        {k: v.snr for k, v in img.items()},
        {k: v.photons_min for k, v in img.items()},
        {k: v.photons_sat for k, v in img.items()},
        chain.fusion_switch()["photons"],
        path,
        dict(meta, figure="SNR versus signal of Gamma1, Gamma2 and Gamma_HDR (photon-transfer series)"),
        {k: f"{names[k]}: DR {v.dr_db:.1f} dB" for k, v in img.items()},
    ))


def fig3(path: Path, stage_images: dict[int, np.ndarray], stages: tuple[int, ...], beta: int,
         meta: dict[str, Any]) -> None:
    """Fig. 3: the stage images of ``stages``."""
    drawn(lambda: fig3_stages(stage_images, stages, beta, path, meta))


def fig4(
    path: Path, cfg: BenchConfig, boxes: tuple[Box, Box], meta: dict[str, Any],
    stage_images: dict[int, np.ndarray], fused: FusionResult, tra8: np.ndarray, panel: Any, geom: Any,
) -> None:
    """Fig. 4 with its insets (``boxes``: the dark and the bright one), each captioned with what was
    measured inside it (:func:`bench_sim.workflows.reproduce.fig4_captions.pass_inset_captions`;
    ``panel`` and ``geom``: the pass's target panel and rig geometry)."""
    mu1, mu2, beta = cfg.fusion.mu1, cfg.fusion.mu2, cfg.dtdi.beta_bits
    dark_box, bright_box = boxes
    hdr01 = np.clip(fused.hdr.astype(np.float32) / np.float32(fused.full_scale_dn), 0, 1)
    tra01 = tra8 / np.float32(255.0)
    g1, g2 = stage_display(stage_images[mu1], beta), stage_display(stage_images[mu2], beta)
    titles = tuple(pass_inset_captions(cfg, stage_images, fused, boxes, panel, geom))
    drawn(lambda: fig4_hdr(hdr01, tra01, g1, g2, dark_box, bright_box, path, meta, cfg.fusion.tra,
                           inset_titles=titles))
