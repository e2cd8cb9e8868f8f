"""``bench-sim mtf``: the e-SFR of a user's image, its files, and one line / exit 2 for bad input."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from bench_sim.cli import app
from bench_sim.io import read_png_text, write_exr
from bench_sim.metrics.sfr import mtf50
from tests.metrics.test_sfr import edge_image, expected

runner = CliRunner()


def _files(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


def _refused(args: list[str], folder: Path, *needles: str) -> None:
    before = _files(folder)
    result = runner.invoke(app, ["mtf", *args, "--out", str(folder / "out")])
    lines = result.stderr.splitlines()
    assert result.exit_code == 2, (result.exit_code, result.stdout, result.stderr)
    assert len(lines) == 1 and lines[0].startswith("bench-sim: error: "), result.stderr
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    assert _files(folder) == before, "files were left behind"


def _scene(angle: float = 5.0, sigma: float = 0.8) -> np.ndarray:
    """A 120 x 160 image: the edge in a 64 x 48 window at (x 40.., y 30..), flat around it."""
    img = np.full((120, 160), 100.0)
    img[30:94, 40:88] = edge_image((64, 48), angle, sigma=sigma)
    img[30:94, 88:] = 400.0
    img[94:, :] = 400.0
    return img


@pytest.mark.physics
def test_mtf_of_an_npy_image(tmp_path: Path) -> None:
    src = tmp_path / "edge.npy"
    np.save(src, _scene())
    out = tmp_path / "res"
    result = runner.invoke(app, ["mtf", str(src), "--roi", "40,30,88,94", "--pixel-pitch-um", "5.5",
                                 "--out", str(out)])
    assert result.exit_code == 0, result.stderr
    assert "vertical edge at 5.00 deg" in result.stdout and "along the edge normal" in result.stdout
    assert {"edges.csv", "sfr.csv", "sfr.png", "rois.png", "summary.json"} <= _files(out)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["frequency_axis"].startswith("along the edge normal")
    edge = summary["edges"][0]
    with (out / "sfr.csv").open() as fh:
        rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))
    f = np.array([float(r["frequency_cyc_px"]) for r in rows])
    s = np.array([float(r["sfr"]) for r in rows])
    np.testing.assert_allclose([float(r["frequency_cyc_mm"]) for r in rows], f / 5.5e-3, rtol=1e-9)
    want = expected(f, 5.0, sigma=0.8)
    assert np.abs(s - want)[f <= 0.5].max() < 0.02
    assert edge["mtf50_cyc_px"] == pytest.approx(mtf50(f, want), rel=0.03)
    assert edge["mtf50_cyc_mm"] == pytest.approx(edge["mtf50_cyc_px"] / 5.5e-3)
    assert edge["mtf50p_cyc_px"] == pytest.approx(edge["mtf50_cyc_px"]) and not edge["sharpened"]
    assert edge["roi"] == [40, 30, 88, 94] and edge["orientation"] == "vertical"
    assert summary["version"] and len(summary["input"]["sha256"]) == 64
    assert read_png_text(out / "sfr.png")["command"] == "mtf"


def test_mtf_reads_png_tiff_exr_bmp_and_jpeg_alike(tmp_path: Path) -> None:
    import tifffile
    from PIL import Image

    img = np.round(_scene(angle=4.0) * 100).astype(np.uint16)  # 10000 .. 40000: no clipping
    Image.fromarray(img).save(tmp_path / "edge.png")
    tifffile.imwrite(tmp_path / "edge.tiff", img)
    write_exr(tmp_path / "edge.exr", {"Y": img.astype(np.float32)}, {})
    img8 = np.round(_scene(angle=4.0) * 0.5).astype(np.uint8)  # 50 .. 200
    Image.fromarray(img8).save(tmp_path / "edge.bmp")
    Image.fromarray(img8).save(tmp_path / "edge.jpg", quality=98)
    got = []
    for name in ("edge.png", "edge.tiff", "edge.exr", "edge.bmp", "edge.jpg"):
        out = tmp_path / f"out_{name}"
        extra = ["--encoding", "linear"] if name.endswith(".jpg") else []
        args = ["mtf", str(tmp_path / name), "--roi", "40,30,88,94", *extra, "--out", str(out)]
        result = runner.invoke(app, args)
        assert result.exit_code == 0, result.stderr
        got.append(json.loads((out / "summary.json").read_text())["edges"][0]["mtf50_cyc_px"])
    assert got[0] == pytest.approx(got[1], rel=1e-9) and got[0] == pytest.approx(got[2], rel=1e-6)
    assert got[3] == pytest.approx(got[0], rel=0.01)  # 8 bits: quantised
    assert got[4] == pytest.approx(got[0], rel=0.05)  # JPEG: lossy
    summary = json.loads((tmp_path / "out_edge.jpg" / "summary.json").read_text())
    assert summary["encoding"] == "linear"


def _save(tmp_path: Path, name: str, img: Any) -> str:
    path = tmp_path / name
    if name.endswith(".npy"):
        np.save(path, img)
    else:
        from PIL import Image

        Image.fromarray(img).save(path)
    return str(path)


def test_bad_inputs_one_line_exit_2(tmp_path: Path) -> None:
    scene = _save(tmp_path, "scene.npy", _scene())
    _refused([scene, "--roi", "100,0,160,25"], tmp_path, "no edge")  # a flat corner
    axis = np.full((64, 48), 100.0)
    axis[:, 24:] = 400.0
    _refused([_save(tmp_path, "axis.npy", axis)], tmp_path, "no usable slanted edge", "edge angle 0.00 deg",
             "allowed 1..40")
    diag = edge_image((64, 64), 45.0, sigma=0.7)
    _refused([_save(tmp_path, "diag.npy", diag), "--roi", "0,0,64,64"], tmp_path, "edge angle 4",
             "to the rows: allowed 1..40")
    _refused([_save(tmp_path, "flat.npy", np.full((64, 64), 7.0))], tmp_path, "no edge found", "--roi")
    clipped = np.clip(np.round(_scene() * 0.7), 0, 255).astype(np.uint8)  # the bright side at 255
    _refused([_save(tmp_path, "clipped.png", clipped), "--roi", "40,30,88,94"], tmp_path,
             "clipped edge", "(255)")
    _refused([scene, "--roi", "40,30,46,94"], tmp_path, "too small")
    _refused([scene, "--roi", "40,30,88,94", "--saturation", "390"], tmp_path, "clipped edge")
    _refused([scene, "--roi", "40,30,88"], tmp_path, "--roi = '40,30,88'", "four integers")
    _refused([scene, "--roi", "40,30,88,200"], tmp_path, "--roi", "0 <= y0 < y1 <= 120")
    _refused([scene, "--pixel-pitch-um", "-1"], tmp_path, "--pixel-pitch-um = -1.0")
    _refused([str(tmp_path / "missing.npy")], tmp_path, "missing.npy", "no such file")
    (tmp_path / "notes.txt").write_text("x")
    _refused([str(tmp_path / "notes.txt")], tmp_path, "unsupported file type")
    rgb = np.stack([np.round(_scene() * 0.5).astype(np.uint8)] * 3, axis=-1)
    _refused([_save(tmp_path, "rgb.png", rgb)], tmp_path, "a colour image", "--channel R, G, B or Y")
    _refused([_save(tmp_path, "rgb2.png", rgb), "--channel", "Q"], tmp_path, "--channel = 'Q'")
    _refused([scene, "--mask", _save(tmp_path, "small.npy", np.ones((5, 5)))], tmp_path, "--mask", "size")
    _refused([scene, "--encoding", "gamma"], tmp_path, "--encoding = 'gamma'")
    _refused([scene, "--frequency-axis", "rows"], tmp_path, "--frequency-axis = 'rows'")
