"""The truth's building blocks: chunked stage sums, the reflectance of all stages at once, the
cumulants of clipped reads worked in blocks, the assembly of completed lines (issue 26)."""

from __future__ import annotations

import numpy as np
import pytest

import bench_sim.sensor.expectation as expectation
from bench_sim.render.exposures import prepare
from bench_sim.sensor.expectation import ReadModel, clipped_sum_mean, read_cumulants
from bench_sim.sensor.pass_lines import ArraySink, LineAssembler
from bench_sim.sensor.stage_truth import (
    StageSums,
    reflectance_rows,
    row_footprints,
    stages_reflectance,
)
from tests.conftest import tiny_cfg


def _push_all(sums: StageSums, quantities: list[np.ndarray], sizes: list[int]) -> dict[int, np.ndarray]:
    """Push (K, R, N) quantities in chunks of ``sizes`` frames; each stage's lines joined."""
    got: dict[int, list[np.ndarray]] = {m: [] for m in sums.stages}
    k = 0
    for size in sizes:
        for m, block in sums.push([q[k : k + size] for q in quantities]).items():
            got[m].append(block)
        k += size
    return {m: np.concatenate(b, axis=1) for m, b in got.items()}


@pytest.mark.physics
def test_stage_sums_of_a_linear_field_are_the_closed_form():
    """``v[k, i] = a k + b i``: ``sum_{i<m} v[j + i, i] = a (m j + m(m-1)/2) + b m(m-1)/2``, every
    line ``j`` that ``K`` frames complete (``K - m + 1`` lines per stage)."""
    a, b, rows, frames = 0.5, 3.0, 9, 40
    k, i = np.meshgrid(np.arange(frames), np.arange(rows), indexing="ij")
    v = (a * k + b * i)[:, :, None] * np.ones(3)
    stages = (1, 4, 9)
    got = _push_all(StageSums(3, stages, 2), [v, 2.0 * v], [16, 16, 8])
    for m in stages:
        j = np.arange(frames - m + 1)
        want = a * (m * j + m * (m - 1) / 2) + b * m * (m - 1) / 2
        assert got[m].shape == (2, j.size, 3)
        np.testing.assert_allclose(got[m][0], want[:, None] * np.ones(3), rtol=1e-14)
        np.testing.assert_allclose(got[m][1], 2 * want[:, None] * np.ones(3), rtol=1e-14)


def test_stage_sums_do_not_depend_on_the_chunking():
    """The same frames pushed in any chunks give the same sums, bit for bit (each line sums its
    rows in the same order), and bool quantities count as 0/1."""
    rng = np.random.default_rng(4)
    v = rng.exponential(100.0, (50, 12, 5))
    flag = rng.random((50, 12, 5)) < 0.1
    stages = (2, 5, 12)
    one = _push_all(StageSums(5, stages, 2), [v, flag], [50])
    many = _push_all(StageSums(5, stages, 2), [v, flag], [1, 7, 16, 3, 16, 7])
    for m in stages:
        assert one[m].tobytes() == many[m].tobytes()
        any_read = [np.any([flag[j + i, i] for i in range(m)], axis=0) for j in range(50 - m + 1)]
        assert np.array_equal(one[m][1] > 0, np.array(any_read))


@pytest.fixture(scope="module")
def tiny_footprints():
    cfg = tiny_cfg(lines=40, timing={"sync_error": 0.05})
    setup = prepare(cfg, cfg.lines + cfg.sensor.rows - 1, np.random.default_rng(0))
    fp = row_footprints(cfg, setup.geom, setup.grid, cfg.sensor.rows)
    return cfg, setup, fp


def _reflectance_by_definition(values, q, fp, m, line0, line1, row0):
    """``rho_m[j] = (1/m) sum_{i < m} X_g(i) <w_i, values[y_base_i + (j + i) q ..]>``, one row and
    one line at a time: each row's along-track weights, then its across-track matrix."""
    out = np.zeros((line1 - line0, fp.x_matrices[0].shape[0]))
    for i in range(m):
        w, mat = fp.y_weights[i], fp.x_matrices[fp.x_group[i]]
        for j in range(line0, line1):
            a = int(fp.y_base[i]) + (j + i) * q - row0
            out[j - line0] += mat @ (w @ values[a : a + w.size])
    return out / m


@pytest.mark.physics
def test_reflectance_of_all_stages_at_once_matches_each_stage_alone(tiny_footprints):
    """:func:`stages_reflectance` (projected across first, grown row by row) equals the
    definition evaluated row by row for every stage, up to float rounding."""
    cfg, setup, fp = tiny_footprints
    q, stages = setup.grid.q, (1, 2, 5, 11, 12)
    r0, r1 = reflectance_rows(fp, q, stages[-1], 3, 30)
    values = np.random.default_rng(1).random((r1 - r0, setup.grid.shape[1]))
    fast = stages_reflectance(values, q, fp, stages, 3, 30, row0=r0)
    for s, m in enumerate(stages):
        direct = _reflectance_by_definition(values, q, fp, m, 3, 30, r0)
        np.testing.assert_allclose(fast[s], direct, rtol=1e-12, atol=1e-15)


@pytest.mark.physics
def test_reflectance_of_a_uniform_texture_is_its_value(tiny_footprints):
    """Footprint weights sum to 1: a uniform texture of 0.37 gives 0.37 at every stage."""
    cfg, setup, fp = tiny_footprints
    q = setup.grid.q
    r0, r1 = reflectance_rows(fp, q, 12, 0, 25)
    out = stages_reflectance(np.full((r1 - r0, setup.grid.shape[1]), 0.37), q, fp, range(1, 13), 0, 25, r0)
    np.testing.assert_allclose(out, 0.37, rtol=1e-12)


def test_read_cumulants_into_out_and_clipped_sum_mean_in_any_block_size(monkeypatch):
    """``read_cumulants`` writing into ``out`` gives its cumulants bit for bit, near-clip reads
    included; :func:`clipped_sum_mean` works in cache-sized blocks, and any block size gives the
    same means bit for bit."""
    rm = ReadModel(gain_dn_per_e=0.07, full_well_e=13500.0, read_noise_e=6.0, top_dn=1023.0,
                   quantization=True)
    rng = np.random.default_rng(2)
    lam = np.concatenate([rng.uniform(0, 40, (3, 50)), rng.uniform(0, 16000, (5, 50))])
    off = rng.normal(8.0, 2.0, 50)
    ref = read_cumulants(lam, 0.0, off, rm)
    outs = tuple(np.empty(lam.shape) for _ in range(3))
    into = read_cumulants(lam, 0.0, off, rm, out=outs)
    for x, y, o in zip(ref, into, outs, strict=True):
        assert x.tobytes() == y.tobytes() and y is o
    sums = [8 * k for k in ref]  # sums of 8 such reads: some near or beyond the clips below
    whole = clipped_sum_mean(*sums, 60.0, 7000.0)
    assert np.any(whole != sums[0])  # the clips matter somewhere
    monkeypatch.setattr(expectation, "_BLOCK_ELEMENTS", 7)
    assert clipped_sum_mean(*sums, 60.0, 7000.0).tobytes() == whole.tobytes()


@pytest.mark.physics
def test_clipped_sum_mean_far_from_both_clips_is_the_mean():
    """More than 12 sd from both clips the shortfalls are below float64's resolution: ``E = k1``
    exactly, as the full expansion gives it there; a sum at the top clip's level loses about
    ``0.4 sd`` (``sd phi(0)``)."""
    k1 = np.array([500.0, 2000.0, 3500.0])
    assert np.array_equal(clipped_sum_mean(k1, 100.0, 50.0, 0.0, 4095.0), k1)
    rng = np.random.default_rng(5)
    sd = rng.uniform(0.5, 40.0, 2000)
    k1 = rng.uniform(12.0, 30.0, 2000) * sd  # 12 .. 30 sd above 0
    gamma = rng.uniform(-1.0, 1.0, 2000)
    shortfall = expectation._shortfall
    lower, upper = sd * shortfall(k1 / sd, -gamma), sd * shortfall((1e9 - k1) / sd, gamma)
    full = k1 + lower - upper
    got = clipped_sum_mean(k1, sd**2 + 1 / 12, gamma * sd**3, 0.0, 1e9)
    assert np.array_equal(got, full) and np.array_equal(got, k1)
    at_top = clipped_sum_mean(np.array([4095.0]), 400.0 + 1 / 12, 0.0, 0.0, 4095.0)
    assert at_top[0] == pytest.approx(4095.0 - 20.0 / np.sqrt(2 * np.pi), rel=1e-6)


def test_line_assembler_joins_words_and_truth_in_any_blocks():
    """Lines put in unequal blocks per variable leave once every variable holds them; ``clipped``
    gains the words at the top; both fusion stages' lines (all variables, as the sink got them)
    reach the fusion callback."""
    rng = np.random.default_rng(3)
    lines, cols, top = 20, 4, 15
    dn = {m: rng.integers(0, top + 1, (lines, cols)).astype(np.uint32) for m in (1, 3)}
    sat = {m: rng.random((lines, cols)) < 0.2 for m in (1, 3)}
    sink = ArraySink((1, 3), lines, cols, {"dn": np.dtype(np.uint16), "clipped": np.dtype(bool)},
                     {"sum": np.dtype(np.float64)})
    asm = LineAssembler((1, 3), {"dn": np.dtype(np.uint16), "clipped": np.dtype(bool)}, sink, top,
                        (1, 3, lambda a, b: {"sum": a["dn"].astype(float) + b["dn"] + 100 * b["clipped"]}))
    for name, data, cuts in (("dn", dn, [0, 3, 3, 11, 20]), ("clipped", sat, [0, 8, 9, 20])):
        for m in (3, 1):
            for c0, c1 in zip(cuts[:-1], cuts[1:], strict=True):
                asm.put(name, m, c0, data[m][c0:c1])
    for s, m in enumerate((1, 3)):
        assert np.array_equal(sink.arrays["dn"][s], dn[m])
        assert np.array_equal(sink.arrays["clipped"][s], sat[m] | (dn[m] == top))
    clipped3 = sat[3] | (dn[3] == top)
    assert np.array_equal(sink.arrays["sum"], dn[1].astype(float) + dn[3] + 100 * clipped3)
