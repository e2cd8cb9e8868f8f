"""``bench-sim mtf IMAGE`` without a ROI, on images drawn here: every edge found and measured
against its closed form, colour channels, masks and invalid pixels, the frequency axis.

The test image holds four near-vertical slanted edges of known Gaussian blur and angle, side by
side in bands of alternating polarity (so the bands meet bright to bright and dark to dark: no
other edge), each drawn analytically over the pixel squares by ``edge_image`` of
``tests/metrics/test_sfr.py``; its e-SFR's closed form is ``expected`` there (the blur, the pixel
aperture along the edge normal and the standard's 1/4-px bins).
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from bench_sim.cli import app
from bench_sim.io import read_png_text
from bench_sim.metrics.sfr import mtf50
from tests.metrics.test_sfr import HI, LO, edge_image, expected

runner = CliRunner()

#: (angle [deg], Gaussian blur sigma [px]) of the four edges, left to right
EDGES = ((5.0, 0.5), (12.0, 0.8), (20.0, 1.1), (30.0, 0.7))
#: per colour channel R, G, B: the blur of each edge [px]
CHANNEL_SIGMAS = {"R": (0.5, 0.9, 1.3, 0.6), "G": (0.7, 0.6, 0.8, 1.0), "B": (1.2, 1.4, 0.5, 0.8)}
ROWS = 160


def four_edges(sigmas: tuple[float, ...] = tuple(s for _, s in EDGES)) -> np.ndarray:
    """The four bands (module docstring), ``LO .. HI``, ``ROWS`` rows."""
    bands = []
    for i, ((angle, _), sigma) in enumerate(zip(EDGES, sigmas, strict=True)):
        width = int(math.ceil(ROWS * math.tan(math.radians(angle)))) + 90
        band = edge_image((ROWS, width), angle, sigma=sigma)
        bands.append(band[:, ::-1] if i % 2 else band)
    return np.concatenate(bands, axis=1)


def closed_mtf50(angle: float, sigmas: dict[str, float] | float) -> float:
    """MTF50 of the closed form: one blur, or the luminance of three (``sum_c w_c SFR_c``: the
    channels share the edge's geometry and step)."""
    f = np.linspace(0.0, 1.0, 4001)
    if isinstance(sigmas, float):
        return mtf50(f, expected(f, angle, sigma=sigmas))
    weights = (0.2125, 0.7154, 0.0721)  # ISO 12233's luminance
    sfr = sum(w * expected(f, angle, sigma=sigmas[c]) for w, c in zip(weights, "RGB", strict=True))
    return mtf50(f, sfr)


def _run(args: list[str], out: Path) -> dict:
    result = runner.invoke(app, ["mtf", *args, "--out", str(out)])
    assert result.exit_code == 0, (result.stdout, result.stderr)
    return json.loads((out / "summary.json").read_text())


def _by_angle(summary: dict) -> list[dict]:
    """The measured edges, matched to :data:`EDGES` by their order left to right."""
    edges = sorted(summary["edges"], key=lambda e: e["roi"][0])
    assert len(edges) == len(EDGES), [e["roi"] for e in edges]
    return edges


@pytest.mark.physics
def test_every_edge_found_and_measured(tmp_path: Path) -> None:
    """Must show: no ROI given, all four edges found, each MTF50 within 3 % of its closed form."""
    src = tmp_path / "four.npy"
    np.save(src, four_edges())
    summary = _run([str(src)], tmp_path / "out")
    assert summary["refused"] == [] and summary["rois"].startswith("found")
    for (angle, sigma), e in zip(EDGES, _by_angle(summary), strict=True):
        assert e["orientation"] == "vertical" and e["angle_deg"] == pytest.approx(angle, abs=0.05)
        assert e["mtf50_cyc_px"] == pytest.approx(closed_mtf50(angle, sigma), rel=0.03), (angle, e)
        assert e["contrast"] == pytest.approx(HI - LO, rel=0.01)
        assert e["frequency_axis"] == "edge normal"
    with (tmp_path / "out" / "edges.csv").open() as fh:
        rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))
    assert [r["status"] for r in rows] == ["ok"] * 4
    assert read_png_text(tmp_path / "out" / "rois.png")["command"] == "mtf"


@pytest.mark.physics
def test_pixel_axis_on_request(tmp_path: Path) -> None:
    """``--frequency-axis pixel``: every reading on the row axis, ``cos(angle)`` times the normal's."""
    src = tmp_path / "four.npy"
    np.save(src, four_edges())
    normal = _by_angle(_run([str(src)], tmp_path / "n"))
    rows = _by_angle(_run([str(src), "--frequency-axis", "pixel"], tmp_path / "p"))
    for (angle, _), a, b in zip(EDGES, normal, rows, strict=True):
        assert b["frequency_axis"] == "pixel rows"
        assert b["mtf50_cyc_px"] == pytest.approx(a["mtf50_cyc_px"] * math.cos(math.radians(angle)), rel=1e-3)
    with (tmp_path / "p" / "sfr.csv").open() as fh:
        assert "f cos(angle)" in fh.readline() + fh.readline() + fh.read(4000)


@pytest.mark.physics
def test_colour_channels(tmp_path: Path) -> None:
    """Must show: the same four edges in RGB with another blur per channel; ``--channel`` gives
    each channel's MTF50 and ``Y`` the ISO 12233 luminance's, within 3 % (16-bit PNG and TIFF)."""
    import tifffile
    from PIL import Image

    planes = [four_edges(CHANNEL_SIGMAS[c]) for c in "RGB"]
    rgb16 = np.round(np.stack(planes, axis=-1) * 100).astype(np.uint16)  # 10000 .. 40000
    import cv2

    cv2.imwrite(str(tmp_path / "rgb.png"), rgb16[..., ::-1])  # OpenCV writes B, G, R
    tifffile.imwrite(tmp_path / "rgb.tiff", rgb16, photometric="rgb")
    Image.fromarray(np.round(np.stack(planes, axis=-1) * 0.5).astype(np.uint8)).save(tmp_path / "rgb.bmp")
    for name, channels in (("rgb.png", "RGBY"), ("rgb.tiff", "Y")):
        for c in channels:
            edges = _by_angle(_run([str(tmp_path / name), "--channel", c], tmp_path / f"{name}_{c}"))
            for k, ((angle, _), e) in enumerate(zip(EDGES, edges, strict=True)):
                sig: dict[str, float] | float = (
                    {ch: CHANNEL_SIGMAS[ch][k] for ch in "RGB"} if c == "Y" else CHANNEL_SIGMAS[c][k])
                assert e["mtf50_cyc_px"] == pytest.approx(closed_mtf50(angle, sig), rel=0.03), (name, c, k)
    green = _by_angle(_run([str(tmp_path / "rgb.bmp"), "--channel", "G"], tmp_path / "bmp"))
    for k, ((angle, _), e) in enumerate(zip(EDGES, green, strict=True)):
        assert e["mtf50_cyc_px"] == pytest.approx(closed_mtf50(angle, CHANNEL_SIGMAS["G"][k]), rel=0.03)


@pytest.mark.physics
def test_invalid_pixels_left_out(tmp_path: Path) -> None:
    """A mask over part of one edge, NaN pixels over another and a clipped patch over a third:
    the ROIs found hold none of them, and every edge measured keeps its closed form."""
    img = four_edges()
    mask = np.ones(img.shape, dtype=np.uint8)
    mask[60:100, :120] = 0  # across the first edge
    img[:30, 150:260] = np.nan  # the top of the second edge
    words = np.round(img * 100)
    words[120:, 280:420] = 65535  # the bottom of the third edge clipped at the word's top
    src, msk = tmp_path / "img.npy", tmp_path / "mask.png"
    np.save(src, words)
    from PIL import Image

    Image.fromarray(mask * 255).save(msk)
    summary = _run([str(src), "--mask", str(msk)], tmp_path / "out")
    assert summary["saturation"] == 65535
    bad = (mask == 0) | np.isnan(words) | (words >= 65535)
    seen = set()
    for e in summary["edges"]:
        x0, y0, x1, y1 = e["roi"]
        assert not bad[y0:y1, x0:x1].any(), e["roi"]
        k = next(i for i, (angle, _) in enumerate(EDGES) if abs(e["angle_deg"] - angle) < 0.3)
        seen.add(k)
        assert e["mtf50_cyc_px"] == pytest.approx(closed_mtf50(*EDGES[k]), rel=0.03), e
    assert seen == {0, 1, 2, 3}
