"""The exposure loop's compiled per-pixel arithmetic equals numpy's evaluation of the same
operations, bit for bit (the quantile of the joint draw, electrons to DN, and both at once)."""

from __future__ import annotations

import numpy as np
import pytest

from bench_sim.sensor.exposure_kernel import electrons_to_dn, joint_draw_dn, joint_quantile


def numpy_quantile(z, mean, var, lam, read_var):
    """The Cornish-Fisher quantile as whole-array numpy passes in the loop's order (float32)."""
    d = np.float32
    v = np.add(var, d(read_var))
    s = np.sqrt(v)
    a = np.divide(lam, v)
    b = np.divide(a, s)
    c = np.multiply(a, d(5 / 36))
    c -= d(0.125)
    c *= b
    c += s
    t = np.multiply(a, d(-1 / 18))
    t += d(1 / 24)
    t *= b
    a *= d(1 / 6)
    x = np.multiply(t, z)
    x += a
    x *= z
    x += c
    x *= z
    x += np.subtract(mean, a)
    return x


def numpy_dn(e, gain, offset_dn, top, quantization, out, saturated):
    """Electrons -> DN as numpy passes: ``e K + offset``, the saturation flag, rint, clip, cast."""
    e = e * gain
    e += offset_dn
    if saturated is not None:
        saturated |= e >= top - (0.5 if quantization else 0.0)
    if quantization:
        np.rint(e, out=e)
    np.clip(e, 0, top, out=e)
    out[...] = e


def _bits(a: np.ndarray) -> np.ndarray:
    return a.view({4: np.int32, 8: np.int64}[a.itemsize]) if a.dtype.kind == "f" else a


def _magnitudes(rng, shape, lo, hi):
    """Values spread over the decades ``10**lo .. 10**hi`` (and some exact zeros)."""
    x = rng.random(shape) * 10.0 ** rng.integers(lo, hi + 1, shape)
    x[rng.random(shape) < 0.05] = 0.0
    return x


SHAPES = [(1, 1), (1, 7), (3, 33), (100, 1024), (2, 5, 17), (9,)]


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("read_var", [0.0, 40.0, 1e-3])
def test_quantile_equals_numpy_bit_for_bit(shape, read_var):
    rng = np.random.default_rng(len(shape) * 1000 + int(np.prod(shape)))
    lam = _magnitudes(rng, shape, -6, 7).astype(np.float32)
    var = (lam + _magnitudes(rng, shape, -3, 4) + 1e-6).astype(np.float32)  # > 0
    mean = (lam + rng.standard_normal(shape) * 10.0 ** rng.integers(-3, 5, shape)).astype(np.float32)
    z = (rng.standard_normal(shape) * 2.5).astype(np.float32)
    z.flat[:: 7] = 0.0  # the quantile's centre
    z.flat[1 :: 11] = 6.66  # the largest Box-Muller radius
    got = joint_quantile(z, mean, var, lam, np.empty(shape, np.float32), np.float32(read_var))
    want = numpy_quantile(z, mean, var, lam, read_var)
    assert got.dtype == np.float32
    assert np.array_equal(_bits(got), _bits(want))


def test_quantile_reads_broadcast_and_shared_inputs():
    """The mean, variance and cumulants may be one array, and any float32 layout (a broadcast
    fixed pattern is copied); only the result must be C-contiguous."""
    rng = np.random.default_rng(3)
    lam = rng.uniform(0.0, 3000.0, (4, 64)).astype(np.float32)
    z = rng.standard_normal((5, 4, 64)).astype(np.float32)
    wide = np.broadcast_to(lam, z.shape)
    got = joint_quantile(z, wide, wide, wide, np.empty(z.shape, np.float32), np.float32(30.0))
    assert np.array_equal(_bits(got), _bits(numpy_quantile(z, wide, wide, wide, 30.0)))
    with pytest.raises(ValueError, match="C-contiguous"):
        joint_quantile(z, wide, wide, wide, np.empty((64, 4, 5), np.float32).T, np.float32(30.0))


def _electrons(rng, shape, gain, top, dtype):
    """Electrons whose DN fall on everything the conversion must treat alike: rounding ties,
    the saturation threshold, the clip limits, negatives, zeros of both signs, huge values."""
    e = rng.uniform(-50.0, 1.2 * top / gain, shape)
    special = np.array([0.0, -0.0, -1e-30, 1e-30, 1e30, -1e30, 2.0, 6.0, 10.0, (top - 0.5 - 64) / gain,
                        (top - 64) / gain, (top + 1 - 64) / gain, -64 / gain, (0.5 - 64) / gain])
    flat = e.reshape(-1)
    flat[: min(flat.size, special.size)] = special[: flat.size]
    ties = rng.random(flat.size) < 0.2  # DN = k + 1/2 exactly (gain 0.25, offset 64): e = 4 k + 2
    flat[ties] = 4.0 * rng.integers(-20, int(top / gain / 4), int(ties.sum())) + 2.0
    return e.astype(dtype)


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize(("dtype", "quantization"), [(np.float32, True), (np.float64, False)])
@pytest.mark.parametrize("with_sat", [False, True])
def test_electrons_to_dn_equals_numpy_bit_for_bit(shape, dtype, quantization, with_sat):
    rng = np.random.default_rng(int(np.prod(shape)) + 7 * len(shape))
    gain, top = dtype(0.25), 1023.0
    cols = shape[-1]
    offset = (64.0 + rng.standard_normal(cols) * 3.0 * (rng.random(cols) < 0.5)).astype(dtype)
    offset[0] = 64.0
    e = _electrons(rng, shape, float(gain), top, dtype)
    out_dtype = np.uint16 if quantization else np.float64
    start = rng.random(shape) < 0.3  # the mask is or-ed into, never cleared
    got_out, want_out = np.empty(shape, out_dtype), np.empty(shape, out_dtype)
    got_sat, want_sat = (start.copy(), start.copy()) if with_sat else (None, None)
    e_before = e.copy()
    electrons_to_dn(e, gain, offset, top, quantization, got_out, got_sat)
    numpy_dn(e, gain, offset, top, quantization, want_out, want_sat)
    assert np.array_equal(_bits(got_out), _bits(want_out))
    assert np.array_equal(_bits(e), _bits(e_before))
    if with_sat:
        assert np.array_equal(got_sat, want_sat)
        assert e.size < 20 or (got_sat.any() and not got_sat.all())


def test_electrons_to_dn_writes_strided_outputs():
    """A strided ``out`` and mask get the same values as contiguous ones."""
    rng = np.random.default_rng(5)
    e = _electrons(rng, (6, 40), 0.25, 1023.0, np.float32)
    offset = np.full(40, 64.0, np.float32)
    out, sat = np.zeros((6, 80), np.uint16)[:, ::2], np.zeros((12, 40), bool)[::2]
    want_out, want_sat = np.empty((6, 40), np.uint16), np.zeros((6, 40), bool)
    electrons_to_dn(e, np.float32(0.25), offset, 1023.0, True, out, sat)
    numpy_dn(e, np.float32(0.25), offset, 1023.0, True, want_out, want_sat)
    assert np.array_equal(out, want_out) and np.array_equal(sat, want_sat)


@pytest.mark.parametrize("shape", [(1, 1), (3, 33), (100, 1024), (7, 1000)])
@pytest.mark.parametrize("with_sat", [False, True])
def test_joint_draw_dn_equals_quantile_then_dn(shape, with_sat):
    """The fused pass (the in-cache loop's) is the quantile, then electrons to DN, in numpy."""
    rng = np.random.default_rng(int(np.prod(shape)))
    lam = _magnitudes(rng, shape, -3, 4).astype(np.float32)
    lam.flat[:: 5] = rng.uniform(3000.0, 4000.0, lam.flat[:: 5].shape)  # reach the ADC's top
    z = (rng.standard_normal(shape) * 2.0).astype(np.float32)
    gain, read_var, top = np.float32(0.25), np.float32(40.0), 1023.0
    offset = (64.0 + rng.standard_normal(shape[-1])).astype(np.float32)
    got, want = np.empty(shape, np.uint16), np.empty(shape, np.uint16)
    got_sat, want_sat = (np.zeros(shape, bool), np.zeros(shape, bool)) if with_sat else (None, None)
    joint_draw_dn(z, lam, read_var, gain, offset, top, got, got_sat)
    numpy_dn(numpy_quantile(z, lam, lam, lam, read_var), gain, offset, top, True, want, want_sat)
    assert np.array_equal(got, want)
    if with_sat:
        assert np.array_equal(got_sat, want_sat)
    if got.size > 20:  # the values reach both sides of the ADC's top
        assert (got == top).any() and (got < top).any()


def test_electrons_to_dn_keeps_numpys_signed_zeros_and_nan():
    """``np.clip`` passes -0.0 and NaN unchanged; so does the loop (seen in float64 DN)."""
    e = np.array([[-0.0, 0.0, -1e-300, np.nan, -np.inf, np.inf, -3.0, 1e300, 1023.0, 1022.5]])
    offset = np.full(e.shape[-1], -0.0)
    got, want = np.empty(e.shape), np.empty(e.shape)
    electrons_to_dn(e, np.float64(1.0), offset, 1023.0, False, got, None)
    numpy_dn(e, np.float64(1.0), offset, 1023.0, False, want, None)
    assert np.array_equal(_bits(got), _bits(want))
    assert np.signbit(got[0, 0]) and np.isnan(got[0, 3])
