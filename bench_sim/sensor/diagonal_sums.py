"""The DTDI diagonal sum, compiled: a chunk of frames added to the partial lines, stages copied out.

Row ``i`` of frame ``k`` sees scene line ``k - i`` (paper eq. 1-2), so a chunk of ``C`` frames
adds to the ``R - 1`` partial lines carried from earlier chunks and to ``C`` new ones. The buffer
``acc`` holds them in line order: its row ``L`` is line ``k0 - R + 1 + L`` (``k0`` the chunk's
first frame), which gets row ``i`` of the chunk's frame ``t = L - R + 1 + i``. Every line gets its
rows in the order ``i = 0, 1, ...``, each as ``acc + value`` in the sum's dtype (float64: the
value converted first, as numpy's ``acc += values`` converts it), from the value the buffer
holds (the carried partial sum, or the caller's zero): the same operations in the same order as
numpy slice additions row after row, so float64 sums are bit-identical to them (integer sums are
exact anyway). When row ``m - 1`` of a line is in, its stage-``m`` value is complete and copied
out, either as the sum itself (the truth, :class:`bench_sim.sensor.stage_truth.StageSums`) or as
the DTDI word (:class:`bench_sim.sensor.dtdi.DTDIAccumulator`, paper eq. 4)::

    word = clip(rint(float64(sum) + shift), 0, top)      (the shift added only where it is not 0)

converted to ``uint32``: the operations of numpy's ``val = sums.astype(float64); val += shift;
np.rint(val, out=val); np.clip(val, 0, top, out=val); val.astype(uint32)`` (exactly rounded, so
bit-identical; a NaN sum has no defined word in either).

Compiled by :func:`bench_sim.runtime.jit.compiled` (numba, imported on first use, cached on disk),
one signature per (input, sum, output) dtype the callers use; :data:`LOOPS` names them for
:func:`bench_sim.runtime.jit.warm_up`. ``tests/sensor/test_diagonal_sums.py`` compares them bit
for bit with numpy.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.lib.stride_tricks import as_strided

from bench_sim.runtime.jit import compiled

__all__ = ["diagonal_sums", "frame_rows", "stage_blocks", "LOOPS"]


def _signature(values: str, sums: str, out: str) -> str:
    # flat input rows (read-only), frame stride, rows, acc, out, emit_from, out_row0, shifts, top
    return (
        f"void(Array({values}, 2, 'C', readonly=True), int64, int64, {sums}[:, ::1], {out}[:, ::1],"
        " int64[::1], int64[::1], float64[::1], float64)"
    )


def _diagonal_loop(
    flat: Any, fs: int, rows: int, acc: Any, out: Any, emit_from: Any, out_row0: Any, shifts: Any, top: float
) -> None:
    # the loop numba compiles (LOOPS); see diagonal_sums for the arguments. Line by line (its
    # buffer row stays in cache), rows in the order i = 0, 1, ...
    n_lines, n_cols = acc.shape
    n_frames = n_lines - rows + 1
    words = top >= 0.0
    for line in range(n_lines):
        row = acc[line]
        i0 = max(0, rows - 1 - line)
        i1 = min(rows, n_frames + rows - 1 - line)
        for i in range(i0, i1):
            t = line - rows + 1 + i
            src = flat[t * fs + i]
            for n in range(n_cols):
                row[n] = row[n] + src[n]
            if t < emit_from[i]:
                continue
            dst = out[out_row0[i] + t]
            if words:
                shift = shifts[i]
                for n in range(n_cols):
                    x = np.float64(row[n])
                    if shift != 0.0:
                        x = x + shift
                    x = np.rint(x)
                    if x < 0.0:
                        x = np.float64(0.0)
                    elif x > top:
                        x = np.float64(top)
                    dst[n] = np.uint32(x)
            else:
                for n in range(n_cols):
                    dst[n] = row[n]


#: (input, sum, output) dtypes: the DTDI words (uint16 DN summed in uint32, other integers in
#: int64, float64 DN in float64) and the truth's sums (photons float32, the cumulants float64,
#: the saturation flags bool, all in float64)
_KINDS = (
    ("uint16", "uint32", "uint32"),
    ("int64", "int64", "uint32"),
    ("float64", "float64", "uint32"),
    ("float32", "float64", "float64"),
    ("float64", "float64", "float64"),
    ("bool", "float64", "float64"),
)
_NUMBA_NAMES = {"bool": "boolean"}
#: the loop and its signatures (:func:`bench_sim.runtime.jit.compiled`, ``warm_up``)
LOOPS = tuple(
    (_diagonal_loop, _signature(*(_NUMBA_NAMES.get(d, d) for d in kind))) for kind in _KINDS
)
_BY_DTYPES = {tuple(np.dtype(d) for d in kind): loop for kind, loop in zip(_KINDS, LOOPS, strict=True)}
#: what an input of another dtype is converted to (exactly) for a sum of this dtype
_INPUT_FOR_SUM: dict[np.dtype, np.dtype] = {
    np.dtype(np.uint32): np.dtype(np.uint16),
    np.dtype(np.int64): np.dtype(np.int64),
    np.dtype(np.float64): np.dtype(np.float64),
}


def stage_blocks(
    stages: Sequence[int], frames_seen: int, n_frames: int, rows: int
) -> tuple[dict[int, slice], np.ndarray, np.ndarray]:
    """Where a chunk's completed lines go: one output block of every stage's lines, stage by
    stage (``stages`` ascending).

    Frame ``t`` of a chunk starting at frame ``frames_seen`` completes line ``frames_seen + t -
    m + 1`` of stage ``m``; lines before 0 are left out. Returns stage ``m`` -> its rows of the
    block, and the ``emit_from``, ``out_row0`` arrays (``rows``,) of :func:`diagonal_sums`.
    """
    emit_from = np.full(rows, n_frames, dtype=np.int64)  # rows that are no stage: none out
    out_row0 = np.zeros(rows, dtype=np.int64)
    blocks, end = {}, 0
    for m in stages:
        first = min(max(m - 1 - frames_seen, 0), n_frames)  # its first frame with a line >= 0
        blocks[m] = slice(end, end + n_frames - first)
        emit_from[m - 1], out_row0[m - 1] = first, end - first
        end += n_frames - first
    return blocks, emit_from, out_row0


def frame_rows(values: np.ndarray, rows: int) -> tuple[np.ndarray, int]:
    """Rows ``0 .. rows - 1`` of a (C, R0, N) chunk as the rows of one C-contiguous 2-D array.

    Returns ``(flat, fs)`` with ``flat[t * fs + i]`` row ``i`` of frame ``t``. A chunk whose rows
    are C-contiguous within and between frames (a C-contiguous array, or a slice ``[:, :rows]``
    of one: ``fs = R0``) is viewed read-only in place (the view spans only memory between the
    chunk's own elements); any other chunk is copied.
    """
    n_frames, _, n_cols = values.shape
    v = values[:, :rows]
    if v.flags.c_contiguous:
        return v.reshape(n_frames * rows, n_cols), rows
    size, (s0, s1, s2) = v.itemsize, v.strides
    row_bytes = n_cols * size
    if (n_cols == 1 or s2 == size) and (rows == 1 or s1 == row_bytes) and s0 > 0 and s0 % row_bytes == 0:
        fs = s0 // row_bytes
        if fs >= rows:
            shape = ((n_frames - 1) * fs + rows, n_cols)
            return as_strided(v, shape=shape, strides=(row_bytes, size), writeable=False), fs
    return np.ascontiguousarray(v).reshape(n_frames * rows, n_cols), rows


def diagonal_sums(
    values: np.ndarray,
    rows: int,
    acc: np.ndarray,
    out: np.ndarray,
    emit_from: np.ndarray,
    out_row0: np.ndarray,
    shifts: np.ndarray | None = None,
    top: float = -1.0,
) -> None:
    """Add a chunk of frames to the partial lines along the diagonals; copy the completed stages.

    Parameters
    ----------
    values : numpy.ndarray
        (C, R0, N) per-read values of ``C`` frames (DN, photons, ...), rows ``0 .. rows - 1``
        read (``R0 >= rows``): uint16/int64/float64 for words, float32/float64/bool for sums.
        Another dtype is converted first (exactly: to uint16 for a uint32 sum of 8- or 16-bit
        values, else to the sum's dtype).
    rows : int
        ``R``, the highest stage.
    acc : numpy.ndarray
        (R - 1 + C, N) C-contiguous running sums (uint32, int64 or float64, the unit of
        ``values``), added to in place: row ``L`` is the line that row ``i`` of frame
        ``L - R + 1 + i`` sees; rows ``0 .. R - 2`` hold the partial lines carried over, the
        others start as the caller leaves them (zero).
    out : numpy.ndarray
        (lines, N) C-contiguous, written: stage ``m``'s line of frame ``t`` goes to row
        ``out_row0[m - 1] + t``; float64 (the sums, ``top < 0``) or uint32 (the words).
    emit_from, out_row0 : numpy.ndarray
        (R,) int64: per row ``i`` the first frame whose line is output as stage ``i + 1`` (``C``
        or more: none, as for rows that are no requested stage), and its output row offset.
    shifts : numpy.ndarray, optional
        (R,) float64: the word's shift [DN] per stage ``i + 1`` (pedestal minus ``m b``).
    top : float
        The word's clip [DN] (``2**beta - 1``); negative: output the sums themselves.

    Releases the GIL: threads can run it on different passes in parallel.
    """
    want = _INPUT_FOR_SUM.get(acc.dtype, acc.dtype)
    if (values.dtype, acc.dtype, out.dtype) not in _BY_DTYPES and values.dtype != want:
        values = values.astype(want)
    flat, fs = frame_rows(values, rows)
    if shifts is None:
        shifts = np.zeros(rows, dtype=np.float64)
    loop = _BY_DTYPES.get((flat.dtype, acc.dtype, out.dtype))
    if loop is None:
        raise TypeError(f"diagonal_sums: no loop for {flat.dtype} values, {acc.dtype} sums, {out.dtype} out")
    compiled(*loop)(flat, fs, rows, acc, out, emit_from, out_row0, shifts, float(top))
