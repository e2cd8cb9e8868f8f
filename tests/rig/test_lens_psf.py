"""The lens' OTF (bench_sim.rig.lens_psf) and its blur of the texture (bench_sim.render.lens_blur)
against closed forms: the round pupil's autocorrelation, a Gaussian PSF's transform, a
sinusoid's contrast; the measured MTF table read as given; the Nyquist warning."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from bench_sim.config import ConfigError, load_config
from bench_sim.errors import BenchSimError
from bench_sim.render.lens_blur import texture_lens
from bench_sim.rig.geometry import rig_geometry
from bench_sim.rig.lens_psf import (
    diffraction_mtf,
    lens_otf,
    spectral_weights,
    system_mtf_across,
    working_f_number,
)
from bench_sim.workflows.preflight import nyquist_warning
from tests.conftest import make_cfg

pytestmark = pytest.mark.physics


def test_diffraction_otf_is_the_pupils_autocorrelation() -> None:
    """The incoherent OTF of a round pupil is its normalised autocorrelation: overlap of a disc of
    radius P (samples) with itself shifted by s is D at x = s / (2 P); computed here by FFT of a
    drawn disc."""
    n, radius = 1024, 200.0
    y, x = np.mgrid[0:n, 0:n] - n // 2
    pupil = (np.hypot(y, x) <= radius).astype(np.float64)
    auto = np.real(np.fft.ifft2(np.abs(np.fft.fft2(pupil)) ** 2))
    auto /= auto[0, 0]
    lam, nw = 550e-9, 4.0
    for s in (0, 40, 100, 200, 300, 390):
        nu = s / (2 * radius) / (lam * nw)  # x = nu lambda N_w
        assert float(diffraction_mtf(np.array([nu]), lam, nw)[0]) == pytest.approx(auto[0, s], abs=2e-3), s
    assert float(diffraction_mtf(np.array([1.0 / (lam * nw) * 1.01]), lam, nw)[0]) == 0.0


def test_default_lens_is_diffraction_at_the_working_f_number() -> None:
    cfg = load_config()
    otf = lens_otf(cfg)
    assert otf is not None and otf.kind == "diffraction"
    nw = cfg.lens.f_number * (1 + cfg.lens.magnification)
    assert working_f_number(cfg) == pytest.approx(nw)
    nyq = 0.5 / cfg.sensor.pixel_pitch_m
    assert float(otf.grid(np.array([nyq]), np.array([0.0]))[0, 0]) == pytest.approx(
        float(diffraction_mtf(np.array([nyq]), 550e-9, nw)[0]))
    assert lens_otf(make_cfg(lens={"diffraction": False})) is None


def test_spectral_diffraction_weights_the_band() -> None:
    wl, w = spectral_weights(make_cfg(render={"spectral": True}))
    assert w.sum() == pytest.approx(1.0) and (w >= 0).all()
    assert wl.min() == pytest.approx(400e-9) and wl.max() == pytest.approx(700e-9)
    mono = spectral_weights(make_cfg())
    assert mono[0].tolist() == [550e-9] and mono[1].tolist() == [1.0]


def _write_mtf(path: Path, nu: np.ndarray, sag: np.ndarray, tan: np.ndarray) -> Path:
    path.write_text("# a lens\nfrequency_cyc_mm,mtf_sagittal,mtf_tangential\n"
                    + "\n".join(f"{a:g},{b:.6g},{c:.6g}" for a, b, c in zip(nu, sag, tan, strict=True)))
    return path


def test_mtf_file_is_read_as_given(tmp_path: Path) -> None:
    """Tangential across the track (x), sagittal along it (y), blended in between; normalised at
    0; past the table's end it falls as diffraction does."""
    nu = np.linspace(0, 200, 21)
    tan, sag = 0.98 * np.exp(-(nu / 90.0) ** 2), 0.98 * np.exp(-nu / 150.0)
    cfg = make_cfg(lens={"mtf_file": str(_write_mtf(tmp_path / "l.csv", nu, sag, tan))})
    otf = lens_otf(cfg)
    assert otf is not None and otf.kind == "mtf_file" and "sha256" in otf.source
    f = np.array([0.0, 50e3, 120e3])
    # (the table is written to 6 digits)
    np.testing.assert_allclose(otf.grid(np.zeros(1), f)[0], np.interp(f / 1e3, nu, tan) / 0.98, rtol=1e-5)
    np.testing.assert_allclose(otf.grid(f, np.zeros(1))[:, 0], np.interp(f / 1e3, nu, sag) / 0.98, rtol=1e-5)
    diag = otf.grid(np.array([80e3]) / math.sqrt(2), np.array([80e3]) / math.sqrt(2))[0, 0]
    assert diag == pytest.approx(0.5 * (np.interp(80, nu, tan) + np.interp(80, nu, sag)) / 0.98, rel=1e-5)
    nw = working_f_number(cfg)
    far = 300e3
    want = tan[-1] / 0.98 * diffraction_mtf(np.array([far]), 550e-9, nw)[0] / diffraction_mtf(
        np.array([200e3]), 550e-9, nw)[0]
    assert otf.grid(np.zeros(1), np.array([far]))[0, 0] == pytest.approx(want, rel=1e-5)


def test_psf_file_gives_its_transform(tmp_path: Path) -> None:
    """A sampled Gaussian PSF of rms sigma, off centre: |OTF| = exp(-2 pi^2 sigma^2 nu^2), no
    phase (taken about the centroid)."""
    sigma, pix = 3e-6, 0.5e-6
    y, x = (np.mgrid[0:81, 0:81] - np.array([38.3, 41.6])[:, None, None]) * pix
    np.save(tmp_path / "psf.npy", np.exp(-(x * x + y * y) / (2 * sigma**2)))
    cfg = make_cfg(lens={"psf_file": str(tmp_path / "psf.npy"), "psf_pixel_m": pix})
    otf = lens_otf(cfg)
    assert otf is not None and otf.kind == "psf_file"
    nu = np.array([0.0, 20e3, 60e3, 100e3])
    h = otf.grid(np.zeros(1), nu)[0]
    np.testing.assert_allclose(np.abs(h), np.exp(-2 * np.pi**2 * sigma**2 * nu**2), atol=2e-3)
    assert np.abs(h.imag).max() < 2e-3
    np.testing.assert_allclose(np.abs(otf.grid(nu, np.zeros(1))[:, 0]), np.abs(h), atol=2e-3)


def test_bad_lens_files(tmp_path: Path) -> None:
    (tmp_path / "bad.csv").write_text("frequency_cyc_mm,mtf\n10,0.9\n5,0.8\n")
    with pytest.raises(BenchSimError, match="start at 0 and increase"):
        lens_otf(make_cfg(lens={"mtf_file": str(tmp_path / "bad.csv")}))
    (tmp_path / "cols.csv").write_text("nu,mtf\n0,1\n5,0.8\n")
    with pytest.raises(BenchSimError, match="frequency_cyc_mm"):
        lens_otf(make_cfg(lens={"mtf_file": str(tmp_path / "cols.csv")}))
    with pytest.raises(ConfigError, match="both set"):
        make_cfg(lens={"mtf_file": "a.csv", "psf_file": "b.npy", "psf_pixel_m": 1e-6})
    with pytest.raises(ConfigError, match="psf_pixel_m"):
        make_cfg(lens={"psf_file": "b.npy"})


def test_lens_file_relative_to_the_config(tmp_path: Path) -> None:
    nu = np.linspace(0, 200, 5)
    _write_mtf(tmp_path / "lens.csv", nu, np.ones(5), np.ones(5))
    rig = Path(__file__).resolve().parents[2] / "scenes" / "paper_rig.toml"
    (tmp_path / "bench.toml").write_text(f'base = "{rig}"\n[lens]\nmtf_file = "lens.csv"\n')
    assert load_config(tmp_path / "bench.toml").lens.mtf_file == str((tmp_path / "lens.csv").resolve())


@pytest.mark.parametrize("axis", [0, 1])
def test_texture_blur_has_the_lens_transfer(axis: int) -> None:
    """A sinusoid on the texture keeps its mean and loses contrast by D at its frequency, along
    (rows) and across (columns) the track."""
    cfg = load_config()
    geom = rig_geometry(cfg)
    q = cfg.target.texels_per_pixel
    lens = texture_lens(cfg, geom, geom.delta_m / q, geom.object_pixel_m / q)
    assert lens is not None
    nw = working_f_number(cfg)
    rows, cols = 256 + 2 * lens.margin_rows, 512
    for f_px in (0.25, 0.5, 1.0):
        yy, xx = np.mgrid[0:rows, 0:cols] / q
        tex = 0.5 + 0.3 * np.cos(2 * np.pi * f_px * (yy if axis == 0 else xx))
        out = lens.apply(tex, 0, 0)
        line = out[:, 200] if axis == 0 else out[100]
        ref = tex[lens.margin_rows:-lens.margin_rows][:, 200] if axis == 0 else tex[100]
        k = int(np.argmax(np.abs(np.fft.rfft(ref - ref.mean()))))
        ratio = abs(np.fft.rfft(line)[k]) / abs(np.fft.rfft(ref)[k])
        want = float(diffraction_mtf(np.array([f_px / cfg.sensor.pixel_pitch_m]), 550e-9, nw)[0])
        assert ratio == pytest.approx(want, abs=2e-3), (f_px, axis)
        assert line.mean() == pytest.approx(ref.mean(), abs=1e-3)


def test_nyquist_warning_for_a_perfect_lens() -> None:
    """Lens x pixel aperture: with diffraction the default rig stays below Nyquist; a perfect
    lens leaves sinc(f), whose MTF50 is 0.6034 cycles/px (sinc(f) = 0.5)."""
    cfg = load_config()
    f = np.linspace(0, 1, 2001)
    assert system_mtf_across(cfg, f)[np.searchsorted(f, 0.5)] < 0.5
    assert nyquist_warning(cfg) is None
    line = nyquist_warning(make_cfg(lens={"diffraction": False}))
    assert line is not None and "0.603 cycles/px" in line and "lens.diffraction = false" in line


def test_narrow_band_diffraction_is_the_mono_one() -> None:
    """Spectral mode weights the band's wavelengths; a 2-nm band around 550 nm is the mono lens."""
    nu = np.linspace(0, 400e3, 9)
    mono = lens_otf(make_cfg())
    narrow = lens_otf(make_cfg(render={"spectral": True, "band_m": [549e-9, 551e-9]}))
    broad = lens_otf(make_cfg(render={"spectral": True}))
    assert mono is not None and narrow is not None and broad is not None
    np.testing.assert_allclose(narrow.grid(np.zeros(1), nu), mono.grid(np.zeros(1), nu), atol=2e-3)
    assert "400..700 nm" in broad.source
    assert not np.allclose(broad.grid(np.zeros(1), nu), mono.grid(np.zeros(1), nu), atol=2e-3)
