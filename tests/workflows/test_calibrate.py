"""``bench-sim calibrate``: the output set, the calibrated sensor in other commands, the predicted
DTDI dynamic range against the chain, the reference implementation (emva1288), bad inputs."""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import bench_sim
from bench_sim.cli import app
from bench_sim.config import config_from_dict, load_config
from bench_sim.measure.chain_dr import measure_chain_dynamic_range
from bench_sim.workflows.calibrate import calibrate
from bench_sim.workflows.calibrate_inputs import read_input
from bench_sim.workflows.ptc_job import run_ptc
from bench_sim.workflows.reproduce.report import AGREE_DB

runner = CliRunner()
#: the emva1288 package computes every result, the undefined ones (no column pattern here) as sqrt(<0)
REFERENCE_WARNINGS = pytest.mark.filterwarnings("ignore:invalid value encountered in sqrt:RuntimeWarning")
#: the 12-bit shot-noise-limited camera of tests/measure/test_calibration.py
SHOT_12BIT = {
    "adc_bits": 12, "conversion_gain_dn_per_e": 0.5, "full_well_e": 6000.0, "read_noise_e": 2.0,
    "black_offset_dn": 40.0,
}
HEADER = "exposure_s,photons_per_pixel,mean_dn,var_dn2"


def _emva_process():
    process = pytest.importorskip("emva1288.process", reason="test dependency emva1288")
    if not hasattr(np, "asfarray"):  # emva1288 1.0.2 calls np.asfarray, gone in numpy 2
        np.asfarray = lambda a, dtype=np.float64: np.asarray(a, dtype=dtype)  # noqa: NPY201
    logging.getLogger("emva1288").setLevel(logging.WARNING)
    return process


def _reference(descriptor: Path):
    process = _emva_process()
    parsed = process.ParseEmvaDescriptorFile(str(descriptor))
    data = process.Data1288(process.LoadImageData(parsed.images).data)
    return process.Results1288(data.data, loglevel=logging.WARNING)


def _ptc_table(
    out: Path, sensor: dict, seed: int, lines: int = 16, columns: int = 64, dense: int = 13
) -> Path:
    sec = {"sensor": {"rows": 16, "columns": columns, **sensor}, "fusion": {"mu1": 2, "mu2": 8}}
    cfg = config_from_dict(sec)
    run_ptc(cfg, stages=[1], seed=seed, out=out, lines=lines, columns=columns, spatial_images=3,
            log_levels=30, dense_levels=dense)
    return out / "stage_001"


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    """The paper's sensor measured by ``ptc`` (stage 1), calibrated on the paper rig."""
    stage = _ptc_table(tmp_path_factory.mktemp("ptc"), {}, seed=3)
    out = tmp_path_factory.mktemp("cal")
    return out, calibrate(stage / "ptc_table.csv", out, stages="10,80", seed=0)


def test_writes_the_set_and_a_sensor_every_command_accepts(calibrated, tmp_path: Path) -> None:
    out, res = calibrated
    files = ("sensor.toml", "calibration.json", "calibration.csv", "report.md", "ptc.png", "residuals.png")
    for name in files:
        assert (out / name).is_file(), name
    assert json.loads((out / "calibration.json").read_text())["stages"] == [10, 80]
    assert res["version"] == bench_sim.__version__ and res["seed"] == 0 and "config" in res
    cal = load_config(out / "sensor.toml")  # a config by itself
    fit = res["fit"]
    for key, value in res["sensor"].items():
        assert getattr(cal.sensor, key) == pytest.approx(value, rel=1e-12), key
    assert abs(cal.sensor.conversion_gain_dn_per_e - 0.072) < 3.5 * fit["k_se"]
    rel_sat = fit["saturation_capacity_e_se"] / fit["saturation_capacity_e"]
    assert cal.sensor.full_well_e == pytest.approx(13500.0, rel=3.5 * rel_sat)
    # the calibrated model saturates where the camera did (EMVA: variance maximum)
    model_sat = res["model_check"]["saturation_capacity_e"]
    assert model_sat == pytest.approx(fit["saturation_capacity_e"], rel=2e-3)
    # named as base by another config: simulate runs on it unchanged
    cfg_file = tmp_path / "bench.toml"
    cfg_file.write_text(
        f'base = "{(out / "sensor.toml").as_posix()}"\nlines = 16\n[sensor]\nrows = 12\ncolumns = 48\n'
        "[target]\npanel_lines = 96\npanel_columns = 48\n[render]\nspp = 4\nsubpixels = 2\n"
        "[fusion]\nmu1 = 2\nmu2 = 8\n"
    )
    cfg = load_config(cfg_file)
    assert cfg.sensor.full_well_e == cal.sensor.full_well_e
    ds = bench_sim.simulate(cfg, stages=[2, 8], seed=1)
    assert float(ds["dn"].max()) > 0


@pytest.mark.physics
@pytest.mark.slow
def test_predicted_dr_agrees_with_the_chain_within_reproduces_scatter(calibrated) -> None:
    """The report's closed-form DTDI DR (EMVA saturation: the model's variance maximum) against the
    DR measured through sensor, DTDI and eq. 11 as ``reproduce`` measures it (three seeds: the
    report's own and two more), within ``reproduce``'s stated scatter (AGREE_DB)."""
    out, res = calibrated
    dr = res["dynamic_range"]
    cfg = config_from_dict(res["config"])  # the paper rig with the calibrated sensor
    chains = [{k: v["chain_db"] for k, v in dr["images"].items()}]
    for seed in (1, 2):
        chains.append(measure_chain_dynamic_range(cfg, seed, mu1=10, mu2=80, columns=64).dr_db)
    for name, v in dr["images"].items():
        mean = float(np.mean([c[name] for c in chains]))
        assert abs(mean - v["closed_form_emva_db"]) <= AGREE_DB, (name, mean, v)
        # the clip-point closed form lies above the variance maximum: by a few tenths of a dB
        assert 0.0 < v["closed_form_clip_db"] - v["closed_form_emva_db"] < 0.6
    assert "Predicted DTDI dynamic range" in (out / "report.md").read_text()


@pytest.mark.physics
@pytest.mark.slow
@REFERENCE_WARNINGS
def test_agrees_with_the_emva1288_package_on_the_same_descriptor(tmp_path: Path) -> None:
    """bench_sim's weighted fit and the reference implementation's on ptc's descriptor (a
    12-bit camera, 256 x 256 pixels so that the two estimators' statistical difference is small):
    within 1 % on K, QE, the dark noise and the saturation capacity."""
    stage = _ptc_table(tmp_path, SHOT_12BIT, seed=1, lines=256, columns=256, dense=5)
    ref = _reference(stage / "emva1288.txt")
    fit = calibrate(stage, tmp_path / "cal", chain=False)["fit"]
    assert fit["k_dn_per_e"] == pytest.approx(ref.K, rel=0.01)
    assert fit["quantum_efficiency"] == pytest.approx(ref.QE / 100, rel=0.01)
    assert fit["dark_noise_dn"] == pytest.approx(ref.sigma_y_dark, rel=0.01)
    assert fit["dark_noise_e"] == pytest.approx(ref.sigma_d, rel=0.01)
    assert fit["saturation_capacity_e"] == pytest.approx(ref.u_e_sat, rel=0.01)
    assert fit["saturation_index"] == ref.index_u_ysat


@pytest.mark.physics
@pytest.mark.slow
@REFERENCE_WARNINGS
@pytest.mark.parametrize(("bits", "k", "seed"), [(12, 0.4, 3), (10, 0.1, 5)])
def test_agrees_with_the_emva1288_package_on_its_own_camera_simulator(
    bits: int, k: float, seed: int, tmp_path: Path
) -> None:
    """Data made by emva1288's camera simulator (exposure-time series, dark current, 128 x 128):
    within 1 % of the reference's K, QE, dark noise and saturation capacity, and the simulator's
    K and QE within 3.5 standard errors. (ADC-limited cameras: with a full-well plateau the
    reference's backward search for the variance maximum stops inside the plateau.)"""
    _emva_process()
    from emva1288.camera.dataset_generator import DatasetGenerator
    from emva1288.camera.routines import Qe

    gen = DatasetGenerator(
        steps=50, L=3, width=128, height=128, bit_depth=bits, K=k, u_esat=40000.0, seed=seed, blackoffset=8,
        outdir=str(tmp_path / "ds"), image_format="tif",
        qe=Qe(qe=np.full((128, 128, 1), 0.6), wavelength=np.array([550.0]), width=128, height=128),
    )
    ref = _reference(Path(gen.descriptor_path))
    res = calibrate(tmp_path / "ds", tmp_path / "cal", chain=False)
    fit = res["fit"]
    assert fit["k_dn_per_e"] == pytest.approx(ref.K, rel=0.01)
    assert fit["quantum_efficiency"] == pytest.approx(ref.QE / 100, rel=0.01)
    assert fit["dark_noise_e"] == pytest.approx(ref.sigma_d, rel=0.01)
    assert fit["saturation_capacity_e"] == pytest.approx(ref.u_e_sat, rel=0.01)
    assert abs(fit["k_dn_per_e"] - gen.cam.K) < 3.5 * fit["k_se"]
    assert abs(fit["quantum_efficiency"] - 0.6) < 3.5 * fit["quantum_efficiency_se"]
    assert res["sensor"]["adc_bits"] == bits and math.isfinite(fit["dark_current_e_s"])


@REFERENCE_WARNINGS
def test_published_results_as_toml_and_as_the_packages_xml(tmp_path: Path) -> None:
    toml = tmp_path / "cam.toml"
    toml.write_text(
        'name = "example"\nK_dn_per_e = 0.25\nqe = 0.6\nwavelength_nm = 525\ndark_noise_e = 6.0\n'
        "saturation_capacity_e = 10000\ndark_current_e_per_s = 50\nprnu_percent = 0.5\nbits = 12\n"
    )
    res = calibrate(toml, tmp_path / "a", chain=False)
    s = res["sensor"]
    assert s["conversion_gain_dn_per_e"] == 0.25 and s["quantum_efficiency"] == 0.6 and s["adc_bits"] == 12
    assert s["wavelength_m"] == pytest.approx(525e-9) and s["prnu"] == pytest.approx(0.005)
    t = load_config().timing.t_int_s  # dark noise taken at the base config's exposure time
    assert math.hypot(s["read_noise_e"], math.sqrt(50 * t)) == pytest.approx(6.0)
    assert res["model_check"]["saturation_capacity_e"] == pytest.approx(10000, rel=2e-3)
    assert "black_offset_dn" in res["kept_from_base"]
    # the results XML the emva1288 package writes
    xml = tmp_path / "results.xml"
    ref = _reference(_ptc_table(tmp_path / "ptc", SHOT_12BIT, seed=2) / "emva1288.txt")
    ref.xml(str(xml))
    got = read_input(xml).results
    assert got["K_dn_per_e"] == pytest.approx(ref.K) and got["qe"] == pytest.approx(ref.QE / 100)
    assert got["saturation_capacity_e"] == pytest.approx(ref.u_e_sat)
    assert calibrate(xml, tmp_path / "b", chain=False)["sensor"]["conversion_gain_dn_per_e"] == ref.K


def _csv(path: Path, rows: list[list[float]], header: str = HEADER) -> Path:
    path.write_text(header + "\n" + "\n".join(",".join(f"{v:g}" for v in r) for r in rows) + "\n")
    return path


def _rows(n: int = 40, top: float = 4000.0) -> list[list[float]]:
    p = np.geomspace(20, top, n)
    sig = np.minimum(0.25 * p, 1000.0)
    var = np.where(0.25 * p < 950, 4.0 + 0.5 * sig, 1.0)
    lit = ([1e-3, float(a), 10.0 + float(b), float(c)] for a, b, c in zip(p, sig, var, strict=True))
    return [[1e-3, 0.0, 10.0, 4.0], *lit]


BAD = {
    "missing column": (lambda r: r, HEADER[:-8], "missing column(s) var_dn2"),
    "negative variance": (lambda r: [*r[:5], [1e-3, *r[5][1:3], -2.0], *r[6:]], HEADER, "cannot be negative"),
    "non-monotonic exposure": (lambda r: [*r[:5], [5e-4, *r[5][1:]], *r[6:]], HEADER, "non-monotonic"),
    "too few in the linear range": (lambda r: _rows(n=6), HEADER, "levels in the linear range"),
    "QE above 1": (
        lambda r: [[a, b / 10.0 if b else 0.0, c, d] for a, b, c, d in r], HEADER, "quantum efficiency"
    ),
    # issue 32: accepted before, and fitted into nonsense
    "lit mean below the dark level": (lambda r: [*r[:3], [1e-3, r[3][1], 9.0, r[3][3]], *r[4:]], HEADER,
                                      "row 4: mean_dn = 9 below its dark level 10 DN"),
    "exposure 0 on every row": (lambda r: [[0.0, *x[1:]] for x in r], HEADER, "row 1: exposure_s = 0"),
    "milliseconds written as seconds": (lambda r: [[20.0, *x[1:]] for x in r], HEADER,
                                        "exposure_s = 20.0: expected about 1e-06..1 s"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_tables_are_one_line_exit_2_and_write_nothing(case: str, tmp_path: Path) -> None:
    change, header, needle = BAD[case]
    table = _csv(tmp_path / "t.csv", change(_rows()), header)
    out = tmp_path / "out"
    res = runner.invoke(app, ["calibrate", str(table), "--out", str(out)])
    assert res.exit_code == 2, res.output
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and needle in lines[0], res.output
    assert not out.exists()


def test_ms_written_as_seconds_gets_a_guess(tmp_path: Path) -> None:
    table = _csv(tmp_path / "t.csv", [[20.0, *x[1:]] for x in _rows()])
    res = runner.invoke(app, ["calibrate", str(table), "--out", str(tmp_path / "out")])
    assert res.exit_code == 2 and "did you mean 20e-3?" in res.output, res.output


def test_calibration_json_is_strict_json_for_a_single_exposure_table(tmp_path: Path) -> None:
    """One exposure time: the dark current and its error are undefined. They were written as
    ``NaN`` tokens (not JSON); now ``null``, and every file parses with a strict parser."""
    table = _csv(tmp_path / "t.csv", _rows())
    calibrate(table, tmp_path / "out", chain=False)

    def refuse(token: str) -> None:
        raise ValueError(f"non-standard JSON token {token}")

    data = json.loads((tmp_path / "out" / "calibration.json").read_text(), parse_constant=refuse)
    assert None in _leaves(data)


def _leaves(value: object) -> list[object]:
    if isinstance(value, dict):
        return [x for v in value.values() for x in _leaves(v)]
    if isinstance(value, list):
        return [x for v in value for x in _leaves(v)]
    return [value]


def test_public_api_and_bad_stages(tmp_path: Path) -> None:
    assert bench_sim.calibrate is calibrate
    table = _csv(tmp_path / "t.csv", _rows())
    res = runner.invoke(app, ["calibrate", str(table), "--out", str(tmp_path / "o"), "--stages", "80,10"])
    assert res.exit_code == 2 and "--stages" in res.output
    res = runner.invoke(app, ["calibrate", str(tmp_path / "t.json"), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "no such file" in res.output


@pytest.mark.slow
def test_reproduce_quick_runs_on_the_calibrated_sensor(calibrated, tmp_path: Path) -> None:
    out, res = calibrated
    run = runner.invoke(app, ["reproduce", str(out / "sensor.toml"), "--quick", "--out", str(tmp_path / "r")])
    assert run.exit_code == 0, run.output
    metrics = json.loads((tmp_path / "r" / "metrics.json").read_text())
    assert set(metrics["dr_db"]) == {"gamma1", "gamma2", "gamma_hdr"}


def test_sweep_and_dataset_run_on_the_calibrated_sensor(calibrated, tmp_path: Path) -> None:
    """The calibrated ``sensor.toml`` as the base of a one-point sweep and a one-sample data set."""
    out, res = calibrated
    bench = tmp_path / "bench.toml"
    bench.write_text(
        f'base = "{(out / "sensor.toml").as_posix()}"\nlines = 16\n[sensor]\nrows = 12\ncolumns = 48\n'
        "[target]\npanel_lines = 48\npanel_columns = 48\n[render]\nspp = 4\nsubpixels = 2\n"
        "[fusion]\nmu1 = 2\nmu2 = 8\n"
    )
    (tmp_path / "sweep.toml").write_text(
        'name = "cal"\nbase = "bench.toml"\nseed = 1\n[[parameters]]\n'
        'key = "lights.strong.irradiance_w_m2"\nvalues = [64.0]\n'
    )
    run = runner.invoke(app, ["sweep", str(tmp_path / "sweep.toml"), "--out", str(tmp_path / "sw"),
                              "--workers", "0", "--no-plots"])
    assert run.exit_code == 0, run.output
    points = (tmp_path / "sw" / "points.csv").read_text().splitlines()
    assert len(points) == 2 and ",ok," in points[1]
    (tmp_path / "ds.toml").write_text(
        'name = "cal"\nbase = "bench.toml"\nsamples = 1\nseed = 2\nstages = [2, 8]\nlines = 16\n'
        'columns = 48\n[randomize]\n'
        '"lights.weak.irradiance_w_m2" = { dist = "uniform", low = 2.0, high = 8.0 }\n'
    )
    run = runner.invoke(app, ["dataset", str(tmp_path / "ds.toml"), "--out", str(tmp_path / "ds"),
                              "--workers", "0"])
    assert run.exit_code == 0, run.output
    ds = bench_sim.dataset.open(tmp_path / "ds")
    assert ds.sizes["sample"] == 1
    assert float(ds.attrs.get("sensor_full_well_e", res["sensor"]["full_well_e"])) == pytest.approx(
        res["sensor"]["full_well_e"])
