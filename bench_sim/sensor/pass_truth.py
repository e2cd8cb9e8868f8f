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

from collections.abc import Collection
from dataclasses import dataclass
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.render.exposures import RenderSetup
from bench_sim.sensor.chain_truth import law_read_cumulants, law_read_model, linear_maps, stage_constant_dn
from bench_sim.sensor.cumulant_kernel import light_quantities
from bench_sim.sensor.dtdi import full_scale_dn, word_shift_dn
from bench_sim.sensor.effects.chain import sensor_chain
from bench_sim.sensor.emva import FixedPattern
from bench_sim.sensor.expectation import clipped_sum_mean, clipped_sum_var, read_cumulants
from bench_sim.sensor.stage_truth import (
    StageSums,
    reflectance_rows,
    row_footprints,
    stage_dark_offset_dn,
    stage_mean_dn,
    stages_reflectance,
)
from bench_sim.sensor.stream import Exposed

__all__ = ["PassTruth", "TruthBlock", "TRUTH_QUANTITIES", "TRUTH_VARIABLES"]

#: per-read quantities the truth sums over a stage's rows: photons, PRNU-weighted photons, the
#: cumulants of the clipped read and the saturation flag (row 0's read with the word's clip folded
#: in, stage 1's mean, is kept apart: it is not summed)
TRUTH_QUANTITIES = ("photons", "gain_photons", "k1", "k2", "k3", "saturated")
#: each truth variable of a stage line -> the quantities of :data:`TRUTH_QUANTITIES` it is made of
#: (``reflectance`` is the target's, per band of lines)
TRUTH_VARIABLES: dict[str, tuple[str, ...]] = {
    "photons": ("photons",), "linear_dn": ("gain_photons",), "mean_dn": ("k1", "k2", "k3"),
    "noise_std_dn": ("k1", "k2", "k3"), "clipped": ("saturated",), "reflectance": (),
}


@dataclass(frozen=True)
class TruthBlock:
    """Consecutive lines of one truth variable of one stage.

    Attributes
    ----------
    name
        ``photons`` [photons], ``linear_dn``, ``mean_dn`` [DN] (float64), ``clipped`` (bool: a read
        saturated; the word's clip is not in yet) or ``reflectance`` (float64, 0..1).
    stage
        The stage ``m``.
    line0
        Scene line of ``values[0]``.
    values
        (n, N) lines ``line0 .. line0 + n - 1``.
    """

    name: str
    stage: int
    line0: int
    values: np.ndarray


class PassTruth:
    """The truth of a pass, accumulated chunk by chunk (:mod:`bench_sim.sensor.stage_truth`):
    ``photons``, ``mean_dn``, ``linear_dn``, ``clipped`` per stage line, ``reflectance`` per band
    of ``band_lines`` lines; :meth:`push` returns the :class:`TruthBlock` of the lines each chunk
    completes, so nothing here grows with the number of lines. ``variables``: the truth variables
    to make (of :data:`TRUTH_VARIABLES`; default all): only the quantities they are made of are
    computed and summed (each quantity is summed on its own: the values are the same bits)."""

    def __init__(
        self, cfg: BenchConfig, setup: RenderSetup, fp: FixedPattern, st: tuple[int, ...], *,
        pedestal_dn: float, band_lines: int = 256, footprint_rows: int | None = None,
        variables: Collection[str] | None = None,
    ) -> None:
        self.cfg, self.setup, self.st, self.band_lines = cfg, setup, st, int(band_lines)
        self.lines, n_cols = cfg.lines, cfg.sensor.columns
        beta, ped = cfg.dtdi.beta_bits, float(pedestal_dn)
        self.variables = tuple(v for v in TRUTH_VARIABLES if variables is None or v in variables)
        #: the quantities summed (at least one: it counts the completed lines)
        self.quantities = tuple(q for q in TRUTH_QUANTITIES
                                if any(q in TRUTH_VARIABLES[v] for v in self.variables)) or ("photons",)
        self.sums = StageSums(n_cols, st, len(self.quantities))
        #: each read's law under the chain's effects (bench_sim.sensor.chain_truth)
        self.law = sensor_chain(cfg.sensor).law(dict(fp.effects))
        self.read_model = law_read_model(cfg.sensor, self.law)
        black = cfg.sensor.black_offset_dn if cfg.dtdi.subtract_black else 0.0
        #: the word's shift per stage, and the word's clip folded into one read (m = 1)
        self.shift = {
            m: word_shift_dn(m, cfg.sensor.black_offset_dn, cfg.dtdi.subtract_black, ped) for m in st
        }
        self.word = float(full_scale_dn(beta) - 1)
        top = min(self.read_model.top_dn, self.word + black - ped)
        self.fold = (max(0.0, black - ped), top)
        self.done = dict.fromkeys(st, 0)
        self.refl_done = 0
        t_int = setup.geom.t_int_s
        # the footprints of the pass's rows (a truth of some of its stages: the same footprints)
        self.footprints = row_footprints(cfg, setup.geom, setup.grid, footprint_rows or st[-1])
        self.gain = fp.prnu_gain
        self.qe_gain = cfg.sensor.quantum_efficiency * fp.prnu_gain
        self.dark_e = fp.dark_current_e_s * t_int
        self.offset_dn = cfg.sensor.black_offset_dn + fp.column_offset_dn
        self.default = self.law.linear and self.law.extra_read_var_dn2 == 0 and fp.offset_dn is None
        if self.default:  # the default chain: its own closed forms (bit for bit as before)
            self.offsets = {
                m: stage_dark_offset_dn(
                    cfg.sensor, fp, t_int, m, subtract_black=cfg.dtdi.subtract_black, pedestal_dn=ped
                )
                for m in st
            }
        else:
            if fp.offset_dn is not None:
                self.offset_dn = self.offset_dn + fp.offset_dn
            self.gain, constant = linear_maps(cfg.sensor, self.law, fp.prnu_gain, self.dark_e, self.offset_dn)
            self.offsets = {m: stage_constant_dn(constant, m, self.shift[m]) for m in st}
        self.offset_stack = np.stack([self.offsets[m] for m in st])
        self._buf: np.ndarray | None = None

    def push(self, got: Exposed) -> list[TruthBlock]:
        """Add one exposed chunk (its photons and saturated reads); the truth of the lines it completed."""
        stack, k1_stage1 = self._read_quantities(got)
        parts = []
        for m, sums in self.sums.push(stack).items():
            j0 = self.done[m]
            n = min(sums.shape[1], self.lines - j0)
            if n > 0:
                parts.append((m, j0, sums[:, :n]))
                self.done[m] = j0 + n
        out = self._stage_lines(parts, k1_stage1) if parts else []
        complete = min(self.done.values())
        band = complete - self.refl_done >= self.band_lines or (complete == self.lines > self.refl_done)
        if band and "reflectance" in self.variables:
            out.extend(self._reflectance_bands(complete))
        return out

    def _stage_lines(
        self, parts: list[tuple[int, int, np.ndarray]], k1_stage1: tuple[np.ndarray, ...] | None
    ) -> list[TruthBlock]:
        """The truth of the lines of every stage a chunk completed, ``(m, j0, (Q, n, N) sums)`` per
        stage, in one vectorised step over all of them (the same operations per pixel as stage by
        stage)."""
        counts = [p[2].shape[1] for p in parts]
        whole = sum(counts) == self.sums.block.shape[1]  # nothing cut at the last line: one block
        sums = self.sums.block if whole else np.concatenate([p[2] for p in parts], axis=1)
        values = self._line_values(dict(zip(self.quantities, sums, strict=True)), parts, counts)
        if parts[0][0] == 1 and k1_stage1 is not None:  # stage 1's lines are this chunk's frames
            values["mean_dn"][: counts[0]] = (0.0 + k1_stage1[0][: counts[0]]) + self.shift[1]
            values["noise_std_dn"][: counts[0]] = np.sqrt(k1_stage1[1][: counts[0]])
        values = {n: v for n, v in values.items() if n in self.variables}
        out: list[TruthBlock] = []
        start = 0
        for (m, j0, _), n in zip(parts, counts, strict=True):
            out.extend(TruthBlock(name, m, j0, v[start : start + n]) for name, v in values.items())
            start += n
        return out

    def _line_values(
        self, q: dict[str, np.ndarray], parts: list[tuple[int, int, np.ndarray]], counts: list[int]
    ) -> dict[str, np.ndarray]:
        """The truth variables of the stage lines ``parts`` (``counts`` lines each) from their
        summed quantities ``q`` (name -> (n, N))."""
        want, values = self.variables, {}
        if "photons" in want:
            values["photons"] = q["photons"]
        if "linear_dn" in want:
            index = [self.st.index(m) for m, _, _ in parts]
            offsets = np.repeat(self.offset_stack[index], counts, axis=0)
            values["linear_dn"] = stage_mean_dn(q["gain_photons"], self.cfg.sensor, offsets)
        if "mean_dn" in want or "noise_std_dn" in want:
            shift = np.repeat([self.shift[m] for m, _, _ in parts], counts)[:, None]
            k = (q["k1"] + shift, q["k2"], q["k3"], 0.0, self.word)
            lattice = self.cfg.sensor.quantization
            values["mean_dn"] = clipped_sum_mean(*k, lattice=lattice)
            values["noise_std_dn"] = np.sqrt(clipped_sum_var(*k, lattice=lattice))
        if "clipped" in want:
            values["clipped"] = q["saturated"] > 0
        return values

    def _cumulants(
        self, lam: np.ndarray, det: np.ndarray, rows: slice | int, noisy: bool, **kw: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each read's cumulants: :func:`~bench_sim.sensor.expectation.read_cumulants` (the
        default chain), else under the chain's law
        (:func:`bench_sim.sensor.chain_truth.law_read_cumulants`)."""
        off = self.offset_dn if np.ndim(self.offset_dn) < 2 else self.offset_dn[rows]
        if self.default:
            return read_cumulants(lam, det, off, self.read_model, noisy=noisy, **kw)
        return law_read_cumulants(lam, det, off, self.read_model, self.law, rows, noisy=noisy, **kw)

    def _read_quantities(self, got: Exposed) -> tuple[list[np.ndarray], tuple[np.ndarray, ...] | None]:
        """Per read of a chunk (C frames, R rows, N columns): the (C, R, N) quantities
        :attr:`quantities` (of :data:`TRUTH_QUANTITIES`) that the stages sum, the cumulants of
        every clipped read (:func:`bench_sim.sensor.expectation.read_cumulants`) when asked; and
        row 0's mean read with the word's clip folded in, (C, N), when stage 1's ``mean_dn`` is.
        Only the rows of this truth's highest stage are read (the pass may expose more)."""
        sensor, rows = self.cfg.sensor, self.st[-1]
        ph = got.photons[:, :rows]
        cumulants = "k1" in self.quantities
        if self._buf is None or self._buf.shape[1:] != ph.shape:  # reused: no page faults per chunk
            self._buf = np.empty((5 if cumulants else 2, *ph.shape), dtype=np.float64)
        gain_photons, light = self._buf[:2]
        got_q: dict[str, np.ndarray] = {"photons": ph}
        if cumulants or "gain_photons" in self.quantities:
            # both noises or neither: one Poisson mean, light + dark (det 0); else one is exact
            one_mean = sensor.shot_noise == sensor.dark_noise
            gain, qe_gain, dark_e = (
                np.ascontiguousarray(a[:rows]) for a in (self.gain, self.qe_gain, self.dark_e)
            )
            photons = np.ascontiguousarray(got.photons)  # all its rows: the loop reads the first `rows`
            light_quantities(photons, gain, qe_gain, dark_e, gain_photons, light, add_dark=one_mean)
            got_q["gain_photons"] = gain_photons
        k1_stage1 = None
        if cumulants:
            k1, k2, k3 = self._buf[2:]
            dark = np.broadcast_to(dark_e, ph.shape)
            det: np.ndarray
            if one_mean:
                lam, det = light, np.zeros(())
            elif sensor.shot_noise:
                lam, det = light, dark
            else:
                lam, det = dark, light
            noisy = sensor.shot_noise or sensor.dark_noise
            if 1 in self.st:  # stage 1 is one read: the word's clip folds into the read's (exact)
                bdet = det if np.ndim(det) == 0 else det[:, 0]
                k1_stage1 = self._cumulants(lam[:, 0], bdet, 0, noisy, lo_dn=self.fold[0], hi_dn=self.fold[1])
            self._cumulants(lam, det, slice(0, rows), noisy, out=(k1, k2, k3))
            got_q.update(k1=k1, k2=k2, k3=k3)
        if "saturated" in self.quantities:
            got_q["saturated"] = (got.saturated[:, :rows] if got.saturated is not None
                                  else np.zeros(ph.shape, dtype=bool))
        return [got_q[q] for q in self.quantities], k1_stage1

    def _reflectance_bands(self, upto: int) -> list[TruthBlock]:
        """The reflectance of lines ``refl_done .. upto - 1`` of every stage, band by band."""
        grid, q = self.setup.grid, self.setup.grid.q
        out: list[TruthBlock] = []
        start = self.refl_done
        while start < upto:
            stop = min(start + self.band_lines, upto)
            r0, r1 = reflectance_rows(self.footprints, q, self.st[-1], start, stop)
            refl = stages_reflectance(grid.rows(r0, r1), q, self.footprints, self.st, start, stop, row0=r0)
            out.extend(TruthBlock("reflectance", m, start, refl[s]) for s, m in enumerate(self.st))
            start = stop
        self.refl_done = start
        return out
