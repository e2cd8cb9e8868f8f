"""The lens through the whole chain, measured as a user would: diffraction on the default rig's
optics against its closed form, a lens MTF table given as a CSV file measured back by
``bench-sim mtf`` from a ``simulate`` output, and ``mtf`` on every format ``simulate`` writes.

The benches: the default rig's lens, pixel and wavelength, every noise source off, lit evenly by
the fill alone, a ``slanted_edges`` target drawn at 8 texels per pixel (at the default 4 the
drawn edge itself costs 7 % of the SFR at Nyquist: :mod:`bench_sim.workflows.reproduce.stage_mtf`).
The closed form across the track at the edges' 5 deg: ``lens(f) sinc(f cos t) sinc(f sin t)``
(the pixel aperture along the normal) times the e-SFR's 1/4-px bins ``sinc(f cos(t) / 4)``.
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
from bench_sim.config import config_to_toml_text
from bench_sim.measure.sharpness import SFR_FREQUENCY_CYC_PX, add_sharpness
from bench_sim.pipeline import run_pass
from bench_sim.rig.lens_psf import diffraction_mtf
from tests.conftest import ALL_OFF, make_cfg

pytestmark = [pytest.mark.slow, pytest.mark.physics]
runner = CliRunner()
ANGLE = math.radians(5.0)
FREQS = (0.1, 0.2, 0.3, 0.4, 0.5)


def _bench(lens: dict, **more: dict):
    return make_cfg(
        lines=256, sensor={"rows": 4, "columns": 256, **ALL_OFF},
        target={"layout": "slanted_edges", "panel_lines": 512, "panel_columns": 256, "edge_cell_px": 128,
                "texels_per_pixel": 8},
        lights={"strong": {"enabled": False}, "weak": {"irradiance_w_m2": 40.0}},
        render={"spp": 4, "subpixels": 4}, fusion={"mu1": 1, "mu2": 4}, lens=lens, **more,
    )


def _closed(lens: np.ndarray, f: np.ndarray) -> np.ndarray:
    pixel = np.sinc(f * math.cos(ANGLE)) * np.sinc(f * math.sin(ANGLE))
    return lens * pixel * np.sinc(f * math.cos(ANGLE) / 4)


def test_default_rigs_diffraction_at_nyquist() -> None:
    """Must show: with diffraction on (the default), the across-track SFR at Nyquist of the default
    rig's optics is within 3 % of the diffraction-limited MTF times the pixel aperture; with it off
    the lens is perfect and the same edge reads higher by 1 / D."""
    cfg = _bench({})
    ds = add_sharpness(run_pass(cfg, (1,), 1).dataset, cfg)
    nw = cfg.lens.f_number * (1 + cfg.lens.magnification)
    d = float(diffraction_mtf(np.array([0.5 / cfg.sensor.pixel_pitch_m]), cfg.sensor.wavelength_m, nw)[0])
    k = int(np.argmin(np.abs(SFR_FREQUENCY_CYC_PX - 0.5)))
    measured = float(ds["sfr_across"].values[0, k])
    assert measured == pytest.approx(float(_closed(np.array(d), np.array(0.5))), rel=0.03)
    perfect = _bench({"diffraction": False})
    off = add_sharpness(run_pass(perfect, (1,), 1).dataset, perfect)
    assert measured / float(off["sfr_across"].values[0, k]) == pytest.approx(d, rel=0.02)


def _simulate(tmp_path: Path, name: str, cfg, fmt: str = "zarr", stages: str = "1") -> Path:
    (tmp_path / f"{name}.toml").write_text(config_to_toml_text(cfg))
    out = tmp_path / f"sim_{name}"
    r = runner.invoke(app, ["simulate", str(tmp_path / f"{name}.toml"), "--stages", stages, "--format", fmt,
                            "--out", str(out)])
    assert r.exit_code == 0, r.stderr
    return out


def _mean_curves(folder: Path) -> dict[tuple[str, str], np.ndarray]:
    with (folder / "sfr_stages.csv").open() as fh:
        rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))
    out: dict[tuple[str, str], list[float]] = {}
    for r in rows:
        out.setdefault((r["stage"], r["direction"]), []).append(float(r["sfr"]) if r["sfr"] else np.nan)
    return {k: np.asarray(v) for k, v in out.items()}


def test_lens_mtf_from_csv_reproduces_itself(tmp_path: Path) -> None:
    """Must show: a lens MTF table (CSV, tangential across the track) applied by ``simulate`` and
    measured back by ``bench-sim mtf`` on its output reproduces itself within 3 % at five
    frequencies up to Nyquist: the e-SFR through the lens over that through a perfect lens (the
    same bench), and the e-SFR over the closed form of the pixel and the bins."""
    nu = np.linspace(0.0, 400.0, 41)
    tan, sag = np.exp(-(nu / 110.0) ** 2), np.exp(-((nu / 160.0) ** 1.5))
    (tmp_path / "lens.csv").write_text("frequency_cyc_mm,mtf_sagittal,mtf_tangential\n" + "\n".join(
        f"{a:g},{b:.8g},{c:.8g}" for a, b, c in zip(nu, sag, tan, strict=True)))
    curves = {}
    lenses = (("lens", {"mtf_file": str(tmp_path / "lens.csv")}), ("perfect", {"diffraction": False}))
    for name, lens in lenses:
        sim = _simulate(tmp_path, name, _bench(lens))
        r = runner.invoke(app, ["mtf", str(sim), "--out", str(tmp_path / f"mtf_{name}")])
        assert r.exit_code == 0, r.stderr
        curves[name] = _mean_curves(tmp_path / f"mtf_{name}")[("1", "across")]
    f = np.asarray(FREQS)
    k = [int(np.argmin(np.abs(SFR_FREQUENCY_CYC_PX - x))) for x in f]
    table = np.interp(f / 5.5e-3, nu, tan)
    np.testing.assert_allclose(curves["lens"][k] / curves["perfect"][k], table, rtol=0.03)
    np.testing.assert_allclose(curves["lens"][k] / _closed(np.ones_like(f), f), table, rtol=0.05)


def test_mtf_measures_every_stage_of_every_format(tmp_path: Path) -> None:
    """``bench-sim mtf`` on a simulate output (its folder, Zarr or the TIFF set) measures every
    stage and ``gamma_hdr`` alike; the TIFF set carries its per-stage SFR curves
    (``sfr_curves.csv``) and its MTF50s agree with ``mtf``'s within the ROIs' difference."""
    cfg = _bench({}, timing={"sync_error": 0.2})
    got = {}
    for fmt in ("zarr", "tiff"):
        sim = _simulate(tmp_path, fmt, cfg, fmt=fmt, stages="1,2,4")
        out = tmp_path / f"mtf_{fmt}"
        r = runner.invoke(app, ["mtf", str(sim), "--out", str(out)])
        assert r.exit_code == 0, r.stderr
        summary = json.loads((out / "summary.json").read_text())
        assert [s["stage"] for s in summary["stages"]] == [1, 2, 4, "gamma_hdr"]
        assert {"edges.csv", "sfr_edges.csv", "sfr_stages.csv", "stages.csv", "sfr.png", "rois.png"} <= {
            p.name for p in out.iterdir()}
        got[fmt] = summary["stages"]
    for a, b in zip(got["zarr"], got["tiff"], strict=True):
        assert a["mtf50_cyc_px_across"] == pytest.approx(b["mtf50_cyc_px_across"], rel=1e-6)
    # along the track a sync error e makes stage m a box of m e pixels: MTF50 falls with m
    along = [s["mtf50_cyc_px_along"] for s in got["zarr"][:3]]
    assert along[0] > along[1] > along[2]
    meta = json.loads((tmp_path / "sim_tiff" / "meta.json").read_text())
    assert (tmp_path / "sim_tiff" / "sfr_curves.csv").is_file()
    for s in got["tiff"][:3]:
        own = meta["mtf50_across_cyc_px"][str(s["stage"])]
        assert s["mtf50_cyc_px_across"] == pytest.approx(own, rel=0.05)
