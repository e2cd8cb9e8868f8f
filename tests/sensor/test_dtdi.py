"""DTDI accumulation: streaming == eq. 1-2, sqrt(m) noise growth, output word, memory."""

from __future__ import annotations

import gc
import tracemalloc

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bench_sim.config import DTDIConfig, SensorConfig
from bench_sim.errors import BenchSimError
from bench_sim.sensor.dtdi import (
    DTDIAccumulator,
    complete_lines,
    dtdi_direct,
    frames_needed,
    full_scale_dn,
    run_dtdi,
)
from bench_sim.sensor.emva import draw_fixed_pattern, expose, pixel_mean_var_dn
from bench_sim.sensor.stream import sensor_dtdi_pass
from tests.conftest import ALL_OFF

#: closed forms, invariants and seeded statistical tests (make test-fast)
pytestmark = pytest.mark.physics

T_INT_S = 100e-6


def eq_1_2(v: np.ndarray, m: int, j: int) -> np.ndarray:
    """Paper eq. 1-2 for one line, written out: sum of row i of frame j + i, i = 0..m-1."""
    total = np.zeros(v.shape[2], dtype=np.float64)
    for i in range(m):
        total += v[j + i, i, :]
    return total


# ------------------------------------------------------- must show 2: streaming == direct


def test_streaming_equals_direct_sum_with_all_noise_off_every_stage_start_and_end() -> None:
    """A moving scene through the noise-free sensor: the streaming accumulator, the direct
    reference and eq. 1-2 written out agree exactly for every stage 1..M, on every complete
    line including the first (j = 0) and the last (j = K - m)."""
    rows, cols, n_frames = 12, 9, 40
    s = SensorConfig(rows=rows, columns=cols, **{**ALL_OFF, "quantization": True})
    rng = np.random.default_rng(0)
    fixed = draw_fixed_pattern(s, rng)
    # a scene moving one row per frame: row i of frame k sees line k - i
    scene = rng.uniform(0, 25000, size=(n_frames + rows, cols))
    photons = np.stack([scene[k - np.arange(rows) + rows] for k in range(n_frames)])
    v = expose(photons, s, fixed, T_INT_S, rng)
    stages = list(range(1, rows + 1))
    direct = dtdi_direct(v, stages, 16, s.black_offset_dn)
    for chunking in (1, 7, n_frames):
        chunks = (v[i : i + chunking] for i in range(0, n_frames, chunking))
        stream = run_dtdi(chunks, stages, 16, s.black_offset_dn)
        for m in stages:
            assert stream[m].shape == (complete_lines(n_frames, m), cols)
            assert np.array_equal(stream[m], direct[m])
    for m in stages:
        for j in (0, 1, n_frames - m - 1, n_frames - m):
            expected = eq_1_2(v.astype(np.float64), m, j) - m * s.black_offset_dn
            assert np.array_equal(direct[m][j], np.clip(np.rint(expected), 0, 65535).astype(np.uint32))
    # the same scene line j has the same photons in every row: stage m = m x stage 1 when noise-free
    for m in (3, 12):
        n = complete_lines(n_frames, m)
        assert np.array_equal(direct[m][:n].astype(np.int64), m * direct[1][:n].astype(np.int64))


def test_push_returns_lines_in_order_as_they_complete() -> None:
    rng = np.random.default_rng(1)
    v = rng.integers(0, 1024, size=(10, 4, 3)).astype(np.uint16)
    acc = DTDIAccumulator(3, [1, 4], beta_bits=16, black_offset_dn=0.0)
    got: dict[int, list[np.ndarray]] = {1: [], 4: []}
    for k in range(10):
        out = acc.push(v[k])
        assert set(out) == ({1, 4} if k >= 3 else {1})
        for m, line in out.items():
            assert acc.lines_emitted(m) - 1 == len(got[m])
            got[m].append(line)
    assert len(got[4]) == 7
    for j, line in enumerate(got[4]):
        assert np.array_equal(line, eq_1_2(v.astype(float), 4, j).astype(np.uint32))


@settings(max_examples=60, deadline=None)
@given(
    n_frames=st.integers(1, 30),
    rows=st.integers(1, 8),
    cols=st.integers(1, 5),
    data=st.data(),
)
def test_streaming_equals_direct_property(n_frames: int, rows: int, cols: int, data) -> None:
    stages = data.draw(st.lists(st.integers(1, rows), min_size=1, max_size=rows, unique=True))
    chunk = data.draw(st.integers(1, 8))
    beta = data.draw(st.integers(8, 20))
    subtract = data.draw(st.booleans())
    ped = data.draw(st.integers(0, 50))
    seed = data.draw(st.integers(0, 2**32 - 1))
    v = np.random.default_rng(seed).integers(0, 1024, size=(n_frames, rows, cols)).astype(np.uint16)
    kw = dict(beta_bits=beta, black_offset_dn=20.0, subtract_black=subtract, pedestal_dn=ped)
    direct = dtdi_direct(v, stages, **kw)
    stream = run_dtdi((v[i : i + chunk] for i in range(0, n_frames, chunk)), stages, **kw)
    for m in stages:
        assert np.array_equal(direct[m], stream[m])


def test_uniform_lines_option_and_frames_needed() -> None:
    rng = np.random.default_rng(2)
    lines, stages = 10, [2, 5]
    k = frames_needed(lines, stages)
    assert k == 14
    v = rng.integers(0, 1024, size=(k, 6, 4)).astype(np.uint16)
    out = run_dtdi(v, stages, 16, 0.0, lines=lines)
    ref = dtdi_direct(v, stages, 16, 0.0)
    for m in stages:
        assert out[m].shape == (lines, 4)
        assert np.array_equal(out[m], ref[m][:lines])
    with pytest.raises(BenchSimError, match="needs 14 frames"):
        run_dtdi(v[:13], stages, 16, 0.0, lines=lines)
    with pytest.raises(BenchSimError, match="needs 14 frames"):
        dtdi_direct(v[:13], stages, 16, 0.0, lines=lines)


def test_bad_stages_and_frames_raise() -> None:
    v = np.zeros((5, 3, 2), dtype=np.uint16)
    with pytest.raises(BenchSimError, match="1..3"):
        dtdi_direct(v, [4], 12, 0.0)
    with pytest.raises(BenchSimError):
        dtdi_direct(v, [0], 12, 0.0)
    acc = DTDIAccumulator(2, [3], 12, 0.0)
    with pytest.raises(BenchSimError, match="frame shape"):
        acc.push(np.zeros((2, 2)))
    with pytest.raises(BenchSimError, match="beta_bits"):
        DTDIAccumulator(2, [1], 40, 0.0)


# --------------------------------------------------------- must show 5: output word clip


def test_output_word_clips_at_2_pow_beta_minus_1_where_expected() -> None:
    """Noise-free pixels of v DN above black: stage m stores m * (v - b) until that exceeds
    2**beta - 1, from where it stores exactly 2**beta - 1."""
    beta = 12
    top = full_scale_dn(beta) - 1
    assert top == 4095
    s = SensorConfig(rows=100, columns=8, **{**ALL_OFF, "quantization": True})
    rng = np.random.default_rng(0)
    fixed = draw_fixed_pattern(s, rng)
    photons = 4000.0  # 0.55 * 4000 e- * 0.072 DN/e- = 158.4 -> 158 DN above black per row
    v = expose(np.full((120, 100, 8), photons), s, fixed, T_INT_S, rng)
    per_row = int(np.rint(s.conversion_gain_dn_per_e * s.quantum_efficiency * photons))
    assert np.all(v == per_row + s.black_offset_dn)
    stages = list(range(1, 101))
    out = run_dtdi(v, stages, beta, s.black_offset_dn)
    m_clip = top // per_row + 1  # first stage whose sum exceeds 4095
    for m in stages:
        expected = top if m * per_row > top else m * per_row
        assert np.all(out[m] == expected), m
    assert np.all(out[m_clip - 1] < top) and np.all(out[m_clip] == top)
    # pixel saturation (full well) inside a stage: stage 10 of saturated pixels is 10 x 972 DN
    v_sat = expose(np.full((20, 100, 8), 1e6), s, fixed, T_INT_S, rng)
    px_sat = int(np.rint(s.full_well_e * s.conversion_gain_dn_per_e))
    out16 = run_dtdi(v_sat, [1, 10], 16, s.black_offset_dn)
    assert np.all(out16[1] == px_sat) and np.all(out16[10] == 10 * px_sat)
    out12 = run_dtdi(v_sat, [1, 10], 12, s.black_offset_dn)
    assert np.all(out12[10] == top)


def test_black_offset_accumulates_without_subtraction_and_pedestal() -> None:
    v = np.full((10, 5, 2), 20, dtype=np.uint16)  # pure black level
    sub = run_dtdi(v, [1, 5], 16, 20.0, subtract_black=True)
    keep = run_dtdi(v, [1, 5], 16, 20.0, subtract_black=False)
    ped = run_dtdi(v, [1, 5], 16, 20.0, pedestal_dn={1: 3, 5: 7})
    assert np.all(sub[5] == 0) and np.all(keep[5] == 100) and np.all(keep[1] == 20)
    assert np.all(ped[1] == 3) and np.all(ped[5] == 7)
    # below-zero sums are stored as 0 (the output word is unsigned)
    low = run_dtdi(np.full((10, 5, 2), 18, dtype=np.uint16), [5], 16, 20.0)
    assert np.all(low[5] == 0)


# -------------------------------------------- must show 3: sqrt(m) growth of noise and SNR


def _temporal_var_over_lines(img: np.ndarray) -> tuple[float, int]:
    """Temporal variance of a stage image: variance over lines per column (every line of a
    column sums the same pixels, so the fixed pattern is constant down a column), averaged."""
    x = img.astype(np.float64)
    return float(np.mean(x.var(axis=0, ddof=1))), x.shape[1] * (x.shape[0] - 1)


def test_dark_noise_of_stage_m_grows_as_sqrt_m() -> None:
    """Digital TDI reads every row: stage m's dark temporal variance is m times one pixel's
    (z-test on each variance with sd sqrt(2 / dof); then the std ratio is sqrt(m))."""
    s = SensorConfig(rows=36, columns=256)  # all noise sources on
    stages = [1, 4, 9, 16, 36]
    rng = np.random.default_rng(17)
    out = sensor_dtdi_pass(
        np.zeros((400 + 35, 36, 256)), s, DTDIConfig(beta_bits=16), T_INT_S, stages, rng,
        lines=400, pedestal_dn=500,
    )
    _, var_px = pixel_mean_var_dn(0.0, s, T_INT_S)
    std_1 = None
    for m in stages:
        assert out[m].min() > 0  # the pedestal keeps the dark signal unclipped
        var_m, dof = _temporal_var_over_lines(out[m])
        z = (var_m / (m * var_px) - 1) / np.sqrt(2 / dof)
        assert abs(z) < 4, (m, var_m, m * var_px)
        std_1 = std_1 or np.sqrt(var_m)
        assert np.sqrt(var_m) / std_1 == pytest.approx(np.sqrt(m), rel=0.03)
    # it is a property of the digital sum: charge-domain TDI would read once (no growth)
    assert _temporal_var_over_lines(out[36])[0] > 30 * _temporal_var_over_lines(out[1])[0]


def test_shot_limited_snr_grows_as_sqrt_m() -> None:
    """Only photon shot noise (plus PRNU, which is fixed): SNR_m = sqrt(m) SNR_1, with
    SNR_1 = sqrt(QE * photons) (Poisson)."""
    s = SensorConfig(
        rows=25, columns=256, read_noise=False, dark_noise=False, quantization=False,
        column_fpn=False,
    )
    photons = 2000.0
    stages = [1, 4, 25]
    rng = np.random.default_rng(23)
    dtdi = DTDIConfig(beta_bits=20)
    out = sensor_dtdi_pass(
        np.full((300 + 24, 25, 256), photons), s, dtdi, T_INT_S, stages, rng, lines=300
    )
    snr_1_model = np.sqrt(s.quantum_efficiency * photons)
    for m in stages:
        img = out[m].astype(np.float64) - dtdi.pedestal_dn  # the word keeps the pedestal
        var_m, dof = _temporal_var_over_lines(img)
        snr = img.mean() / np.sqrt(var_m)
        # sd of an SNR estimate from a variance with dof degrees of freedom: SNR / sqrt(2 dof)
        assert abs(snr / (np.sqrt(m) * snr_1_model) - 1) < 4 / np.sqrt(2 * dof) + 0.005, (m, snr)


# --------------------------------------------------------------- must show 7: memory


def _peak_bytes(n_lines: int) -> int:
    rows, cols, stages = 20, 64, [1, 5, 20]
    acc = DTDIAccumulator(cols, stages, 16, 20.0)
    rng = np.random.default_rng(0)
    frame = rng.integers(0, 1024, size=(rows, cols)).astype(np.uint16)
    gc.collect()
    tracemalloc.start()
    tracemalloc.reset_peak()
    n_out = 0
    for k in range(n_lines + stages[-1] - 1):
        frame[k % rows, k % cols] ^= 1  # a changing stream, frames not kept
        for line in acc.push(frame).values():
            n_out += line.size  # consume and drop
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert acc.lines_emitted(20) == n_lines
    assert n_out == cols * sum(acc.lines_emitted(m) for m in stages)
    return peak


@pytest.mark.slow
def test_accumulator_memory_does_not_grow_with_lines() -> None:
    peak_1k = _peak_bytes(1_000)
    peak_10k = _peak_bytes(10_000)
    # 10x the lines: the peak stays the same (a few kB of slack), far below 10x
    assert peak_10k < peak_1k * 1.1 + 4096, (peak_1k, peak_10k)
