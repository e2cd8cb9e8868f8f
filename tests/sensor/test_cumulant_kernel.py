"""The truth's compiled per-read loops equal numpy's evaluation of the same formulas, bit for bit."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from bench_sim.sensor.cumulant_kernel import light_quantities, linear_cumulants
from bench_sim.sensor.model import QUANTIZATION_VAR_DN2

SIGMAS = 6.0


def numpy_light(ph, gain, qe_gain, dark, add_dark):
    """``p g`` and ``p (QE g)`` (``+ d``) as numpy evaluates them into float64 buffers."""
    rows = gain.shape[0]
    p = ph[:, :rows]
    gp, light = np.empty(p.shape), np.empty(p.shape)
    np.multiply(p, gain, out=gp)
    np.multiply(p, qe_gain, out=light)
    if add_dark:
        np.add(light, np.broadcast_to(dark, p.shape), out=light)
    return gp, light


def numpy_linear(lam, det, off, lo, top, k, rn, noisy, quantization):
    """The linear cumulants, ``near`` and ``c sd`` as whole-array numpy passes, in the loop's order."""
    k1, k2, k3, sd, edge = (np.empty(lam.shape) for _ in range(5))
    np.add(lam, det, out=k1)
    np.multiply(k, k1, out=k1)
    np.add(k1, off, out=k1)
    if noisy:
        np.add(lam, rn**2, out=k2)
        np.multiply(k**3, lam, out=k3)
    else:
        k2[...] = rn**2
        k3[...] = 0.0
    np.multiply(k * k, k2, out=k2)
    np.sqrt(k2, out=sd)
    if quantization:
        np.add(k2, QUANTIZATION_VAR_DN2, out=k2)
    np.multiply(SIGMAS, sd, out=sd)
    np.add(k1, sd, out=edge)
    np.add(edge, 1.0, out=edge)
    near = edge >= top
    np.subtract(k1, sd, out=edge)
    np.subtract(edge, 1.0, out=edge)
    return k1, k2, k3, near | (edge <= lo), sd


def _bits(a: np.ndarray) -> np.ndarray:
    return a.view(np.int64 if a.dtype == np.float64 else np.int32)


def _magnitudes(rng: np.random.Generator, shape, lo: int, hi: int) -> np.ndarray:
    """Positive values over many decades: a fused multiply-add would change some roundings."""
    return rng.random(shape) * 10.0 ** rng.integers(lo, hi, shape)


def _awkward(values: np.ndarray, specials: list[float]) -> np.ndarray:
    flat = values.reshape(-1)
    flat[: min(len(specials), flat.size)] = specials[: flat.size]
    return values


@pytest.mark.parametrize("add_dark", [True, False])
@pytest.mark.parametrize(
    ("frames", "rows", "extra", "cols", "seed"), [(1, 1, 0, 1, 0), (5, 8, 3, 33, 1), (16, 80, 0, 256, 2)]
)
def test_light_loop_equals_numpy_bit_for_bit(frames, rows, extra, cols, seed, add_dark):
    rng = np.random.default_rng(seed)
    specials = [0.0, -0.0, 1e-45, 3.4e38, 0.5, 1.0, 65504.0, 1e-38, 16777217.0]
    ph = _awkward(_magnitudes(rng, (frames, rows + extra, cols), -6, 7).astype(np.float32), specials)
    gain = _awkward(1.0 + 0.01 * rng.standard_normal((rows, cols)), [0.0, 1.0, 1e300, 1e-300])
    qe_gain = 0.6 * gain
    dark = _awkward(_magnitudes(rng, (rows, cols), -3, 4), [0.0, -0.0, 1e308])
    gp, light = np.full((2, frames, rows, cols), np.nan)
    light_quantities(ph, gain, qe_gain, dark, gp, light, add_dark=add_dark)
    want_gp, want_light = numpy_light(ph, gain, qe_gain, dark, add_dark)
    assert np.array_equal(_bits(gp), _bits(want_gp)) and np.array_equal(_bits(light), _bits(want_light))


def _operands(rng: np.random.Generator, shape: tuple[int, ...], how: str) -> list[np.ndarray]:
    """det, off, lo, top broadcastable to ``shape``: scalars, per column, per pixel (the trailing
    axes), per read, or broadcast over a middle axis (a copy)."""
    n = shape[-1] if shape else 1
    part = {"scalar": (), "column": (n,), "pixel": shape[1:], "read": shape,
            "middle": (*shape[:1], 1, *shape[2:])}[how]
    det = _magnitudes(rng, part, -2, 4)
    off = rng.normal(8.0, 3.0, part)
    lo = rng.choice([0.0, -0.0, 5.0], part)
    top = rng.choice([1023.0, 4095.0, 60.0], part)
    return [np.asarray(a, dtype=np.float64) for a in (det, off, lo, top)]


@pytest.mark.parametrize("flags", [(True, True), (True, False), (False, True), (False, False)])
@pytest.mark.parametrize(
    ("shape", "how", "seed"),
    [((), "scalar", 0), ((1,), "scalar", 1), ((7,), "column", 2), ((3, 5), "pixel", 3),
     ((4, 6, 33), "pixel", 4), ((4, 6, 33), "column", 5), ((2, 3, 9), "read", 6), ((3, 4, 5), "middle", 7),
     ((16, 80, 128), "pixel", 8)],
)
def test_linear_loop_equals_numpy_bit_for_bit(shape, how, seed, flags):
    noisy, quantization = flags
    rng = np.random.default_rng(seed)
    k, rn = 0.0712345, (6.3 if seed % 2 else 0.0)
    specials = [0.0, -0.0, 1e-300, 1e300, np.inf, 13500.0, 0.5, 2.0**53, -0.0]
    lam = _awkward(_magnitudes(rng, shape or (1,), -4, 6), specials).reshape(shape)
    det, off, lo, top = _operands(rng, shape, how)
    with np.errstate(all="ignore"):
        want = numpy_linear(lam, det, off, lo, top, k, rn, noisy, quantization)
        if how == "read":  # reads exactly at a clip's edge: the comparisons' equality cases
            k1, sd = want[0].reshape(-1), want[4].reshape(-1)
            top.reshape(-1)[:2] = ((k1 + sd) + 1.0)[:2]
            lo.reshape(-1)[2:4] = ((k1 - sd) - 1.0)[2:4]
            want = numpy_linear(lam, det, off, lo, top, k, rn, noisy, quantization)
            assert want[3].reshape(-1)[:4].all()
    got = [np.full(lam.shape, np.nan) for _ in range(3)]
    near = np.zeros(lam.shape, dtype=bool)
    linear_cumulants(
        lam, det, off, lo, top, (got[0], got[1], got[2]), near, gain_dn_per_e=k, read_noise_e=rn, noisy=noisy,
        quantization_var_dn2=QUANTIZATION_VAR_DN2 if quantization else None, clip_sigmas=SIGMAS,
    )
    for g, w in zip(got, want[:3], strict=True):
        assert np.array_equal(_bits(g), _bits(w))
    assert np.array_equal(near, want[3])


def test_read_only_inputs_and_checks():
    """The fixed pattern and broadcast views are read-only: the loops take them as they are;
    wrong shapes, layouts and dtypes are refused before the loop runs."""
    gain = np.ones((2, 3))
    gain.flags.writeable = False
    ph = np.ones((4, 2, 3), dtype=np.float32)
    ph.flags.writeable = False
    gp, light = np.empty((2, 4, 2, 3))
    light_quantities(ph, gain, gain, gain, gp, light, add_dark=True)
    assert np.array_equal(light, np.full((4, 2, 3), 2.0))
    with pytest.raises(TypeError):
        light_quantities(ph.astype(np.float64), gain, gain, gain, gp, light, add_dark=True)
    with pytest.raises(ValueError):
        light_quantities(ph[:, :1], gain, gain, gain, gp, light, add_dark=True)
    lam = np.broadcast_to(np.arange(3.0), (4, 3))
    out = (np.empty((4, 3)), np.empty((4, 3)), np.empty((4, 3)))
    read: dict[str, Any] = {
        "gain_dn_per_e": 1.0, "read_noise_e": 1.0, "noisy": True, "quantization_var_dn2": None
    }
    with pytest.raises(ValueError):
        linear_cumulants(lam, 0.0, 0.0, 0.0, 9.0, out, np.empty((4, 3), bool), clip_sigmas=6.0, **read)
    near = np.empty((4, 3), bool)
    linear_cumulants(np.ascontiguousarray(lam), 0.0, 0.0, 0.0, 9.0, out, near, clip_sigmas=6.0, **read)
    assert np.array_equal(out[0], lam)
