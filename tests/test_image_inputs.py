"""The image inputs of the commands added since the audit (issue 32), each refused in one line,
exit status 2, before any decoder and with nothing written: ``mtf`` of a photograph and of a
``simulate`` TIFF set, ``calibrate`` of a folder of images (``frames.csv``) and of a frames
``.npz``, for an empty image (0 x 0) and a header claiming 10^10 pixels (as ``fuse`` and ``mtf``
of an NPY are in ``tests/test_bad_inputs.py``). Two cases run as real processes."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from bench_sim.cli import app
from tests.io.test_image_header import _claim_png, _claim_tiff

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()
#: 10^10 pixels: more than every bound (MAX_IMAGE_PIXELS, Pillow's)
SIDE = 100_000


def _files(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


def _png(width: int, height: int) -> Callable[[Path], Path]:
    def make(folder: Path) -> Path:
        return _claim_png(folder, width, height)

    return make


def _photo(make: Callable[[Path], Path]) -> Callable[[Path], list[str]]:
    """``mtf`` of the image file ``make`` writes."""

    def args(folder: Path) -> list[str]:
        return ["mtf", str(make(folder)), "--out", str(folder / "out")]

    return args


def _tiff_set(width: int, height: int) -> Callable[[Path], list[str]]:
    """``mtf`` of a ``simulate --format tiff`` set whose stage image claims ``width x height``."""

    def args(folder: Path) -> list[str]:
        sim = folder / "sim"
        sim.mkdir()
        _claim_tiff(sim, width, height).rename(sim / "stage_002_dn.tiff")
        meta = {"files": {"stage_002_dn.tiff": {"variable": "dn", "stage": 2}}, "config": {}}
        (sim / "meta.json").write_text(json.dumps(meta))
        return ["mtf", str(sim), "--out", str(folder / "out")]

    return args


def _frames_folder(width: int, height: int) -> Callable[[Path], list[str]]:
    """``calibrate`` of a folder of images whose second flat claims ``width x height``."""

    def args(folder: Path) -> list[str]:
        lab = folder / "lab"
        lab.mkdir()
        np.save(lab / "f0.npy", np.full((4, 4), 100, np.uint16))
        _claim_png(lab, width, height).rename(lab / "f1.png")
        (lab / "frames.csv").write_text("file,kind,exposure_s\nf0.npy,flat,1e-3\nf1.png,flat,1e-3\n")
        return ["calibrate", str(lab), "--out", str(folder / "out")]

    return args


def _npz_claiming(shape: tuple[int, ...]) -> Callable[[Path], list[str]]:
    """``calibrate`` of a frames ``.npz`` whose ``flats`` header claims ``shape`` (no data follows)."""

    def args(folder: Path) -> list[str]:
        path = folder / "frames.npz"
        with zipfile.ZipFile(path, "w") as zf:
            for name, arr in (("exposure_s", np.full(3, 1e-3)), ("darks", np.zeros((3, 2, 4, 4)))):
                with zf.open(f"{name}.npy", "w") as f:
                    np.lib.format.write_array(f, arr)
            with zf.open("flats.npy", "w") as f:
                header = {"descr": "<u2", "fortran_order": False, "shape": shape}
                np.lib.format.write_array_header_1_0(f, header)
        return ["calibrate", str(path), "--out", str(folder / "out")]

    return args


CASES: dict[str, tuple[Callable[[Path], list[str]], list[str]]] = {
    "mtf photo 0 x 0": (_photo(_png(0, 0)), ["c.png", "empty image (0 x 0 pixels)"]),
    "mtf photo 10^10 pixels": (_photo(_png(SIDE, SIDE)), ["c.png", f"{SIDE * SIDE} pixels: more than"]),
    "mtf tiff set 0 x 0": (_tiff_set(0, 0), ["stage_002_dn.tiff", "empty image (0 x 0 pixels)"]),
    "mtf tiff set 10^10 pixels": (_tiff_set(SIDE, SIDE), ["stage_002_dn.tiff", f"{SIDE * SIDE} pixels"]),
    "calibrate folder 0 x 0": (_frames_folder(0, 0), ["f1.png", "empty image (0 x 0 pixels)"]),
    "calibrate folder 10^10 pixels": (_frames_folder(SIDE, SIDE), ["f1.png", f"{SIDE * SIDE} pixels"]),
    "calibrate npz empty images": (_npz_claiming((3, 2, 0, 0)), ["frames.npz", "'flats' holds empty images"]),
    "calibrate npz 10^10 pixels": (_npz_claiming((3, 2, SIDE, SIDE)), ["frames.npz", "headers claim"]),
}


@pytest.mark.parametrize("case", list(CASES))
def test_an_empty_or_huge_image_is_one_line(
    tmp_path: Path, case: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    make, needles = CASES[case]
    args = make(tmp_path)
    before = _files(tmp_path)

    def no_decoder(*a: object, **k: object) -> None:
        raise AssertionError("a decoder ran")

    monkeypatch.setattr("bench_sim.io.images.read_image_data", no_decoder)
    monkeypatch.setattr("tifffile.imread", no_decoder)
    res = runner.invoke(app, args)
    lines = res.stderr.splitlines()
    assert res.exit_code == 2, (res.exit_code, res.stdout[-400:], res.stderr[-1200:])
    assert len(lines) == 1 and lines[0].startswith("bench-sim: error: "), res.stderr
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    assert _files(tmp_path) == before


@pytest.mark.parametrize("case", ["mtf photo 10^10 pixels", "calibrate folder 0 x 0"])
def test_in_a_real_process(tmp_path: Path, case: str) -> None:
    """The same in a process of its own (the CLI's exit status and its one line on stderr)."""
    make, needles = CASES[case]
    args = make(tmp_path)
    before = _files(tmp_path)
    env = {**os.environ, "PYTHONPATH": str(ROOT), "BENCH_SIM_THREADS": "1"}
    res = subprocess.run([sys.executable, "-m", "bench_sim", *args], env=env, capture_output=True, text=True,
                         timeout=120)
    lines = res.stderr.splitlines()
    assert res.returncode == 2 and len(lines) == 1, res.stderr
    assert all(n in lines[0] for n in needles), lines[0]
    assert _files(tmp_path) == before
