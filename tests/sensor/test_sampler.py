"""Shot-noise samplers (``sensor.shot_noise_sampler``) and the thread-independent sensor pass.

The quantised output of the pixel model is compared, by a chi-squared test, with its exact
distribution: ``DN = clip(rint(K (min(n, FW) + sigma_r z) + b))`` with ``n ~ Poisson(lam)``,
summed over ``n`` in closed form. Both samplers must pass at means below, at and above the
hybrid sampler's switch-overs (exact Poisson / normal approximation at 30 e-, shot and read noise
drawn apart near the full well).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from bench_sim.config import SensorConfig
from bench_sim.sensor.emva import (
    COMBINED_READ_NOISE_MIN_E,
    FULL_WELL_SIGMAS,
    SHOT_NOISE_SWITCH_E,
    draw_fixed_pattern,
    expose,
)
from tests.conftest import ALL_OFF, tiny_cfg

#: closed forms, invariants and seeded statistical tests (make test-fast)
pytestmark = pytest.mark.physics

T_INT_S = 100e-6


def _dn_pmf(lam: float, s: SensorConfig) -> tuple[np.ndarray, np.ndarray]:
    """Exact P(DN = d) of one read: Poisson electrons, full-well clip, normal read noise, gain,
    black offset, rounding and the ADC range. Returns (d values, probabilities)."""
    sd = np.sqrt(lam)
    n = np.arange(max(0, int(lam - 10 * sd - 10)), int(lam + 10 * sd + 10) + 1)
    p_n = stats.poisson.pmf(n, lam)
    e = np.minimum(n, s.full_well_e).astype(float)
    k, b, sigma = s.conversion_gain_dn_per_e, s.black_offset_dn, s.read_noise_e
    top = 2**s.adc_bits - 1
    lo = int(np.floor(k * (e.min() - 10 * sigma) + b)) - 1
    hi = int(np.ceil(k * (e.max() + 10 * sigma) + b)) + 1
    d = np.arange(max(lo, 0), min(hi, top) + 1)
    # P(rint(k (e + sigma z) + b) = d) for every (n, d): the read noise between the DN edges
    edges = (np.append(d - 0.5, d[-1] + 0.5) - b) / k
    cdf = stats.norm.cdf((edges[None, :] - e[:, None]) / sigma)
    cdf[:, 0] = np.where(d[0] == 0, 0.0, cdf[:, 0])  # the ADC clips at 0 and top
    cdf[:, -1] = np.where(d[-1] == top, 1.0, cdf[:, -1])
    return d, p_n @ np.diff(cdf, axis=1)


def _chi2_p(x: np.ndarray, d: np.ndarray, p: np.ndarray) -> float:
    """Chi-squared goodness of fit of the integer sample ``x`` to P(d); bins of fewer than 5
    expected counts are pooled with their neighbours."""
    counts = np.bincount((x.astype(np.int64) - d[0]).clip(0, d.size - 1), minlength=d.size).astype(float)
    expected = p / p.sum() * x.size
    obs, exp, o_acc, e_acc = [], [], 0.0, 0.0
    for o, e in zip(counts, expected, strict=True):
        o_acc, e_acc = o_acc + o, e_acc + e
        if e_acc >= 5:
            obs.append(o_acc)
            exp.append(e_acc)
            o_acc = e_acc = 0.0
    obs[-1] += o_acc
    exp[-1] += e_acc
    return float(stats.chisquare(obs, exp).pvalue)


def _sensor(sampler: str, **kw) -> SensorConfig:
    base = {**ALL_OFF, "shot_noise": True, "read_noise": True, "quantization": True}
    return SensorConfig(rows=16, columns=256, shot_noise_sampler=sampler, quantum_efficiency=1.0,
                        dark_current_e_s=0.0, **{**base, **kw})


#: an electron-resolving sensor (1 DN/e-, 0.6 e- read noise): the shot noise's shape shows
RESOLVING = dict(conversion_gain_dn_per_e=1.0, read_noise_e=0.6, black_offset_dn=10.0, adc_bits=16,
                 full_well_e=1e6)
#: the default pixel (13 e- read noise, 0.072 DN/e-, 13.5 ke- full well, 10-bit ADC)
DEFAULT = dict(conversion_gain_dn_per_e=0.072, read_noise_e=13.0, black_offset_dn=20.0, adc_bits=10,
               full_well_e=13500.0)


def _near_full_well(fw: float) -> float:
    k = FULL_WELL_SIGMAS
    return ((-k + np.sqrt(k * k + 4 * fw)) / 2) ** 2


CASES = [
    ("resolving", RESOLVING, 2.5),
    ("resolving", RESOLVING, SHOT_NOISE_SWITCH_E - 0.5),  # exact Poisson just below the switch
    ("resolving", RESOLVING, SHOT_NOISE_SWITCH_E + 0.5),  # the normal approximation just above
    ("resolving", RESOLVING, 400.0),
    ("default", DEFAULT, 6.0),  # shot + read noise as one draw
    ("default", DEFAULT, 2500.0),
    ("default", DEFAULT, _near_full_well(13500.0) - 40.0),  # as one draw, just below ...
    ("default", DEFAULT, _near_full_well(13500.0) + 40.0),  # ... apart, just above the switch
    ("default", DEFAULT, 13480.0),  # the full well clips a part of the reads
]


@pytest.mark.parametrize("sampler", ["hybrid", "poisson"])
@pytest.mark.parametrize("name, settings, lam", CASES, ids=[f"{c[0]}-{c[2]:.1f}e" for c in CASES])
def test_quantised_reads_follow_the_exact_distribution(sampler, name, settings, lam):
    s = _sensor(sampler, **settings)
    if name == "default":
        assert s.read_noise_e >= COMBINED_READ_NOISE_MIN_E  # the combined draw is what is tested
    rng = np.random.default_rng(20_000 + int(lam))
    fixed = draw_fixed_pattern(s, rng)
    x = expose(np.full((48, 16, 256), lam), s, fixed, T_INT_S, rng).ravel()
    d, p = _dn_pmf(lam, s)
    assert _chi2_p(x, d, p) > 1e-3


def test_hybrid_sampler_matches_the_poisson_moments_on_electrons():
    """Mean, variance and third central moment of the electron counts (no read noise, 1 DN/e-)
    are the Poisson's ``lam``, ``lam``, ``lam`` just above the switch-over and far above it."""
    for lam in (SHOT_NOISE_SWITCH_E + 1.0, 2000.0):
        s = _sensor("hybrid", **{**RESOLVING, "read_noise": False, "black_offset_dn": 0.0})
        rng = np.random.default_rng(7)
        x = expose(np.full((200, 16, 256), lam), s, draw_fixed_pattern(s, rng), T_INT_S, rng)
        x = x.astype(np.float64).ravel()
        n = x.size
        m3 = np.mean((x - lam) ** 3)
        assert abs(x.mean() - lam) < 4 * np.sqrt(lam / n)
        assert abs(x.var() - lam) < 4 * np.sqrt((lam * (1 + 3 * lam) - lam**2) / n)
        # Var of the third central moment ~ (mu6 - mu3^2) / n, mu6 ~ 15 lam^3 for large lam
        assert abs(m3 - lam) < 4 * np.sqrt(15 * lam**3 / n) + 0.05 * lam


def test_pass_is_the_same_with_one_and_two_threads(monkeypatch):
    """Every chunk of frames draws from its own stream: 1 or 2 threads, same stage words, same
    truth; a SeedSequence seed is the integer seed's stream."""
    from bench_sim.pipeline import run_pass

    cfg = tiny_cfg(lines=40)
    out = {}
    for threads in ("1", "2"):
        monkeypatch.setenv("BENCH_SIM_THREADS", threads)
        out[threads] = run_pass(cfg, [1, 2, 8, 12], 3, truth=True)
    a, b = out["1"], out["2"]
    for m in a.stage_dn:
        assert np.array_equal(a.stage_dn[m], b.stage_dn[m])
    for var in ("mean_dn", "photons", "reflectance", "clipped"):
        assert np.array_equal(a.dataset[var].values, b.dataset[var].values), var
    seq = run_pass(cfg, [1, 2, 8, 12], np.random.SeedSequence(3), truth=False)
    assert all(np.array_equal(seq.stage_dn[m], a.stage_dn[m]) for m in a.stage_dn)
