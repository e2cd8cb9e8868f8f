"""``bench-sim dataset`` (issue 12): samples independent of workers and order, resumable after a
kill, exact truth per sample, a manifest that reproduces every sample, one-line refusals."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest

import bench_sim.workflows.dataset.reader as bds
from bench_sim.config import DEFAULT_CONFIG_PATH, config_from_dict, config_sha256, with_overrides
from bench_sim.errors import BenchSimError
from bench_sim.workflows.dataset.run import run_dataset
from tests.conftest import subpixel_shift

#: a 12 x 48 sensor on the paper rig, 32 lines, stages 2 and 8 (fused)
TINY_SPEC = f"""
base = "{DEFAULT_CONFIG_PATH}"
samples = {{samples}}
seed = 31
stages = [2, 8]
lines = 32
columns = 48

[config]
sensor.rows = 12
target.panel_lines = 96
target.panel_columns = 48
target.edge_cell_px = 16
fusion.mu1 = 2
fusion.mu2 = 8

[randomize]
"lights.strong.irradiance_w_m2" = {{{{ dist = "loguniform", low = 32.0, high = 512.0 }}}}
"lights.weak.irradiance_w_m2" = {{{{ dist = "uniform", low = 2.0, high = 12.0 }}}}
"timing.sync_error" = {{{{ dist = "normal", mean = 0.0, std = 0.02, low = -0.05, high = 0.05 }}}}

[randomize.target.layout]  # nested tables work too
dist = "choice"
values = ["slanted_edges", "random_bars", "image"]
weights = [1, 1, 2]

[randomize.target.image]
dist = "glob"
pattern = "img/*.tif"
"""

N_REF = 8


def _write_spec(folder: Path, samples: int = N_REF, extra: str = "", text: str | None = None) -> Path:
    """A tiny spec in ``folder`` with two 8-bit target images in ``folder/img``."""
    import tifffile

    (folder / "img").mkdir(exist_ok=True)
    rng = np.random.default_rng(0)
    for k in range(2):
        tifffile.imwrite(folder / "img" / f"t{k}.tif", rng.integers(0, 256, (40, 30), dtype=np.uint8))
    path = folder / "spec.toml"
    path.write_text((TINY_SPEC.format(samples=samples) if text is None else text) + extra)
    return path


def _assert_same_samples(a: Path, b: Path, indices: list[int]) -> None:
    """Samples ``indices`` of datasets ``a`` and ``b``: identical arrays, values and metrics."""
    sa = {s.index: s for s in bds.iter_samples(a, only=indices, incomplete=True)}
    sb = {s.index: s for s in bds.iter_samples(b, only=indices, incomplete=True)}
    assert sorted(sa) == sorted(sb) == sorted(indices)
    for i in indices:
        assert set(sa[i].arrays) == set(sb[i].arrays)
        for name, arr in sa[i].arrays.items():
            assert np.array_equal(arr, sb[i].arrays[name]), (i, name)
        assert sa[i].values == sb[i].values
        assert sa[i].metrics == sb[i].metrics


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> tuple[Path, Path]:
    """(spec, dataset): the tiny dataset made in this process, one sample after the other."""
    folder = tmp_path_factory.mktemp("dataset-ref")
    spec = _write_spec(folder)
    run = run_dataset(spec, folder / "ref", workers=0)
    assert run.done and not run.failed
    return spec, folder / "ref"


# --- must show 1: sample i does not depend on the workers, the order, or --only -----------------


def test_samples_equal_across_workers_and_only(reference, tmp_path):
    spec, ref = reference
    run = run_dataset(spec, tmp_path / "two", workers=2)  # a LocalCluster: samples finish out of order
    assert run.done
    workers = {r["worker"] for r in bds.read_records(tmp_path / "two").values()}
    assert workers != {"local"}
    _assert_same_samples(ref, tmp_path / "two", list(range(N_REF)))
    # --only i, alone into a new folder, and again into the complete dataset
    run = run_dataset(spec, tmp_path / "only", workers=0, only=[5])
    assert run.ran == [5] and not run.done
    _assert_same_samples(ref, tmp_path / "only", [5])
    with pytest.raises(BenchSimError, match=r"incomplete dataset \(1 of 8 samples complete\)"):
        bds.open(tmp_path / "only")
    run = run_dataset(spec, tmp_path / "two", workers=0, only=[3])
    assert run.done and (tmp_path / "two" / bds.COMPLETION_RECORD).is_file()
    _assert_same_samples(ref, tmp_path / "two", [3])
    # the xarray view and the numpy view agree; the manifest's values are coordinates
    ds = bds.open(ref)
    assert dict(ds.sizes) == {"sample": N_REF, "stage": 2, "line": 32, "column": 48}
    assert ds.dn.attrs["units"] == "DN" and ds.reflectance.attrs["units"] == "1"
    for s in bds.iter_samples(ref, only=[2, 6]):
        assert np.array_equal(ds.mean_dn.sel(sample=s.index).values, s.arrays["mean_dn"])
        assert ds["target.layout"].sel(sample=s.index).item() == s.values["target.layout"]


# --- must show 2: --resume after a kill gives the uninterrupted dataset -------------------------


def test_resume_after_kill_equals_uninterrupted_run(reference, tmp_path):
    spec, ref = reference
    out = tmp_path / "killed"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    proc = subprocess.Popen(
        [sys.executable, "-m", "bench_sim.cli", "dataset", str(spec), "--out", str(out), "--workers", "0"],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 120
        while len(bds.complete_samples(out) if out.is_dir() else []) < 3:
            assert proc.poll() is None, "the run ended before it could be killed"
            assert time.monotonic() < deadline
            time.sleep(0.02)
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait()
    done = bds.complete_samples(out)
    assert 3 <= len(done) < N_REF and not bds.is_complete(out)
    # every sample marked complete is complete and right
    _assert_same_samples(ref, out, done)
    # a half-written sample: its arrays changed on disk, its record gone (killed between the two)
    import zarr

    half = done[1]
    zarr.open_group(str(out / bds.DATA_STORE), mode="r+")["dn"][half] = 7
    bds.record_path(out, half).unlink()
    # without --resume the incomplete dataset is refused; with another spec too
    from typer.testing import CliRunner

    from bench_sim.cli import app

    res = CliRunner().invoke(app, ["dataset", str(spec), "--out", str(out), "--workers", "0"])
    assert res.exit_code == 2 and "--resume completes it" in res.output
    other = spec.with_name("other.toml")
    other.write_text(spec.read_text().replace("seed = 31", "seed = 32"))
    res = CliRunner().invoke(app, ["dataset", str(other), "--out", str(out), "--resume", "--workers", "0"])
    assert res.exit_code == 2 and "made from another spec" in res.output
    res = CliRunner().invoke(app, ["dataset", str(spec), "--out", str(out), "--resume", "--workers", "0"])
    assert res.exit_code == 0, res.output
    assert bds.is_complete(out)
    _assert_same_samples(ref, out, list(range(N_REF)))
    import pandas as pd

    cols = [c for c in pd.read_parquet(ref / bds.MANIFEST_PARQUET).columns if c not in ("wall_s", "worker")]
    pd.testing.assert_frame_equal(
        pd.read_parquet(ref / bds.MANIFEST_PARQUET)[cols], pd.read_parquet(out / bds.MANIFEST_PARQUET)[cols]
    )


# --- must show 3: exact truth per sample ---------------------------------------------------------


TRUTH_SPEC = f"""
base = "{DEFAULT_CONFIG_PATH}"
samples = 5
seed = 5
stages = [1, 80]
lines = 96
columns = 32

[config.sensor]  # every noise source off
shot_noise = false
dark_noise = false
read_noise = false
prnu_enabled = false
dsnu_enabled = false
column_fpn = false
quantization = false

[config.target]
panel_lines = 128
panel_columns = 32
bar_width_min_px = 6.0
bar_width_max_px = 14.0

[config.lights.strong]
enabled = false

[randomize]
"lights.weak.irradiance_w_m2" = {{ dist = "loguniform", low = 6.0, high = 12.0 }}
"timing.sync_error" = {{ dist = "uniform", low = -0.06, high = 0.06 }}
"target.layout" = {{ dist = "choice", values = ["random_bars", "uniform"], weights = [3, 1] }}
"target.uniform_reflectance" = {{ dist = "uniform", low = 0.05, high = 0.8 }}
"""


def _fit_sync_error(stage1: np.ndarray, stage_m: np.ndarray, m: int) -> float:
    """The sync error ``e`` that best explains a stage-``m`` profile from the stage-1 profile
    along the track, when row ``i`` reads its line ``i e`` object pixels further on:
    ``rho_m(x) = (1/m) sum_{i<m} rho_1(x + i e)`` (least squares over ``e`` in +-0.08)."""
    x = np.arange(stage1.size, dtype=np.float64)
    inner = slice(8, -8)

    def residual(e: float) -> float:
        model = np.mean([np.interp(x + i * e, x, stage1) for i in range(m)], axis=0)
        return float(np.sum((model - stage_m)[inner] ** 2))

    grid = np.linspace(-0.08, 0.08, 321)
    return float(grid[int(np.argmin([residual(e) for e in grid]))])


@pytest.mark.physics
def test_truth_holds_per_sample(tmp_path):
    """Noise off: ``dn`` is ``mean_dn`` rounded; ``reflectance`` is the drawn uniform reflectance,
    or, for random bars under the fill, carries the drawn sync error: from stage 1 to stage 80
    it moves as row ``i`` reading its line ``i e`` object pixels further on (the sync error fitted
    back from the truth is the drawn one, to the few per cent of the rows' off-axis geometry),
    and ``dn`` follows it edge for edge in every stage."""
    spec = tmp_path / "truth.toml"
    spec.write_text(TRUTH_SPEC)
    run_dataset(spec, tmp_path / "truth", workers=0)
    layouts = set()
    for s in bds.iter_samples(tmp_path / "truth"):
        dn, mean, clipped = s.arrays["dn"].astype(np.float64), s.arrays["mean_dn"], s.arrays["clipped"]
        assert not clipped.any()
        assert np.abs(dn - mean).max() <= 0.5 + 1e-9
        refl = s.arrays["reflectance"]
        layout, e = s.values["target.layout"], s.values["timing.sync_error"]
        layouts.add(layout)
        if layout == "uniform":
            np.testing.assert_allclose(refl, s.values["target.uniform_reflectance"], rtol=1e-6)
            continue
        prof = {k: np.asarray(a[:, :, 4:-4], dtype=np.float64).mean(axis=2)
                for k, a in (("dn", dn), ("refl", refl))}
        for st in (0, 1):
            edges_dn, edges_refl = np.diff(prof["dn"][st][8:]), np.diff(prof["refl"][st][8:])
            assert abs(subpixel_shift(edges_refl, edges_dn)) < 0.1
        assert _fit_sync_error(prof["refl"][0], prof["refl"][1], 80) == pytest.approx(e, rel=0.1, abs=0.002)
    assert layouts == {"random_bars", "uniform"}


# --- must show 4: the manifest's values are the values used -------------------------------------


def test_manifest_row_reproduces_its_sample(reference):
    """Rebuild a sample from its manifest row alone (base bench of dataset.json + the row's
    values, the documented stream ``SeedSequence(seed, spawn_key=(i, 1))``) and run it."""
    import pandas as pd

    from bench_sim.pipeline import run_pass

    spec, ref = reference
    info = json.loads((ref / bds.DATASET_JSON).read_text())
    manifest = pd.read_parquet(ref / bds.MANIFEST_PARQUET)
    keys = list(info["randomize"])
    assert set(keys) <= set(manifest.columns)
    base = config_from_dict(info["base"]["config"])
    rows = manifest[manifest.status == "complete"]
    picked = [rows[rows["target.layout"] == "image"].iloc[0], rows[rows["target.layout"] != "image"].iloc[0]]
    for row in picked:
        over: dict = {}
        for key in keys:
            value = row[key].item() if hasattr(row[key], "item") else row[key]
            if key == "target.image" and (value is None or value != value):
                value = None  # null: the sample's layout uses no image (issue 24)
            elif key == "target.image":
                value = str((spec.parent / value).resolve())
            *head, last = key.split(".")
            node = over
            for part in head:
                node = node.setdefault(part, {})
            node[last] = value
        cfg = with_overrides(base, over)
        assert config_sha256(cfg) == row["config_sha256"]
        i = int(row["sample"])
        rng = np.random.default_rng(np.random.SeedSequence(info["seed"], spawn_key=(i, 1)))
        again = run_pass(cfg, info["stages"], rng, truth=True).dataset
        (s,) = bds.iter_samples(ref, only=[i])
        assert "gamma_hdr" in s.arrays and "true_hdr_dn" in s.arrays and "hdr" not in s.arrays
        for name, arr in s.arrays.items():  # the pass's variables, the truth stored as float32
            assert np.array_equal(again[name].values.astype(arr.dtype), arr), (i, name)


# --- must show 5: bad specs are one line, exit 2, nothing written -------------------------------


BAD = [
    ("colour = 3\n", None, r"unknown key 'colour'"),
    ('"lights.strong.flux" = { dist = "uniform", low = 1.0, high = 2.0 }\n', "[randomize]",
     r"unknown key 'lights\.strong\.flux'"),
    ('"lens.f_number" = { dist = "uniform", low = 8.0, high = 2.0 }\n', "[randomize]",
     r"randomize\.lens\.f_number: low = 8\.0 must be below high = 2\.0"),
    ('"target.finish" = { dist = "choice", values = [] }\n', "[randomize]",
     r"randomize\.target\.finish: values = \[\]: a choice needs at least one value"),
    ('"lens.f_number" = { dist = "normal", mean = 4.0, std = 0.0, low = 2.0, high = 8.0 }\n', "[randomize]",
     r"randomize\.lens\.f_number\.std = 0\.0: Input should be greater than 0"),
    ('"lens.transmission" = { dist = "uniform", low = 0.5, high = 1.2 }\n', "[randomize]",
     r"lens\.transmission = 1\.2: Input should be less than or equal to 1"),
    ('"sensor.columns" = { dist = "choice", values = [32, 48] }\n', "[randomize]",
     r"randomize\.sensor\.columns: fixes the arrays' shape"),
    (None, "glob", r"randomize\.target\.image\.pattern = 'nothing/\*\.png': matches no file"),
    (None, "disk", r"needs about .*[PT]iB .* free"),
    (None, "stages", r"stages = \[2, 13\]: stage 13 outside 1\.\.12"),
]


@pytest.mark.parametrize("line, where, problem", BAD, ids=[
    "unknown-spec-key", "unknown-config-key", "low-above-high", "empty-choice", "zero-std",
    "value-outside-config", "shape-key", "glob-no-match", "larger-than-disk", "bad-stage",
])
def test_bad_spec_one_line_exit_2_nothing_written(tmp_path, line, where, problem):
    from typer.testing import CliRunner

    from bench_sim.cli import app

    text = TINY_SPEC.format(samples=4)
    if where is None:
        text = line + text
    elif where == "[randomize]":
        text = text.replace("[randomize]\n", "[randomize]\n" + line)
    elif where == "glob":
        text = text.replace('pattern = "img/*.tif"', 'pattern = "nothing/*.png"')
    elif where == "disk":  # 100 000 samples (the most a spec may ask) of 8192 x 1024 at all 100 stages
        text = text.replace("samples = 4", "samples = 100000").replace("lines = 32", "lines = 8192")
        text = text.replace("columns = 48", "columns = 1024").replace("stages = [2, 8]", 'stages = "all"')
        text = text.replace("sensor.rows = 12", "sensor.rows = 100").replace("panel_columns = 48", "")
    elif where == "stages":
        text = text.replace("stages = [2, 8]", "stages = [2, 13]")
    assert tomllib.loads(text)  # the spec itself is valid TOML
    spec = _write_spec(tmp_path, text=text)
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["dataset", str(spec), "--out", str(out), "--workers", "0"])
    assert res.exit_code == 2, res.output
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("bench-sim: error:"), res.output
    assert re.search(problem, lines[0]), lines[0]
    assert not out.exists() and not list(tmp_path.glob(".out.*"))


def test_unreachable_scheduler_is_one_line_and_writes_nothing(tmp_path, monkeypatch):
    """--scheduler naming an address where no scheduler listens: one line naming it, exit 2,
    nothing at --out (the connection timeout shortened from 20 s to 1 s for the test)."""
    import socket

    from typer.testing import CliRunner

    from bench_sim.cli import app
    from bench_sim.runtime import execution

    monkeypatch.setitem(execution.open_client.__wrapped__.__kwdefaults__, "connect_timeout_s", 1.0)
    with socket.socket() as sock:  # a free port: nothing listens there
        sock.bind(("127.0.0.1", 0))
        address = f"tcp://127.0.0.1:{sock.getsockname()[1]}"
    spec = _write_spec(tmp_path, text=TINY_SPEC.format(samples=2))
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["dataset", str(spec), "--out", str(out), "--scheduler", address])
    assert res.exit_code == 2, res.output
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1, res.output
    assert lines[0].startswith(f"bench-sim: error: --scheduler = '{address}': cannot reach a Dask scheduler")
    assert not out.exists() and not list(tmp_path.glob(".out.*"))
