"""The fusion of two stages of one DTDI pass, as every part of bench_sim does it, and its truth.

One bench's two stage words ``Gamma1`` (stage ``mu1``) and ``Gamma2`` (stage ``mu2 > mu1``) carry
an offset besides the signal: the DTDI pedestal ``P`` (``dtdi.pedestal_dn``) and, with
``dtdi.subtract_black = false``, the black offset every read adds, ``m b`` for stage ``m``
(:func:`bench_sim.sensor.model.stage_offset_dn`). The functions here are the one place that
removes them, so ``simulate``, ``dataset``, ``reproduce``, ``sweep`` and the chain's dynamic range
fuse the same words into the same image:

- :func:`stage_offsets_dn`: the offset ``o_m`` of each stage [DN];
- :func:`eq11_signal_threshold_dn`: eq. 11's threshold on the stage-``mu1`` *signal*,
  ``(Phi_FS - o_mu2) mu1 / mu2`` (with ``o_mu2 = 0``: the paper's ``Phi_FS / (mu2/mu1)``);
- :func:`fuse_stage_words`: eq. 11 of the words, offsets removed
  (:func:`bench_sim.fusion.paper.fuse_dtdi_hdr_eq11`);
- :func:`true_hdr_dn`: the true HDR target, the noise-free stage-``mu2`` signal without any clip,
  ``linear_dn`` of stage ``mu2`` less ``o_mu2``, in stage-``mu2`` DN (what an ideal HDR image
  holds; both branches of eq. 11 aim at it, and miss it where the light changes along the TDI
  window or ``Gamma2`` clips);
- :func:`eq11_expected_dn`: eq. 11 applied to the expected words (``mean_dn`` of both stages,
  clipped to the word as the words are): what eq. 11 gives without noise, *not* the truth.

Every function takes the bench (:class:`~bench_sim.config.BenchConfig`) and, optionally, other
stages than ``fusion.mu1``, ``fusion.mu2`` (every pair of an all-stage pass) and a pedestal other
than ``dtdi.pedestal_dn`` (a measurement's own).

References
----------
An HDR Imaging Method With DTDI Technology for Push-Broom Cameras (the reproduced paper),
eq. 4 (the word), eq. 5-11 (the fusion).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bench_sim.config import BenchConfig
from bench_sim.fusion.common import FusionResult, check_stage_pair
from bench_sim.fusion.paper import eq11_threshold_dn, fuse_dtdi_hdr_eq11
from bench_sim.sensor.model import stage_offset_dn, word_clip_dn

__all__ = [
    "stage_offsets_dn",
    "eq11_signal_threshold_dn",
    "fuse_stage_words",
    "true_hdr_dn",
    "eq11_expected_dn",
]


def _pair(cfg: BenchConfig, mu1: int | None, mu2: int | None) -> tuple[int, int]:
    return check_stage_pair(cfg.fusion.mu1 if mu1 is None else mu1, cfg.fusion.mu2 if mu2 is None else mu2)


def stage_offsets_dn(
    cfg: BenchConfig, stages: Iterable[int], pedestal_dn: float | None = None
) -> dict[int, float]:
    """Stage ``m`` -> the offset ``o_m`` [DN] its word carries besides the signal: the pedestal
    ``P`` plus ``m b`` when the black offset ``b`` is not subtracted (``dtdi.subtract_black``).

    Parameters
    ----------
    cfg
        The bench (``sensor.black_offset_dn``, ``dtdi.subtract_black``, ``dtdi.pedestal_dn``).
    stages
        The stages ``m``.
    pedestal_dn
        The words' pedestal ``P`` [DN], if not ``dtdi.pedestal_dn`` (a measurement's own).

    Returns
    -------
    dict of int to float
        ``o_m = P + m b [subtract_black off]`` [DN] (:func:`bench_sim.sensor.model.stage_offset_dn`;
        paper eq. 4 with the black offset and the pedestal of the word).
    """
    return {int(m): stage_offset_dn(cfg.sensor, cfg.dtdi, int(m), pedestal_dn) for m in stages}


def eq11_signal_threshold_dn(
    cfg: BenchConfig, mu1: int | None = None, mu2: int | None = None, pedestal_dn: float | None = None
) -> float:
    """Eq. 11's threshold on the stage-``mu1`` signal (its word less ``o_mu1``) [DN]:
    ``(Phi_FS - o_mu2) / (mu2 / mu1)`` with ``Phi_FS = 2**beta`` (eq. 4): the signal range left
    to ``Gamma2``'s word above its offset decides where it clips.

    Parameters
    ----------
    cfg
        The bench (``dtdi.beta_bits``, its offsets).
    mu1, mu2
        The stages (default: ``fusion.mu1``, ``fusion.mu2``).
    pedestal_dn
        The words' pedestal [DN], if not ``dtdi.pedestal_dn``.

    Returns
    -------
    float
        The threshold [DN, stage-``mu1`` units]: 504 DN for the paper rig (``mu1 = 10``,
        ``mu2 = 80``, ``beta = 12``, ``P = 64``); ``Phi_FS / (mu2/mu1) = 512`` DN without any
        offset (the paper's).

    References
    ----------
    The reproduced paper, eq. 4, 5 and 11.
    """
    m1, m2 = _pair(cfg, mu1, mu2)
    off2 = stage_offset_dn(cfg.sensor, cfg.dtdi, m2, pedestal_dn)
    return eq11_threshold_dn(m1, m2, cfg.dtdi.beta_bits, off2)


def fuse_stage_words(
    cfg: BenchConfig,
    gamma1: ArrayLike,
    gamma2: ArrayLike,
    *,
    mu1: int | None = None,
    mu2: int | None = None,
    pedestal_dn: float | None = None,
) -> FusionResult:
    """Eq. 11 of two stage words of the bench ``cfg``, each word's offset removed.

    Parameters
    ----------
    cfg
        The bench that made the words (its output word ``dtdi.beta_bits``, its offsets).
    gamma1, gamma2
        The words of stages ``mu1`` and ``mu2`` [DN], as stored (``0 .. 2**beta - 1``), same
        shape; or their expectations.
    mu1, mu2
        The stages (default: ``fusion.mu1``, ``fusion.mu2``).
    pedestal_dn
        The words' pedestal [DN], if not ``dtdi.pedestal_dn``.

    Returns
    -------
    FusionResult
        ``hdr`` = ``Gamma2 - o_mu2`` where ``Gamma1 - o_mu1`` is at or below
        :func:`eq11_signal_threshold_dn`, else ``(mu2/mu1) (Gamma1 - o_mu1)`` [DN, stage-``mu2``
        units, float64]; ``source`` the stage each pixel came from; ``saturated`` where
        ``Gamma1`` is at the word's top; ``full_scale_dn = (mu2/mu1) (2**beta - 1 - o_mu1)``.
    """
    m1, m2 = _pair(cfg, mu1, mu2)
    off = stage_offsets_dn(cfg, (m1, m2), pedestal_dn)
    return fuse_dtdi_hdr_eq11(
        gamma1, gamma2, mu1=m1, mu2=m2, beta=cfg.dtdi.beta_bits, pedestal_dn=(off[m1], off[m2])
    )


def true_hdr_dn(
    cfg: BenchConfig, linear_dn_mu2: ArrayLike, *, mu2: int | None = None, pedestal_dn: float | None = None
) -> NDArray[np.float64]:
    """The true HDR target [DN, stage-``mu2`` units, float64]: the noise-free stage-``mu2`` signal
    without any clip, ``linear_dn`` of stage ``mu2`` less its offset ``o_mu2``.

    ``linear_dn`` is what an ideal linear camera with the same fixed patterns would record (every
    clip removed, a non-linear response replaced by its small-signal slope), so the target keeps
    the dark signal and the fixed patterns and holds values past every clip: what an ideal HDR
    image of the scene holds in stage-``mu2`` units.

    Parameters
    ----------
    cfg
        The bench.
    linear_dn_mu2
        ``linear_dn`` of stage ``mu2`` [DN] (:data:`bench_sim.pipeline.PASS_VARIABLES`).
    mu2
        The stage (default ``fusion.mu2``).
    pedestal_dn
        The pedestal, if not ``dtdi.pedestal_dn``.

    Returns
    -------
    numpy.ndarray
        The target [DN, stage-``mu2`` units], the shape of ``linear_dn_mu2``.
    """
    m2 = int(cfg.fusion.mu2 if mu2 is None else mu2)
    offset = stage_offset_dn(cfg.sensor, cfg.dtdi, m2, pedestal_dn)
    return np.asarray(linear_dn_mu2, dtype=np.float64) - offset


def eq11_expected_dn(
    cfg: BenchConfig,
    mean_dn_mu1: ArrayLike,
    mean_dn_mu2: ArrayLike,
    *,
    mu1: int | None = None,
    mu2: int | None = None,
    pedestal_dn: float | None = None,
) -> NDArray[np.float64]:
    """Eq. 11 of the expected words [DN, stage-``mu2`` units, offsets removed, float64]: each
    stage's ``mean_dn`` clipped to the word ``0 .. 2**beta - 1`` as the words are, then
    :func:`fuse_stage_words`.

    It is ``E[gamma_hdr]`` wherever the stage-``mu1`` signal is a few noise standard deviations
    from the threshold (there the noisy switch mixes both branches), and it is eq. 11's answer
    without noise: not the truth. Against :func:`true_hdr_dn` it is off where ``Gamma2`` clips
    below the threshold or the light changes along the TDI window (the spot's edge).

    Parameters
    ----------
    cfg
        The bench.
    mean_dn_mu1, mean_dn_mu2
        ``mean_dn`` of stages ``mu1`` and ``mu2`` [DN] (the exact expectations of the words).
    mu1, mu2
        The stages (default: ``fusion.mu1``, ``fusion.mu2``).
    pedestal_dn
        The pedestal, if not ``dtdi.pedestal_dn``.

    Returns
    -------
    numpy.ndarray
        Eq. 11 of the expected words [DN, stage-``mu2`` units, offsets removed, float64].
    """
    top = float(word_clip_dn(cfg.dtdi.beta_bits))
    g1 = np.clip(np.asarray(mean_dn_mu1, dtype=np.float64), 0.0, top)
    g2 = np.clip(np.asarray(mean_dn_mu2, dtype=np.float64), 0.0, top)
    return fuse_stage_words(cfg, g1, g2, mu1=mu1, mu2=mu2, pedestal_dn=pedestal_dn).hdr
