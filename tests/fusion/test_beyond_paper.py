"""Beyond the paper: inverse-variance merge, OpenCV's classic merges, Gamma_TRA transforms."""

from __future__ import annotations

import numpy as np
import pytest

from bench_sim.config import ConfigError
from bench_sim.errors import BenchSimError
from bench_sim.fusion import (
    TONEMAP_METHODS,
    fuse_stages_highest_unsaturated,
    fuse_stages_inverse_variance,
    gamma_tra,
    merge_debevec_opencv,
    merge_mertens_opencv,
    tone_map,
)
from bench_sim.fusion.tonemap import check_tonemap_method, tra_histeq

#: closed forms, invariants and seeded statistical tests (make test-fast)
pytestmark = pytest.mark.physics

K = 0.072  # DN/e-
SIGMA_D = 13.0  # e-


def test_inverse_variance_closed_form_and_saturation() -> None:
    # equal per-read noise -> weights ~ m: hdr = m_K * sum(gamma_k) / sum(m_k) over unsaturated
    g = {10: np.array([100.0, 500.0, 4095.0]), 80: np.array([790.0, 4095.0, 4095.0])}
    r = fuse_stages_inverse_variance(g, beta=12, conversion_gain_dn_per_e=K, dark_noise_e=SIGMA_D)
    assert r.hdr[0] == pytest.approx(80 * (100 + 790) / 90)
    assert r.hdr[1] == pytest.approx(8 * 500)  # stage 80 saturated: excluded
    assert r.hdr[2] == pytest.approx(8 * 4095) and r.saturated[2]  # both saturated
    np.testing.assert_array_equal(r.source, [80, 10, 10])
    assert r.variance is not None and np.all(r.variance > 0)


def test_inverse_variance_beats_single_stage_on_independent_images() -> None:
    # independent stage images of one uniform scene: 200 e- per read
    rng = np.random.default_rng(11)
    mu_e, shape = 200.0, (200, 200)
    stages = {}
    for m in (10, 20, 40):
        e = rng.poisson(mu_e, (m, *shape)) + SIGMA_D * rng.standard_normal((m, *shape))
        stages[m] = np.round(K * e).sum(axis=0)
    ivm = fuse_stages_inverse_variance(stages, beta=16, conversion_gain_dn_per_e=K, dark_noise_e=SIGMA_D)
    top = fuse_stages_highest_unsaturated(stages, beta=16, criterion="clip")
    var_ivm, var_top = ivm.hdr.var(), top.hdr.var()
    # optimum for weights ~ m: var = m_K^2 v / sum(m) = 40^2 v / 70 vs 40 v for stage 40 alone
    assert var_ivm < 0.7 * var_top
    assert var_ivm == pytest.approx(var_top * 40 / 70, rel=0.1)
    assert float(np.median(ivm.variance)) == pytest.approx(var_ivm, rel=0.15)


def test_debevec_recovers_linear_radiance() -> None:
    # noise-free linear stages: value = m * s, clipped at 4095; radiance in stage-80 DN = 80 s
    s = np.linspace(0.5, 400.0, 64).reshape(8, 8)
    stages = {m: np.minimum(np.round(m * s), 4095) for m in (10, 80)}
    rad = merge_debevec_opencv(stages, beta=12)
    np.testing.assert_allclose(rad, 80 * s, rtol=0.02, atol=2.0)


def test_mertens_is_display_referred_and_ordered() -> None:
    s = np.linspace(0.5, 400.0, 64).reshape(8, 8)
    stages = {m: np.minimum(np.round(m * s), 4095) for m in (10, 80)}
    out = merge_mertens_opencv(stages, beta=12)
    assert out.shape == s.shape and out.min() >= 0 and out.max() <= 1
    assert out[-1, -1] > out[0, 0]


def test_tra_formulas() -> None:
    x = np.array([[0.0, 1.0, 7.0, 63.0]])
    np.testing.assert_allclose(tone_map(x, "log", full_scale_dn=63.0), np.log1p(x) / np.log(64.0))
    np.testing.assert_allclose(
        tone_map(x, "gamma", full_scale_dn=63.0, gamma=2.0), np.sqrt(x / 63.0)
    )
    # histeq on exact values: C = [1, 2, 3, 4], C_min = 1 -> (C - 1) / 3
    np.testing.assert_allclose(tra_histeq(np.array([5.0, 1.0, 9.0, 3.0])), [2 / 3, 0, 1, 1 / 3])
    np.testing.assert_array_equal(tra_histeq(np.full((2, 2), 7.0)), np.zeros((2, 2)))
    # round(255 * ln(1 + x) / ln 64) for x = 0, 2, 10, 63: 0, 67.36, 147.03, 255
    np.testing.assert_array_equal(
        gamma_tra(np.array([[0.0, 2.0, 10.0, 63.0]]), "log", full_scale_dn=63.0), [[0, 67, 147, 255]]
    )
    assert gamma_tra(x, "log", bits=16).dtype == np.uint16
    with pytest.raises(BenchSimError, match="tra"):
        tone_map(x, "sepia")


def test_tra_name_check_is_one_config_line() -> None:
    check_tonemap_method("log")
    with pytest.raises(ConfigError, match=r"^config error: fusion.tra = 'sepia': must be one of log, gamma,"):
        check_tonemap_method("sepia")


@pytest.mark.parametrize("method", TONEMAP_METHODS)
def test_every_tra_method_gives_a_monotone_8_bit_image(method: str) -> None:
    # a smooth ramp over 4.5 decades: every display transform must keep the order (on average)
    ramp = np.geomspace(1.0, 32760.0, 96 * 64).reshape(96, 64)
    y = gamma_tra(ramp, method, full_scale_dn=32760.0)
    assert y.dtype == np.uint8 and y.shape == ramp.shape
    assert int(y.max()) - int(y.min()) > 100
    rows = y.astype(float).mean(axis=1)
    if method in ("log", "gamma", "histeq", "drago", "reinhard"):
        assert np.all(np.diff(y.ravel().astype(int)) >= 0)
    else:  # Mantiuk works on local contrast: monotone on average along the ramp
        assert np.corrcoef(rows, np.arange(rows.size))[0, 1] > 0.9
