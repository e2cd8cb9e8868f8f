"""Photon-transfer experiment: K and dark noise recovered, EMVA files, determinism, CLI, errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import tifffile
from typer.testing import CliRunner

import bench_sim
from bench_sim.cli import app
from bench_sim.config import BenchConfig, config_from_dict, config_sha256
from bench_sim.errors import BenchSimError
from bench_sim.workflows.ptc_job import run_ptc

SMALL = {
    "sensor": {"rows": 16, "columns": 128},
    "fusion": {"mu1": 2, "mu2": 8},
}
TOML = """
[sensor]
rows = 16
columns = 64
[fusion]
mu1 = 2
mu2 = 8
"""


def small_cfg(**sections: dict) -> BenchConfig:
    data = {k: dict(v) for k, v in SMALL.items()}
    for k, v in sections.items():
        data.setdefault(k, {}).update(v)
    return config_from_dict(data)


def parse_descriptor(path: Path) -> dict:
    """Minimal reader of the EMVA 1288 descriptor format (the reference package's rules)."""
    out: dict = {"bright": [], "dark": []}
    cur: list | None = None
    for raw in path.read_text().splitlines():
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        tok = line.split()
        if tok[0] == "n":
            out["bits"], out["width"], out["height"] = (int(t) for t in tok[1:4])
        elif tok[0] == "b":
            cur = []
            out["bright"].append((float(tok[1]), float(tok[2]), cur))
        elif tok[0] == "d":
            cur = []
            out["dark"].append((float(tok[1]), cur))
        elif tok[0] == "i":
            assert cur is not None
            cur.append(path.parent / tok[1])
        elif tok[0] != "v":
            raise AssertionError(f"unknown line {line!r}")
    return out


#: fixed patterns well above the temporal residual of the 16-image spatial stacks, so that DSNU
#: and PRNU are measurable at every stage (dark current 10 e- per frame, DSNU 2 e-)
PATTERNS = {"dark_current_e_s": 1e5, "dsnu_e_s": 2e4, "column_offset_dn": 0.5, "prnu": 0.02}


@pytest.fixture(scope="module")
def ptc_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict, BenchConfig]:
    cfg = small_cfg(sensor=PATTERNS)
    out = tmp_path_factory.mktemp("ptc")
    res = run_ptc(cfg, stages=[1, 4, 16], seed=5, out=out, lines=64, columns=128)
    return out, res, cfg


@pytest.mark.physics
def test_ptc_recovers_gain_and_dark_noise_within_3_percent(ptc_run) -> None:
    """Must show 6: K and the dark temporal noise (e- per stage: sqrt(m) x the pixel's
    sqrt(read^2 + dark)) from the photon-transfer analysis of the stage images."""
    _, res, cfg = ptc_run
    s = cfg.sensor
    sigma_px = np.sqrt(s.read_noise_e**2 + s.dark_current_e_s * cfg.timing.t_int_s)
    for m in (1, 4, 16):
        r = res["results"][str(m)]
        meas = r["measured"]
        assert abs(meas["K_dn_per_e"] / s.conversion_gain_dn_per_e - 1) < 0.03, (m, meas)
        assert abs(meas["dark_temporal_noise_e"] / (np.sqrt(m) * sigma_px) - 1) < 0.03, (m, meas)
        assert abs(r["relative_error"]["dark_temporal_noise_dn"]) < 0.03
        assert abs(meas["quantum_efficiency"] / s.quantum_efficiency - 1) < 0.03
        # saturation: full well (stage 1) or the output word (stages 4, 16), a few % below the clip
        ratio = r["per_frame"]["photons_sat"] / r["expected"]["saturation_photons_per_frame"]
        assert 0.88 < ratio <= 1.0, (m, ratio)
        # SNR = 1 measured on the curve agrees with the linear model
        assert meas["photons_min"] == pytest.approx(meas["photons_min_model"], rel=0.05)


def test_ptc_files_follow_the_emva_descriptor_format(ptc_run) -> None:
    out, res, cfg = ptc_run
    assert res["levels"] >= 31 and res["version"] == bench_sim.__version__
    assert res["config_sha256"] == config_sha256(cfg) and res["seed"] == 5
    for m in (1, 4, 16):
        d = parse_descriptor(out / f"stage_{m:03d}" / "emva1288.txt")
        assert (d["bits"], d["width"], d["height"]) == (cfg.dtdi.beta_bits, 128, 64)
        temporal = [b for b in d["bright"] if len(b[2]) == 2]
        spatial = [b for b in d["bright"] if len(b[2]) > 2]
        assert len(temporal) >= 30 and len(spatial) == 1 and len(d["dark"]) == 2
        exposures = {b[0] for b in d["bright"]} | {e for e, _ in d["dark"]}
        assert len(exposures) == 1
        assert exposures.pop() == pytest.approx(m * cfg.timing.t_int_s * 1e9)
        photons = [b[1] for b in temporal]
        assert photons == sorted(photons) and len(set(photons)) == len(photons)
        assert photons == pytest.approx(res["results"][str(m)]["series"]["photons"])
        # the images: 16-bit, the stage word, the right size; the pair mean matches the JSON
        a, b = (tifffile.imread(p) for p in temporal[5][2])
        assert a.dtype == np.uint16 and a.shape == (64, 128)
        mean = 0.5 * (a.mean() + b.mean())
        assert mean == pytest.approx(res["results"][str(m)]["series"]["mean_dn"][5])
        top = max(tifffile.imread(p).max() for p in temporal[-1][2])
        assert top <= 2**cfg.dtdi.beta_bits - 1
        meta = json.loads(tifffile.TiffFile(temporal[0][2][0]).pages[0].description)
        assert meta["seed"] == 5 and meta["stage"] == m
    for name in ("ptc_results.json", "ptc_levels.csv", "ptc_summary.csv", "ptc.png", "snr.png"):
        assert (out / name).stat().st_size > 0
    assert (out / "ptc_summary.csv").read_text().startswith("# bench_sim ")
    assert b"bench_sim" in (out / "ptc.png").read_bytes()[:4096]


def _fast(cfg: BenchConfig, seed: int, out: Path) -> dict:
    return run_ptc(cfg, [1, 3], seed, out, lines=8, columns=16, dense_levels=3, spatial_images=3)


def test_ptc_is_deterministic(tmp_path: Path) -> None:
    cfg = small_cfg()
    _fast(cfg, 9, tmp_path / "a")
    _fast(cfg, 9, tmp_path / "b")
    _fast(cfg, 10, tmp_path / "c")
    files = sorted(p.relative_to(tmp_path / "a") for p in (tmp_path / "a").rglob("*") if p.is_file())
    assert len(files) > 100
    for rel in files:
        if rel.suffix == ".png":
            continue
        assert (tmp_path / "a" / rel).read_bytes() == (tmp_path / "b" / rel).read_bytes(), rel
    img = Path("stage_003/images/bright_010_a.tif")
    assert not np.array_equal(tifffile.imread(tmp_path / "a" / img), tifffile.imread(tmp_path / "c" / img))


def test_cli_ptc_writes_results(tmp_path: Path) -> None:
    cfg_path = tmp_path / "small.toml"
    cfg_path.write_text(TOML)
    out = tmp_path / "out"
    r = CliRunner().invoke(
        app, ["ptc", str(cfg_path), "--stages", "1,4", "--seed", "3", "--out", str(out)]
    )
    assert r.exit_code == 0, r.output
    res = json.loads((out / "ptc_results.json").read_text())
    assert res["stages"] == [1, 4] and res["seed"] == 3
    assert (res["image_lines"], res["image_columns"]) == (64, 64)
    assert (out / "stage_004" / "emva1288.txt").is_file()


@pytest.mark.parametrize(
    "args, message",
    [
        (["--stages", "1,17"], "stage 17 outside 1..16"),
        (["--stages", "0"], "stage 0 outside 1..16"),
        (["--stages", "1,4,4"], "stage 4 is given twice"),
        (["--stages", "1:8:0"], "ranges like '5:100:5'"),
        (["--stages", "a,b"], "--stages"),
        (["--stages", "1,4", "--seed", "-1"], "seed"),
    ],
)
def test_cli_bad_argument_one_line_error_no_output(tmp_path: Path, args: list[str], message: str) -> None:
    cfg_path = tmp_path / "small.toml"
    cfg_path.write_text(TOML)
    out = tmp_path / "out"
    r = CliRunner().invoke(app, ["ptc", str(cfg_path), "--out", str(out), *args])
    assert r.exit_code == 2
    err = r.stderr if r.stderr else r.output
    assert message in err and len(err.strip().splitlines()) == 1, err
    assert not out.exists()


def test_beta_above_16_is_refused_before_writing(tmp_path: Path) -> None:
    cfg = small_cfg(dtdi={"beta_bits": 20})
    with pytest.raises(BenchSimError, match="beta_bits <= 16"):
        run_ptc(cfg, [1, 4], 0, tmp_path / "out")
    assert not (tmp_path / "out").exists()
    (tmp_path / "file").write_text("x")
    with pytest.raises(BenchSimError, match="not a folder"):
        run_ptc(small_cfg(), [1], 0, tmp_path / "file")


@pytest.mark.physics
def test_subtract_black_off_keeps_the_accumulated_offset(tmp_path: Path) -> None:
    """subtract_black off: stage m's dark level is m x black + the configured pedestal, and the
    analysis (dark-subtracted) still recovers K."""
    cfg = small_cfg(dtdi={"subtract_black": False, "beta_bits": 16})
    res = _fast(cfg, 1, tmp_path)
    for m in (1, 3):
        r = res["results"][str(m)]
        assert r["pedestal_dn"] == cfg.dtdi.pedestal_dn  # the configured one already suffices
        offset = m * cfg.sensor.black_offset_dn + cfg.dtdi.pedestal_dn
        assert r["offset_dn"] == offset
        dark_e = m * cfg.sensor.dark_current_e_s * cfg.timing.t_int_s * cfg.sensor.conversion_gain_dn_per_e
        assert r["dark"]["mean_dn"] == pytest.approx(offset + dark_e, abs=1.0)


@pytest.mark.physics
def test_measurement_raises_a_too_small_pedestal(tmp_path: Path) -> None:
    """A configured pedestal of 0 is raised to 5 sigma of the highest stage's dark spread, so
    the dark pair has no value clipped at 0 DN."""
    cfg = small_cfg(dtdi={"pedestal_dn": 0})
    res = _fast(cfg, 2, tmp_path)
    assert res["configured_pedestal_dn"] == 0 and res["pedestal_dn"] > 0
    dark = tifffile.imread(tmp_path / "stage_003" / "images" / "dark_a.tif")
    assert dark.min() > 0


@pytest.mark.physics
def test_ptc_recovers_dsnu_and_prnu_of_the_sensor(ptc_run) -> None:
    """DSNU and PRNU from the EMVA 1288 spatial stacks of each stage: equal to those of this
    physical sensor (its fixed pattern, drawn first from the run's seed, summed over the stage's
    rows: a column pattern) within 5 %, and to the config's model values within the sampling
    spread of a standard deviation over the image's columns."""
    from bench_sim.sensor.emva import draw_fixed_pattern

    _, res, cfg = ptc_run
    s, t = cfg.sensor, cfg.timing.t_int_s
    k = s.conversion_gain_dn_per_e
    lines, cols, n_img = 64, 128, 16
    fixed = draw_fixed_pattern(s, np.random.default_rng(5)).window(16, cols)  # drawn first

    def tolerance(target_var: float, fixed_var: float, residual_var: float) -> float:
        """4 sigma (relative) of a pattern's std estimated from one averaged image of lines x
        cols pixels. The fixed part of the image (variance ``fixed_var`` over its pixels) is this
        sensor's, so only the temporal residual left by averaging n_img images (``residual_var``,
        subtracted by EMVA on average) scatters the sample variance: by
        sqrt((4 F R + 2 R^2) / N) for N pixels."""
        se_var = np.sqrt((4 * fixed_var * residual_var + 2 * residual_var**2) / (lines * cols))
        return 4 * 0.5 * se_var / target_var

    for m in (1, 4, 16):
        r = res["results"][str(m)]
        temporal_dn2 = r["measured"]["dark_temporal_noise_dn"] ** 2
        # this sensor's stage pattern per column: dark value [DN] and mean gain of its m pixels
        dark_dn = k * (fixed.dark_current_e_s[:m] * t).sum(axis=0) + m * fixed.column_offset_dn
        gain = fixed.prnu_gain[:m].mean(axis=0)
        dsnu_var = dark_dn.var()
        tol = tolerance(dsnu_var, dsnu_var, temporal_dn2 / n_img)
        # in DN (DSNU in e- divides it by the measured K, which has its own scatter)
        assert r["spatial"]["dark_spatial_std_dn"] == pytest.approx(np.sqrt(dsnu_var), rel=tol), m
        # PRNU as EMVA 1288 defines it: sqrt(s^2_bright - s^2_dark) / (mu_bright - mu_dark)
        signal = r["spatial"]["bright_signal_dn"]
        bright_var = (dark_dn + signal * gain / gain.mean()).var()
        prnu_var = bright_var - dsnu_var
        tol = tolerance(prnu_var, bright_var, (temporal_dn2 + k * signal) / n_img)
        tol += tolerance(prnu_var, dsnu_var, temporal_dn2 / n_img)
        assert r["spatial"]["prnu"] == pytest.approx(np.sqrt(prnu_var) / signal, rel=tol), m
        # against the config: a std over n = 128 columns scatters by a further 1/sqrt(2n) (4 sigma)
        spread = 4 / np.sqrt(2 * cols) + 0.05
        assert abs(r["spatial"]["dsnu_e"] / r["expected"]["dsnu_e"] - 1) < spread, m
        assert abs(r["spatial"]["prnu"] / r["expected"]["prnu"] - 1) < spread, m


@pytest.mark.physics
def test_emva1288_reference_package_reads_the_descriptor_files(ptc_run) -> None:
    """The EMVA 1288 reference implementation (the ``emva1288`` package) reads ptc's descriptor
    files and agrees with bench_sim's own analysis and with the config on K, the dark noise and
    the quantum efficiency within 3 %."""
    import logging

    emva_process = pytest.importorskip("emva1288.process", reason="test dependency emva1288")
    if not hasattr(np, "asfarray"):  # emva1288 1.0.2 calls np.asfarray, gone in numpy 2
        np.asfarray = lambda a, dtype=np.float64: np.asarray(a, dtype=dtype)  # noqa: NPY201
    logging.getLogger("emva1288").setLevel(logging.WARNING)
    out, res, cfg = ptc_run
    s = cfg.sensor
    for m in (1, 4):
        parsed = emva_process.ParseEmvaDescriptorFile(str(out / f"stage_{m:03d}" / "emva1288.txt"))
        data = emva_process.Data1288(emva_process.LoadImageData(parsed.images).data)
        ref = emva_process.Results1288(data.data, pixel_area=(s.pixel_pitch_m * 1e6) ** 2)
        ours = res["results"][str(m)]["measured"]
        assert ref.K == pytest.approx(ours["K_dn_per_e"], rel=0.03), m
        assert ref.K == pytest.approx(s.conversion_gain_dn_per_e, rel=0.03), m
        assert ref.QE / 100 == pytest.approx(s.quantum_efficiency, rel=0.03), m
        assert ref.sigma_y_dark == pytest.approx(ours["dark_temporal_noise_dn"], rel=0.03), m
        # in electrons the reference takes off one ADC rounding (1/12 DN^2); a stage-m word holds
        # m pixel roundings, which bench_sim's own analysis takes off instead: same dark noise
        one_rounding_e = np.sqrt(ours["dark_temporal_noise_dn"] ** 2 - 1 / 12) / ours["K_dn_per_e"]
        assert ref.sigma_d == pytest.approx(one_rounding_e, rel=0.03), m
