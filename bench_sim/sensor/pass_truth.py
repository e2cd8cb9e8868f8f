"""The truth of a simulation pass, accumulated in the same streaming pass as the stage words.

:class:`PassTruth` receives every exposed chunk of frames (:class:`bench_sim.sensor.stream.Exposed`),
computes per read the photons, the PRNU-weighted photons and the cumulants of the clipped read
(:func:`bench_sim.sensor.expectation.read_cumulants`), sums them over each stage's rows
(:class:`bench_sim.sensor.stage_truth.StageSums`, paper eq. 1-2) and turns the sums into
``photons``, ``linear_dn`` (:func:`bench_sim.sensor.stage_truth.stage_mean_dn`), ``mean_dn`` (the
exact expectation of the word, :func:`bench_sim.sensor.expectation.clipped_sum_mean`; for stage 1
the word's clip folded into the read's) and ``clipped``; ``reflectance`` per band of lines.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.render.exposures import RenderSetup
from bench_sim.sensor.dtdi import full_scale_dn
from bench_sim.sensor.emva import FixedPattern
from bench_sim.sensor.expectation import ReadModel, clipped_sum_mean, read_cumulants
from bench_sim.sensor.stage_truth import (
    StageSums,
    reflectance_rows,
    row_footprints,
    stage_dark_offset_dn,
    stage_mean_dn,
    stage_reflectance,
)
from bench_sim.sensor.stream import Exposed

__all__ = ["PassTruth", "TRUTH_QUANTITIES"]

#: per-read quantities the truth sums over a stage's rows: photons, PRNU-weighted photons, the
#: cumulants of the clipped read, the saturation flag, and row 0's read with the word's clip folded in
TRUTH_QUANTITIES = ("photons", "gain_photons", "k1", "k2", "k3", "saturated", "k1_stage1")


class PassTruth:
    """The truth of a pass, accumulated chunk by chunk (:mod:`bench_sim.sensor.stage_truth`):
    ``photons``, ``mean_dn``, ``linear_dn``, ``clipped`` per stage line, ``reflectance`` per band
    of ``band_lines`` lines, into ``arrays`` (name -> (stages, lines, columns), of ``dtypes``)."""

    def __init__(
        self, cfg: BenchConfig, setup: RenderSetup, fp: FixedPattern, st: tuple[int, ...],
        dtypes: Mapping[str, np.dtype], *, pedestal_dn: float, band_lines: int = 256,
    ) -> None:
        self.cfg, self.setup, self.st, self.band_lines = cfg, setup, st, int(band_lines)
        self.lines, n_cols = cfg.lines, cfg.sensor.columns
        beta, ped = cfg.dtdi.beta_bits, float(pedestal_dn)
        shape = (len(st), self.lines, n_cols)
        self.arrays = {name: np.empty(shape, dtype=dt) for name, dt in dtypes.items()}
        self.sums = StageSums(n_cols, st, len(TRUTH_QUANTITIES))
        self.read_model = ReadModel.of(cfg.sensor)
        black = cfg.sensor.black_offset_dn if cfg.dtdi.subtract_black else 0.0
        #: the word's shift (- m b + P) per stage, and the word's clip folded into one read (m = 1)
        self.shift = {m: ped - m * black for m in st}
        top = min(self.read_model.top_dn, full_scale_dn(beta) - 1 + black - ped)
        self.fold = (max(0.0, black - ped), top)
        self.done = dict.fromkeys(st, 0)
        self.refl_done = 0
        t_int = setup.geom.t_int_s
        self.offsets = {
            m: stage_dark_offset_dn(
                cfg.sensor, fp, t_int, m, subtract_black=cfg.dtdi.subtract_black, pedestal_dn=ped
            )
            for m in st
        }
        self.footprints = row_footprints(cfg, setup.geom, setup.grid, st[-1])
        self.gain = fp.prnu_gain
        self.dark_e = fp.dark_current_e_s * t_int
        self.offset_dn = cfg.sensor.black_offset_dn + fp.column_offset_dn

    def push(self, got: Exposed) -> None:
        """Add one exposed chunk (its photons and saturated reads)."""
        a = self.arrays
        stack = self._read_quantities(got)
        word, lattice = float(full_scale_dn(self.cfg.dtdi.beta_bits) - 1), self.cfg.sensor.quantization
        for frame in stack:
            for m, line in self.sums.push(frame).items():
                s, j = self.st.index(m), self.done[m]
                if j < self.lines:
                    q = dict(zip(TRUTH_QUANTITIES, line, strict=True))
                    a["photons"][s, j] = q["photons"]
                    a["linear_dn"][s, j] = stage_mean_dn(q["gain_photons"], self.cfg.sensor, self.offsets[m])
                    if m == 1:
                        a["mean_dn"][s, j] = q["k1_stage1"] + self.shift[1]
                    else:
                        a["mean_dn"][s, j] = clipped_sum_mean(
                            q["k1"] + self.shift[m], q["k2"], q["k3"], 0.0, word, lattice=lattice
                        )
                    a["clipped"][s, j] = q["saturated"] > 0
                    self.done[m] = j + 1
        complete = min(self.done.values())
        if complete - self.refl_done >= self.band_lines or complete == self.lines:
            self._reflectance_band(complete)

    def _read_quantities(self, got: Exposed) -> np.ndarray:
        """Per read of a chunk (frames, R, Q, N): the quantities :data:`TRUTH_QUANTITIES` that the stages
        sum; the cumulants of every clipped read (:func:`bench_sim.sensor.expectation.read_cumulants`)."""
        sensor, ph = self.cfg.sensor, got.photons
        rows = ph.shape[1]
        light = ph * (sensor.quantum_efficiency * self.gain[:rows])
        dark = np.broadcast_to(self.dark_e[:rows], ph.shape)
        if sensor.shot_noise and not sensor.dark_noise:
            lam, det = light, dark
        elif sensor.dark_noise and not sensor.shot_noise:
            lam, det = dark, light
        else:
            lam, det = light + dark, np.zeros(())
        noisy = sensor.shot_noise or sensor.dark_noise
        stack = np.zeros((ph.shape[0], self.st[-1], len(TRUTH_QUANTITIES), ph.shape[2]), dtype=np.float64)
        q = {name: i for i, name in enumerate(TRUTH_QUANTITIES)}
        stack[:, :, q["photons"]] = ph
        np.multiply(ph, self.gain[:rows], out=stack[:, :, q["gain_photons"]])
        k1, k2, k3 = read_cumulants(lam, det, self.offset_dn, self.read_model, noisy=noisy)
        stack[:, :, q["k1"]], stack[:, :, q["k2"]], stack[:, :, q["k3"]] = k1, k2, k3
        stack[:, :, q["saturated"]] = got.saturated
        if 1 in self.st:  # stage 1 is one read: the word's clip folds into the read's (exact)
            bdet = det if np.ndim(det) == 0 else det[:, 0]
            stack[:, 0, q["k1_stage1"]] = read_cumulants(
                lam[:, 0], bdet, self.offset_dn, self.read_model, noisy=noisy, lo_dn=self.fold[0],
                hi_dn=self.fold[1],
            )[0]
        return stack

    def _reflectance_band(self, upto: int) -> None:
        grid, q, refl = self.setup.grid, self.setup.grid.q, self.arrays["reflectance"]
        start = self.refl_done
        while start < upto:
            stop = min(start + self.band_lines, upto)
            r0, r1 = reflectance_rows(self.footprints, q, self.st[-1], start, stop)
            band = grid.rows(r0, r1)
            for s, m in enumerate(self.st):
                refl[s, start:stop] = stage_reflectance(band, q, self.footprints, m, start, stop, row0=r0)
            start = stop
        self.refl_done = start

    def finish(self, dn_all: np.ndarray) -> None:
        """Mark the words that hit the top of the word as clipped."""
        self.arrays["clipped"] |= dn_all >= full_scale_dn(self.cfg.dtdi.beta_bits) - 1
