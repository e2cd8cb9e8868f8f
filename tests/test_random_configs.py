"""Random valid tiny benches through the commands: each run succeeds (a complete output set) or is
refused with one line (exit 2) — never a traceback, never an internal error.

The configs are drawn from the settings' own allowed ranges (log-uniform over decades where the
physics spans them: irradiance, gain, full well, dark current, line period), tiny sizes
(``reproduce --quick`` at most), every target layout and both engines. Bounded for CI:
derandomized (the same examples every run), few examples, no deadline. To search wider, set
``BENCH_SIM_RANDOM_CONFIGS=500`` (examples) when running this file.
"""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path
from typing import Any

from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from bench_sim.cli import app
from bench_sim.config import DEFAULT_CONFIG_PATH, config_to_toml_text, load_config, with_overrides
from bench_sim.errors import BenchSimError
from bench_sim.io import OUTPUT_MARKER

runner = CliRunner()
EXAMPLES = int(os.environ.get("BENCH_SIM_RANDOM_CONFIGS", "10"))


def _log(lo: float, hi: float) -> st.SearchStrategy[float]:
    return st.floats(math.log10(lo), math.log10(hi)).map(lambda x: float(f"{10**x:.4g}"))


@st.composite
def benches(draw: Any) -> tuple[str, dict[str, Any], list[str]]:
    """(command, config overrides on the default rig, extra arguments)."""
    command = draw(st.sampled_from(["simulate", "simulate", "render", "reproduce"]))
    rows = draw(st.integers(2, 16))
    mu1 = draw(st.integers(1, rows - 1))
    mu2 = draw(st.integers(mu1 + 1, rows))
    if command == "reproduce":  # the paper target in view (wider, longer), 16-bit TIFF words
        cols, panel_lines = draw(st.integers(48, 96)), draw(st.integers(48, 128))
        lines, beta = draw(st.integers(panel_lines, 2 * panel_lines)), draw(st.integers(8, 16))
    else:
        cols, lines, panel_lines = (draw(st.integers(*r)) for r in ((16, 64), (1, 40), (16, 160)))
        beta = draw(st.integers(1, 32))
    adc = draw(st.integers(1, 16))
    line_period = draw(_log(1e-6, 1e-1))
    cfg: dict[str, Any] = {
        "lines": lines,
        "sensor": {
            "rows": rows, "columns": cols, "adc_bits": adc,
            "black_offset_dn": draw(st.floats(0, 2.0**adc - 1, exclude_max=True).map(lambda v: round(v, 2))),
            "conversion_gain_dn_per_e": draw(_log(1e-4, 10)),
            "full_well_e": draw(_log(1, 1e6)),
            "read_noise_e": draw(st.floats(0, 100)),
            "dark_current_e_s": draw(st.one_of(st.just(0.0), _log(1e-3, 1e6))),
            "quantum_efficiency": draw(st.floats(0.01, 1)),
            "prnu": draw(st.floats(0, 0.5)),
            "column_offset_dn": draw(st.floats(0, 5)),
            "shot_noise": draw(st.booleans()),
            "quantization": draw(st.booleans()),
        },
        "dtdi": {
            "beta_bits": beta,
            "pedestal_dn": draw(st.integers(0, 2 ** (beta - 1) - 1)) if beta > 1 else 0,
            "subtract_black": draw(st.booleans()),
        },
        "timing": {
            "line_period_s": line_period,
            "integration_time_s": float(f"{line_period * draw(st.floats(0.01, 1)):.4g}"),
            "sync_error": draw(st.floats(-0.4, 0.4)),
        },
        "lights": {
            "strong": {"enabled": draw(st.booleans()), "irradiance_w_m2": draw(_log(1e-3, 1e6))},
            "weak": {"enabled": draw(st.booleans()), "irradiance_w_m2": draw(_log(1e-3, 1e4))},
        },
        "lens": {"f_number": draw(st.floats(0.5, 32)), "cos4_falloff": draw(st.booleans())},
        "target": {
            "layout": "paper" if command == "reproduce" else draw(
                st.sampled_from(["paper", "uniform", "dead_leaves", "slanted_edges", "random_bars"])
            ),
            "panel_lines": panel_lines,
            "panel_columns": draw(st.integers(16, cols)),
            "texels_per_pixel": draw(st.integers(1, 4)),
            "dead_leaves_radius_min_px": 2.0,
            "dead_leaves_radius_max_px": draw(st.floats(3, 32)),
        },
        "render": {
            "engine": draw(st.sampled_from(["fast", "fast", "reference"])),
            "spp": draw(st.integers(1, 8)),
            "subpixels": draw(st.integers(1, 4)),
        },
        "fusion": {"mu1": mu1, "mu2": mu2},
    }
    extra = {
        "simulate": ["--stages", draw(st.sampled_from(["all", f"{mu1},{mu2}", "1"]))],
        "render": ["--frames", str(draw(st.integers(1, 40)))],
        "reproduce": [],
    }[command]
    return command, cfg, extra


#: a bench every command can run, so each CI run sees a complete reproduction too
KNOWN_GOOD = {
    "lines": 100,
    "sensor": {"rows": 12, "columns": 64},
    "target": {"panel_lines": 96, "panel_columns": 64},
    "render": {"spp": 4},
    "fusion": {"mu1": 2, "mu2": 8},
}


@example(bench=("reproduce", KNOWN_GOOD, []), seed=7)
@settings(
    max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
@given(bench=benches(), seed=st.integers(0, 2**63 - 1))
def test_random_tiny_benches_run_or_are_refused_in_one_line(
    bench: tuple[str, dict, list[str]], seed: int
) -> None:
    command, overrides, extra = bench
    try:
        cfg = with_overrides(load_config(DEFAULT_CONFIG_PATH), overrides)
    except BenchSimError:  # refused as a config: the one-line path is tested in test_bad_inputs
        return
    with tempfile.TemporaryDirectory() as d:
        folder = Path(d)
        path = folder / "bench.toml"
        path.write_text(config_to_toml_text(cfg))
        out = folder / "out"
        r = runner.invoke(app, [command, str(path), *extra, "--seed", str(seed), "--out", str(out)])
        lines = r.stderr.splitlines()
        assert "Traceback" not in r.stderr and "internal error" not in r.stderr, (overrides, r.stderr[-3000:])
        assert all(ln.startswith(("bench-sim: warning: ", "bench-sim: error: ")) for ln in lines), r.stderr
        if command == "reproduce" and overrides is KNOWN_GOOD:
            assert r.exit_code == 0, r.stderr
        if r.exit_code == 0:
            assert (out / OUTPUT_MARKER).is_file()
            assert not any(ln.startswith("bench-sim: error") for ln in lines)
        else:
            assert r.exit_code == 2, (overrides, r.exit_code, r.stderr[-3000:])
            assert sum(ln.startswith("bench-sim: error: ") for ln in lines) == 1, r.stderr
            assert not out.exists() and sorted(p.name for p in folder.iterdir()) == ["bench.toml"]
