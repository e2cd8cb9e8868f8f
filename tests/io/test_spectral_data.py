"""Measured spectra by name (colour-science) and from CSV files (bench_sim.io.spectral_data), their
checks in a config, and ``config keys`` listing the names."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from bench_sim.cli import app
from bench_sim.config import ConfigError
from bench_sim.errors import BenchSimError
from bench_sim.io.spectral_data import load_spectrum, named_spectrum, read_spectrum_csv, spectrum_names
from bench_sim.rig.spectra import check_spectra
from tests.conftest import make_cfg

runner = CliRunner()


@pytest.mark.parametrize("kind, names", [
    ("light", ("A", "FL2", "FL11", "FL3.15", "LED-B1", "LED-RGB1", "D65", "Kinoton 75P", "Incandescent")),
    ("reflectance", ("ColorChecker N Ohta/dark skin", "BabelColor Average/neutral 5 (.70 D)")),
    ("qe", ("Nikon 5100 (NPL)/green", "Sigma SDMerill (NPL)/red")),
])
def test_names_of_each_kind(kind: str, names: tuple[str, ...]) -> None:
    listed = spectrum_names(kind)
    assert set(names) <= set(listed) and len(listed) == len(set(listed))
    for n in names:
        s = named_spectrum(kind, n)
        assert (np.diff(s.wavelength_nm) > 0).all() and (s.values >= 0).all() and "colour" in s.source


def test_cie_a_is_plancks_law_at_2856_k() -> None:
    """CIE A is defined as a blackbody at 2848 K (c2 = 1.435e-2 m K) normalised to 100 at 560 nm:
    the package's table agrees with that closed form."""
    s = named_spectrum("light", "A")
    wl = s.wavelength_nm * 1e-9
    planck = wl**-5 / np.expm1(1.435e-2 / (wl * 2848.0))
    planck *= 100.0 / float(np.interp(560e-9, wl, planck))
    np.testing.assert_allclose(s.values, planck, rtol=2e-4)


def test_unknown_names_get_a_hint() -> None:
    with pytest.raises(ConfigError) as err:
        make_cfg(lights={"strong": {"spectrum": "CIE A"}})
    assert "did you mean 'A'" in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(ConfigError, match="did you mean 'ColorChecker N Ohta/dark skin'"):
        make_cfg(target={"reflectance_spectrum": "ColorChecker N Ohta/darkskin"})
    with pytest.raises(ConfigError, match="sensor.qe_spectrum"):
        make_cfg(sensor={"qe_spectrum": "Nikon 5200/green"})
    with pytest.raises(ConfigError, match="both set"):
        make_cfg(sensor={"qe_spectrum": "Nikon 5100 (NPL)/green", "qe_curve": [[4e-7, 0.5], [7e-7, 0.5]]})


def test_csv_spectra(tmp_path: Path) -> None:
    (tmp_path / "lamp.csv").write_text("# a lamp\nwavelength_m,power\n4e-7,1\n5e-7,2\n7e-7,3\n")
    s = read_spectrum_csv(tmp_path / "lamp.csv", "lamp")
    np.testing.assert_allclose(s.wavelength_nm, [400, 500, 700])
    assert s.at(np.array([450.0]))[0] == pytest.approx(1.5) and "sha256" in s.source
    for text, words in (("wavelength_nm,a,b\n400,1,2\n500,1,2\n", "one value column"),
                        ("nm,a\n400,1\n500,1\n", "wavelength_nm"),
                        ("wavelength_nm,a\n500,1\n400,1\n", "increase"),
                        ("wavelength_nm,a\n400,-1\n500,1\n", "negative")):
        (tmp_path / "bad.csv").write_text(text)
        with pytest.raises(BenchSimError, match=words):
            read_spectrum_csv(tmp_path / "bad.csv", "bad")
    assert load_spectrum("light", f"csv:{tmp_path / 'lamp.csv'}", "k").values.tolist() == [1.0, 2.0, 3.0]


def test_a_spectrum_must_cover_the_band(tmp_path: Path) -> None:
    (tmp_path / "narrow.csv").write_text("wavelength_nm,r\n450,0.5\n650,0.5\n")
    narrow = f"csv:{tmp_path / 'narrow.csv'}"
    cfg = make_cfg(render={"spectral": True}, target={"reflectance_spectrum": narrow})
    with pytest.raises(BenchSimError, match="covers 450..650 nm; render.band_m needs 400..700 nm"):
        check_spectra(cfg)
    assert check_spectra(make_cfg()) == {}


def test_spectrum_csv_relative_to_the_config(tmp_path: Path) -> None:
    (tmp_path / "paper.csv").write_text("wavelength_nm,r\n380,0.8\n780,0.9\n")
    rig = Path(__file__).resolve().parents[2] / "scenes" / "paper_rig.toml"
    (tmp_path / "b.toml").write_text(f'base = "{rig}"\n[target]\nreflectance_spectrum = "csv:paper.csv"\n')
    from bench_sim.config import load_config

    with pytest.warns(UserWarning, match="render.spectral = false"):
        cfg = load_config(tmp_path / "b.toml")
    assert cfg.target.reflectance_spectrum == f"csv:{(tmp_path / 'paper.csv').resolve()}"


def test_config_keys_lists_the_names() -> None:
    r = runner.invoke(app, ["config", "keys", "lights.strong"])
    assert r.exit_code == 0 and "FL3.15" in r.stdout and "LED-B5" in r.stdout and "Kinoton 75P" in r.stdout
    r = runner.invoke(app, ["config", "keys", "target"])
    assert "ColorChecker N Ohta/dark skin" in r.stdout
    r = runner.invoke(app, ["config", "keys", "sensor"])
    assert "Nikon 5100 (NPL)/green" in r.stdout


def test_looking_up_a_name_keeps_numpys_print_options() -> None:
    """colour-science's import sets numpy's print options to 1.13's (``str`` of a float64 to 12
    digits) for the whole process; bench_sim keeps them as they were (a fresh process)."""
    import subprocess
    import sys

    code = ("import numpy as np; from bench_sim.io.spectral_data import named_spectrum; "
            "named_spectrum('light', 'A'); print(np.get_printoptions()['legacy'], str(np.float64(1 / 3)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", "0.3333333333333333"]
