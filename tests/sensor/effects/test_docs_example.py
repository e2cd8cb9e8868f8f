"""The complete example of ``docs/sensor-effects.md`` runs as written: its ``my_effects.py`` and
``my_camera.toml`` blocks, on the rig ``bench-sim init`` copies, give a chain whose truth is exact
(z-scores of every word of stages 1 and 40 of a flat field: mean 0, variance 1) and, with the
dust switched on, a pass that says its truth is not exact."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from bench_sim.cli import app
from bench_sim.config import load_config, with_overrides
from bench_sim.pipeline import run_pass

pytestmark = pytest.mark.slow

PAGE = Path(__file__).resolve().parents[3] / "docs" / "sensor-effects.md"


def _block(name: str) -> str:
    """The fenced block of the page whose info string names ``name`` (```python my_effects.py)."""
    found = re.findall(r"^```\w+ " + re.escape(name) + r"\n(.*?)^```", PAGE.read_text(), re.M | re.S)
    assert len(found) == 1, name
    return found[0]


def test_the_pages_example_runs_with_its_exact_truth(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert CliRunner().invoke(app, ["init", "start"]).exit_code == 0
    (tmp_path / "my_effects.py").write_text(_block("my_effects.py"))
    (tmp_path / "my_camera.toml").write_text(_block("my_camera.toml"))
    shown = CliRunner().invoke(app, ["config", "show", "my_camera.toml"])
    assert shown.exit_code == 0, shown.stderr
    cfg = with_overrides(load_config(tmp_path / "my_camera.toml"), {"lines": 64})
    d = run_pass(cfg, [1, 40], 0).dataset
    assert d.attrs["truth_exact"] == 1
    z = ((d.dn.astype(np.float64) - d.mean_dn) / d.noise_std_dn).values.ravel()
    assert abs(z.mean()) < 5 / np.sqrt(z.size) and abs(z.var() - 1) < 5 * np.sqrt(2 / z.size)
    dusty = with_overrides(cfg, {"sensor": {"effects": {"dust": {"enabled": True}}}})
    assert run_pass(dusty, [1], 0).dataset.attrs["truth_exact"] == 0
