"""The fast engine's compiled tap loop equals numpy's evaluation of the same taps, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from bench_sim.render.exposures import prepare
from bench_sim.render.frame_kernel import apply_taps
from tests.conftest import tiny_cfg


def numpy_taps(planes: np.ndarray, weights: np.ndarray, y0: int, x0: int, acc: np.ndarray) -> None:
    """The taps as numpy slices, in the order of the compiled loop: ``acc += planes * w`` per tap."""
    q, (nk, n) = planes.shape[0], acc.shape
    tmp = np.empty_like(acc)
    for a in range(weights.shape[0]):
        ya = y0 + a
        for b in range(weights.shape[1]):
            xb = x0 + b
            plane = planes[ya % q, xb % q, ya // q : ya // q + nk, xb // q : xb // q + n]
            np.multiply(plane, weights[a, b], out=tmp)
            acc += tmp


def _bits(a: np.ndarray) -> np.ndarray:
    return a.view(np.int32)


@pytest.mark.parametrize(
    ("q", "frames", "columns", "taps", "seed"),
    [(1, 1, 1, (1, 1), 0), (4, 64, 1024, (5, 6), 1), (3, 7, 33, (4, 2), 2), (2, 16, 100, (7, 9), 3)],
)
def test_compiled_taps_equal_numpy_bit_for_bit(q, frames, columns, taps, seed):
    rng = np.random.default_rng(seed)
    y0, x0 = (int(v) for v in rng.integers(0, 3 * q + 1, size=2))
    rows = -(-(y0 + taps[0]) // q) + frames + int(rng.integers(0, 3))  # padding never read
    cols = -(-(x0 + taps[1]) // q) + columns + int(rng.integers(0, 3))
    # values over many magnitudes: roundings differ at once if a multiply-add were fused
    shape = (q, q, rows, cols)
    planes = (rng.random(shape) * 10.0 ** rng.integers(-3, 4, shape)).astype(np.float32)
    weights = rng.standard_normal((*taps, columns)).astype(np.float32)
    start = rng.standard_normal((frames, columns)).astype(np.float32)
    got, want = start.copy(), start.copy()
    apply_taps(planes, weights, y0, x0, got)
    numpy_taps(planes, weights, y0, x0, want)
    assert np.array_equal(_bits(got), _bits(want))
    assert not np.array_equal(got, start)


@pytest.mark.slow
def test_fast_engine_frames_with_a_flickering_light_equal_numpy_bit_for_bit():
    """A frame is the steady lights' combined kernel plus each flickering light's own kernel
    scaled per frame (:meth:`FastEngine.radiance_frames`), evaluated here with numpy slices."""
    cfg = tiny_cfg(lights={"strong": {"flicker_hz": 1700.0, "flicker_depth": 0.8}})
    first, k0, k1 = 60, 61, 68
    eng = prepare(cfg, 8, np.random.default_rng(0), engine="fast", first_frame=first).engine
    got = eng.radiance_frames(k0, k1)
    coeffs = eng.light_coefficients(k0, k1)
    varying = [li for li in range(coeffs.shape[0]) if np.ptp(coeffs[li]) > 0]
    assert varying, "no light flickers"
    steady = tuple(0.0 if li in varying else float(coeffs[li, 0]) for li in range(coeffs.shape[0]))
    combined, static = eng._combined_kernels(steady)
    w0, planes = eng._window(k0, k1)
    q, a0 = eng.grid.q, eng.grid.a0
    want = np.empty_like(got)
    for i, kern in enumerate(eng.kernels):
        y0 = kern.base_y - a0 + k0 * q - w0
        acc = np.empty((k1 - k0, cfg.sensor.columns), dtype=np.float32)
        acc[...] = static[i]
        for li in varying:
            acc += coeffs[li].astype(np.float32)[:, None] * eng.records.static[li][i]
        numpy_taps(planes, combined[i], y0, kern.base_x, acc)
        for li in varying:
            part = np.zeros_like(acc)
            numpy_taps(planes, kern.weights[li], y0, kern.base_x, part)
            acc += part * coeffs[li].astype(np.float32)[:, None]
        want[:, i] = acc
    assert np.array_equal(_bits(got), _bits(want))
    assert np.ptp(got.mean(axis=(1, 2))) > 0.01 * got.mean()  # the flicker shows in the frames
