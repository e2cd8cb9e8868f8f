"""The compiled diagonal sum (DTDI words and the truth's stage sums) equals numpy's row-by-row
slice additions, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from bench_sim.runtime.jit import compiled
from bench_sim.sensor.diagonal_sums import LOOPS, diagonal_sums, frame_rows
from bench_sim.sensor.dtdi import DTDIAccumulator, dtdi_direct
from bench_sim.sensor.stage_truth import StageSums


def numpy_diagonal(values, rows, acc, out, emit_from, out_row0, shifts, top):
    """Row after row: ``acc[lines of row i] += values[:, i]`` (numpy slices), then the lines that
    row completes copied out, as sums or as words (``val += shift; rint; clip; astype``)."""
    n_frames = acc.shape[0] - rows + 1
    for i in range(rows):
        lo = rows - 1 - i
        acc[lo : lo + n_frames] += values[:, i]
        first = int(emit_from[i])
        if first >= n_frames:
            continue
        done = acc[lo + first : lo + n_frames]
        dst = slice(int(out_row0[i]) + first, int(out_row0[i]) + n_frames)
        if top < 0:
            out[dst] = done
            continue
        val = done.astype(np.float64)
        if shifts[i] != 0.0:
            val += shifts[i]
        np.rint(val, out=val)
        np.clip(val, 0.0, top, out=val)
        out[dst] = val.astype(np.uint32)


def _bits(a: np.ndarray) -> np.ndarray:
    return a.view(np.uint64) if a.dtype == np.float64 else a


def _awkward(rng: np.random.Generator, shape: tuple[int, ...], dtype: np.dtype, top: float) -> np.ndarray:
    """Values over many magnitudes with signed zeros (float sums), rounding ties and values past
    the word's clip at both ends (words), every integer range (integers)."""
    if dtype == np.bool_:
        return rng.random(shape) < 0.3
    if dtype.kind in "ui":
        hi = np.iinfo(dtype).max if dtype.itemsize < 8 else 1 << 40
        lo = 0 if dtype.kind == "u" else -hi
        return rng.integers(lo, hi, size=shape, endpoint=True).astype(dtype)
    if top >= 0:  # DN: around the clip limits, on half-integers (ties) and plain
        kind = rng.integers(0, 3, size=shape)
        base = rng.uniform(-0.2 * top, 0.5 * top, size=shape)
        x = np.where(kind == 0, np.floor(base) + 0.5, np.where(kind == 1, np.rint(base), base))
        return x.astype(dtype)
    x = rng.standard_normal(shape) * 10.0 ** rng.integers(-3, 4, size=shape)  # order shows in the bits
    far = rng.random(shape) < 0.003
    span = 30 if dtype.itemsize == 4 else 300  # huge and tiny, finite in the dtype
    x[far] *= 10.0 ** rng.integers(-span, span, size=int(far.sum()))
    x[rng.random(shape) < 0.1] = 0.0
    x[rng.random(shape) < 0.1] = -0.0
    return x.astype(dtype)


#: (values, sums, out) dtypes: the compiled ones, and inputs converted to them
KINDS = [
    ("uint16", "uint32", "uint32"), ("int64", "int64", "uint32"), ("float64", "float64", "uint32"),
    ("float32", "float64", "float64"), ("float64", "float64", "float64"), ("bool", "float64", "float64"),
    ("uint8", "uint32", "uint32"), ("int32", "int64", "uint32"), ("float32", "float64", "uint32"),
    ("uint16", "float64", "float64"),
]


@pytest.mark.parametrize("kind", KINDS, ids=["-".join(k) for k in KINDS])
@pytest.mark.parametrize(
    ("frames", "rows0", "rows", "columns", "k0", "seed"),
    [(1, 1, 1, 1, 0, 0), (16, 100, 80, 33, 0, 1), (3, 7, 7, 5, 2, 2), (40, 6, 4, 8, 1, 3),
     (16, 12, 12, 1024, 50, 4)],
)
def test_compiled_diagonal_sum_equals_numpy_bit_for_bit(kind, frames, rows0, rows, columns, k0, seed):
    rng = np.random.default_rng(seed)
    vt, st, ot = (np.dtype(d) for d in kind)
    words = ot == np.uint32
    beta = int(rng.integers(8, 17)) if vt.itemsize <= 2 or vt.kind == "f" else 32
    top = float(2**beta - 1) if words else -1.0
    values = _awkward(rng, (frames, rows0, columns), vt, top)[:, :rows]  # a row slice, as callers pass
    stages = sorted({rows, *(int(m) for m in rng.integers(1, rows + 1, size=3))})
    firsts = {m: min(max(m - 1 - k0, 0), frames) for m in stages}
    ends = np.cumsum([frames - f for f in firsts.values()])
    emit_from, out_row0 = np.full(rows, frames, dtype=np.int64), np.zeros(rows, dtype=np.int64)
    for (m, f), e in zip(firsts.items(), ends, strict=True):
        emit_from[m - 1], out_row0[m - 1] = f, e - frames
    shifts = rng.choice([0.0, 0.5, -20.5, 64.0, -1e6, 1e12], size=rows) if words else None
    acc = np.zeros((rows - 1 + frames, columns), dtype=st)  # the partial lines carried over, then 0
    if st.kind == "f":
        acc[: rows - 1] = _awkward(rng, (rows - 1, columns), st, top)
    else:
        acc[: rows - 1] = rng.integers(0, 1 << 20, (rows - 1, columns))
    want_acc, got_acc = acc.copy(), acc
    want = np.full((int(ends[-1]), columns), 7, dtype=ot)
    got = want.copy()
    numpy_diagonal(values, rows, want_acc, want, emit_from, out_row0, shifts, top)
    diagonal_sums(values, rows, got_acc, got, emit_from, out_row0, shifts, top)
    assert np.array_equal(_bits(got_acc), _bits(want_acc))
    assert np.array_equal(_bits(got), _bits(want))


def test_every_loop_compiles_for_its_signature():
    assert len({sig for _, sig in LOOPS}) == len(LOOPS) == 6
    for loop in LOOPS:
        assert callable(compiled(*loop))


def test_frame_rows_views_row_slices_and_copies_the_rest():
    full = np.arange(5 * 7 * 3, dtype=np.float32).reshape(5, 7, 3)
    flat, fs = frame_rows(full[:, :4], 4)  # a row slice: viewed in place, frame stride 7
    assert fs == 7 and np.shares_memory(flat, full) and not flat.flags.writeable
    flat, fs = frame_rows(full, 4)  # C-contiguous: rows 0..3 of every frame, stride 7 too
    assert fs == 7 and np.shares_memory(flat, full)
    odd = np.asfortranarray(full)
    flat2, fs2 = frame_rows(odd[:, :4], 4)
    assert fs2 == 4 and not np.shares_memory(flat2, odd)
    for f, s in ((flat, fs), (flat2, fs2)):
        for t in range(5):
            for i in range(4):
                assert np.array_equal(f[t * s + i], full[t, i])


def _old_stage_sums(quantities, stages, sizes):
    """The stage sums as numpy slice additions row after row, chunk by chunk (the reference)."""
    r_rows, k0 = max(stages), 0
    carry = np.zeros((len(quantities), r_rows - 1, quantities[0].shape[2]))
    got: dict[int, list[np.ndarray]] = {m: [] for m in stages}
    for size in sizes:
        acc = np.zeros((len(quantities), r_rows - 1 + size, carry.shape[2]))
        acc[:, : r_rows - 1] = carry
        done: dict[int, list[np.ndarray]] = {m: [] for m in stages}
        for q, values in enumerate(quantities):
            for i in range(r_rows):
                lo = r_rows - 1 - i
                acc[q, lo : lo + size] += values[k0 : k0 + size, i]
                if i + 1 in done:  # stage i + 1 of these lines is complete: copied now
                    done[i + 1].append(acc[q, lo + max(0, i - k0) : lo + size].copy())
        for m in stages:
            got[m].append(np.stack(done[m]))
        carry = acc[:, size:].copy()
        k0 += size
    return {m: np.concatenate(b, axis=1) for m, b in got.items()}


def test_stage_sums_of_truth_quantities_equal_numpy_bit_for_bit():
    """Photons float32 (a row slice), cumulants float64 over many magnitudes, flags bool."""
    rng = np.random.default_rng(7)
    frames, rows0, cols, stages, sizes = 45, 12, 6, (1, 3, 10), [16, 16, 1, 12]
    ph = (rng.exponential(1e3, (frames, rows0, cols))).astype(np.float32)[:, :10]
    k1 = _awkward(rng, (frames, 10, cols), np.dtype(np.float64), -1.0)
    flag = rng.random((frames, 10, cols)) < 0.2
    sums = StageSums(cols, stages, 3)
    got: dict[int, list[np.ndarray]] = {m: [] for m in stages}
    k = 0
    for size in sizes:
        for m, block in sums.push([ph[k : k + size], k1[k : k + size], flag[k : k + size]]).items():
            got[m].append(block.copy())
        k += size
    want = _old_stage_sums([ph, k1, flag], stages, sizes)
    for m in stages:
        assert np.array_equal(_bits(np.concatenate(got[m], axis=1)), _bits(want[m]))


def test_float_dn_words_equal_the_direct_sum_with_ties_and_clips():
    """Non-integer DN (quantisation off): streaming words equal the direct float64 sum's."""
    rng = np.random.default_rng(8)
    v = _awkward(rng, (30, 9, 7), np.dtype(np.float64), 4095.0)
    stages = (1, 2, 5, 9)
    kw = dict(beta_bits=12, black_offset_dn=20.25, subtract_black=True, pedestal_dn=64.0)
    want = dtdi_direct(v, stages, **kw)
    acc = DTDIAccumulator(7, stages, **kw)
    got: dict[int, list[np.ndarray]] = {m: [] for m in stages}
    for a, b in ((0, 1), (1, 17), (17, 18), (18, 30)):
        for m, block in acc.push_many(v[a:b]).items():
            assert block.dtype == np.uint32 and block.shape[1] == 7
            got[m].append(block)
    for m in stages:
        assert np.array_equal(np.concatenate(got[m]), want[m])
