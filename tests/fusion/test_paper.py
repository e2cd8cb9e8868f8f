"""Paper eq. 11 on hand-made arrays (must show 1), and the generalised rules that reduce to it."""

from __future__ import annotations

import numpy as np
import pytest

from bench_sim.errors import BenchSimError
from bench_sim.fusion import (
    eq11_threshold_dn,
    fuse_dtdi_hdr_eq11,
    fuse_stages_highest_unsaturated,
)

#: closed forms, invariants and seeded statistical tests (make test-fast)
pytestmark = pytest.mark.physics


def test_threshold_is_phi_fs_over_stage_ratio() -> None:
    # eq. 4 and eq. 9: Phi_FS / (mu2/mu1) = 4096 / 8
    assert eq11_threshold_dn(10, 80, 12) == 512.0
    assert eq11_threshold_dn(5, 100, 12) == pytest.approx(204.8)
    assert eq11_threshold_dn(10, 80, 16) == 8192.0


def test_eq11_hand_made_12_bit() -> None:
    # mu1 = 10, mu2 = 80, beta = 12: threshold 512 DN on gamma1
    gamma1 = np.array([[0, 100, 511, 512], [513, 600, 4094, 4095]])
    gamma2 = np.array([[3, 800, 4088, 4095], [4095, 4095, 4095, 4095]])
    r = fuse_dtdi_hdr_eq11(gamma1, gamma2, mu1=10, mu2=80, beta=12)
    expected = np.array([[3, 800, 4088, 4095], [8 * 513, 8 * 600, 8 * 4094, 8 * 4095]], dtype=float)
    np.testing.assert_array_equal(r.hdr, expected)
    # exactly at the threshold (gamma1 = 512) eq. 11 keeps gamma2, even though it is clipped
    assert r.hdr[0, 3] == 4095.0 and r.source[0, 3] == 80
    np.testing.assert_array_equal(r.source, [[80, 80, 80, 80], [10, 10, 10, 10]])
    # gamma1 at 2**beta - 1: the HDR reaches (mu2/mu1) * (2**beta - 1) and is flagged saturated
    assert r.hdr.max() == r.full_scale_dn == 8 * 4095
    np.testing.assert_array_equal(r.saturated, [[False] * 4, [False, False, False, True]])
    assert r.unit_stage == 80 and r.hdr.dtype == np.float64 and r.source.dtype == np.int32


def test_eq11_non_integer_ratio_threshold_exact() -> None:
    # mu2/mu1 = 3: threshold 4096/3 = 1365.33; 1365 -> gamma2, 1366 -> 3 * gamma1
    r = fuse_dtdi_hdr_eq11(np.array([1365, 1366]), np.array([4095, 4095]), mu1=10, mu2=30, beta=12)
    np.testing.assert_array_equal(r.hdr, [4095.0, 3 * 1366.0])
    # threshold for beta = 4, mu1 = 1, mu2 = 2: 8; 8 -> gamma2, 9 -> 18 (word max 15 -> 30)
    r = fuse_dtdi_hdr_eq11(np.array([8, 9, 15]), np.array([15, 15, 15]), mu1=1, mu2=2, beta=4)
    np.testing.assert_array_equal(r.hdr, [15.0, 18.0, 30.0])
    assert r.full_scale_dn == 30.0


def test_eq11_pedestal_variant() -> None:
    ped = 100.0
    g1 = np.array([100, 100 + 499, 100 + 500, 4095])
    g2 = np.array([100, 100 + 3992, 4095, 4095])
    r = fuse_dtdi_hdr_eq11(g1, g2, mu1=10, mu2=80, beta=12, pedestal_dn=ped)
    # threshold (4096 - 100) / 8 = 499.5 in signal units
    np.testing.assert_array_equal(r.hdr, [0.0, 3992.0, 4000.0, 8 * 3995.0])
    assert r.full_scale_dn == 8 * 3995
    with pytest.raises(BenchSimError, match="pedestal_dn"):
        fuse_dtdi_hdr_eq11(g1, g2, mu1=10, mu2=80, beta=12, pedestal_dn=5000)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"mu1": 80, "mu2": 10, "beta": 12}, "mu1 < mu2"),
        ({"mu1": 10, "mu2": 10, "beta": 12}, "mu1 < mu2"),
        ({"mu1": 0, "mu2": 10, "beta": 12}, "mu1 = 0"),
        ({"mu1": 10, "mu2": 80, "beta": 0}, "beta = 0"),
        ({"mu1": 10, "mu2": 80, "beta": 33}, "beta = 33"),
    ],
)
def test_eq11_rejects_bad_parameters(kwargs: dict[str, int], match: str) -> None:
    with pytest.raises(BenchSimError, match=match):
        fuse_dtdi_hdr_eq11(np.zeros((2, 2)), np.zeros((2, 2)), **kwargs)


def test_eq11_rejects_shape_mismatch_and_nan() -> None:
    with pytest.raises(BenchSimError, match="shape"):
        fuse_dtdi_hdr_eq11(np.zeros((2, 2)), np.zeros((2, 3)), mu1=10, mu2=80, beta=12)
    with pytest.raises(BenchSimError, match="non-finite"):
        fuse_dtdi_hdr_eq11(np.array([np.nan]), np.array([1.0]), mu1=10, mu2=80, beta=12)


def test_two_stage_generalisation_is_eq11() -> None:
    rng = np.random.default_rng(3)
    g1 = rng.integers(0, 4096, (40, 50))
    g2 = np.minimum(8 * g1 + rng.integers(-30, 30, g1.shape), 4095).clip(0)
    paper = fuse_dtdi_hdr_eq11(g1, g2, mu1=10, mu2=80, beta=12)
    gen = fuse_stages_highest_unsaturated({80: g2, 10: g1}, beta=12)
    np.testing.assert_array_equal(gen.hdr, paper.hdr)
    np.testing.assert_array_equal(gen.source, paper.source)
    assert gen.full_scale_dn == paper.full_scale_dn


def test_three_stages_highest_unsaturated() -> None:
    # stages 10, 40, 80 at beta = 12; per-read signal s -> stage m reads m * s, clipped
    s = np.array([1.0, 20.0, 60.0, 200.0, 409.0])
    stages = {m: np.minimum(np.round(m * s), 4095) for m in (10, 40, 80)}
    pred = fuse_stages_highest_unsaturated(stages, beta=12)
    clip = fuse_stages_highest_unsaturated(stages, beta=12, criterion="clip")
    # s = 1, 20: stage 80 (80, 1600); s = 60: 40 * 60 = 2400 ok, 80 * 60 = 4800 clipped -> stage 40
    # s = 200: only stage 10 (2000) fits; s = 409: stage 10 = 4090
    np.testing.assert_array_equal(pred.source, [80, 80, 40, 10, 10])
    np.testing.assert_array_equal(pred.hdr, 80 * s)
    np.testing.assert_array_equal(clip.source, pred.source)
    np.testing.assert_array_equal(clip.hdr, pred.hdr)
    # a pixel-saturation level below the word (stage 10 tops out at 10 * 972 DN)
    r = fuse_stages_highest_unsaturated(
        {10: np.array([9720.0]), 80: np.array([65535.0])},
        beta=16,
        criterion="clip",
        saturation_dn={10: 9720.0},
    )
    assert r.saturated[0] and r.source[0] == 10 and r.hdr[0] == 8 * 9720
    with pytest.raises(BenchSimError, match="criterion"):
        fuse_stages_highest_unsaturated(stages, beta=12, criterion="nope")  # type: ignore[arg-type]


def test_noise_free_stages_fuse_to_a_linear_response_over_the_whole_range() -> None:
    """Noise-free, consistent stage words (Gamma1 = k for every k in 0..4095, Gamma2 = 8 k
    clipped at 4095): eq. 11 gives 8 k everywhere, i.e. a linear response over the fused range
    0 .. 8 * 4095 DN, except at k = 512 = Phi_FS / 8, where Gamma2 has just clipped to 4095 and
    the threshold (strict ">") still picks it: one DN short. The inputs are left untouched."""
    k = np.arange(4096)
    g1, g2 = k.copy(), np.minimum(8 * k, 4095)
    before = (g1.copy(), g2.copy())
    hdr = fuse_dtdi_hdr_eq11(g1, g2, mu1=10, mu2=80, beta=12).hdr
    off = np.flatnonzero(hdr != 8 * k)
    np.testing.assert_array_equal(off, [512])
    assert hdr[512] == 4095
    np.testing.assert_array_equal(g1, before[0])
    np.testing.assert_array_equal(g2, before[1])
