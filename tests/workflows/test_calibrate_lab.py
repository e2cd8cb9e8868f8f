"""``calibrate`` on a lab camera written with numpy alone (issue 35's Must show): a camera 3 %
non-linear at the clip, 30 hot pixels, a 1.5 e- offset pattern, 10 % dark-current
non-uniformity, the ADC clipping before the full well, 40 exposure steps with two flats and two
darks each; the same camera as a table without photons and dark-subtracted; the errors over seeds;
a word that caps a stage."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from bench_sim.io import write_frames_npz
from bench_sim.metrics.emva_fit import fit_camera
from bench_sim.metrics.frame_series import FrameSeries, LitLevel, analyse_frames
from bench_sim.workflows.calibrate import calibrate
from bench_sim.workflows.calibrate_inputs import read_input
from tests.workflows.lab_camera import LabCamera, pair_table

pytestmark = pytest.mark.physics


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> tuple[LabCamera, dict[str, np.ndarray], Path]:
    cam = LabCamera(seed=0)
    series = cam.series()
    folder = tmp_path_factory.mktemp("lab")
    write_frames_npz(folder / "frames.npz", series)
    return cam, series, folder


@pytest.fixture(scope="module")
def calibrated(lab, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    _, _, folder = lab
    out = tmp_path_factory.mktemp("cal")
    return out, calibrate(folder / "frames.npz", out, stages="10,80", chain=False)


def _true_le(cam: LabCamera, series: dict[str, np.ndarray], i_sat: int) -> float:
    """LE of the camera's noise-free mean response on the measured grid, fitted by numpy's own
    weighted polynomial (weights 1 / y: the relative deviations) over 5-95 % of saturation."""
    t, ph = series["exposure_s"], series["photons_per_pixel"]
    y = np.array([cam.mean_signal_dn(p, ti) for p, ti in zip(ph, t, strict=True)])
    sel = (y >= 0.05 * y[i_sat]) & (y <= 0.95 * y[i_sat]) & (np.arange(y.size) <= i_sat)
    b, a = np.polynomial.polynomial.polyfit(ph[sel], y[sel], 1, w=1.0 / y[sel])
    dev = 100.0 * (y[sel] - (a * ph[sel] + b)) / (a * ph[sel] + b)
    return 0.5 * float(dev.max() - dev.min())


@pytest.mark.slow
def test_the_lab_camera_is_found_as_it_is(lab, calibrated) -> None:
    """The 30 hot pixels exactly; LE within 0.3 percentage points; the offset pattern and the dark
    current's non-uniformity within 10 %; K and the dark current within 2 reported standard errors;
    'clips on the ADC'."""
    cam, series, _ = lab
    out, res = calibrated
    fit, fr = res["fit"], res["frames"]
    good = ~cam.hot_mask
    assert fr["defects"]["counts"]["hot"] == 30 and sum(fr["defects"]["counts"].values()) == 30
    assert [tuple(p) for p in fr["defects"]["positions"]["hot"]] == cam.hot_positions
    assert abs(fit["linearity_error_percent"] - _true_le(cam, series, fit["saturation_index"])) < 0.3
    split = fr["dsnu_split"]
    assert split["dsnu0_e"]["pixel_e"] == pytest.approx(cam.offset_e[good].std(), rel=0.10)
    assert split["dark_current_nu_e_s"]["total_e_s"] == pytest.approx(cam.dark_map[good].std(), rel=0.10)
    assert abs(fit["k_dn_per_e"] - cam.k) < 2 * fit["k_se"]
    assert abs(fit["dark_current_e_s"] - cam.dark_map[good].mean()) < 2 * fit["dark_current_e_s_se"]
    assert fit["clips_on"] == "adc" and fit["linearized"]
    report = (out / "report.md").read_text()
    assert "The camera clips on the ADC" in report and "Linearity error LE" in report
    defects = (out / "defects.csv").read_text().splitlines()
    assert len(defects) == 31 and all(",hot," in ln for ln in defects[1:])


@pytest.mark.slow
def test_the_twin_follows_the_camera_past_saturation(lab, calibrated) -> None:
    """The twin carries the fitted response, the offset pattern and the defect map; its exact
    photon-transfer curve (each read through its chain) follows the data beyond saturation: the
    plateau's signal within 0.2 % and its variance collapsing to ~0 as the data's does."""
    cam, _, _ = lab
    out, res = calibrated
    effects = res["sensor"]["effects"]
    assert effects["nonlinearity"]["table"] == "response.csv" and (out / "response.csv").is_file()
    assert effects["defects"]["map_file"] == "defect_map.csv" and "offset_pattern" in effects
    assert res["sensor"]["adc_bits"] == cam.bits and res["sensor"]["full_well_e"] > cam.e_clip
    curve = res["model_curve"]
    i_sat = res["fit"]["saturation_index"]
    data_sig, data_var = np.array(curve["data_signal_dn"]), np.array(curve["data_var_dn2"])
    twin_sig, twin_var = np.array(curve["signal_dn"]), np.array(curve["var_dn2"])
    past = np.arange(data_sig.size) > i_sat
    plateau = past & (data_var < 0.25)  # every value at the ADC's top
    assert plateau.sum() >= 5
    assert np.all(np.abs(twin_sig[past] / data_sig[past] - 1) < 2e-3)
    assert np.all(twin_var[plateau] < 0.25)
    for j in np.flatnonzero(
        past & ~plateau
    ):  # where the clip cuts the distribution: the variance falls alike
        assert abs(twin_var[j] - data_var[j]) <= max(0.25 * data_var[j], 1.5), (j, twin_var[j], data_var[j])
    below = np.arange(data_sig.size) < i_sat
    assert np.all(np.abs(twin_sig[below] / data_sig[below] - 1) < 5e-3)


def test_without_photons_K_dark_noise_and_saturation_and_qe_unknown(lab, tmp_path: Path) -> None:
    """A table of exposure, mean and variance only (the exposure time the abscissa): K, the dark
    noise and the saturation in e- and DN; QE and the responsivity unknown, said so."""
    cam, series, _ = lab
    table = tmp_path / "ptc.csv"
    rows = pair_table(series)
    kinds = {1.0: "dark", 0.0: "flat"}
    table.write_text(
        "exposure_s,kind,mean_dn,var_dn2\n"
        + "".join(f"{t!r},{kinds[k]},{m!r},{v!r}\n" for t, k, m, v in rows)
    )
    res = calibrate(table, tmp_path / "out", chain=False)
    fit = res["fit"]
    assert (
        not fit["qe_known"] and math.isnan(fit["quantum_efficiency"]) and fit["irradiance_kind"] == "exposure"
    )
    assert fit["k_dn_per_e"] == pytest.approx(cam.k, rel=0.02)
    assert fit["dark_noise_e"] == pytest.approx(cam.read_noise_e, rel=0.03)
    assert fit["saturation_signal_dn"] > 0 and fit["saturation_capacity_e"] == pytest.approx(
        fit["saturation_signal_dn"] / fit["k_dn_per_e"], rel=0.03
    )
    assert "quantum_efficiency" in res["kept_from_base"] and "quantum efficiency" in res["unknown"]
    assert "Quantum efficiency and responsivity: unknown" in (tmp_path / "out" / "report.md").read_text()


def test_a_dark_subtracted_table_gives_the_results_of_the_raw_one(lab, tmp_path: Path) -> None:
    """The same table raw (dark rows) and dark-subtracted (signal_dn, signal_var_dn2 and the dark
    level of each row): the same fit."""
    _, series, _ = lab
    rows = pair_table(series)
    raw = tmp_path / "raw.csv"
    raw.write_text(
        "exposure_s,photons_per_pixel,mean_dn,var_dn2,pixels,bits\n"
        + "".join(f"{t!r},{0.0 if k else 68600.0 * t!r},{m!r},{v!r},65536,12\n" for t, k, m, v in rows)
    )
    sub = tmp_path / "sub.csv"
    lines = ["exposure_s,photons_per_pixel,signal_dn,signal_var_dn2,dark_mean_dn,dark_var_dn2,pixels,bits"]
    for (t, _, dm, dv), (_, _, m, v) in zip(rows[::2], rows[1::2], strict=True):
        lines.append(f"{t!r},{68600.0 * t!r},{m - dm!r},{v - dv!r},{dm!r},{dv!r},65536,12")
    sub.write_text("\n".join(lines) + "\n")
    a, b = (fit_camera(read_input(p).table).summary() for p in (raw, sub))
    for key, value in a.items():
        if isinstance(value, float) and math.isfinite(value):
            assert b[key] == pytest.approx(value, rel=1e-9, abs=1e-12), key
        elif key != "linearity":
            assert b[key] == value, key


@pytest.mark.slow
def test_reported_errors_have_unit_spread_over_50_seeds() -> None:
    """(fitted - true) / reported error over 50 seeds of the camera (a 96 x 96 crop, 4 hot
    pixels): a standard deviation between 0.7 and 1.4 for K, QE and the dark noise."""
    z: dict[str, list[float]] = {"K": [], "QE": [], "dark noise": []}
    for seed in range(50):
        cam = LabCamera(shape=(96, 96), hot=4, seed=100 + seed)
        s = cam.series()
        lit = tuple(
            LitLevel(float(t), float(p), f)
            for t, p, f in zip(s["exposure_s"], s["photons_per_pixel"], s["flats"], strict=True)
        )
        dark = tuple((float(t), d) for t, d in zip(s["exposure_s"], s["darks"], strict=True))
        fit = analyse_frames(FrameSeries(lit=lit, dark=dark, bits=cam.bits)).fit
        z["K"].append((fit.k_dn_per_e - cam.k) / fit.k_se)
        z["QE"].append((fit.quantum_efficiency - cam.qe) / fit.quantum_efficiency_se)
        z["dark noise"].append((fit.dark_noise_e - cam.read_noise_e) / fit.dark_noise_e_se)
    for name, values in z.items():
        assert 0.7 < float(np.std(values, ddof=1)) < 1.4, (name, np.std(values, ddof=1))
        assert abs(float(np.mean(values))) < 3.0 / math.sqrt(50) * 1.4, (name, np.mean(values))


def test_a_word_that_caps_stage_10_is_named_with_the_width_that_removes_it(tmp_path: Path) -> None:
    """A 12-bit camera of 15 000 e- at K = 0.25 sums 10 reads of up to 3 750 DN: stage 10 clips on a
    12-bit word. The prediction warns, says its DR lies below the camera's own, and names the
    narrowest word that holds 10 full reads above the pedestal (DESIGN: m min(K FW, T - b) <= 2^beta
    - 1 - pedestal)."""
    toml = tmp_path / "cam.toml"
    toml.write_text(
        'name = "capped"\nK_dn_per_e = 0.25\nqe = 0.6\ndark_noise_e = 6.0\n'
        "saturation_capacity_e = 15000\nbits = 12\n"
    )
    res = calibrate(toml, tmp_path / "out", stages="10,80", chain=False)
    dr = res["dynamic_range"]
    caps = {c["stage"]: c for c in dr["word_caps"]}
    assert dr["images"]["gamma1"]["clips_on"] == "word" and caps[10]["below_single_frame"]
    s = res["sensor"]
    black = json.loads(json.dumps(res["config"]))["sensor"]["black_offset_dn"]
    per_read = min(s["conversion_gain_dn_per_e"] * s["full_well_e"], (1 << s["adc_bits"]) - 1 - black)
    need = math.ceil(math.log2(10 * per_read + dr["pedestal_dn"] + 1))
    assert caps[10]["word_bits_without_cap"] == need
    report = (tmp_path / "out" / "report.md").read_text()
    assert (
        "the 12-bit output word caps stage 10" in report
        and f"a word of {need} bits removes the cap" in report
    )
    assert "clips on" in report and "output word" in report


def test_a_misfit_is_said_in_words_and_widens_the_errors(tmp_path: Path) -> None:
    """An illumination series with no irradiation given (no linearisation possible) whose variance
    bends 6 % at the clip, 65 536 pixels: chi2_red above its 99 % quantile; the report says the linear
    model does not fit and by how much, and K's error is the statistical one times sqrt(chi2_red)."""
    rng = np.random.default_rng(4)
    sig = np.r_[np.linspace(20, 3600, 30), [3700.0, 3750.0, 3760.0]]
    var = 4.0 + 0.5 * sig * (1 - 0.06 * (sig / 3600) ** 2)
    var[-3:] = [1700.0, 300.0, 0.0]
    var *= 1 + np.sqrt(2 / 65536) * rng.standard_normal(var.size)
    lines = ["exposure_s,kind,mean_dn,var_dn2,pixels", "0.01,dark,100,4,65536"]
    lines += [f"0.01,flat,{100 + float(s)!r},{float(v)!r},65536" for s, v in zip(sig, var, strict=True)]
    (tmp_path / "t.csv").write_text("\n".join(lines) + "\n")
    res = calibrate(tmp_path / "t.csv", tmp_path / "out", chain=False)
    fit = res["fit"]
    assert fit["irradiance_kind"] == "none" and not fit["linearized"]
    assert fit["k_misfit"] and fit["chi2_red_k"] > 3
    assert fit["k_se"] == pytest.approx(fit["k_se_statistical"] * math.sqrt(fit["chi2_red_k"]), rel=1e-9)
    report = (tmp_path / "out" / "report.md").read_text()
    assert "does not fit the data within their errors" in report
    assert f"chi2_red = {fit['chi2_red_k']:.3g}" in report and "Birge" in report
