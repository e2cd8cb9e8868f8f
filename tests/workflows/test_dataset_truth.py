"""HDR truth a dataset can train on (issue 34): the true HDR target against an independent
computation, eq. 11's error against it at the spot's edge, scenes the spec controls (where the
window sits, the light relative to full scale, the light ratio as the metadata says), exact-size
splits, a plain manifest, the smallest word type, and one schema for ``simulate`` and ``dataset``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import bench_sim
from bench_sim.config import DEFAULT_CONFIG_PATH
from bench_sim.errors import BenchSimError
from bench_sim.workflows.dataset.run import run_dataset
from bench_sim.workflows.dataset.spec import load_spec
from bench_sim.workflows.dataset.splits import split_indices, split_sizes
from bench_sim.workflows.simulate import run_simulate

#: the default rig through a 64-column window at the spot's edge, stages 10 and 80
RIG_SPEC = f"""
base = "{DEFAULT_CONFIG_PATH}"
samples = 4
seed = 3
stages = [10, 80]
lines = 32
columns = 64
splits = {{ train = 0.5, val = 0.25, test = 0.25 }}

[config]
target.layout = "uniform"
target.panel_lines = 64
target.panel_columns = 64

[scene]
window_across_mm = 0.0
peak_of_mu2_clip = [3.0, 6.0]
"""

#: a 12-row sensor on the default rig, uniform print; the window placed by the scene
TINY_SPEC = f"""
base = "{DEFAULT_CONFIG_PATH}"
samples = 2
seed = 8
stages = [2, 8]
lines = 24
columns = 48

[config]
sensor.rows = 12
fusion = {{ mu1 = 2, mu2 = 8 }}
target.layout = "uniform"
target.panel_lines = 48
target.panel_columns = 48

[scene]
"""


@pytest.fixture(scope="module")
def rig(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("rig")
    (folder / "spec.toml").write_text(RIG_SPEC)
    run = run_dataset(folder / "spec.toml", folder / "ds", workers=0)
    assert run.done and not run.failed
    return folder / "ds"


@pytest.mark.parametrize("samples, fractions, sizes", [
    (8, {"train": 0.5, "val": 0.25, "test": 0.25}, {"train": 4, "val": 2, "test": 2}),
    (160, {"train": 0.7, "val": 0.15, "test": 0.15}, {"train": 112, "val": 24, "test": 24}),
    (16, {"train": 0.6, "val": 0.2, "test": 0.2}, {"train": 10, "val": 3, "test": 3}),
    (3, {"a": 0.5, "b": 0.5}, {"a": 2, "b": 1}),
])
def test_splits_have_exact_sizes_and_are_stable(samples, fractions, sizes):
    assert split_sizes(samples, fractions) == dict(sorted(sizes.items()))
    parts = split_indices(77, samples, fractions)
    assert {k: len(v) for k, v in parts.items()} == sizes
    assert sorted(i for v in parts.values() for i in v) == list(range(samples))  # disjoint, covering
    assert split_indices(77, samples, fractions) == parts  # every rerun
    assert split_indices(78, samples, fractions) != parts or samples < 4  # the seed ranks the samples


@pytest.mark.physics
@pytest.mark.parametrize("seed", range(5))
def test_split_sizes_are_the_largest_remainder_rounding(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 500))
    f = rng.dirichlet(np.ones(int(rng.integers(2, 6))))
    got = split_sizes(n, {f"s{k}": float(v) for k, v in enumerate(f)})
    assert sum(got.values()) == n
    assert all(abs(got[f"s{k}"] - v * n) < 1 for k, v in enumerate(f))


@pytest.mark.slow
def test_true_target_is_linear_dn_less_offsets_and_eq11_errs_at_the_spot_edge(rig):
    info = bench_sim.dataset.read_info(rig)
    assert info["split_samples"] == {"train": 2, "val": 1, "test": 1}
    for s in bench_sim.dataset.iter_samples(rig):
        lin = s.arrays["linear_dn"][1].astype(np.float64)
        want = lin - 64.0  # stage 80 less the pedestal (the black offset is subtracted on the rig)
        np.testing.assert_allclose(s.arrays["true_hdr_dn"], want, rtol=1e-6)
        assert s.arrays["dn"].dtype == np.uint16
    # eq. 11 of the expected words against it: right under the fill, wrong along the spot's edge
    eq11 = bench_sim.dataset.score_fusion(rig, "eq11_expected_dn", split=None).regions
    assert eq11["spot_edge"]["pixels"] > 50 and eq11["fill"]["pixels"] > 50
    assert eq11["spot_edge"]["bias"] < -0.1 and eq11["spot_edge"]["rms"] > 0.2  # about -25 % / 33 %
    assert abs(eq11["fill"]["bias"]) < 0.01 and eq11["fill"]["rms"] < 0.05
    assert eq11["lost"]["pixels"] == 0  # 3 and 6 times stage 80's clip: stage 10 is clear (8x)
    noisy = bench_sim.dataset.score_fusion(rig, "gamma_hdr", split=None).regions
    assert noisy["spot_edge"]["bias"] < -0.1
    # a fusion that knew the truth scores 0 everywhere
    exact = bench_sim.dataset.score_fusion(rig, lambda s: s.arrays["true_hdr_dn"], split="test")
    assert exact.samples == bench_sim.dataset.split_samples(rig, "test")
    assert all(v["rms"] == 0.0 for v in exact.regions.values() if v["pixels"])


@pytest.mark.slow
def test_light_level_is_the_fraction_of_the_mu2_clip_asked_for(rig):
    for s in bench_sim.dataset.iter_samples(rig, variables=["photons"]):
        peak = 0.072 * 0.55 * float(s.arrays["photons"][1].max()) / (4095 - 64)  # K eta photons / range
        assert peak == pytest.approx([3.0, 6.0][s.index % 2], rel=1e-6)


@pytest.mark.slow
def test_manifest_is_plain_csv_and_the_schema_is_simulate_s(rig, tmp_path):
    import pandas as pd
    import xarray as xr

    manifest = pd.read_csv(rig / "manifest.csv")  # no options
    assert list(manifest["sample"]) == [0, 1, 2, 3] and set(manifest["split"]) == {"train", "val", "test"}
    assert list(manifest["scene.peak_of_mu2_clip"]) == [3.0, 6.0, 3.0, 6.0]
    side = json.loads((rig / "manifest.csv.json").read_text())
    assert side["columns"] == list(manifest.columns) and side["seed"] == 3
    # simulate of the same bench and stages: the same variables, dtypes, attributes and chunks
    spec = load_spec(rig.parent / "spec.toml")
    data = xr.open_zarr(rig / "data.zarr")
    cfg_path = tmp_path / "bench.toml"
    cfg_path.write_text(data.attrs["base_config"])  # the dataset's base bench
    run_simulate(cfg_path, stages="10,80", seed=1, out=tmp_path / "sim", progress=False)
    sim = xr.open_zarr(tmp_path / "sim" / "simulation.zarr")
    assert list(sim.data_vars) == list(data.data_vars)
    for name in sim.data_vars:
        a, b = sim[name], data[name]
        assert a.dtype == b.dtype, name
        assert a.dims == b.dims[1:], name
        assert a.attrs == b.attrs, name
        assert a.encoding["chunks"] == b.encoding["chunks"][1:], name
    assert set(sim.coords) == set(data.coords) - {"sample"}
    for key in ("sensor_read_noise_e", "dtdi_pedestal_dn", "line_period_s", "sensor_chain", "truth_exact"):
        assert sim.attrs[key] == data.attrs[key], key
    assert spec.word_bits == 12 and sim.dn.dtype == np.uint16


def _tiny(tmp_path: Path, name: str, scene: str) -> Path:
    (tmp_path / f"{name}.toml").write_text(TINY_SPEC + scene)
    run = run_dataset(tmp_path / f"{name}.toml", tmp_path / name, workers=0)
    assert run.done and not run.failed
    return tmp_path / name


@pytest.mark.slow
def test_window_on_the_fill_has_r_1_and_on_the_spot_edge_not(tmp_path):
    import pandas as pd

    fill = _tiny(tmp_path, "fill", "window_across_mm = 40.0\n")
    edge = _tiny(tmp_path, "edge", "window_across_mm = [0.0, -1.0]\n")
    for folder, uniform in ((fill, True), (edge, False)):
        manifest = pd.read_csv(folder / "manifest.csv")
        for s in bench_sim.dataset.iter_samples(folder):
            r = s.arrays["tdi_light_ratio"].astype(np.float64)
            row = manifest.loc[manifest["sample"] == s.index].iloc[0]
            # the metadata says what the map shows
            assert row["light_ratio_max_dev"] == pytest.approx(np.abs(r - 1).max(), rel=1e-5)
            if uniform:
                assert np.abs(r - 1).max() < 1e-4 and row["light_ratio_outside_fraction"] == 0
            else:
                assert np.abs(r - 1).max() > 0.05 and row["light_ratio_outside_fraction"] > 0
            # the sample's own coordinates: its window across the track
            across = s_coords(folder, s.index)
            assert across.mean() == pytest.approx(row["scene.window_across_mm"], abs=1e-9)


def s_coords(folder: Path, index: int) -> np.ndarray:
    import xarray as xr

    return xr.open_zarr(folder / "data.zarr")["across_track_mm"].sel(sample=index).values


@pytest.mark.parametrize("scene, problem", [
    ('window_across_mm = "far"\n', r"scene\.window_across_mm = 'far': expected a number"),
    ('peak_of_mu2_clip = "rig"\n', r"scene\.peak_of_mu2_clip = 'rig': expected a number"),
    ("peak_of_mu2_clip = [1.0, -2.0]\n", r"-2\.0 is not a fraction > 0"),
    ("spot = 1.0\n", r"unknown key 'scene\.spot'"),
    ('window_along_mm = { dist = "uniform", low = 3.0, high = 1.0 }\n', r"low = 3\.0 must be below high"),
])
def test_bad_scene_is_one_line(tmp_path, scene, problem):
    (tmp_path / "spec.toml").write_text(TINY_SPEC + scene)
    with pytest.raises(BenchSimError, match=problem):
        load_spec(tmp_path / "spec.toml")


def test_scene_values_are_drawn_listed_or_over_the_rig(tmp_path):
    (tmp_path / "spec.toml").write_text(TINY_SPEC.replace("samples = 2", "samples = 40") + (
        'window_across_mm = "rig"\nwindow_along_mm = [1.0, 2.0, 3.0]\n'
        'peak_of_mu2_clip = { dist = "loguniform", low = 0.5, high = 8.0 }\n'))
    spec = load_spec(tmp_path / "spec.toml")
    values = [spec.draw(i) for i in range(40)]
    across = np.array([v["scene.window_across_mm"] for v in values])
    half = 0.5 * (300.0 - 48 * 0.0495)  # the drum's length less the window, mm
    assert np.all(np.abs(across) <= half) and across.max() - across.min() > half  # spread over the rig
    assert [v["scene.window_along_mm"] for v in values[:4]] == [1.0, 2.0, 3.0, 1.0]
    peaks = np.array([v["scene.peak_of_mu2_clip"] for v in values])
    assert np.all((peaks >= 0.5) & (peaks < 8.0))
    assert spec.draw(7) == values[7]  # the sample's own stream


def test_true_target_says_when_the_truth_is_not_exact(tmp_path):
    """A chain with a plug-in that declares no truth: the true target carries the same
    ``truth_exact = 0`` (and why) as every truth variable; without it, 1."""
    from bench_sim.pipeline import run_pass, variable_attrs
    from tests.conftest import tiny_cfg

    (tmp_path / "fx.py").write_text("def same(x, *, rng):\n    return x\n")
    plain = tiny_cfg(lines=8)
    black_box = tiny_cfg(lines=8, sensor={"effects": {"box": {
        "kind": "plugin", "function": f"{tmp_path / 'fx.py'}:same", "point": "digital"}}})
    for cfg, exact in ((plain, 1), (black_box, 0)):
        ds = run_pass(cfg, (2, 8), 0).dataset
        for name in ("true_hdr_dn", "eq11_expected_dn", "stage_clip_flags", "hdr_recoverable"):
            attrs = ds[name].attrs
            assert attrs == variable_attrs(cfg, name) and attrs["truth_exact"] == exact, name
            assert attrs.get("truth_not_exact") == ds["mean_dn"].attrs.get("truth_not_exact"), name
        assert "truth_exact" not in ds["gamma_hdr"].attrs  # the fused words are no truth
