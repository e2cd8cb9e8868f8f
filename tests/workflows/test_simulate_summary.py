"""The one-screen summary at the end of ``bench-sim simulate``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr
from typer.testing import CliRunner

from bench_sim.cli import app
from bench_sim.config import config_to_toml_text
from tests.conftest import tiny_cfg

runner = CliRunner()


def test_summary_says_what_was_written_and_what_clipped(tmp_path: Path) -> None:
    # a bright spot: stage 8 clips where it falls, stage 2 hardly
    cfg = tiny_cfg(lines=48, fusion={"mu1": 2, "mu2": 8}, lights={"strong": {"irradiance_w_m2": 2000.0}})
    path = tmp_path / "bench.toml"
    path.write_text(config_to_toml_text(cfg))
    out = tmp_path / "sim"
    r = runner.invoke(app, ["simulate", str(path), "--stages", "2,8", "--seed", "5", "--out", str(out)])
    assert r.exit_code == 0, r.stderr
    text = r.stdout[r.stdout.index("simulate: bench"):]  # after the progress bar
    lines = text.strip().splitlines()
    assert len(lines) <= 12
    assert lines[0].startswith("simulate: bench 'paper_rig', seed 5, stages 2, 8, 48 lines x 48 columns")
    assert lines[1].startswith(f"wrote {out}/ (") and "simulation.zarr" in lines[2]
    ds = xr.open_zarr(out / "simulation.zarr")
    clipped = {int(m): float(ds["clipped"].sel(stage=m).mean()) for m in (2, 8)}
    assert clipped[8] > clipped[2] and clipped[8] > 0
    line = next(ln for ln in lines if ln.startswith("clipped"))
    for m, f in clipped.items():
        assert f"stage {m}: {100 * f:.2f} %" in line
    size = sum(p.stat().st_size for p in (out / "simulation.zarr").rglob("*") if p.is_file())
    visible = sum(p.stat().st_size for p in out.rglob("*") if p.is_file() and ".bench" not in p.name)
    assert np.isclose(size, visible)
    assert lines[-1] == f'open it: xarray.open_zarr("{out / "simulation.zarr"}")'
