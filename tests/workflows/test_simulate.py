"""``bench_sim.simulate``: stage images with their exact ground truth (issue 9)."""

from __future__ import annotations

import hashlib
import tomllib

import numpy as np
import pytest

import bench_sim
from bench_sim.config import config_from_dict, config_to_toml_dict
from bench_sim.errors import BenchSimError
from bench_sim.pipeline import PASS_VARIABLES, VARIABLES_BY_NAME, stage_pixel_bytes, stored_dataset
from bench_sim.sensor import stage_mean_var_dn
from bench_sim.sensor.model import stage_offset_dn
from bench_sim.workflows.dataset.reader import FUSED_VARIABLES, STAGE_VARIABLES
from tests.conftest import ALL_OFF, TINY, subpixel_shift

NOISE_OFF = dict(ALL_OFF)
TEMPORAL_OFF = dict(shot_noise=False, dark_noise=False, read_noise=False, quantization=False)

#: the fill light alone: a uniformly lit field
FILL_ONLY = {"strong": {"enabled": False}, "weak": {"irradiance_w_m2": 1.0}}


def _overrides(**sections):
    out = {k: dict(v) for k, v in TINY.items()}
    out["lines"] = 48
    for k, v in sections.items():
        if isinstance(v, dict):
            out[k] = {**out.get(k, {}), **v}
        else:
            out[k] = v
    return out


# --- must show 1: dn equals mean_dn without noise, with and without sync error -------------------


@pytest.mark.physics
@pytest.mark.parametrize("sync_error", [0.0, 0.05])
@pytest.mark.parametrize("sensor_switches", [NOISE_OFF, TEMPORAL_OFF], ids=["all-off", "fixed-patterns-on"])
def test_dn_is_mean_dn_without_noise(sync_error, sensor_switches):
    ds = bench_sim.simulate(
        _overrides(sensor=sensor_switches, timing={"sync_error": sync_error}), stages=[1, 2, 7, 12]
    )
    assert list(ds.stage.values) == [1, 2, 7, 12]
    for m in ds.stage.values:
        d = ds.sel(stage=m)
        dn, mean = d.dn.values.astype(np.float64), d.mean_dn.values
        ok = ~d.clipped.values
        assert ok.mean() > 0.5  # the tiny bench's spot saturates part of the field
        # the stage word rounds once: |dn - E[dn]| <= 1/2, and dn is E[dn] rounded
        assert np.abs(dn - mean)[ok].max() <= 0.5 + 1e-9
        tie = np.abs(np.abs(mean - np.floor(mean)) - 0.5) < 1e-6
        assert np.array_equal(dn[ok & ~tie], np.rint(mean[ok & ~tie]))
        # where the word clips, the expectation lies above the clip value
        top = 2 ** ds.attrs["beta_bits"] - 1
        assert np.all(mean[dn >= top] > top - 0.5)


# --- must show 2: the temporal variance of dn - mean_dn per stage ---------------------------------


@pytest.mark.physics
@pytest.mark.parametrize("lit", [True, False], ids=["uniform-fill", "dark"])
def test_temporal_variance_grows_as_closed_form(lit):
    lights = FILL_ONLY if lit else {"strong": {"enabled": False}, "weak": {"enabled": False}}
    ov = _overrides(
        lines=256,
        sensor={"columns": 128},
        target={"layout": "uniform", "panel_columns": 128},
        lights=lights,
        dtdi={"subtract_black": False},  # the dark words keep m * b: no clipping at 0
    )
    cfg = config_from_dict(ov)
    stages = [1, 3, 12]
    ds = bench_sim.simulate(cfg, stages=stages, seed=11)
    t_int = cfg.timing.t_int_s
    sd = []
    for m in stages:
        d = ds.sel(stage=m)
        assert not d.clipped.values.any()
        resid = d.dn.values.astype(np.float64) - d.mean_dn.values
        per_frame = d.photons.values / m
        _, var = stage_mean_var_dn(per_frame, cfg.sensor, t_int, m, subtract_black=False)
        # the residual has mean 0 and the closed-form variance; 5 sigma of the sample variance
        n = resid.size
        assert abs(resid.mean()) < 5 * np.sqrt(var.mean() / n)
        assert resid.var() == pytest.approx(var.mean(), rel=5 * np.sqrt(2 / n))
        sd.append(resid.std())
    if not lit:  # only read and dark noise: the standard deviation grows as sqrt(m)
        assert sd[2] / sd[0] == pytest.approx(np.sqrt(12), rel=0.05)
        assert sd[1] / sd[0] == pytest.approx(np.sqrt(3), rel=0.05)


# --- must show 3: under sync error, truth follows the stage ------------------------------------


@pytest.mark.physics
def test_sync_error_edges_of_dn_and_reflectance_coincide():
    ov = _overrides(
        lines=120,
        sensor={"rows": 80, "columns": 256},
        target={"panel_lines": 128, "panel_columns": 256},
        lights={"strong": {"enabled": False}, "weak": {"irradiance_w_m2": 12.0}},
        timing={"sync_error": 0.05},
        fusion={"mu1": 10, "mu2": 80},
    )
    ds = bench_sim.simulate(ov, stages=[1, 80], seed=3)
    # the step wedge of the left half panel: reflectance steps along the track (its first edge,
    # at the top of the image, is left out)
    w = config_from_dict(ov).target.panel_columns / 2.0
    cols = slice(int(0.03 * w) + 2, int(0.23 * w) - 1)
    prof = {}
    for m in (1, 80):
        d = ds.sel(stage=m)
        assert not d.clipped.values[:, cols].any()
        prof[m] = {
            k: np.diff(np.asarray(d[k].values[10:, cols], dtype=np.float64).mean(axis=1))
            for k in ("dn", "reflectance")
        }
    # in each stage the edges in dn and in its truth coincide
    for m in (1, 80):
        assert abs(subpixel_shift(prof[m]["reflectance"], prof[m]["dn"])) < 0.1
    # and stage 80's moved against stage 1's: row i of stage m reads line j's material plus
    # i * e object pixels further along the track (to larger lines: a negative lag)
    for k in ("dn", "reflectance"):
        assert subpixel_shift(prof[1][k], prof[80][k]) < -1.0


# --- dataset contract ----------------------------------------------------------------------------


def test_dataset_variables_units_and_provenance():
    ds = bench_sim.simulate(_overrides(), stages=[2, 8], seed=5)
    assert dict(ds.sizes) == {"stage": 2, "line": 48, "column": 48}
    for name in ("dn", "mean_dn", "photons", "reflectance", "clipped", "gamma_hdr", "gamma_hdr_source"):
        assert ds[name].attrs["units"] and ds[name].attrs["long_name"], name
    assert np.issubdtype(ds.dn.dtype, np.integer) and ds.clipped.dtype == bool
    assert ds.gamma_hdr.dims == ("line", "column")
    cfg = config_from_dict(tomllib.loads(ds.attrs["config"]))
    assert cfg == config_from_dict(_overrides())
    assert ds.attrs["config_sha256"] == hashlib.sha256(
        __import__("json").dumps(config_to_toml_dict(cfg), sort_keys=True).encode()
    ).hexdigest()
    assert (ds.attrs["seed"], ds.attrs["version"]) == (5, bench_sim.__version__)
    assert ds.attrs["engine"] == "fast" and ds.attrs["variant"]
    # truth is physical: reflectance in 0..1, photons >= 0, words clip only at the top
    assert 0 <= float(ds.reflectance.min()) and float(ds.reflectance.max()) <= 1
    assert float(ds.photons.min()) >= 0
    # the one variables table drives the dataset, the data set's dtypes and the memory estimate
    assert list(ds.data_vars) == [v.name for v in PASS_VARIABLES]
    for v in PASS_VARIABLES:
        assert ds[v.name].dims == v.dims and ds[v.name].dtype == v.array_dtype(ds.attrs["beta_bits"]), v
        assert (ds[v.name].attrs["units"], ds[v.name].attrs["long_name"]) == (v.units, v.doc), v
    # the data set stores every variable of the pass (simulate's schema, issue 34)
    assert (*STAGE_VARIABLES, *FUSED_VARIABLES) == tuple(v.name for v in PASS_VARIABLES)
    stored = {v.name: v.stored_dtype(12).name for v in PASS_VARIABLES}
    assert stored["dn"] == "uint16" and stored["mean_dn"] == "float32" and stored["clipped"] == "bool"
    assert stage_pixel_bytes(12, truth=False) == ds.dn.dtype.itemsize == 2
    per_pixel = sum(ds[v].dtype.itemsize for v in ds.data_vars if "stage" in ds[v].dims)
    assert stage_pixel_bytes(12, truth=True) == per_pixel
    assert stage_pixel_bytes(None, truth=True) == 4 + 8 + 8 + 8 + 8 + 4 + 1  # dn, mean_dn, linear_dn, ...
    assert stage_pixel_bytes(12, truth=True, stored=True) == 2 + 4 + 4 + 4 + 4 + 4 + 1  # in the files


def test_same_seed_same_data_and_no_hdr_without_both_stages():
    a = bench_sim.simulate(_overrides(), stages=[3], seed=9)
    b = bench_sim.simulate(_overrides(), stages=[3], seed=9)
    c = bench_sim.simulate(_overrides(), stages=[3], seed=10)
    assert a.identical(b)
    assert not np.array_equal(a.dn.values, c.dn.values)
    assert "gamma_hdr" not in a and "gamma_hdr_source" not in a


@pytest.mark.parametrize(
    "stages, what",
    [([0, 2], "outside 1..12"), ([2, 13], "outside 1..12"), ([2, 2], "given twice"), ([], "at least one")],
)
def test_bad_stages_raise_one_line(stages, what):
    with pytest.raises(BenchSimError, match=what) as exc:
        bench_sim.simulate(_overrides(), stages=stages)
    assert "\n" not in str(exc.value)


# --- must show 5: reproduce's pass is unchanged -------------------------------------------------


@pytest.mark.parametrize("truth", [False, True])
def test_run_pass_gives_the_previous_pipelines_stage_images(truth):
    """``reproduce`` now runs its pass through :func:`run_pass`: with the same generator it gives
    the stage words of the render -> ``sensor_dtdi_pass`` chain it replaced, bit for bit, and
    leaves the generator in the same state (the DR measurement draws from it next), so every
    number in ``metrics.json`` is unchanged."""
    from bench_sim.pipeline import run_pass
    from bench_sim.render.exposures import iter_photon_frames, prepare
    from bench_sim.sensor.stream import sensor_dtdi_pass

    cfg = config_from_dict(_overrides(timing={"sync_error": 0.02}))
    stages = [1, 2, 5, 8, 12]
    rng_old = np.random.default_rng(21)
    setup = prepare(cfg, cfg.lines + max(stages) - 1, rng_old)
    old = sensor_dtdi_pass(
        iter_photon_frames(setup, chunk=64), cfg.sensor, cfg.dtdi, setup.geom.t_int_s, stages, rng_old,
        lines=cfg.lines,
    )
    rng_new = np.random.default_rng(21)
    new = run_pass(cfg, stages, rng_new, truth=truth)
    assert set(new.stage_dn) == set(old)
    for m in stages:
        assert np.array_equal(new.stage_dn[m], old[m])
        assert np.array_equal(new.dataset.dn.sel(stage=m).values, old[m])
    assert rng_new.integers(0, 2**62) == rng_old.integers(0, 2**62)


def test_truth_of_some_stages_is_the_truth_of_those_stages():
    """``truth_stages``: the truth of the fusion's two stages only (what ``reproduce`` reads) is
    theirs in the pass with the truth of every stage, the words and the fused image's maps are
    unchanged, and the dataset holds just those stages."""
    from bench_sim.pipeline import run_pass

    spot = {"strong": {"irradiance_w_m2": 900.0}}
    cfg = config_from_dict(_overrides(timing={"sync_error": 0.02}, lights=spot))
    stages, some = [1, 2, 5, 8, 12], (2, 8)  # TINY's mu1, mu2
    full = run_pass(cfg, stages, 5, truth=True)
    part = run_pass(cfg, stages, 5, truth=True, truth_stages=some)
    for m in stages:
        assert np.array_equal(part.stage_dn[m], full.stage_dn[m])
    assert list(part.dataset.stage.values) == list(some)
    assert part.dataset["clipped"].values.any()  # the spot clips: the clip-aware truth is exercised
    for name in ("dn", "mean_dn", "linear_dn", "photons", "clipped", "reflectance"):
        want = full.dataset[name].sel(stage=list(some)).values
        assert np.array_equal(part.dataset[name].values, want), name
    for name in ("gamma_hdr", "gamma_hdr_source"):
        assert np.array_equal(part.dataset[name].values, full.dataset[name].values, equal_nan=True), name


@pytest.mark.parametrize("truth, some", [(True, None), (True, (2, 8)), (False, None)])
def test_a_pass_reads_its_dataset_without_building_it(truth, some):
    """``PassResult.read``, ``values``, ``stages``, ``variables`` and ``attrs``: the dataset's
    arrays (by stage, the words of a pass whose truth has fewer stages too), its stages, its
    variables and its attributes, read without building it (what a sweep point and a sample read
    in a worker that never imports xarray)."""
    from bench_sim.pipeline import run_pass

    cfg = config_from_dict(_overrides(lights={"strong": {"irradiance_w_m2": 900.0}}))
    sim = run_pass(cfg, [1, 2, 8], 5, truth=truth, truth_stages=some)
    stages = sim.stages
    per_stage = {n for n in sim.variables if "stage" in VARIABLES_BY_NAME[n].dims}
    got = {n: (sim.values(n), {m: sim.read(n, m) for m in (stages if n in per_stage else (None,))})
           for n in sorted(sim.variables)}
    attrs = dict(sim.attrs)
    assert "dataset" not in vars(sim)  # not built by any of the reads
    ds = sim.dataset
    assert stages == tuple(int(m) for m in ds.stage.values) == (some or (1, 2, 8))
    assert set(got) == {str(n) for n in ds.data_vars} and attrs == ds.attrs
    for name, (values, by_stage) in got.items():
        want = ds[name].values
        assert values.dtype == want.dtype and np.array_equal(values, want, equal_nan=True), name
        for m, arr in by_stage.items():
            want = ds[name].values if m is None else ds[name].sel(stage=m).values
            assert np.array_equal(arr, want, equal_nan=True), (name, m)
    with pytest.raises(BenchSimError, match="no image variable dn"):
        sim.read("dn", None)


@pytest.mark.parametrize("keep", [
    ("dn", "photons", "linear_dn", "reflectance", "clipped"),  # reproduce's: no read cumulants
    ("dn", "mean_dn"),  # the companion pass's core: the cumulants, no other truth
    ("dn", "noise_std_dn", "gamma_hdr", "gamma_hdr_source"),
])
def test_variables_kept_are_the_same_bytes(keep):
    """``variables``: a pass that keeps some of its variables (the truth computing only the
    quantities they are made of) gives them the same bytes as the pass that keeps all of them,
    stage 1 (whose mean folds the word's clip into its one read) and a clipping spot included,
    and holds no other."""
    from bench_sim.pipeline import run_pass

    spot = {"strong": {"irradiance_w_m2": 900.0}}
    cfg = config_from_dict(_overrides(timing={"sync_error": 0.02}, lights=spot))
    stages = [1, 2, 5, 8, 12]
    full = run_pass(cfg, stages, 5, truth=True)
    part = run_pass(cfg, stages, 5, truth=True, variables=keep)
    assert part.arrays is not None and set(part.arrays.arrays) == set(keep)
    assert full.dataset["clipped"].values.any()
    for name in keep:
        assert np.array_equal(part.dataset[name].values, full.dataset[name].values, equal_nan=True), name


@pytest.mark.parametrize("keep, problem", [
    (("dn", "photon"), "unknown"), (("dn", "true_hdr_dn", "linear_dn"), "made of the stage truth"),
])
def test_variables_refused(keep, problem):
    from bench_sim.pipeline import run_pass

    with pytest.raises(BenchSimError, match=problem) as exc:
        run_pass(config_from_dict(_overrides()), [2, 8], 1, variables=keep)
    assert "\n" not in str(exc.value)


def test_a_pass_drops_what_its_caller_is_done_with():
    """``PassResult.drop``: the arrays let go (not in ``stage_array`` nor the dataset); the words stay."""
    from bench_sim.pipeline import run_pass

    sim = run_pass(config_from_dict(_overrides()), [2, 8], 1, truth=True)
    words = sim.stage_dn[8].copy()
    sim.drop("photons", "dn")
    with pytest.raises(BenchSimError, match="no photons"):
        sim.stage_array("photons", 8)
    assert "photons" not in sim.dataset and np.array_equal(sim.dataset["dn"].sel(stage=8).values, words)


@pytest.mark.parametrize("some, problem", [((2, 7), "one of the pass's stages"), ((2, 2), "given twice")])
def test_truth_stages_outside_the_pass_refused(some, problem):
    from bench_sim.pipeline import run_pass

    with pytest.raises(BenchSimError, match=problem) as exc:
        run_pass(config_from_dict(_overrides()), [2, 8], 1, truth_stages=some)
    assert "\n" not in str(exc.value)


# --- must show 4: an image target round-trips ----------------------------------------------------


@pytest.mark.physics
def test_image_target_round_trips(tmp_path):
    """Under the fill alone, ``reflectance`` is the image resampled to the pixel grid and
    ``mean_dn`` is proportional to it (fixed patterns off; the field is narrow: cos^4 ~ 1)."""
    import tifffile
    from scipy.ndimage import gaussian_filter

    pl, pc, rmin, rmax = 64, 96, 0.02, 0.9
    img = gaussian_filter(np.random.default_rng(0).random((2 * pl, 2 * pc)), 3.0)
    img8 = np.round(255 * (img - img.min()) / (img.max() - img.min())).astype(np.uint8)
    tifffile.imwrite(tmp_path / "target.tif", img8)
    ov = _overrides(
        sensor={"columns": pc, "prnu_enabled": False, "dsnu_enabled": False, "column_fpn": False},
        target={
            "layout": "image", "image": str(tmp_path / "target.tif"), "image_encoding": "linear",
            "panel_lines": pl, "panel_columns": pc, "reflectance_min": rmin, "reflectance_max": rmax,
        },
        lights={"strong": {"enabled": False}, "weak": {"irradiance_w_m2": 1200.0}},
        timing={"integration_time_s": 1e-6},  # no smear: the footprint is the pixel
    )
    ds = bench_sim.simulate(ov, stages=[1, 8])
    # the image on the pixel grid: 2 x 2 image pixels per object pixel, mapped into
    # [rmin, rmax]; scene line j is centred on the border of panel rows j - 1 and j
    px = rmin + (rmax - rmin) * img8.reshape(pl, 2, pc, 2).mean(axis=(1, 3)) / 255.0
    expected = 0.5 * (px[:-1] + px[1:])[: ds.sizes["line"] - 1]
    step = max(np.abs(np.diff(px, axis=0)).max(), np.abs(np.diff(px, axis=1)).max())
    inner = (slice(None), slice(2, -2))  # the panel's side borders meet the background
    cfg = config_from_dict(ov)
    half_fov = np.arctan(0.5 * pc * cfg.sensor.pixel_pitch_m / cfg.lens.image_distance_m)
    cos4_spread = 1 - np.cos(half_fov) ** 4
    for m in (1, 8):
        d = ds.sel(stage=m)
        assert not d.clipped.values.any()
        err = (d.reflectance.values[1:] - expected)[inner]
        # resampling error: the texture grid and its bilinear interpolant blur by < 1/4 pixel
        assert np.abs(err).max() < 0.1 * step and np.abs(err).mean() < 0.02 * step
        # the word carries the digital pedestal (and m * black unless subtracted): take it off
        signal = d.mean_dn.values - stage_offset_dn(cfg.sensor, cfg.dtdi, m)
        ratio = (signal / d.reflectance.values)[inner]
        dev = np.abs(ratio / np.median(ratio) - 1)
        assert dev.max() < cos4_spread + 0.02 and dev.mean() < cos4_spread + 0.002


# --- the command ----------------------------------------------------------------------------------


def _tiny_toml(tmp_path, extra: str = "") -> str:
    from bench_sim.config import DEFAULT_CONFIG_PATH

    path = tmp_path / "tiny.toml"
    path.write_text(
        f'base = "{DEFAULT_CONFIG_PATH}"\nlines = 24\n[sensor]\nrows = 12\ncolumns = 48\n'
        "[target]\npanel_lines = 96\npanel_columns = 48\n" + extra + "[fusion]\nmu1 = 2\nmu2 = 8\n"
    )
    return str(path)


@pytest.mark.parametrize("fmt", ["zarr", "netcdf", "tiff"])
def test_cli_writes_each_format(tmp_path, fmt):
    import json

    import tifffile
    import xarray as xr
    from typer.testing import CliRunner

    from bench_sim.cli import app

    out = tmp_path / "out"
    res = CliRunner().invoke(
        app, ["simulate", _tiny_toml(tmp_path), "--stages", "2,8", "--seed", "4", "--out", str(out),
              "--format", fmt],
    )
    assert res.exit_code == 0, res.output
    ref = bench_sim.simulate(_tiny_toml(tmp_path), stages=[2, 8], seed=4)
    stored = stored_dataset(ref, 12)  # the files' schema: the truth in float32 (issue 34)
    if fmt == "zarr":
        ds = xr.open_zarr(out / "simulation.zarr").load()
        assert ds.identical(stored) and ds.mean_dn.dtype == np.float32
    elif fmt == "netcdf":
        ds = xr.open_dataset(out / "simulation.nc").load()
        assert ds.identical(stored)
    else:
        meta = json.loads((out / "meta.json").read_text())
        assert meta["seed"] == 4 and meta["version"] == bench_sim.__version__ and meta["config_sha256"]
        for m in (2, 8):
            for var in ("dn", "mean_dn", "photons", "reflectance", "clipped"):
                name = f"stage_{m:03d}_{var}.tiff"
                arr = tifffile.imread(out / name)
                assert arr.dtype.itemsize == 4 and meta["files"][name]["units"]
                np.testing.assert_allclose(arr, ref[var].sel(stage=m).values, rtol=1e-6)
        assert (out / "gamma_hdr.tiff").is_file() and (out / "gamma_hdr_source.tiff").is_file()


@pytest.mark.parametrize(
    "args, extra, problem",
    [
        (["--stages", "0,8"], "", "stage 0 outside 1..12"),
        (["--stages", "2,13"], "", "stage 13 outside 1..12"),
        (["--stages", "8,2,8"], "", "stage 8 is given twice"),
        (["--stages", "two"], "", "expected 'all', integers like '10,80'"),
        (["--format", "hdf5"], "", "--format = 'hdf5'"),
        ([], '[target]\nlayout = "image"\nimage = "missing.png"\n', "missing.png'?: no such file"),
        ([], '[target]\nlayout = "image"\nimage = "broken.png"\n', "broken.png'?: cannot read"),
        ([], '[target]\nlayout = "image"\nimage = "nan.npy"\n', "nan.npy'?: contains NaN"),
        ([], '[target]\nlayout = "image"\nimage = "big.npy"\n', "big.npy'?: float values"),
    ],
)
def test_cli_bad_input_one_line_exit_2_nothing_written(tmp_path, args, extra, problem):
    from typer.testing import CliRunner

    from bench_sim.cli import app

    (tmp_path / "broken.png").write_bytes(b"\x89PNG not really")
    np.save(tmp_path / "nan.npy", np.array([[0.1, np.nan]]))
    np.save(tmp_path / "big.npy", np.array([[0.1, 2.0]]))
    cfg = _tiny_toml(tmp_path)
    if extra:  # a config on top of the tiny one, naming the image
        (tmp_path / "img.toml").write_text(f'base = "tiny.toml"\n{extra}')
        cfg = str(tmp_path / "img.toml")
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["simulate", cfg, "--out", str(out), "--stages", "2,8", *args])
    assert res.exit_code == 2, res.output
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("bench-sim: error:")
    import re

    assert re.search(problem, lines[0]), lines[0]
    assert not out.exists() and not list(tmp_path.glob(".out.*"))
