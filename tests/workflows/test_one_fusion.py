"""One stage-fusion function (issue 34): ``simulate``, ``reproduce``, ``sweep``, ``dataset`` and the
chain's dynamic range fuse the same words into the same image, with the black offset subtracted or
kept in the words (then every stage carries ``m b`` besides the pedestal, and eq. 11's threshold
moves with it)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import bench_sim
from bench_sim.fusion import stage_pair
from bench_sim.measure import chain_dr
from bench_sim.measure.uniform_field import measurement_pedestal_dn
from bench_sim.pipeline import run_pass
from bench_sim.workflows.dataset.run import SampleTask, make_sample
from bench_sim.workflows.reproduce.run import _fuse
from bench_sim.workflows.sweep import point
from bench_sim.workflows.sweep.plan import PointTask
from tests.conftest import tiny_cfg

BLACK_DN, PEDESTAL_DN, MU1, MU2, BETA = 20.0, 64.0, 2, 8, 12


def _eq11(g1: np.ndarray, g2: np.ndarray, subtract_black: bool, pedestal: float = PEDESTAL_DN) -> np.ndarray:
    """Eq. 11 written out: each word less its offset (pedestal, plus ``m b`` when the black offset
    stays in the words), ``Gamma2``'s signal where ``Gamma1``'s is at or below
    ``(2**beta - o2) mu1 / mu2``, else ``Gamma1``'s scaled by ``mu2 / mu1``."""
    o1 = pedestal + (0.0 if subtract_black else MU1 * BLACK_DN)
    o2 = pedestal + (0.0 if subtract_black else MU2 * BLACK_DN)
    s1, s2 = g1.astype(np.float64) - o1, g2.astype(np.float64) - o2
    return np.where(s1 * MU2 > (2**BETA - o2) * MU1, s1 * MU2 / MU1, s2)


class _Stop(Exception):
    pass


def _spy(monkeypatch: pytest.MonkeyPatch, module: Any, seen: list[tuple[Any, ...]]) -> None:
    """Record the words and the image of the module's first call of the one fusion function, then stop."""

    def fuse(cfg, g1, g2, **kw):  # type: ignore[no-untyped-def]
        seen.append((np.array(g1), np.array(g2), stage_pair.fuse_stage_words(cfg, g1, g2, **kw), kw))
        raise _Stop

    monkeypatch.setattr(module, "fuse_stage_words", fuse)


@pytest.mark.slow
@pytest.mark.parametrize("subtract_black", [False, True], ids=["black-kept", "black-subtracted"])
def test_every_workflow_fuses_the_same_words_into_the_same_image(subtract_black, monkeypatch):
    cfg = tiny_cfg(lines=24, dtdi={"subtract_black": subtract_black, "pedestal_dn": int(PEDESTAL_DN)},
                   sensor={"black_offset_dn": BLACK_DN}, lights={"strong": {"irradiance_w_m2": 512.0}})
    seed = np.random.SeedSequence(11)
    sim = run_pass(cfg, (MU1, MU2), np.random.default_rng(seed))
    g1, g2 = sim.stage_dn[MU1], sim.stage_dn[MU2]
    want = _eq11(g1, g2, subtract_black)
    low = want != (g2.astype(np.float64) - (PEDESTAL_DN + (0 if subtract_black else MU2 * BLACK_DN)))
    assert low.any() and (~low).any()  # both branches of eq. 11 in the scene
    # simulate (the pass's gamma_hdr, what simulate writes) and reproduce
    ds = bench_sim.simulate(cfg, stages=[MU1, MU2], seed=11)
    assert np.array_equal(ds.dn.values, np.stack([g1, g2]))
    np.testing.assert_array_equal(ds.gamma_hdr.values, want.astype(np.float32))
    np.testing.assert_array_equal(_fuse(cfg, sim)[0].hdr, want)
    # dataset: a sample of this bench on the same stream
    out = make_sample(SampleTask(0, cfg, (MU1, MU2), seed))
    np.testing.assert_array_equal(out.arrays["gamma_hdr"], want.astype(np.float32))
    # sweep: a point of this bench, on its own stream; its image is eq. 11 of its own words
    seen: list[tuple[Any, ...]] = []
    _spy(monkeypatch, point, seen)
    with pytest.raises(_Stop):
        point.measure_point(PointTask(0, cfg, 3, 0, (MU1, MU2), 4, ()))
    w1, w2, fused, _ = seen.pop()
    np.testing.assert_array_equal(fused.hdr, _eq11(w1, w2, subtract_black))
    # the chain's DR: uniform fields with the measurement's own pedestal, the same rule
    _spy(monkeypatch, chain_dr, seen)
    with pytest.raises(_Stop):
        chain_dr.measure_chain_dynamic_range(cfg, 5, n_levels=3, lines=8, columns=16)
    w1, w2, fused, kw = seen.pop()
    ped = measurement_pedestal_dn(cfg, (MU1, MU2))
    assert kw["pedestal_dn"] == ped
    np.testing.assert_array_equal(fused.hdr, _eq11(w1, w2, subtract_black, float(ped)))


@pytest.mark.physics
def test_kept_black_offset_moves_the_threshold_and_the_offsets():
    """Closed form: with ``b`` kept in the words, stage ``m`` carries ``P + m b`` and eq. 11's
    threshold on the stage-``mu1`` signal is ``(2**beta - P - mu2 b) mu1 / mu2``; a signal just
    below it takes ``Gamma2``, just above it the scaled ``Gamma1``; the true target is
    ``linear_dn`` less ``P + mu2 b``."""
    cfg = tiny_cfg(dtdi={"subtract_black": False, "pedestal_dn": 64}, sensor={"black_offset_dn": 20.0})
    assert stage_pair.stage_offsets_dn(cfg, (2, 8)) == {2: 104.0, 8: 224.0}
    thr = stage_pair.eq11_signal_threshold_dn(cfg)
    assert thr == (4096 - 224) * 2 / 8
    s1 = np.array([thr - 1.0, thr, thr + 1.0])
    g1, g2 = s1 + 104.0, np.minimum(4 * s1 + 224.0, 4095.0)
    fused = stage_pair.fuse_stage_words(cfg, g1, g2)
    assert fused.source.tolist() == [8, 8, 2]
    # at the threshold Gamma2 would be Phi_FS: the word holds 2**beta - 1 (the step eq. 11 keeps)
    np.testing.assert_allclose(fused.hdr, [4 * (thr - 1), 4095 - 224, 4 * (thr + 1)])
    lin = np.array([[500.0, 5000.0]])
    np.testing.assert_array_equal(stage_pair.true_hdr_dn(cfg, lin), lin - 224.0)
