"""The two-stage rules by name (``fuse --method``): eq. 11 and the clip-aware rule on synthetic
stage words with a known truth."""

from __future__ import annotations

import numpy as np
import pytest

from bench_sim.errors import BenchSimError
from bench_sim.fusion import FUSE_METHODS, check_fuse_method, fuse_pair

pytestmark = pytest.mark.physics

MU1, MU2, BETA = 10, 80, 12
TOP = 2**BETA - 1


def _words(per_row: np.ndarray, pedestal: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Noise-free stage words of one DTDI pass: ``per_row`` (80, N) is the signal [DN] each of the
    80 rows adds to one pixel; stage m sums rows 0..m-1 (paper eq. 1-2), plus the pedestal,
    rounded and clipped to the word. Returns (Gamma1, Gamma2, truth of stage 80 [DN])."""
    truth = per_row.sum(axis=0)
    g1 = np.minimum(np.round(per_row[:MU1].sum(axis=0) + pedestal), TOP)
    g2 = np.minimum(np.round(truth + pedestal), TOP)
    return g1, g2, truth


@pytest.mark.parametrize("pedestal", [0.0, 64.0])
def test_clip_rule_never_takes_a_clipped_stage_eq11_does(pedestal: float) -> None:
    # the light per row doubles after row 10 (it changes along the TDI window): stage 80 collects
    # 15x stage 10, not 8x, so eq. 11 keeps a clipped Gamma2 where Gamma1 is below its threshold
    a = np.linspace(0.1, 100.0, 1000)  # signal per row over rows 0..9 [DN]
    per_row = np.concatenate([np.tile(a, (MU1, 1)), np.tile(2 * a, (MU2 - MU1, 1))])
    g1, g2, truth = _words(per_row, pedestal)
    eq11 = fuse_pair(g1, g2, method="eq11", mu1=MU1, mu2=MU2, beta=BETA, pedestal_dn=pedestal)
    clip = fuse_pair(g1, g2, method="clip", mu1=MU1, mu2=MU2, beta=BETA, pedestal_dn=pedestal)
    clipped2 = g2 >= TOP
    assert not np.any(clip.source[clipped2] == MU2)  # never a clipped stage
    np.testing.assert_array_equal(clip.source, np.where(clipped2, MU1, MU2))
    np.testing.assert_array_equal(clip.hdr, np.where(clipped2, (g1 - pedestal) * 8, g2 - pedestal))
    # eq. 11, closed form: Gamma2 - P wherever Gamma1 - P <= (4096 - P) / 8, else 8 (Gamma1 - P)
    below = (g1 - pedestal) <= (TOP + 1 - pedestal) * MU1 / MU2
    np.testing.assert_array_equal(eq11.hdr, np.where(below, g2 - pedestal, 8 * (g1 - pedestal)))
    from_clipped = below & clipped2
    assert from_clipped.sum() > 100  # the band of the issue: eq. 11 keeps clipped Gamma2 there
    # against the truth: eq. 11 there is the clip value, up to 47 % too low (4095 of 7680 DN)
    np.testing.assert_array_equal(eq11.hdr[from_clipped], TOP - pedestal)
    assert np.all(eq11.hdr[from_clipped] <= truth[from_clipped] + 0.5)  # 0.5: the word's rounding
    assert (eq11.hdr[from_clipped] / truth[from_clipped]).min() < 0.55
    # the clip rule rescales Gamma1 there, which misses the same light ratio: 8 x 10 a of 150 a
    np.testing.assert_allclose(clip.hdr[from_clipped], truth[from_clipped] * 80 / 150, atol=8 * 0.5)
    assert clip.full_scale_dn == eq11.full_scale_dn == 8 * (TOP - pedestal)


def test_both_rules_equal_the_truth_under_uniform_light() -> None:
    # light uniform along the TDI window: Gamma2 = 8 Gamma1 (before rounding), both rules exact
    # to the rounding of Gamma1 (8 x 0.5 DN) up to Gamma1's own clip
    a = np.linspace(0.0, 409.0, 3000)
    g1, g2, truth = _words(np.tile(a, (MU2, 1)), 0.0)
    for method in FUSE_METHODS:
        r = fuse_pair(g1, g2, method=method, mu1=MU1, mu2=MU2, beta=BETA)
        err = np.abs(r.hdr - truth)
        # eq. 11 at its threshold: Gamma2 = 4096 is clipped to 4095 (1 DN, the paper's step)
        assert err.max() <= 8 * 0.5 + (1.0 if method == "eq11" else 0.0), (method, err.max())


def test_unknown_method_is_one_line() -> None:
    with pytest.raises(BenchSimError, match=r"^--method = 'median': allowed eq11, clip$"):
        check_fuse_method("median")
    assert list(FUSE_METHODS)[0] == "eq11"  # the default is the paper's rule
