"""Many fusions of one pass against its exact truth, compiled: the sums behind every candidate's scores.

``bench-sim design`` scores every pair (and chosen triple) of stages of one all-stage pass under
several fusion rules. Fusing each candidate with numpy and scoring it with
:mod:`bench_sim.metrics.fusion_truth` runs a few dozen whole-image passes per candidate; the loop
here runs one, over the pixels of one top stage's candidates at a time, and returns per
candidate and rule the sums the scores are made of (:data:`FIELDS`). Per pixel it does what
these functions do, with the same float64 operations in the same order (no fused multiply-add:
numba's default, ``fastmath`` off), so every fused value is bit-identical to theirs; the sums
run pixel by pixel in order (numpy's ``sum`` adds pairwise, so they agree to rounding, 1e-13):

- the rules: ``eq11``, :func:`bench_sim.fusion.paper.fuse_dtdi_hdr_eq11` of the signals (the
  words less their offsets, :func:`bench_sim.fusion.stage_pair.fuse_stage_words`): the low
  stage's value ``(s_l mu_t) / mu_l`` where ``s_l mu_t > (Phi_FS - o_t) mu_l``, else ``s_t``;
  ``sat`` (the clip-aware rules), :func:`bench_sim.fusion.multistage.fuse_stages_highest_unsaturated`
  with ``criterion="clip"``: the highest stage whose signal is below its saturation level,
  ``(s_k mu_t) / mu_k``; two or three stages;
- the error: :func:`bench_sim.metrics.fusion_truth.relative_error`, ``(h - t) / t`` where the
  truth ``t >= 1`` DN;
- the regions (:data:`REGIONS`): ``whole``; ``spot`` and ``fill`` of the top stage
  (:func:`bench_sim.metrics.fusion_truth.light_regions`, given); ``spot_edge`` where the TDI
  window's light ratio ``r = (p_t / mu_t) / (p_l / mu_l)`` is finite and leaves ``1 +- tol``
  (:func:`bench_sim.metrics.fusion_truth.tdi_light_ratio`); ``clipped``, ``recoverable``,
  ``lost`` from each fused stage's clearance of its clips
  (:func:`bench_sim.metrics.fusion_truth.clip_regions`);
- the pixels taken from a stage that clipped there
  (:func:`bench_sim.metrics.fusion_truth.from_clipped_stage`) and from each stage;
- over the darkest region's pixels: the true signal of the stage each pixel came from and its
  temporal variance, both scaled to top-stage units (``scale = mu_t / mu_k``, the variance by
  ``scale**2``), for its temporal SNR (:func:`bench_sim.measure.pass_metrics.fused_temporal_snr`).

Compiled by :func:`bench_sim.runtime.jit.compiled` (numba, imported on first use, cached on
disk); :data:`LOOPS` names the loop for :func:`bench_sim.runtime.jit.warm_up`.
``tests/metrics/test_fusion_sums.py`` compares it with the numpy functions.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from bench_sim.runtime.jit import compiled

__all__ = ["REGIONS", "FIELDS", "RULE_EQ11", "RULE_SAT", "fusion_sums", "LOOPS"]

#: the regions of the error sums, in the order of :data:`FIELDS`
REGIONS = ("whole", "spot", "fill", "spot_edge", "clipped", "recoverable", "lost")
#: what :func:`fusion_sums` returns per candidate and rule, in this order: per region the pixels
#: with a finite error, the sum of the errors and of their squares; the pixels taken from a
#: clipped stage, from the low and from the middle stage; over the darkest region the sum of the
#: fused true signal, of its variance and the pixels
FIELDS: tuple[str, ...] = (
    *(f"{r}_{q}" for r in REGIONS for q in ("n", "sum", "sumsq")),
    "from_clipped",
    "from_low",
    "from_mid",
    "dark_signal",
    "dark_var",
    "dark_n",
)
#: rule codes: eq. 11 (two stages), the highest stage below its saturation level (two or three)
RULE_EQ11, RULE_SAT = 0, 1
_N = len(REGIONS)
#: the loops' arguments: S, T, VALID, CLIP, CLEAR, PHR, SPOT, FILL (stages x pixels), top, lows,
#: mids, stage numbers, rule codes, saturations, Phi_FS - o_top, tolerance, out; the dark loop:
#: S, T, dark pixels, their variances, top, lows, mids, stage numbers, codes, saturations,
#: Phi_FS - o_top, out
_F2, _B2 = "float64[:, ::1]", "boolean[:, ::1]"
_I1, _F1 = "int64[::1]", "float64[::1]"
_SIGNATURE = (f"void({_F2}, {_F2}, {_B2}, {_B2}, {_B2}, {_F2}, {_I1}, {_F2}, {_I1}, int64, {_I1}, "
              f"{_I1}, {_F1}, {_I1}, {_F2}, float64, float64, float64[:, :, ::1])")
_DARK_SIGNATURE = (f"void({_F2}, {_F2}, {_I1}, {_F2}, int64, {_I1}, {_I1}, {_F1}, {_I1}, {_F2}, float64, "
                   "float64[:, :, ::1])")


def _sums_loop(S: Any, T: Any, VALID: Any, CLIP: Any, CLEAR: Any, PHR: Any, LIGHT: Any, ETOP: Any, ALIKE: Any,
               top: int, lows: Any, mids: Any, mst: Any, codes: Any, sat: Any, phi_off_top: float, tol: float,
               out: Any) -> None:
    # the loop numba compiles (LOOPS[0]); see fusion_sums. The rule's choice of a stage k: eq. 11
    # the low stage where s_l mu_t > (Phi_FS - o_t) mu_l, else the top; the others the highest
    # stage below its level. The error goes to bin 0 ("whole"), 1 or 2 ("spot", "fill", LIGHT), 3
    # ("spot_edge") and one clearance class (4-6: every stage clear, some, none), summed into the
    # regions last: a[rule, 3 bin + (n, sum, sumsq)], then 21-23 the counts. Where every rule
    # takes one stage with one value it is added once, to row n_r: ALIKE 0 where every rule but
    # eq. 11 takes the top stage with eq. 11's value, 1 where none does, 2 otherwise; ETOP: the top
    # stage's error as eq. 11 takes it (s_t) and as the others do ((s_t mu_t) / mu_t).
    n_r, m_t, eq11 = codes.size, mst[top], (codes == 0).any()
    acc = np.zeros((lows.size, n_r + 1, 24))
    for j in range(lows.size):
        il, im, m_l, a = lows[j], mids[j], mst[lows[j]], acc[j]
        c = phi_off_top * m_l
        for p in range(S.shape[1]):
            s_l, ok, mode = S[il, p], VALID[top, p], ALIKE[p]
            low = s_l * m_t > c  # eq. 11 takes the low stage
            if (eq11 and (im >= 0 or low == (mode == 0))) or (mode == 1 and im >= 0):
                mode = 2
            c_l, c_t = CLEAR[il, p], CLEAR[top, p]
            c_m = CLEAR[im, p] if im >= 0 else c_l
            cls = 4 if (c_l and c_t and c_m) else (5 if (c_l or c_t or c_m) else 6)
            edge = PHR[il, p] > 0.0 and abs(PHR[top, p] / PHR[il, p] - 1.0) > tol
            e_low = (s_l * m_t / m_l - T[top, p]) / T[top, p] if ok and (low or mode > 0) else 0.0
            for rr in range(1 if mode < 2 else n_r):
                r, k, e = n_r, top, ETOP[0, p]
                if mode == 1:
                    k, e = il, e_low
                elif mode == 2:
                    r = rr
                    if codes[rr] == 0:
                        if im >= 0:
                            continue
                        if low:
                            k, e = il, e_low
                    elif S[top, p] < sat[rr, top]:
                        e = ETOP[1, p]
                    else:
                        k = im if im >= 0 and S[im, p] < sat[rr, im] else il
                        h = s_l * m_t / m_l if k == il else S[im, p] * m_t / mst[im]
                        e = (h - T[top, p]) / T[top, p] if ok else 0.0
                if k != top:
                    a[r, 22 if k == il else 23] += 1.0
                if CLIP[k, p]:
                    a[r, 21] += 1.0
                if ok:
                    e2, g = e * e, LIGHT[p]
                    a[r, 0] += 1.0
                    a[r, 1] += e
                    a[r, 2] += e2
                    a[r, 3 * cls] += 1.0
                    a[r, 3 * cls + 1] += e
                    a[r, 3 * cls + 2] += e2
                    if g > 0:
                        a[r, 3 * g] += 1.0
                        a[r, 3 * g + 1] += e
                        a[r, 3 * g + 2] += e2
                    if edge:
                        a[r, 9] += 1.0
                        a[r, 10] += e
                        a[r, 11] += e2
    for j in range(lows.size):
        for r in range(n_r):
            if codes[r] == 0 and mids[j] >= 0:
                continue
            b = acc[j, r] + acc[j, n_r]
            out[j, r, :12] = b[:12]  # whole, spot, fill, spot_edge
            out[j, r, 12:15] = b[15:18]  # clipped: some stage not clear, some clear
            out[j, r, 15:18] = b[12:15] + b[15:18]  # recoverable
            out[j, r, 18:24] = b[18:24]  # lost; from a clipped stage, the low, the middle


def _dark_loop(S: Any, T: Any, DIDX: Any, DVAR: Any, top: int, lows: Any, mids: Any, mst: Any, codes: Any,
               sat: Any, phi_off_top: float, out: Any) -> None:
    # the loop numba compiles (LOOPS[1]): over the darkest region, the stage each rule takes (as
    # in _sums_loop), its true signal and variance scaled to top-stage units
    m_t = mst[top]
    for j in range(lows.size):
        il, im = lows[j], mids[j]
        c = phi_off_top * mst[il]
        for d in range(DIDX.size):
            p = DIDX[d]
            s_l, s_t = S[il, p], S[top, p]
            s_m = S[im, p] if im >= 0 else 0.0
            for r in range(codes.size):
                if codes[r] == 0:
                    if im >= 0:
                        continue
                    k = il if s_l * m_t > c else top
                else:
                    k = top if s_t < sat[r, top] else (im if im >= 0 and s_m < sat[r, im] else il)
                if k == top:
                    out[j, r, 3 * _N + 3] += T[top, p]
                    out[j, r, 3 * _N + 4] += DVAR[top, d]
                else:
                    scale = m_t / mst[k]
                    out[j, r, 3 * _N + 3] += T[k, p] * scale
                    out[j, r, 3 * _N + 4] += DVAR[k, d] * scale**2
                out[j, r, 3 * _N + 5] += 1.0


#: the loops and their signatures (:func:`bench_sim.runtime.jit.compiled`, ``warm_up``)
LOOPS = ((_sums_loop, _SIGNATURE), (_dark_loop, _DARK_SIGNATURE))


def fusion_sums(
    *, signal: np.ndarray, truth: np.ndarray, valid: np.ndarray, clipped: np.ndarray, clear: np.ndarray,
    photons_per_row: np.ndarray, spot: np.ndarray, fill: np.ndarray, dark_pixels: np.ndarray,
    dark_var: np.ndarray, stages: np.ndarray, top: int, lows: np.ndarray, mids: np.ndarray, codes: np.ndarray,
    saturation: np.ndarray, phi_minus_offset_top: float, tolerance: float,
) -> np.ndarray:
    """The sums (:data:`FIELDS`) of every candidate with top stage ``top`` and rule (module docstring).

    Parameters
    ----------
    signal, truth
        (stages, pixels) float64: each stage's word less its offset, and its true signal
        (``linear_dn`` less the offset) [DN].
    valid
        (stages, pixels) bool: ``truth >= 1`` (where the relative error is defined).
    clipped, clear
        (stages, pixels) bool: the stage value clipped anywhere (the truth's ``clipped``), and
        clear of its clips (:func:`bench_sim.metrics.fusion_truth.clear_of_clips`).
    photons_per_row
        (stages, pixels) float64: the truth's ``photons`` over the stage ``m``.
    spot, fill
        (stages, pixels) bool: the light regions of each stage as the top stage.
    dark_pixels, dark_var
        The darkest region's flat pixel indices and each stage's temporal variance there,
        (stages, D) [DN^2].
    stages
        (stages,) the stage numbers ``m`` of the rows.
    top, lows, mids
        Row indices: the top stage, and per candidate its low and middle stage (``-1``: two stages).
    codes, saturation
        Per rule its code (:data:`RULE_EQ11`, :data:`RULE_SAT`), and (rules, stages) saturation
        levels of the signals [DN] (used by :data:`RULE_SAT`).
    phi_minus_offset_top
        ``Phi_FS - o_top`` [DN] (eq. 11's threshold times ``mu_t / mu_l``).
    tolerance
        ``|r - 1|`` beyond which a pixel is at the spot's edge.

    Returns
    -------
    numpy.ndarray
        (candidates, rules, len(FIELDS)) float64; a rule of code :data:`RULE_EQ11` on a
        three-stage candidate is left at 0.
    """
    out = np.zeros((lows.size, codes.size, len(FIELDS)), dtype=np.float64)
    ints = [np.ascontiguousarray(a, dtype=np.int64) for a in (lows, mids, codes)]
    mst = np.ascontiguousarray(stages, dtype=np.float64)
    sat = np.ascontiguousarray(saturation, dtype=np.float64)
    light, e_top, alike = _top_arrays(signal, truth, valid, spot, fill, mst, int(top), ints[2], sat)
    compiled(*LOOPS[0])(signal, truth, valid, clipped, clear, photons_per_row, light, e_top, alike,
                        int(top), ints[0], ints[1], mst, ints[2], sat, float(phi_minus_offset_top),
                        float(tolerance), out)
    compiled(*LOOPS[1])(signal, truth, np.ascontiguousarray(dark_pixels, dtype=np.int64), dark_var, int(top),
                        ints[0], ints[1], mst, ints[2], sat, float(phi_minus_offset_top), out)
    return out


def _top_arrays(signal: np.ndarray, truth: np.ndarray, valid: np.ndarray, spot: np.ndarray, fill: np.ndarray,
                mst: np.ndarray, top: int, codes: np.ndarray, sat: np.ndarray) -> tuple[np.ndarray, ...]:
    """Per pixel of the top stage: its light region (1 spot, 2 fill, 0 neither), its error as eq. 11
    takes it (``s_t``) and as the other rules do (``(s_t mu_t) / mu_t``), 0 where the truth is
    below 1 DN, and the loop's common cases (0: every rule but eq. 11 takes the top stage with
    eq. 11's value; 1: none of them takes it; 2: neither)."""
    s, t, ok, m = signal[top], truth[top], valid[top], mst[top]
    e_top = np.zeros((2, s.size))
    np.divide(s - t, t, out=e_top[0], where=ok)
    np.divide(s * m / m - t, t, out=e_top[1], where=ok)
    takes = [s < sat[r, top] for r in np.flatnonzero(codes != 0)]
    every = np.logical_and.reduce(takes) if takes else np.ones(s.size, dtype=bool)
    none = ~np.logical_or.reduce(takes) if takes else np.ones(s.size, dtype=bool)
    mode = np.where(every & (e_top[0] == e_top[1]), 0, np.where(none, 1, 2)).astype(np.int64)
    light = np.where(spot[top], 1, np.where(fill[top], 2, 0)).astype(np.int64)
    return light, e_top, mode
