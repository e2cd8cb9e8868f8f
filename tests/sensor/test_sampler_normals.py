"""The standard normals of the joint shot + read draw (Box-Muller, ``box_muller_normals``) and
the in-cache exposure loop that uses them.

Seeded statistical tests: chi-squared goodness of fit to N(0, 1) in equiprobable bins (each half
of the output, the cosines and the sines, and the whole), the tail mass beyond 4 sigma, the
independence of the cosine and sine of one pair, and exact equality of the in-cache loop of
:func:`bench_sim.sensor.emva.expose` with its general loop.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from bench_sim.config import SensorConfig
from bench_sim.sensor.emva import ExposurePlan, draw_fixed_pattern, expose
from bench_sim.sensor.sampler import box_muller_normals

pytestmark = pytest.mark.physics

N = 2_000_000


def _normals(seed: int, n: int = N) -> np.ndarray:
    return box_muller_normals(np.random.default_rng(seed), np.empty(n, dtype=np.float32))


def _chi2_normal_p(x: np.ndarray, bins: int = 200) -> float:
    """Chi-squared p-value of ``x`` against N(0, 1) in ``bins`` equiprobable bins."""
    edges = stats.norm.ppf(np.linspace(0.0, 1.0, bins + 1)[1:-1])
    counts = np.bincount(np.searchsorted(edges, x.astype(np.float64)), minlength=bins)
    return float(stats.chisquare(counts).pvalue)


def test_box_muller_normals_follow_the_standard_normal():
    z = _normals(11)
    h = z.size // 2
    for part in (z, z[:h], z[h:]):  # all, the cosines, the sines
        assert _chi2_normal_p(part) > 1e-3
    n = z.size
    assert abs(z.mean()) < 5 / np.sqrt(n)
    assert abs(z.var() - 1.0) < 5 * np.sqrt(2 / n)
    assert abs(stats.skew(z)) < 5 * np.sqrt(6 / n)
    assert abs(stats.kurtosis(z)) < 5 * np.sqrt(24 / n)


def test_box_muller_tail_mass_and_pair_independence():
    z = _normals(12, 4 * N)
    p4 = 2 * stats.norm.sf(4.0)  # 6.3e-5
    n_tail = int((np.abs(z) > 4.0).sum())
    assert abs(n_tail - p4 * z.size) < 5 * np.sqrt(p4 * z.size)
    h = z.size // 2
    c, s = z[:h].astype(np.float64), z[h:].astype(np.float64)
    assert abs(np.mean(c * s)) < 5 / np.sqrt(h)  # uncorrelated
    assert abs(np.mean(c * c * s * s) - 1.0) < 5 * np.sqrt(8 / h)  # E[c^2 s^2] = 1: independent
    assert np.abs(z).max() <= np.sqrt(64 * np.log(2.0)) + 1e-4  # the radius's bound


def test_box_muller_shapes_odd_sizes_and_seeds():
    a = box_muller_normals(np.random.default_rng(3), np.empty((3, 5, 7), dtype=np.float32))
    b = box_muller_normals(np.random.default_rng(3), np.empty(105, dtype=np.float32))
    assert a.shape == (3, 5, 7) and np.array_equal(a.ravel(), b)
    assert np.isfinite(a).all()
    c = box_muller_normals(np.random.default_rng(4), np.empty(105, dtype=np.float32))
    assert not np.array_equal(b, c)
    assert box_muller_normals(np.random.default_rng(3), np.empty(0, dtype=np.float32)).size == 0


@pytest.mark.parametrize("top, frames, rows, cols", [(3000.0, 5, 30, 64), (40000.0, 3, 100, 1400)])
def test_in_cache_loop_equals_the_general_loop(monkeypatch, top, frames, rows, cols):
    """Default switches (the in-cache loop): the same DN and saturation flags as the general
    loop, bit for bit, including reads near and at the full well and several slabs per block."""
    sensor = SensorConfig(rows=rows, columns=cols, adc_bits=16, conversion_gain_dn_per_e=0.5)
    fixed = draw_fixed_pattern(sensor, np.random.default_rng(0))
    ph = np.random.default_rng(1).uniform(0.0, top, size=(frames, rows, cols)).astype(np.float32)
    ph[:, ::5] *= 0.001  # means below the exact-Poisson switch
    assert ExposurePlan.of(sensor, fixed, 1e-4).in_cache
    out = {}
    for in_cache in (True, False):
        monkeypatch.setattr(ExposurePlan, "in_cache", property(lambda self, v=in_cache: v))
        sat = np.empty(ph.shape, dtype=bool)
        dn = expose(ph, sensor, fixed, 1e-4, np.random.default_rng(2), saturated=sat)
        out[in_cache] = (dn, sat)
    assert np.array_equal(out[True][0], out[False][0])
    assert np.array_equal(out[True][1], out[False][1])
    if top > 20000:
        assert out[True][1].any()  # the full well was reached
