"""``bench-sim fuse``: happy path, determinism, and clean failures on bad input (must show 5)."""

from __future__ import annotations

import json
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import tifffile
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from bench_sim.cli import app
from bench_sim.fusion import FUSE_METHODS, fuse_dtdi_hdr_eq11, fuse_pair
from bench_sim.io import read_image, write_exr, write_png

runner = CliRunner()


def _exr(path: Path) -> tuple[dict[str, np.ndarray], dict]:
    """Channels and bench_sim metadata of an EXR (header copied while the file is open)."""
    import OpenEXR

    with OpenEXR.File(str(path), separate_channels=True) as f:
        header = dict(f.header())
        channels = {name: np.array(ch.pixels) for name, ch in f.channels().items()}
    return channels, json.loads(header["bench_sim"])


def _pair(rng: np.random.Generator, shape: tuple[int, int] = (12, 17)) -> tuple[np.ndarray, np.ndarray]:
    s = rng.uniform(0, 409.5, shape)  # per-read signal [DN]
    return np.minimum(np.round(10 * s), 4095), np.minimum(np.round(80 * s), 4095)


def _fuse(*args: str) -> object:
    return runner.invoke(app, ["fuse", *args])


def _assert_clean_failure(result: object, folder: Path, before: set[str], *needles: str) -> None:
    assert result.exit_code == 2, (result.exit_code, result.stdout, result.stderr)  # type: ignore[attr-defined]
    err = result.stderr  # type: ignore[attr-defined]
    assert err.startswith("bench-sim: error: ") and err.endswith("\n") and err.count("\n") == 1, err
    for needle in needles:
        assert needle in err, (needle, err)
    assert {p.name for p in folder.iterdir()} == before, "an output file was left behind"


# ---------------------------------------------------------------- happy path
def test_fuse_happy_path(tmp_path: Path) -> None:
    g1, g2 = _pair(np.random.default_rng(1))
    low, high = tmp_path / "low.tif", tmp_path / "high.png"
    tifffile.imwrite(low, g1.astype(np.uint16))
    write_png(high, g2.astype(np.uint16))
    out, tra = tmp_path / "res" / "hdr.exr", tmp_path / "res" / "tra.png"
    r = _fuse(str(low), str(high), "--mu1", "10", "--mu2", "80", "--beta", "12",
              "--out", str(out), "--tra", str(tra))
    assert r.exit_code == 0, r.stderr
    channels, meta = _exr(out)
    expected = fuse_dtdi_hdr_eq11(g1, g2, mu1=10, mu2=80, beta=12)
    np.testing.assert_array_equal(channels["Y"], expected.hdr.astype(np.float32))
    np.testing.assert_array_equal(channels["source"], expected.source)
    assert (meta["mu1"], meta["mu2"], meta["beta"], meta["phi_fs_dn"]) == (10, 80, 12, 4096)
    assert meta["threshold_dn"] == 512.0 and meta["full_scale_dn"] == 8 * 4095
    assert meta["inputs"]["low"]["path"] == str(low) and len(meta["inputs"]["high"]["sha256"]) == 64
    assert meta["version"] and meta["pixels_from_low"] == int((expected.source == 10).sum())
    display = read_image(tra)
    assert display.shape == g1.shape and display.max() <= 255 and display.max() > 200
    # the HDR file reads back as the fused image (channel Y)
    np.testing.assert_array_equal(read_image(out), expected.hdr.astype(np.float32))


@pytest.mark.physics
@pytest.mark.parametrize("pedestal", [0, 64, 300])
def test_fuse_pedestal_keeps_the_noise_free_response_linear(tmp_path: Path, pedestal: int) -> None:
    """Noise-free words carrying a pedestal P: with ``--pedestal P`` the fused response is
    ``(mu2/mu1) * signal1`` across the switch (to the 1-DN clip step of eq. 11); without it the
    dark end is off by P."""
    s1 = np.arange(0, 4096 - pedestal, 7, dtype=np.float64)[None, :]  # stage-10 signal [DN]
    s2 = np.minimum(8 * s1, 4095 - pedestal)
    np.save(tmp_path / "low.npy", (s1 + pedestal).astype(np.int32))
    np.save(tmp_path / "high.npy", (s2 + pedestal).astype(np.int32))
    args = [str(tmp_path / "low.npy"), str(tmp_path / "high.npy"), "--mu1", "10", "--mu2", "80"]
    r = _fuse(*args, "--pedestal", str(pedestal), "--out", str(tmp_path / "p.exr"))
    assert r.exit_code == 0, r.stderr  # type: ignore[attr-defined]
    channels, meta = _exr(tmp_path / "p.exr")
    assert np.all(np.abs(channels["Y"] - 8 * s1) <= 1.0)
    assert meta["pedestal_dn"] == pedestal and meta["threshold_dn"] == (4096 - pedestal) / 8
    if pedestal:
        _fuse(*args, "--out", str(tmp_path / "n.exr"))
        plain, _ = _exr(tmp_path / "n.exr")
        assert plain["Y"][0, 0] - 8 * s1[0, 0] == pedestal  # the offset left in


@pytest.mark.parametrize("method", list(FUSE_METHODS))
def test_fuse_method_is_applied_and_recorded(tmp_path: Path, method: str) -> None:
    """``--method``: the file is that rule's fusion (pedestal 64 removed) and says which rule."""
    s = np.linspace(0.0, 100.0, 240)[None, :]  # signal per row over rows 0..9 [DN]
    g1 = np.minimum(np.round(10 * s) + 64, 4095)
    g2 = np.minimum(np.round(150 * s) + 64, 4095)  # light doubles after row 10: Gamma2 = 15 Gamma1
    np.save(tmp_path / "low.npy", g1.astype(np.int32))
    np.save(tmp_path / "high.npy", g2.astype(np.int32))
    args = [str(tmp_path / "low.npy"), str(tmp_path / "high.npy"), "--pedestal", "64"]
    r = _fuse(*args, "--method", method, "--out", str(tmp_path / "m.exr"), "--tra", str(tmp_path / "m.png"))
    assert r.exit_code == 0, r.stderr  # type: ignore[attr-defined]
    channels, meta = _exr(tmp_path / "m.exr")
    want = fuse_pair(g1, g2, method=method, mu1=10, mu2=80, beta=12, pedestal_dn=64.0)
    np.testing.assert_array_equal(channels["Y"], want.hdr.astype(np.float32))
    assert meta["method"] == method and meta["method_description"] == FUSE_METHODS[method]
    n_clipped = int(((want.source == 80) & (g2 >= 4095)).sum())
    assert meta["pixels_from_clipped_high"] == n_clipped
    assert (n_clipped > 0) == (method == "eq11")  # the clip rule never takes a clipped Gamma2
    assert f"method {method};" in r.stdout and f"{n_clipped} pixels from a clipped Gamma2" in r.stdout  # type: ignore[attr-defined]


def test_fuse_unknown_method_fails_before_any_work(tmp_path: Path) -> None:
    # the inputs do not even exist: the method is checked first
    before = {p.name for p in tmp_path.iterdir()}
    r = _fuse(str(tmp_path / "nope1.tif"), str(tmp_path / "nope2.tif"), "--method", "median",
              "--out", str(tmp_path / "o.exr"))
    _assert_clean_failure(r, tmp_path, before, "--method = 'median'", "allowed eq11, clip")


def test_fuse_npy_and_exr_inputs_and_determinism(tmp_path: Path) -> None:
    g1, g2 = _pair(np.random.default_rng(2))
    np.save(tmp_path / "low.npy", g1.astype(np.int32))
    write_exr(tmp_path / "high.exr", {"Y": g2})
    args = [str(tmp_path / "low.npy"), str(tmp_path / "high.exr"), "--mu1", "10", "--mu2", "80"]
    r1 = _fuse(*args, "--out", str(tmp_path / "a.exr"), "--tra", str(tmp_path / "a.png"))
    r2 = _fuse(*args, "--out", str(tmp_path / "b.exr"), "--tra", str(tmp_path / "b.png"))
    assert r1.exit_code == 0 and r2.exit_code == 0, (r1.stderr, r2.stderr)
    (ca, ma), (cb, mb) = _exr(tmp_path / "a.exr"), _exr(tmp_path / "b.exr")
    for name in ("Y", "source"):
        np.testing.assert_array_equal(ca[name], cb[name])
    assert ma == mb
    np.testing.assert_array_equal(read_image(tmp_path / "a.png"), read_image(tmp_path / "b.png"))


# ---------------------------------------------------------------- bad inputs
def _write_npy(arr: np.ndarray) -> Callable[[Path], Path]:
    def make(folder: Path) -> Path:
        p = folder / "bad.npy"
        np.save(p, arr)
        return p

    return make


def _good_low(folder: Path) -> Path:
    p = folder / "low.npy"
    np.save(p, np.full((4, 5), 100, dtype=np.uint16))
    return p


def _good_high(folder: Path) -> Path:
    p = folder / "high.npy"
    np.save(p, np.full((4, 5), 800, dtype=np.uint16))
    return p


def _text_file(folder: Path) -> Path:
    p = folder / "notes.txt"
    p.write_text("not an image")
    return p


def _corrupt_tif(folder: Path) -> Path:
    p = folder / "broken.tif"
    p.write_bytes(b"II*\x00garbage")
    return p


BAD_HIGH = [
    ("shape", _write_npy(np.full((4, 6), 800)), ["bad.npy", "shape (4, 6)", "(4, 5)"]),
    ("above", _write_npy(np.full((4, 5), 4096)), ["bad.npy", "4096", "0..4095"]),
    ("negative", _write_npy(np.full((4, 5), -1.0)), ["bad.npy", "-1", "negative"]),
    ("nan", _write_npy(np.full((4, 5), np.nan)), ["bad.npy", "nan", "finite"]),
    ("inf", _write_npy(np.full((4, 5), np.inf)), ["bad.npy", "inf"]),
    ("fraction", _write_npy(np.full((4, 5), 0.25)), ["bad.npy", "0.25", "not an integer"]),
    ("3d", _write_npy(np.zeros((2, 4, 5))), ["bad.npy", "shape (2, 4, 5)"]),
    ("empty", _write_npy(np.zeros((0, 5))), ["bad.npy", "empty"]),
    ("text", _text_file, ["notes.txt", "unsupported file type", ".txt"]),
    ("corrupt", _corrupt_tif, ["broken.tif"]),
    ("missing", lambda folder: folder / "nope.tif", ["nope.tif", "no such file"]),
]


@pytest.mark.parametrize(("make", "needles"), [c[1:] for c in BAD_HIGH], ids=[c[0] for c in BAD_HIGH])
def test_fuse_bad_input_file(tmp_path: Path, make: Callable[[Path], Path], needles: list[str]) -> None:
    low = _good_low(tmp_path)
    high = make(tmp_path)
    before = {p.name for p in tmp_path.iterdir()}
    r = _fuse(str(low), str(high), "--out", str(tmp_path / "o.exr"), "--tra", str(tmp_path / "o.png"))
    _assert_clean_failure(r, tmp_path, before, *needles)


BAD_OPTIONS = [
    ("mu1>mu2", ["--mu1", "80", "--mu2", "10"], ["--mu1 = 80", "--mu2 = 10", "mu1 < mu2"]),
    ("mu1=mu2", ["--mu1", "10", "--mu2", "10"], ["mu1 < mu2"]),
    ("mu1=0", ["--mu1", "0"], ["--mu1 = 0", ">= 1"]),
    ("mu1<0", ["--mu1", "-3"], ["--mu1 = -3"]),
    ("beta=0", ["--beta", "0"], ["--beta = 0", "1..32"]),
    ("beta=33", ["--beta", "33"], ["--beta = 33", "1..32"]),
    ("beta too small for data", ["--beta", "8"], ["high.npy", "800", "0..255"]),
    ("out suffix", ["--out", "{d}/o.png"], ["--out", ".exr"]),
    ("out is dir", ["--out", "{d}/adir.exr"], ["--out", "directory"]),
    ("out is input", ["--out", "{d}/low.npy"], ["--out", ".exr"]),
    ("tra suffix", ["--tra", "{d}/t.jpg"], ["--tra", ".png"]),
    ("tra equals out", ["--out", "{d}/x.exr", "--tra", "{d}/x.exr"], ["--tra", ".png"]),
]


@pytest.mark.parametrize(("opts", "needles"), [c[1:] for c in BAD_OPTIONS], ids=[c[0] for c in BAD_OPTIONS])
def test_fuse_bad_option(tmp_path: Path, opts: list[str], needles: list[str]) -> None:
    low, high = _good_low(tmp_path), _good_high(tmp_path)
    (tmp_path / "adir.exr").mkdir()
    before = {p.name for p in tmp_path.iterdir()}
    opts = [o.replace("{d}", str(tmp_path)) for o in opts]
    if "--out" not in opts:
        opts += ["--out", str(tmp_path / "o.exr")]
    r = _fuse(str(low), str(high), *opts)
    _assert_clean_failure(r, tmp_path, before, *needles)


def test_fuse_refuses_to_overwrite_an_input_with_the_exr(tmp_path: Path) -> None:
    g1, g2 = _pair(np.random.default_rng(3))
    write_exr(tmp_path / "low.exr", {"Y": g1})
    np.save(tmp_path / "high.npy", g2)
    before = {p.name for p in tmp_path.iterdir()}
    data = (tmp_path / "low.exr").read_bytes()
    r = _fuse(str(tmp_path / "low.exr"), str(tmp_path / "high.npy"), "--out", str(tmp_path / "low.exr"))
    _assert_clean_failure(r, tmp_path, before, "--out", "input")
    assert (tmp_path / "low.exr").read_bytes() == data


# ---------------------------------------------------------------- property tests
DEFECTS = ("above", "negative", "nan", "fraction", "shape")


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    beta=st.integers(1, 16),
    shape=st.tuples(st.integers(1, 6), st.integers(1, 6)),
    defect=st.sampled_from(DEFECTS),
    which=st.sampled_from(("low", "high")),
    seed=st.integers(0, 2**32 - 1),
    where=st.floats(0, 1, exclude_max=True),
)
def test_fuse_any_defect_fails_cleanly(
    beta: int, shape: tuple[int, int], defect: str, which: str, seed: int, where: float
) -> None:
    rng = np.random.default_rng(seed)
    top = 2**beta - 1
    arrays = {k: rng.integers(0, top + 1, shape).astype(np.float64) for k in ("low", "high")}
    bad = arrays[which]
    idx = np.unravel_index(int(where * bad.size), bad.shape)
    if defect == "above":
        bad[idx] = top + 1 + rng.integers(0, 1000)
    elif defect == "negative":
        bad[idx] = -1 - rng.integers(0, 1000)
    elif defect == "nan":
        bad[idx] = np.nan
    elif defect == "fraction":
        bad[idx] = min(bad[idx], top - 1) + 0.5
    else:
        arrays[which] = np.zeros((shape[0] + 1, shape[1]))
    with tempfile.TemporaryDirectory() as d:
        folder = Path(d)
        for k, arr in arrays.items():
            np.save(folder / f"{k}.npy", arr)
        before = {p.name for p in folder.iterdir()}
        r = _fuse(str(folder / "low.npy"), str(folder / "high.npy"), "--mu1", "2", "--mu2", "5",
                  "--beta", str(beta), "--out", str(folder / "o.exr"), "--tra", str(folder / "o.png"))
        name = "high.npy" if defect == "shape" else f"{which}.npy"
        _assert_clean_failure(r, folder, before, name)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    mu1=st.integers(-5, 120),
    mu2=st.integers(-5, 120),
    beta=st.integers(-2, 40),
)
def test_fuse_stage_and_beta_options(mu1: int, mu2: int, beta: int) -> None:
    valid = 1 <= mu1 < mu2 and 1 <= beta <= 32
    with tempfile.TemporaryDirectory() as d:
        folder = Path(d)
        np.save(folder / "low.npy", np.zeros((3, 3), dtype=np.uint8))
        np.save(folder / "high.npy", np.ones((3, 3), dtype=np.uint8))
        before = {p.name for p in folder.iterdir()}
        r = _fuse(str(folder / "low.npy"), str(folder / "high.npy"), "--mu1", str(mu1), "--mu2", str(mu2),
                  "--beta", str(beta), "--out", str(folder / "o.exr"))
        if valid:
            assert r.exit_code == 0, r.stderr
            assert (folder / "o.exr").is_file()
        else:
            _assert_clean_failure(r, folder, before)
