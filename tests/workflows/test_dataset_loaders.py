"""Datasets for training (issue 24): splits and loaders, the noise-free Gamma_HDR and the
per-pixel noise, a fixed camera, physical coordinates and units, strict JSON."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import bench_sim
from bench_sim.config import DEFAULT_CONFIG_PATH
from bench_sim.errors import BenchSimError
from bench_sim.workflows.dataset.run import run_dataset
from bench_sim.workflows.dataset.splits import check_splits, split_indices

#: one scene (no randomised key), one physical camera, many temporal-noise draws: 12 x 48 sensor,
#: 16 lines, stages 2 and 8 fused; the spot lights part of the view above the eq. 11 threshold
SPEC = f"""
base = "{DEFAULT_CONFIG_PATH}"
samples = {{samples}}
seed = 5
stages = [2, 8]
lines = 16
columns = 48
camera = "fixed"
splits = {{{{ train = 0.6, val = 0.2, test = 0.2 }}}}

[config]
sensor.rows = 12
target.layout = "uniform"
target.panel_lines = 64
target.panel_columns = 48
fusion.mu1 = 2
fusion.mu2 = 8
lights.strong.irradiance_w_m2 = 700.0
lights.weak.irradiance_w_m2 = 6.0
"""
N = 16


@pytest.fixture(scope="module")
def fixed(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("fixed")
    spec = folder / "spec.toml"
    spec.write_text(SPEC.format(samples=N))
    run = run_dataset(spec, folder / "ds", workers=0)
    assert run.done
    return folder / "ds"


def _stack(folder: Path, name: str) -> np.ndarray:
    return np.stack([s.arrays[name] for s in bench_sim.dataset.iter_samples(folder, variables=[name])])


def test_three_epochs_every_sample_once_splits_disjoint_and_stable(fixed):
    info = json.loads((fixed / "dataset.json").read_text())
    assert info["splits"] == {"train": 0.6, "val": 0.2, "test": 0.2}
    parts = {name: bench_sim.dataset.split_samples(fixed, name) for name in ("train", "val", "test")}
    flat = [i for p in parts.values() for i in p]
    assert sorted(flat) == list(range(N)) and len(set(flat)) == N  # disjoint, covering
    # exact sizes: 9.6 / 3.2 / 3.2 -> 9 / 3 / 3, the sample left over to the largest remainder
    assert {k: len(v) for k, v in parts.items()} == {"train": 10, "val": 3, "test": 3}
    assert info["split_samples"] == {k: len(v) for k, v in parts.items()}
    import pandas as pd

    manifest = pd.read_csv(fixed / "manifest.csv")  # plain CSV (issue 34)
    assert {s: sorted(manifest.loc[manifest.split == s, "sample"]) for s in parts} == parts
    orders = []
    for epoch in range(3):
        seen = []
        for batch in bench_sim.dataset.iter_batches(fixed, split="train", fields=["dn", "true_hdr_dn"],
                                                    batch_size=3, seed=7, epoch=epoch):
            assert batch["dn"].shape[1:] == (2, 16, 48) and batch["true_hdr_dn"].dtype == np.float32
            seen += batch["sample"].tolist()
        assert sorted(seen) == parts["train"]  # every train sample exactly once per epoch
        orders.append(seen)
        for shards in (2, 3):  # loader workers: together the same samples, each once
            got = [int(i) for k in range(shards) for b in bench_sim.dataset.iter_batches(
                fixed, split="train", fields=["dn"], batch_size=3, seed=7, epoch=epoch, shard=(k, shards))
                for i in b["sample"]]
            assert sorted(got) == parts["train"]
    assert orders[0] != orders[1] or orders[1] != orders[2]  # reshuffled between epochs
    again = [int(i) for b in bench_sim.dataset.iter_batches(fixed, split="train", fields=["dn"], batch_size=3,
                                                          seed=7, epoch=1) for i in b["sample"]]
    assert again == orders[1]  # a rerun gives the same order
    # the split is a function of (seed, samples, splits): the same on every rerun
    assert split_indices(5, N, info["splits"]) == parts


@pytest.mark.physics
@pytest.mark.slow
def test_noise_std_matches_temporal_std_of_repeated_samples(fixed):
    mean_dn, dn = _stack(fixed, "mean_dn"), _stack(fixed, "dn").astype(np.float64)
    std, clipped = _stack(fixed, "noise_std_dn"), _stack(fixed, "clipped")
    # camera fixed, no randomised key: one scene, one sensor, so the expectation is the same
    assert np.array_equal(mean_dn, np.broadcast_to(mean_dn[0], mean_dn.shape))
    assert np.array_equal(std, np.broadcast_to(std[0], std.shape))
    ok = ~clipped.any(axis=0)
    var = dn.var(axis=0, ddof=1)
    for s in range(2):
        pred = std[0, s].astype(np.float64) ** 2
        keep = ok[s] & (mean_dn[0, s] > 5 * std[0, s])
        for half in (pred <= np.median(pred[keep]), pred > np.median(pred[keep])):
            sel = keep & half
            ratio = float(np.mean(var[s][sel] / pred[sel]))
            # E[s^2 / sigma^2] = 1, sd sqrt(2 / (N - 1) / pixels) for Gaussian noise
            sd = np.sqrt(2.0 / (N - 1) / sel.sum())
            assert abs(ratio - 1.0) < 5 * sd + 0.02, (s, ratio, sd)


@pytest.mark.physics
@pytest.mark.slow
def test_eq11_expected_is_eq11_of_the_stage_truth_and_the_mean_of_gamma_hdr(fixed):
    info = bench_sim.dataset.read_info(fixed)
    beta, ped = 12, 64.0
    mean_dn = _stack(fixed, "mean_dn")[0].astype(np.float64)
    truth = _stack(fixed, "eq11_expected_dn")
    # closed form from the stage truth: both words' expectations clipped to 0 .. 2**beta - 1,
    # pedestal removed; Gamma1 scaled by 8 / 2 where its signal exceeds (2**beta - P) * 2 / 8
    s1 = np.clip(mean_dn[0], 0, 2**beta - 1) - ped
    s2 = np.clip(mean_dn[1], 0, 2**beta - 1) - ped
    low = s1 * 8 > (2**beta - ped) * 2
    assert low.any() and (~low).any()  # both branches in the scene
    np.testing.assert_allclose(truth[0], np.where(low, 4.0 * s1, s2), rtol=1e-6, atol=1e-3)
    assert info["schema"]["variables"]["eq11_expected_dn"]["units"] == "DN"
    # and it is the expectation of gamma_hdr away from the threshold: mean of N draws
    hdr = _stack(fixed, "gamma_hdr").astype(np.float64)
    std = _stack(fixed, "noise_std_dn")[0].astype(np.float64)
    sigma = np.where(low, 4.0 * std[0], std[1])
    clipped = _stack(fixed, "clipped").any(axis=0)
    far = (np.abs(s1 - (2**beta - ped) * 2 / 8) > 5 * std[0]) & ~np.where(low, clipped[0], clipped[1])
    z = (hdr.mean(axis=0) - truth[0]) / (sigma / np.sqrt(N))
    assert far.sum() > 100
    assert abs(float(z[far].mean())) < 5 / np.sqrt(far.sum()) + 0.05
    assert 0.8 < float(z[far].std()) < 1.2


def test_zarr_store_has_units_physical_coordinates_and_constants(fixed):
    import xarray as xr

    ds = xr.open_zarr(fixed / "data.zarr", consolidated=True)
    for name in [*ds.data_vars, *ds.coords]:
        assert ds[name].attrs.get("units") and ds[name].attrs.get("long_name"), name
    # each sample's own coordinates (issue 34)
    assert ds["along_track_mm"].dims == ("sample", "line")
    assert ds["across_track_mm"].dims == ("sample", "column")
    assert ds["time_s"].attrs["units"] == "s"
    # one line is one surface travel per line period: object pixel (5.5 um / magnification)
    step = np.diff(ds["along_track_mm"].values, axis=1)
    np.testing.assert_allclose(step, ds.attrs["delta_m"] * 1e3)
    np.testing.assert_allclose(np.diff(ds["time_s"].values, axis=1), 1e-4)
    assert np.abs(ds["across_track_mm"].values.mean(axis=1)).max() < 1e-12
    assert ds["dn"].attrs["pedestal_included"] == "yes" and ds["gamma_hdr"].attrs["pedestal_included"] == "no"
    assert ds["mean_dn"].dtype == np.float32 and ds["photons"].dtype == np.float32
    assert ds.attrs["sensor_conversion_gain_dn_per_e"] == 0.072 and ds.attrs["dtdi_pedestal_dn"] == 64
    assert ds.attrs["camera"] == "fixed"
    opened = bench_sim.dataset.open(fixed)
    assert set(opened["split"].values) == {"train", "val", "test"}


def test_records_and_dataset_json_are_strict_json(fixed):
    def refuse(token: str) -> None:
        raise ValueError(f"non-standard JSON constant {token}")

    for path in [fixed / "dataset.json", *sorted((fixed / "samples").glob("*.json"))]:
        json.loads(path.read_text(), parse_constant=refuse)
    rec = json.loads((fixed / "samples" / "00000000.json").read_text())
    assert rec["split"] in ("train", "val", "test")


def test_a_damaged_chunk_names_the_sample_the_variable_and_the_file(fixed, tmp_path):
    """A chunk file overwritten with noise: ``iter_batches`` and ``iter_samples`` name the
    sample, the variable and the file, and say how to remake it (before: zstd's own error)."""
    import shutil

    copy = tmp_path / "ds"
    shutil.copytree(fixed, copy)
    chunk = copy / "data.zarr" / "gamma_hdr" / "c" / "3" / "0" / "0"
    assert chunk.is_file()
    chunk.write_bytes(np.random.default_rng(0).bytes(64))
    pattern = (r"sample 3, variable 'gamma_hdr': cannot read .*data.zarr/gamma_hdr/c/3/0/0 \(.*\): a damaged "
               r"file; remake the sample with 'bench-sim dataset SPEC --out .* --only 3'")
    with pytest.raises(BenchSimError, match=pattern):
        for _ in bench_sim.dataset.iter_batches(copy, batch_size=4, shuffle=False):
            pass
    with pytest.raises(BenchSimError, match=pattern):
        for _ in bench_sim.dataset.iter_samples(copy, variables=["gamma_hdr"]):
            pass
    first = next(bench_sim.dataset.iter_batches(copy, batch_size=3, shuffle=False, fields=["gamma_hdr"]))
    assert list(first["sample"]) == [0, 1, 2]  # the other samples read as before


def test_torch_dataset_or_a_one_line_refusal(fixed):
    try:
        import torch
    except ImportError:  # torch is optional (extra "torch"): the loader says how to get it
        with pytest.raises(BenchSimError, match="PyTorch is not installed"):
            bench_sim.dataset.torch_dataset(fixed, split="train")
        return
    ds = bench_sim.dataset.torch_dataset(fixed, split="val", fields=["dn", "true_hdr_dn"])
    loader = torch.utils.data.DataLoader(ds, batch_size=2, num_workers=2)
    seen = [int(i) for b in loader for i in b["sample"]]
    assert sorted(seen) == bench_sim.dataset.split_samples(fixed, "val")


@pytest.mark.parametrize("splits, problem", [
    ({"train": 0.8, "val": 0.1}, "sum to 0.9"),
    ({"train": 1.2, "test": -0.2}, "a fraction >= 0"),
    ({"Train": 1.0}, "lower-case"),
])
def test_bad_splits_one_line(splits, problem):
    with pytest.raises(BenchSimError, match=problem):
        check_splits(splits)


def test_fixed_camera_refuses_randomised_sensor_keys(tmp_path):
    spec = tmp_path / "spec.toml"
    spec.write_text(SPEC.format(samples=2) + '\n[randomize]\n"sensor.prnu" = { dist = "uniform", low = 0.0, '
                    'high = 0.02 }\n')
    with pytest.raises(BenchSimError, match="camera = 'fixed'"):
        run_dataset(spec, tmp_path / "ds", workers=0)
    assert not (tmp_path / "ds").exists()
