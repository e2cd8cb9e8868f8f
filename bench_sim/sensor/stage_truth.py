"""Exact ground truth of DTDI stage images, computed in the same pass as the images.

A stage-``m`` pixel (scene line ``j``, column ``n``) sums the reads of sensor rows
``i = 0 .. m-1`` in frames ``j + i`` (paper eq. 1-2). Its truth is therefore a sum over the same
``m`` (frame, row) pairs:

``photons``
    ``sum_i mu_p[j + i, i, n]``: the mean photons the ``m`` pixels collected (the renderer's
    exposures, smear included), accumulated by :class:`StageSums`.
``mean_dn``
    The exact expectation of the stage word before it is clipped, for this physical sensor
    (:func:`stage_mean_dn`): the EMVA 1288 linear model of every read with the pixel's own fixed
    pattern, summed over the ``m`` reads.
``reflectance``
    The target reflectance the pixel integrated: the mean over its ``m`` rows of the target
    averaged over each row's footprint on the drum in its frame -- the pixel's area projected
    through the lens centre onto the drum, swept by the surface's travel during the integration
    time (smear). Footprints are computed from the rig geometry (:func:`row_footprints`), so
    they follow every row's own position: under a sync error ``e`` the ``m`` footprints of one
    stage pixel walk ``e`` object pixels apart per row, and the truth moves and widens with them.
    Optical blur (defocus, diffraction) is not part of the footprint.

Memory: :class:`StageSums` carries the ``max(stages) - 1`` partial line sums in progress (as the
DTDI accumulator's ring does) and :func:`stages_reflectance` works on a band of output lines at a
time, so only the requested stage images grow with the number of lines (and nothing does when the
pass streams them to a sink, :func:`bench_sim.pipeline.run_pass`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from bench_sim.config import BenchConfig, SensorConfig
from bench_sim.errors import BenchSimError
from bench_sim.render.texture import RunTexture
from bench_sim.rig.geometry import RigGeometry, surface_angles
from bench_sim.sensor.diagonal_sums import diagonal_sums, stage_blocks
from bench_sim.sensor.emva import FixedPattern

if TYPE_CHECKING:  # scipy is imported where the matrices are built (it costs start-up time)
    import scipy.sparse as sp

__all__ = [
    "RowFootprints",
    "row_footprints",
    "stages_reflectance",
    "reflectance_rows",
    "StageSums",
    "stage_dark_offset_dn",
    "stage_mean_dn",
]

#: Quadrature points per pixel side (along the track: also per integration time)
_SAMPLES_Y = 32
_SAMPLES_T = 32
_SAMPLES_X = 16
#: Rows whose across-track footprints differ by less than this [texels] at the outermost column
#: share one across-track matrix.
_X_GROUP_TOL_TEXELS = 0.01


@dataclass(frozen=True)
class RowFootprints:
    """Footprints of the pixels of each sensor row on the run's texture grid (frame 0).

    Attributes
    ----------
    y_base
        (R,) first texel row of each row's along-track weights in frame 0; frame ``k`` adds
        ``k * q`` (the grid moves exactly ``q`` texels per line period).
    y_weights
        Per row, the weights of consecutive texel rows from ``y_base`` (sum 1): the pixel's
        height projected on the drum convolved with the smear, on the bilinear interpolant.
    x_group
        (R,) index of each row's across-track matrix in ``x_matrices``.
    x_matrices
        (N, nx) sparse matrices, rows sum to 1: column ``n``'s footprint across the track.
    """

    y_base: np.ndarray
    y_weights: tuple[np.ndarray, ...]
    x_group: np.ndarray
    x_matrices: tuple[sp.csr_matrix, ...]


def _hat_weights(pos: np.ndarray, n_nodes: int, what: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Node indices and weights of the linear interpolant at fractional node positions ``pos``."""
    i0 = np.floor(pos).astype(np.int64)
    if i0.min() < 0 or i0.max() + 1 >= n_nodes:
        raise BenchSimError(f"stage truth: pixel footprints fall outside the run texture ({what})")
    w1 = pos - i0
    return i0, 1.0 - w1, w1


def row_footprints(cfg: BenchConfig, geom: RigGeometry, grid: RunTexture, rows: int) -> RowFootprints:
    """Footprints of sensor rows ``0 .. rows-1`` (see :class:`RowFootprints`).

    Along the track, row ``i`` at sensor offset ``o = (i + f - M/2) * pitch`` (``f`` in 0..1
    over the pixel height) sees drum angle ``theta(o)`` (the chief ray through the lens
    centre, :func:`bench_sim.rig.geometry.surface_angles`); at time ``t`` in ``[0, t_int]`` of
    frame 0 that is material ``y = R (omega t - theta) + y_offset``. Across the track, column
    ``n`` at offset ``x_s = (n + g - N/2) * pitch`` sees ``x = x_s (D - R cos theta_i) / s'``
    (``D`` lens to axis, ``s'`` image distance). Both are integrated by midpoint quadrature
    (32 x 32 points along, 16 across) on the texture's bilinear interpolant.
    """
    s = cfg.sensor
    M, N, pitch = s.rows, s.columns, s.pixel_pitch_m
    ny, nx = grid.shape
    R, D, s_img = geom.radius_m, geom.camera_distance_m, geom.image_distance_m
    f = (np.arange(_SAMPLES_Y) + 0.5) / _SAMPLES_Y
    t = (np.arange(_SAMPLES_T) + 0.5) / _SAMPLES_T * geom.t_int_s
    g = (np.arange(_SAMPLES_X) + 0.5) / _SAMPLES_X
    y_base = np.zeros(rows, dtype=np.int64)
    y_weights = []
    scales = np.zeros(rows)
    for i in range(rows):
        theta = surface_angles((i + f - M / 2.0) * pitch, s_img, R, D)
        y = geom.y_material(theta[:, None], t[None, :]).ravel()
        i0, w0, w1 = _hat_weights((y - grid.y_start_m) / grid.h_y_m, ny, "along the track")
        base = int(i0.min())
        w = np.bincount(i0 - base, w0, minlength=int(i0.max()) - base + 2)
        w += np.bincount(i0 + 1 - base, w1, minlength=w.size)
        y_base[i] = base
        y_weights.append(w / w.sum())
        theta_c = surface_angles(np.array([(i + 0.5 - M / 2.0) * pitch]), s_img, R, D)[0]
        scales[i] = (D - R * np.cos(theta_c)) / s_img
    # rows whose across-track footprints agree to _X_GROUP_TOL_TEXELS share a matrix
    edge_texels = scales * (0.5 * N * pitch) / grid.h_x_m
    keys = np.round((edge_texels - edge_texels[0]) / _X_GROUP_TOL_TEXELS).astype(np.int64)
    x_group = np.zeros(rows, dtype=np.int64)
    import scipy.sparse as sp

    mats: list[sp.csr_matrix] = []
    seen: dict[int, int] = {}
    xs = (np.arange(N)[:, None] + g[None, :] - N / 2.0) * pitch  # (N, S) sensor offsets
    cols = np.repeat(np.arange(N), _SAMPLES_X)
    for i in range(rows):
        k = int(keys[i])
        if k not in seen:
            members = keys == k
            scale = float(scales[members].mean())
            pos = ((xs * scale).ravel() - grid.x_start_m) / grid.h_x_m
            i0, w0, w1 = _hat_weights(pos, nx, "across the track")
            data = np.concatenate([w0, w1]) / _SAMPLES_X
            mat = sp.coo_matrix(
                (data, (np.concatenate([cols, cols]), np.concatenate([i0, i0 + 1]))), shape=(N, nx)
            ).tocsr()
            seen[k] = len(mats)
            mats.append(mat)
        x_group[i] = seen[k]
    return RowFootprints(y_base, tuple(y_weights), x_group, tuple(mats))


def reflectance_rows(fp: RowFootprints, q: int, stage: int, line0: int, line1: int) -> tuple[int, int]:
    """Texture grid rows ``(r0, r1)`` that :func:`stages_reflectance` reads for stage ``m`` and
    lines ``line0 .. line1 - 1`` (a stage reads the rows of every lower stage too)."""
    m = int(stage)
    starts = [int(fp.y_base[i]) + i * q for i in range(m)]
    ends = [st + fp.y_weights[i].size for i, st in enumerate(starts)]
    return int(line0) * q + min(starts), (int(line1) - 1) * q + max(ends)


def stages_reflectance(
    values: np.ndarray, q: int, fp: RowFootprints, stages: Sequence[int], line0: int, line1: int,
    row0: int = 0,
) -> np.ndarray:
    """Reflectance integrated by the stage-``m`` pixels of scene lines ``line0 .. line1 - 1``, for
    every ``m`` in ``stages``: (S, line1 - line0, N) float64, 0..1.

    ``rho_m[j, n] = (1/m) sum_{i < m} <footprint of row i in frame j + i, texture>``: row ``i``
    reads line ``j`` in frame ``j + i`` (eq. 1-2), when its footprint sits ``(j + i) q`` texel
    rows further along the grid than in frame 0. The texture is projected across the track first
    (one sparse product per across-track matrix: ``P_g = values X_g^T``, (rows, N)); the stages
    then grow row by row, ``m rho_m = (m' rho_m') + sum_{m' <= i < m} <along-track footprint of
    row i, P_g(i)>`` between consecutive requested stages ``m' < m``, the rows of one group
    sharing one summed kernel.

    Parameters
    ----------
    values
        Reflectance of the run's texture grid rows ``row0 ..`` (:meth:`RunTexture.rows`; the
        rows :func:`reflectance_rows` names for the highest stage suffice), shape (rows, nx).
    q
        Texels per line period along the track.
    fp
        :func:`row_footprints` of at least ``max(stages)`` rows.
    stages, line0, line1
        The stages ``m`` and the band of output lines.
    row0
        Grid row of ``values[0]``.
    """
    st = tuple(sorted(int(m) for m in stages))
    if st and st[-1] > len(fp.y_weights):
        raise BenchSimError(f"stage {st[-1]}: footprints known for {len(fp.y_weights)} rows only")
    nl = int(line1) - int(line0)
    n_cols = fp.x_matrices[0].shape[0]
    out = np.zeros((len(st), max(nl, 0), n_cols), dtype=np.float64)
    if nl <= 0 or not st:
        return out
    vt = np.ascontiguousarray(np.asarray(values, dtype=np.float64).T)  # (nx, rows)
    proj: dict[int, np.ndarray] = {}
    acc = np.zeros((n_cols, nl), dtype=np.float64)  # m rho_m, columns first
    prev = 0
    for s, m in enumerate(st):
        for group in np.unique(fp.x_group[prev:m]):
            g = int(group)
            if g not in proj:
                proj[g] = np.asarray(fp.x_matrices[g] @ vt)  # (N, rows)
            rows = [i for i in range(prev, m) if fp.x_group[i] == g]
            kern, lo = _summed_kernel(fp, q, rows)
            start0 = int(line0) * q + lo - int(row0)
            if start0 < 0 or start0 + (nl - 1) * q + kern.size > vt.shape[1]:
                raise BenchSimError("stage truth: requested lines fall outside the run texture")
            for c in np.nonzero(kern)[0]:
                a = start0 + int(c)
                acc += kern[c] * proj[g][:, a : a + (nl - 1) * q + 1 : q]
        out[s] = acc.T / m
        prev = m
    return out


def _summed_kernel(fp: RowFootprints, q: int, rows: Sequence[int]) -> tuple[np.ndarray, int]:
    """The along-track weights of ``rows`` summed on one texel axis, and its first texel row
    (frame 0, line 0: row ``i`` sits ``i q`` rows further along, eq. 1-2)."""
    offs = [int(fp.y_base[i]) + i * q for i in rows]
    lo = min(offs)
    kern = np.zeros(max(o + fp.y_weights[i].size for o, i in zip(offs, rows, strict=True)) - lo)
    for o, i in zip(offs, rows, strict=True):
        kern[o - lo : o - lo + fp.y_weights[i].size] += fp.y_weights[i]
    return kern, lo


class StageSums:
    """Float DTDI sums of per-pixel quantities: for every stage ``m`` and scene line ``j``,
    ``sum_{i < m} v[frame j + i, row i]`` (paper eq. 1-2 without the output word).

    Works a chunk of frames at a time, by diagonal (the compiled loop
    :func:`bench_sim.sensor.diagonal_sums.diagonal_sums`): row ``i`` of frame ``k`` is added to
    scene line ``j = k - i``, and when row ``m - 1`` of a line is in, its stage ``m`` is complete.
    Every line sums its rows in the order ``i = 0, 1, ...`` from ``0.0``, as a per-frame ring
    would (and as numpy slice additions row after row: the same bits). Only the
    ``max(stages) - 1`` lines in progress are carried between chunks, so memory does not grow
    with the number of lines. A chunk holds ``Q`` quantities per pixel, each (C, R, N) with
    ``R >= max(stages)`` rows.
    """

    def __init__(self, n_columns: int, stages: Sequence[int], n_quantities: int) -> None:
        self.stages = tuple(sorted(int(m) for m in stages))
        self.ring_rows = self.stages[-1]
        self._carry = np.zeros((int(n_quantities), self.ring_rows - 1, int(n_columns)), dtype=np.float64)
        self.frames_seen = 0
        self.block = np.empty((int(n_quantities), 0, int(n_columns)))

    def push(self, chunk: Sequence[np.ndarray]) -> dict[int, np.ndarray]:
        """Add one chunk of ``C`` frames, its ``Q`` quantities each (C, R, N) (any real or bool
        dtype; summed in float64); return stage ``m`` -> the (Q, n, N) sums of the lines it
        completed (continuing the previous block; lines before 0 are left out), views into
        :attr:`block` in stage order."""
        r_rows, n_frames = self.ring_rows, chunk[0].shape[0]
        k0 = self.frames_seen
        acc = np.zeros((len(chunk), r_rows - 1 + n_frames, chunk[0].shape[2]), dtype=np.float64)
        acc[:, : r_rows - 1] = self._carry
        blocks, emit_from, out_row0 = stage_blocks(self.stages, k0, n_frames, r_rows)
        #: the completed lines of all stages, one block (stage by stage, as ``out``'s views)
        self.block = np.empty((len(chunk), max(b.stop for b in blocks.values()), acc.shape[2]))
        out = {m: self.block[:, b] for m, b in blocks.items()}
        for q, values in enumerate(chunk):  # one quantity at a time: its buffer stays in cache
            diagonal_sums(values, r_rows, acc[q], self.block[q], emit_from, out_row0)
        self._carry = acc[:, n_frames:].copy()
        self.frames_seen = k0 + n_frames
        return out


def stage_dark_offset_dn(
    sensor: SensorConfig,
    fixed: FixedPattern,
    t_int_s: float,
    stage: int,
    *,
    subtract_black: bool,
    pedestal_dn: float,
) -> np.ndarray:
    """The light-independent part [DN] of the expected stage-``m`` word of each column.

    ``sum_{i < m} (K I_d[i, n] t_int + b + c[n]) - m b [subtract_black] + P``: the dark signal of
    the ``m`` pixels (their own dark currents ``I_d``), the black offset ``b`` (left in when not
    subtracted), the column amplifier offset ``c[n]`` (coherent over the ``m`` rows) and the
    pedestal ``P``. Shape (N,).
    """
    m = int(stage)
    k = sensor.conversion_gain_dn_per_e
    dark = k * t_int_s * fixed.dark_current_e_s[:m].sum(axis=0)
    black = 0.0 if subtract_black else m * sensor.black_offset_dn
    return dark + m * fixed.column_offset_dn + black + float(pedestal_dn)


def stage_mean_dn(
    gain_weighted_photons: np.ndarray, sensor: SensorConfig, dark_offset_dn: np.ndarray
) -> np.ndarray:
    """Exact expectation [DN] of stage words before the word clips (linear range of every read).

    Each read is ``y = K (eta g mu_p + I_d t_int) + b + c`` in the mean (EMVA 1288 R4 eq. 5 with
    the pixel's PRNU gain ``g``, dark current ``I_d`` and column offset ``c``); the stage sums
    ``m`` reads (eq. 1-2), so
    ``E[gamma_m] = K eta sum_i g_i mu_p,i + stage_dark_offset_dn``.

    Parameters
    ----------
    gain_weighted_photons
        ``sum_i g_i mu_p,i`` over the stage's reads (photons), shape (..., N).
    sensor
        Pixel model.
    dark_offset_dn
        (N,) :func:`stage_dark_offset_dn` of the stage.

    References
    ----------
    EMVA Standard 1288, Release 4.0 Linear (2021), eq. 5; the DTDI sum of paper eq. 1-2.
    """
    k_eta = sensor.conversion_gain_dn_per_e * sensor.quantum_efficiency
    return k_eta * np.asarray(gain_weighted_photons, dtype=np.float64) + dark_offset_dn
