"""The moving drum: DTDI sync, the two engines' agreement, determinism, kernel reuse."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import drjit as dr
import numpy as np
import pytest

from bench_sim.errors import BenchSimError
from bench_sim.render.exposures import iter_photon_frames, prepare, render_photons
from bench_sim.render.texture import smear_filter
from tests.conftest import tiny_cfg

FIRST = 60  # frames around the horizontal bar groups of the tiny panel: structure along the track


def _pass(cfg, frames, seed, engine="reference", first=FIRST):
    setup = prepare(cfg, frames, np.random.default_rng(seed), engine=engine, first_frame=first)
    return np.concatenate(list(iter_photon_frames(setup))), setup


def _shift_mismatch(ph: np.ndarray, rows: range) -> float:
    """Mean |row i+1 of frame k+1 - row i of frame k| over rows near the axis, relative."""
    a = ph[:-1, rows.start : rows.stop]
    b = ph[1:, rows.start + 1 : rows.stop + 1]
    return float(np.abs(a - b).mean() / b.mean())


@pytest.mark.physics
def test_rows_see_the_same_line_one_frame_later_only_in_sync():
    """With sync_error = 0 the surface image moves exactly one row per line period near the
    optical axis: the mismatch between row i+1 of frame k+1 and row i of frame k is no larger
    than Monte Carlo noise (measured by re-rendering with another seed). A 25 % sync error makes
    it several times larger."""
    cfg = tiny_cfg(render={"spp": 256})
    rows = range(4, 7)
    ph, _ = _pass(cfg, 10, seed=1)
    ph2, _ = _pass(cfg, 10, seed=2)
    noise = float(np.abs(ph[1:, 5:8] - ph2[1:, 5:8]).mean() / ph2.mean())
    in_sync = _shift_mismatch(ph, rows)
    assert noise > 0
    assert in_sync < 1.5 * noise
    off, _ = _pass(tiny_cfg(render={"spp": 256}, timing={"sync_error": 0.25}), 10, seed=1)
    assert _shift_mismatch(off, rows) > 4 * noise


@pytest.mark.physics
def test_fast_and_reference_engines_agree_within_two_percent():
    """On the bar groups (the hardest region: sharp edges moving along the track). The reference
    needs many samples per pixel to resolve them (at 64 spp its own noise is ~2.3 %), so it runs
    at 512 spp; the fast engine at its default 16 spp x 4 x 4 records."""
    fast, _ = _pass(tiny_cfg(render={"spp": 16}), 8, seed=5, engine="fast")
    ref, _ = _pass(tiny_cfg(render={"spp": 512}), 8, seed=6, engine="reference")
    mae = np.abs(fast - ref).mean() / ref.mean()
    assert mae < 0.02
    assert abs(fast.mean() / ref.mean() - 1) < 0.005  # and no bias


def test_same_seed_same_exposures_other_seed_other_noise():
    """The reference engine's render noise follows the run's seed; the fast engine's records are
    rendered once with a fixed sampler seed (a fixed estimate of the scene, shared by every run
    of it), so its exposures do not depend on the seed -- and do depend on the record seed."""
    from bench_sim.render import records

    cfg = tiny_cfg(render={"spp": 4})
    for engine in ("fast", "reference"):
        a, _ = render_photons(cfg, 3, np.random.default_rng(11), engine=engine)
        b, _ = render_photons(cfg, 3, np.random.default_rng(11), engine=engine)
        c, _ = render_photons(cfg, 3, np.random.default_rng(12), engine=engine)
        assert np.array_equal(a, b)
        assert np.array_equal(a, c) == (engine == "fast")
    records.clear_record_cache()
    try:
        records.RECORD_SEED = 1
        d, _ = render_photons(cfg, 3, np.random.default_rng(11), engine="fast")
    finally:
        records.RECORD_SEED = 0
        records.clear_record_cache()
    assert not np.array_equal(a, d)


def test_turning_the_drum_does_not_recompile_kernels():
    cfg = tiny_cfg(render={"spp": 4})
    setup = prepare(cfg, 4, np.random.default_rng(0), engine="reference")
    setup.engine.radiance_frames(0, 1)  # first frame: compiles (or loads) the kernels
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()  # clear
        setup.engine.radiance_frames(1, 4)
        jit = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert jit, "no kernels were launched"
    assert all(k["cache_hit"] for k in jit)


def test_fast_engine_refuses_glossy_print_and_indirect_light():
    with pytest.raises(BenchSimError, match="finish = 'glossy'.*reference"):
        prepare(tiny_cfg(target={"finish": "glossy"}), 2, np.random.default_rng(0), engine="fast")
    with pytest.raises(BenchSimError, match="max_depth = 4"):
        prepare(tiny_cfg(render={"max_depth": 4}), 2, np.random.default_rng(0), engine="fast")
    # the reference engine renders the glints
    ph, _ = render_photons(tiny_cfg(target={"finish": "glossy"}, render={"spp": 4}), 1,
                           np.random.default_rng(0), engine="reference")
    assert np.isfinite(ph).all() and ph.max() > 0


@pytest.mark.physics
def test_mesh_drum_matches_analytic_cylinder():
    """The trimesh drum (2048 facets, smooth normals, caps, axle, mounts, bench) renders the same
    target as the analytic cylinder; the bench below shades a little of the fill."""
    a, _ = render_photons(tiny_cfg(), 4, np.random.default_rng(0), engine="fast")
    m, _ = render_photons(tiny_cfg(drum={"geometry": "mesh"}), 4, np.random.default_rng(0), engine="fast")
    assert np.abs(a - m).mean() / a.mean() < 0.02


@pytest.mark.physics
@pytest.mark.parametrize("smear_texels", [4.0, 2.37, 0.6])
def test_smear_filter_is_the_box_integral_of_the_linear_interpolant(smear_texels):
    """``smear_filter`` = (1/S) * integral_0^S A(y + s) ds of the piecewise-linear interpolant,
    against a brute-force midpoint integral (20,000 points per texel): the whole-texel branch
    (S = 4 texels, the default t_int = T with q = 4), the fractional branch (2.37) and a smear
    shorter than one texel (0.6); nodes within S of the end clamp to the last value."""
    rng = np.random.default_rng(4)
    values = rng.uniform(0.02, 0.9, (40, 3))
    h_y = 1e-5  # m per texel
    got = smear_filter(values, h_y, smear_texels * h_y)
    n = values.shape[0]
    pts = (np.arange(int(20_000 * smear_texels)) + 0.5) / 20_000  # midpoints in 0..S texels
    ext = np.concatenate([values, np.repeat(values[-1:], 8, axis=0)])  # clamp past the end
    expected = np.empty_like(values)
    for i in range(n):
        y = i + pts
        j = np.minimum(np.floor(y).astype(int), ext.shape[0] - 2)
        f = (y - j)[:, None]
        expected[i] = ((1 - f) * ext[j] + f * ext[j + 1]).mean(axis=0)
    np.testing.assert_allclose(got, expected, rtol=2e-5, atol=2e-6)


def test_mesh_files_are_written_once_and_removed_at_exit(tmp_path):
    """The drum's PLY files are written once per process and drum configuration, into one
    temporary folder that is gone when the process exits (sweeps used to leave a folder per
    scene in /tmp)."""
    code = (
        "from bench_sim.rig.scene import _mesh_files\n"
        "from tests.conftest import tiny_cfg\n"
        "a = _mesh_files(tiny_cfg(drum={'geometry': 'mesh'}))\n"
        "t = {k: p.stat().st_mtime_ns for k, p in a.items()}\n"
        "b = _mesh_files(tiny_cfg(drum={'geometry': 'mesh'}))\n"
        "c = _mesh_files(tiny_cfg(drum={'geometry': 'mesh', 'bench': False}))\n"
        "assert a == b and {k: p.stat().st_mtime_ns for k, p in b.items()} == t\n"
        "assert set(a) - set(c) == {'bench'} and a['body'].parent != c['body'].parent\n"
        "print(len(list(a['body'].parent.parent.iterdir())))\n"
    )
    env = {**os.environ, "TMPDIR": str(tmp_path)}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         cwd=Path(__file__).resolve().parents[2], check=True)
    assert out.stdout.strip() == "2"
    assert list(tmp_path.iterdir()) == []


def test_a_target_that_is_not_drawn_shares_its_rasterised_blocks_between_passes():
    """Two passes over the same grid of a procedural target read one set of rasterised blocks
    (equal to a fresh rasterisation); a drawn target (dead leaves) gets its own each time."""
    from bench_sim.render import texture
    from bench_sim.rig.geometry import rig_geometry

    cfg = tiny_cfg()
    geom = rig_geometry(cfg)
    a = texture.run_texture(cfg, geom, FIRST, 8, np.random.default_rng(0))
    rows = a.rows(0, a.n_rows)
    b = texture.run_texture(tiny_cfg(lights={"strong": {"irradiance_w_m2": 7.0}}), geom, FIRST, 8,
                            np.random.default_rng(1))
    assert b._blocks is a._blocks and b.held_bytes == a.held_bytes > 0
    np.testing.assert_array_equal(b.rows(0, b.n_rows), rows)
    # a fresh rasterisation, blurred by the lens block by block (diffraction: the default)
    assert b.lens is not None
    fresh = np.concatenate([b._made_block(k) for k in range(-(-b.n_rows // texture.BLOCK_ROWS))])
    np.testing.assert_array_equal(fresh, rows)
    np.testing.assert_array_equal(b.values, rows)
    perfect = tiny_cfg(lens={"diffraction": False})
    e = texture.run_texture(perfect, geom, FIRST, 8, np.random.default_rng(0))
    assert e.lens is None and e._blocks is not a._blocks
    np.testing.assert_array_equal(e.rows(0, e.n_rows), e._rasterize(0, e.n_rows))
    leaves = tiny_cfg(target={"layout": "dead_leaves"})
    c = texture.run_texture(leaves, geom, FIRST, 8, np.random.default_rng(0))
    d = texture.run_texture(leaves, geom, FIRST, 8, np.random.default_rng(0))
    assert c._blocks is not d._blocks


@pytest.mark.slow
@pytest.mark.parametrize("fewer", [False, True])
def test_a_pass_keeps_the_blocks_it_reads_at_once(monkeypatch, fewer):
    """A texture keeps the blocks its pass reads at once (the engine's window and the truth's
    band, each over the sensor's rows and :data:`~bench_sim.render.texture.PASS_WINDOW_FRAMES`
    frames or lines, which the pass's own chunk and band do not exceed), at most
    :data:`~bench_sim.render.texture.CACHE_BLOCKS`: a pass of the paper rig over 20 blocks makes
    none twice (with the stores off, a block made twice is rasterised and blurred twice); with
    half as many kept, some are."""
    from bench_sim.config import SCENES_DIR, load_config, with_overrides
    from bench_sim.pipeline import RENDER_CHUNK_FRAMES, TRUTH_BAND_LINES, run_pass
    from bench_sim.render import texture

    assert max(RENDER_CHUNK_FRAMES, TRUTH_BAND_LINES) <= texture.PASS_WINDOW_FRAMES
    assert texture.blocks_read_at_once(100, 4) == 8  # the paper rig: 4 blocks of window, 4 of band
    assert texture.blocks_read_at_once(1000, 8) == texture.CACHE_BLOCKS
    if fewer:
        keep = texture.blocks_read_at_once
        monkeypatch.setattr(texture, "blocks_read_at_once", lambda rows, q: keep(rows, q) // 2)
    made: list[int] = []
    make = texture.RunTexture._made_block

    def counted(self, b):
        made.append(b)
        return make(self, b)

    monkeypatch.setattr(texture.RunTexture, "_made_block", counted)
    cfg = with_overrides(load_config(SCENES_DIR / "paper_rig.toml"),
                         {"sensor": {"columns": 32}, "target": {"panel_columns": 32}})
    run_pass(cfg, [10, 80], 0, truth=True)
    assert len(set(made)) >= 18
    assert (len(made) == len(set(made))) is not fewer
