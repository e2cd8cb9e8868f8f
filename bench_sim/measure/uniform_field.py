"""Uniform-field photon transfer through the real sensor and DTDI: the one runner behind
``bench-sim ptc`` (:mod:`bench_sim.measure.ptc`) and the whole-chain dynamic range
(:mod:`bench_sim.measure.chain_dr`).

A uniform field of ``mu_p`` photons per pixel per frame is exposed through the EMVA 1288 pixel
model and the streaming DTDI accumulator (:func:`bench_sim.sensor.stream.sensor_dtdi_pass`,
one fixed pattern for the whole series). One pass of ``n L + max(stages) - 1`` frames over the
top-left ``max(stages)`` rows x ``C`` columns gives, for every requested stage, ``n L`` complete
lines: ``n`` images of ``L`` lines (consecutive line blocks). Every raw read (frame ``k``, row
``i``) belongs to exactly one scene line (``j = k - i``) and every line of a column sums the
same physical pixels, so the blocks are temporally independent images with the same fixed
pattern (``n = 2``: an EMVA 1288 image pair; ``n > 2``: a spatial stack).

Pedestal (one rule)
-------------------
EMVA 1288 needs the dark signal unclipped. The stage word keeps a digital pedestal
(``dtdi.pedestal_dn``, :mod:`bench_sim.sensor.dtdi`); a measurement uses the configured
pedestal, raised where it would not keep the dark value of every measured stage
:data:`PEDESTAL_SIGMAS` (5) standard deviations above 0 DN (its spread: temporal noise, DSNU and
the column offsets, which add coherently over the ``m`` rows,
:func:`bench_sim.sensor.model.stage_dark_std_dn`; with ``subtract_black`` off the accumulated
black offset ``m b`` counts towards it). With the default config (64 DN) the measurement runs
the configured chain unchanged. The offset every image carries,
:func:`bench_sim.sensor.model.stage_offset_dn`, is subtracted by the consumers.

References
----------
EMVA Standard 1288, Release 4.0 Linear (2021): photon-transfer method (section 6), image pairs
(section 6.3), spatial stacks (section 8).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.errors import BenchSimError
from bench_sim.sensor.emva import FixedPattern
from bench_sim.sensor.model import stage_dark_std_dn, stage_offset_dn, word_clip_dn
from bench_sim.sensor.stream import sensor_dtdi_pass

__all__ = ["PEDESTAL_SIGMAS", "measurement_pedestal_dn", "measurement_offsets_dn", "expose_uniform"]

#: Standard deviations of a stage's dark spread the pedestal keeps above 0 DN (a Gaussian dark
#: value is clipped with probability 3e-7).
PEDESTAL_SIGMAS = 5.0


def measurement_pedestal_dn(cfg: BenchConfig, stages: Sequence[int]) -> int:
    """The word pedestal [DN] of a uniform-field measurement of ``stages`` (see module doc).

    ``max(dtdi.pedestal_dn, max_m ceil(5 sigma_m - m b [subtract_black off]))``.

    Raises
    ------
    BenchSimError
        When that pedestal would take half the output word or more (a word too narrow for the
        dark noise of the stages).
    """
    s, dtdi = cfg.sensor, cfg.dtdi
    need = 0
    for m in stages:
        n = math.ceil(PEDESTAL_SIGMAS * stage_dark_std_dn(s, cfg.timing.t_int_s, m))
        if not dtdi.subtract_black:
            n -= math.floor(m * s.black_offset_dn)
        need = max(need, n)
    ped = max(int(dtdi.pedestal_dn), need)
    top = word_clip_dn(dtdi.beta_bits)
    worst = max(stage_offset_dn(s, dtdi, m, ped) for m in stages)
    if not worst < 0.5 * top:
        raise BenchSimError(
            f"dtdi.beta_bits = {dtdi.beta_bits}: the dark level of stage {max(stages)} needs an offset of "
            f"{worst:g} DN, half the word or more; use a wider word, subtract the black offset, or "
            "measure lower stages"
        )
    return ped


def measurement_offsets_dn(cfg: BenchConfig, stages: Sequence[int], pedestal_dn: float) -> dict[int, float]:
    """Offset [DN] every stage's image carries in the measurement (pedestal + ``m b`` if kept)."""
    return {int(m): stage_offset_dn(cfg.sensor, cfg.dtdi, m, pedestal_dn) for m in stages}


def expose_uniform(
    cfg: BenchConfig,
    stages: Sequence[int],
    photons_per_frame: float,
    rng: np.random.Generator,
    *,
    fixed: FixedPattern,
    lines: int,
    columns: int,
    images: int,
    pedestal_dn: float,
) -> dict[int, np.ndarray]:
    """One uniform-field pass: stage -> ``(images, lines, columns)`` ``uint32`` stage words.

    Parameters
    ----------
    cfg
        Bench config (sensor, timing, DTDI).
    stages
        Stages of the pass (sorted; the pass covers the top-left ``max(stages)`` rows).
    photons_per_frame
        ``mu_p`` [mean photons per pixel per frame], >= 0.
    rng
        The measurement's random generator (temporal noise).
    fixed
        The sensor's fixed pattern (whole sensor or at least ``max(stages) x columns``).
    lines, columns
        Image size ``L x C``.
    images
        Images per stage (consecutive blocks of ``L`` lines).
    pedestal_dn
        Word pedestal [DN] (:func:`measurement_pedestal_dn`).
    """
    if not (np.isfinite(photons_per_frame) and photons_per_frame >= 0):
        raise BenchSimError(f"photons_per_frame = {photons_per_frame!r}: must be finite and >= 0")
    st = tuple(sorted(int(m) for m in stages))
    rows = st[-1]
    n_lines = int(images) * int(lines)
    frames = n_lines + rows - 1
    photons = np.broadcast_to(np.float64(photons_per_frame), (frames, rows, int(columns)))
    window = fixed if fixed.shape == (rows, columns) else fixed.window(rows, columns)
    imgs = sensor_dtdi_pass(
        photons, cfg.sensor, cfg.dtdi, cfg.timing.t_int_s, st, rng, fixed=window, lines=n_lines,
        pedestal_dn=float(pedestal_dn),
    )
    return {m: imgs[m].reshape(int(images), int(lines), int(columns)) for m in st}
